"""The effect reference pages (docs/effects/<effect>.md) agree with the library.

The parameter tables, presets, passes and halo in the pages are generated from
`libfx describe` by scripts/gen_effect_docs.py; this test fails when the library changed
(a parameter added, a default or range moved, a doc string edited) and the pages were not
regenerated, when an effect has no page or no image, and when the docs index misses a page.
The bench block comes from docs/bench/bench_all.csv when that file exists; the check
passes with and without it (fresh clones included).
"""
import csv
import json
import math
import pathlib
import re
import shutil
import struct
import subprocess
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
GEN = REPO / "scripts" / "gen_effect_docs.py"
PAGES = REPO / "docs" / "effects"
PY = sys.executable


@pytest.fixture(scope="module")
def effects(cli):
    out = subprocess.run([cli, "list"], check=True, capture_output=True, text=True).stdout
    names = [line.split("\t")[0] for line in out.splitlines() if line.strip()]
    assert len(names) >= 10, out
    return {n: json.loads(subprocess.run([cli, "describe", "--compact", n], check=True,
                                         capture_output=True, text=True).stdout)
            for n in names}


def gen(cli, *args):
    return subprocess.run([PY, str(GEN), "--cli", cli, *map(str, args)],
                          capture_output=True, text=True, timeout=120)


def block(text, name):
    m = re.search(rf"<!-- generated:{name} begin -->(.*?)<!-- generated:{name} end -->",
                  text, re.S)
    return m.group(1) if m else None


def f32(v):
    return struct.unpack("f", struct.pack("f", float(v)))[0]


def same_number(shown, value):
    """A number as the page prints it equals the library's (float params are float32)."""
    got = float(shown)
    if isinstance(value, bool) or isinstance(value, int):
        return got == value
    try:
        return f32(got) == f32(value)
    except OverflowError:
        return math.isclose(got, value, rel_tol=1e-9)


def param_rows(page_text):
    """{name: (type, default, range)} from the generated parameter table."""
    rows = {}
    for line in (block(page_text, "params") or "").splitlines():
        m = re.match(r"\| `([^`]+)` \| ([^|]*) \| ([^|]*) \| ([^|]*) \|", line)
        if m:
            rows[m.group(1)] = tuple(c.strip() for c in m.group(2, 3, 4))
    return rows


def test_every_effect_has_a_page_with_the_blocks(effects):
    for name in effects:
        page = PAGES / f"{name}.md"
        assert page.is_file(), f"{name} has no page {page} (run scripts/gen_effect_docs.py)"
        text = page.read_text()
        assert text.startswith(f"# {name}"), f"{page}: the title should name {name}"
        for b in ("params", "image", "bench"):
            assert block(text, b) is not None, f"{page}: no generated:{b} block"
        # params first, right after the intro; the hand-written prose follows
        assert text.index("generated:params begin") < text.index("generated:image begin") \
            < text.index("generated:bench begin")
        assert not re.search(r"^\| parameter \|", text.replace(block(text, "params"), ""),
                             re.M), f"{page}: a hand-written parameter table is left"


def test_generated_pages_are_current(cli):
    """The committed pages are what the generator writes for this library and this CSV
    state (a parameter added without regenerating the docs fails here)."""
    r = gen(cli, "--check")
    assert r.returncode == 0, r.stdout + r.stderr


def test_check_catches_a_stale_page_and_regenerating_fixes_it(cli, tmp_path):
    docs = tmp_path / "effects"
    shutil.copytree(PAGES, docs)
    # the committed pages were generated from the committed CSV (or none): the same state here
    committed_csv = REPO / "docs" / "bench" / "bench_all.csv"
    csv_state = committed_csv if committed_csv.exists() else tmp_path / "absent.csv"
    page = docs / "gaussian_blur.md"
    text = page.read_text()
    # what a library change without regeneration looks like: the table disagrees
    page.write_text(text.replace("| `sigma` | float, pixels | 5 |",
                                 "| `sigma` | float, pixels | 4 |"))
    r = gen(cli, "--check", "--docs", docs, "--bench-csv", csv_state)
    assert r.returncode == 1 and "gaussian_blur.md" in r.stderr, r.stdout + r.stderr
    (docs / "posterize.md").unlink()
    r = gen(cli, "--check", "--docs", docs, "--bench-csv", csv_state)
    assert r.returncode == 1 and "posterize.md: missing" in r.stderr, r.stderr
    assert not (docs / "posterize.md").exists(), "--check must not write"
    r = gen(cli, "--docs", docs, "--bench-csv", csv_state)
    assert r.returncode == 0, r.stderr
    assert page.read_text() == text, "regenerating must restore the committed page"
    assert "generated:params begin" in (docs / "posterize.md").read_text()
    assert gen(cli, "--check", "--docs", docs, "--bench-csv", csv_state).returncode == 0


