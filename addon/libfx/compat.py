"""Every difference between the Blender versions the add-on supports (3.4 to 5.x).

The rest of the add-on (and the scene builders in blend_scenes/) call these
functions and never look at ``bpy.app.version``.  Each branch is named after
the API it serves and, where Blender lets us, is chosen by asking for that API
(``hasattr``) rather than by version number, so a point release that back-ports
or drops an API still takes the right branch.  No other module of the add-on
imports anything here but bpy; the scene builders load this file directly.

The differences, and the releases that made them:

- compositor tree: ``scene.use_nodes`` + ``scene.node_tree`` (3.4-4.5);
  a node-group data-block ``scene.compositing_node_group`` whose result leaves
  through a Group Output node; no Composite node (5.0+).
- File Output node: ``base_path`` + ``layer_slots`` (3.4-4.5); ``directory`` +
  ``file_name`` + typed ``file_output_items``, multilayer EXR written as one part
  per layer (5.0+).
- Render Layers outputs: short names (3.4-4.5: "IndexOB", "DiffDir"), long names
  (5.0+: "Object Index", "Diffuse Direct").
- image formats: multilayer EXR is a ``file_format`` (3.4-4.5) or a
  ``media_type`` (5.0+).
- node settings that became input sockets (5.0+): none that the add-on sets
  (the File Output node's format is still a property).
- engine identifiers: Eevee is ``BLENDER_EEVEE`` (3.4-4.1, 5.0+) and
  ``BLENDER_EEVEE_NEXT`` (4.2-4.5); Eevee Next renders no index passes.
- Principled BSDF sockets renamed in 4.0 ("Specular" -> "Specular IOR Level"...).
- material blend and shadow modes (4.2: ``surface_render_method``,
  ``use_transparent_shadow``; 5.0 dropped ``shadow_method``).
- light shadows (``cycles.cast_shadow`` gone in 5.0) and animation F-curves
  (slotted actions: ``action.fcurves`` gone in 5.0), for the scene builders.
- mesh auto smooth (``use_auto_smooth`` until 4.0; ``set_sharp_from_angle`` 4.1+).
- panoramic cameras: the projection is ``cam.data.cycles.panorama_type`` (3.x)
  or ``cam.data.panorama_type`` (4.0+); reflection-cubemap light probes are
  type ``CUBEMAP`` (3.x) or ``SPHERE`` (4.1+).
- extensions (4.2+): the add-on's module is ``bl_ext.<repo>.libfx`` (batch.py
  looks for either name before it can import this module).
- ID writes refused for a moment on the render thread (seen on 4.3 under F12):
  ``when_writable`` retries them.
"""

import os
import sys
import time

import bpy

#: Oldest release whose API this add-on knows, and the newest major it knows.
OLDEST = (3, 4)
NEWEST_MAJOR = 5


def blender_version():
    return tuple(bpy.app.version)


def version_problem(version=None):
    """None when this Blender is one the add-on was written for, else a message."""
    v = tuple(version or blender_version())
    if v[:2] < OLDEST:
        return ("Blender %d.%d is older than %d.%d, the oldest release the libfx add-on "
                "supports: use Blender %d.%d or newer" % (v[0], v[1], OLDEST[0], OLDEST[1],
                                                          OLDEST[0], OLDEST[1]))
    if v[0] > NEWEST_MAJOR:
        return ("Blender %d.%d is a major release this libfx add-on does not know (it knows "
                "%d.%d to %d.x): install a newer libfx add-on" % (v[0], v[1], OLDEST[0], OLDEST[1],
                                                                  NEWEST_MAJOR))
    return None


# ---------------------------------------------------------------- compositor tree

def has_compositing_node_group():
    """5.0+: the scene's compositor is a node-group data-block."""
    return "compositing_node_group" in bpy.types.Scene.bl_rna.properties


def compositor_tree(scene):
    """The scene's compositor node tree, or None when it has none."""
    if has_compositing_node_group():
        return scene.compositing_node_group
    return scene.node_tree


def ensure_compositor_tree(scene, name):
    """The scene's compositor tree, made when missing. Returns (tree, how): how is
    None when the tree was there already, else what was changed, for
    ``release_compositor_tree`` to undo: "use_nodes" (3.4-4.5: turned on; Blender
    adds Render Layers -> Composite itself) or "node_group" (5.0+: a new group
    whose Group Output passes the render through unchanged). Either way a new
    tree holds a Render Layers node whose Image is the final image."""
    if has_compositing_node_group():
        tree = scene.compositing_node_group
        if tree is not None:
            return tree, None
        tree = bpy.data.node_groups.new(name, "CompositorNodeTree")
        _pass_through_group(tree, scene)
        scene.compositing_node_group = tree
        return tree, "node_group"
    if scene.use_nodes and scene.node_tree is not None:
        return scene.node_tree, None
    scene.use_nodes = True
    return scene.node_tree, "use_nodes"


