"""Auxiliary views: depth renders from a light (shadow maps) and from above (rain map).

The library says which views the stack needs (fx_stack_required_aux_views): this
module renders exactly those, and nothing when the stack needs none.  Each view
is a Cycles depth render (1 sample, Depth pass through a File Output node) of a
temporary scene that links the objects which cast shadows (``visible_shadow``;
the rain covers do not), so alpha-clipped leaves are discarded by Cycles' pass
alpha threshold exactly as in the main render and cast leaf-shaped shadows.

- ``light:<name>``: a sun gets an orthographic view along its direction, a spot
  a perspective one from its position.  Extent: the scene's shadow casters'
  bounding box intersected with the union of the camera frusta over the frames
  being rendered, seen from the light; depth range: the casters' box (tight, for
  VSM precision).  Resolution: from the render's size (max(W, H) * 1.5 rounded to
  64, 256..4096) or the scene's ID property ``libfx_light_map_size``.
- ``rain_map``: orthographic, straight down, over the same region in XY, ~5 cm
  texels (128..2048) or ``libfx_rain_map_size``.
- ``water:<material>`` (voronoi_caustics' mode refractive): the objects that use the
  material <material> (also those hidden from the render or from the camera: a scene
  often hides its water so that the floor below is in plain sunlight) seen from the
  scene's first sun, orthographic, Normal and Depth passes, nothing else linked.
  Extent: the water's box seen from the sun, cut to the receivers the cameras see
  widened by the water's height above them (refracted light comes from beside a
  point, not only from straight up the sun's direction); resolution as a light view
  (``libfx_water_map_size`` overrides it).

- ``probe:<key>``: a reflection probe for one mirror entry (the view lists the
  entry's mask): an equirectangular panorama (Cycles PANO camera, 512x256 or
  ``libfx_probe_size`` wide, ``libfx_probe_samples`` samples (16 at most by
  default), colour with the scene's indirect light + radial Depth) of the whole
  scene with the mirror's objects rendered as perfect mirrors (so each mirror of a
  facing pair sees the other one's reflections).  Placed at the
  reflection-cubemap Light Probe nearest the mirror if the scene has one, else
  at the centre of the mirror objects' bounding box pushed out past their front
  along their mean normal (towards the camera); a mirror whose planes face
  different ways (a facing pair in one entry) gets one probe per plane, each
  before its own plane (``probe:<key>``, ``probe:<key>#2``, ...: probe_specs).
  Each probe also carries a ``Sky`` layer: the world alone (a second view layer
  without the objects, 4 samples), the sky a ray meets where a wall hides it from
  the probe.  A probe that fails to render is a warning: the run goes on and
  ssr_mirror takes its texture fallback.
- ``planar:<key>``: for a mirror whose faces lie in a few planes (a flat mirror: one;
  a facing pair in one entry: two; at most PLANAR_MAX), one view per plane
  (``planar:<key>``, ``planar:<key>#2``, ...): the scene seen by the camera mirrored
  in that plane (ssr_mirror's ``planar_view``: the ``final`` and ``reference`` presets), at the
  render's size and samples times the need's samples_scale (ssr_mirror's planar_samples:
  2 at final, 4 at reference; or ``libfx_planar_samples``), only over the
  plane's mirror (a render border, the file cropped to it: planar_border, planar_window;
  the entry's "window" places it in the view), colour + Depth,
  with every mirror entry's objects as perfect mirrors (the other plane's mirror reflects
  the room again; stack_mirrors) and the plane's own mirror objects and the objects
  wholly behind the plane hidden from the camera (they still cast shadows and bounce
  light); each entry carries its plane and ssr_mirror looks each pixel up in its own
  plane's view. A mirror that is not flat (a curved one) gets no view: a log line, and
  the sidecar lists the view as absent with the reason (ssr_mirror keeps the trace and
  the probe there, without a warning).

A view is rendered once and reused while its signature (camera, resolution, the
light, every linked object's transform, mesh size and materials) does not
change: frames 2..N of a batch cost no extra render.  Log lines say which.
"""

import hashlib
import json
import math
import os
import struct
import time

import bpy
from mathutils import Euler, Matrix, Vector

from . import compat, native, recipe, scene_setup
from .log import log

AUX_SCENE = "libfx aux view"
BUSY = {"on": False}   # while an aux view renders here (busy())
PROBES_MAX = 4         # probes per mirror entry (ssr_mirror's PROBES_MAX)
PROBE_SKY_LAYER = "Sky"  # a probe's layer of the world alone (math/panorama.h, fx_pano.sky)
SKY_SAMPLES = 4        # the world alone is smooth: a few samples per texel anti-alias it


def busy():
    """Whether an aux view is rendering now: the render handlers ignore its renders."""
    return BUSY["on"]


def needed(scene):
    """[{"name", "kind", "light"?}] the scene's stack needs (library's answer)."""
    if not scene_setup.has_stack(scene) or native.load() is None:
        return []
    if not native.has("aux_views"):
        log(native.feature_problem("aux_views"))
        return []
    return scene_setup.answers(recipe.to_recipe(scene))["aux_views"]


# ---------------------------------------------------------------- geometry

def casters(scene):
    out = []
    for ob in scene.objects:
        if ob.type not in ("MESH", "CURVE", "SURFACE", "META", "FONT") or ob.hide_render:
            continue
        if not getattr(ob, "visible_shadow", True):
            continue  # camera-only helpers (the rain covers)
        out.append(ob)
    return sorted(out, key=lambda o: o.name)


def world_box(objs):
    lo = Vector((math.inf,) * 3)
    hi = Vector((-math.inf,) * 3)
    for ob in objs:
        for c in ob.bound_box:
            p = ob.matrix_world @ Vector(c)
            lo = Vector(map(min, lo, p))
            hi = Vector(map(max, hi, p))
    return lo, hi


def frustum_points(scene, cam_ob, far):
    """World corners of the camera frustum from clip_start to `far`."""
    data = cam_ob.data
    frame = data.view_frame(scene=scene)  # 4 points at distance 1 (perspective) in camera space
    mw = cam_ob.matrix_world
    pts = []
    if data.type == "ORTHO":
        for c in frame:
            for z in (-data.clip_start, -far):
                pts.append(mw @ Vector((c.x, c.y, z)))
    else:
        for c in frame:
            for d in (data.clip_start, far):
                s = d / max(1e-6, -c.z)
                pts.append(mw @ Vector((c.x * s, c.y * s, -d)))
    return pts


