"""Build mirror_room.blend: a room with eleven mirror slabs of different kinds
(each object ``Mirror_<Type>`` with a material of the same name) and coloured
objects to reflect.  In this render the mirrors are a plain dark grey-blue
"mirror backing"; libfx adds the reflections.  make_mirror_reference.py swaps
in true Cycles mirrors to render the ground truth.

    blender -b --factory-startup --python blend_scenes/mirror_room/make_mirror_room.py

Coordinates: metres, Z up.  Room x in [-3.5, 3.5], y in [0, 8], z in [0, 3.2];
the camera stands near the front wall (y ~ 0.5) looking +Y at the back wall.
Back wall: Clear, Low, Blurred, Fresnel, Sepia.  Left wall (x = -3.5):
FacingA, Grayscale, BentOut.  Right wall (x = +3.5): FacingB (exactly opposite
FacingA), Cel, BentIn.
"""

import json
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import bpy  # noqa: E402
from mathutils import Vector  # noqa: E402

import scene_common as sc  # noqa: E402

HERE = sc.script_dir(__file__)

RX, RY, RZ = 3.5, 8.0, 3.2          # room half width, depth, height
SLAB_T = 0.04                       # mirror slab thickness
MIRROR_Z = (0.7, 2.3)               # bottom / top of the wall mirrors
BEND_ANGLE_DEG = 65.0
SKYLIGHT = (-0.9, 0.9, 1.2, 2.4)    # ceiling opening x0, x1, y0, y1

# name, wall, position along the wall (x on the back wall, y on the side walls), width
MIRRORS = [
    ("Mirror_Clear", "back", -2.6, 1.1),
    ("Mirror_Low", "back", -1.3, 1.1),
    ("Mirror_Blurred", "back", 0.0, 1.1),
    ("Mirror_Fresnel", "back", 1.3, 1.1),
    ("Mirror_Sepia", "back", 2.6, 1.1),
    ("Mirror_FacingA", "left", 4.4, 1.2),
    ("Mirror_Grayscale", "left", 5.85, 1.1),
    ("Mirror_BentOut", "left", 7.1, 1.0),
    ("Mirror_FacingB", "right", 4.4, 1.2),
    ("Mirror_Cel", "right", 5.85, 1.1),
    ("Mirror_BentIn", "right", 7.1, 1.0),
]
MIRROR_INDEX0 = 20                  # Mirror_* objects and materials: 20..30 in list order

ALL_MIRRORS = [m[0] for m in MIRRORS]


def ssr(name, label, **params):
    """One ssr_mirror entry: one mirror kind on its own material mask."""
    return {"effect": "ssr_mirror", "params_version": 2, "enabled": True, "label": label, "params": params,
            "mask": {"material": name}}


# Every mirror kind as one ssr_mirror entry (docs/effects/ssr_mirror.md). The facing
# pair is one entry masked by both panels: a ray landing on the other panel is
# reflected again there (bounces); it runs last, so rays landing on the other mirrors
# take their finished reflections.
# The bent panels are curved geometry: their Normal pass already carries the
# curvature, so they need no `bend` (which curves flat panels).
RECIPE = {
    "version": 1,
    "quality": "final",
    "effects": [
        ssr("Mirror_Clear", "clear mirror"),
        ssr("Mirror_Low", "low reflectivity", reflectivity=0.25),
        ssr("Mirror_Blurred", "blurred (glossy) mirror", glossiness=6.0),
        ssr("Mirror_Fresnel", "Fresnel-only (glass, IOR 1.5)", fresnel=True, f0=0.04,
            fresnel_power=5.0),
        ssr("Mirror_Sepia", "sepia reflection", operator="sepia"),
        ssr("Mirror_Grayscale", "grayscale reflection", operator="grayscale"),
        ssr("Mirror_Cel", "cel/edge reflection", operator="cel", cel_levels=4,
            edge_threshold=0.05),
        ssr("Mirror_BentOut", "convex (curved geometry)"),
        ssr("Mirror_BentIn", "concave (curved geometry)"),
        # last, so rays landing on the other mirrors see their finished reflections;
        # one entry for both panels, so the regress between them is traced (bounces)
        {"effect": "ssr_mirror", "params_version": 2, "enabled": True, "label": "facing pair (multiple reflections)",
         "params": {"bounces": 4}, "mask": {"material": ["Mirror_FacingA", "Mirror_FacingB"]}},
    ],
}


