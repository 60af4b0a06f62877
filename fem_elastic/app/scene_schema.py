"""The scene-file schema: every table and key, its type, unit, default and allowed values.

:data:`SCENE_FILE` is the one description of a scene file. :func:`validate`
walks it to check a parsed TOML document and fill in the defaults, and
:func:`schema_help` walks it to print the reference that ``fem-elastic run
--help`` shows, so the two cannot disagree. The names a scene file may use for
materials, integrators, spring calibrations, contact methods and linear
solvers are the keys of the tables below (:data:`MATERIALS`,
:data:`INTEGRATORS`, ...), which map them to the library's classes.

Errors are raised as :class:`Invalid` with the *path* of the offending key, a
tuple such as ``("compare", 1, "body", "material")``; :mod:`fem_elastic.app.scene`
turns it into a :class:`fem_elastic.app.scene.SceneError` with the file and line.

Units are SI (m, s, kg, Pa, N); angles in a scene file are in degrees.
"""

from __future__ import annotations

import difflib
import inspect
import math
import re
import textwrap
from dataclasses import dataclass, field
from typing import Any, Callable

from ..physics.contact import METHODS as CONTACT_METHODS
from ..physics.damping import Rayleigh
from ..errors import InvalidParameter
from ..dynamics.integrators import (
    RK4,
    ExplicitEuler,
    ImplicitEuler,
    LinearizedImplicitEuler,
    Midpoint,
    Newmark,
    SymplecticEuler,
)
from ..solvers.linear_solvers import AMGSolver, AutoSolver, DirectSolver
from ..materials import Corotated, LinearElastic, NeoHookean, StableNeoHookean, StVK
from ..physics.springs import lloyd_stiffness, van_gelder_stiffness

__all__ = [
    "CALIBRATIONS", "INTEGRATORS", "LINEAR_SOLVERS", "MATERIALS", "SCENE_FILE",
    "Invalid", "Key", "Table", "TableArray",
    "closest", "format_path", "integrator_options", "key_name", "make_integrator",
    "schema_help", "split_path", "validate",
]

# ---------------------------------------------------------------------------------------
# the names a scene file uses, mapped to the library

MATERIALS = {
    "linear": LinearElastic,
    "stvk": StVK,
    "neo_hookean": NeoHookean,
    "stable_neo_hookean": StableNeoHookean,
    "corotated": Corotated,
}
INTEGRATORS = {
    "explicit_euler": ExplicitEuler,
    "symplectic_euler": SymplecticEuler,
    "midpoint": Midpoint,
    "rk4": RK4,
    "implicit_euler": ImplicitEuler,
    "linearized_implicit_euler": LinearizedImplicitEuler,
    "newmark": Newmark,
}
CALIBRATIONS = {"van_gelder": van_gelder_stiffness, "lloyd": lloyd_stiffness}
#: ``linear_solver = "..."`` in [integrator]: the solver objects it stands for
LINEAR_SOLVERS = {"auto": AutoSolver, "direct": DirectSolver, "amg": AMGSolver}
MOTIONS = ("twist", "translate")
RENDER_FORMATS = ("mp4", "gif", "png")
COLOR_FIELDS = ("von_mises", "displacement")


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

    label = "value"

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

    @property
    def label(self) -> str:
        if self.choices:
            return " | ".join(str(c) for c in self.choices)
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


@dataclass(frozen=True)
class Fixed(Type):
    """What ``[boundary] fixed`` accepts: a boundary name, names, or vertex indices."""

    label = 'boundary names, e.g. ["left"], or vertex indices, e.g. [0, 1, 2]'

    def check(self, value, path, unit=""):
        if isinstance(value, str):
            return [value]
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
            f"(e.g. [0, 4, 7]), not a mix; {_got(value)}.",
        )


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
        homes = [] if near else _homes(name)
        if not path:
            hint = f" — did you mean [{near}]?" if near else "."
            if homes:
                hint = f": {name} is a key of {' and '.join(homes)}."
            what = f"table [{name}]" if isinstance(value[name], dict) else f'top-level key "{name}"'
            allowed = ", ".join(f"[{k}]" for k in applicable)
            return Invalid(p, f"unknown {what}{hint} Allowed tables: {allowed}.", near)
        hint = f' — did you mean "{near}"?' if near else "."
        if homes:
            hint = f": {name} is a key of {' and '.join(homes)}, not of this table."
        return Invalid(p, f'unknown key "{name}"{hint} Allowed keys: {", ".join(applicable)}.', near)


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


