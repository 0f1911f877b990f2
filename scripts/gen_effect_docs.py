#!/usr/bin/python3
"""Keeps the generated parts of docs/effects/<effect>.md in step with the library.

    /usr/bin/python3 scripts/gen_effect_docs.py [--cli PATH] [--check]
                                               [--docs DIR] [--bench-csv FILE]

The effects describe themselves (GUIDE §1): `libfx list` names them and `libfx describe
EFFECT` gives the one-line doc, the parameter table (type, default, hard and soft range,
enum items, doc string, hint), the quality presets, the passes it needs with its defaults
and its halo. For every listed effect this script rewrites three blocks of its page and
leaves everything outside them (the hand-written prose) alone:

  <!-- generated:params begin/end -->  one-line doc, parameters, presets, passes, halo
  <!-- generated:image begin/end -->   the before|after image of scripts/effect_gallery.py
  <!-- generated:bench begin/end -->   time and error from docs/bench/bench_all.csv
                                       (written by tests/bench/bench_all.py), or a note
                                       naming that command when the file has no rows

The bench block shows the effect's rows at 1920x1080, then each method variant's (CSV
entry "effect:variant", e.g. god_rays:volumetric: its own presets against its own
reference) in its own table titled by the parameter that selects it (`method: volumetric`),
then the first frame of a process of the effect and of each variant, the peers and the
Cycles rows.

A page that does not exist is created with a title and the blocks; a page that lacks a
block gets it (params and image after the first paragraph, bench at the end).

--check writes nothing: it lists the stale or missing pages and exits 1. The bench block
is compared with what the CSV in the tree gives when that file exists, and only for its
markers when it does not (a fresh clone without measurements still passes; measurements
committed without regenerating the pages do not).

Standard library only. The CLI is --cli, else $LIBFX_CLI, else build/libfx/libfx.
"""
import argparse
import csv
import json
import os
import pathlib
import re
import struct
import subprocess
import sys

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import effect_gallery  # noqa: E402  (stdlib at import time; GALLERY and the captions)

BLOCKS = ("params", "image", "bench")
PRESETS = ("draft", "preview", "final", "reference")
BENCH_COMMAND = "/usr/bin/python3 tests/bench/bench_all.py"
GEN_COMMAND = "/usr/bin/python3 scripts/gen_effect_docs.py"
CSV_FIELDS = ["kind", "scene", "effect", "setting", "width", "height", "threads", "runs",
              "ms_median", "mae", "max_err", "psnr_db", "mask_px", "note"]


def begin(name):
    return f"<!-- generated:{name} begin -->"


def end(name):
    return f"<!-- generated:{name} end -->"


# ---- formatting ------------------------------------------------------------------------