def mirror_backing_material(name, index):
    """Plain dark grey-blue, slightly glossy 'glass over a dark backing'."""
    return sc.principled_material(name, (0.085, 0.1, 0.13), index, roughness=0.3,
                                  specular=0.5)


def wall_frame(wall, along, width, z0, z1, inset=0.0):
    """World placement of a wall-mounted panel: (centre, rotation_z_deg) with the
    panel's local +Y facing into the room and local X along the wall."""
    zc = (z0 + z1) * 0.5
    if wall == "back":
        return Vector((along, RY - inset, zc)), 180.0
    if wall == "left":
        return Vector((-RX + inset, along, zc)), -90.0
    return Vector((RX - inset, along, zc)), 90.0


def build_flat_slab(width, height):
    def build(bm):
        sc.bm_box(bm, (0, 0, 0), (width, SLAB_T, height))
    return build


def build_bent_panel(width, height, segments=40):
    """A subdivided panel (local XZ plane, normal +Y); thickness and curvature
    come from Solidify and Simple Deform (Bend) modifiers kept live."""
    def build(bm):
        rows = [[bm.verts.new((-width / 2 + width * i / segments, 0.0, z))
                 for i in range(segments + 1)] for z in (-height / 2, 0.0, height / 2)]
        for r in range(2):
            for i in range(segments):
                bm.faces.new((rows[r][i], rows[r][i + 1], rows[r + 1][i + 1], rows[r + 1][i]))
    return build


def bend(obj, convex_towards_room):
    """Solidify + Simple Deform 'BEND' about local Z; choose the sign so the
    centre bulges towards (convex) or away from (concave) the room (+Y local)."""
    sol = obj.modifiers.new("Solidify", 'SOLIDIFY')
    sol.thickness = SLAB_T
    sol.offset = -1.0               # thickness goes behind the mirror face
    sol.use_even_offset = True
    sd = obj.modifiers.new("Bend", 'SIMPLE_DEFORM')
    sd.deform_method = 'BEND'
    sd.deform_axis = 'Z'
    sd.angle = math.radians(BEND_ANGLE_DEG)
    dg = bpy.context.evaluated_depsgraph_get()
    me = obj.evaluated_get(dg).to_mesh()
    ys_mid = [v.co.y for v in me.vertices if abs(v.co.x) < 0.02]
    ys_edge = [v.co.y for v in me.vertices if abs(v.co.x) > max(abs(w.co.x) for w in me.vertices) - 0.02]
    bulge = max(ys_mid) - max(ys_edge)   # > 0: centre is nearer the room than the edges
    obj.evaluated_get(dg).to_mesh_clear()
    if (bulge > 0) != convex_towards_room:
        sd.angle = -sd.angle
    return abs(bulge)


