"""The scene's effect stack <-> the library's recipe JSON (recipe_json.py: the JSON itself).

One code path for the UI, F12, batch runs and the CLI: whatever runs, runs the
JSON that ``to_recipe`` makes.  Only parameters the user set are written (the
rest are left to the effect's defaults and quality presets); ``from_recipe``
sets exactly the parameters the recipe names.
"""

import json

import bpy

from . import hooks, native, props
from . import recipe_json
from .recipe_json import (RECIPE_VERSION, RecipeError, indices, library_migrate,  # noqa: F401
                          one_or_list, parse, raw_to_json, validate, value_from_json, value_to_json)

TEXT_NAME = "libfx_recipe.json"


def mask_to_json(item):
    kinds = item.mask_kinds
    m = {}
    where = "effect '%s' mask" % item.effect
    if "MATERIAL" in kinds:
        names = [n.name for n in item.mask_materials if n.name]
        if names:
            m["material"] = one_or_list(names)
    if "OBJECT" in kinds:
        names = [n.name for n in item.mask_objects if n.name]
        if names:
            m["object"] = one_or_list(names)
    if "MATERIAL_INDEX" in kinds:
        idx = indices(item.mask_material_indices, where + " material indices")
        if idx:
            m["material_index"] = one_or_list(idx)
    if "OBJECT_INDEX" in kinds:
        idx = indices(item.mask_object_indices, where + " object indices")
        if idx:
            m["object_index"] = one_or_list(idx)
    if "RECT" in kinds:
        m["rect"] = list(item.mask_rect)
    if m and item.mask_invert:
        m["invert"] = True
    return m


def _value_to_json(p, v, resolve_paths):
    return value_to_json(p, v, bpy.path.abspath if resolve_paths else None)


def set_params(item, eff, resolve_paths=True):
    """The parameters the user set, by the library's names (the rest are left to the
    effect's defaults and the quality presets)."""
    group = props.effect_group(item)
    params = {}
    for p in eff.params:
        if group is not None and group.is_property_set(p.prop):
            params[p.name] = _value_to_json(p, getattr(group, p.prop), resolve_paths)
    return params


def stored_params(item, eff, resolve_paths=True):
    """Every value stored in the item's parameter group, also under names the current
    table no longer has (a parameter renamed since the file was saved: its value stays
    in the .blend as an ID property the new class does not show). Known names are
    converted by their type; unknown ones are sent as stored, for the library to
    migrate."""
    group = props.effect_group(item)
    if group is None:
        return {}
    known = {p.prop: p for p in eff.params}
    params = {}
    for key in group.keys():
        p = known.get(key)
        if p is not None:
            if group.is_property_set(p.prop):
                params[p.name] = _value_to_json(p, getattr(group, p.prop), resolve_paths)
        else:
            params[key] = raw_to_json(group[key])
    return params


def needs_migration(item, eff):
    return eff is not None and item.params_version < eff.params_version


def item_to_json(item, resolve_paths=True):
    cat = props.catalog()
    eff = cat.effects.get(item.effect) if cat else None
    if eff is None:
        if item.raw_json:
            entry = json.loads(item.raw_json)
            entry["enabled"] = bool(item.enabled)
            return entry
        return {"effect": item.effect, "enabled": bool(item.enabled)}
    entry = {"effect": item.effect, "enabled": bool(item.enabled)}
    if item.label:
        entry["label"] = item.label
    if item.quality != "STACK":
        entry["quality"] = item.quality
    if needs_migration(item, eff):
        # values from an older table: all of them, as stored, for the library to migrate
        params = stored_params(item, eff, resolve_paths)
    else:
        params = set_params(item, eff, resolve_paths)
    if item.params_version != 1 or needs_migration(item, eff):
        entry["params_version"] = int(item.params_version)   # absent: version 1
    if params:
        entry["params"] = params
    mask = mask_to_json(item)
    if mask:
        entry["mask"] = mask
    return entry


def to_recipe(scene, resolve_paths=True):
    """The scene's stack as a recipe dict (paths made absolute unless exporting)."""
    s = scene.libfx
    return {"version": RECIPE_VERSION, "quality": s.quality,
            "effects": [item_to_json(item, resolve_paths) for item in s.stack]}


def to_json_text(scene, resolve_paths=True):
    return json.dumps(to_recipe(scene, resolve_paths), indent=2) + "\n"


def _set_param(group, p, value, where):
    try:
        setattr(group, p.prop, value_from_json(p, value))
    except (TypeError, ValueError, IndexError) as e:
        raise RecipeError("%s: parameter '%s' = %r: %s" % (where, p.name, value, e))


def _fill_names(coll, value):
    coll.clear()
    for n in value if isinstance(value, list) else [value]:
        coll.add().name = str(n)