# ---------------------------------------------------------------------------------------
# integrator options: taken from the constructor's signature


def _constructor_parameters(cls) -> list[inspect.Parameter]:
    """Keyword parameters of ``cls.__init__``; through ``*args, **kwargs`` to the parent's."""
    for klass in cls.__mro__:
        init = klass.__dict__.get("__init__")
        if init is None:
            continue
        params = list(inspect.signature(init).parameters.values())[1:]
        if any(p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD) for p in params):
            continue  # passes everything on: the parent's signature is the real one
        return [p for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    return []


#: integrator options whose values are names: the allowed names (for suggestions)
OPTION_CHOICES = {"mass": ("lumped", "consistent"), "linear_solver": tuple(LINEAR_SOLVERS)}


def _option_type(param: inspect.Parameter) -> Type | None:
    """The scene type of an integrator option: from :data:`OPTION_CHOICES`, else its default."""
    if param.name in OPTION_CHOICES:
        return Choice(OPTION_CHOICES[param.name])
    d = param.default
    if isinstance(d, bool):
        return Boolean()
    if isinstance(d, int):
        return Integer()
    if isinstance(d, float):
        return Number()
    if isinstance(d, str):
        return String()
    return None  # not expressible in TOML: the option cannot be set from a scene


def integrator_options(name: str) -> dict[str, tuple[Type, Any]]:
    """``{option: (type, default)}`` of the integrator ``name`` (see :data:`INTEGRATORS`).

    Examples
    --------
    >>> sorted(integrator_options("linearized_implicit_euler"))
    ['linear_solver', 'mass', 'project', 'warping']
    >>> sorted(integrator_options("rk4"))
    ['max_substeps', 'recheck_every', 'safety', 'substep']
    """
    out = {}
    for p in _constructor_parameters(INTEGRATORS[name]):
        t = _option_type(p)
        if t is not None:
            out[p.name] = (t, "auto" if p.name == "linear_solver" else p.default)
    return out


def make_integrator(spec: dict):
    """The integrator object of a validated ``[integrator]`` table (a fresh one each call)."""
    cls = INTEGRATORS[spec["type"]]
    kwargs = {k: v for k, v in spec.items() if k != "type"}
    if "linear_solver" in kwargs:
        kwargs["linear_solver"] = LINEAR_SOLVERS[kwargs["linear_solver"]]()
    return cls(**kwargs)


def _integrator_options(table: dict, extra: dict, path: tuple) -> dict:
    name = table["type"]
    allowed = integrator_options(name)
    out = {}
    for key, value in extra.items():
        if key not in allowed:
            near = closest(key, allowed)
            hint = f' — did you mean "{near}"?' if near else "."
            listed = ", ".join(allowed) if allowed else f"none ({name} takes no options)"
            raise Invalid(path + (key,), f'unknown option "{key}" for integrator "{name}"{hint} '
                                         f"Its options: {listed}.", near)
        out[key] = allowed[key][0].check(value, path + (key,))
    # the constructor checks the values (ranges, "lumped" | "consistent"); find the culprit
    for key in out:
        try:
            make_integrator({"type": name, key: out[key]})
        except InvalidParameter as exc:
            raise Invalid(path + (key,), f"{key} = {_toml(out[key])}: {exc}") from None
    filled = {k: d for k, (_, d) in allowed.items()}
    filled.update(out)
    return filled


# ---------------------------------------------------------------------------------------
# cross-key rules


def _damping_rule(table: dict, path: tuple) -> dict:
    by_coefficients = table["alpha"] is not None or table["beta"] is not None
    by_ratios = table["ratios"] is not None or table["frequencies"] is not None
    if by_coefficients and by_ratios:
        key = "ratios" if table["ratios"] is not None else "frequencies"
        raise Invalid(path + (key,), "[damping] takes alpha and beta, or ratios and frequencies, "
                                     "not both: remove one pair.")
    if by_ratios:
        for key in ("ratios", "frequencies"):
            if table[key] is None:
                raise Invalid(path + (key,), "[damping] needs both ratios and frequencies, e.g. "
                                             "ratios = [0.02, 0.02] and frequencies = [2.0, 20.0] (Hz).")
        (z1, z2), (f1, f2) = table["ratios"], table["frequencies"]
        try:
            r = Rayleigh.from_damping_ratios(z1, f1, z2, f2)
        except InvalidParameter as exc:
            raise Invalid(path + ("ratios",), str(exc)) from None
        table["alpha"], table["beta"] = r.alpha, r.beta
    elif not by_coefficients:
        raise Invalid(path, "[damping] is empty: give alpha (1/s) and/or beta (s), or ratios and "
                            "frequencies (Hz); remove the table for no damping.")
    table["alpha"] = table["alpha"] or 0.0
    table["beta"] = table["beta"] or 0.0
    return table


def _output_rule(table: dict, path: tuple) -> dict:
    w, h = table["size"]
    if "mp4" in table["render"] and (w % 2 or h % 2):
        # checked here, before the run: the renderer would refuse it only after simulating
        raise Invalid(path + ("size",), f"size = [{w}, {h}]: an MP4 (H.264, yuv420p) needs an "
                                        f"even width and height; use e.g. [{w + w % 2}, {h + h % 2}].")
    return table


#: A run's name is the name of its directory under the output directory.
RUN_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]*")

