"""The building blocks of a TOML schema: typed keys, tables, error paths, near-miss suggestions.

A schema is a :class:`Table` of :class:`Key` s, each with a value type
(:class:`Number`, :class:`Choice`, :class:`Array`, a nested :class:`Table` or
:class:`TableArray`, ...). ``table.check(document, ())`` converts a parsed TOML
document or raises :class:`Invalid` with the path of the first offending key and,
for a near miss, the spelling the user probably meant (:func:`closest`). A key
put in the wrong table is answered with the tables of the schema that have it
(:func:`homes`, searched from the outermost table being checked).

:mod:`fem_elastic.app.scene_schema` builds the scene file's schema from these.
"""

from __future__ import annotations

import difflib
import math
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Any, Callable

__all__ = [
    "ABSENT", "REQUIRED",
    "Array", "Boolean", "Choice", "Displacements", "Fixed", "Integer", "Invalid", "Key", "NamedVectors", "Number",
    "String", "Table", "TableArray", "Type", "Vector",
    "closest", "format_path", "homes", "key_name", "split_path",
]

# ---------------------------------------------------------------------------------------
# errors and paths


class Invalid(Exception):
    """A scene document breaks the schema at ``path``.

    Parameters
    ----------
    path : tuple
        Keys (str) and array indices (int) from the document root to the
        offending key, e.g. ``("compare", 0, "body", "E")``.
    message : str
        What is wrong and how to fix it.
    suggestion : str or None
        The near-miss the user probably meant (a key or an allowed value).
    """

    def __init__(self, path: tuple, message: str, suggestion: str | None = None):
        super().__init__(message)
        self.path = tuple(path)
        self.message = message
        self.suggestion = suggestion


def format_path(path) -> str:
    """``("compare", 1, "body", "E")`` -> ``"compare[1].body.E"``.

    Examples
    --------
    >>> format_path(("loads", "driven", 0, "motion"))
    'loads.driven[0].motion'
    """
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


def split_path(path) -> tuple[tuple, str]:
    """The table a key is in, and the key as written there (with its array indices).

    Examples
    --------
    >>> split_path(("mesh", "cells", 1))
    (('mesh',), 'cells[1]')
    >>> split_path(("compare", 0, "body", "E"))
    (('compare', 0, 'body'), 'E')
    """
    path = tuple(path)
    k = len(path)
    while k > 0 and isinstance(path[k - 1], int):
        k -= 1
    if k == 0:
        return (), format_path(path)
    return path[:k - 1], format_path(path[k - 1:])


def key_name(path) -> str:
    """The key of ``path`` as written in its table, e.g. ``cells[1]``."""
    return split_path(path)[1] if path else "value"


