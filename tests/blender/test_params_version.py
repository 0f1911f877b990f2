"""Per-effect parameter versions, the add-on's half: a stack item keeps the version of the
parameter table its values were saved with; when the library's is newer, every stored
value (also one under a name the current table no longer has) goes to the library with
the stored version, and the migrated values are written back."""
import shutil

import addon_testlib as T

OK = "LIBFX-TEST-OK"
STATE_BLEND = T.REPO / "tests" / "data" / "blender" / "addon_state_blender34.blend"


def _check(proc):
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-4000:]
    assert OK in proc.stdout, out[-4000:]
    assert not T.tracebacks(out), out[-4000:]
    return out


def test_a_value_under_an_old_name_is_sent_and_migrated_not_dropped(blender, library, tmp_path):
    saved = tmp_path / "versions.blend"
    script = T.PRELUDE + r"""
from libfx import recipe, props
scene = bpy.context.scene
cat = props.catalog()
eff = cat.effects['gaussian_blur']
assert eff.params_version >= 1
it = scene.libfx.stack.add()
it.effect = 'gaussian_blur'
assert it.params_version == 1          # the default: what a file saved before versions reads
g = it.fx_gaussian_blur
g.sigma = 2.5
g['old_sigma'] = 7.0                   # a value the .blend keeps under a renamed parameter
g['old_kernel'] = 1                    # (an enum is stored as its index)
assert 'old_sigma' not in [p.identifier for p in g.bl_rna.properties]

# same version as the library: only the parameters the table knows, and no version key
e = recipe.item_to_json(it)
assert e['params'] == {'sigma': 2.5} and 'params_version' not in e, e

# the library's table is newer: every stored value goes, under its stored name, with the
# stored version (nothing is dropped)
eff.params_version = 3
e = recipe.item_to_json(it)
assert e['params_version'] == 1, e
assert e['params'] == {'sigma': 2.5, 'old_sigma': 7.0, 'old_kernel': 1}, e
assert recipe.to_recipe(scene)['effects'][0] == e

# what the library migrates is written back, the old names go, the version follows
sent = []
def migrate(entry):   # stands in for the library (fx_stack_load_json + fx_stack_to_json)
    sent.append(entry)
    p = dict(entry['params'])
    p['sigma'] = p.pop('old_sigma')
    p.pop('old_kernel')
    return dict(entry, params=p, params_version=3), ['sigma was called old_sigma']
notes = recipe.migrate_stack(scene, migrate)
assert sent and sent[0]['params']['old_sigma'] == 7.0, sent
assert it.params_version == 3
assert abs(g.sigma - 7.0) < 1e-6 and 'old_sigma' not in g.keys() and 'old_kernel' not in g.keys(), g.keys()
assert any('version 1 migrated to version 3' in n for n in notes), notes
assert any('old_sigma' in n for n in notes), notes
e = recipe.item_to_json(it)
assert e['params'] == {'sigma': 7.0} and e['params_version'] == 3, e
assert recipe.migrate_stack(scene, migrate) == [] and len(sent) == 1   # once only

# a migration that fails leaves the item as stored and says why
it2 = scene.libfx.stack.add()
it2.effect = 'gaussian_blur'
it2.fx_gaussian_blur['old_sigma'] = 4.0
def refuse(entry):
    raise recipe.RecipeError('no way')
notes = recipe.migrate_stack(scene, refuse)
assert it2.params_version == 1 and it2.fx_gaussian_blur['old_sigma'] == 4.0
assert any('cannot be migrated' in n and 'no way' in n for n in notes), notes

# the stored version is kept in the file
eff.params_version = 1
scene.libfx.stack.remove(1)
bpy.ops.wm.save_as_mainfile(filepath=%r)
bpy.ops.wm.open_mainfile(filepath=%r)
it = bpy.context.scene.libfx.stack[0]
assert it.params_version == 3 and abs(it.fx_gaussian_blur.sigma - 7.0) < 1e-6
print(%r)
""" % (str(saved), str(saved), OK)
    _check(T.run_blender([], env=T.addon_env(library), python_expr=script))


def test_new_items_take_the_library_version_and_old_files_read_version_1(blender, library, tmp_path):
    blend = tmp_path / STATE_BLEND.name
    shutil.copy(STATE_BLEND, blend)
    script = T.PRELUDE + r"""
from libfx import recipe, props, native
cat = props.catalog()
s = bpy.context.scene
assert len(s.libfx.stack), [sc.name for sc in bpy.data.scenes]
# saved before parameter versions existed: version 1, and nothing to migrate today
assert all(it.params_version == 1 for it in s.libfx.stack)
assert all(cat.effects[it.effect].params_version == native.effect_params_version(it.effect)
           for it in s.libfx.stack)
bpy.ops.libfx.stack_add(effect='pixelate')
it = s.libfx.stack[len(s.libfx.stack) - 1]
assert it.params_version == cat.effects['pixelate'].params_version
print(%r)
""" % OK
    _check(T.run_blender([], blend=blend, env=T.addon_env(library), python_expr=script))


def test_a_parameter_renamed_in_the_library_keeps_its_saved_value(blender, library, tmp_path):
    """The real case: a .blend saved while the table called it 'sigma'; the add-on then
    registers a table that calls it 'radius' (version 2): the saved value, which the new
    class no longer shows, is still collected under 'sigma' and sent with version 1.
    Today's library cannot migrate (it has no version 2): the item stays as stored and the
    panel says so."""
    saved = tmp_path / "renamed.blend"
    script = T.PRELUDE + r"""
from libfx import catalog, recipe, props, scene_setup
scene = bpy.context.scene
it = scene.libfx.stack.add()
it.effect = 'gaussian_blur'
it.fx_gaussian_blur.sigma = 7.0
bpy.ops.wm.save_as_mainfile(filepath=%r)
libfx.unregister()
load = catalog.Catalog.load
def renamed(cls):
    cat = load.__func__(cls)
    eff = cat.effects['gaussian_blur']
    p = eff.param('sigma')
    p.name = p.prop = 'radius'
    eff.params_version = 2
    return cat
catalog.Catalog.load = classmethod(renamed)
libfx.register()
bpy.ops.wm.open_mainfile(filepath=%r)
scene = bpy.context.scene
it = scene.libfx.stack[0]
group = it.fx_gaussian_blur
assert 'sigma' not in [p.identifier for p in group.bl_rna.properties]
assert not group.is_property_set('radius')
e = recipe.item_to_json(it)
assert e['params_version'] == 1 and e['params'].get('sigma') == 7.0, e
notes = scene_setup.status(scene).get('migrated')
assert it.params_version == 1 and notes and 'cannot be migrated' in notes[0], notes
print(%r)
""" % (str(saved), str(saved), OK)
    _check(T.run_blender([], env=T.addon_env(library), python_expr=script))
