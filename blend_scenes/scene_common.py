"""Shared helpers for the libfx test-scene builders (Blender 3.4+, run headless).

Each ``<scene>/make_<scene>.py`` puts this file's directory on ``sys.path`` and
imports it.  Everything here is deterministic: no clocks, no unseeded random,
procedural geometry and procedural textures only (no image files).

Typical use::

    import scene_common as sc
    sc.reset_file()
    mat = sc.principled_material("Marble_Column", (0.8, 0.78, 0.72), pass_index=3,
                                 roughness=0.3, texture=sc.tex_marble)
    col = sc.mesh_object("Column_01", sc.bm_cylinder(...), mat, pass_index=10)
    ...
    sc.render_settings(scene)
    sc.write_recipe(here, recipe)
    sc.save_blend(os.path.join(here, "scene.blend"))
"""

import json
import math
import os

import bmesh
import bpy
from mathutils import Euler, Matrix, Vector


def _load_compat():
    """The add-on's module of Blender version differences (addon/libfx/compat.py),
    loaded by path: the builders share it without registering the add-on."""
    import importlib.util
    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                        "addon", "libfx", "compat.py")
    spec = importlib.util.spec_from_file_location("libfx_compat", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


compat = _load_compat()

RECIPE_TEXT_NAME = "libfx_recipe.json"

# Settings every libfx test scene shares (see blend_scenes/README.md).
RESOLUTION = (1280, 720)
FRAME_RANGE = (1, 8)
FPS = 24
SAMPLES = 16


# --------------------------------------------------------------------------
# File / scene
# --------------------------------------------------------------------------

def reset_file():
    """Start from a truly empty file (no cube, camera, light, world)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    return scene


def render_settings(scene, samples=SAMPLES):
    """Cycles, 16 adaptive samples, no denoiser (Debian's Blender has no OIDN),
    1280x720 at 100 %, frames 1..8 at 24 fps, 'Standard' view transform.
    Render passes are left at their defaults: the add-on enables what a stack needs."""
    scene.render.engine = 'CYCLES'
    cy = scene.cycles
    cy.device = 'CPU'
    cy.samples = samples
    cy.preview_samples = 8
    cy.use_adaptive_sampling = True
    cy.use_denoising = False
    cy.use_preview_denoising = False
    cy.seed = 0
    # Noise control for 16 un-denoised samples: clamp indirect fireflies, blur
    # glossy paths a little, no caustic paths (libfx adds caustics as an effect).
    cy.sample_clamp_direct = 0.0
    cy.sample_clamp_indirect = 0.5
    cy.blur_glossy = 1.0
    cy.caustics_reflective = False
    cy.caustics_refractive = False
    cy.max_bounces = 6
    cy.diffuse_bounces = 2
    cy.glossy_bounces = 4
    cy.transmission_bounces = 6
    cy.use_animated_seed = False
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.render.resolution_percentage = 100
    scene.render.fps = FPS
    scene.render.fps_base = 1.0
    scene.frame_start, scene.frame_end = FRAME_RANGE
    scene.frame_current = FRAME_RANGE[0]
    scene.view_settings.view_transform = 'Standard'
    scene.view_settings.look = 'None'
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    compat.set_file_format(scene.render.image_settings, 'OPEN_EXR_MULTILAYER', '32', 'ZIP')


def output_path(path):
    """Where a builder writes ``path``: beside the script, or into $LIBFX_SCENES_OUT
    (same file name) to build a scene elsewhere without touching the committed one."""
    out = os.environ.get("LIBFX_SCENES_OUT")
    if out:
        os.makedirs(out, exist_ok=True)
        return os.path.join(out, os.path.basename(path))
    return path


def save_blend(path):
    """Save compressed, relative paths, no UI-dependent state."""
    path = output_path(path)
    bpy.context.scene.frame_set(FRAME_RANGE[0])
    bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(path), compress=True,
                                relative_remap=True)
    print("saved", path, os.path.getsize(path), "bytes")


def write_recipe(scene_dir, recipe):
    """Write the libfx effect recipe twice: ``recipe.json`` beside the .blend
    (pretty-printed, key order as given, which is the documented order) and a
    Text datablock ``libfx_recipe.json`` inside the .blend (the add-on imports
    it on load when its stack is empty)."""
    text = json.dumps(recipe, indent=2, ensure_ascii=True) + "\n"
    with open(output_path(os.path.join(scene_dir, "recipe.json")), "w", encoding="utf-8",
              newline="\n") as f:
        f.write(text)
    block = bpy.data.texts.get(RECIPE_TEXT_NAME) or bpy.data.texts.new(RECIPE_TEXT_NAME)
    block.clear()
    block.write(text)
    return text


def script_dir(file):
    return os.path.dirname(os.path.abspath(file))


# --------------------------------------------------------------------------
# World, lights, camera
# --------------------------------------------------------------------------

def sky_world(name, zenith=(0.18, 0.38, 0.85), horizon=(0.75, 0.85, 1.0),
              ground=(0.25, 0.23, 0.2), strength=1.0, sun_dir=None,
              sun_color=(1.0, 0.92, 0.75), sun_strength=0.0, sun_size_deg=3.0,
              glow_strength=0.0, glow_size_deg=15.0):
    """A sky-ish gradient world (ground / horizon / zenith by view elevation).

    With ``sun_strength > 0`` a visible sun disc (plus an optional soft glow) is
    drawn in direction ``sun_dir`` (pointing *towards* the sun), so the sun is
    visible to the camera; a Cycles Sun lamp is not."""
    world = bpy.data.worlds.new(name)
    bpy.context.scene.world = world
    world.use_nodes = True
    nt = world.node_tree
    nodes, links = nt.nodes, nt.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputWorld")
    out.location = (900, 0)
    tc = nodes.new("ShaderNodeTexCoord")
    tc.location = (-900, 0)
    sep = nodes.new("ShaderNodeSeparateXYZ")
    sep.location = (-700, 100)
    norm = nodes.new("ShaderNodeVectorMath")
    norm.operation = 'NORMALIZE'
    norm.location = (-700, -100)
    links.new(tc.outputs["Generated"], norm.inputs[0])
    links.new(norm.outputs["Vector"], sep.inputs[0])
    ramp = nodes.new("ShaderNodeValToRGB")
    ramp.location = (-300, 100)
    # map z in [-1, 1] to [0, 1]
    mapz = nodes.new("ShaderNodeMapRange")
    mapz.location = (-500, 100)
    mapz.inputs["From Min"].default_value = -1.0
    mapz.inputs["From Max"].default_value = 1.0
    links.new(sep.outputs["Z"], mapz.inputs["Value"])
    links.new(mapz.outputs["Result"], ramp.inputs["Fac"])
    els = ramp.color_ramp.elements
    els[0].position = 0.45
    els[0].color = (*ground, 1.0)
    els[1].position = 0.5
    els[1].color = (*horizon, 1.0)
    e = els.new(0.8)
    e.color = (*zenith, 1.0)
    bg = nodes.new("ShaderNodeBackground")
    bg.location = (0, 100)
    bg.inputs["Strength"].default_value = strength
    links.new(ramp.outputs["Color"], bg.inputs["Color"])
    last = bg.outputs["Background"]
    if sun_dir is not None and (sun_strength > 0 or glow_strength > 0):
        d = Vector(sun_dir).normalized()
        dot = nodes.new("ShaderNodeVectorMath")
        dot.operation = 'DOT_PRODUCT'
        dot.location = (-500, -200)
        dot.inputs[1].default_value = d
        links.new(norm.outputs["Vector"], dot.inputs[0])
        # hard disc
        disc = nodes.new("ShaderNodeMapRange")
        disc.location = (-300, -150)
        c_in = math.cos(math.radians(sun_size_deg * 0.5 * 0.9))
        c_out = math.cos(math.radians(sun_size_deg * 0.5))
        disc.inputs["From Min"].default_value = c_out
        disc.inputs["From Max"].default_value = c_in
        disc.clamp = True
        links.new(dot.outputs["Value"], disc.inputs["Value"])
        # soft glow: ((dot - cos(g)) / (1 - cos(g)))^4
        glow = nodes.new("ShaderNodeMapRange")
        glow.location = (-300, -350)
        glow.inputs["From Min"].default_value = math.cos(math.radians(glow_size_deg))
        glow.inputs["From Max"].default_value = 1.0
        glow.clamp = True
        links.new(dot.outputs["Value"], glow.inputs["Value"])
        powr = nodes.new("ShaderNodeMath")
        powr.operation = 'POWER'
        powr.inputs[1].default_value = 4.0
        powr.location = (-100, -350)
        links.new(glow.outputs["Result"], powr.inputs[0])
        mdisc = nodes.new("ShaderNodeMath")
        mdisc.operation = 'MULTIPLY'
        mdisc.inputs[1].default_value = sun_strength
        mdisc.location = (-100, -150)
        links.new(disc.outputs["Result"], mdisc.inputs[0])
        mglow = nodes.new("ShaderNodeMath")
        mglow.operation = 'MULTIPLY'
        mglow.inputs[1].default_value = glow_strength
        mglow.location = (100, -350)
        links.new(powr.outputs["Value"], mglow.inputs[0])
        total = nodes.new("ShaderNodeMath")
        total.operation = 'ADD'
        total.location = (300, -250)
        links.new(mdisc.outputs["Value"], total.inputs[0])
        links.new(mglow.outputs["Value"], total.inputs[1])
        # Only camera rays see the disc and glow: as lighting they would be a
        # tiny, very bright background feature (fireflies at 16 samples); the
        # Sun lamp does the lighting instead.
        lp = nodes.new("ShaderNodeLightPath")
        lp.location = (100, -550)
        cam_only = nodes.new("ShaderNodeMath")
        cam_only.operation = 'MULTIPLY'
        cam_only.location = (400, -400)
        links.new(total.outputs["Value"], cam_only.inputs[0])
        links.new(lp.outputs["Is Camera Ray"], cam_only.inputs[1])
        sbg = nodes.new("ShaderNodeBackground")
        sbg.location = (500, -250)
        sbg.inputs["Color"].default_value = (*sun_color, 1.0)
        links.new(cam_only.outputs["Value"], sbg.inputs["Strength"])
        add = nodes.new("ShaderNodeAddShader")
        add.location = (700, 0)
        links.new(bg.outputs["Background"], add.inputs[0])
        links.new(sbg.outputs["Background"], add.inputs[1])
        last = add.outputs["Shader"]
    links.new(last, out.inputs["Surface"])
    return world


def direction_from_angles(azimuth_deg, elevation_deg):
    """Unit vector pointing *towards* a light at the given azimuth (from +Y,
    counter-clockwise seen from above, 0 = +Y) and elevation above horizon."""
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    return Vector((-math.sin(az) * math.cos(el), math.cos(az) * math.cos(el),
                   math.sin(el)))


def add_sun(name="Sun", direction=(0, 0, 1), strength=4.0, color=(1.0, 0.95, 0.85),
            angle_deg=1.0):
    """Sun lamp whose light travels *against* ``direction`` (direction points at the sun)."""
    data = bpy.data.lights.new(name, 'SUN')
    data.energy = strength
    data.color = color
    data.angle = math.radians(angle_deg)
    obj = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(obj)
    d = Vector(direction).normalized()
    # A sun shines along its local -Z: rotate +Z onto d.
    obj.rotation_euler = d.to_track_quat('Z', 'Y').to_euler()
    obj.location = d * 20.0
    return obj


def add_area_light(name, location, target, size=(2.0, 2.0), power=200.0,
                   color=(1.0, 1.0, 1.0), shadow=True):
    data = bpy.data.lights.new(name, 'AREA')
    data.shape = 'RECTANGLE'
    data.size, data.size_y = size
    data.energy = power
    data.color = color
    compat.light_cast_shadow(data, shadow)
    obj = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(obj)
    obj.visible_camera = False
    obj.visible_glossy = False
    obj.location = location
    look_at(obj, target)
    return obj


def add_point_light(name, location, power=100.0, radius=0.2, color=(1, 1, 1)):
    data = bpy.data.lights.new(name, 'POINT')
    data.energy = power
    data.shadow_soft_size = radius
    data.color = color
    obj = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = location
    return obj


def look_at(obj, target):
    d = Vector(target) - obj.location
    obj.rotation_euler = d.to_track_quat('-Z', 'Y').to_euler()


def look_at_euler(location, target, roll_deg=0.0):
    d = Vector(target) - Vector(location)
    e = d.to_track_quat('-Z', 'Y').to_euler()
    if roll_deg:
        m = e.to_matrix() @ Matrix.Rotation(math.radians(roll_deg), 3, 'Z')
        e = m.to_euler()
    return e


def add_camera(name="Camera", lens=24.0, clip_end=200.0):
    data = bpy.data.cameras.new(name)
    data.lens = lens
    data.sensor_fit = 'AUTO'
    data.sensor_width = 36.0
    data.clip_start = 0.05
    data.clip_end = clip_end
    obj = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.scene.camera = obj
    return obj


def animate_camera(cam, keys, interpolation='BEZIER'):
    """Keyframe camera location and rotation.

    ``keys``: list of ``(frame, location, target)`` (look-at point) or
    ``(frame, location, target, roll_deg)``.  Euler rotations are made
    continuous between keys so interpolation never spins."""
    prev = None
    for k in keys:
        frame, loc, target = k[0], k[1], k[2]
        roll = k[3] if len(k) > 3 else 0.0
        cam.location = loc
        e = look_at_euler(loc, target, roll)
        if prev is not None:
            e.make_compatible(prev)
        cam.rotation_euler = e
        prev = e.copy()
        cam.keyframe_insert("location", frame=frame)
        cam.keyframe_insert("rotation_euler", frame=frame)
    for fc in compat.animation_fcurves(cam):
        for kp in fc.keyframe_points:
            kp.interpolation = interpolation
            kp.easing = 'EASE_IN_OUT'
    cam.animation_data.action.name = cam.name + "_Move"


# --------------------------------------------------------------------------
# Materials (procedural textures only)
# --------------------------------------------------------------------------

def _nodes(mat):
    mat.use_nodes = True
    nt = mat.node_tree
    return nt, nt.nodes, nt.links


def principled_material(name, color, pass_index, roughness=0.5, metallic=0.0,
                        specular=0.5, texture=None, bump=0.0, **extra):
    """A named Principled material.  ``texture(nt, bsdf)`` may wire procedural
    texture nodes into it (see ``tex_*`` below).  ``extra`` sets further
    Principled inputs by name (e.g. ``Transmission=1.0``)."""
    mat = bpy.data.materials.new(name)
    mat.pass_index = pass_index
    nt, nodes, links = _nodes(mat)
    bsdf = nodes.get("Principled BSDF")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    compat.principled_input(bsdf, "Specular").default_value = specular
    for k, v in extra.items():
        compat.principled_input(bsdf, k.replace("_", " ")).default_value = v
    mat.diffuse_color = (*color, 1.0)  # viewport / solid mode colour
    if texture is not None:
        texture(nt, bsdf, color, bump)
    return mat


def _coord(nt, space="Object", scale=1.0):
    tc = nt.nodes.new("ShaderNodeTexCoord")
    tc.location = (-1100, 0)
    mp = nt.nodes.new("ShaderNodeMapping")
    mp.location = (-900, 0)
    mp.inputs["Scale"].default_value = (scale, scale, scale)
    nt.links.new(tc.outputs[space], mp.inputs["Vector"])
    return mp.outputs["Vector"]


def _bump(nt, bsdf, height_socket, strength):
    if strength <= 0:
        return
    b = nt.nodes.new("ShaderNodeBump")
    b.location = (-250, -400)
    b.inputs["Strength"].default_value = strength
    b.inputs["Distance"].default_value = 0.05
    nt.links.new(height_socket, b.inputs["Height"])
    nt.links.new(b.outputs["Normal"], bsdf.inputs["Normal"])


def _color_ramp(nt, fac_socket, c0, c1, p0=0.3, p1=0.7):
    r = nt.nodes.new("ShaderNodeValToRGB")
    r.location = (-450, 200)
    r.color_ramp.elements[0].position = p0
    r.color_ramp.elements[0].color = (*c0, 1.0)
    r.color_ramp.elements[1].position = p1
    r.color_ramp.elements[1].color = (*c1, 1.0)
    nt.links.new(fac_socket, r.inputs["Fac"])
    return r.outputs["Color"]


def _scaled(color, k):
    return tuple(min(1.0, c * k) for c in color)


def tex_marble(nt, bsdf, color, bump, scale=1.5):
    """Veined marble: distorted wave texture."""
    v = _coord(nt, scale=scale)
    w = nt.nodes.new("ShaderNodeTexWave")
    w.location = (-700, 200)
    w.wave_type = 'BANDS'
    w.inputs["Scale"].default_value = 1.2
    w.inputs["Distortion"].default_value = 12.0
    w.inputs["Detail"].default_value = 4.0
    nt.links.new(v, w.inputs["Vector"])
    col = _color_ramp(nt, w.outputs["Fac"], _scaled(color, 0.78), color, 0.0, 0.35)
    nt.links.new(col, bsdf.inputs["Base Color"])
    _bump(nt, bsdf, w.outputs["Fac"], bump)


def tex_noise(nt, bsdf, color, bump, scale=4.0, contrast=0.7):
    """Stone-like noise variation of the base colour."""
    v = _coord(nt, scale=scale)
    n = nt.nodes.new("ShaderNodeTexNoise")
    n.location = (-700, 200)
    n.inputs["Scale"].default_value = 2.0
    n.inputs["Detail"].default_value = 6.0
    nt.links.new(v, n.inputs["Vector"])
    col = _color_ramp(nt, n.outputs["Fac"], _scaled(color, contrast), color)
    nt.links.new(col, bsdf.inputs["Base Color"])
    _bump(nt, bsdf, n.outputs["Fac"], bump)


def tex_tiles(nt, bsdf, color, bump, scale=2.0, mortar=(0.5, 0.5, 0.48),
              mortar_size=0.03):
    """Square tiles (Brick texture, no offset) with slight per-tile variation."""
    v = _coord(nt, scale=1.0)
    b = nt.nodes.new("ShaderNodeTexBrick")
    b.location = (-700, 200)
    b.offset = 0.0
    b.squash = 1.0
    b.inputs["Scale"].default_value = scale
    b.inputs["Brick Width"].default_value = 1.0
    b.inputs["Row Height"].default_value = 1.0
    b.inputs["Mortar Size"].default_value = mortar_size
    b.inputs["Color1"].default_value = (*color, 1.0)
    b.inputs["Color2"].default_value = (*_scaled(color, 0.8), 1.0)
    b.inputs["Mortar"].default_value = (*mortar, 1.0)
    b.inputs["Bias"].default_value = 0.0
    nt.links.new(v, b.inputs["Vector"])
    nt.links.new(b.outputs["Color"], bsdf.inputs["Base Color"])
    inv = nt.nodes.new("ShaderNodeMath")
    inv.operation = 'SUBTRACT'
    inv.inputs[0].default_value = 1.0
    nt.links.new(b.outputs["Fac"], inv.inputs[1])
    _bump(nt, bsdf, inv.outputs["Value"], bump)


def tex_bricks(nt, bsdf, color, bump, scale=3.0):
    """Running-bond bricks / roof tiles."""
    v = _coord(nt, scale=1.0)
    b = nt.nodes.new("ShaderNodeTexBrick")
    b.location = (-700, 200)
    b.offset = 0.5
    b.inputs["Scale"].default_value = scale
    b.inputs["Mortar Size"].default_value = 0.02
    b.inputs["Color1"].default_value = (*color, 1.0)
    b.inputs["Color2"].default_value = (*_scaled(color, 0.75), 1.0)
    b.inputs["Mortar"].default_value = (*_scaled(color, 0.4), 1.0)
    nt.links.new(v, b.inputs["Vector"])
    nt.links.new(b.outputs["Color"], bsdf.inputs["Base Color"])
    _bump(nt, bsdf, b.outputs["Fac"], bump)


def tex_checker(nt, bsdf, color, bump, scale=2.0, color2=None):
    """Checkerboard (good for judging reflections and distortion)."""
    v = _coord(nt, scale=1.0)
    c = nt.nodes.new("ShaderNodeTexChecker")
    c.location = (-700, 200)
    c.inputs["Scale"].default_value = scale
    c.inputs["Color1"].default_value = (*color, 1.0)
    c.inputs["Color2"].default_value = (*(color2 or _scaled(color, 0.25)), 1.0)
    nt.links.new(v, c.inputs["Vector"])
    nt.links.new(c.outputs["Color"], bsdf.inputs["Base Color"])


def tex_wood(nt, bsdf, color, bump, scale=3.0):
    """Bark / wood: stretched noise rings."""
    tc = nt.nodes.new("ShaderNodeTexCoord")
    mp = nt.nodes.new("ShaderNodeMapping")
    mp.inputs["Scale"].default_value = (scale * 4, scale * 4, scale * 0.5)
    nt.links.new(tc.outputs["Object"], mp.inputs["Vector"])
    n = nt.nodes.new("ShaderNodeTexNoise")
    n.inputs["Scale"].default_value = 2.0
    n.inputs["Detail"].default_value = 8.0
    n.inputs["Distortion"].default_value = 1.5
    nt.links.new(mp.outputs["Vector"], n.inputs["Vector"])
    col = _color_ramp(nt, n.outputs["Fac"], _scaled(color, 0.45), color)
    nt.links.new(col, bsdf.inputs["Base Color"])
    _bump(nt, bsdf, n.outputs["Fac"], bump)


def sharp_bsdf(node):
    """A perfectly sharp Glossy/Glass BSDF node: distribution 'SHARP' up to Blender 3.6;
    4.0 dropped it (GGX at roughness 0 is the same there)."""
    try:
        node.distribution = 'SHARP'
    except TypeError:
        node.distribution = 'GGX'
    node.inputs["Roughness"].default_value = 0.0


def transparent_material(name, pass_index, opacity=0.07, tint=(1.0, 1.0, 1.0)):
    """A see-through veil: one Transparent BSDF whose colour is
    ``tint * (1 - opacity)``; Cycles treats it as alpha = ``opacity``."""
    mat = bpy.data.materials.new(name)
    mat.pass_index = pass_index
    nt, nodes, links = _nodes(mat)
    for n in list(nodes):
        if n.type != 'OUTPUT_MATERIAL':
            nodes.remove(n)
    tr = nodes.new("ShaderNodeBsdfTransparent")
    tr.inputs["Color"].default_value = (*(c * (1.0 - opacity) for c in tint), 1.0)
    links.new(tr.outputs["BSDF"], nodes.get("Material Output").inputs["Surface"])
    mat.diffuse_color = (*tint, opacity)
    return mat


def mix_with_transparent(mat, alpha_socket_fn=None, alpha=1.0):
    """Route ``mat``'s Principled output through a Mix with a Transparent BSDF.
    ``alpha_socket_fn(nt)`` returns a socket giving opacity (1 = opaque);
    otherwise the constant ``alpha`` is used."""
    nt, nodes, links = _nodes(mat)
    out = nodes.get("Material Output")
    bsdf = nodes.get("Principled BSDF")
    tr = nodes.new("ShaderNodeBsdfTransparent")
    tr.location = (100, 200)
    mix = nodes.new("ShaderNodeMixShader")
    mix.location = (350, 100)
    links.new(tr.outputs["BSDF"], mix.inputs[1])
    links.new(bsdf.outputs["BSDF"], mix.inputs[2])
    if alpha_socket_fn is not None:
        links.new(alpha_socket_fn(nt), mix.inputs["Fac"])
    else:
        mix.inputs["Fac"].default_value = alpha
    links.new(mix.outputs["Shader"], out.inputs["Surface"])
    return mix


# --------------------------------------------------------------------------
# Geometry (bmesh; every builder appends to a given BMesh with a matrix)
# --------------------------------------------------------------------------

def T(loc=(0, 0, 0), rot_deg=(0, 0, 0), scale=(1, 1, 1)):
    """Matrix from location, XYZ Euler in degrees and (non-uniform) scale."""
    r = Euler(tuple(math.radians(a) for a in rot_deg), 'XYZ').to_matrix().to_4x4()
    s = Matrix.Diagonal((*scale, 1.0))
    return Matrix.Translation(loc) @ r @ s


def bm_box(bm, center, size, rot_deg=(0, 0, 0)):
    """Axis-aligned (then rotated) box of full ``size`` centred at ``center``."""
    bmesh.ops.create_cube(bm, size=1.0, matrix=T(center, rot_deg, size))


def bm_box_minmax(bm, lo, hi):
    c = [(a + b) * 0.5 for a, b in zip(lo, hi)]
    s = [abs(b - a) for a, b in zip(lo, hi)]
    bm_box(bm, c, s)


def bm_cylinder(bm, base_center, radius, height, segments=24, radius_top=None,
                rot_deg=(0, 0, 0)):
    """Cylinder / cone standing on ``base_center`` (before rotation about it)."""
    rt = radius if radius_top is None else radius_top
    m = T(base_center, rot_deg) @ Matrix.Translation((0, 0, height * 0.5))
    bmesh.ops.create_cone(bm, cap_ends=True, cap_tris=False, segments=segments,
                          radius1=radius, radius2=rt, depth=height, matrix=m)


def bm_segment(bm, a, b, radius_a, radius_b=None, segments=12):
    """Tapered cylinder from point ``a`` to point ``b`` (limbs, branches)."""
    a, b = Vector(a), Vector(b)
    d = b - a
    q = d.normalized().to_track_quat('Z', 'Y')
    m = Matrix.Translation((a + b) * 0.5) @ q.to_matrix().to_4x4()
    bmesh.ops.create_cone(bm, cap_ends=True, cap_tris=False, segments=segments,
                          radius1=radius_a,
                          radius2=radius_a if radius_b is None else radius_b,
                          depth=d.length, matrix=m)


def bm_sphere(bm, center, radius, scale=(1, 1, 1), segments=24, rings=12,
              rot_deg=(0, 0, 0)):
    bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=rings,
                              radius=radius, matrix=T(center, rot_deg, scale))


def bm_torus(bm, center, major, minor, major_seg=32, minor_seg=12, rot_deg=(0, 0, 0)):
    m = T(center, rot_deg)
    verts = []
    for i in range(major_seg):
        u = 2 * math.pi * i / major_seg
        ring = []
        for j in range(minor_seg):
            v = 2 * math.pi * j / minor_seg
            r = major + minor * math.cos(v)
            p = m @ Vector((r * math.cos(u), r * math.sin(u), minor * math.sin(v)))
            ring.append(bm.verts.new(p))
        verts.append(ring)
    for i in range(major_seg):
        a, b = verts[i], verts[(i + 1) % major_seg]
        for j in range(minor_seg):
            k = (j + 1) % minor_seg
            bm.faces.new((a[j], b[j], b[k], a[k]))


def bm_quad(bm, corners):
    vs = [bm.verts.new(Vector(c)) for c in corners]
    return bm.faces.new(vs)


def mesh_object(name, build, material=None, pass_index=0, smooth=False,
                auto_smooth_deg=None, collection=None):
    """Create object ``name`` from a builder ``build(bm)``; assign one material
    and the object pass index.  Returns the object."""
    bm = bmesh.new()
    build(bm)
    bmesh.ops.remove_doubles(bm, verts=bm.verts, dist=1e-6)
    me = bpy.data.meshes.new(name)
    bm.to_mesh(me)
    bm.free()
    if smooth and auto_smooth_deg is not None:
        compat.mesh_smooth_by_angle(me, math.radians(auto_smooth_deg))
    elif smooth:
        for p in me.polygons:
            p.use_smooth = True
    obj = bpy.data.objects.new(name, me)
    (collection or bpy.context.scene.collection).objects.link(obj)
    if material is not None:
        me.materials.append(material)
    obj.pass_index = pass_index
    return obj


def uv_unwrap_planar(obj, axes=(0, 1), scale=1.0):
    """Planar UVs from object-space coordinates (for procedural textures that use UV)."""
    me = obj.data
    uv = me.uv_layers.new(name="UVMap")
    for loop in me.loops:
        co = me.vertices[loop.vertex_index].co
        uv.data[loop.index].uv = (co[axes[0]] * scale, co[axes[1]] * scale)


def new_collection(name):
    col = bpy.data.collections.new(name)
    bpy.context.scene.collection.children.link(col)
    return col


def index_table(objects=(), materials=()):
    """Rows for the README: (kind, name, pass_index)."""
    rows = [("object", o.name, o.pass_index) for o in objects]
    rows += [("material", m.name, m.pass_index) for m in materials]
    return rows


def check_unique_indices():
    """Fail the build if two objects or two materials share a pass index > 0."""
    for coll, kind in ((bpy.data.objects, "object"), (bpy.data.materials, "material")):
        seen = {}
        for item in coll:
            idx = getattr(item, "pass_index", 0)
            if idx > 0:
                if idx in seen:
                    raise RuntimeError("%s pass_index %d used by %s and %s"
                                       % (kind, idx, seen[idx], item.name))
                seen[idx] = item.name


def print_index_table():
    print("| kind | name | pass_index |")
    print("|---|---|---|")
    for o in sorted(bpy.data.objects, key=lambda o: (o.pass_index, o.name)):
        if o.type == 'MESH':
            print("| object | `%s` | %d |" % (o.name, o.pass_index))
    for m in sorted(bpy.data.materials, key=lambda m: (m.pass_index, m.name)):
        print("| material | `%s` | %d |" % (m.name, m.pass_index))


def run_main(main):
    """Run a script's main() under `blender -b --python`; exit non-zero on failure
    (exceptions there otherwise still exit 0): 2 for a usage error (SystemExit with a
    message), 1 for anything else."""
    import sys
    import traceback
    try:
        main()
    except SystemExit as e:
        if e.code in (None, 0):
            return
        print(e)
        sys.stdout.flush()
        os._exit(2)
    except Exception:
        traceback.print_exc()
        sys.stdout.flush()
        os._exit(1)