def _toml(value) -> str:
    """A value as it is written in TOML (for messages and the help)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + "}"
    return repr(value)


def _kind_of(value) -> str:
    """How TOML spelled ``value``: for 'got ... (a string)' in messages."""
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, dict):
        return "a table"
    return f"a {type(value).__name__}"


def _got(value) -> str:
    text = _toml(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"got {text} ({_kind_of(value)})"


def closest(word: str, choices) -> str | None:
    """The allowed spelling nearest ``word`` (case, ``_`` and ``-`` ignored), or None.

    Examples
    --------
    >>> closest("neohookean", ["linear", "neo_hookean", "stable_neo_hookean"])
    'neo_hookean'
    >>> closest("xyz", ["linear", "stvk"]) is None
    True
    """
    choices = [str(c) for c in choices]

    def norm(s):
        return s.lower().replace("_", "").replace("-", "")

    exact = [c for c in choices if norm(c) == norm(word)]
    if exact:
        return exact[0]
    normed = {norm(c): c for c in choices}
    hit = difflib.get_close_matches(norm(word), list(normed), n=1, cutoff=0.6)
    return normed[hit[0]] if hit else None


# ---------------------------------------------------------------------------------------
# value types: each checks a TOML value and describes itself for the help


class Type:
    """A value type of the schema: :meth:`check` converts or raises :class:`Invalid`."""

    @property
    def label(self) -> str:
        """How the help names the accepted values (subclasses override it)."""
        return "value"

    def check(self, value, path: tuple, unit: str = ""):  # pragma: no cover - abstract
        raise NotImplementedError


def _unit(unit: str) -> str:
    return f" ({unit})" if unit else ""


@dataclass(frozen=True)
class Number(Type):
    """A finite real number; an integer is accepted, a boolean is not.

    ``gt``/``ge``/``lt``/``le`` bound it (exclusive/inclusive).
    """

    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None

    @property
    def label(self) -> str:
        lo = f"> {self.gt:g}" if self.gt is not None else f">= {self.ge:g}" if self.ge is not None else ""
        hi = f"< {self.lt:g}" if self.lt is not None else f"<= {self.le:g}" if self.le is not None else ""
        if lo and hi:
            left = "(" if self.gt is not None else "["
            right = ")" if self.lt is not None else "]"
            a = self.gt if self.gt is not None else self.ge
            b = self.lt if self.lt is not None else self.le
            return f"number in {left}{a:g}, {b:g}{right}"
        return " ".join(s for s in ("number", lo or hi) if s)

    def check(self, value, path, unit=""):
        name = key_name(path)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            hint = ""
            if isinstance(value, str):
                try:
                    float(value)
                    hint = f" Write {name} = {value.strip()} without quotes."
                except ValueError:
                    hint = ""
            raise Invalid(path, f"{name} must be a number{_unit(unit)}, {_got(value)}.{hint}")
        try:
            v = float(value)
        except OverflowError:  # an integer beyond the float range (TOML integers are unbounded here)
            v = math.inf
        if not math.isfinite(v):
            raise Invalid(path, f"{name} must be a finite number{_unit(unit)}, {_got(value)}.")
        bad = (
            (self.gt is not None and not v > self.gt)
            or (self.ge is not None and not v >= self.ge)
            or (self.lt is not None and not v < self.lt)
            or (self.le is not None and not v <= self.le)
        )
        if bad:
            raise Invalid(
                path, f"{name} = {value!r} is out of range: it must be a {self.label}{_unit(unit)}."
            )
        return v


@dataclass(frozen=True)
class Integer(Type):
    """An integer (not a boolean, not a float), at least ``ge``, or one of ``choices``."""

    ge: int | None = None
    choices: tuple = ()
    le: int | None = None

    @property
    def label(self) -> str:
        if self.choices:
            return " | ".join(str(c) for c in self.choices)
        if self.ge is not None and self.le is not None:
            return f"integer from {self.ge} to {self.le}"
        return "integer" + (f" >= {self.ge}" if self.ge is not None else "")

    def check(self, value, path, unit=""):
        name = key_name(path)
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                hint = f" Write {int(value)} without a decimal point."
            else:
                hint = ""
            raise Invalid(path, f"{name} must be an integer{_unit(unit)}, {_got(value)}.{hint}")
        if self.choices and value not in self.choices:
            raise Invalid(path, f"{name} = {value} is not allowed: it must be {self.label}.")
        if self.ge is not None and value < self.ge:
            raise Invalid(path, f"{name} = {value} is out of range: it must be >= {self.ge}{_unit(unit)}.")
        if self.le is not None and value > self.le:
            raise Invalid(path, f"{name} = {value} is out of range: it must be <= {self.le}{_unit(unit)}.")
        return value


@dataclass(frozen=True)
class Boolean(Type):
    """``true`` or ``false``."""

    label = "true | false"

    def check(self, value, path, unit=""):
        if not isinstance(value, bool):
            raise Invalid(path, f"{key_name(path)} must be true or false, {_got(value)}.")
        return value


@dataclass(frozen=True)
class String(Type):
    """Any string."""

    label = "string"

    def check(self, value, path, unit=""):
        if not isinstance(value, str):
            raise Invalid(path, f"{key_name(path)} must be a string (in quotes), {_got(value)}.")
        return value


@dataclass(frozen=True)
class Choice(Type):
    """One of a fixed set of strings; a near miss gets a suggestion."""

    choices: tuple

    @property
    def label(self) -> str:
        return " | ".join(f'"{c}"' for c in self.choices)

    def check(self, value, path, unit=""):
        name = key_name(path)
        if not isinstance(value, str):
            raise Invalid(path, f"{name} must be one of {self.label}, {_got(value)}.")
        if value not in self.choices:
            near = closest(value, self.choices)
            hint = f' — did you mean "{near}"?' if near else "."
            raise Invalid(
                path, f'{name} = "{value}" is not allowed{hint} Allowed values: {self.label}.', near
            )
        return value


@dataclass(frozen=True)
class Array(Type):
    """An array of ``item`` values, of length ``length`` (or any length if None)."""

    item: Type
    length: int | None = None
    label_text: str | None = None

    @property
    def label(self) -> str:
        if self.label_text:
            return self.label_text
        n = f"{self.length} " if self.length else ""
        return f"array of {n}({self.item.label})"

    def check(self, value, path, unit=""):
        name = key_name(path)
        if not isinstance(value, list):
            raise Invalid(path, f"{name} must be an array, {self.label}{_unit(unit)}; {_got(value)}.")
        if self.length is not None and len(value) != self.length:
            raise Invalid(
                path, f"{name} must have {self.length} entries ({self.label}{_unit(unit)}), "
                f"got {len(value)}: {_toml(value)}."
            )
        return [self.item.check(v, path + (i,), unit) for i, v in enumerate(value)]


def Vector(n: int = 3, item: Type = Number(), label: str | None = None) -> Array:
    """An array of ``n`` numbers, e.g. ``[0.0, 0.0, -9.81]``."""
    names = {3: "[x, y, z]", 2: "[a, b]"}
    return Array(item, n, label or f"{names.get(n, 'array')} numbers")


#: How the components a support holds are written in a scene file (for messages).
COMPONENTS_TEXT = 'a string of the components held, "x", "y", "z", "xy", "yz", "xz" or "xyz", or an array of three booleans'


def _components(value, path):
    """A support's components as written in a scene: "xz" or [true, false, true]."""
    if isinstance(value, str) and value and all(c in "xyz" for c in value) and len(set(value)) == len(value):
        return value
    if isinstance(value, list) and len(value) == 3 and all(isinstance(v, bool) for v in value) and any(value):
        return list(value)
    raise Invalid(path, f"{key_name(path)} must be {COMPONENTS_TEXT}; {_got(value)}.")


