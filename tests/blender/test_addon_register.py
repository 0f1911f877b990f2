"""Registration, library discovery and the UI model generated from the library."""
import json

import addon_testlib as T

OK = "LIBFX-TEST-OK"


def _check(proc):
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-4000:]
    assert OK in proc.stdout, out[-4000:]
    assert not T.tracebacks(out), out[-4000:]
    return out


def test_register_twice_cleanly(blender, library):
    script = T.PRELUDE + """
import bpy
def ours():
    return {n: [h.__name__ for h in getattr(bpy.app.handlers, n) if h.__module__.startswith('libfx')]
            for n in ('frame_change_post', 'render_init', 'render_post', 'load_post')}
first = ours()
assert all(len(v) == 1 for v in first.values()), first
foreign = lambda *a: None
bpy.app.handlers.render_post.append(foreign)
libfx.unregister()
assert not hasattr(bpy.types.Scene, 'libfx')
assert all(len(v) == 0 for v in ours().values()), ours()
assert foreign in bpy.app.handlers.render_post   # only our handlers go
libfx.register()
libfx.register()                                  # twice in a row: no duplicates
assert ours() == first, ours()
assert bpy.types.Scene.bl_rna.properties['libfx'].fixed_type.identifier == 'LIBFX_PG_settings'
assert hasattr(bpy.types, 'LIBFX_UL_stack')
libfx.unregister(); libfx.unregister()            # and twice out
assert not hasattr(bpy.types, 'LIBFX_UL_stack')
libfx.register()
print('%s')
""" % OK
    _check(T.run_blender([], env=T.addon_env(library), python_expr=script))


def test_missing_library_is_a_message_not_a_traceback(blender):
    script = T.PRELUDE + """
cat = libfx.props.catalog()
assert not cat.ok and 'No such file' in cat.error and '/nonexistent/libfx.so' in cat.error, cat.error
assert cat.error == libfx.native.load_error()
assert hasattr(bpy.types.Scene, 'libfx') and hasattr(bpy.types, 'LIBFX_PT_output')
# the panel draws exactly the loader's message, wrapped (a fake layout records the labels)
""" + T.FAKE_LAYOUT + """
libfx.ui.draw_stack(lay, bpy.context)
i = lay.labels.index('libfx library unavailable')
width = libfx.ui._chars(bpy.context)
lines = libfx.ui._wrap(cat.error, width)
assert lay.labels[i + 1:i + 1 + len(lines)] == lines, (lay.labels, lines)
assert ''.join(lines).replace(' ', '') == cat.error.replace(' ', '') and len(lines) > 1, lines
assert all(len(l) <= width for l in lines), (width, lines)
# the batch runner fails with the message too (tested below); the stack still serialises
assert libfx.recipe.to_recipe(bpy.context.scene)['effects'] == []
libfx.unregister()
print('%s')
""" % OK
    out = _check(T.run_blender([], env={"LIBFX_LIBRARY": "/nonexistent/libfx.so"}, python_expr=script))
    assert "/nonexistent/libfx.so: cannot open shared object file: No such file or directory" in out


def test_not_libfx_and_wrong_abi(blender, library):
    # A real shared library that is not libfx: refused by name, add-on still registers.
    script = T.PRELUDE + """
cat = libfx.props.catalog()
assert not cat.ok and 'is not libfx' in cat.error, cat.error
print('%s')
""" % OK
    _check(T.run_blender([], env={"LIBFX_LIBRARY": "/lib/x86_64-linux-gnu/libm.so.6"}, python_expr=script))
    # The ABI check: the add-on expecting another ABI than the library reports.
    script = T.PRELUDE.replace("libfx.register()\n", "") + """
real_abi = libfx.native.ABI_VERSION
libfx.native.ABI_VERSION = 99
libfx.register()
cat = libfx.props.catalog()
assert not cat.ok and ('has ABI ' + str(real_abi)) in cat.error and 'ABI 99' in cat.error, cat.error
print('%s')
""" % OK
    _check(T.run_blender([], env=T.addon_env(library), python_expr=script))