def frusta_box(scene, frames, geo_lo, geo_hi):
    """World AABB of the camera frusta over `frames`, clipped to the geometry box."""
    cam = scene.camera
    if cam is None:
        return geo_lo, geo_hi
    keep = scene.frame_current
    pts = []
    diag = (geo_hi - geo_lo).length
    for f in frames:
        scene.frame_set(f)
        far = min(cam.data.clip_end, (cam.matrix_world.translation - (geo_lo + geo_hi) / 2).length + diag)
        pts += frustum_points(scene, cam, far)
    scene.frame_set(keep)
    lo = Vector(map(max, geo_lo, Vector(map(min, zip(*pts))))) if pts else geo_lo
    hi = Vector(map(min, geo_hi, Vector(map(max, zip(*pts))))) if pts else geo_hi
    if any(lo[i] >= hi[i] for i in range(3)):
        return geo_lo, geo_hi
    return lo, hi


def box_corners(lo, hi):
    return [Vector((x, y, z)) for x in (lo.x, hi.x) for y in (lo.y, hi.y) for z in (lo.z, hi.z)]


def ortho_projection(half_x, half_y, near, far):
    return [[1.0 / half_x, 0, 0, 0], [0, 1.0 / half_y, 0, 0],
            [0, 0, -2.0 / (far - near), -(far + near) / (far - near)], [0, 0, 0, 1]]


def _round64(v, lo, hi):
    return int(max(lo, min(hi, 64 * math.ceil(v / 64.0))))


def view_spec(scene, view, frames, objs):
    """Camera matrices, resolution and the camera object's placement for one view."""
    geo_lo, geo_hi = world_box(objs)
    reg_lo, reg_hi = frusta_box(scene, frames, geo_lo, geo_hi)
    r = scene.render
    rw = int(r.resolution_x * r.resolution_percentage / 100)
    rh = int(r.resolution_y * r.resolution_percentage / 100)
    if view["kind"] == "rain_map":
        rot = Matrix.Identity(3)                      # looks down -Z
        ext = Vector((reg_hi.x - reg_lo.x, reg_hi.y - reg_lo.y))
        centre = Vector(((reg_lo.x + reg_hi.x) / 2, (reg_lo.y + reg_hi.y) / 2, geo_hi.z + 1.0))
        near, far = 0.5, geo_hi.z - geo_lo.z + 2.0
        size = scene.get("libfx_rain_map_size") or _round64(max(ext) / 0.05, 128, 2048)
        light = None
    else:
        lname = view.get("light") or ""
        light = None
        for ob in scene.objects:
            if ob.type == "LIGHT" and not ob.hide_render and (ob.name == lname or (not lname and ob.data.type == "SUN")):
                light = ob
                break
        if light is None:
            raise native.LibfxError("the stack needs the light view '%s' but the scene has no such light" % view["name"])
        if light.data.type != "SUN":
            raise native.LibfxError("light views are made for sun lights only so far ('%s' is %s)"
                                    % (light.name, light.data.type))
        d = -light.matrix_world.col[2].xyz.normalized()
        rot = d.to_track_quat('-Z', 'Y').to_matrix()
        inv = rot.transposed()
        # receivers: the region the cameras see; casters: the whole geometry box
        rc = [inv @ p for p in box_corners(reg_lo, reg_hi)]
        gc = [inv @ p for p in box_corners(geo_lo, geo_hi)]
        lo = Vector(map(min, zip(*rc)))
        hi = Vector(map(max, zip(*rc)))
        zmax = max(p.z for p in gc) + 1.0            # nearest caster to the light (view looks down -Z)
        zmin = min(p.z for p in gc) - 1.0
        ext = Vector((hi.x - lo.x, hi.y - lo.y))
        centre = rot @ Vector(((lo.x + hi.x) / 2, (lo.y + hi.y) / 2, zmax + 0.5))
        near, far = 0.5, zmax - zmin + 0.5
        size = scene.get("libfx_light_map_size") or _round64(max(rw, rh) * 1.5, 256, 4096)
    size = int(size)
    if ext.x >= ext.y:
        w, h = size, max(16, int(round(size * ext.y / max(ext.x, 1e-6))))
        half_x = ext.x / 2 * 1.02
        half_y = half_x * h / w
    else:
        h, w = size, max(16, int(round(size * ext.x / max(ext.y, 1e-6))))
        half_y = ext.y / 2 * 1.02
        half_x = half_y * w / h
    mw = Matrix.Translation(centre) @ rot.to_4x4()
    return {
        "name": view["name"], "kind": view["kind"], "width": w, "height": h,
        "matrix_world": [list(row) for row in mw],
        "world_to_camera": [list(row) for row in mw.inverted()],
        "projection": ortho_projection(half_x, half_y, near, far),
        "clip_start": near, "clip_end": far, "orthographic": True,
        "ortho_scale": 2 * max(half_x, half_y),
        "light": None if light is None else [light.name, [list(r) for r in light.matrix_world]],
    }


def signature(spec, objs):
    geo = []
    for ob in objs:
        me = ob.data
        geo.append([ob.name, [round(v, 5) for row in ob.matrix_world for v in row],
                    len(getattr(me, "vertices", [])), len(getattr(me, "polygons", [])),
                    [s.material.name if s.material else "" for s in ob.material_slots]])
    text = json.dumps([{k: v for k, v in spec.items()}, geo], sort_keys=True, default=str)
    return hashlib.sha1(text.encode("utf-8")).hexdigest()


# ---------------------------------------------------------------- render

def _render_view(scene, aux, path, passes, what, layer_passes=()):
    """Renders the aux scene and moves the EXR its File Output node wrote to path (32-bit
    multilayer, uncompressed: the mirror room's first frame at final reads its ten probes in
    0.1 G instructions instead of 0.93 G with ZIP; callgrind, docs/effects/ssr_mirror.md).
    passes: [(EXR layer name, render pass)] of the aux scene's first view layer;
    layer_passes: [(EXR layer name, view layer name, render pass)] of its other view layers;
    `what` names the view in errors."""
    nt, made = compat.ensure_compositor_tree(aux, AUX_SCENE)
    try:
        rl = next(n for n in nt.nodes if n.bl_idname == "CompositorNodeRLayers")
        rl.scene = aux
        sources = [(name, compat.render_layer_output(rl, p)) for name, p in passes]
        for name, layer, p in layer_passes:
            other = nt.nodes.new("CompositorNodeRLayers")
            other.scene = aux
            other.layer = layer
            sources.append((name, compat.render_layer_output(other, p)))
        fo = nt.nodes.new("CompositorNodeOutputFile")
        compat.file_output_format(fo, "OPEN_EXR_MULTILAYER", "32", "NONE")
        base = path[:-len(".exr")] + ".tmp."
        compat.file_output_set_prefix(fo, base)
        compat.file_output_link(nt, fo, sources)
        BUSY["on"] = True
        try:
            bpy.ops.render.render(write_still=False, scene=aux.name)
        finally:
            BUSY["on"] = False
        # the File Output node numbers the file with the frame of the scene the render was
        # started from (frame 8 of a batch gives .0008.exr), not the aux scene's frame 1
        written = None
        for f in (scene.frame_current, 1):
            if os.path.exists(base + "%04d.exr" % f):
                written = base + "%04d.exr" % f
                break
        if written is None:
            import glob
            found = sorted(glob.glob(glob.escape(base) + "[0-9]*.exr"))
            written = found[-1] if found else base + "0001.exr"
        if not os.path.exists(written):
            raise native.LibfxError("%s wrote no file (%s)" % (what, written))
        os.replace(written, path)
    finally:
        compat.release_compositor_tree(aux, made)


