"""Build the mirror truth scenes (issue 14): one .blend per variant, each a small room
with one mirror material ``Mirror`` that is a plain diffuse grey card in the .blend
(libfx's input: ssr_mirror adds the reflection) and that ``apply_truth()`` turns into
a perfect Cycles mirror (the ground truth, tests/bench/truth_mirrors.py).

    blender -b --factory-startup --python blend_scenes/truth_mirrors/make_truth_mirrors.py \\
        [-- --variant facing|grazing|pair|curved|all]

Variants (all: the default), each written to truth_mirrors_<variant>.blend:
  facing   the issue's scene: a card standing at a slant (15 deg about Z) facing
           the camera, coloured blocks and a sphere in front of it, a brick wall
           behind the camera (seen only in the mirror);
  grazing  a long mirror on the left wall seen at a grazing angle (60-80 deg incidence,
           the camera near that wall);
  pair     two mirrors facing each other on the left and right walls (the recipe's
           one entry traces bounces between them);
  curved   a convex mirror: a 120 deg section of a vertical cylinder (r 0.9 m).

Coordinates: metres, Z up; room x in [-3, 3], y in [-2.5, 6], z in [0, 3]; the camera
stands at y = -1.6 looking +Y.  The room has no ceiling: a Sun (from behind the camera's
left, 50 deg up) and a sky world light it, so 16 samples are clean enough.  Cycles'
indirect clamp is off (everything seen in a mirror is indirect light: clamped, the
reflection comes out darker than what it reflects; bench_ssr_render.py's note).
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import bpy  # noqa: E402

import scene_common as sc  # noqa: E402

HERE = sc.script_dir(__file__)
VARIANTS = ("facing", "grazing", "pair", "curved")
RX, Y0, Y1, RZ = 3.0, -2.5, 6.0, 3.0
RESOLUTION = (480, 270)
SAMPLES = 16
MIRROR_INDEX = 20
CARD_GREY = (0.45, 0.45, 0.45)

RECIPE = {
    "version": 1,
    "quality": "final",
    "effects": [
        # params_version 2: final's footprints (tests/bench/truth_mirrors.py passes this
        # recipe explicitly; the .blend's embedded copy predates it)
        {"effect": "ssr_mirror", "params_version": 2, "enabled": True, "label": "the truth scene's mirror",
         "params": {}, "mask": {"material": "Mirror"}},
    ],
}


def parse(argv):
    args = argv[argv.index("--") + 1:] if "--" in argv else []
    if args[:1] == ["--variant"] and len(args) == 2:
        if args[1] == "all":
            return list(VARIANTS)
        if args[1] not in VARIANTS:
            raise SystemExit("unknown variant %r (one of %s, all)" % (args[1], ", ".join(VARIANTS)))
        return [args[1]]
    if args:
        raise SystemExit("usage: make_truth_mirrors.py [-- --variant %s|all]" % "|".join(VARIANTS))
    return list(VARIANTS)


def room(mats):
    t = 0.2
    sc.mesh_object("Floor", lambda bm: sc.bm_box_minmax(bm, (-RX - t, Y0 - t, -t), (RX + t, Y1 + t, 0)),
                   mats["Floor"], 1)
    sc.mesh_object("Wall_Back", lambda bm: sc.bm_box_minmax(bm, (-RX - t, Y1, 0), (RX + t, Y1 + t, RZ)),
                   mats["Wall_Back"], 2)
    sc.mesh_object("Wall_Left", lambda bm: sc.bm_box_minmax(bm, (-RX - t, Y0 - t, 0), (-RX, Y1, RZ)),
                   mats["Wall_Left"], 3)
    sc.mesh_object("Wall_Right", lambda bm: sc.bm_box_minmax(bm, (RX, Y0 - t, 0), (RX + t, Y1, RZ)),
                   mats["Wall_Right"], 4)
    sc.mesh_object("Wall_Front", lambda bm: sc.bm_box_minmax(bm, (-RX, Y0 - t, 0), (RX, Y0, RZ)),
                   mats["Wall_Front"], 5)


def props(mats, y=1.6):
    """Coloured blocks and a sphere between the camera and the mirror."""
    sc.mesh_object("Red_Block", lambda bm: sc.bm_box(bm, (-1.1, y, 0.35), (0.7, 0.7, 0.7), rot_deg=(0, 0, 20)),
                   mats["Red"], 40)
    sc.mesh_object("Green_Block", lambda bm: sc.bm_box(bm, (1.2, y + 0.6, 0.5), (0.5, 0.5, 1.0),
                                                       rot_deg=(0, 0, -15)),
                   mats["Green"], 41)
    sc.mesh_object("Yellow_Sphere", lambda bm: sc.bm_sphere(bm, (0.1, y + 1.0, 0.45), 0.45, segments=32,
                                                            rings=16),
                   mats["Yellow"], 42, smooth=True)
    sc.mesh_object("Blue_Block", lambda bm: sc.bm_box(bm, (-0.2, y - 0.9, 0.2), (0.9, 0.4, 0.4),
                                                      rot_deg=(0, 0, 5)),
                   mats["Blue"], 43)


def mirror_card(mat, centre, size, rz, tilt=0.0, name="Mirror_Card", index=MIRROR_INDEX):
    """A 3 cm slab of size (width, height), its face normal +Y rotated by rz about Z
    (degrees) and tilted back by ``tilt`` degrees."""
    w, h = size
    return sc.mesh_object(name, lambda bm: sc.bm_box(bm, centre, (w, 0.03, h), rot_deg=(tilt, 0, rz)),
                          mat, index)


def curved_mirror(mat, centre, radius, height, arc_deg=120.0, segments=48):
    """Convex: the outer face of a cylinder section (axis Z through centre), its middle
    facing -Y (the camera). Smooth-shaded; 3 cm thick."""
    cx, cy, z0 = centre

    def build(bm):
        a0 = math.radians(-90.0 - arc_deg / 2)
        rows = []
        for r in (radius, radius - 0.03):
            ring = []
            for i in range(segments + 1):
                a = a0 + math.radians(arc_deg) * i / segments
                ring.append((bm.verts.new((cx + r * math.cos(a), cy + r * math.sin(a), z0)),
                             bm.verts.new((cx + r * math.cos(a), cy + r * math.sin(a), z0 + height))))
            rows.append(ring)
        out, inn = rows
        for i in range(segments):
            bm.faces.new((out[i][0], out[i + 1][0], out[i + 1][1], out[i][1]))
            bm.faces.new((inn[i + 1][0], inn[i][0], inn[i][1], inn[i + 1][1]))
            bm.faces.new((out[i + 1][0], out[i][0], inn[i][0], inn[i + 1][0]))
            bm.faces.new((out[i][1], out[i + 1][1], inn[i + 1][1], inn[i][1]))
        bm.faces.new((out[0][0], out[0][1], inn[0][1], inn[0][0]))
        bm.faces.new((out[-1][1], out[-1][0], inn[-1][0], inn[-1][1]))
    obj = sc.mesh_object("Mirror_Curved", build, mat, MIRROR_INDEX, smooth=True, auto_smooth_deg=40)
    return obj


def build(variant):
    scene = sc.reset_file()
    scene.name = "TruthMirrors_" + variant
    sc.render_settings(scene, samples=SAMPLES)
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.frame_start = scene.frame_end = 1
    cy = scene.cycles
    cy.sample_clamp_indirect = 0.0     # the same estimator for input and truth
    cy.blur_glossy = 0.0
    sc.sky_world("Sky_TruthMirrors", strength=0.5)
    mats = {
        "Floor": sc.principled_material(
            "Floor", (0.8, 0.8, 0.78), 1, roughness=0.6,
            texture=lambda nt, b, c, k: sc.tex_checker(nt, b, c, k, scale=1.0, color2=(0.1, 0.1, 0.11))),
        "Wall_Back": sc.principled_material(
            "Wall_Back", (0.55, 0.68, 0.5), 2, roughness=0.8,
            texture=lambda nt, b, c, k: sc.tex_noise(nt, b, c, k, scale=1.0, contrast=0.85)),
        "Wall_Left": sc.principled_material(
            "Wall_Left", (0.75, 0.42, 0.3), 3, roughness=0.8,
            texture=lambda nt, b, c, k: sc.tex_noise(nt, b, c, k, scale=1.0, contrast=0.85)),
        "Wall_Right": sc.principled_material(
            "Wall_Right", (0.42, 0.55, 0.75), 4, roughness=0.8,
            texture=lambda nt, b, c, k: sc.tex_noise(nt, b, c, k, scale=1.0, contrast=0.85)),
        "Wall_Front": sc.principled_material(
            "Wall_Front", (0.8, 0.72, 0.45), 5, roughness=0.8,
            texture=lambda nt, b, c, k: sc.tex_bricks(nt, b, c, k, scale=2.0)),
        "Red": sc.principled_material("Red_Paint", (0.8, 0.05, 0.04), 40, roughness=0.4),
        "Green": sc.principled_material("Green_Paint", (0.08, 0.6, 0.1), 41, roughness=0.4),
        "Yellow": sc.principled_material("Yellow_Paint", (0.9, 0.75, 0.05), 42, roughness=0.4),
        "Blue": sc.principled_material("Blue_Paint", (0.05, 0.15, 0.8), 43, roughness=0.4),
        # the card: diffuse grey here, a perfect mirror in the truth (apply_truth)
        "Mirror": sc.principled_material("Mirror", CARD_GREY, MIRROR_INDEX, roughness=0.8, specular=0.0),
    }
    room(mats)
    cam = sc.add_camera("Camera", lens=20.0)
    if variant == "facing":
        props(mats, y=1.4)
        mirror_card(mats["Mirror"], (0.3, 4.2, 1.0), (2.8, 1.8), rz=15.0)
        cam_loc, target = (0.0, -1.6, 1.5), (0.2, 5.0, 1.0)
    elif variant == "grazing":
        props(mats, y=2.0)
        mirror_card(mats["Mirror"], (-RX + 0.05, 2.6, 1.3), (5.0, 1.8), rz=90.0)
        cam_loc, target = (-1.9, -1.8, 1.5), (-0.6, 5.0, 1.1)
    elif variant == "pair":
        props(mats, y=2.2)
        mirror_card(mats["Mirror"], (-RX + 0.05, 3.0, 1.3), (2.4, 1.8), rz=90.0, name="Mirror_Left")
        mirror_card(mats["Mirror"], (RX - 0.05, 3.0, 1.3), (2.4, 1.8), rz=90.0, name="Mirror_Right",
                    index=MIRROR_INDEX + 1)
        cam_loc, target = (0.0, -1.8, 1.5), (0.0, 5.0, 1.1)
    else:
        props(mats, y=1.4)
        curved_mirror(mats["Mirror"], (0.2, 4.9, 0.0), 0.9, 2.2)
        cam_loc, target = (0.0, -1.6, 1.5), (0.1, 5.0, 1.0)
    cam.location = cam_loc
    cam.rotation_euler = sc.look_at_euler(cam_loc, target)
    # open to the sky (no ceiling): direct light dominates, so 16 samples stay clean
    sc.add_sun("Sun", sc.direction_from_angles(200.0, 50.0), strength=2.5, color=(1.0, 0.95, 0.85),
               angle_deg=1.0)
    sc.check_unique_indices()
    sc.write_recipe(HERE, RECIPE)
    sc.save_blend(os.path.join(HERE, "truth_mirrors_%s.blend" % variant))


def apply_truth(scene=None):
    """The ground truth: ``Mirror`` becomes a perfect Glossy mirror (white, sharp), with
    glossy bounces enough for the facing pair. Call in the opened .blend (the bench
    passes it to batch.py as --python-expr); never saved."""
    scene = scene or bpy.context.scene
    mat = bpy.data.materials["Mirror"]
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    g = nt.nodes.new("ShaderNodeBsdfGlossy")
    sc.sharp_bsdf(g)
    g.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    g.inputs["Roughness"].default_value = 0.0
    nt.links.new(g.outputs[0], out.inputs["Surface"])
    cy = scene.cycles
    cy.glossy_bounces = 12
    cy.max_bounces = 16
    cy.blur_glossy = 0.0
    cy.sample_clamp_indirect = 0.0


def main():
    for v in parse(sys.argv):
        build(v)


if __name__ == "__main__":
    sc.run_main(main)
