#!/usr/bin/python3
"""Before|after images of each effect for its reference page: docs/images/effect_<effect>.jpg.

    /usr/bin/python3 scripts/effect_gallery.py [--cli build/libfx/libfx] [--out out]
                                              [--effects bloom,rain] [--keep]

Input: the demo renders in out/<scene>/ that `bash scripts/demo.sh` writes (640x360,
headless Blender through the add-on's batch runner): libfx_passes.0001.exr holds the
plain render's Combined and the passes the scene's own stack needs, libfx.0001.camera.json
is the scene sidecar (camera, lights, time and the aux views: the atrium's light view and
rain map, written beside it as libfx_aux_*.exr). Run demo.sh once if out/ lacks them.

For each effect, a one-effect recipe (GALLERY below; every parameter not named keeps the
library's default) runs through `libfx run` on the scene where the effect makes sense;
left: the input's Combined, right: the result, both converted linear -> sRGB the same way
(as demo.sh does), side by side, JPEG <= 150 KB. The pages embed the image in their
`generated:image` block (scripts/gen_effect_docs.py). Needs Debian's python3 with numpy,
PIL and OpenImageIO.
"""
import argparse
import io
import json
import os
import pathlib
import subprocess
import sys
import tempfile

REPO = pathlib.Path(__file__).resolve().parents[1]
MAX_BYTES = 150 * 1024

# effect -> scene, params, mask (None: whole frame). One entry per effect that `libfx list`
# prints; each picks the demo scene whose passes and sidecar it needs.
GALLERY = {
    "bloom": ("greek_bath", {"threshold": 0.8, "radius": 96, "intensity": 0.8}, None),
    "cel_shading": ("greek_bath", {"lighting": "normal_light", "light": "Sun", "bands": 3,
                                   "band_softness": 0.05, "outline_width": 2}, None),
    "color_matrix": ("atrium", {"operator": "sepia"}, None),
    "edges": ("greek_bath", {"depth": True, "depth_mode": "planar", "normal": True}, None),
    "gaussian_blur": ("atrium", {"sigma": 4}, None),
    "god_rays": ("greek_bath", {"light": "Sun", "occlusion": "sky", "threshold": 0.9, "knee": 0.5,
                                "max_source": 6.0, "decay": 0.975, "density": 0.95,
                                "exposure": 0.006}, None),
    "pixelate": ("greek_bath", {"mode": "average", "cell_size": 12, "anchor": "mask"},
                 {"object": "Statue"}),
    "posterize": ("atrium", {"levels": 6}, None),
    "rain": ("atrium", {"density": 0.5, "brightness": 0.8, "wind_angle": 10.0,
                        "cover_material": "Rain_Cover"}, None),
    "rain_splashes": ("atrium", {"spacing": 0.3, "rate": 1.0, "size": 0.14, "brightness": 2.0},
                      None),
    "sin_city": ("atrium", {"levels": 4, "white": 1.5, "keep": "hue", "hue": 0, "hue_width": 20,
                            "hue_softness": 10, "min_saturation": 0.45}, None),
    "ssr_mirror": ("mirror_room", {},
                   {"material": ["Mirror_Clear", "Mirror_Low", "Mirror_Blurred", "Mirror_Fresnel",
                                 "Mirror_Sepia", "Mirror_Grayscale", "Mirror_Cel",
                                 "Mirror_BentOut", "Mirror_BentIn"]}),
    "voronoi_caustics": ("greek_bath", {"tile_size": 3.0, "strength": 0.8, "speed": 2.0,
                                        "environment_strength": 0.25}, {"material": "Water"}),
    "vsm_shadows": ("atrium", {"light": "Sun", "filter_size": 5.0, "bleed_reduction": 0.3,
                               "apply": "sun_diffuse"}, None),
    "wet_surfaces": ("atrium", {"darken": 0.5, "specular": 1.5, "edge_softness": 0.4}, None),
}

COMMAND = "/usr/bin/python3 scripts/effect_gallery.py"


def caption(effect):
    """What the page says under the image (gen_effect_docs.py imports this)."""
    scene, params, mask = GALLERY[effect]
    entry = {"effect": effect, "params": params}
    if mask:
        entry["mask"] = mask
    return (f"Before | after: the `{scene}` demo render (640x360, `bash scripts/demo.sh`), "
            f"recipe `{json.dumps(entry, separators=(', ', ': '))}`; "
            f"made by `{COMMAND} --effects {effect}`.")