def write_bench_csv(path, effect):
    fields = ["kind", "scene", "effect", "setting", "width", "height", "threads", "runs",
              "ms_median", "mae", "max_err", "psnr_db", "mask_px", "note"]
    rows = [
        ["effect", "synthetic", effect, "quality=final", 1920, 1080, 1, 5, 38.5, 5.3e-5,
         1.2e-3, 72.1, "", ""],
        ["effect", "synthetic", effect, "quality=final", 1920, 1080, 2, 5, 20.25, 5.3e-5,
         1.2e-3, 72.1, "", ""],
        ["reference", "synthetic", effect, "quality=reference", 1920, 1080, 2, 3, 640, "",
         "", "", "", "the reference"],
        ["effect", "synthetic", effect, "quality=final", 1280, 720, 2, 5, 9.1, "", "", "",
         "", "not at 1080p: left out"],
        ["peer", "synthetic", effect, "opencv GaussianBlur 51x51", 1920, 1080, 2, 5, 64.0,
         "", "", "", "", ""],
        ["cycles", "atrium", effect, "quality=final", 640, 360, 2, 1, 40, 0.011, 0.3, 31.2,
         "", "direct only"],
        ["io", "atrium", "", "read", 1920, 1080, 2, 5, 190, "", "", "", "", ""],
    ]
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(fields)
        w.writerows(rows)


def test_bench_block_with_and_without_the_csv(cli, tmp_path):
    """The check depends on the CSV only through the bench block: pages generated from a
    CSV pass the check with that CSV and without any CSV; a changed CSV makes them stale."""
    docs = tmp_path / "effects"
    shutil.copytree(PAGES, docs)
    bench = tmp_path / "bench_all.csv"
    write_bench_csv(bench, "gaussian_blur")
    assert gen(cli, "--docs", docs, "--bench-csv", bench).returncode == 0
    text = (docs / "gaussian_blur.md").read_text()
    b = block(text, "bench")
    assert "| synthetic | `quality=final` | 1920x1080 | 38.5 | 20.2 |" in b, b
    assert "`quality=reference` (reference)" in b and "640 |" in b
    assert "opencv GaussianBlur 51x51" in b and "direct only" in b
    assert "not at 1080p" not in b and "| read |" not in b
    assert "../performance.md" in b
    # another effect without rows keeps the note naming the one command
    assert "tests/bench/bench_all.py" in block((docs / "bloom.md").read_text(), "bench")
    assert gen(cli, "--check", "--docs", docs, "--bench-csv", bench).returncode == 0
    assert gen(cli, "--check", "--docs", docs, "--bench-csv",
               tmp_path / "absent.csv").returncode == 0
    bench.write_text(bench.read_text().replace("38.5", "41.0"))
    r = gen(cli, "--check", "--docs", docs, "--bench-csv", bench)
    assert r.returncode == 1 and "gaussian_blur.md: stale (bench)" in r.stderr, r.stderr
    # a page without its bench markers is stale even without a CSV
    page = docs / "bloom.md"
    page.write_text(re.sub(r"<!-- generated:bench begin -->.*?<!-- generated:bench end -->",
                           "", page.read_text(), flags=re.S))
    r = gen(cli, "--check", "--docs", docs, "--bench-csv", tmp_path / "absent.csv")
    assert r.returncode == 1 and "bloom.md" in r.stderr, r.stderr


def test_bench_block_variants_and_first_frames(cli, tmp_path):
    """A method variant's rows (CSV entry "effect:variant", bench_all's VARIANTS) get their
    own table, titled by the parameter that selects the variant, never mixed into the
    effect's; the first frames of the effect and of its variants are shown."""
    docs = tmp_path / "effects"
    shutil.copytree(PAGES, docs)
    bench = tmp_path / "bench_all.csv"
    write_bench_csv(bench, "gaussian_blur")
    with open(bench, "a", newline="") as f:
        w = csv.writer(f)
        w.writerow(["effect", "bath", "gaussian_blur:box", "quality=draft", 1920, 1080, 2, 5, 7.25,
                    2e-3, 0.1, 50.5, "", "variant row"])
        w.writerow(["reference", "bath", "gaussian_blur:box", "quality=reference", 1920, 1080, 2, 5,
                    333, "", "", "", "", ""])
        w.writerow(["first_frame", "bath", "gaussian_blur", "quality=final", 1920, 1080, 2, 3, 45.9,
                    "", "", "", "", "warm 45.2 ms (frames 2-4, median); first / warm 1.02x"])
        w.writerow(["first_frame", "bath", "gaussian_blur:box", "quality=final", 1920, 1080, 2, 3,
                    12.99, "", "", "", "", "warm 11.0 ms (frames 2-4, median); first / warm 1.18x"])
        w.writerow(["effect", "atrium", "rain_splashes:other", "quality=final", 1920, 1080, 2, 5, 3.5,
                    "", "", "", "", "not rain's"])
    assert gen(cli, "--docs", docs, "--bench-csv", bench).returncode == 0
    b = block((docs / "gaussian_blur.md").read_text(), "bench")
    main, rest = b.split("Variant `algorithm: box` (CSV entry `gaussian_blur:box`", 1)
    assert "| synthetic | `quality=final` | 1920x1080 | 38.5 | 20.2 |" in main
    assert "variant row" not in main and "333" not in main
    variant, first = rest.split("First frame of a process", 1)
    assert "| bath | `quality=draft` | 1920x1080 | 7.25 |" in variant and "variant row" in variant
    assert "`quality=reference` (reference) | 1920x1080 | 333 |" in variant
    assert "| `gaussian_blur` | bath | 1920x1080 | 45.9 | 45.2 | 1.02x | 3 |" in first
    assert "| `gaussian_blur:box` | bath | 1920x1080 | 13.0 | 11.0 | 1.18x | 3 |" in first
    # rain_splashes' variant is not rain's (nor its name's beginning)
    assert "not rain's" in block((docs / "rain_splashes.md").read_text(), "bench")
    assert "not rain's" not in block((docs / "rain.md").read_text(), "bench")
    assert gen(cli, "--check", "--docs", docs, "--bench-csv", bench).returncode == 0