def num(v):
    """Shortest decimal that gives the same float32 (the library stores float params as
    float; describe prints the double of that float: 0.300000011920929 is 0.3)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    v = float(v)
    if v != v:
        return "nan"
    if v in (float("inf"), float("-inf")):
        return "inf" if v > 0 else "-inf"
    if v == int(v) and abs(v) < 1e7:
        return str(int(v))
    s = repr(v)
    try:
        f32 = struct.unpack("f", struct.pack("f", v))[0]
    except OverflowError:  # beyond float32: a double bound, print it as it is
        f32 = None
    if f32 is not None:
        for digits in range(1, 10):
            cand = f"{v:.{digits}g}"
            if struct.unpack("f", struct.pack("f", float(cand)))[0] == f32:
                s = cand
                break
    return s.replace("e+", "e").replace("e-0", "e-")


def md(text):
    """A library doc string as one Markdown table cell."""
    text = " ".join(str(text).split())
    return text.replace("\\", "\\\\").replace("|", "\\|").replace("*", "\\*") \
               .replace("<", "&lt;").replace(">", "&gt;")


def type_cell(p):
    t, hint = p["type"], p.get("hint") or ""
    if t == "floats":
        n = p.get("count", 0)
        if hint == "color":
            s = {3: "RGB colour", 4: "RGBA colour"}.get(n, f"{n} floats, colour")
        elif hint == "matrix4":
            s = "4x4 matrix (16 floats)"
        else:
            s = f"{n} floats"
        return s
    if t == "string" and hint == "mask":
        return "string, mask (a JSON object as an entry's `mask` takes)"
    return f"{t}, {hint}" if hint else t


def default_cell(p):
    d = p["default"]
    t = p["type"]
    if t == "enum":
        return f"`{d}`"
    if t == "string":
        return f'`"{d}"`' if d else "`\"\"` (none)"
    if t == "bool":
        return "`true`" if d else "`false`"
    if t == "floats":
        if p.get("hint") == "matrix4" and [float(x) for x in d] == \
                [1.0 if i % 5 == 0 else 0.0 for i in range(16)]:
            return "identity"
        return ", ".join(num(x) for x in d)
    return num(d)


def range_cell(p):
    t = p["type"]
    if t == "enum":
        return ", ".join(f"`{i}`" for i in p.get("items", []))
    if "min" not in p or "max" not in p:
        return ""
    s = f"{num(p['min'])} … {num(p['max'])}"
    if t == "floats":
        s += " each"
    if "soft_min" in p and (p["soft_min"], p["soft_max"]) != (p["min"], p["max"]):
        s += f" (soft {num(p['soft_min'])} … {num(p['soft_max'])})"
    return s


def preset_value(p, v):
    if p is None:
        return f"`{json.dumps(v)}`"
    if p["type"] == "enum":
        return f"`{v}`"
    if p["type"] == "bool":
        return "`true`" if v else "`false`"
    if isinstance(v, list):
        return ", ".join(num(x) for x in v)
    return num(v)


# ---- the blocks ------------------------------------------------------------------------

def params_block(d):
    name = d["name"]
    out = [begin("params"),
           f"<!-- from `libfx describe {name}` by scripts/gen_effect_docs.py: edit the doc "
           f"strings in libfx/src/effects/{name}.c, not here -->",
           "",
           f"> {md(d['doc'])}",
           "",
           "| parameter | type | default | range | meaning |",
           "|---|---|---|---|---|"]
    for p in d["params"]:
        out.append(f"| `{p['name']}` | {type_cell(p)} | {default_cell(p)} | {range_cell(p)} "
                   f"| {md(p.get('doc', ''))} |")
    out.append("")
    presets = {k: v for k, v in (d.get("presets") or {}).items() if v is not None}
    if presets:
        by_name = {p["name"]: p for p in d["params"]}
        keys = []
        for q in PRESETS + tuple(k for k in presets if k not in PRESETS):
            for k in presets.get(q, {}):
                if k not in keys:
                    keys.append(k)
        out.append("**Quality presets** (the recipe's `quality`, or `--quality`; a value "
                   "given in `params` always wins; – keeps the default):")
        out.append("")
        out.append("| preset | " + " | ".join(f"`{k}`" for k in keys) + " |")
        out.append("|---|" + "---|" * len(keys))
        for q in PRESETS + tuple(k for k in presets if k not in PRESETS):
            if q not in presets:
                continue
            cells = [preset_value(by_name.get(k), presets[q][k]) if k in presets[q] else "–"
                     for k in keys]
            out.append(f"| {q} | " + " | ".join(cells) + " |")
        missing = [q for q in PRESETS if q not in presets]
        if missing:
            out.append("")
            out.append(f"Presets {', '.join(f'`{q}`' for q in missing)} set nothing here "
                       "(the defaults).")
    else:
        out.append("**Quality presets**: none (nothing here trades time for accuracy; "
                   "every preset gives the defaults).")
    out.append("")
    passes = ", ".join(f"`{x}`" for x in d.get("passes", []))
    cam = ("yes (the scene sidecar: `--sidecar`, written by the add-on)"
           if d.get("needs_camera") else "no")
    out.append(f"**Passes** with the defaults: {passes}; camera needed: {cam}. "
               f"Other parameter values may need other passes (`libfx passes --stack "
               f"recipe.json`).")
    out.append("")
    out.append(f"**Halo**: {d.get('halo', 0)} px (the border a masked region reads around "
               f"itself, for the defaults at 1920x1080).")
    out.append(end("params"))
    return "\n".join(out)


def image_block(name):
    out = [begin("image")]
    if name in effect_gallery.GALLERY:
        out += [f"![{name}: before | after](../images/effect_{name}.jpg)",
                "",
                f"*{effect_gallery.caption(name)}*"]
    else:
        out.append(f"No gallery image: add `{name}` to GALLERY in scripts/effect_gallery.py.")
    out.append(end("image"))
    return "\n".join(out)


def read_bench(path):
    """The rows of bench_all.csv, or None when the file is absent."""
    if path is None or not path.is_file():
        return None
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = [c for c in CSV_FIELDS if c not in (reader.fieldnames or [])]
        if missing:
            raise SystemExit(f"gen_effect_docs: {path}: columns {', '.join(missing)} missing "
                             f"(header must be {','.join(CSV_FIELDS)})")
        return [dict(r) for r in reader]


def fnum(s, kind):
    s = (s or "").strip()
    if not s:
        return ""
    try:
        v = float(s)
    except ValueError:
        return md(s)
    if v != v:
        return ""
    if kind == "ms":
        return f"{v:.0f}" if v >= 100 else f"{v:.1f}" if v >= 10 else f"{v:.2f}"
    if kind == "db":
        return "∞" if v == float("inf") else f"{v:.1f}"
    if v == 0:
        return "0"
    if 0.01 <= abs(v) < 1000:
        return f"{v:.2g}"
    return f"{v:.1e}".replace("e-0", "e-").replace("e+0", "e").replace("e+", "e")


def pivot(rows, label):
    """Rows grouped by (scene, setting, size); one ms column per thread count."""
    threads = sorted({int(r["threads"]) for r in rows if r["threads"].strip().isdigit()})
    groups = {}
    for r in rows:
        key = (r["kind"], r["scene"], r["setting"], r["width"], r["height"])
        groups.setdefault(key, []).append(r)
    head = ["scene", label, "size"] + [f"ms, {t} thread{'s' if t != 1 else ''}"
                                       for t in threads] + ["MAE", "max err", "PSNR dB", "note"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * 3 + "---:|" * (len(threads) + 3)
           + "---|"]
    for (kind, scene, setting, w, h), rs in groups.items():
        by_t = {}
        for r in rs:
            by_t.setdefault(r["threads"].strip(), fnum(r["ms_median"], "ms"))

        def first(col):
            return next((r[col] for r in rs if (r[col] or "").strip()), "")

        notes = []
        for r in rs:
            n = (r["note"] or "").strip()
            if n and n not in notes:
                notes.append(n)
        tag = f" ({kind})" if kind in ("reference", "floor") else ""
        cells = [md(scene), (f"`{md(setting)}`" if setting else "") + tag, f"{w}x{h}"]
        cells += [by_t.get(str(t), "") for t in threads]
        cells += [fnum(first("mae"), "err"), fnum(first("max_err"), "err"),
                  fnum(first("psnr_db"), "db"), md("; ".join(notes))]
        out.append("| " + " | ".join(cells) + " |")
    return out


def variant_title(label, params):
    """"god_rays:volumetric" -> "`method: volumetric`": the enum parameter that has the
    variant as an item (the label's own words when none has)."""
    variant = label.split(":", 1)[1]
    for p in params or []:
        if p["type"] == "enum" and variant in p.get("items", []):
            return f"`{p['name']}: {variant}`"
    return f"`{md(variant)}`"


def main_rows(rows):
    """The presets' table rows: effect, reference and floor at 1920x1080, in that order."""
    out = [r for r in rows if r["kind"] in ("effect", "reference", "floor")
           and r["width"].strip() == "1920" and r["height"].strip() == "1080"]
    out.sort(key=lambda r: {"effect": 0, "reference": 1, "floor": 2}[r["kind"]])
    return out


def first_frame_table(rows):
    """bench_all's first_frame rows: frame 1 of a fresh `libfx run` against the later
    frames (its note: "warm W ms (frames 2-N, median); first / warm Rx; ...")."""
    out = ["| entry | scene | size | first frame ms | warm ms | first / warm | processes |",
           "|---|---|---|---:|---:|---:|---:|"]
    for r in rows:
        note = r["note"] or ""
        warm = re.match(r"warm ([0-9.]+) ms", note)
        ratio = re.search(r"first / warm ([0-9.]+x)", note)
        out.append(f"| `{md(r['effect'])}` | {md(r['scene'])} | {r['width']}x{r['height']} | "
                   f"{fnum(r['ms_median'], 'ms')} | {fnum(warm.group(1), 'ms') if warm else ''} | "
                   f"{ratio.group(1) if ratio else ''} | {r['runs']} |")
    return out


def bench_block(name, rows, params=None):
    out = [begin("bench"), "## Measured time and error", ""]
    mine = [r for r in (rows or []) if r["effect"].strip() == name]
    # method variants: their own entries (bench_all's VARIANTS), in the CSV's order
    variants = {}
    for r in rows or []:
        if r["effect"].strip().startswith(name + ":"):
            variants.setdefault(r["effect"].strip(), []).append(r)
    main = main_rows(mine)
    vmain = {label: main_rows(rs) for label, rs in variants.items()}
    vmain = {label: rs for label, rs in vmain.items() if rs}
    first = [r for r in mine if r["kind"] == "first_frame"] + \
        [r for rs in variants.values() for r in rs if r["kind"] == "first_frame"]
    peers = [r for r in mine if r["kind"] == "peer"]
    cycles = [r for r in mine if r["kind"] == "cycles"]
    if not (main or vmain or first or peers or cycles):
        out.append(f"Not measured yet: the table comes from `{BENCH_COMMAND}` (it writes "
                   f"docs/bench/bench_all.csv; then `{GEN_COMMAND}`). How we measure: "
                   f"[performance.md](../performance.md).")
    else:
        out.append(f"From docs/bench/bench_all.csv (`{BENCH_COMMAND}`): median ms of the "
                   f"runs; errors (MAE, max, PSNR; values in [0, 1], empty: not measured) "
                   f"against the effect's `reference` setting, or against Cycles in the last "
                   f"table; the method, the machine and the other effects are in "
                   f"[performance.md](../performance.md).")
        if main:
            out += ["", "At 1920x1080 (floor: a memcpy of the same bytes, the bandwidth bound):",
                    ""]
            out += pivot(main, "setting")
        for label, rs in vmain.items():
            out += ["", f"Variant {variant_title(label, params)} (CSV entry `{md(label)}`: its "
                        f"own presets against its own `reference`; its params in "
                        f"[performance.md](../performance.md)), at 1920x1080:", ""]
            out += pivot(rs, "setting")
        if first:
            out += ["", "First frame of a process (`libfx run -v`, 2 threads, `final`: frame 1 "
                        "against the later frames of the same process, medians over fresh "
                        "processes):", ""]
            out += first_frame_table(first)
        if peers:
            out += ["", "Peers (other tools doing the nearest job):", ""]
            out += pivot(peers, "peer")
        if cycles:
            out += ["", "Against a Cycles render of what the effect imitates (the truth Blender can render):", ""]
            out += pivot(cycles, "setting")
    out.append(end("bench"))
    return "\n".join(out)


# ---- pages -----------------------------------------------------------------------------

BLOCK_RE = {b: re.compile(re.escape(begin(b)) + r".*?" + re.escape(end(b)), re.S)
            for b in BLOCKS}


def split_intro(text):
    """Index after the title and the first paragraph (where params and image go)."""
    m = re.match(r"(#[^\n]*\n+)", text)
    pos = m.end() if m else 0
    para = re.compile(r"\n\s*\n").search(text, pos)
    return para.end() if para else len(text)


def render_page(name, d, text, rows):
    blocks = {"params": params_block(d), "image": image_block(name),
              "bench": bench_block(name, rows, d.get("params"))}
    if text is None:
        text = (f"# {name}\n\n{d['doc']}. Code: `libfx/src/effects/{name}.c`.\n\n")
    for b in BLOCKS:
        if BLOCK_RE[b].search(text):
            text = BLOCK_RE[b].sub(lambda _m, s=blocks[b]: s, text, count=1)
        elif b in ("params", "image"):
            at = split_intro(text)
            if b == "image" and BLOCK_RE["params"].search(text):
                at = BLOCK_RE["params"].search(text).end()
                text = text[:at] + "\n\n" + blocks[b] + text[at:]
            else:
                text = text[:at] + blocks[b] + "\n\n" + text[at:]
        else:
            text = text.rstrip("\n") + "\n\n" + blocks[b] + "\n"
    return text


def describe_all(cli):
    try:
        listed = subprocess.run([cli, "list"], check=True, capture_output=True, text=True)
    except (OSError, subprocess.CalledProcessError) as e:
        raise SystemExit(f"gen_effect_docs: cannot run `{cli} list`: {e} (build libfx, or "
                         f"give --cli / LIBFX_CLI)")
    names = [line.split("\t")[0] for line in listed.stdout.splitlines() if line.strip()]
    out = {}
    for n in names:
        p = subprocess.run([cli, "describe", "--compact", n], check=True, capture_output=True,
                           text=True)
        out[n] = json.loads(p.stdout)
    return out


def bench_markers_only(old, new):
    """old with its bench block replaced by new's: for --check without a CSV."""
    ob, nb = BLOCK_RE["bench"].search(old), BLOCK_RE["bench"].search(new)
    if not ob or not nb:
        return new
    return new[:nb.start()] + old[ob.start():ob.end()] + new[nb.end():]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cli", default=os.environ.get("LIBFX_CLI") or
                    str(REPO / "build" / "libfx" / "libfx"))
    ap.add_argument("--check", action="store_true",
                    help="write nothing; list stale pages and exit 1 if any")
    ap.add_argument("--docs", default=str(REPO / "docs" / "effects"),
                    help="the effect pages' folder (default docs/effects)")
    ap.add_argument("--bench-csv", default=str(REPO / "docs" / "bench" / "bench_all.csv"))
    a = ap.parse_args(argv)

    docs = pathlib.Path(a.docs)
    csv_path = pathlib.Path(a.bench_csv)
    rows = read_bench(csv_path)
    effects = describe_all(a.cli)
    stale = []
    for name, d in effects.items():
        page = docs / f"{name}.md"
        old = page.read_text() if page.is_file() else None
        new = render_page(name, d, old, rows)
        if a.check:
            if old is None:
                stale.append(f"{page}: missing")
                continue
            cmp = new
            if rows is None:
                if not BLOCK_RE["bench"].search(old):
                    stale.append(f"{page}: no generated:bench block")
                    continue
                cmp = bench_markers_only(old, new)
            if cmp != old:
                which = [b for b in BLOCKS
                         if (BLOCK_RE[b].search(old) or [None])[0] !=
                         (BLOCK_RE[b].search(cmp) or [None])[0]]
                stale.append(f"{page}: stale ({', '.join(which) or 'layout'})")
        elif new != old:
            docs.mkdir(parents=True, exist_ok=True)
            tmp = page.with_suffix(".md.tmp")
            tmp.write_text(new)
            os.replace(tmp, page)
            print(f"gen_effect_docs: wrote {page}")
    if a.check:
        if stale:
            print("gen_effect_docs: stale effect pages (run "
                  f"`{GEN_COMMAND}` and commit them):", file=sys.stderr)
            for s in stale:
                print(f"  {s}", file=sys.stderr)
            return 1
        print(f"gen_effect_docs: {len(effects)} effect pages up to date "
              f"({'bench from ' + str(csv_path) if rows is not None else 'no bench CSV: bench blocks checked for markers only'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