#: Names the output directory uses itself (PNG frames of the renders).
RESERVED_RUN_NAMES = ("png",)


def _check_run_name(name: str, path: tuple) -> None:
    if not RUN_NAME.fullmatch(name) or name in RESERVED_RUN_NAMES:
        raise Invalid(path, f'the run name "{name}" cannot name its output folder: use letters, '
                            'digits, "_" and "-" (starting with a letter or digit), and not '
                            f'{", ".join(map(repr, RESERVED_RUN_NAMES))}; e.g. name = "fem".')


def _compare_rule(table: dict, path: tuple) -> dict:
    if table["body"] is None and table["integrator"] is None:
        raise Invalid(path, "a [[compare]] run needs a body or an integrator (or both) to "
                            "differ from the main run, e.g. body = { type = \"springs\", E = 2e7, "
                            "density = 1000.0 }.")
    return table


# ---------------------------------------------------------------------------------------
# the schema

FEM, SPRINGS = {"type": ("fem",)}, {"type": ("springs",)}

BODY = Table(
    "body",
    (
        Key("type", Choice(("fem", "springs")), "fem", doc="finite elements, or springs on the mesh edges"),
        Key("name", String(), lambda t: t["type"], doc="the run's name (variant)",
            default_text="the body type"),
        Key("material", Choice(tuple(MATERIALS)), REQUIRED, when=FEM,
            doc="hyperelastic material", default_text='"neo_hookean"'),
        Key("E", Number(gt=0), REQUIRED, "Pa", "Young's modulus", aliases=("young", "youngs_modulus",
            "young_modulus", "e_modulus", "youngs"), default_text="2e7"),
        Key("nu", Number(gt=-1, lt=0.5), REQUIRED, doc="Poisson's ratio", when=FEM,
            aliases=("poisson", "poisson_ratio", "poissons_ratio"), default_text="0.3"),
        Key("nu", Number(gt=-1, lt=0.5), 0.25, doc="Poisson's ratio, the calibration's target "
            "(a spring network has 1/4 built in)", when=SPRINGS,
            aliases=("poisson", "poisson_ratio", "poissons_ratio")),
        Key("order", Integer(choices=(1, 2)), 1, doc="1: linear tets, 2: quadratic tets", when=FEM),
        Key("density", Number(gt=0), REQUIRED, "kg/m^3", "mass density", aliases=("rho",),
            default_text="1000.0"),
        Key("calibration", Choice(tuple(CALIBRATIONS)), "van_gelder", when=SPRINGS,
            doc="spring stiffness from E (fe.van_gelder_stiffness | fe.lloyd_stiffness)"),
        Key("k_d", Number(ge=0), 0.0, "N s/m", "damping along each spring", when=SPRINGS),
    ),
    "The body: a material on finite elements, or a mass-spring network.",
)

INTEGRATOR = Table(
    "integrator",
    (Key("type", Choice(tuple(INTEGRATORS)), REQUIRED, doc="time integrator",
         default_text='"implicit_euler"'),),
    "The time integrator; any further key is one of its constructor's options.",
    options=_integrator_options,
)