@dataclass(frozen=True)
class Fixed(Type):
    """What ``[boundary] fixed`` accepts: a boundary name, names, vertex indices, or a table
    ``{boundary = components}`` (``{ left = "x", bottom = "z" }``: rollers)."""

    label = ('boundary names, e.g. ["left"], vertex indices, e.g. [0, 1, 2], or a table of the '
             'components held, e.g. { left = "xyz", front = "z" }')

    def check(self, value, path, unit=""):
        if isinstance(value, str):
            return [value]
        if isinstance(value, dict):
            if not value:
                return []
            return {k: _components(v, path + (k,)) for k, v in value.items()}
        if isinstance(value, list):
            if all(isinstance(v, str) for v in value):
                return list(value)
            if all(isinstance(v, int) and not isinstance(v, bool) for v in value):
                for i, v in enumerate(value):
                    if v < 0:
                        raise Invalid(path + (i,), f"fixed vertex index {v} is negative; indices start at 0.")
                return list(value)
        raise Invalid(
            path,
            f"fixed must be a list of boundary names (e.g. [\"left\"]) or of vertex indices "
            f"(e.g. [0, 4, 7]), not a mix, or a table of the components each boundary holds "
            f"(e.g. {{ left = \"xyz\", front = \"z\" }}, components: {COMPONENTS_TEXT}); {_got(value)}.",
        )


@dataclass(frozen=True)
class Displacements(Type):
    """``[boundary] displacement``: ``{boundary = [ux, uy, uz]}`` (m), ``"free"`` for a free
    component, e.g. ``{ right = [0.01, "free", "free"] }``."""

    label = 'table {boundary = [ux, uy, uz]} (m), "free" for a component left free'

    def check(self, value, path, unit=""):
        if not isinstance(value, dict):
            raise Invalid(
                path, f"{key_name(path)} must be a table {{boundary = [ux, uy, uz]}} in metres, "
                f'"free" for a free component, e.g. {{ right = [0.01, "free", "free"] }}; {_got(value)}.'
            )
        out = {}
        for name, vec in value.items():
            p = path + (name,)
            if not isinstance(vec, list) or len(vec) != 3:
                raise Invalid(p, f'{key_name(p)} must be [ux, uy, uz] (m), "free" for a free '
                                 f'component, e.g. [0.01, "free", "free"]; {_got(vec)}.')
            comps = []
            for i, c in enumerate(vec):
                if c == "free":
                    comps.append(None)
                elif isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c):
                    comps.append(float(c))
                else:
                    raise Invalid(p + (i,), f'each component must be a finite number (m) or "free"; '
                                            f"{_got(c)}.")
            if all(c is None for c in comps):
                raise Invalid(p, f"{key_name(p)} leaves every component free: prescribe at least one.")
            out[name] = comps
        return out


