"""Fuzzing scene files with hypothesis: a valid scene or a typed error, never a traceback.

A valid base scene (every table of the schema used once) is broken by a random list
of edits of its parsed document: keys added (random names, the schema's own names in
the wrong table, near misses), deleted, or given random TOML values of every type
(strings, integers up to 2^64 and beyond, floats including nan and +-inf, booleans,
arrays, inline tables, dates, times), tables of random names added; or by edits of
its text (random characters, bytes, truncation). Then:

- ``fe.parse_scene(text)`` returns a :class:`Scene` or raises :class:`fe.SceneError`;
- a scene that parses builds (``Scene.build()``: models, integrators, initial states)
  or raises :class:`fe.SceneError`, and its first run takes one step or stops with a
  typed :class:`fe.FemElasticError` (a bad time step may well diverge);
- ``fem-elastic run`` on a handful of bad scene files exits with status 2 and prints
  one error message, no traceback.

Anything else (a KeyError, OverflowError, TypeError, ... from deep inside) is a bug.
"""

import datetime as dt
import json
import math
import random
import re
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python < 3.11
    import tomli as tomllib

import fem_elastic as fe
from fem_elastic.app.cli import main
from fem_elastic.app.scene_schema import SCENE_FILE, Table, TableArray

SETTINGS = dict(deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                       HealthCheck.function_scoped_fixture])

# Every table of the schema once, on a 2-cell beam: a build costs ~20 ms.
BASE = """\
[scene]
name = "fuzz"
description = "every table once"

[mesh]
kind = "beam"
length = 1.0
width = 0.2
height = 0.2
cells = [2, 1, 1]

[body]
material = "neo_hookean"
E = 1e6
nu = 0.3
density = 1000.0

[boundary]
fixed = ["left"]

[loads]
gravity = [0.0, 0.0, -9.81]
traction = { right = [0.0, 0.0, -10.0] }

[[loads.driven]]
boundary = "right"
motion = "translate"
offset = [0.0, 0.0, -0.01]
duration = 0.1

[ground]
z = -1.0
method = "penalty"

[damping]
alpha = 0.1
beta = 0.001

[initial]
velocity = [0.0, 0.0, 0.0]

[integrator]
type = "implicit_euler"
rtol = 1e-6

[time]
dt = 0.01
duration = 0.02

[output]
every = 1
render = []

[[compare]]
name = "springs"
body = { type = "springs", E = 1e6, density = 1000.0 }
"""
BASE_DOC = tomllib.loads(BASE)


def test_the_base_scene_builds_and_steps():
    runs = fe.parse_scene(BASE).build()
    assert [r.name for r in runs] == ["fem", "springs"]
    traj = runs[0].simulate(steps=1)
    assert np.isfinite(traj.displacement).all()


# ---------------------------------------------------------------------------------------
# writing TOML (tomllib only reads it)

_BARE = re.compile(r"[A-Za-z0-9_-]+")


def _string(s: str) -> str:
    out = []
    for c in s:
        if c in '"\\':
            out.append("\\" + c)
        elif ord(c) < 0x20 or ord(c) == 0x7F:
            out.append(f"\\u{ord(c):04x}")
        else:
            out.append(c)
    return '"' + "".join(out) + '"'


def _key(k) -> str:
    k = str(k)
    return k if _BARE.fullmatch(k) else _string(k)


def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, (dt.datetime, dt.date, dt.time)):
        return v.isoformat()
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))  # pragma: no cover - the strategies make only the above


def toml_dump(doc: dict) -> str:
    """TOML text of ``doc``: top-level tables as [sections], arrays of tables as [[...]]."""
    head, sections = [], []
    for k, v in doc.items():
        if isinstance(v, dict):
            sections.append(f"[{_key(k)}]")
            sections += [f"{_key(kk)} = {toml_value(vv)}" for kk, vv in v.items()]
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            for x in v:
                sections.append(f"[[{_key(k)}]]")
                sections += [f"{_key(kk)} = {toml_value(vv)}" for kk, vv in x.items()]
        else:
            head.append(f"{_key(k)} = {toml_value(v)}")
    return "\n".join(head + sections) + "\n"


