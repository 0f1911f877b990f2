#!/usr/bin/python3
"""bench_peers: the peers (Blender's compositor nodes, oiiotool, OpenCV), plain EXR I/O and the
memcpy floor on one EXR, plus the peak memory of `libfx run` when it decodes only what the stack
needs vs every pass. A thin wrapper over bench_peers_all.run_peers (the one place for peer
timing; tests/bench/bench_all.py runs the same rows beside libfx's own).

Usage: /usr/bin/python3 tests/bench/bench_peers.py [--runs 5] [--out out/bench] [--exr E --sidecar S]
Default input: out/bench/allpasses_1080p.exr, the Greek bath at 1920x1080 with every pass
(Cycles, 1 sample; rendered when missing): a heavy file for the I/O and memory rows. It has no
sidecar, so there is no Sun Beams row unless --sidecar names one. Writes out/bench/peers.md and
peers.csv (bench_peers_all.SCHEMA). Medians of --runs runs; the machine's memory bandwidth
drifts between runs, so compare ratios within one run (docs/performance.md)."""
import argparse
import json
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_peers_all as peers  # noqa: E402


def peak_rss_mib(cmd):
    r = subprocess.run(["/usr/bin/time", "-f", "%M"] + cmd, check=True, capture_output=True, text=True)
    return int(r.stderr.strip().splitlines()[-1]) / 1024.0


def memory_rows(cli, src, out_dir):
    """Only the needed passes are decoded, unless --keep-passes asks for all."""
    info = json.loads(subprocess.run([cli, "info", src], check=True, capture_output=True, text=True).stdout)
    rp = os.path.join(out_dir, "recipe_memory.json")
    with open(rp, "w") as f:
        json.dump({"version": 1, "effects": [{"effect": "gaussian_blur", "params": {"sigma": peers.SIGMA}}]}, f)
    out_exr = os.path.join(out_dir, "memory_out.exr")
    mem_needed = peak_rss_mib([cli, "run", "--stack", rp, "--force", "--quiet", src, "-o", out_exr])
    mem_all = peak_rss_mib([cli, "run", "--stack", rp, "--keep-passes", "--force", "--quiet", src, "-o", out_exr])
    n_channels = sum(len(p["channels"]) for p in info["passes"])
    px = info["width"] * info["height"]
    rows = [
        ("channels in the file", n_channels),
        ("all passes as float, MiB", px * n_channels * 4 / 2**20),
        ("Combined only as float, MiB", px * 4 * 4 / 2**20),
        ("peak RSS, blur decoding only Combined, MiB", mem_needed),
        ("peak RSS, blur with --keep-passes (decodes all), MiB", mem_all),
    ]
    md = ["| memory (%dx%d, %s) | value |" % (info["width"], info["height"], os.path.basename(src)), "|---|---:|"]
    return md + ["| %s | %s |" % (k, ("%.1f" % v) if isinstance(v, float) else v) for k, v in rows]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--out", default=os.path.join(peers.ROOT, "out", "bench"))
    ap.add_argument("--exr", help="a scene's passes EXR (default: the all-passes Greek bath frame)")
    ap.add_argument("--sidecar", help="its camera sidecar (Sun Beams / god_rays rows)")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    src = a.exr or peers.render_all_passes(os.path.join(a.out, "allpasses_1080p.exr"))
    w, h = peers.exr_size(src)
    rows = peers.run_peers(src, a.sidecar, w, h, a.runs, os.path.join(a.out, "peers"))
    peers.write_csv(rows, os.path.join(a.out, "peers.csv"))
    md = peers.markdown(rows) + [""] + memory_rows(peers.find_cli(), src, a.out)
    md += ["", "Notes (how each peer was matched):", ""]
    md += ["- %s / %s: %s" % (r["effect"], r["setting"], r["note"]) for r in rows]
    with open(os.path.join(a.out, "peers.md"), "w") as f:
        f.write("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    sys.exit(main())