@dataclass(frozen=True)
class NamedVectors(Type):
    """A table ``{boundary name = [x, y, z]}`` (traction per named boundary)."""

    item: Type = field(default_factory=Vector)
    label = "table {boundary = [x, y, z]}"

    def check(self, value, path, unit=""):
        if not isinstance(value, dict):
            raise Invalid(
                path, f"{key_name(path)} must be a table {{boundary = [x, y, z]}}, e.g. "
                f"{{ right = [0.0, 0.0, -1000.0] }}; {_got(value)}."
            )
        return {k: self.item.check(v, path + (k,), unit) for k, v in value.items()}


# ---------------------------------------------------------------------------------------
# keys and tables

REQUIRED = "required"  #: a key that must be present
#: a key that may be absent: it is then None in the validated spec
ABSENT = None


@dataclass(frozen=True)
class Key:
    """One key of a table.

    Parameters
    ----------
    name : str
    type : Type or Table or TableArray
    default : object
        ``REQUIRED``, ``ABSENT`` (None in the spec), a value, or a function of
        the table validated so far (for defaults that depend on other keys).
    unit : str
        SI unit, "" if none.
    doc : str
        One line for the help.
    when : dict or None
        ``{other key: allowed values}``: the key belongs to the table only
        when the other key (validated before it) has one of those values.
    aliases : tuple of str
        Other names users reach for (``young``, ``poisson``): an unknown key
        that matches one is answered with this key's name.
    default_text : str or None
        How the help shows a computed default.
    """

    name: str
    type: Any
    default: Any = REQUIRED
    unit: str = ""
    doc: str = ""
    when: dict | None = None
    aliases: tuple = ()
    default_text: str | None = None

    def applies(self, table: dict) -> bool:
        return self.when is None or all(table.get(k) in v for k, v in self.when.items())