def _place_ortho_camera(aux, cam, spec):
    """The aux scene's camera as the orthographic view spec describes (light and water views)."""
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = spec["ortho_scale"]
    cam.data.sensor_fit = "HORIZONTAL" if spec["width"] >= spec["height"] else "VERTICAL"
    cam.data.clip_start = spec["clip_start"]
    cam.data.clip_end = spec["clip_end"]
    cam.matrix_world = Matrix(spec["matrix_world"])
    aux.camera = cam


def _render(scene, spec, objs, path):
    aux = bpy.data.scenes.new(AUX_SCENE)
    cam_data = bpy.data.cameras.new(AUX_SCENE)
    cam = bpy.data.objects.new(AUX_SCENE, cam_data)
    try:
        for ob in objs:
            aux.collection.objects.link(ob)
        aux.collection.objects.link(cam)
        _place_ortho_camera(aux, cam, spec)
        aux.world = scene.world
        r = aux.render
        r.engine = "CYCLES"
        r.resolution_x, r.resolution_y, r.resolution_percentage = spec["width"], spec["height"], 100
        r.use_compositing = True
        r.filepath = os.path.join(os.path.dirname(path), "")
        aux.cycles.samples = 1
        aux.cycles.use_adaptive_sampling = False
        aux.cycles.use_denoising = False
        aux.cycles.max_bounces = 0
        aux.cycles.transparent_max_bounces = scene.cycles.transparent_max_bounces
        aux.cycles.filter_width = 0.01            # one sample at each texel's centre
        aux.cycles.seed = 0
        aux.frame_start = aux.frame_end = aux.frame_current = 1
        vl = aux.view_layers[0]
        vl.use_pass_z = True
        _render_view(scene, aux, path, [("Depth", "Depth")], "the aux view render of '%s'" % spec["name"])
    finally:
        bpy.data.scenes.remove(aux)
        bpy.data.objects.remove(cam)
        bpy.data.cameras.remove(cam_data)


# ---------------------------------------------------------------- probes

def mask_objects(scene, mask):
    """The scene's objects a stack mask selects by name or index (materials, objects);
    rectangles and inversion cannot place a probe and are ignored."""
    mats = set(mask.get("material") or [])
    obs = set(mask.get("object") or [])
    mat_idx = set(mask.get("material_index") or [])
    ob_idx = set(mask.get("object_index") or [])
    out = []
    for ob in scene.objects:
        if ob.type != "MESH" or ob.hide_render:
            continue
        slots = [sl.material for sl in ob.material_slots if sl.material]
        if (ob.name in obs or ob.pass_index in ob_idx or any(m.name in mats for m in slots)
                or any(m.pass_index in mat_idx for m in slots)):
            out.append(ob)
    return sorted(out, key=lambda o: o.name)


def _mirror_faces(objs, mats):
    """World (centre, area-weighted normal, area) of the mirror's faces (those with a
    mirror material, or all faces of an object named by the mask)."""
    faces = []
    for ob in objs:
        me = ob.data
        mw = ob.matrix_world
        nm = mw.to_3x3().inverted_safe().transposed()
        slot_mat = [sl.material.name if sl.material else "" for sl in ob.material_slots]
        for poly in me.polygons:
            if mats and slot_mat and poly.material_index < len(slot_mat) and slot_mat[poly.material_index] not in mats:
                continue
            n = (nm @ poly.normal).normalized()
            faces.append((mw @ poly.center, n, poly.area))
    return faces


def _mirror_normals(ob, mats):
    """The mesh-space normals of ob's faces that _mirror_faces([ob], mats) lists, in its order."""
    slot_mat = [sl.material.name if sl.material else "" for sl in ob.material_slots]
    return [poly.normal for poly in ob.data.polygons
            if not (mats and slot_mat and poly.material_index < len(slot_mat)
                    and slot_mat[poly.material_index] not in mats)]


def stack_mirrors(scene, views):
    """The objects of every mirror entry of the stack (the masks of its probe and planar
    needs): the views show them all as perfect mirrors, as the truth renders show the
    sharp kinds (make_mirror_reference.py); with their own materials, the pair's planar
    views showed the opposite wall's mirrors as their grey backing."""
    names = set()
    for v in views:
        if v["kind"] in ("probe", "planar"):
            names.update(o.name for o in mask_objects(scene, v.get("mask") or {}))
    return sorted(names)


def probe_spec(scene, view, mirrors=()):
    """Where the probe of `view` goes, its size and its camera matrices; it shows its
    entry's objects and `mirrors` (stack_mirrors) as perfect mirrors."""
    mask = view.get("mask") or {}
    objs = mask_objects(scene, mask)
    cam = scene.camera
    cam_pos = cam.matrix_world.translation if cam else Vector((0, 0, 0))
    if objs:
        lo, hi = world_box(objs)
        centre = (lo + hi) / 2
        faces = _mirror_faces(objs, set(mask.get("material") or []))
        n = Vector((0, 0, 0))
        for c, fn, area in faces:
            # each face's normal turned to the camera's side: a pair facing each other
            # cancels out (the probe stays in the room between them)
            n += fn * area * (1.0 if fn.dot(cam_pos - c) >= 0 else -1.0)
        size = (hi - lo).length
        if n.length > 1e-6 * max(1e-6, size * size):
            n.normalize()
            front = max([(c - centre).dot(n) for c, _, _ in faces] + [0.0])
            pos = centre + n * (front + min(1.0, max(0.1, 0.15 * size)))
        else:
            pos = centre
        where = "the mirror (%s)" % ", ".join(o.name for o in objs[:4])
    else:
        centre = pos = Vector(cam_pos)
        where = "the camera (the mask names no object)"
    probes = [ob for ob in scene.objects if compat.is_reflection_probe(ob) and not ob.hide_render]
    if probes and objs:
        ob = min(probes, key=lambda o: ((o.matrix_world.translation - centre).length, o.name))
        pos = ob.matrix_world.translation.copy()
        where = "the Light Probe '%s'" % ob.name
    width = int(scene.get("libfx_probe_size") or 512)
    width = max(16, width + width % 2)
    samples = int(scene.get("libfx_probe_samples") or min(16, max(1, scene.cycles.samples)))
    # looks along world +Y, up +Z (any rotation would do: the matrix goes to the library)
    mw = Matrix.Translation(pos) @ Euler((math.pi / 2, 0.0, 0.0)).to_matrix().to_4x4()
    clip_end = cam.data.clip_end if cam else 1000.0
    return {
        "name": view["name"], "kind": "probe", "width": width, "height": width // 2, "samples": samples,
        "matrix_world": [list(row) for row in mw], "world_to_camera": [list(row) for row in mw.inverted()],
        "clip_start": 0.0, "clip_end": clip_end, "hidden": [o.name for o in objs], "where": where,
        "mirrors": sorted({o.name for o in objs} | set(mirrors)),   # shown as perfect mirrors
        "sky": PROBE_SKY_LAYER,  # the world alone as a second layer (part of the signature)
    }


