"""Where the add-on puts a mirror entry's reflection probes (aux_views.probe_specs), on the
mirror truth scenes: a facing pair in one entry gets one probe per mirror plane
("probe:<key>", "probe:<key>#2"), each before its own mirror (the single probe sat between
them, in the room's middle); a single flat mirror and a curved one keep one probe, before
the mirror."""
import json

import addon_testlib as T

OK = "LIBFX-TEST-OK"

SCRIPT = T.PRELUDE + r"""
import json
from mathutils import Matrix, Vector
from libfx import aux_views
scene = bpy.context.scene
specs = aux_views.probe_specs(scene, {"name": "probe:k", "kind": "probe", "mask": {"material": ["Mirror"]}})
out = []
for s in specs:
    pos = Matrix(s["matrix_world"]).translation
    mirrors = []
    for ob in scene.objects:
        if ob.type == "MESH" and any(sl.material and sl.material.name == "Mirror" for sl in ob.material_slots):
            lo = Vector([min(c[i] for c in (ob.matrix_world @ Vector(v) for v in ob.bound_box)) for i in range(3)])
            hi = Vector([max(c[i] for c in (ob.matrix_world @ Vector(v) for v in ob.bound_box)) for i in range(3)])
            mirrors.append([ob.name, ((lo + hi) / 2 - pos).length])
    out.append({"name": s["name"], "where": s["where"], "pos": list(pos), "mirrors": sorted(mirrors, key=lambda m: m[1])})
print("SPECS " + json.dumps(out))
print("LIBFX-TEST-OK")
"""


def _specs(blender, library, variant):
    blend = T.REPO / "blend_scenes" / "truth_mirrors" / ("truth_mirrors_%s.blend" % variant)
    proc = T.run_blender([], blend=str(blend), python_expr=SCRIPT, env=T.addon_env(library), timeout=300)
    text = proc.stdout + proc.stderr
    assert proc.returncode == 0 and OK in proc.stdout, text[-4000:]
    line = next(x for x in proc.stdout.splitlines() if x.startswith("SPECS "))
    return json.loads(line[len("SPECS "):])


def test_facing_pair_gets_a_probe_per_mirror(blender, library):
    specs = _specs(blender, library, "pair")
    assert [s["name"] for s in specs] == ["probe:k", "probe:k#2"], specs
    # each probe is nearest its own mirror, within a metre of its centre, and they differ
    nearest = [s["mirrors"][0] for s in specs]
    assert {m[0] for m in nearest} == {"Mirror_Left", "Mirror_Right"}, specs
    assert all(m[1] < 1.0 for m in nearest), specs
    assert all(s["mirrors"][1][1] > 3.0 for s in specs), specs


def test_single_and_curved_mirrors_keep_one_probe(blender, library):
    for variant in ("facing", "curved"):
        specs = _specs(blender, library, variant)
        assert [s["name"] for s in specs] == ["probe:k"], (variant, specs)
        assert specs[0]["mirrors"][0][1] < 1.5, (variant, specs)
