"""Render the ground-truth reflections of mirror_room.blend with Cycles.

Opens mirror_room.blend (beside this script), replaces the shading of every
``Mirror_*`` material by a true Cycles mirror, and renders one frame to the
path given after ``--`` (``.exr``: 32-bit float multilayer; ``.png``: 8-bit).
The .blend itself is never saved.

    blender -b --factory-startup --python blend_scenes/mirror_room/make_mirror_reference.py \\
        -- /tmp/mirror_ref.exr [--frame 1] [--samples 128] [--resolution 320 180]

What each kind becomes:
  Clear, FacingA, FacingB, BentOut, BentIn: Glossy BSDF, white, roughness 0 (a
      perfect mirror; the bent ones keep their curved geometry).
  Low:      25 % perfect mirror over the dark backing (Mix Shader, fac 0.25).
  Blurred:  Glossy GGX roughness 0.2.  Only an approximation: libfx blurs the
      reflection in screen space (gaussian sigma px), a rough BRDF blurs by angle.
  Fresnel:  backing + perfect mirror mixed by a Fresnel node (IOR 1.5):
      dielectric-like, reflective at grazing angles, dark head-on.
  Sepia, Grayscale, Cel: *no physical equivalent* -- a colour transform of the
      reflected image (or cel quantisation) cannot be expressed as a BSDF.  They
      render as perfect mirrors here; compare them after applying the same
      colour operator to the reference's mirror region.
Glossy bounces are raised so the facing pair shows several inter-reflections, and the
indirect clamp is off (mirror paths are indirect light: clamped, they come out darker
than the surfaces they reflect).
"""

import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import scene_common as sc  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
BLEND = os.path.join(HERE, "mirror_room.blend")

BACKING = (0.085, 0.1, 0.13, 1.0)     # same as make_mirror_room.mirror_backing_material

PERFECT = {"Mirror_Clear", "Mirror_FacingA", "Mirror_FacingB", "Mirror_BentOut",
           "Mirror_BentIn",
           # no physical equivalent (colour operators): geometry-only reference
           "Mirror_Sepia", "Mirror_Grayscale", "Mirror_Cel"}


def parse_args(argv):
    args = argv[argv.index("--") + 1:] if "--" in argv else []
    if not args or args[0].startswith("--"):
        raise SystemExit("usage: ... make_mirror_reference.py -- OUT.exr|OUT.png "
                         "[--frame N] [--samples N] [--resolution W H]")
    opts = {"out": os.path.abspath(args[0]), "frame": 1, "samples": None, "res": None}
    i = 1
    while i < len(args):
        if args[i] == "--frame":
            opts["frame"] = int(args[i + 1])
            i += 2
        elif args[i] == "--samples":
            opts["samples"] = int(args[i + 1])
            i += 2
        elif args[i] == "--resolution":
            opts["res"] = (int(args[i + 1]), int(args[i + 2]))
            i += 3
        else:
            raise SystemExit("unknown option %r" % args[i])
    return opts


def _reset(mat):
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.location = (600, 0)
    return nt, out


def _glossy(nt, roughness=0.0):
    g = nt.nodes.new("ShaderNodeBsdfGlossy")
    g.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    if roughness == 0.0:
        sc.sharp_bsdf(g)          # 'SHARP' is gone from 4.0
    else:
        g.distribution = 'GGX'
        g.inputs["Roughness"].default_value = roughness
    return g


def _backing(nt):
    b = nt.nodes.new("ShaderNodeBsdfPrincipled")
    b.inputs["Base Color"].default_value = BACKING
    b.inputs["Roughness"].default_value = 0.3
    sc.compat.principled_input(b, "Specular").default_value = 0.0
    return b


def make_true_mirror(mat):
    name = mat.name
    nt, out = _reset(mat)
    if name in PERFECT:
        shader = _glossy(nt).outputs[0]
    elif name == "Mirror_Low":
        mix = nt.nodes.new("ShaderNodeMixShader")
        mix.inputs["Fac"].default_value = 0.25
        nt.links.new(_backing(nt).outputs[0], mix.inputs[1])
        nt.links.new(_glossy(nt).outputs[0], mix.inputs[2])
        shader = mix.outputs[0]
    elif name == "Mirror_Blurred":
        shader = _glossy(nt, 0.2).outputs[0]
    elif name == "Mirror_Fresnel":
        fr = nt.nodes.new("ShaderNodeFresnel")
        fr.inputs["IOR"].default_value = 1.5
        mix = nt.nodes.new("ShaderNodeMixShader")
        nt.links.new(fr.outputs[0], mix.inputs["Fac"])
        nt.links.new(_backing(nt).outputs[0], mix.inputs[1])
        nt.links.new(_glossy(nt).outputs[0], mix.inputs[2])
        shader = mix.outputs[0]
    else:
        print("make_mirror_reference: unknown mirror kind %s, using a perfect mirror" % name)
        shader = _glossy(nt).outputs[0]
    nt.links.new(shader, out.inputs["Surface"])


def main():
    opts = parse_args(sys.argv)
    bpy.ops.wm.open_mainfile(filepath=BLEND)
    scene = bpy.context.scene
    mirrors = [m for m in bpy.data.materials if m.name.startswith("Mirror_")]
    for m in mirrors:
        make_true_mirror(m)
    print("make_mirror_reference: %d mirror materials replaced: %s"
          % (len(mirrors), ", ".join(sorted(m.name for m in mirrors))))
    cy = scene.cycles
    cy.glossy_bounces = 12
    cy.max_bounces = 16
    cy.blur_glossy = 0.0          # keep mirror paths exact
    # Everything seen in a mirror is indirect light for Cycles: the scene's indirect
    # clamp (0.5) would darken the reflected room 1.5-2.2x. Off, for the truth; render
    # the input the same way to compare (tests/bench/bench_ssr_render.py does).
    cy.sample_clamp_indirect = 0.0
    if opts["samples"]:
        cy.samples = opts["samples"]
    if opts["res"]:
        scene.render.resolution_x, scene.render.resolution_y = opts["res"]
        scene.render.resolution_percentage = 100
    scene.frame_set(opts["frame"])
    img = scene.render.image_settings
    if opts["out"].lower().endswith(".png"):
        img.file_format = 'PNG'
        img.color_mode = 'RGBA'
        img.color_depth = '8'
    else:
        img.file_format = 'OPEN_EXR_MULTILAYER'
        img.color_depth = '32'
        img.exr_codec = 'ZIP'
    scene.render.use_file_extension = False
    scene.render.filepath = opts["out"]
    bpy.ops.render.render(write_still=True)
    if not os.path.exists(opts["out"]):
        raise RuntimeError("no output written to %s" % opts["out"])
    print("make_mirror_reference: wrote", opts["out"])


if __name__ == "__main__":
    sc.run_main(main)