def probe_specs(scene, view, mirrors=()):
    """The probes of a need: one (probe_spec), or, for a mirror whose planes face different
    ways (a facing pair in one entry: the single probe would sit between them, in the
    room's middle, far from what either mirror's rays start from), one per plane, each
    placed before its own plane as a single flat mirror's probe is ("probe:<key>",
    "probe:<key>#2", ...; ssr_mirror takes for each mirror point the nearest probe in front
    of it). A curved mirror, a Light Probe in the scene, or planes that face one way keep
    the one probe."""
    base = probe_spec(scene, view, mirrors)
    mask = view.get("mask") or {}
    objs = mask_objects(scene, mask)
    cam = scene.camera
    if not objs or cam is None or base["where"].startswith("the Light Probe"):
        return [base]
    mats = set(mask.get("material") or [])
    try:
        planes = _planes(objs, mats, cam.matrix_world.translation)
    except NotPlanar:
        return [base]
    if len(planes) < 2 or all(p[0].dot(planes[0][0]) > 0.5 for p in planes):
        return [base]
    specs = []
    for k, (n, d, _, names) in enumerate(planes[:PROBES_MAX]):
        on = [o for o in objs if o.name in names]
        faces = [f for f in _mirror_faces(on, mats) if f[1].dot(n) > 0.999]
        area = sum(f[2] for f in faces)
        if not faces or area <= 0:
            return [base]
        centre = sum((f[0] * f[2] for f in faces), Vector((0, 0, 0))) / area
        lo, hi = world_box(on)
        size = (hi - lo).length
        pos = centre + n * min(1.0, max(0.1, 0.15 * size))
        mw = Matrix.Translation(pos) @ Euler((math.pi / 2, 0.0, 0.0)).to_matrix().to_4x4()
        specs.append(dict(base, name=planar_view_name(view["name"], k), where="the mirror plane of %s"
                          % ", ".join(names[:4]), matrix_world=[list(row) for row in mw],
                          world_to_camera=[list(row) for row in mw.inverted()]))
    return specs


def _probe_scene_objects(scene):
    return sorted([ob for ob in scene.objects if ob.type != "CAMERA" and not ob.hide_render],
                  key=lambda o: o.name)


def _probe_signature(scene, spec, objs):
    lights = []
    for ob in objs:
        if ob.type == "LIGHT":
            d = ob.data
            lights.append([ob.name, d.type, round(d.energy, 5), [round(c, 5) for c in d.color]])
    world = scene.world.name if scene.world else ""
    return signature(dict(spec, lights=lights, world=world, engine_samples=scene.cycles.max_bounces), objs)


PROBE_MIRROR = "libfx probe mirror"


def _probe_mirror_material():
    """A perfect white mirror (sharp Glossy BSDF) for the mirrors a probe sees."""
    mat = bpy.data.materials.get(PROBE_MIRROR)
    if mat is None:
        mat = bpy.data.materials.new(PROBE_MIRROR)
        mat.use_nodes = True
        nt = mat.node_tree
        for n in list(nt.nodes):
            nt.nodes.remove(n)
        g = nt.nodes.new("ShaderNodeBsdfGlossy")
        g.inputs["Color"].default_value = (1, 1, 1, 1)
        g.inputs["Roughness"].default_value = 0.0
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        nt.links.new(g.outputs[0], out.inputs[0])
    return mat


def _render_probe(scene, spec, objs, path, sky=True):
    """Renders the probe or planar view `spec` of objs to path; sky=False leaves out a
    probe's Sky layer (only to measure what it costs: tests/bench/bench_probe_sky.py)."""
    aux = bpy.data.scenes.new(AUX_SCENE)
    cam_data = bpy.data.cameras.new(AUX_SCENE)
    cam = bpy.data.objects.new(AUX_SCENE, cam_data)
    # the objects in a collection of their own, which a probe's second view layer leaves
    # out: that layer is the world alone (the sky a ray meets after passing over a wall
    # that hides that part of the sky from the probe; math/panorama.h, fx_pano.sky)
    coll = bpy.data.collections.new(AUX_SCENE)
    hidden = []
    swapped = []
    try:
        aux.collection.children.link(coll)
        for ob in objs:
            coll.objects.link(ob)
        aux.collection.objects.link(cam)
        layer_passes = []
        if spec["kind"] == "probe" and sky:
            vl_sky = aux.view_layers.new(PROBE_SKY_LAYER)
            vl_sky.layer_collection.children[coll.name].exclude = True
            if hasattr(vl_sky, "samples"):
                vl_sky.samples = min(SKY_SAMPLES, spec["samples"])
            layer_passes = [(PROBE_SKY_LAYER, vl_sky.name, "Combined")]
        if spec["kind"] == "probe":
            compat.set_equirect_camera(cam_data)
            cam_data.clip_start = 0.01
        else:  # planar: the main camera's lens, mirrored (x flipped: the shift too)
            src = scene.camera.data
            for k in ("type", "lens", "lens_unit", "sensor_width", "sensor_height", "sensor_fit", "shift_y",
                      "ortho_scale"):
                setattr(cam_data, k, getattr(src, k))
            cam_data.shift_x = -src.shift_x
            cam_data.clip_start = spec["clip_start"]
        cam_data.clip_end = spec["clip_end"]
        cam.matrix_world = Matrix(spec["matrix_world"])
        # the views see the stack's mirrors as perfect mirrors: a mirror of a facing pair
        # reflects the other one (and what that one reflects), the opposite wall's mirrors
        # reflect the room; a flat or convex mirror never looks up its own direction; the
        # room is lit with the mirrors in it, as in Cycles
        shown = set(spec.get("mirrors") or ()) | (set(spec["hidden"]) if spec["kind"] == "probe" else set())
        for name in sorted(shown):
            ob = bpy.data.objects.get(name)
            if ob is None:
                continue
            swapped.append((ob, [sl.material for sl in ob.material_slots], ob.data.materials[:]))
            mat = _probe_mirror_material()
            if not ob.material_slots:
                ob.data.materials.append(mat)
            for sl in ob.material_slots:
                sl.material = mat
        for name in spec["hidden"] + spec.get("behind", []) if spec["kind"] == "planar" else []:
            ob = bpy.data.objects.get(name)
            if ob is not None and ob.visible_camera:
                # a planar view shows the room, not its own plane's mirror, and not what stands
                # behind that plane (still there for shadows and bounce light)
                ob.visible_camera = False
                hidden.append(ob)
        aux.camera = cam
        aux.world = scene.world
        r = aux.render
        r.engine = "CYCLES"
        r.resolution_x, r.resolution_y, r.resolution_percentage = spec["width"], spec["height"], 100
        if spec.get("border"):   # a planar view: only the mirror's region is looked up, cropped
            r.use_border, r.use_crop_to_border = True, True
            r.border_min_x, r.border_min_y, r.border_max_x, r.border_max_y = spec["border"]
        r.film_transparent = False
        r.use_compositing = True
        r.filepath = os.path.join(os.path.dirname(path), "")
        c, sc = aux.cycles, scene.cycles
        c.samples = spec["samples"]
        c.use_adaptive_sampling = False
        c.use_denoising = False
        for k in ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces",
                  "volume_bounces", "transparent_max_bounces", "sample_clamp_indirect",
                  "sample_clamp_direct", "blur_glossy", "caustics_reflective", "caustics_refractive"):
            if hasattr(sc, k):
                setattr(c, k, getattr(sc, k))
        c.seed = 0
        aux.frame_start = aux.frame_end = aux.frame_current = 1
        vl = aux.view_layers[0]
        vl.use_pass_z = True
        _render_view(scene, aux, path, [("Image", "Combined"), ("Depth", "Depth")],
                     "the %s render '%s'" % (spec["kind"], spec["name"]), layer_passes)
        if spec.get("border"):
            got = _exr_size(path)
            if list(got) != spec["crop"][2:]:
                os.remove(path)
                raise RuntimeError("the render cropped to its border is %dx%d, not the %dx%d at %s it was set to"
                                   % (got[0], got[1], spec["crop"][2], spec["crop"][3], spec["crop"][:2]))
    finally:
        for ob in hidden:
            ob.visible_camera = True
        for ob, slot_mats, data_mats in swapped:
            if len(ob.data.materials) > len(data_mats):
                ob.data.materials.pop()
            for sl, m in zip(ob.material_slots, slot_mats):
                sl.material = m
        bpy.data.scenes.remove(aux)
        bpy.data.collections.remove(coll)
        bpy.data.objects.remove(cam)
        bpy.data.cameras.remove(cam_data)