@dataclass(frozen=True)
class Table:
    """A TOML table: its keys, and optional hooks for options and cross-key rules.

    Parameters
    ----------
    title : str
        Shown in the help.
    keys : tuple of Key
        In validation order: a key named in another key's ``when`` comes first.
    doc : str
    options : callable or None
        ``options(table, extra, path) -> dict``: validates the keys that are
        not in ``keys`` (the integrator's constructor options); None rejects them.
    rule : callable or None
        ``rule(table, path) -> table``: checks across keys, fills derived values.
    """

    title: str
    keys: tuple
    doc: str = ""
    options: Callable | None = None
    rule: Callable | None = None
    label = "table"

    def discriminators(self) -> set:
        """Keys that decide which other keys belong to the table (``mesh.kind``, ``body.type``)."""
        return {k for key in self.keys if key.when for k in key.when}

    def required(self) -> list[str]:
        return [k.name for k in self.keys if k.default is REQUIRED and k.when is None]

    def check(self, value, path, unit=""):
        if _ROOT.get() is not None:
            return self._check(value, path)
        token = _ROOT.set(self)  # the outermost table: where a misplaced key is looked for
        try:
            return self._check(value, path)
        finally:
            _ROOT.reset(token)

    def _check(self, value, path):
        if not isinstance(value, dict):
            where = f"[{format_path(path)}]" if path else "the file"
            raise Invalid(path, f"{where} must be a table, {_got(value)}.")
        out: dict = {}
        applicable: dict[str, Key] = {}
        missing = []
        for key in self.keys:
            if not key.applies(out):
                continue
            applicable[key.name] = key
            if key.name not in value and key.default is REQUIRED:
                if key.name in self.discriminators():
                    raise self._missing(key, path)
                missing.append(key)
                out[key.name] = None
            else:
                out[key.name] = self._value(key, value, out, path)
        # an unknown key first: it is often the misspelling of a missing one
        unknown = [k for k in value if k not in applicable]
        if unknown and self.options is None:
            raise self._unknown(unknown[0], applicable, value, out, path)
        if missing:
            raise self._missing(missing[0], path)
        if self.options is not None:
            out.update(self.options(out, {k: value[k] for k in unknown}, path))
        if self.rule is not None:
            out = self.rule(out, path)
        return out

    def _missing(self, key: Key, path: tuple) -> Invalid:
        p = path + (key.name,)
        if isinstance(key.type, Table):
            keys = key.type.required()
            add = f": add [{format_path(p)}]" + (f" with {', '.join(keys)}" if keys else "")
            return Invalid(p, f"missing table [{format_path(p)}] ({key.doc}){add}.")
        example = f", e.g. {key.name} = {key.default_text}" if key.default_text else ""
        return Invalid(p, f"missing required key {key.name}: {key.doc}{_unit(key.unit)}{example}.")

    def _value(self, key: Key, value: dict, out: dict, path: tuple):
        p = path + (key.name,)
        if key.name in value:
            return key.type.check(value[key.name], p, key.unit)
        if callable(key.default):
            return key.default(out)
        if isinstance(key.default, dict) and isinstance(key.type, Table):
            return key.type.check(dict(key.default), p)
        if isinstance(key.default, (list, dict)):
            return type(key.default)(key.default)
        return key.default

    def _unknown(self, name, applicable, value, out, path) -> Invalid:
        p = path + (name,)
        # a key of another variant of this table (e.g. "path" with kind = "beam")
        for key in self.keys:
            if key.name == name and key.when:
                cond = " or ".join(
                    f"{k} = {' | '.join(_toml(v) for v in vals)}" for k, vals in key.when.items()
                )
                now = ", ".join(f"{k} = {_toml(out.get(k))}" for k in key.when)
                return Invalid(p, f"key {name} applies only when {cond} (here {now}). "
                                  f"Allowed keys here: {', '.join(applicable)}.")
        near = None
        for key in applicable.values():
            if name.lower() in key.aliases:
                near = key.name
        near = near or closest(name, applicable)
        if near in value:  # the near miss is there already: no use suggesting it
            near = None
        elsewhere = [] if near else homes(_ROOT.get() or self, name)
        if not path:
            hint = f" — did you mean [{near}]?" if near else "."
            if elsewhere:
                hint = f": {name} is a key of {' and '.join(elsewhere)}."
            what = f"table [{name}]" if isinstance(value[name], dict) else f'top-level key "{name}"'
            allowed = ", ".join(f"[{k}]" for k in applicable)
            return Invalid(p, f"unknown {what}{hint} Allowed tables: {allowed}.", near)
        hint = f' — did you mean "{near}"?' if near else "."
        if elsewhere:
            hint = f": {name} is a key of {' and '.join(elsewhere)}, not of this table."
        return Invalid(p, f'unknown key "{name}"{hint} Allowed keys: {", ".join(applicable)}.', near)


#: the table whose check is under way outermost (the document's root), for :func:`homes`
_ROOT: ContextVar[Table | None] = ContextVar("fem_elastic_schema_root", default=None)


def homes(root: Table, name: str) -> list[str]:
    """Tables under ``root`` that have a key ``name`` (for a key put in the wrong table).

    Examples
    --------
    >>> inner = Table("b", (Key("x", Number()),))
    >>> homes(Table("root", (Key("a", Table("a", (Key("b", inner),))),)), "x")
    ['[a.b]']
    """
    found = []

    def walk(table: Table, where: str):
        for key in table.keys:
            sub = key.type.table if isinstance(key.type, TableArray) else key.type
            here = f"{where}.{key.name}" if where else key.name
            if key.name == name and where and f"[{where}]" not in found:
                found.append(f"[{where}]")
            if isinstance(sub, Table) and sub is not table:
                walk(sub, here)

    walk(root, "")
    return found


@dataclass(frozen=True)
class TableArray(Type):
    """An array of tables (``[[compare]]``, ``[[loads.driven]]``), each checked by ``table``."""

    table: Table

    @property
    def label(self) -> str:
        return f"array of tables ({self.table.title})"

    def check(self, value, path, unit=""):
        if isinstance(value, dict):
            value = [value]
        if not isinstance(value, list):
            raise Invalid(path, f"{key_name(path)} must be an array of tables, written "
                                f"[[{format_path(path)}]]; {_got(value)}.")
        return [self.table.check(v, path + (i,)) for i, v in enumerate(value)]
