"""The recipe JSON the library runs, with no bpy: its version, how values are written
(float32 values as their shortest decimal, pass-index lists), parsing, and what the
library says about a recipe (validation, parameter migration).

recipe.py maps a scene's stack items to and from this; the CLI and any C program read
the same JSON (docs/recipes.md).
"""

import json
import struct

from . import native

RECIPE_VERSION = 1


class RecipeError(ValueError):
    pass


def f32(v):
    """The shortest decimal that is the same float32 (clean JSON from float32 RNA values)."""
    v = float(v)
    packed = struct.pack("<f", v)
    for digits in range(6, 10):
        s = float("%.*g" % (digits, v))
        if struct.pack("<f", s) == packed:
            return s
    return v


def indices(text, what):
    """'1, 2;3' -> [1, 2, 3]; RecipeError naming `what` for a token that is not an integer."""
    out = []
    for tok in text.replace(";", ",").split(","):
        tok = tok.strip()
        if not tok:
            continue
        try:
            out.append(int(tok))
        except ValueError:
            raise RecipeError("%s: '%s' is not an integer pass index" % (what, tok))
    return out


def one_or_list(values):
    return values[0] if len(values) == 1 else list(values)


def value_to_json(p, v, abspath=None):
    """A parameter value (p: a catalog.Param) as the recipe writes it; abspath(text) makes a
    path parameter absolute (None: as it is)."""
    if p.type == "float":
        return f32(v)
    if p.type == "int":
        return int(v)
    if p.type == "bool":
        return bool(v)
    if p.type == "enum":
        return str(v)
    if p.type == "floats":
        return [f32(x) for x in v]
    s = str(v)
    if abspath is not None and p.hint == "path" and s:
        s = abspath(s)
    return s


def value_from_json(p, value):
    """A recipe value as the parameter's Python type (enum: an index or a name). Raises
    TypeError, ValueError or IndexError when it is not one."""
    if p.type == "float":
        return float(value)
    if p.type == "int":
        return int(value)
    if p.type == "bool":
        return bool(value)
    if p.type == "enum":
        return p.items[int(value)] if isinstance(value, (int, float)) else str(value)
    if p.type == "floats":
        return [float(x) for x in value]
    return str(value)


def raw_to_json(v):
    """A stored value the current parameter table does not describe (an ID property:
    to_dict / to_list), as JSON."""
    if hasattr(v, "to_dict"):
        return {k: raw_to_json(x) for k, x in v.to_dict().items()}
    if hasattr(v, "to_list"):
        v = v.to_list()
    if isinstance(v, (list, tuple)):
        return [raw_to_json(x) for x in v]
    if isinstance(v, float):
        return f32(v)
    return v


def parse(text):
    try:
        recipe = json.loads(text)
    except ValueError as e:
        raise RecipeError("recipe is not JSON: %s" % e)
    if not isinstance(recipe, dict) or not isinstance(recipe.get("effects", []), list):
        raise RecipeError("recipe must be an object with an 'effects' list")
    return recipe


def validate(recipe):
    """Lets the library check the recipe (messages name effect, parameter, range)."""
    if native.load() is None:
        return
    with native.Context(1) as ctx:
        native.Stack(ctx, recipe).close()


def library_migrate(entry):
    """(the entry with its parameters migrated by the library to the effect's current
    table, the library's warnings): fx_stack_load_json migrates an entry that carries an
    older "params_version", fx_stack_to_json writes the result."""
    with native.Context(1) as ctx:
        stack = native.Stack(ctx, {"version": RECIPE_VERSION, "effects": [entry]})
        try:
            out = stack.to_json()["effects"][0]
        finally:
            stack.close()
        return out, ctx.warnings()


def check_migrated(migrated, eff):
    """The migrated entry's parameters, when they land in the effect's table (eff: a
    catalog.Effect): a library that stops short of the table's version, or returns names the
    table lacks, would otherwise drop values. Raises RecipeError."""
    new_params = migrated.get("params") or {}
    got = int(migrated.get("params_version", 1))
    if got != eff.params_version:
        raise RecipeError("the library migrates to parameter version %d, the panel's table is version %d"
                          % (got, eff.params_version))
    unknown = sorted(k for k in new_params if eff.param(k) is None)
    if unknown:
        raise RecipeError("the migrated parameters include %s, which the panel's table does not have"
                          % ", ".join(unknown))
    return new_params