class NotPlanar(Exception):
    pass


PLANAR_MAX = 4   # planar views per mirror entry (ssr_mirror looks up at most this many)


def planar_view_name(name, k):
    """The k-th plane's view of the need `name` ("planar:<key>"): the first plane keeps the
    need's name, the others are "planar:<key>#2", "#3", ... (ssr_mirror loads them in turn)."""
    return name if k == 0 else "%s#%d" % (name, k + 1)


def _planes(objs, mats, cam_pos):
    """The planes of a mirror's faces that the camera sees: [(n, d, area, objects)], the
    largest first. Faces are grouped by normal (within 2.6 deg) and offset; groups under
    10 % of the seen area (a slab's edges) are left out; NotPlanar when the planes leave
    more than 10 % of it (a curved mirror) or there are more than PLANAR_MAX."""
    faces = []
    for ob in objs:
        m3 = ob.matrix_world.to_3x3()
        # _mirror_faces' areas are the mesh's own: a scaled object's faces grow by
        # |det M| |M^-T n| in the world (a slab made by scaling a cube)
        det = abs(m3.determinant())
        nm = m3.inverted_safe().transposed()
        for (fc, fn, area), n0 in zip(_mirror_faces([ob], mats), _mirror_normals(ob, mats)):
            k = det * (nm @ n0).length
            if abs(k - 1.0) > 1e-4:   # (an unscaled object's areas stay bit for bit)
                area *= k
            if fn.dot(cam_pos - fc) > 0:   # a slab's back face reflects nothing the camera sees
                faces.append((fc, fn, area, ob))
    if not faces:
        raise NotPlanar("the camera sees none of its faces")
    lo, hi = world_box(objs)
    tol = 0.01 + 0.002 * (hi - lo).length
    groups = []   # [n, [faces]]: n the first (largest) face's normal
    for f in sorted(faces, key=lambda f: -f[2]):
        for g in groups:
            if f[1].dot(g[0]) > 0.999 and abs((f[0] - g[1][0][0]).dot(g[0])) <= tol:
                g[1].append(f)
                break
        else:
            groups.append([f[1], [f]])
    total = sum(f[2] for f in faces)
    out = []
    for _, fs in groups:
        area = sum(f[2] for f in fs)
        if area < 0.1 * total:
            continue
        n = Vector((0, 0, 0))
        c = Vector((0, 0, 0))
        for fc, fn, a, _ in fs:
            n += fn * a
            c += fc * a
        if n.length < 1e-12:
            continue
        n.normalize()
        c /= area
        if any(abs((fc - c).dot(n)) > tol for fc, _, _, _ in fs):
            raise NotPlanar("its faces lie in parallel planes, not one")
        out.append((n, n.dot(c), area, sorted({f[3].name for f in fs})))
    if not out or sum(o[2] for o in out) < 0.9 * total:
        raise NotPlanar("its faces do not lie in a few planes (a curved mirror?)")
    if len(out) > PLANAR_MAX:
        raise NotPlanar("its faces lie in %d planes (at most %d planar views)" % (len(out), PLANAR_MAX))
    out.sort(key=lambda o: -o[2])
    return out


PLANAR_BORDER_PX = 4   # around a planar view's region: its bilinear lookups' neighbours, and rounding


def planar_border(objs, world_to_camera, proj, width, height):
    """The part of a planar view that ssr_mirror looks up: the box [x0, y0, x1, y1] (0..1,
    from the bottom left, Blender's render border) around the mirror objects' bounding
    boxes as the view's camera sees them, PLANAR_BORDER_PX wider each way; None (the whole
    view) when a corner is not in front of that camera or the box covers most of the view.
    The view renders only this region (Cycles' border, cropped to it: planar_window; its
    pixels are the whole view's): on the mirror truth scenes 1.1-3.7x faster than the
    whole view."""
    xs, ys = [], []
    for ob in objs:
        for c in ob.bound_box:
            q = world_to_camera @ (ob.matrix_world @ Vector(c)).to_4d()
            h = proj @ q
            if not (h.w > 1e-6):
                return None
            xs.append(0.5 * (h.x / h.w + 1.0))
            ys.append(0.5 * (h.y / h.w + 1.0))
    if not xs:
        return None
    mx, my = PLANAR_BORDER_PX / max(1, width), PLANAR_BORDER_PX / max(1, height)
    box = [max(0.0, min(xs) - mx), max(0.0, min(ys) - my), min(1.0, max(xs) + mx), min(1.0, max(ys) + my)]
    if not (box[0] < box[2] and box[1] < box[3]):
        return None   # off the view: nothing there to look up, and an empty border is no render
    if (box[2] - box[0]) * (box[3] - box[1]) > 0.8:
        return None
    return box