def test_the_writer_round_trips_the_base_scene():
    assert tomllib.loads(toml_dump(BASE_DOC)) == BASE_DOC


# ---------------------------------------------------------------------------------------
# strategies


def _schema_names() -> list[str]:
    """Every key and table name of the schema (to put in the wrong place)."""
    names = set()

    def walk(table):
        for key in table.keys:
            names.add(key.name)
            names.update(key.aliases)
            sub = key.type.table if isinstance(key.type, TableArray) else key.type
            if isinstance(sub, Table):
                walk(sub)

    walk(SCENE_FILE)
    return sorted(names)


NAMES = _schema_names()
# values the schema gives meaning to, so that edits reach past the type checks
MEANINGFUL = ["neo_hookean", "stvk", "linear", "corotated", "stable_neo_hookean", "fem",
              "springs", "beam", "file", "left", "right", "top", "twist", "translate",
              "implicit_euler", "rk4", "newmark", "symplectic_euler", "linearized_implicit_euler",
              "explicit_euler", "midpoint", "lumped", "consistent", "amg", "direct", "auto",
              "penalty", "barrier", "impulse", "mp4", "gif", "png", "von_mises", "van_gelder",
              "lloyd", "", " ", "../x", "nan", "Neo-Hookean"]

scalars = st.one_of(
    st.booleans(),
    st.integers(-(2**63), 2**63 - 1),
    st.integers(),  # unbounded: TOML readers may accept more than 64 bits
    st.sampled_from([0, 1, 2, 3, -1, 16, 100, 10**6]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-300, 5e-324, 1e300, 1.7976931348623157e308, 0.4999999999, 0.5,
                     -0.99, 1e-12, 1e12]),
    st.text(max_size=8),
    st.sampled_from(MEANINGFUL),
    st.dates(), st.datetimes(), st.times(),
)
toml_values = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=4)
    | st.dictionaries(st.one_of(st.sampled_from(NAMES), st.text(min_size=1, max_size=6)), inner,
                      max_size=3),
    max_leaves=8,
)
key_names = st.one_of(st.sampled_from(NAMES), st.text(min_size=1, max_size=8),
                      st.sampled_from(["Young", "E ", "dencity", "poisson", "fixed_", "type2"]))


def _paths(node, prefix=()):
    """Every (path to a value) in the document, tables and list items included."""
    out = []
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for k, v in items:
        out.append(prefix + (k,))
        out += _paths(v, prefix + (k,))
    return out


def _get(doc, path):
    for k in path:
        doc = doc[k]
    return doc


floats = st.one_of(
    st.floats(-12.0, 12.0).map(lambda e: 10.0 ** e),  # any positive magnitude
    st.floats(-12.0, 12.0).map(lambda e: -(10.0 ** e)),
    st.floats(allow_nan=False, allow_infinity=False),
    st.sampled_from([0.0, -0.0, 1e-300, 1e300, 0.4999999999, -0.99, 1.0]),
)
ints = st.one_of(st.integers(0, 20), st.integers(-3, 10**6), st.integers())


def similar(draw, value):
    """A value of the same type as ``value``: past the type checks, into the ranges."""
    if isinstance(value, bool):
        return draw(st.booleans())
    if isinstance(value, int):
        return draw(ints)
    if isinstance(value, float):
        return draw(floats)
    if isinstance(value, str):
        return draw(st.sampled_from(MEANINGFUL))
    if isinstance(value, list) and value and not isinstance(value[0], dict):
        return [similar(draw, v) for v in value]
    return draw(toml_values)