def _pass_through_group(tree, scene):
    """A new 5.x compositor group: Render Layers -> Group Output, so that the
    render the scene writes is the one it wrote before the group existed."""
    tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    rl = tree.nodes.new("CompositorNodeRLayers")
    rl.scene = scene
    rl.location = (-300, 0)
    out = tree.nodes.new("NodeGroupOutput")
    out.location = (100, 0)
    tree.links.new(rl.outputs["Image"], out.inputs[0])


def release_compositor_tree(scene, how):
    """Undoes ``ensure_compositor_tree``'s change (how as it returned). A scene whose
    Use Nodes a 3.4-4.5 add-on turned on reaches 5.x with that tree made into a group:
    the group goes, as Use Nodes would have gone off."""
    if not how:
        return
    if not has_compositing_node_group():
        if how == "use_nodes":
            scene.use_nodes = False
    else:
        tree = scene.compositing_node_group
        if tree is not None:
            scene.compositing_node_group = None
            if tree.users == 0:
                bpy.data.node_groups.remove(tree)


# ---------------------------------------------------------------- File Output node

def has_file_output_items(node):
    """5.0+: the File Output node has directory, file_name and output items."""
    return hasattr(node, "file_output_items")


def file_output_set_prefix(node, prefix):
    """Where the node writes: files named prefix + frame (4 digits) + '.exr', for
    animation and still renders alike (5.0+ numbers a still's file only when the
    name holds '#')."""
    if has_file_output_items(node):
        directory, name = os.path.split(prefix)
        node.directory = directory + os.sep if directory else ""
        node.file_name = name + "####"
    else:
        node.base_path = prefix


def file_output_prefix(node):
    if has_file_output_items(node):
        return os.path.join(node.directory, node.file_name.rstrip("#"))
    return node.base_path


def _file_output_items(node):
    return node.file_output_items if has_file_output_items(node) else node.layer_slots


def file_output_slot_names(node):
    return [s.name for s in _file_output_items(node)]


#: 5.0+ output items are typed like the socket that feeds them: a float item
#: writes one channel ("Depth.V"), a vector three ("Normal.X"), a colour four.
_ITEM_TYPE = {"VALUE": "FLOAT", "VECTOR": "VECTOR", "RGBA": "RGBA"}


def file_output_link(tree, node, sources):
    """Makes the node's inputs (the layers of its multilayer EXR) exactly
    ``sources`` = [(layer name, Render Layers output socket)], in order, each
    linked to its socket."""
    names = [n for n, _ in sources]
    if has_file_output_items(node):
        want = [(n, _ITEM_TYPE.get(sock.type, "RGBA")) for n, sock in sources]
        have = [(i.name, i.socket_type) for i in node.file_output_items]
        if have != want:
            node.file_output_items.clear()
            for n, t in want:
                node.file_output_items.new(t, n)
    elif file_output_slot_names(node) != names:
        node.layer_slots.clear()
        for n in names:
            node.layer_slots.new(n)
    for n, sock in sources:
        inp = node.inputs.get(n)
        if not inp.is_linked or inp.links[0].from_socket != sock:
            tree.links.new(sock, inp)


def set_file_format(settings, file_format, depth=None, codec=None):
    """Sets an ImageFormatSettings' format by its 3.4-4.5 name. 5.0+ chooses
    multilayer EXR (and video) by ``media_type``; its ``file_format`` then reads
    back as the old name."""
    if hasattr(settings, "media_type"):
        media = {"OPEN_EXR_MULTILAYER": "MULTI_LAYER_IMAGE", "FFMPEG": "VIDEO"}.get(file_format, "IMAGE")
        if settings.media_type != media:
            settings.media_type = media
    if settings.file_format != file_format:
        settings.file_format = file_format
    if depth is not None:
        settings.color_depth = depth
    if codec is not None:
        settings.exr_codec = codec


#: ImageFormatSettings properties a format change may reset, in the order they are put back
#: (media_type, 5.0+, first: it decides which file formats are valid).
_FORMAT_PROPS = ("media_type", "file_format", "color_mode", "color_depth", "exr_codec", "quality",
                 "compression", "use_preview")


#: How long a handler waits for Blender to allow ID writes again before it gives up.
WRITE_WAIT_S = 20.0