def planar_window(border, width, height):
    """The render border `border` (planar_border) widened to whole pixels: (the border to
    give Cycles, [x0, y0, w, h]: the w x h pixels from column x0 and row y0 (top down) of
    the width x height view that the render cropped to it holds). Each edge sits a quarter
    pixel inside its pixel, so Blender's border-to-pixel conversion gives that pixel whether
    it truncates or rounds; _render_probe checks the size."""
    x0, x1 = int(math.floor(border[0] * width)), min(width, int(math.ceil(border[2] * width)))
    y0, y1 = int(math.floor(border[1] * height)), min(height, int(math.ceil(border[3] * height)))

    def edge(p, n):
        return 1.0 if p >= n else (p + 0.25) / n
    return ([edge(x0, width), edge(y0, height), edge(x1, width), edge(y1, height)],
            [x0, height - y1, x1 - x0, y1 - y0])


def _exr_size(path):
    """(width, height) of an EXR's data window, from its header (Blender writes one part)."""
    with open(path, "rb") as f:
        head = f.read(1 << 16)
    if head[:4] != b"\x76\x2f\x31\x01":
        raise ValueError("%s is not an OpenEXR file" % path)
    pos = 8
    while True:
        end = head.index(b"\0", pos)
        name, pos = head[pos:end], end + 1
        if not name:
            raise ValueError("%s has no dataWindow" % path)
        end = head.index(b"\0", pos)
        pos = end + 1
        size = struct.unpack_from("<i", head, pos)[0]
        pos += 4
        if name == b"dataWindow":
            x0, y0, x1, y1 = struct.unpack_from("<4i", head, pos)
            return x1 - x0 + 1, y1 - y0 + 1
        pos += size


def planar_samples(scene, view):
    """A planar view's samples per pixel: the need's samples_scale (ssr_mirror's
    planar_samples: 2 at final, 4 at reference) times the render's, or the scene's
    libfx_planar_samples."""
    scale = float(view.get("samples_scale") or 1.0)
    return int(scene.get("libfx_planar_samples") or max(1, round(scale * max(1, scene.cycles.samples))))


def planar_specs(scene, view, mirrors=()):
    """One mirrored camera per plane of the mirror (a flat mirror: one; a facing pair in
    one entry: two): its matrices, the plane, what it hides. Each view shows the entry's
    mirrors and `mirrors` (stack_mirrors) as perfect mirrors (the other plane's mirror
    reflects the room again, as Cycles' mirror does) and hides from its camera the mirror
    objects on its own plane and what stands wholly behind that plane."""
    mask = view.get("mask") or {}
    objs = mask_objects(scene, mask)
    cam = scene.camera
    if not objs or cam is None:
        raise NotPlanar("the mask names no object" if cam else "the scene has no camera")
    cam_pos = cam.matrix_world.translation
    planes = _planes(objs, set(mask.get("material") or []), cam_pos)
    r = scene.render
    rw = int(r.resolution_x * r.resolution_percentage / 100)
    rh = int(r.resolution_y * r.resolution_percentage / 100)
    proj = cam.calc_matrix_camera(bpy.context.evaluated_depsgraph_get(), x=rw, y=rh, scale_x=r.pixel_aspect_x,
                                  scale_y=r.pixel_aspect_y)
    proj = [list(row) for row in proj]
    proj[0][2] = -proj[0][2]                          # the lens shift, mirrored with x
    samples = planar_samples(scene, view)
    specs = []
    for k, (n, d, _, on_plane) in enumerate(planes):
        if n.dot(cam_pos) - d <= 0:
            raise NotPlanar("the camera is behind its plane")
        S = Matrix.Identity(3)
        for i in range(3):
            for j in range(3):
                S[i][j] -= 2.0 * n[i] * n[j]
        R = cam.matrix_world.to_3x3().normalized()
        e2 = cam_pos - 2.0 * (cam_pos.dot(n) - d) * n
        R2 = S @ R @ Matrix.Diagonal((-1.0, 1.0, 1.0))   # a proper rotation: the image is mirrored
        mw = Matrix.Translation(e2) @ R2.to_4x4()
        behind = []
        for ob in scene.objects:
            if ob.type in ("MESH", "CURVE", "SURFACE", "META", "FONT") and ob not in objs:
                corners = [ob.matrix_world @ Vector(v) for v in ob.bound_box]
                if all(n.dot(p) - d < -1e-4 for p in corners):
                    behind.append(ob.name)
        border = planar_border([bpy.data.objects[name] for name in on_plane], mw.inverted(), Matrix(proj), rw, rh)
        crop = None
        if border:   # rendered cropped to whole pixels: the file holds the region only
            border, crop = planar_window(border, rw, rh)
        specs.append({
            "name": planar_view_name(view["name"], k), "kind": "planar", "width": rw, "height": rh,
            "samples": samples, "matrix_world": [list(row) for row in mw],
            "world_to_camera": [list(row) for row in mw.inverted()], "projection": proj, "border": border,
            "crop": crop,
            "clip_start": float(cam.data.clip_start), "clip_end": float(cam.data.clip_end),
            "hidden": on_plane, "mirrors": sorted({o.name for o in objs} | set(mirrors)), "behind": sorted(behind),
            "plane": [n.x, n.y, n.z, d],
            "where": "the plane of %s" % ", ".join(on_plane[:4]),
        })
    return specs


def _prepare_probe(scene, spec, path, meta_path):
    """Renders (or reuses) one probe or planar view (spec: probe_spec / planar_specs); its
    sidecar entry, or None (a warning) when it failed to render."""
    try:
        objs = _probe_scene_objects(scene)
        sig = _probe_signature(scene, spec, objs)
        old = _stored_entry(path, meta_path)
        if old and old.get("signature") == sig:
            log("%s '%s' reused (scene unchanged): %s" % (spec["kind"], spec["name"], path))
        else:
            os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
            t0 = time.perf_counter()
            _render_probe(scene, spec, objs, path)
            log("%s '%s' at %s rendered %dx%d (%d samples) in %.2f s: %s"
                % (spec["kind"], spec["name"], spec["where"], spec["width"], spec["height"], spec["samples"],
                   time.perf_counter() - t0, path))
    except Exception as e:  # a probe is an improvement, never a reason to fail the frame
        log("warning: the %s view '%s' failed to render (%s): ssr_mirror falls back to %s"
            % (spec["kind"], spec["name"], e,
               "the mirror's texture" if spec["kind"] == "probe" else "the trace and the probe"))
        return None
    if spec["kind"] == "planar":
        return {"name": spec["name"], "path": path, "world_to_camera": spec["world_to_camera"],
                "projection": spec["projection"], "clip_start": spec["clip_start"], "clip_end": spec["clip_end"],
                "orthographic": False, "kind": "planar", "plane": spec["plane"], "signature": sig,
                **({"window": spec["crop"][:2] + [spec["width"], spec["height"]]} if spec.get("border") else {})}
    ident = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
    return {"name": spec["name"], "path": path, "world_to_camera": spec["world_to_camera"],
            "projection": ident, "clip_start": 0.0, "clip_end": spec["clip_end"], "orthographic": False,
            "kind": "probe", "panorama": "equirect", "signature": sig}


