"""tests/bench/bench_all.py's plumbing (no measurement): entry labels of method variants
("god_rays:volumetric"), the scenes' plans with them, and --merge of a subset run into the
docs CSV (the named entries' rows replaced, every other row kept in its place)."""
import importlib.util
import json
import pathlib

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("bench_all", REPO / "tests" / "bench" / "bench_all.py")
B = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(B)


def row(kind, effect, setting="quality=final", w=1920, h=1080, threads=2, ms="1.000", note=""):
    return B.as_text(dict(kind=kind, scene="greek_bath", effect=effect, setting=setting, width=w, height=h,
                          threads=threads, runs=3, ms_median=ms, note=note))


def test_labels():
    assert B.split_label("god_rays:volumetric") == ("god_rays", "volumetric")
    assert B.split_label("god_rays") == ("god_rays", None)
    for bad in ("", ":volumetric", "god_rays:", "a:b:c"):
        with pytest.raises(ValueError):
            B.split_label(bad)
    assert ":" not in B.label_slug("voronoi_caustics:refractive")


def test_the_bath_plan_holds_the_variants_as_their_own_entries():
    render, benches, labels = B.scene_plan("greek_bath")
    # each variant right after its effect
    assert labels.index("god_rays:volumetric") == labels.index("god_rays") + 1
    assert labels.index("voronoi_caustics:refractive") == labels.index("voronoi_caustics") + 1
    vol = benches["god_rays:volumetric"]["effects"]
    assert [e["effect"] for e in vol] == ["god_rays"] and vol[0]["params"]["method"] == "volumetric"
    assert vol[0]["params"]["light"] == "Sun"  # the recipe's entry under the variant's params
    assert all(e["params"].get("method", "polar") != "volumetric"
               for e in benches["god_rays"]["effects"] if e["effect"] == "god_rays")
    refr = benches["voronoi_caustics:refractive"]["effects"]
    assert [e["effect"] for e in refr] == ["voronoi_caustics"]
    assert refr[0]["params"]["mode"] == "refractive" and refr[0]["mask"] == {"material": "Water"}
    # the render holds both methods' entries: their passes and aux views (light:Sun, water:Water)
    modes = {(e["effect"], e["params"].get("method") or e["params"].get("mode")) for e in render["effects"]}
    assert {("god_rays", "volumetric"), ("god_rays", None), ("voronoi_caustics", "refractive"),
            ("voronoi_caustics", "physical")} <= modes


def test_only_effects_selects_entries_and_names_the_known_ones():
    plan = {sc: B.scene_plan(sc)[2] for sc in B.SCENES}
    sel = B.select_plan(plan, ["god_rays:volumetric", "ssr_mirror"])
    assert sel == {"greek_bath": ["god_rays:volumetric"], "atrium": [], "mirror_room": ["ssr_mirror"]}
    with pytest.raises(SystemExit, match="no entry god_rays:foo.*god_rays:volumetric"):
        B.select_plan(plan, ["god_rays:foo"])


def test_merge_needs_docs_and_a_subset_with_docs_needs_merge():
    only = ["--only-effects", "god_rays:volumetric"]
    for argv in (["--docs"] + only, ["--merge"] + only, ["--docs", "--merge", "--quick"] + only,
                 ["--only-effects", "god_rays:"]):
        with pytest.raises(SystemExit):
            B.parse_args(argv)
    a = B.parse_args(["--docs", "--merge"] + only)
    assert a.only == ["god_rays:volumetric"] and "peers" in a.skip_stages
    assert B.cycles_effects(a) == []
    assert B.cycles_effects(B.parse_args(["--only-effects", "vsm_shadows"])) == ["vsm_shadows"]


def old_csv():
    return [row("reference", "god_rays", "quality=reference", 1280, 720),
            row("effect", "god_rays", w=1280, h=720, ms="18.0"),
            row("floor", "god_rays", "memcpy", 1280, 720),
            row("effect", "pixelate", w=1280, h=720),
            row("reference", "god_rays", "quality=reference"),
            row("effect", "god_rays", ms="41.0"),
            row("effect", "god_rays", "polar_resolution=1", ms="88.0"),
            row("effect", "pixelate"),
            row("scaling_res", "god_rays", "mp=1"),
            row("scaling_res", "pixelate", "mp=1"),
            row("first_frame", "(empty stack)"),
            row("first_frame", "god_rays", note="warm 45.2 ms (frames 2-4, median); first / warm 1.02x"),
            row("first_frame", "pixelate"),
            row("peer", "god_rays", "blender Sun Beams"),
            row("io", "read+write", "read")]