def when_writable(fn, *args, wait=None):
    """fn(*args), called again while Blender refuses writes to ID data ("Writing to ID
    classes in this context is not allowed"). Blender's switch for that refusal is one flag
    for the whole process, set while the UI thread runs a Python draw() or poll(); an F12
    render's handlers run on the render thread, so a panel redrawing at that moment made
    the render_post handler's format change fail on 4.3 (the frame then had no result).
    Sleeping hands the interpreter to the UI thread, whose draw then ends. wait: seconds
    (default WRITE_WAIT_S)."""
    wait = WRITE_WAIT_S if wait is None else wait
    t0 = time.monotonic()
    pause = 0.001
    while True:
        try:
            out = fn(*args)
            break
        except AttributeError as e:
            if "not allowed" not in str(e) or time.monotonic() - t0 > wait:
                raise
        time.sleep(pause)
        pause = min(pause * 2, 0.05)
    if pause > 0.001:   # printed as log.log does: this file imports nothing of the add-on
        print("libfx: Blender refused ID writes for %.3f s (%s); written then"
              % (time.monotonic() - t0, fn.__name__), file=sys.stderr, flush=True)
    return out


def image_format_snapshot(settings):
    return [(p, getattr(settings, p)) for p in _FORMAT_PROPS if hasattr(settings, p)]


def image_format_restore(settings, snapshot):
    """Puts back what image_format_snapshot saw (waiting out refused writes: when_writable);
    a value the restored format refuses (none should) is left as Blender set it rather than
    raising in a render handler. Returns the properties it could not put back."""
    missed = []
    for prop, value in snapshot:
        if getattr(settings, prop) != value:
            try:
                when_writable(setattr, settings, prop, value)
            except (TypeError, ValueError, AttributeError):
                missed.append(prop)
    return missed


def file_output_format(node, file_format="OPEN_EXR_MULTILAYER", depth="32", codec="ZIP"):
    set_file_format(node.format, file_format, depth, codec)


# ---------------------------------------------------------------- Render Layers node

#: Render Layers outputs that 5.0 renamed (the EXR layers keep the short names).
RENDER_LAYER_RENAMED = {
    "IndexOB": "Object Index", "IndexMA": "Material Index",
    "DiffDir": "Diffuse Direct", "DiffInd": "Diffuse Indirect", "DiffCol": "Diffuse Color",
    "GlossDir": "Glossy Direct", "GlossInd": "Glossy Indirect", "GlossCol": "Glossy Color",
    "TransDir": "Transmission Direct", "TransInd": "Transmission Indirect",
    "TransCol": "Transmission Color", "VolumeDir": "Volume Direct", "VolumeInd": "Volume Indirect",
    "Emit": "Emission", "Env": "Environment", "AO": "Ambient Occlusion",
}


def render_layer_output(rl, pass_name):
    """The Render Layers output of a pass by its short (EXR) name, or None (4.3+
    also when the engine does not render it; 3.4 has it, disabled); the render's
    combined image is 'Image' in every release."""
    name = "Image" if pass_name == "Combined" else pass_name
    sock = rl.outputs.get(name)
    if sock is None and name in RENDER_LAYER_RENAMED:
        sock = rl.outputs.get(RENDER_LAYER_RENAMED[name])
    return sock


# ---------------------------------------------------------------- engines

def _engine_ids():
    try:
        return {i.identifier for i in bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items}
    except (KeyError, AttributeError):
        return set()


def eevee_engine():
    """Eevee's engine identifier: BLENDER_EEVEE_NEXT on 4.2-4.5, else BLENDER_EEVEE."""
    ids = _engine_ids()
    return "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in ids else "BLENDER_EEVEE"


def is_eevee(engine):
    return engine in ("BLENDER_EEVEE", "BLENDER_EEVEE_NEXT")


def engine_label(engine):
    return {"BLENDER_EEVEE_NEXT": "Eevee", "BLENDER_EEVEE": "Eevee", "CYCLES": "Cycles",
            "BLENDER_WORKBENCH": "Workbench"}.get(engine, engine)


def eevee_is_next():
    """Eevee Next (4.2+, still the Eevee of 5.x): ray tracing settings, Position and
    Vector passes; the Eevee before it (3.4-4.1) had screen-space reflections."""
    return "use_raytracing" in bpy.types.SceneEEVEE.bl_rna.properties


def engine_renders_pass(engine, pass_name):
    """Whether the engine writes this pass (its EXR name) at all. Index passes:
    Cycles only; Position and Vector: Cycles and Eevee Next; Workbench: Depth only.
    Cryptomatte, Depth, Normal and the light passes: Cycles and every Eevee."""
    if engine == "CYCLES":
        return True
    if engine == "BLENDER_WORKBENCH":
        return pass_name in ("Combined", "Depth")
    if is_eevee(engine):
        if pass_name in ("IndexOB", "IndexMA"):
            return False
        if pass_name in ("Position", "Vector"):
            return eevee_is_next()
    return True   # another engine: the render's missing-socket warning tells


def set_render_samples(scene, samples):
    if scene.render.engine == "CYCLES":
        scene.cycles.samples = samples
    elif is_eevee(scene.render.engine) and hasattr(scene, "eevee"):
        scene.eevee.taa_render_samples = samples