def _view_specs(scene, view, mirrors=()):
    """The renders one needed probe or planar view takes: ([spec], None) (planar: one per
    plane), or ([], reason) for a mirror that is not flat (logged): the sidecar then lists
    the view as absent with that reason, so ssr_mirror uses the trace and the probe there
    without warning of a missing view."""
    if view["kind"] != "planar":
        return probe_specs(scene, view, mirrors), None
    try:
        return planar_specs(scene, view, mirrors), None
    except NotPlanar as e:
        reason = "the mirror is not flat (%s)" % e
        log("no planar view '%s': %s; ssr_mirror uses the trace and the probe there" % (view["name"], reason))
        return [], reason


def _file_name(view_name):
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in view_name)


def _stored_entry(path, meta_path):
    """The sidecar entry stored beside a view's EXR by an earlier render, or None."""
    if not (os.path.exists(path) and os.path.exists(meta_path)):
        return None
    try:
        with open(meta_path, encoding="utf-8") as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def _store_entry(meta_path, entry):
    with open(meta_path + ".tmp", "w", encoding="utf-8") as f:
        json.dump(entry, f, indent=1)
    os.replace(meta_path + ".tmp", meta_path)


# ---------------------------------------------------------------- water (refractive caustics)

WATER = "water:"


def water_objects(scene, material):
    """The mesh objects that use `material` (hidden from the render or the camera or not)."""
    out = []
    for ob in scene.objects:
        if ob.type != "MESH":
            continue
        if any(sl.material is not None and sl.material.name == material for sl in ob.material_slots):
            out.append(ob)
    return sorted(out, key=lambda o: o.name)


def _first_sun(scene):
    for ob in scene.objects:
        if ob.type == "LIGHT" and not ob.hide_render and ob.data.type == "SUN":
            return ob
    return None


def water_spec(scene, view, frames):
    """The sun's orthographic view of the water objects: camera matrices, resolution."""
    material = view["name"][len(WATER):]
    water = water_objects(scene, material)
    if not water:
        raise native.LibfxError("voronoi_caustics (mode refractive) needs the water's geometry, but no mesh "
                                "object of the scene uses the material '%s' (the effect's 'water' parameter)"
                                % material)
    sun = _first_sun(scene)
    if sun is None:
        others = [ob.name + " (" + ob.data.type + ")" for ob in scene.objects if ob.type == "LIGHT"]
        raise native.LibfxError("voronoi_caustics (mode refractive) refracts a sun's light; the scene has no sun "
                                "lamp (lights: %s); spot and point lights are not supported yet"
                                % (", ".join(others) or "none"))
    d = -sun.matrix_world.col[2].xyz.normalized()
    rot = d.to_track_quat('-Z', 'Y').to_matrix()
    inv = rot.transposed()
    w_lo, w_hi = world_box(water)
    recv = [ob for ob in casters(scene) if ob not in water]
    wc = [inv @ p for p in box_corners(w_lo, w_hi)]
    lo = Vector(map(min, zip(*wc)))
    hi = Vector(map(max, zip(*wc)))
    if recv:
        g_lo, g_hi = world_box(recv)
        r_lo, r_hi = frusta_box(scene, frames, g_lo, g_hi)
        rc = [inv @ p for p in box_corners(r_lo, r_hi)]
        margin = max(0.0, w_hi.z - r_lo.z) * 0.5 + 0.05
        c_lo = Vector(map(min, zip(*rc))) - Vector((margin, margin, 0))
        c_hi = Vector(map(max, zip(*rc))) + Vector((margin, margin, 0))
        if c_lo.x < hi.x and c_hi.x > lo.x and c_lo.y < hi.y and c_hi.y > lo.y:
            lo.x, lo.y = max(lo.x, c_lo.x), max(lo.y, c_lo.y)
            hi.x, hi.y = min(hi.x, c_hi.x), min(hi.y, c_hi.y)
    zmax, zmin = hi.z + 1.0, lo.z - 1.0
    ext = Vector((max(hi.x - lo.x, 1e-3), max(hi.y - lo.y, 1e-3)))
    centre = rot @ Vector(((lo.x + hi.x) / 2, (lo.y + hi.y) / 2, zmax + 0.5))
    near, far = 0.5, zmax - zmin + 0.5
    r = scene.render
    rw = int(r.resolution_x * r.resolution_percentage / 100)
    rh = int(r.resolution_y * r.resolution_percentage / 100)
    size = int(scene.get("libfx_water_map_size") or _round64(max(rw, rh) * 1.5, 256, 4096))
    if ext.x >= ext.y:
        w, h = size, max(16, int(round(size * ext.y / ext.x)))
        half_x = ext.x / 2 * 1.02
        half_y = half_x * h / w
    else:
        h, w = size, max(16, int(round(size * ext.x / ext.y)))
        half_y = ext.y / 2 * 1.02
        half_x = half_y * w / h
    mw = Matrix.Translation(centre) @ rot.to_4x4()
    return {
        "name": view["name"], "kind": "water", "width": w, "height": h, "material": material,
        "matrix_world": [list(row) for row in mw], "world_to_camera": [list(row) for row in mw.inverted()],
        "projection": ortho_projection(half_x, half_y, near, far),
        "clip_start": near, "clip_end": far, "orthographic": True, "ortho_scale": 2 * max(half_x, half_y),
        "light": [sun.name, [list(r) for r in sun.matrix_world]],
    }, water


def _render_water(scene, spec, water, path):
    """The water objects alone, from the sun: Normal and Depth (1 sample at texel centres).
    Objects hidden from the render or the camera are shown for this render only."""
    aux = bpy.data.scenes.new(AUX_SCENE)
    cam_data = bpy.data.cameras.new(AUX_SCENE)
    cam = bpy.data.objects.new(AUX_SCENE, cam_data)
    shown = []
    try:
        for ob in water:
            aux.collection.objects.link(ob)
            shown.append((ob, ob.hide_render, ob.visible_camera))
            ob.hide_render = False
            ob.visible_camera = True
        aux.collection.objects.link(cam)
        _place_ortho_camera(aux, cam, spec)
        r = aux.render
        r.engine = "CYCLES"
        r.resolution_x, r.resolution_y, r.resolution_percentage = spec["width"], spec["height"], 100
        r.use_compositing = True
        r.filepath = os.path.join(os.path.dirname(path), "")
        c = aux.cycles
        c.samples = 1
        c.use_adaptive_sampling = False
        c.use_denoising = False
        c.max_bounces = 0
        c.filter_width = 0.01
        c.seed = 0
        aux.frame_start = aux.frame_end = aux.frame_current = 1
        vl = aux.view_layers[0]
        vl.use_pass_z = True
        vl.use_pass_normal = True
        _render_view(scene, aux, path, [("Depth", "Depth"), ("Normal", "Normal")],
                     "the water view render of '%s'" % spec["name"])
    finally:
        for ob, hide, cam_vis in shown:
            ob.hide_render = hide
            ob.visible_camera = cam_vis
        bpy.data.scenes.remove(aux)
        bpy.data.objects.remove(cam)
        bpy.data.cameras.remove(cam_data)