def build_room():
    """The room: floor, four walls and a ceiling with a skylight, each its own object and material; returns the materials."""
    mats = {
        "Floor_Checker": sc.principled_material(
            "Floor_Checker", (0.85, 0.85, 0.82), 1, roughness=0.45,
            texture=lambda nt, b, c, k: sc.tex_checker(nt, b, c, k, scale=1.0,
                                                       color2=(0.08, 0.08, 0.09))),
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
        "Ceiling_White": sc.principled_material("Ceiling_White", (0.85, 0.85, 0.82), 6,
                                                roughness=0.9),
        "Frame_Wood": sc.principled_material(
            "Frame_Wood", (0.35, 0.2, 0.1), 7, roughness=0.5, texture=sc.tex_wood),
    }
    t = 0.2
    sc.mesh_object("Floor", lambda bm: sc.bm_box_minmax(bm, (-RX - t, -t, -t), (RX + t, RY + t, 0)),
                   mats["Floor_Checker"], 1)
    sc.mesh_object("Wall_Back", lambda bm: sc.bm_box_minmax(bm, (-RX - t, RY, 0), (RX + t, RY + t, RZ)),
                   mats["Wall_Back"], 2)
    sc.mesh_object("Wall_Left", lambda bm: sc.bm_box_minmax(bm, (-RX - t, -t, 0), (-RX, RY, RZ)),
                   mats["Wall_Left"], 3)
    sc.mesh_object("Wall_Right", lambda bm: sc.bm_box_minmax(bm, (RX, -t, 0), (RX + t, RY, RZ)),
                   mats["Wall_Right"], 4)
    sc.mesh_object("Wall_Front", lambda bm: sc.bm_box_minmax(bm, (-RX, -t, 0), (RX, 0, RZ)),
                   mats["Wall_Front"], 5)

    def ceiling(bm):
        x0, x1, y0, y1 = SKYLIGHT
        z0, z1 = RZ, RZ + t
        sc.bm_box_minmax(bm, (-RX - t, -t, z0), (RX + t, y0, z1))
        sc.bm_box_minmax(bm, (-RX - t, y1, z0), (RX + t, RY + t, z1))
        sc.bm_box_minmax(bm, (-RX - t, y0, z0), (x0, y1, z1))
        sc.bm_box_minmax(bm, (x1, y0, z0), (RX + t, y1, z1))
    sc.mesh_object("Ceiling", ceiling, mats["Ceiling_White"], 6)
    return mats


def build_mirrors(mats):
    """The mirrors of MIRRORS on their walls (the bent ones curved in place) and the wooden frames of the flat ones."""
    frames = []
    z0, z1 = MIRROR_Z
    h = z1 - z0
    for i, (name, wall, along, width) in enumerate(MIRRORS):
        idx = MIRROR_INDEX0 + i
        mat = mirror_backing_material(name, idx)
        if name in ("Mirror_BentOut", "Mirror_BentIn"):
            obj = sc.mesh_object(name, build_bent_panel(width, h), mat, idx)
            c, rz = wall_frame(wall, along, width, z0, z1, inset=0.0)
            obj.location = c
            obj.rotation_euler = (0, 0, math.radians(rz))
            sag = bend(obj, convex_towards_room=(name == "Mirror_BentOut"))
            # keep the rearmost point of the curved slab just off the wall
            obj.location = wall_frame(wall, along, width, z0, z1,
                                      inset=0.03 + SLAB_T + (sag if name == "Mirror_BentOut" else 0.0))[0]
            for p in obj.data.polygons:
                p.use_smooth = True
        else:
            obj = sc.mesh_object(name, build_flat_slab(width, h), mat, idx)
            c, rz = wall_frame(wall, along, width, z0, z1, inset=0.03 + SLAB_T / 2)
            obj.location = c
            obj.rotation_euler = (0, 0, math.radians(rz))
            frames.append((c, rz, width, h))

    def build_frames(bm):
        from mathutils import Matrix
        b = 0.07
        for c, rz, w, hh in frames:
            m = Matrix.Translation(c) @ Matrix.Rotation(math.radians(rz), 4, 'Z')
            for (x, z, sx, sz) in ((0, hh / 2 + b / 2, w + 2 * b, b), (0, -hh / 2 - b / 2, w + 2 * b, b),
                                   (-w / 2 - b / 2, 0, b, hh), (w / 2 + b / 2, 0, b, hh)):
                p = m @ Vector((x, -0.005, z))
                sc.bm_box(bm, p, (sx, SLAB_T + 0.05, sz), rot_deg=(0, 0, rz))
    sc.mesh_object("Mirror_Frames", build_frames, mats["Frame_Wood"], 8)