DRIVEN = Table(
    "loads.driven",
    (
        Key("boundary", String(), REQUIRED, doc="named boundary of the mesh it moves",
            default_text='"right"'),
        Key("motion", Choice(MOTIONS), REQUIRED, doc="fe.Twist or fe.Translate",
            default_text='"twist"'),
        Key("angle", Number(), REQUIRED, "degrees", "total rotation", when={"motion": ("twist",)},
            default_text="360.0"),
        Key("axis", Vector(), [1.0, 0.0, 0.0], doc="rotation axis", when={"motion": ("twist",)}),
        Key("center", Vector(), ABSENT, "m", "a point on the axis (default: the boundary's centroid)",
            when={"motion": ("twist",)}),
        Key("offset", Vector(), REQUIRED, "m", "total displacement", when={"motion": ("translate",)},
            default_text="[0.0, 0.0, -0.05]"),
        Key("duration", Number(ge=0), REQUIRED, "s", "time over which the motion ramps linearly",
            default_text="1.0"),
        Key("release", Number(ge=0), ABSENT, "s", "time from which the boundary is free "
            "(default: held for ever)"),
    ),
    "A boundary moved in time (repeat [[loads.driven]] for several).",
)

COMPARE = Table(
    "compare",
    (
        Key("body", BODY, ABSENT, doc="a full body table, as [body] (default: the main body)"),
        Key("integrator", INTEGRATOR, ABSENT,
            doc="a full integrator table, as [integrator] (default: the main one)"),
        Key("name", String(), lambda t: (t["body"] or {}).get("name") or (t["integrator"] or {}).get("type"),
            doc="the run's name (variant)", default_text="the body's name, else the integrator type"),
    ),
    "Another run of the same scene with another body and/or integrator (repeat for several).",
    rule=_compare_rule,
)