def test_merge_replaces_the_named_entries_kinds_and_keeps_every_other_row_in_place():
    old = old_csv()
    new = [row("reference", "god_rays", "quality=reference", 1280, 720, ms="900"),
           row("effect", "god_rays", w=1280, h=720, ms="17.0"),
           row("reference", "god_rays", "quality=reference", ms="2000"),
           row("effect", "god_rays", ms="40.0"),
           row("reference", "god_rays:volumetric", "quality=reference", ms="5000"),
           row("effect", "god_rays:volumetric", ms="110"),
           row("reference", "god_rays:volumetric", "quality=reference", 1280, 720, ms="2500"),
           row("first_frame", "god_rays:volumetric")]
    merged = B.merge_rows(old, new)
    gone = {("god_rays", "effect"), ("god_rays", "reference"), ("god_rays:volumetric", "effect"),
            ("god_rays:volumetric", "reference"), ("god_rays:volumetric", "first_frame")}
    assert B.replaced_pairs(new) == gone
    kept = [r for r in old if (r["effect"], r["kind"]) not in gone]
    # every other row kept, in its order: god_rays' floor, scaling, first-frame and peer rows too
    # (kinds this run did not measure), and every other entry's
    assert [r for r in merged if r in kept] == kept and len(kept) == 10
    assert all(r in merged for r in new) and len(merged) == len(kept) + len(new)
    # every row of a replaced pair goes, its knob rows too (the new run made that kind again)
    assert not any(r["ms_median"] in ("18.0", "41.0", "88.0") for r in merged), "replaced rows remain"
    keys = [(r["kind"], r["effect"], r["width"], r["ms_median"]) for r in merged]
    # replaced rows where the first old one of their block was; the variant (new to the CSV)
    # after the last row of its block
    assert keys[:5] == [("reference", "god_rays", "1280", "900"), ("effect", "god_rays", "1280", "17.0"),
                        ("reference", "god_rays:volumetric", "1280", "2500"),
                        ("floor", "god_rays", "1280", "1.000"), ("effect", "pixelate", "1280", "1.000")]
    at = keys.index(("reference", "god_rays", "1920", "2000"))
    assert keys[at:at + 5] == [("reference", "god_rays", "1920", "2000"), ("effect", "god_rays", "1920", "40.0"),
                               ("reference", "god_rays:volumetric", "1920", "5000"),
                               ("effect", "god_rays:volumetric", "1920", "110"),
                               ("effect", "pixelate", "1920", "1.000")]
    ff = [r["effect"] for r in merged if r["kind"] == "first_frame"]
    assert ff == ["(empty stack)", "god_rays", "pixelate", "god_rays:volumetric"]
    assert merged[-2:] == old[-2:]  # peers and io untouched
    # a CSV without the new rows' blocks gets them at the end
    m = B.merge_rows([row("peer", "x")], new)
    assert m[0]["effect"] == "x" and len(m) == 1 + len(new) and all(r in m for r in new)


def test_merge_of_the_same_run_twice_is_the_same_csv():
    old = old_csv()
    new = [row("effect", "god_rays", ms="40.0"), row("first_frame", "god_rays:volumetric")]
    once = B.merge_rows(old, new)
    assert B.merge_rows(once, new) == once


def test_runs_after_a_merge():
    base = dict(B.unknown_run(), command="whole run")
    a = dict(B.unknown_run(), rows=[["god_rays:volumetric", "effect"], ["god_rays:volumetric", "first_frame"]],
             command="merge 1")
    b = dict(B.unknown_run(), rows=[["voronoi_caustics:refractive", "effect"]], command="merge 2")
    c = dict(B.unknown_run(), rows=[["god_rays:volumetric", "effect"], ["voronoi_caustics:refractive", "effect"]],
             command="merge 3")
    runs = B.merge_runs([base, a, b], c)
    assert [r["command"] for r in runs] == ["whole run", "merge 1", "merge 3"]
    assert runs[1]["rows"] == [["god_rays:volumetric", "first_frame"]]
    md = "\n".join(B.merged_runs_md(runs[1:]))
    assert "`god_rays:volumetric` (first_frame)" in md and "merge 3" in md
    json.dumps(runs)  # the runs file


def test_report_lists_variants_after_their_effect_and_names_their_plots():
    rows = [row("effect", "god_rays"), row("effect", "pixelate"), row("effect", "god_rays:volumetric")]
    assert B.entry_labels(["god_rays", "pixelate"], rows) == ["god_rays", "god_rays:volumetric", "pixelate"]
    md = "\n".join(B.effect_tables(rows, ["god_rays", "god_rays:volumetric"], {}))
    assert "#### god_rays:volumetric" in md and '"method": "volumetric"' in md
    assert B.peer_rows_of(old_csv()) == old_csv()[-2:]
