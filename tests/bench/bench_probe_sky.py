"""What the reflection probe's Sky layer (the world alone, aux_views._render_probe) costs:
the probe of a truth mirror scene rendered with and without it, alternated in one Blender
process, medians.

    LIBFX_LIBRARY=build/libfx/libfx.so blender -b blend_scenes/truth_mirrors/truth_mirrors_facing.blend \\
        --python tests/bench/bench_probe_sky.py -- [RUNS]
"""
import os
import statistics
import sys
import tempfile
import time

import bpy

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "addon"))
from libfx import aux_views  # noqa: E402

runs = int(sys.argv[sys.argv.index("--") + 1]) if "--" in sys.argv and len(sys.argv) > sys.argv.index("--") + 1 else 3
scene = bpy.context.scene
scene.cycles.use_denoising = False
view = {"name": "probe:bench", "mask": {"material": ["Mirror"]}}
spec = aux_views.probe_spec(scene, view)
objs = aux_views._probe_scene_objects(scene)
times = {True: [], False: []}
with tempfile.TemporaryDirectory() as d:
    for k in range(runs):
        for sky in (False, True) if k % 2 == 0 else (True, False):
            t0 = time.perf_counter()
            aux_views._render_probe(scene, spec, objs, os.path.join(d, "p%d.exr" % k), sky=sky)
            times[sky].append(time.perf_counter() - t0)
print("probe %dx%d, %d samples at %s: without Sky %.2f s, with Sky %.2f s (medians of %d, alternated)"
      % (spec["width"], spec["height"], spec["samples"], spec["where"], statistics.median(times[False]),
         statistics.median(times[True]), runs))