@st.composite
def edited_documents(draw):
    """The base document after 1-4 random edits of its parsed form."""
    doc = json.loads(json.dumps(BASE_DOC))  # a deep copy (the base holds only JSON types)
    for _ in range(draw(st.sampled_from([1, 1, 1, 2, 2, 3, 4]))):
        op = draw(st.sampled_from(["delete", "replace", "similar", "similar", "similar", "add",
                                   "add_table"]))
        paths = _paths(doc)
        if op in ("delete", "replace", "similar") and paths:
            path = draw(st.sampled_from(paths))
            parent = _get(doc, path[:-1])
            if op == "delete":
                del parent[path[-1]]
            elif op == "replace":
                parent[path[-1]] = draw(toml_values)
            else:
                parent[path[-1]] = similar(draw, parent[path[-1]])
        elif op == "add":
            tables = [()] + [p for p in paths if isinstance(_get(doc, p), dict)]
            table = _get(doc, draw(st.sampled_from(tables)))
            table[draw(key_names)] = draw(toml_values)
        else:
            doc[draw(key_names)] = draw(st.dictionaries(key_names, toml_values, max_size=3))
    return doc


@st.composite
def edited_texts(draw):
    """The base text with random characters or bytes spliced in, or cut short."""
    text = BASE
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(text)))
        j = draw(st.integers(i, min(len(text), i + 20)))
        new = draw(st.one_of(
            st.text(max_size=6),
            st.binary(max_size=6).map(lambda b: b.decode("latin-1")),
            st.sampled_from(["[", "]", "[[", "=", '"', "'''", "{", "}", ",", "\n", "#", ".",
                             "[body]\n", "[[compare]]\n", "E = ", "\x00", "\ufeff"]),
        ))
        text = text[:i] + new + text[j:]
    return text


# ---------------------------------------------------------------------------------------
# the property


def _small(spec) -> bool:
    """Whether building and stepping the scene is cheap enough to try here.

    A random ``cells`` may ask for 1e18 tets, and a random integer option for 1e9
    Newton iterations or substeps: legitimate requests the schema accepts, which
    would only make the test slow.
    """
    m = spec["mesh"]
    if m["kind"] != "beam" or int(np.prod(m["cells"], dtype=object)) > 16:
        return m["kind"] != "beam"  # a file mesh fails fast: no such file in the temp folder
    integrators = [spec["integrator"]] + [c["integrator"] for c in spec["compare"] if c["integrator"]]
    return all(not isinstance(v, int) or isinstance(v, bool) or v <= 50
               for integ in integrators for v in integ.values())


def check_scene(text: str) -> str:
    """'rejected', 'parsed', 'built' or 'stepped'; fails on any untyped exception."""
    with tempfile.TemporaryDirectory() as folder:
        try:
            scene = fe.parse_scene(text, source="fuzz.toml", base_dir=folder)
        except fe.SceneError as err:
            assert str(err).startswith("fuzz.toml"), str(err)  # placed in the file
            return "rejected"
        assert isinstance(scene, fe.Scene)
        if not _small(scene.spec):
            return "parsed"
        try:
            runs = scene.build()
        except fe.SceneError as err:
            assert str(err)
            return "parsed"
    try:
        with np.errstate(all="ignore"):  # a wild but valid scene may overflow on its way to Diverged
            traj = runs[0].simulate(steps=1)
    except fe.FemElasticError as err:
        assert str(err)
        return "built"
    assert traj.times.size >= 1
    return "stepped"


@settings(max_examples=300, **SETTINGS)
@given(doc=edited_documents())
# regressions: each raised an untyped exception before the fix
@example(doc={**BASE_DOC, "time": {"dt": 1e-300, "duration": 1e300}})  # OverflowError in ceil
@example(doc={**BASE_DOC, "mesh": {"kind": "beam", "cells": [10**9, 10**9, 1000]}})  # MemoryError
@example(doc={**BASE_DOC, "body": {**BASE_DOC["body"], "E": 10**400}})  # OverflowError in float()
def test_edited_scene_is_valid_or_a_scene_error(doc):
    try:
        text = toml_dump(doc)
    except ValueError:  # pragma: no cover - a value TOML cannot write (none known)
        assume(False)
    check_scene(text)


@settings(max_examples=150, **SETTINGS)
@given(text=edited_texts())
@example(text="\x00")
@example(text="")
@example(text=BASE[: BASE.index("[time]") + 12])  # cut inside a table
def test_broken_text_is_valid_or_a_scene_error(text):
    check_scene(text)