def light_cast_shadow(light, on):
    """Whether a light casts shadows in every engine: ``use_shadow`` (Eevee; both
    engines once Cycles' own ``cycles.cast_shadow`` went away in 5.0)."""
    light.use_shadow = on
    cycles = getattr(light, "cycles", None)
    if cycles is not None and hasattr(cycles, "cast_shadow"):
        cycles.cast_shadow = on


def animation_fcurves(id_data):
    """The F-curves animating an ID: ``action.fcurves`` (3.4-4.x) or, with slotted
    actions (4.4+; the only kind in 5.0+), those of the ID's slot."""
    ad = id_data.animation_data
    action = ad.action if ad else None
    if action is None:
        return []
    slot = getattr(ad, "action_slot", None)
    if slot is not None and hasattr(action, "layers"):
        from bpy_extras import anim_utils
        bag = anim_utils.action_get_channelbag_for_slot(action, slot)
        if bag is not None:
            return list(bag.fcurves)
    return list(getattr(action, "fcurves", []))


# ---------------------------------------------------------------- materials and meshes

#: Principled BSDF inputs renamed in 4.0: old name -> new name.
PRINCIPLED_RENAMED = {
    "Specular": "Specular IOR Level",
    "Transmission": "Transmission Weight",
    "Subsurface": "Subsurface Weight",
    "Emission": "Emission Color",
    "Clearcoat": "Coat Weight",
    "Clearcoat Roughness": "Coat Roughness",
    "Sheen": "Sheen Weight",
}


def principled_input(bsdf, name):
    """A Principled BSDF input by its 3.x or 4.x name, on either release."""
    sock = bsdf.inputs.get(name)
    if sock is None:
        sock = bsdf.inputs.get(PRINCIPLED_RENAMED.get(name, ""))
    if sock is None:
        old = {v: k for k, v in PRINCIPLED_RENAMED.items()}.get(name)
        sock = bsdf.inputs.get(old) if old else None
    if sock is None:
        raise KeyError("Principled BSDF has no input '%s' in Blender %s" % (name, bpy.app.version_string))
    return sock


def material_alpha_clip(mat, threshold=0.5):
    """Eevee shows and shadows the material's alpha as cut-out (Cycles always does)."""
    if hasattr(mat, "surface_render_method"):      # 4.2+: Eevee Next
        mat.surface_render_method = "DITHERED"
        if hasattr(mat, "use_transparent_shadow"):
            mat.use_transparent_shadow = True
    else:
        mat.blend_method = "CLIP"
        mat.shadow_method = "CLIP"
    if hasattr(mat, "alpha_threshold"):
        mat.alpha_threshold = threshold


def material_alpha_blend(mat, casts_shadow=False):
    """Eevee blends the material (a veil); it casts no shadow unless asked."""
    if hasattr(mat, "surface_render_method"):      # 4.2+: Eevee Next
        mat.surface_render_method = "BLENDED"
        if hasattr(mat, "use_transparent_shadow"):
            mat.use_transparent_shadow = casts_shadow
    else:
        mat.blend_method = "BLEND"
        mat.shadow_method = "HASHED" if casts_shadow else "NONE"
    mat.show_transparent_back = False


def mesh_smooth_by_angle(mesh, angle):
    """Smooth shading with edges sharper than angle (radians) kept sharp."""
    for p in mesh.polygons:
        p.use_smooth = True
    if hasattr(mesh, "set_sharp_from_angle"):        # 4.1+
        mesh.set_sharp_from_angle(angle=angle)
    else:                                            # 3.4-4.0: auto smooth
        mesh.use_auto_smooth = True
        mesh.auto_smooth_angle = angle


# ---------------------------------------------------------------- probes

def set_equirect_camera(cam_data):
    """Makes a camera Cycles' full 360 x 180 degree equirectangular panorama:
    ``panorama_type`` on the camera (4.0+) or on its Cycles settings (3.x)."""
    cam_data.type = "PANO"
    for owner in (cam_data, getattr(cam_data, "cycles", None)):
        if owner is not None and hasattr(owner, "panorama_type"):
            owner.panorama_type = "EQUIRECTANGULAR"
            for k, v in (("latitude_min", -1.5707963), ("latitude_max", 1.5707963),
                         ("longitude_min", -3.1415927), ("longitude_max", 3.1415927)):
                if hasattr(owner, k):
                    setattr(owner, k, v)
            return
    raise RuntimeError("this Blender has no panoramic camera type setting")


def is_reflection_probe(ob):
    """A reflection-cubemap Light Probe object (3.x 'CUBEMAP', 4.1+ 'SPHERE')."""
    return ob.type == "LIGHT_PROBE" and getattr(ob.data, "type", "") in ("CUBEMAP", "SPHERE")