SCENE_FILE = Table(
    "scene file",
    (
        Key("scene", Table("scene", (
            Key("name", String(), ABSENT, doc="the scene's name", default_text="the file name"),
            Key("description", String(), "", doc="one line on what it shows"),
        ), "Name and description."), {}, doc="name and description"),
        Key("mesh", Table("mesh", (
            Key("kind", Choice(("beam", "file")), REQUIRED, doc="a generated box (fe.beam_mesh) or a "
                "mesh file (fe.load_mesh)", default_text='"beam"'),
            Key("length", Number(gt=0), 1.0, "m", "extent along x", when={"kind": ("beam",)}),
            Key("width", Number(gt=0), 0.1, "m", "extent along y", when={"kind": ("beam",)}),
            Key("height", Number(gt=0), 0.1, "m", "extent along z", when={"kind": ("beam",)}),
            Key("cells", Array(Integer(ge=1), 3, "[nx, ny, nz] integers >= 1"), [20, 2, 2],
                doc="hexahedral cells along x, y, z (6 tets each)", when={"kind": ("beam",)}),
            Key("path", String(), REQUIRED, doc="mesh file, relative to the scene file's folder",
                when={"kind": ("file",)}, default_text='"meshes/blob.vtu"'),
            Key("reorient", Boolean(), False, doc="fix tets written with the opposite orientation",
                when={"kind": ("file",)}),
            Key("translate", Vector(), ABSENT, "m", "move the mesh by this offset"),
        ), "The reference mesh. A beam has boundaries left (x = 0), right, front, back, bottom, "
           "top."), REQUIRED, doc="the reference mesh"),
        Key("body", BODY, REQUIRED, doc="the body"),
        Key("boundary", Table("boundary", (
            Key("fixed", Fixed(), [], doc="held at their reference positions"),
        ), "Supports."), {}, doc="supports"),
        Key("loads", Table("loads", (
            Key("gravity", Vector(), ABSENT, "m/s^2", "gravitational acceleration (none if absent)"),
            Key("traction", NamedVectors(), {}, "Pa", "dead load per reference area on named boundaries"),
            Key("driven", TableArray(DRIVEN), [], doc="boundaries moved in time, [[loads.driven]]"),
        ), "External loads; only those given are built."), {}, doc="loads"),
        Key("ground", Table("ground", (
            Key("z", Number(), 0.0, "m", "height of the ground plane"),
            Key("method", Choice(CONTACT_METHODS), "penalty",
                doc="penalty springs | log barrier (implicit integrators) | impulses (explicit ones)"),
            Key("stiffness", Number(gt=0), ABSENT, "N/m", "per-node stiffness (default: carries the "
                "weight at the design penetration or gap)", when={"method": ("penalty", "barrier")}),
            Key("penetration", Number(gt=0), 1e-3, "m", "design resting penetration",
                when={"method": ("penalty",)}),
            Key("dhat", Number(gt=0), 1e-3, "m", "barrier activation distance",
                when={"method": ("barrier",)}),
            Key("restitution", Number(ge=0, le=1), 0.0, doc="0: no bounce, 1: elastic",
                when={"method": ("impulse",)}),
            Key("friction", Number(ge=0), 0.0, doc="Coulomb coefficient", when={"method": ("impulse",)}),
        ), "A ground plane z = const (fe.Ground); no contact if absent."), ABSENT, doc="ground contact"),
        Key("damping", Table("damping", (
            Key("alpha", Number(ge=0), ABSENT, "1/s", "mass-proportional coefficient"),
            Key("beta", Number(ge=0), ABSENT, "s", "stiffness-proportional coefficient"),
            Key("ratios", Vector(2, Number(ge=0, lt=1)), ABSENT, doc="damping ratios zeta1, zeta2 ..."),
            Key("frequencies", Vector(2, Number(gt=0)), ABSENT, "Hz", "... at these frequencies f1 < f2"),
        ), "Rayleigh damping C = alpha M + beta K: alpha and/or beta, or ratios and frequencies; "
           "none if absent.", rule=_damping_rule), ABSENT, doc="Rayleigh damping"),
        Key("initial", Table("initial", (
            Key("velocity", Vector(), [0.0, 0.0, 0.0], "m/s", "uniform initial velocity"),
        ), "Initial state (default: at rest in the reference configuration)."), ABSENT,
            doc="initial state"),
        Key("integrator", INTEGRATOR, REQUIRED, doc="the time integrator"),
        Key("time", Table("time", (
            Key("dt", Number(gt=0), REQUIRED, "s", "time step", default_text="0.0166667"),
            Key("duration", Number(gt=0), REQUIRED, "s", "simulated time", default_text="2.0"),
        ), "Time stepping: ceil(duration / dt) steps."), REQUIRED, doc="time stepping"),
        Key("output", Table("output", (
            Key("every", Integer(ge=1), 1, doc="record a frame every this many steps"),
            Key("checkpoint_every", Integer(ge=0), 0,
                doc="write a checkpoint every this many steps, for `fem-elastic run --resume` (0: only on Ctrl-C)"),
            Key("vtu", Boolean(), True, doc="keep the VTU frames and the PVD series (false: only summary.json and the renders)"),
            Key("render", Array(Choice(RENDER_FORMATS), None, 'array of "mp4" | "gif" | "png"'),
                ["mp4"], doc="movies and pictures to render ([] for none)"),
            Key("color_by", Choice(COLOR_FIELDS), "von_mises", doc="field the renders are coloured by"),
            Key("size", Array(Integer(ge=16), 2, "[width, height] integers >= 16"), [960, 540], "px",
                "render size"),
            Key("fps", Integer(ge=1), 30, "frames/s", "movie frame rate"),
        ), "What the run writes.", rule=_output_rule), {}, doc="outputs"),
        Key("compare", TableArray(COMPARE), [], doc="further runs, [[compare]]"),
    ),
    "A scene file.",
)


def _homes(name: str) -> list[str]:
    """Tables of the schema that have a key ``name`` (for a key put in the wrong table)."""
    found = []

    def walk(table: Table, where: str):
        for key in table.keys:
            sub = key.type.table if isinstance(key.type, TableArray) else key.type
            here = f"{where}.{key.name}" if where else key.name
            if key.name == name and where and f"[{where}]" not in found:
                found.append(f"[{where}]")
            if isinstance(sub, Table) and sub is not table:
                walk(sub, here)

    walk(SCENE_FILE, "")
    return found