def test_a_scene_asking_for_too_many_steps_is_a_scene_error():
    """duration / dt beyond what simulate runs: said at build time, at [time]."""
    for time_table in ({"dt": 1e-300, "duration": 1e300}, {"dt": 1e-9, "duration": 1e3}):
        scene = fe.parse_scene(toml_dump({**BASE_DOC, "time": time_table}), source="x.toml")
        with pytest.raises(fe.SceneError) as info:
            scene.build()
        assert info.value.key.startswith("time") and "steps" in str(info.value)


def test_a_huge_beam_is_a_scene_error():
    scene = fe.parse_scene(toml_dump({**BASE_DOC, "mesh": {"kind": "beam", "cells": [10**9, 10**9, 1000]}}),
                           source="x.toml")
    with pytest.raises(fe.SceneError) as info:
        scene.build()
    assert info.value.key == "mesh" and "fewer cells" in str(info.value)


# ---------------------------------------------------------------------------------------
# the command line


@settings(max_examples=4, **SETTINGS)
@given(doc=edited_documents())
def test_cli_on_a_bad_scene_exits_2_without_traceback(doc, capsys):
    """A handful (each CLI run costs ~0.3 s): exit status 2, one message, no traceback."""
    text = toml_dump(doc)
    try:
        fe.parse_scene(text)
    except fe.SceneError:
        pass
    else:
        assume(False)  # only scenes the checker rejects
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bad.toml"
        path.write_text(text, encoding="utf-8")
        capsys.readouterr()
        status = main(["run", str(path), "--out", str(Path(folder) / "out"), "--no-render", "-q"])
        out, err = capsys.readouterr()
    assert status == 2, (status, err)
    assert "Traceback" not in err + out
    assert err.startswith("fem-elastic: error: ") and "bad.toml" in err, err


def test_cli_on_a_file_of_random_bytes_exits_2_without_traceback(capsys, tmp_path):
    path = tmp_path / "bytes.toml"
    path.write_bytes(bytes(range(256)))  # not UTF-8
    status = main(["run", str(path), "--out", str(tmp_path / "out"), "--no-render", "-q"])
    out, err = capsys.readouterr()
    assert status == 2 and "Traceback" not in err + out
    assert err.startswith("fem-elastic: error: "), err


@pytest.mark.parametrize("edit", [
    {"boundary": {"fixed": ["nowhere"]}},  # parses; the mesh has no such boundary
    {"time": {"dt": 1e-300, "duration": 1e300}},  # parses; was an OverflowError at build
    {"body": {**BASE_DOC["body"], "E": 10**400}},  # was an OverflowError in the checker
])
def test_cli_on_a_scene_that_fails_later_exits_2_without_traceback(edit, capsys, tmp_path):
    path = tmp_path / "late.toml"
    path.write_text(toml_dump({**BASE_DOC, **edit}), encoding="utf-8")
    status = main(["run", str(path), "--out", str(tmp_path / "out"), "--no-render", "-q"])
    out, err = capsys.readouterr()
    assert status == 2, (status, err)
    assert "Traceback" not in err + out
    assert err.startswith("fem-elastic: error: ") and "late.toml, line" in err, err