def srgb8(rgb):
    import numpy as np
    x = np.clip(np.nan_to_num(rgb, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return (x * 255.0 + 0.5).astype(np.uint8)


def read_combined(path):
    import numpy as np
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise RuntimeError(f"cannot read {path}: {oiio.geterror()}")
    spec = inp.spec()
    data = np.asarray(inp.read_image(format=oiio.FLOAT), np.float32)
    inp.close()
    data = data.reshape(spec.height, spec.width, spec.nchannels)
    names = list(spec.channelnames)
    planes = []
    for c in "RGB":
        hit = [i for i, n in enumerate(names) if n.endswith(f"Combined.{c}")]
        if not hit:
            raise RuntimeError(f"{path}: no Combined.{c} among {names}")
        planes.append(data[..., hit[-1]])
    return np.stack(planes, axis=-1)


def side_by_side_jpeg(before, after, path):
    import numpy as np
    from PIL import Image
    gap = np.full((before.shape[0], 4, 3), 255, np.uint8)
    img = Image.fromarray(np.concatenate([srgb8(before), gap, srgb8(after)], axis=1))
    for quality in range(88, 40, -4):
        buf = io.BytesIO()
        img.save(buf, "JPEG", quality=quality, optimize=True, progressive=True)
        if buf.tell() <= MAX_BYTES:
            break
    else:
        img = img.resize((img.width * 3 // 4, img.height * 3 // 4), Image.LANCZOS)
        buf = io.BytesIO()
        img.save(buf, "JPEG", quality=80, optimize=True, progressive=True)
    tmp = path.with_suffix(".tmp.jpg")
    tmp.write_bytes(buf.getvalue())
    os.replace(tmp, path)
    return buf.tell()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cli", default=os.environ.get("LIBFX_CLI", str(REPO / "build/libfx/libfx")))
    ap.add_argument("--out", default=str(REPO / "out"), help="demo renders (out/<scene>/)")
    ap.add_argument("--images", default=str(REPO / "docs/images"))
    ap.add_argument("--effects", default="", help="comma-separated subset (default: all)")
    ap.add_argument("--keep", action="store_true", help="keep the result EXRs in out/gallery/")
    a = ap.parse_args(argv)

    listed = [l.split("\t")[0] for l in subprocess.run(
        [a.cli, "list"], check=True, capture_output=True, text=True).stdout.splitlines() if l]
    missing = [e for e in listed if e not in GALLERY]
    if missing:
        print(f"effect_gallery: no gallery entry for {', '.join(missing)} (add one to GALLERY)",
              file=sys.stderr)
    todo = [e for e in (a.effects.split(",") if a.effects else listed) if e]
    unknown = [e for e in todo if e not in GALLERY or e not in listed]
    if unknown:
        print(f"effect_gallery: unknown effect(s) {', '.join(unknown)}", file=sys.stderr)
        return 2

    out_root = pathlib.Path(a.out)
    images = pathlib.Path(a.images)
    images.mkdir(parents=True, exist_ok=True)
    work = pathlib.Path(tempfile.mkdtemp(prefix="libfx-gallery-"))
    keep_dir = out_root / "gallery"
    failed = 0
    for effect in todo:
        scene, params, mask = GALLERY[effect]
        src = out_root / scene / "libfx_passes.0001.exr"
        sidecar = out_root / scene / "libfx.0001.camera.json"
        if not src.is_file() or not sidecar.is_file():
            print(f"effect_gallery: {src} or its sidecar is missing: run `bash scripts/demo.sh` "
                  f"first", file=sys.stderr)
            return 3
        entry = {"effect": effect, "params": params}
        if mask:
            entry["mask"] = mask
        recipe = work / f"{effect}.json"
        recipe.write_text(json.dumps({"version": 1, "quality": "final", "effects": [entry]},
                                     indent=2))
        result = (keep_dir if a.keep else work) / f"{effect}.exr"
        result.parent.mkdir(parents=True, exist_ok=True)
        cmd = [a.cli, "run", "--quiet", "--force", "--stack", str(recipe), "--camera",
               str(sidecar), "--frame", "1", str(src), "-o", str(result)]
        p = subprocess.run(cmd, capture_output=True, text=True)
        if p.returncode != 0:
            print(f"effect_gallery: {effect}: libfx run failed ({p.returncode}): "
                  f"{p.stderr.strip()}", file=sys.stderr)
            failed += 1
            continue
        dest = images / f"effect_{effect}.jpg"
        size = side_by_side_jpeg(read_combined(src), read_combined(result), dest)
        print(f"effect_gallery: {effect} on {scene}: {dest} ({size // 1024} KB)")
        if not a.keep:
            result.unlink()
    for f in work.iterdir():
        f.unlink()
    work.rmdir()
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
