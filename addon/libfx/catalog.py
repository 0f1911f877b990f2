"""The effect catalogue, as the library describes it (fx_effect_describe_json).

Nothing about an effect is written in Python: names, docs, parameters, types,
defaults, ranges, enum items and quality presets all come from the library.
This module only normalises the JSON into small records the UI code uses.
No bpy here.
"""

import re

from . import native

FLOAT_LIMIT = 3.0e38
INT_LIMIT = 2 ** 31 - 1
TYPES = ("float", "int", "bool", "enum", "floats", "string")
# Python/RNA names a parameter may not take as a Blender property identifier.
_RESERVED = {"name", "rna_type", "bl_rna", "type", "effect", "enabled"}


class Param:
    __slots__ = ("name", "prop", "type", "doc", "hint", "default", "min", "max",
                 "soft_min", "soft_max", "count", "items")

    def label(self):
        return self.name.replace("_", " ").strip().capitalize()


class Effect:
    __slots__ = ("name", "doc", "params", "presets", "passes", "needs_camera", "halo", "raw",
                 "params_version")

    def param(self, name):
        for p in self.params:
            if p.name == name:
                return p
        return None

    def preset_value(self, quality, param_name):
        return self.presets.get(quality, {}).get(param_name)

    def label(self):
        return self.name.replace("_", " ").strip().title()


def _num(v, default, limit):
    try:
        f = float(v)
    except (TypeError, ValueError):
        return default
    if f != f:
        return default
    return max(-limit, min(limit, f))


def prop_identifier(name):
    """A Blender property identifier for a parameter name (kept 1:1 with the name
    where possible)."""
    ident = re.sub(r"\W", "_", name)
    if not ident or ident[0].isdigit() or ident in _RESERVED or ident.startswith("bl_"):
        ident = "p_" + ident
    return ident[:60]


def _type(v):
    if isinstance(v, int):
        return TYPES[v] if 0 <= v < len(TYPES) else "float"
    v = str(v).lower()
    if v.startswith("fx_param_"):
        v = v[len("fx_param_"):]
    aliases = {"double": "float", "integer": "int", "boolean": "bool", "vector": "floats",
               "float_array": "floats", "str": "string", "choice": "enum"}
    return aliases.get(v, v if v in TYPES else "float")


def normalise(name, d):
    e = Effect()
    e.raw = d
    e.name = d.get("name", name)
    e.doc = d.get("doc") or d.get("description") or ""
    e.params = []
    for pd in d.get("params", d.get("parameters", [])):
        p = Param()
        p.name = pd["name"]
        p.prop = prop_identifier(p.name)
        p.type = _type(pd.get("type", "float"))
        p.doc = pd.get("doc") or pd.get("description") or ""
        p.hint = pd.get("hint") or ""
        p.count = int(pd.get("count", 1) or 1)
        items = pd.get("items", pd.get("enum_items")) or []
        p.items = [str(i) for i in items]
        limit = INT_LIMIT if p.type == "int" else FLOAT_LIMIT
        p.min = _num(pd.get("min"), -limit, limit)
        p.max = _num(pd.get("max"), limit, limit)
        p.soft_min = _num(pd.get("soft_min"), p.min, limit)
        p.soft_max = _num(pd.get("soft_max"), p.max, limit)
        dv = pd.get("default", pd.get("default_value"))
        if p.type == "floats":
            if not isinstance(dv, list):
                dv = pd.get("default_floats") or [0.0] * p.count
            p.default = [float(x) for x in dv][:p.count] + [0.0] * max(0, p.count - len(dv))
        elif p.type == "string":
            p.default = dv if isinstance(dv, str) else (pd.get("default_string") or "")
        elif p.type == "enum":
            if isinstance(dv, str) and dv in p.items:
                p.default = dv
            elif isinstance(dv, (int, float)) and 0 <= int(dv) < len(p.items):
                p.default = p.items[int(dv)]
            else:
                p.default = p.items[0] if p.items else ""
        elif p.type == "bool":
            p.default = bool(dv)
        elif p.type == "int":
            p.default = int(_num(dv, 0, INT_LIMIT))
        else:
            p.default = _num(dv, 0.0, FLOAT_LIMIT)
        e.params.append(p)
    presets = d.get("presets", d.get("quality_presets")) or {}
    if isinstance(presets, list):  # [draft, preview, final, reference] by index
        names = native.quality_names()
        presets = {names[i]: v for i, v in enumerate(presets) if i < len(names) and v}
    e.presets = {k: (v or {}) for k, v in presets.items()}
    e.passes = list(d.get("passes", []))
    e.needs_camera = bool(d.get("camera", d.get("needs_camera", False)))
    e.params_version = 1
    e.halo = d.get("halo", 0)
    return e


class Catalog:
    """Everything the library says about its effects (parameters, presets, parameter
    versions), asked once per registration and kept for the session."""

    def __init__(self):
        self.effects = {}
        self.order = []
        self.qualities = []
        self.version = ""
        self.path = ""
        self.error = None
        self.warnings = []

    @classmethod
    def load(cls):
        cat = cls()
        native.retry_if_failed()
        if native.load() is None:
            cat.error = native.load_error()
            return cat
        try:
            cat.version = native.version()
            cat.path = native.library_path()
            cat.qualities = native.quality_names()
            cat.warnings.extend(native.feature_problems())
            with native.Context(1) as ctx:
                for name in native.effect_names():
                    try:
                        desc = ctx.describe(name)
                        cat.effects[name] = normalise(name, desc)
                        # in the description since ABI 2 (no second query, no context per effect)
                        cat.effects[name].params_version = max(1, int(desc.get("params_version", 1)))
                        cat.order.append(name)
                    except (native.LibfxError, ValueError, KeyError) as e:
                        cat.warnings.append("effect %s cannot be described: %s" % (name, e))
        except native.LibfxError as e:
            cat.error = str(e)
        return cat

    @property
    def ok(self):
        return self.error is None