def _evaluated_shape(water):
    """A hash of the water's evaluated vertices (waves animated by modifiers or shape keys
    change it while the objects' transforms stay): a changed surface is rendered again."""
    h = hashlib.sha1()
    dg = bpy.context.evaluated_depsgraph_get()
    for ob in water:
        ev = ob.evaluated_get(dg)
        me = ev.to_mesh()
        try:
            co = [0.0] * (3 * len(me.vertices))
            me.vertices.foreach_get("co", co)
            h.update(json.dumps([ob.name, [round(v, 5) for v in co]]).encode("utf-8"))
        finally:
            ev.to_mesh_clear()
    return h.hexdigest()


def _ortho_view(scene, view, spec, sig, render, reused, rendered):
    """Renders (render(path)) or reuses the orthographic view `view` whose signature is
    sig; its sidecar entry, stored beside the EXR. reused / rendered: what the log says."""
    path = "%slibfx_aux_%s.exr" % (scene_setup.output_prefix(scene), _file_name(view["name"]))
    meta_path = path[:-4] + ".json"
    old = _stored_entry(path, meta_path)
    if old and old.get("signature") == sig:
        log("%s '%s' reused (%s unchanged): %s" % (reused[0], view["name"], reused[1], path))
    else:
        os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
        t0 = time.perf_counter()
        render(path)
        log("%s '%s'%s rendered %dx%d in %.2f s: %s" % (reused[0], view["name"], rendered, spec["width"],
                                                      spec["height"], time.perf_counter() - t0, path))
    entry = {"name": view["name"], "path": path, "world_to_camera": spec["world_to_camera"],
             "projection": spec["projection"], "clip_start": spec["clip_start"], "clip_end": spec["clip_end"],
             "orthographic": True, "kind": view["kind"], "signature": sig}
    _store_entry(meta_path, entry)
    return entry


def _prepare_water(scene, view, frames):
    spec, water = water_spec(scene, view, frames)
    sig = signature(dict(spec, shape=_evaluated_shape(water)), water)
    return _ortho_view(scene, view, spec, sig, lambda path: _render_water(scene, spec, water, path),
                       ("water view", "sun and water"),
                       " (%s, from the sun '%s')" % (", ".join(o.name for o in water[:4]), spec["light"][0]))


def prepare(scene, frames):
    """Renders (or reuses) every aux view the stack needs for `frames`; returns the
    sidecar entries. An empty list, and no render, when the stack needs none."""
    views = needed(scene)
    if not views:
        return []
    objs = casters(scene)
    mirrors = stack_mirrors(scene, views)
    entries = []
    for view in views:
        if view["kind"] in ("probe", "planar"):
            absent = None
            try:
                specs, absent = _view_specs(scene, view, mirrors)
            except Exception as e:  # a probe is an improvement, never a reason to fail the frame
                log("warning: the %s view '%s' could not be placed (%s): ssr_mirror falls back to %s"
                    % (view["kind"], view["name"], e,
                       "the mirror's texture" if view["kind"] == "probe" else "the trace and the probe"))
                specs = []
            if absent:   # listed, so that F12 finds it on disk too (from_disk); an older view goes
                base = "%slibfx_aux_%s" % (scene_setup.output_prefix(scene), _file_name(view["name"]))
                entry = {"name": view["name"], "absent": absent}
                _store_entry(base + ".json", entry)
                entries.append(entry)
                if os.path.exists(base + ".exr"):
                    os.remove(base + ".exr")
            for spec in specs:
                path = "%slibfx_aux_%s.exr" % (scene_setup.output_prefix(scene), _file_name(spec["name"]))
                meta_path = path[:-4] + ".json"
                entry = _prepare_probe(scene, spec, path, meta_path)
                if entry is None:
                    continue
                _store_entry(meta_path, entry)
                entries.append(entry)
            _drop_stale_planes(scene, view, {s["name"] for s in specs} | ({view["name"]} if absent else set()))
            continue
        if view["kind"] == "water":
            entries.append(_prepare_water(scene, view, frames))
            continue
        spec = view_spec(scene, view, frames, objs)
        entry = _ortho_view(scene, view, spec, signature(spec, objs),
                            lambda path, spec=spec: _render(scene, spec, objs, path),
                            ("aux view", "light and geometry"), "")
        entries.append(entry)
    return entries


def _plane_names(view):
    """Every name a probe or planar need's views may have on disk: one per plane."""
    most = PLANAR_MAX if view["kind"] == "planar" else PROBES_MAX
    return [planar_view_name(view["name"], k) for k in range(most)]


def _drop_stale_planes(scene, view, current):
    """Removes the files of this need's views that the scene no longer has (a facing pair
    that became one mirror leaves "probe:<key>#2"): F12 reads what is on disk
    (from_disk), and would take the old plane's view for a mirror point it is nearer."""
    for name in _plane_names(view):
        if name in current:
            continue
        path = "%slibfx_aux_%s.exr" % (scene_setup.output_prefix(scene), _file_name(name))
        for stale in (path[:-4] + ".json", path):
            try:
                os.remove(stale)
                log("%s view '%s' removed: the scene has no such plane now (%s)" % (view["kind"], name, stale))
            except FileNotFoundError:
                pass
            except OSError as e:
                log("warning: the stale %s view '%s' could not be removed (%s)" % (view["kind"], name, e))


def from_disk(scene):
    """The views a previous batch run left beside the output (for F12, which cannot
    render them from inside a render)."""
    out = []
    for view in needed(scene):
        names = [view["name"]]
        if view["kind"] in ("planar", "probe"):   # one view per mirror plane
            names = _plane_names(view)
        for name in names:
            meta_path = "%slibfx_aux_%s.json" % (scene_setup.output_prefix(scene), _file_name(name))
            try:
                with open(meta_path, encoding="utf-8") as f:
                    out.append(json.load(f))
                log("aux view '%s' from disk (F12 cannot render it; a batch run re-renders it when it is stale)"
                    % name)
            except (OSError, ValueError):
                pass
    return out