def test_defaults_and_ranges_in_the_pages_are_the_librarys(effects):
    checked = 0
    for name, d in effects.items():
        rows = param_rows((PAGES / f"{name}.md").read_text())
        assert list(rows) == [p["name"] for p in d["params"]], \
            f"{name}: the page's parameters differ from `libfx describe {name}`"
        for p in d["params"]:
            typ, default, rng = rows[p["name"]]
            where = f"{name}.{p['name']}"
            assert typ.split(",")[0].split(" ")[0] in (p["type"], "RGB", "RGBA", "4x4",
                                                       str(p.get("count"))), where
            if p["type"] in ("float", "int"):
                assert same_number(default, p["default"]), f"{where}: default {default}"
                m = re.fullmatch(r"(\S+) … (\S+)(?: \(soft (\S+) … (\S+)\))?", rng)
                assert m, f"{where}: range cell {rng!r}"
                assert same_number(m.group(1), p["min"]) and \
                    same_number(m.group(2), p["max"]), f"{where}: range {rng}"
                soft = (m.group(3), m.group(4)) if m.group(3) else (m.group(1), m.group(2))
                assert same_number(soft[0], p["soft_min"]) and \
                    same_number(soft[1], p["soft_max"]), f"{where}: soft range {rng}"
                checked += 1
            elif p["type"] == "enum":
                assert default == f"`{p['default']}`", where
                assert re.findall(r"`([^`]+)`", rng) == p["items"], where
            elif p["type"] == "bool":
                assert default == ("`true`" if p["default"] else "`false`"), where
            elif p["type"] == "floats" and default != "identity":
                vals = [v.strip() for v in default.split(",")]
                assert len(vals) == len(p["default"]) and all(
                    same_number(a, b) for a, b in zip(vals, p["default"])), where
            elif p["type"] == "string":
                assert (f'`"{p["default"]}"`' in default) if p["default"] else \
                    default.startswith('`""`'), where
    assert checked > 50


def test_presets_passes_and_halo_are_the_librarys(effects):
    for name, d in effects.items():
        params = block((PAGES / f"{name}.md").read_text(), "params")
        for preset, values in (d.get("presets") or {}).items():
            row = next((l for l in params.splitlines() if l.startswith(f"| {preset} |")), None)
            assert row is not None, f"{name}: preset {preset} missing"
            for k in values:
                assert f"`{k}`" in params, f"{name}: preset {preset} sets {k}"
        passes = re.search(r"\*\*Passes\*\* with the defaults: ([^;]*);", params)
        assert passes and re.findall(r"`([^`]+)`", passes.group(1)) == d["passes"], name
        assert f"**Halo**: {d['halo']} px" in params, name
        assert d["doc"].split()[0] in params


def test_every_page_shows_an_image_that_exists(effects):
    for name in effects:
        text = (PAGES / f"{name}.md").read_text()
        images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", block(text, "image") or "")
        assert images, f"{name}: no image in the generated:image block"
        for rel in images:
            path = (PAGES / rel).resolve()
            assert path.is_file(), f"{name}: {rel} does not exist"
            assert path.stat().st_size <= 150 * 1024, f"{rel}: over 150 KB"
        assert "scripts/effect_gallery.py" in block(text, "image"), name


def test_docs_index_links_every_effect_page(effects):
    index = (REPO / "docs" / "index.md").read_text()
    linked = set(re.findall(r"\]\(effects/([a-z0-9_]+)\.md\)", index))
    missing = sorted(set(effects) - linked)
    assert not missing, f"docs/index.md does not link {missing}"
    for name in linked:
        assert (PAGES / f"{name}.md").is_file(), f"docs/index.md links a missing page {name}"