def validate(document: dict) -> dict:
    """Check a parsed scene document against :data:`SCENE_FILE` and fill the defaults.

    Parameters
    ----------
    document : dict
        What ``tomllib.loads`` returned.

    Returns
    -------
    dict
        The validated spec: every key of every present table, with its
        default where the file leaves it out (None for optional keys and
        tables that are absent).

    Raises
    ------
    Invalid
        With the path of the first offending key.

    Examples
    --------
    >>> spec = validate({"mesh": {"kind": "beam"}, "body": {"material": "stvk", "E": 1e6,
    ...                  "nu": 0.3, "density": 1000.0}, "integrator": {"type": "rk4"},
    ...                  "time": {"dt": 1e-3, "duration": 0.01}})
    >>> spec["mesh"]["cells"], spec["body"]["order"], spec["ground"], spec["loads"]["gravity"]
    ([20, 2, 2], 1, None, None)
    """
    spec = SCENE_FILE.check(document, ())
    names = [spec["body"]["name"]]
    _check_run_name(names[0], ("body", "name"))
    for i, run in enumerate(spec["compare"]):
        _check_run_name(run["name"], ("compare", i, "name"))
        if run["name"] in names:
            raise Invalid(
                ("compare", i, "name"),
                f'the run name "{run["name"]}" is already used (runs so far: '
                f'{", ".join(names)}); give this [[compare]] a name = "...".',
            )
        names.append(run["name"])
    return spec


# ---------------------------------------------------------------------------------------
# the help


def _default_text(key: Key) -> str:
    if key.default is REQUIRED:
        return "required" + (f", e.g. {key.default_text}" if key.default_text else "")
    if key.default_text is not None:
        return f"default {key.default_text}"
    if key.default is ABSENT or isinstance(key.default, dict):
        return "optional"
    return f"default {_toml(key.default)}"


def _key_lines(table: Table, indent: str) -> list[str]:
    lines = []
    pad = indent + " " * 13
    for key in table.keys:
        if isinstance(key.type, TableArray):
            typ = f"[[{key.type.table.title}]] tables (below)"
        elif isinstance(key.type, Table):
            typ = f"table, as [{key.type.title}]"
        else:
            typ = key.type.label
        if key.unit:
            typ += f", {key.unit}"
        name = f"{key.name:<12} "  # a longer name still keeps a space before its type
        lines.append(f"{indent}{name}{typ}; {_default_text(key)}")
        cond = ""
        if key.when:
            cond = " (if " + ", ".join(f"{k} = {' | '.join(_toml(v) for v in vals)}"
                                       for k, vals in key.when.items()) + ")"
        lines += textwrap.wrap(key.doc + cond, 96, initial_indent=pad, subsequent_indent=pad)
    return lines


def schema_help() -> str:
    """The scene-file reference: every table and key with type, unit, default and allowed values.

    Generated from :data:`SCENE_FILE` and the integrators' signatures.

    Examples
    --------
    >>> text = schema_help()
    >>> "[body]" in text and "neo_hookean" in text and "rtol" in text
    True
    """
    out = [
        "Scene files are TOML. Units are SI (m, s, kg, Pa, N); angles are in degrees.",
        "A table or key marked 'required' must be given; 'optional' ones are built only if present.",
        "",
    ]
    for key in SCENE_FILE.keys:
        t = key.type
        table = t.table if isinstance(t, TableArray) else t
        header = f"[[{key.name}]]" if isinstance(t, TableArray) else f"[{key.name}]"
        status = "required" if key.default is REQUIRED else "optional"
        if isinstance(t, TableArray):
            status = "optional, repeatable"
        out.append(f"{header}  ({status}) {table.doc}")
        out += _key_lines(table, "  ")
        if key.name == "loads":
            out.append(f"  [[loads.driven]]  {DRIVEN.doc}")
            out += _key_lines(DRIVEN, "    ")
        if key.name == "integrator":
            out.append("  options, by type (name = default):")
            for name in INTEGRATORS:
                opts = integrator_options(name)
                text = ", ".join(
                    f"{k} = {_toml(d)}" + (f" ({t.label})" if isinstance(t, Choice) else "")
                    for k, (t, d) in opts.items()
                ) or "none"
                out += textwrap.wrap(f"{name}: {text}", 96, initial_indent="    ",
                                     subsequent_indent="      ")
        out.append("")
    return "\n".join(out).rstrip() + "\n"
