"""Renders the mirror room for the ssr_mirror measurements (docs/effects/ssr_mirror.md).

    blender -b --factory-startup --python tests/bench/bench_ssr_render.py -- OUT_PREFIX \\
        [--mode backing|cycles_mirror|eevee_ssr|eevee_nossr] [--resolution W H] \\
        [--samples N] [--frame N] [--repeat N]

Writes OUT_PREFIX.exr (32-bit multilayer render output with Combined, Depth, Normal,
Position, IndexOB, IndexMA and CryptoMaterial), OUT_PREFIX.camera.json (the libfx
scene sidecar: camera matrices as rows, clip range) and OUT_PREFIX.time.json (render
wall time in seconds, as measured around bpy.ops.render.render). With --repeat N the
frame is rendered N times in this one Blender session and "seconds" is the median of
renders 2..N (warm: Eevee's shader compilation and Cycles' kernel/BVH set-up are paid by
the first); "all_seconds" lists every render.

Modes:
  backing        the scene as built (mirrors are a dark backing): libfx's input.
  cycles_mirror  the mirror materials made real (make_mirror_reference.py's rules):
                 the ground truth.
  eevee_ssr      the same true mirrors rendered by Eevee with screen-space
                 reflections on (Eevee's own SSR: the peer).
  eevee_nossr    Eevee, SSR off (the time baseline for Eevee's SSR cost).

Light transport is made the same in every mode (--clamp-indirect, default 0 = off;
Filter Glossy 0): the scene's own settings clamp indirect samples at 0.5, and in
Cycles everything seen *in a mirror* is indirect light, so a clamped truth shows the
reflected room 1.5-2.2x darker than the same surfaces seen directly (measured on the
mirror room: walls lit by the ceiling lights lose the most). libfx reflects what the
camera saw, so input and truth must share one unclamped estimator.
"""

import json
import os
import sys
import time

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
SCENE_DIR = os.path.join(ROOT, "blend_scenes", "mirror_room")


def parse(argv):
    args = argv[argv.index("--") + 1:] if "--" in argv else []
    o = {"prefix": os.path.abspath(args[0]), "mode": "backing", "res": (640, 360),
         "samples": 16, "frame": 1, "clamp": 0.0, "repeat": 1}
    i = 1
    while i < len(args):
        a = args[i]
        if a == "--mode":
            o["mode"] = args[i + 1]
            i += 2
        elif a == "--resolution":
            o["res"] = (int(args[i + 1]), int(args[i + 2]))
            i += 3
        elif a == "--samples":
            o["samples"] = int(args[i + 1])
            i += 2
        elif a == "--clamp-indirect":
            o["clamp"] = float(args[i + 1])
            i += 2
        elif a == "--repeat":
            o["repeat"] = max(1, int(args[i + 1]))
            i += 2
        elif a == "--frame":
            o["frame"] = int(args[i + 1])
            i += 2
        else:
            raise SystemExit("unknown option %r" % a)
    return o


def camera_sidecar(scene):
    dg = bpy.context.evaluated_depsgraph_get()
    cam = scene.camera.evaluated_get(dg)
    r = scene.render
    proj = cam.calc_matrix_camera(dg, x=r.resolution_x, y=r.resolution_y,
                                  scale_x=r.pixel_aspect_x, scale_y=r.pixel_aspect_y)
    return {"world_to_camera": [list(row) for row in cam.matrix_world.inverted()],
            "projection": [list(row) for row in proj],
            "clip_start": cam.data.clip_start, "clip_end": cam.data.clip_end}


def main():
    o = parse(sys.argv)
    bpy.ops.wm.open_mainfile(filepath=os.path.join(SCENE_DIR, "mirror_room.blend"))
    scene = bpy.context.scene
    if o["mode"] != "backing":
        sys.path.insert(0, SCENE_DIR)
        import make_mirror_reference as ref
        for m in bpy.data.materials:
            if m.name.startswith("Mirror_"):
                ref.make_true_mirror(m)
        cy = scene.cycles
        cy.glossy_bounces = 12
        cy.max_bounces = 16
        cy.blur_glossy = 0.0
    # the same light transport for input and truth (see the module doc)
    scene.cycles.sample_clamp_indirect = o["clamp"]
    scene.cycles.blur_glossy = 0.0
    if o["mode"].startswith("eevee"):
        scene.render.engine = 'BLENDER_EEVEE'
        ee = scene.eevee
        ee.taa_render_samples = o["samples"]
        ee.use_ssr = o["mode"] == "eevee_ssr"
        ee.use_ssr_refraction = False
        ee.ssr_quality = 1.0
        ee.ssr_thickness = 0.2
        ee.ssr_max_roughness = 0.5
    else:
        scene.cycles.samples = o["samples"]
    scene.render.resolution_x, scene.render.resolution_y = o["res"]
    scene.render.resolution_percentage = 100
    scene.frame_set(o["frame"])
    vl = scene.view_layers[0]
    vl.use_pass_z = True
    vl.use_pass_normal = True
    if scene.render.engine == 'CYCLES':
        vl.use_pass_position = True
        vl.use_pass_object_index = True
        vl.use_pass_material_index = True
    vl.use_pass_cryptomatte_material = True
    vl.use_pass_cryptomatte_object = True
    img = scene.render.image_settings
    img.file_format = 'OPEN_EXR_MULTILAYER'
    img.color_depth = '32'
    img.exr_codec = 'ZIP'
    scene.render.use_file_extension = False
    scene.render.use_compositing = False
    scene.render.filepath = o["prefix"] + ".exr"
    with open(o["prefix"] + ".camera.json", "w") as f:
        json.dump(camera_sidecar(scene), f, indent=1)
    times = []
    for _ in range(o["repeat"]):
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        times.append(time.perf_counter() - t0)
    warm = sorted(times[1:]) if len(times) > 1 else times
    dt = warm[len(warm) // 2]
    with open(o["prefix"] + ".time.json", "w") as f:
        json.dump({"mode": o["mode"], "seconds": dt, "all_seconds": times, "res": o["res"],
                   "samples": o["samples"]}, f)
    print("bench_ssr_render: %s %s %.2f s (all: %s)" % (o["mode"], o["prefix"], dt,
                                                      " ".join("%.2f" % t for t in times)))


if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(SCENE_DIR))
    import scene_common  # noqa: E402
    scene_common.run_main(main)