class Style:
    """Random TOML spellings of the same document, for the line scanner of scene.py.

    Strings basic, literal or multi-line; keys bare, "quoted" or 'quoted'; sub-tables as
    inline tables, [a.b] headers or dotted keys; arrays on one line or one item per
    line with a trailing comma; comments and blank lines between entries.
    """

    def __init__(self, seed: int):
        self.rng = random.Random(seed)  # ~100 choices a document: one draw, not 100

    def choice(self, options):
        return self.rng.choice(options)

    def string(self, v: str) -> str:
        kind = self.choice(["basic", "literal", "multi", "multi_literal"])
        control = re.search(r"[\x00-\x1f\x7f]", v)
        if kind == "literal" and "'" not in v and not control:
            return "'" + v + "'"
        if kind == "multi_literal" and "'" not in v and not control:
            return "'''" + v + "'''"
        if kind == "multi":
            return '"""' + _string(v)[1:-1] + '"""'
        return _string(v)

    def key(self, k) -> str:
        k = str(k)
        kind = self.choice(["bare", "basic", "literal"])
        if kind == "bare" and _BARE.fullmatch(k):
            return k
        if kind == "literal" and "'" not in k and not re.search(r"[\x00-\x1f\x7f]", k):
            return "'" + k + "'"
        return _string(k)

    def value(self, v) -> str:
        if isinstance(v, str):
            return self.string(v)
        if isinstance(v, list):
            items = [self.value(x) for x in v]
            if items and self.choice([False, True]):
                return "[\n" + "".join(f"  {x},  # item\n" for x in items) + "]"
            return "[" + ", ".join(items) + "]"
        if isinstance(v, dict):
            return "{" + ", ".join(f"{self.key(k)} = {self.value(x)}" for k, x in v.items()) + "}"
        return toml_value(v)

    def filler(self) -> str:
        return self.choice(["", "", "\n", "# a comment\n", "  \t\n"])

    def table_body(self, path: list, table: dict, out: list) -> None:
        """Lines of a table's keys; sub-tables inline, as dotted keys, or as [headers] after."""
        later = []
        for k, v in table.items():
            out.append(self.filler())
            if isinstance(v, dict) and v:
                how = self.choice(["inline", "dotted", "header"])
                if how == "dotted" and all(not isinstance(x, dict) for x in v.values()):
                    for kk, vv in v.items():
                        out.append(f"{self.key(k)}.{self.key(kk)} = {self.value(vv)}  # dotted\n")
                    continue
                if how != "inline":
                    later.append((k, v))
                    continue
            out.append(f"{self.key(k)} = {self.value(v)}\n")
        for k, v in later:
            header = ".".join(self.key(p) for p in path + [k])
            out.append(f"\n[{header}]\n")
            self.table_body(path + [k], v, out)

    def dump(self, doc: dict) -> str:
        def is_tables(v):
            return isinstance(v, list) and v and all(isinstance(x, dict) for x in v)

        out = [f"{self.key(k)} = {self.value(v)}\n" for k, v in doc.items()
               if not isinstance(v, dict) and not is_tables(v)]
        for k, v in doc.items():
            if isinstance(v, dict):
                out.append(f"\n[{self.key(k)}]  # table\n")
                self.table_body([k], v, out)
            elif is_tables(v):
                for x in v:
                    out.append(f"\n[[{self.key(k)}]]\n")
                    self.table_body([k], x, out)
        return "".join(out)


@st.composite
def styled_texts(draw):
    """An edited document in a random TOML spelling (it parses to the same document)."""
    doc = draw(edited_documents())
    return doc, Style(draw(st.integers(0, 2**32 - 1))).dump(doc)


@settings(max_examples=150, **SETTINGS)
@given(case=styled_texts())
def test_styled_scene_is_valid_or_a_scene_error_with_its_line(case):
    """Any spelling: the same verdict as the plain one, and errors placed on a real line."""
    doc, text = case
    plain = toml_dump(doc)
    assert _canonical(tomllib.loads(text)) == _canonical(tomllib.loads(plain))  # the writer is right
    try:
        fe.parse_scene(text, source="fuzz.toml")
    except fe.SceneError as err:
        assert err.line is None or 1 <= err.line <= text.count("\n") + 1, (err.line, str(err))
        with pytest.raises(fe.SceneError):  # (maybe another key first: [headers] come last)
            fe.parse_scene(plain, source="fuzz.toml")
    else:
        fe.parse_scene(plain)


def _canonical(x):
    """A form of a parsed document that compares equal with NaN and in any key order."""
    if isinstance(x, dict):
        return sorted((str(k), _canonical(v)) for k, v in x.items())
    if isinstance(x, list):
        return [_canonical(v) for v in x]
    if isinstance(x, float) and math.isnan(x):
        return "nan"
    return (type(x).__name__, repr(x))