def test_ui_model_is_generated_from_the_library(blender, library):
    script = T.PRELUDE + """
from libfx import native, props
cat = props.catalog()
assert cat.ok, cat.error
report = {}
with native.Context(1) as ctx:
    for name in native.effect_names():
        d = ctx.describe(name)
        cls = props._GROUPS[name]
        assert cls.__name__ == 'LIBFX_PG_' + name
        rna = cls.bl_rna.properties
        for p in d['params']:
            prop = rna[libfx.catalog.prop_identifier(p['name'])]
            t = {'float': 'FLOAT', 'int': 'INT', 'bool': 'BOOLEAN', 'enum': 'ENUM',
                 'floats': 'FLOAT', 'string': 'STRING'}[p['type']]
            assert prop.type == t, (name, p['name'], prop.type)
            assert prop.description == (p['doc'] or p['name'])
            if p['type'] in ('float', 'int'):
                assert abs(prop.default - p['default']) < 1e-6, (name, p)
                assert abs(prop.hard_min - p['min']) <= 1e-6 * max(1, abs(p['min'])), (name, p, prop.hard_min)
                assert abs(prop.hard_max - p['max']) <= 1e-6 * max(1, abs(p['max'])), (name, p, prop.hard_max)
                assert abs(prop.soft_min - p['soft_min']) <= 1e-6 * max(1, abs(p['soft_min'])), (name, p)
                assert abs(prop.soft_max - p['soft_max']) <= 1e-6 * max(1, abs(p['soft_max'])), (name, p)
            if p['type'] == 'enum':
                assert [i.identifier for i in prop.enum_items] == p['items']
                assert prop.default == p['default']
            if p['type'] == 'floats':
                assert prop.array_length == p['count']
                if p['hint'] == 'color':
                    assert prop.subtype == 'COLOR'
            if p['type'] == 'string' and p['hint'] == 'path':
                assert prop.subtype == 'FILE_PATH'
        report[name] = len(d['params'])
settings_rna = bpy.types.Scene.bl_rna.properties['libfx'].fixed_type
assert [i.identifier for i in settings_rna.properties['quality'].enum_items] == native.quality_names()
item_rna = settings_rna.properties['stack'].fixed_type.properties
for name in report:
    assert item_rna[props.group_attr(name)].fixed_type.identifier == 'LIBFX_PG_' + name
print(json.dumps(report))
print('%s')
""" % OK
    _check(T.run_blender([], env=T.addon_env(library), python_expr=script))


def test_recipes_round_trip_and_passes_restore(blender, library, tmp_path):
    recipes = [str(p) for p in sorted(T.SCENES_DIR.glob("*/recipe.json"))]
    script = T.PRELUDE + """
from libfx import native, recipe, scene_setup
scene = bpy.context.scene
scene.render.engine = 'CYCLES'
vl = scene.view_layers[0]
def canon(r):
    with native.Context(1) as ctx:
        return native.Stack(ctx, r).to_json()
for path in %r:
    want = json.load(open(path))
    recipe.from_recipe(scene, json.dumps(want))
    got = recipe.to_recipe(scene, resolve_paths=False)
    # the same stack for the library, and the same params the recipe set (no more)
    assert canon(got) == canon(want), (path, got, want)
    for g, w in zip(got['effects'], want['effects']):
        assert g.get('params', {}) == w.get('params', {}), (path, g, w)
        assert g.get('mask', {}) == w.get('mask', {}), (path, g, w)
# passes: an object-index mask turns use_pass_object_index on; emptying the stack restores it
scene.libfx.stack.clear(); scene_setup.sync(scene)   # the last recipe's passes (Depth for mirrors) go
assert not vl.use_pass_object_index and not vl.use_pass_z
name = native.effect_names()[0]
recipe.from_recipe(scene, {'version': 1, 'effects': [{'effect': name, 'mask': {'object_index': 3}}]})
req = scene_setup.sync(scene)
assert 'IndexOB' in req['passes'] and vl.use_pass_object_index, req
assert 'use_pass_object_index' in json.loads(scene.libfx.owned)['settings'][vl.name]
vl.use_pass_z = True   # the user's own choice: never touched
scene.libfx.stack[0].enabled = False   # update callback syncs
assert not vl.use_pass_object_index and vl.use_pass_z
scene.libfx.stack[0].enabled = True
assert vl.use_pass_object_index
scene.libfx.stack.clear(); scene_setup.sync(scene)
assert not vl.use_pass_object_index and vl.use_pass_z
# Eevee cannot render index passes: the add-on says what to use instead
scene.render.engine = libfx.compat.eevee_engine()
recipe.from_recipe(scene, {'version': 1, 'effects': [{'effect': name, 'mask': {'object_index': 3}}]})
w = scene_setup.status(scene)['warnings']
assert any('Cryptomatte' in x for x in w), w
print('%s')
""" % (recipes, OK)
    _check(T.run_blender([], env=T.addon_env(library), python_expr=script))