def _fill_mask(item, mask):
    kinds = set()
    if "material" in mask:
        kinds.add("MATERIAL")
        _fill_names(item.mask_materials, mask["material"])
    if "object" in mask:
        kinds.add("OBJECT")
        _fill_names(item.mask_objects, mask["object"])
    for key, kind, attr in (("material_index", "MATERIAL_INDEX", "mask_material_indices"),
                            ("object_index", "OBJECT_INDEX", "mask_object_indices")):
        if key in mask:
            kinds.add(kind)
            v = mask[key]
            setattr(item, attr, ", ".join(str(int(x)) for x in (v if isinstance(v, list) else [v])))
    if "rect" in mask:
        kinds.add("RECT")
        item.mask_rect = [int(x) for x in mask["rect"]]
    item.mask_invert = bool(mask.get("invert", False))
    item.mask_kinds = kinds


def fill_item(item, entry, n=0):
    """Sets a stack item from one recipe entry (only the parameters it names). An entry
    of an older parameter version is migrated by the library first."""
    cat = props.catalog()
    name = entry.get("effect", "")
    where = "effect %d (%s)" % (n, name)
    with props.suspended():
        item.effect = name
        item.enabled = bool(entry.get("enabled", True))
        item.label = str(entry.get("label", ""))
        q = entry.get("quality")
        item.quality = q if (q and cat and q in cat.qualities) else "STACK"
        _fill_mask(item, entry.get("mask") or {})
        eff = cat.effects.get(name) if cat else None
        if eff is None:
            item.raw_json = json.dumps(entry)
            return
        if int(entry.get("params_version", 1)) < eff.params_version:
            entry, _ = library_migrate(entry)
        item.params_version = eff.params_version
        group = props.effect_group(item)
        for pname, value in (entry.get("params") or {}).items():
            p = eff.param(pname)
            if p is None:
                raise RecipeError("%s: unknown parameter '%s'" % (where, pname))
            _set_param(group, p, value, where)


# ---------------------------------------------------------------- parameter versions

def migrate_item(item, n=0, migrate=library_migrate):
    """Brings an item whose parameters were saved with an older table up to the library's:
    its stored values (old names included) go through ``migrate``, the migrated values are
    written back, old names the table no longer has are removed, and the version is bumped.
    Returns the messages to show, or [] when there was nothing to do. Raises
    native.LibfxError / RecipeError when the values cannot be migrated (the item is left
    as it was: runs still send the stored values for the library to migrate)."""
    cat = props.catalog()
    eff = cat.effects.get(item.effect) if cat else None
    if not needs_migration(item, eff):
        return []
    where = "effect %d (%s)" % (n, item.effect)
    old = item.params_version
    entry = item_to_json(item, resolve_paths=False)
    migrated, warnings = migrate(entry)
    # Only what lands in this table is written back.
    new_params = recipe_json.check_migrated(migrated, eff)
    group = props.effect_group(item)
    with props.suspended():
        known = {p.prop for p in eff.params}
        for key in list(group.keys()):
            if key not in known:
                del group[key]           # migrated: its value now lives under the new name
        for p in eff.params:
            if p.name in new_params:
                _set_param(group, p, new_params[p.name], where)
            elif group.is_property_set(p.prop):
                group.property_unset(p.prop)
        item.params_version = eff.params_version
    return ["%s: parameters saved with version %d migrated to version %d" % (where, old, eff.params_version)] + [
        "%s: %s" % (where, w) for w in warnings]


def migrate_stack(scene, migrate=library_migrate):
    """migrate_item for every item of the scene's stack (file load); returns the messages
    (also the failures: such an item stays as stored)."""
    out = []
    for n, item in enumerate(scene.libfx.stack):
        try:
            out += migrate_item(item, n, migrate)
        except (native.LibfxError, RecipeError, ValueError, KeyError, IndexError) as e:
            out.append("effect %d (%s): parameters saved with version %d cannot be migrated: %s"
                       % (n, item.effect, item.params_version, e))
    return out


def from_recipe(scene, recipe, check=True):
    """Replaces the scene's stack with the recipe's effects."""
    if isinstance(recipe, str):
        recipe = parse(recipe)
    if check:
        validate(recipe)
    cat = props.catalog()
    s = scene.libfx
    with props.suspended():
        s.stack.clear()
        if "quality" in recipe and cat and recipe["quality"] in cat.qualities:
            s.quality = recipe["quality"]
        for n, entry in enumerate(recipe.get("effects", [])):
            fill_item(s.stack.add(), entry, n)
        s.active_index = 0
    hooks.notify("stack_changed", scene)


def load_text_block(scene, force=False):
    """Imports the scene's Text datablock libfx_recipe.json if the stack is empty."""
    text = bpy.data.texts.get(TEXT_NAME)
    if text is None or (len(scene.libfx.stack) and not force):
        return False
    from_recipe(scene, text.as_string())
    return True
