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


STALE = T.PRELUDE + r"""
import os
from libfx import aux_views, recipe, scene_setup
scene = bpy.context.scene
with open(os.environ["STALE_RECIPE"], encoding="utf-8") as f:
    recipe.from_recipe(scene, f.read())   # the scene's stack at final: it reads a probe
scene.render.filepath = os.environ["STALE_OUT"] + "/f_"
scene["libfx_probe_size"] = 32        # a thumbnail probe: the test is about its files
scene["libfx_probe_samples"] = 1
scene["libfx_planar_samples"] = 1     # final's planar view renders too: small and cheap
scene.render.resolution_percentage = 10
need = [v for v in aux_views.needed(scene) if v["kind"] == "probe"][0]
prefix = scene_setup.output_prefix(scene)
stale = {}
for k in (1, 2):                    # what a facing pair left there: "#2" and "#3"
    name = aux_views.planar_view_name(need["name"], k)
    base = prefix + "libfx_aux_" + aux_views._file_name(name)
    for ext in (".json", ".exr"):
        with open(base + ext, "w") as f:
            f.write(json.dumps({"name": name, "path": base + ".exr", "kind": "probe"}) if ext == ".json" else "x")
    stale[name] = base
entries = aux_views.prepare(scene, [1])
print("PREPARED " + json.dumps(sorted(e["name"] for e in entries if e["name"].startswith("probe:"))))
print("DISK " + json.dumps(sorted(e["name"] for e in aux_views.from_disk(scene) if e["name"].startswith("probe:"))))
print("LEFT " + json.dumps(sorted(n for n, b in stale.items() if os.path.exists(b + ".json") or os.path.exists(b + ".exr"))))
print("NEED " + json.dumps(need["name"]))
print("LIBFX-TEST-OK")
"""


def test_a_batch_run_removes_the_probes_of_planes_gone(blender, library, tmp_path):
    """F12 reads the probes a batch run left on disk (aux_views.from_disk): a "#2" probe
    from when the scene's mirror was a facing pair must not outlive it."""
    blend = T.REPO / "blend_scenes" / "truth_mirrors" / "truth_mirrors_facing.blend"
    proc = T.run_blender([], blend=str(blend), python_expr=STALE,
                         env=dict(T.addon_env(library), STALE_OUT=str(tmp_path),
                                                   STALE_RECIPE=str(blend.parent / "recipe.json")), timeout=300)
    text = proc.stdout + proc.stderr
    assert proc.returncode == 0 and OK in proc.stdout, text[-4000:]
    got = {x.split(" ", 1)[0]: json.loads(x.split(" ", 1)[1]) for x in proc.stdout.splitlines()
           if x.split(" ", 1)[0] in ("PREPARED", "DISK", "LEFT", "NEED")}
    assert got["PREPARED"] == [got["NEED"]], text[-3000:]
    assert got["DISK"] == [got["NEED"]], text[-3000:]   # the fresh probe, and only it
    assert got["LEFT"] == [], text[-3000:]


ROOM = T.PRELUDE + r"""
import json, os
from libfx import aux_views, recipe
scene = bpy.context.scene
with open(os.environ["ROOM_RECIPE"], encoding="utf-8") as f:
    recipe.from_recipe(scene, f.read())   # final: a probe per entry, a planar view per flat one
views = aux_views.needed(scene)
mirrors = aux_views.stack_mirrors(scene, views)
pair = next(v for v in views if v["kind"] == "planar" and "Mirror_FacingA" in str(v["mask"]))
clear = next(v for v in views if v["kind"] == "probe" and "Mirror_Clear" in str(v["mask"]))
specs, _ = aux_views._view_specs(scene, pair, mirrors)
probes, _ = aux_views._view_specs(scene, clear, mirrors)
alone, _ = aux_views._view_specs(scene, clear)
print("ROOM " + json.dumps({"stack": mirrors, "planar": [s["mirrors"] for s in specs],
                            "probe": [s["mirrors"] for s in probes], "alone": [s["mirrors"] for s in alone]}))
print("LIBFX-TEST-OK")
"""


def test_views_show_every_mirror_of_the_stack(blender, library):
    """The mirror room at final: the pair's planar views and the clear mirror's probe show
    every mirror entry's objects as perfect mirrors (aux_views.stack_mirrors; how they
    render is test_probe_view's), not only their own entry's."""
    blend = T.SCENES_DIR / "mirror_room" / "mirror_room.blend"
    proc = T.run_blender([], blend=str(blend), python_expr=ROOM,
                         env=dict(T.addon_env(library), ROOM_RECIPE=str(blend.parent / "recipe.json")), timeout=300)
    text = proc.stdout + proc.stderr
    assert proc.returncode == 0 and OK in proc.stdout, text[-4000:]
    got = json.loads(next(x for x in proc.stdout.splitlines() if x.startswith("ROOM "))[len("ROOM "):])
    want = ["Mirror_BentIn", "Mirror_BentOut", "Mirror_Blurred", "Mirror_Cel", "Mirror_Clear", "Mirror_FacingA",
            "Mirror_FacingB", "Mirror_Fresnel", "Mirror_Grayscale", "Mirror_Low", "Mirror_Sepia"]
    assert got["stack"] == want, got["stack"]
    assert got["planar"] == [want, want] and got["probe"] == [want], got
    assert got["alone"] == [["Mirror_Clear"]], got["alone"]
