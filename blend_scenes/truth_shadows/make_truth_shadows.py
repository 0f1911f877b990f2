"""Build the sun-shadow truth scenes (issue 14): one .blend per variant. The ``Sun``
casts no ray-traced shadow in the .blend (libfx's vsm_shadows adds it, ``apply:
light_group``, as in the atrium); ``apply_truth()`` turns its Cycles shadow on (the
ground truth, tests/bench/truth_shadows.py).

    blender -b --factory-startup --python blend_scenes/truth_shadows/make_truth_shadows.py \\
        [-- --variant floor|wall|roof|all]

Variants (all: the default), each written to truth_shadows_<variant>.blend:
  floor  blocks, a pillar and a sphere on a stone floor, the Sun 40 deg up: shadows on
         the floor, seen from 30 deg above;
  wall   a wall facing the camera lit at a grazing angle (the Sun 12 deg off the wall's
         plane), with a ledge, a pilaster and a pole in front of it: long shadows across
         the wall;
  roof   an open pavilion (four columns, a flat roof) over the floor, the Sun 55 deg up:
         the floor under the roof is in shadow, lit by the sky and the bounce only.

Principled materials (roughness 0.5, the vsm_shadows default) with a faint noise texture;
a sky world of strength 0.6; Cycles' usual test settings (scene_common.render_settings),
480x270.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import bpy  # noqa: E402

import scene_common as sc  # noqa: E402

HERE = sc.script_dir(__file__)
VARIANTS = ("floor", "wall", "roof")
RESOLUTION = (480, 270)
SAMPLES = 16

RECIPE = {
    "version": 1,
    "quality": "final",
    "effects": [
        {"effect": "vsm_shadows", "enabled": True, "params_version": 2,
         "params": {"light": "Sun", "filter_size": 5.0, "bleed_reduction": 0.3, "apply": "light_group"}},
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
        raise SystemExit("usage: make_truth_shadows.py [-- --variant %s|all]" % "|".join(VARIANTS))
    return list(VARIANTS)


def mat(name, colour, index):
    return sc.principled_material(
        name, colour, index, roughness=0.5,
        texture=lambda nt, b, c, k: sc.tex_noise(nt, b, c, k, scale=2.0, contrast=0.9))


def build(variant):
    scene = sc.reset_file()
    scene.name = "TruthShadows_" + variant
    sc.render_settings(scene, samples=SAMPLES)
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.frame_start = scene.frame_end = 1
    sc.sky_world("Sky_TruthShadows", strength=0.6)
    floor = mat("Floor_Stone", (0.6, 0.58, 0.55), 1)
    wall = mat("Wall_Plaster", (0.75, 0.7, 0.62), 2)
    red = mat("Red_Paint", (0.7, 0.12, 0.08), 3)
    blue = mat("Blue_Paint", (0.12, 0.25, 0.7), 4)
    white = mat("Column_White", (0.8, 0.8, 0.78), 5)
    sc.mesh_object("Floor", lambda bm: sc.bm_box_minmax(bm, (-12, -12, -0.2), (12, 12, 0)), floor, 1)
    cam = sc.add_camera("Camera", lens=24.0)
    if variant == "floor":
        sc.mesh_object("Block_A", lambda bm: sc.bm_box(bm, (-1.5, 1.0, 0.5), (1.0, 1.0, 1.0), rot_deg=(0, 0, 20)),
                       red, 10)
        sc.mesh_object("Block_B", lambda bm: sc.bm_box(bm, (1.4, 2.2, 0.3), (1.6, 0.6, 0.6), rot_deg=(0, 0, -10)),
                       blue, 11)
        sc.mesh_object("Pillar", lambda bm: sc.bm_cylinder(bm, (0.2, 3.5, 0), 0.25, 2.5, segments=24),
                       white, 12, smooth=True, auto_smooth_deg=60)
        sc.mesh_object("Sphere", lambda bm: sc.bm_sphere(bm, (-0.2, -0.3, 0.45), 0.45, segments=32, rings=16),
                       white, 13, smooth=True)
        sun_dir = sc.direction_from_angles(120.0, 40.0)
        cam_loc, target = (0.0, -6.0, 3.8), (0.0, 1.2, 0.0)
    elif variant == "wall":
        sc.mesh_object("Wall", lambda bm: sc.bm_box_minmax(bm, (-5, 3.0, 0), (5, 3.3, 4.0)), wall, 20)
        sc.mesh_object("Ledge", lambda bm: sc.bm_box_minmax(bm, (-3.5, 2.6, 2.2), (1.5, 3.0, 2.4)), white, 21)
        sc.mesh_object("Pilaster", lambda bm: sc.bm_box_minmax(bm, (2.2, 2.7, 0), (2.6, 3.0, 4.0)), white, 22)
        sc.mesh_object("Pole", lambda bm: sc.bm_cylinder(bm, (-1.0, 2.0, 0), 0.08, 3.2, segments=16),
                       red, 23, smooth=True, auto_smooth_deg=60)
        sc.mesh_object("Box", lambda bm: sc.bm_box(bm, (0.8, 2.4, 0.4), (0.8, 0.8, 0.8)), blue, 24)
        # the Sun 12 deg off the wall's plane (the wall faces -Y), from the right, 30 deg up
        sun_dir = sc.direction_from_angles(-102.0, 30.0)
        cam_loc, target = (0.0, -5.5, 1.8), (0.0, 3.0, 1.7)
    else:
        def pavilion(bm):
            for x in (-1.8, 1.8):
                for y in (-1.2, 1.6):
                    sc.bm_cylinder(bm, (x, y, 0), 0.18, 2.6, segments=20)
        sc.mesh_object("Columns", pavilion, white, 30, smooth=True, auto_smooth_deg=60)
        sc.mesh_object("Roof", lambda bm: sc.bm_box_minmax(bm, (-2.3, -1.7, 2.6), (2.3, 2.1, 2.9)), wall, 31)
        sc.mesh_object("Bench", lambda bm: sc.bm_box(bm, (0.0, 0.6, 0.25), (1.6, 0.5, 0.5)), red, 32)
        sun_dir = sc.direction_from_angles(150.0, 55.0)
        cam_loc, target = (1.0, -7.0, 2.4), (0.0, 0.5, 0.8)
    cam.location = cam_loc
    cam.rotation_euler = sc.look_at_euler(cam_loc, target)
    sun = sc.add_sun("Sun", sun_dir, strength=3.0, color=(1.0, 0.95, 0.85), angle_deg=1.0)
    # libfx's vsm_shadows adds the Sun's shadows (apply "light_group"): Cycles must not
    sc.compat.light_cast_shadow(sun.data, False)
    sc.check_unique_indices()
    sc.write_recipe(HERE, RECIPE)
    sc.save_blend(os.path.join(HERE, "truth_shadows_%s.blend" % variant))


def apply_truth(scene=None):
    """The ground truth: the Sun casts its ray-traced shadow. Never saved."""
    sc.compat.light_cast_shadow(bpy.data.objects["Sun"].data, True)


def main():
    for v in parse(sys.argv):
        build(v)


if __name__ == "__main__":
    sc.run_main(main)