def build_props():
    """Coloured objects for the mirrors to reflect."""
    def colour(name, rgb, idx, rough=0.35):
        return sc.principled_material(name, rgb, idx, roughness=rough)
    sc.mesh_object("Red_Sphere", lambda bm: sc.bm_sphere(bm, (-1.2, 4.6, 0.5), 0.5, segments=32,
                                                         rings=16),
                   colour("Red_Paint", (0.8, 0.05, 0.04), 40), 40, smooth=True)
    sc.mesh_object("Green_Cube", lambda bm: sc.bm_box(bm, (1.3, 5.2, 0.375), (0.75, 0.75, 0.75),
                                                      rot_deg=(0, 0, 25)),
                   colour("Green_Paint", (0.08, 0.6, 0.1), 41), 41)
    sc.mesh_object("Blue_Cone", lambda bm: sc.bm_cylinder(bm, (0.1, 6.3, 0.0), 0.45, 1.3,
                                                          segments=32, radius_top=0.0),
                   colour("Blue_Paint", (0.05, 0.15, 0.8), 42), 42, smooth=True,
                   auto_smooth_deg=60)
    sc.mesh_object("Yellow_Torus", lambda bm: sc.bm_torus(bm, (-0.1, 3.4, 0.55), 0.4, 0.13,
                                                          rot_deg=(90, 0, 20)),
                   colour("Yellow_Paint", (0.9, 0.75, 0.05), 43), 43, smooth=True)
    sc.mesh_object("Magenta_Cylinder", lambda bm: sc.bm_cylinder(bm, (2.3, 3.6, 0.0), 0.25, 1.6,
                                                                 segments=24),
                   colour("Magenta_Paint", (0.7, 0.05, 0.5), 44), 44, smooth=True,
                   auto_smooth_deg=60)
    sc.mesh_object("White_Pillar", lambda bm: sc.bm_box(bm, (2.6, 2.2, 0.9), (0.4, 0.4, 1.8)),
                   colour("White_Paint", (0.9, 0.9, 0.88), 45, rough=0.6), 45)


def main():
    scene = sc.reset_file()
    scene.name = "MirrorRoom"
    sc.render_settings(scene)

    sun_dir = sc.direction_from_angles(160.0, 62.0)
    sc.sky_world("Sky_MirrorRoom", zenith=(0.2, 0.4, 0.85), horizon=(0.75, 0.85, 1.0),
                 ground=(0.3, 0.28, 0.25), strength=1.0)
    sc.add_sun("Sun", sun_dir, strength=4.0, color=(1.0, 0.95, 0.85), angle_deg=1.0)

    mats = build_room()
    build_mirrors(mats)
    build_props()

    sc.add_area_light("Ceiling_Light_Front", (0.0, 3.0, RZ - 0.02), (0.0, 3.0, 0.0),
                      size=(2.5, 0.6), power=350.0, color=(1.0, 0.97, 0.92))
    sc.add_area_light("Ceiling_Light_Back", (0.0, 6.0, RZ - 0.02), (0.0, 6.0, 0.0),
                      size=(2.5, 0.6), power=350.0, color=(1.0, 0.97, 0.92))

    cam = sc.add_camera("Camera", lens=17.0)
    sc.animate_camera(cam, [
        (1, (-0.35, 0.45, 1.6), (0.0, 8.0, 1.05)),
        (8, (0.25, 0.75, 1.65), (0.1, 8.0, 1.1)),
    ])

    sc.check_unique_indices()
    sc.write_recipe(HERE, RECIPE)
    sc.print_index_table()
    sc.save_blend(os.path.join(HERE, "mirror_room.blend"))


if __name__ == "__main__":
    sc.run_main(main)
