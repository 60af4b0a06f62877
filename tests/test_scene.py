"""Scene files: checking, error messages with their place, and building the runs."""

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.app.scene import BuiltRun, Scene, SceneError, load_scene, parse_scene, scene_help
from fem_elastic.app.scene_schema import SCENE_FILE, Table, TableArray

ROOT = Path(__file__).resolve().parent.parent

# A small, complete scene; the error tests edit one line of it at a time.
BASE = """\
[scene]
name = "t"
[mesh]
kind = "beam"
cells = [4, 1, 1]
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
[integrator]
type = "implicit_euler"
[time]
dt = 0.01
duration = 0.05

[[compare]]
name = "springs"
body = { type = "springs", E = 1e6, density = 1000.0 }
"""

MINIMAL = """\
[mesh]
kind = "beam"
cells = [4, 1, 1]
[body]
material = "linear"
E = 1e6
nu = 0.3
density = 1000.0
[integrator]
type = "symplectic_euler"
[time]
dt = 0.001
duration = 0.003
"""


def line_of(text: str, snippet: str) -> int:
    """1-based line of the first line containing ``snippet``."""
    for i, line in enumerate(text.splitlines(), start=1):
        if snippet in line:
            return i
    raise AssertionError(f"{snippet!r} not in the text")


def error_of(text: str, build: bool = False) -> SceneError:
    with pytest.raises(SceneError) as info:
        scene = parse_scene(text, source="x.toml")
        if build:
            scene.build()
    return info.value


# (old, new, key, snippet of the line it must point at, words the message must contain, suggestion)
ERRORS = [
    # unknown keys: top level, nested, in [[compare]], with near-miss suggestions
    ("[scene]", "[scne]", "scne", "[scne]", ["unknown table [scne]", "[scene]"], "scene"),
    ("E = 1e6\n", "Young = 1e6\n", "body.Young", "Young", ['[body] unknown key "Young"', '"E"'], "E"),
    ("density = 1000.0 }", "densty = 1000.0 }", "compare[0].body.densty", "densty",
     ["[compare[0].body]", '"densty"', '"density"'], "density"),
    ('name = "springs"', 'nmae = "springs"', "compare[0].nmae", "nmae", ['"nmae"', '"name"'], "name"),
    ("[time]", "[time]\nstep = 0.01", "time.step", "step = ", ['"step"'], None),
    # a key of the other variant of the table
    ('E = 1e6, density', 'E = 1e6, order = 2, density', "compare[0].body.order", "order = 2",
     ["order applies only when type = \"fem\""], None),
    # enum values with suggestions
    ('material = "neo_hookean"', 'material = "neohookean"', "body.material", "neohookean",
     ['"neo_hookean"'], "neo_hookean"),
    ('type = "springs"', 'type = "spring"', "compare[0].body.type", '"spring"', ['"springs"'], "springs"),
    ('type = "implicit_euler"', 'type = "implicit_euler"\nmass = "lumpd"', "integrator.mass", "lumpd",
     ['"lumped"'], "lumped"),
    # integrator options checked against the constructor's signature
    ('type = "implicit_euler"', 'type = "implicit_euler"\nrtoll = 1e-6', "integrator.rtoll", "rtoll",
     ['unknown option "rtoll"', '"rtol"'], "rtol"),
    ('type = "implicit_euler"', 'type = "rk4"\nrtol = 1e-6', "integrator.rtol", "rtol", ['unknown option "rtol" for integrator "rk4"', "Its options: substep"],
     None),
    ('type = "implicit_euler"', 'type = "implicit_euler"\nrtol = 2.0', "integrator.rtol", "rtol = 2.0",
     ["rtol must be in (0, 1)"], None),
    ('type = "implicit_euler"', 'type = "implicit_euler"\nvelocity_tol = -1.0', "integrator.velocity_tol",
     "velocity_tol = -1.0", ["velocity_tol must be a finite number >= 0"], None),
    # wrong types: a string, a boolean for a number, a float for an integer, an integer for a bool
    ("E = 1e6\n", 'E = "1e6"\n', "body.E", 'E = "1e6"', ["E must be a number", "without quotes"], None),
    ("E = 1e6\n", "E = true\n", "body.E", "E = true", ["E must be a number", "a boolean"], None),
    ("cells = [4, 1, 1]", "cells = [4, 1.0, 1]", "mesh.cells[1]", "cells", ["cells[1] must be an integer"], None),
    ("cells = [4, 1, 1]", "cells = [4, 1]", "mesh.cells", "cells", ["cells must have 3 entries"], None),
    ("[time]", "[output]\nvtu = 1\n[time]", "output.vtu", "vtu = 1", ["vtu must be true or false"], None),
    ('fixed = ["left"]', 'fixed = ["left", 3]', "boundary.fixed", "fixed", ["not a mix"], None),
    # missing required keys and tables
    ("nu = 0.3\n", "", "body.nu", "[body]", ["[body] missing required key nu"], None),
    ("E = 1e6, density = 1000.0", "E = 1e6", "compare[0].body.density", "body = {",
     ["missing required key density"], None),
    # out of range
    ("E = 1e6\n", "E = -1.0\n", "body.E", "E = -1.0", ["E = -1.0 is out of range", "> 0"], None),
    ("E = 1e6\n", "E = 0\n", "body.E", "E = 0", ["out of range"], None),
    ("nu = 0.3", "nu = 0.5", "body.nu", "nu = 0.5", ["nu = 0.5 is out of range", "(-1, 0.5)"], None),
    ("density = 1000.0\n", "density = -5.0\n", "body.density", "density = -5.0", ["out of range"], None),
    ("dt = 0.01", "dt = 0.0", "time.dt", "dt = 0.0", ["dt = 0.0 is out of range"], None),
    ("duration = 0.05", "duration = -1.0", "time.duration", "duration = -1.0", ["out of range"], None),
    ('material = "neo_hookean"', 'material = "neo_hookean"\norder = 3', "body.order", "order = 3",
     ["order = 3 is not allowed", "1 | 2"], None),
    ("E = 1e6, density = 1000.0", "E = 1e6, density = 1000.0, k_d = -1.0", "compare[0].body.k_d", "k_d",
     ["out of range"], None),
    # cross-key rules
    ('name = "springs"', 'name = "fem"', "compare[0].name", 'name = "fem"', ['"fem" is already used'], None),
    ("[time]", "[damping]\nalpha = 1.0\nratios = [0.1, 0.1]\nfrequencies = [1.0, 5.0]\n[time]",
     "damping.ratios", "ratios", ["not both"], None),
    # an MP4 needs an even size: refused before the run, not by the renderer after it
    ("[time]", '[output]\nrender = ["mp4"]\nsize = [161, 120]\n[time]', "output.size", "size =",
     ["even width and height", "[162, 120]"], None),
    # run names are folder names under --out: no escaping it, no clash with its png/ folder
    ('name = "springs"', 'name = "../springs"', "compare[0].name", 'name = "../springs"',
     ['"../springs" cannot name its output folder'], None),
    ('name = "springs"', 'name = "png"', "compare[0].name", 'name = "png"',
     ['"png" cannot name its output folder'], None),
    ("[body]\n", '[body]\nname = ""\n', "body.name", 'name = ""', ['"" cannot name its output folder'],
     None),
]


@pytest.mark.parametrize("old, new, key, snippet, words, suggestion", ERRORS,
                         ids=[e[2] + ":" + e[1].split("\n")[-1][:20] for e in ERRORS])
def test_each_mistake_names_the_key_and_its_line(old, new, key, snippet, words, suggestion):
    assert old in BASE
    text = BASE.replace(old, new, 1)
    err = error_of(text)
    line = line_of(text, snippet)
    assert (err.key, err.line, err.file, err.suggestion) == (key, line, "x.toml", suggestion), str(err)
    assert str(err).startswith(f"x.toml, line {line}: ")
    for word in words:
        assert word in str(err), str(err)
    assert isinstance(err, fe.InvalidParameter)


def test_missing_table_has_no_line_but_says_what_to_add():
    err = error_of(BASE.replace("[time]\ndt = 0.01\nduration = 0.05\n", ""))
    assert (err.key, err.line) == ("time", None)
    assert str(err) == "x.toml: missing table [time] (time stepping): add [time] with dt, duration."


def test_toml_syntax_error_gives_the_line():
    text = BASE.replace("dt = 0.01", "dt = = 0.01")
    err = error_of(text)
    assert err.key is None and err.line == line_of(text, "dt = = 0.01")
    assert "TOML syntax error" in str(err)
    err = error_of(BASE.replace('fixed = ["left"]', 'fixed = ["left"'))  # unclosed array
    assert "TOML syntax error" in str(err) and err.line is not None


@pytest.mark.parametrize("old, new, key, snippet", [
    ('fixed = ["left"]', 'fixed = ["lft"]', "boundary.fixed[0]", "fixed"),
    ("traction = { right", "traction = { rigth", "loads.traction.rigth", "rigth"),
    ("[integrator]", '[[loads.driven]]\nboundary = "rihgt"\nmotion = "translate"\noffset = [0.0, 0.0, 0.1]\n'
                     "duration = 1.0\n[integrator]", "loads.driven[0].boundary", "rihgt"),
])
def test_unknown_boundary_name_is_caught_at_build_with_a_suggestion(old, new, key, snippet):
    text = BASE.replace(old, new, 1)
    scene = parse_scene(text, source="x.toml")  # the names are checked against the mesh
    err = error_of(text, build=True)
    assert (err.key, err.line, err.suggestion) == (key, line_of(text, snippet), "right" if "r" in
                                                   snippet[:2] else "left")
    assert "the mesh has no boundary" in str(err) and '"left"' in str(err)
    assert scene.variants == ["fem", "springs"]


def test_vertex_index_out_of_range_is_caught_at_build():
    text = BASE.replace('fixed = ["left"]', "fixed = [0, 999]")
    err = error_of(text, build=True)
    assert err.key == "boundary.fixed[1]" and "20 vertices" in str(err)


def test_defaults_are_filled():
    spec = parse_scene(MINIMAL, source="scenes/minimal.toml").spec
    assert spec["scene"] == {"name": "minimal", "description": ""}
    assert spec["mesh"] == {"kind": "beam", "length": 1.0, "width": 0.1, "height": 0.1,
                            "cells": [4, 1, 1], "translate": None}
    assert spec["body"]["type"] == "fem" and spec["body"]["name"] == "fem" and spec["body"]["order"] == 1
    assert spec["boundary"] == {"fixed": []}
    assert spec["loads"] == {"gravity": None, "traction": {}, "driven": []}
    assert spec["ground"] is None and spec["damping"] is None and spec["initial"] is None
    assert spec["output"] == {"every": 1, "vtu": True, "render": ["mp4"], "color_by": "von_mises",
                              "size": [960, 540], "fps": 30, "checkpoint_every": 0}
    assert spec["compare"] == []
    springs = parse_scene(BASE).spec["compare"][0]["body"]
    assert springs == {"type": "springs", "name": "springs", "E": 1e6, "nu": 0.25, "density": 1000.0,
                       "calibration": "van_gelder", "k_d": 0.0}
    integrator = parse_scene(BASE).spec["integrator"]
    assert integrator["rtol"] == 1e-8 and integrator["max_iter"] == 30  # ImplicitEuler's own defaults


def test_an_integer_is_accepted_for_a_number():
    spec = parse_scene(BASE.replace("E = 1e6\n", "E = 1000000\n")).spec
    assert spec["body"]["E"] == 1e6 and isinstance(spec["body"]["E"], float)


def test_only_declared_terms_are_built():
    run = parse_scene(MINIMAL).build()[0]
    model = run.model
    assert model.loads == () and model.obstacles == () and model.contacts == ()
    assert model.damping is None and model.driven == () and model.fixed_dofs.size == 0
    assert model.gravity_magnitude == 0.0
    assert isinstance(run.integrator, fe.SymplecticEuler)
    assert run.info["ground"] is None and run.info["gravity"] is None and run.info["damping"] is None

    full = MINIMAL + """
[boundary]
fixed = ["left"]
[loads]
gravity = [0.0, 0.0, -9.81]
[[loads.driven]]
boundary = "right"
motion = "twist"
angle = 90.0
duration = 1.0
release = 2.0
[ground]
z = -0.5
method = "barrier"
dhat = 0.01
[damping]
alpha = 0.5
beta = 0.001
[initial]
velocity = [0.0, 0.0, -1.0]
"""
    run = parse_scene(full).build()[0]
    model = run.model
    assert len(model.loads) == 1 and model.gravity_magnitude == pytest.approx(9.81)
    (ground,) = model.obstacles
    assert isinstance(ground, fe.Ground) and ground.method == "barrier" and ground.dhat == 0.01
    assert float(ground.point[2]) == -0.5
    assert (model.damping.alpha, model.damping.beta) == (0.5, 0.001)
    assert len(model.driven) == 1
    motion = model.driven[0][0]  # (motion, reference positions, DOFs)
    assert isinstance(motion, fe.Twist)
    assert motion.angle == pytest.approx(math.pi / 2) and motion.release == 2.0
    assert model.fixed_dofs.size > 0
    free = model.free
    assert np.all(run.state.v[free][2::3] == -1.0)
    assert run.info["ground"] == {"kind": "plane", "z": -0.5, "method": "barrier"}
    assert run.info["gravity"] == [0.0, 0.0, -9.81]
    json.dumps(run.info)  # plain values only


def test_damping_from_ratios_and_frequencies():
    text = MINIMAL + "[damping]\nratios = [0.05, 0.05]\nfrequencies = [2.0, 20.0]\n"
    damping = parse_scene(text).build()[0].model.damping
    expected = fe.Rayleigh.from_damping_ratios(0.05, 2.0, 0.05, 20.0)
    assert (damping.alpha, damping.beta) == (expected.alpha, expected.beta)


def test_integrator_options_are_forwarded():
    text = BASE.replace('type = "implicit_euler"', 'type = "implicit_euler"\nrtol = 1e-6\nmax_iter = 7\n'
                        'mass = "consistent"\nlinear_solver = "direct"')
    run = parse_scene(text).build()[0]
    ie = run.integrator
    assert isinstance(ie, fe.ImplicitEuler)
    assert (ie.rtol, ie.max_iter, ie.mass) == (1e-6, 7, "consistent")
    assert isinstance(ie.linear_solver, fe.DirectSolver)
    # Newmark passes *args, **kwargs on: its options are ImplicitEuler's
    nm = parse_scene(BASE.replace('"implicit_euler"', '"newmark"\nmax_iter = 5')).build()[0].integrator
    assert isinstance(nm, fe.Newmark) and nm.max_iter == 5


def test_variants_are_built_in_order_and_on_request():
    text = BASE + '\n[[compare]]\nintegrator = { type = "newmark", rtol = 1e-6 }\n'
    scene = parse_scene(text)
    assert scene.variants == ["fem", "springs", "newmark"]
    runs = scene.build()
    assert [r.name for r in runs] == scene.variants
    assert isinstance(runs[0].model.body_potential, fe.ElasticPotential)
    assert isinstance(runs[1].model.body_potential, fe.SpringPotential)
    assert isinstance(runs[1].integrator, fe.ImplicitEuler)  # the main integrator
    assert isinstance(runs[2].model.body_potential, fe.ElasticPotential)  # the main body
    assert isinstance(runs[2].integrator, fe.Newmark) and runs[2].integrator.rtol == 1e-6
    assert runs[0].integrator is not runs[1].integrator  # each run gets its own
    (only,) = scene.build(["springs"])
    assert only.name == "springs" and only.info["variant"] == "springs"
    with pytest.raises(SceneError, match='did you mean "springs"') as info:
        scene.build(["spring"])
    assert info.value.suggestion == "springs"


def test_built_run_fields():
    text = BASE.replace("[time]", '[output]\nevery = 2\nrender = ["gif", "png"]\nsize = [320, 240]\n[time]')
    text = text.replace("dt = 0.01", "dt = 0.3").replace("duration = 0.05", "duration = 1.0")
    run = parse_scene(text).build()[0]
    assert isinstance(run, BuiltRun)
    assert run.dt == 0.3 and run.steps == 4  # ceil(1.0 / 0.3)
    assert run.record_every == 2
    assert run.output == {"vtu": True, "render": ["gif", "png"], "color_by": "von_mises",
                          "size": (320, 240), "fps": 30, "checkpoint_every": 0}
    info = run.info
    assert (info["scene"], info["variant"], info["E"], info["nu"], info["order"]) == ("t", "fem", 1e6, 0.3, 1)
    assert info["mesh"]["kind"] == "beam" and info["mesh"]["cells"] == [4, 1, 1]
    assert (info["n_vertices"], info["n_tets"]) == (20, 24)
    assert info["integrator"] == "ImplicitEuler" and info["steps_planned"] == 4
    assert info["body_spec"]["material"] == "neo_hookean"
    json.dumps(info)
    # 1/60 s steps over 3 s: 180 steps, although 3.0 / (1/60) is a hair above 180 in floating point
    text = BASE.replace("dt = 0.01", "dt = 0.016666666666666666").replace("duration = 0.05", "duration = 3.0")
    assert parse_scene(text).build()[0].steps == 180


def test_file_mesh_path_is_relative_to_the_scene_file(tmp_path, monkeypatch):
    folder = tmp_path / "scenes"
    (folder / "meshes").mkdir(parents=True)
    shutil.copy(ROOT / "meshes" / "beam.vtu", folder / "meshes" / "beam.vtu")
    text = MINIMAL.replace('kind = "beam"\ncells = [4, 1, 1]',
                           'kind = "file"\npath = "meshes/beam.vtu"\ntranslate = [0.0, 0.0, 1.0]')
    (folder / "s.toml").write_text(text)
    monkeypatch.chdir(tmp_path)  # elsewhere than the scene's folder
    run = load_scene(folder / "s.toml").build()[0]
    assert run.info["n_vertices"] == 189 and run.info["mesh"]["path"] == "meshes/beam.vtu"
    assert float(run.model.mesh.p[2].min()) == 1.0  # translated
    (folder / "t.toml").write_text(text.replace("meshes/beam.vtu", "meshes/nope.vtu"))
    with pytest.raises(SceneError, match="not found") as info:
        load_scene(folder / "t.toml").build()
    assert info.value.key == "mesh.path" and info.value.line == line_of(text, "path =")
    # a key of the beam variant in a file mesh
    (folder / "u.toml").write_text(text.replace('path = "meshes/beam.vtu"', 'path = "m.vtu"\ncells = [1, 1, 1]'))
    with pytest.raises(SceneError, match='applies only when kind = "beam"'):
        load_scene(folder / "u.toml")


def test_missing_scene_file():
    with pytest.raises(SceneError, match="not found"):
        load_scene("no/such/scene.toml")


SHIPPED = sorted((ROOT / "scenes").glob("*.toml")) + sorted((ROOT / "fem_elastic" / "app" / "scenes").glob("*.toml"))


@pytest.mark.parametrize("path", SHIPPED, ids=[p.name for p in SHIPPED])
def test_every_shipped_scene_builds(path):
    scene = load_scene(path)
    runs = scene.build()
    assert [r.name for r in runs] == scene.variants
    for run in runs:
        assert run.steps >= 1 and run.state.x.shape == (run.model.ndofs,)
        assert scene.description
        json.dumps(run.info)


def test_shipped_scenes_exist():
    names = {p.name for p in SHIPPED}
    assert "demo.toml" in names and len(names) >= 4


def test_demo_scene():
    scene = load_scene(ROOT / "fem_elastic" / "app" / "scenes" / "demo.toml")
    assert scene.name == "demo" and scene.variants == ["fem", "springs"]
    spec = scene.spec
    assert spec["body"]["material"] == "neo_hookean" and spec["compare"][0]["body"]["nu"] == 0.25
    assert spec["loads"]["gravity"] == [0.0, 0.0, -9.81] and spec["boundary"]["fixed"] == ["left"]
    assert spec["integrator"]["type"] == "implicit_euler" and spec["damping"] is not None
    assert spec["output"]["render"] == ["mp4", "png"] and spec["output"]["vtu"]


@pytest.mark.parametrize("variant", ["fem", "springs"])
def test_a_scene_run_equals_the_hand_built_model(variant):
    text = MINIMAL.replace("symplectic_euler", "implicit_euler").replace("dt = 0.001", "dt = 0.01").replace(
        "duration = 0.003", "duration = 0.03") + """
[boundary]
fixed = ["left"]
[loads]
gravity = [0.0, 0.0, -9.81]
traction = { right = [0.0, 100.0, 0.0] }
[damping]
alpha = 0.5
[[compare]]
body = { type = "springs", E = 2e6, density = 800.0, k_d = 0.01 }
"""
    (run,) = parse_scene(text).build([variant])
    traj = run.simulate()
    mesh = fe.beam_mesh(cells=(4, 1, 1))
    if variant == "fem":
        body, density = fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)), 1000.0
    else:
        body, density = fe.MassSpring(E=2e6, k_d=0.01), 800.0
    model = fe.Model(mesh, density, body, fixed="left", gravity=(0.0, 0.0, -9.81),
                     traction={"right": (0.0, 100.0, 0.0)}, damping=fe.Rayleigh(0.5, 0.0))
    ref = fe.simulate(model, fe.ImplicitEuler(), 0.01, steps=3)
    assert run.steps == 3
    # the same model and integrator, so the same floating-point operations: exact equality
    np.testing.assert_array_equal(traj.displacement, ref.displacement)
    np.testing.assert_array_equal(traj.times, ref.times)
    assert np.abs(traj.displacement[-1]).max() > 0


def test_key_lines_in_inline_tables_arrays_and_strings():
    text = """\
# a comment with [brackets] and key = "value"
[scene]
name = "a # not a comment"
description = '''
multi-line [not a table]
E = 5
'''
[mesh]
kind = "beam"
cells = [
  4,
  1,
  1.5,
]
[body]
material = "linear"
E = 1e6
nu = 0.3
density = 1000.0
[integrator]
type = "rk4"
[time]
dt = 0.1
duration = 1.0
[[compare]]
name = "a"
body = { type = "springs", E = 1e6, density = 1000.0 }
[[compare]]
"name" = "b"
body = { type = "springs", E = 1e6, density = 1000.0, calibration = "loyd" }
"""
    err = error_of(text)
    assert (err.key, err.line) == ("mesh.cells[2]", 13)
    text = text.replace("1.5", "1")
    err = error_of(text)
    assert (err.key, err.line, err.suggestion) == ("compare[1].body.calibration", 30, "lloyd")


def test_help_lists_every_table_and_key_of_the_schema():
    text = scene_help()

    def walk(table: Table):
        for key in table.keys:
            sub = key.type.table if isinstance(key.type, TableArray) else key.type
            if isinstance(sub, Table):
                walk(sub)
            assert f"  {key.name} " in text or f"[{key.name}]" in text, key.name

    for key in SCENE_FILE.keys:
        assert f"[{key.name}]" in text or f"[[{key.name}]]" in text
    walk(SCENE_FILE)
    for word in ("neo_hookean", "symplectic_euler", "barrier", "van_gelder", "rtol", "Pa", "kg/m^3"):
        assert word in text


def test_scene_is_frozen():
    scene = parse_scene(MINIMAL)
    assert isinstance(scene, Scene)
    with pytest.raises(AttributeError):
        scene.name = "other"


def test_a_key_in_the_wrong_table_says_where_it_belongs():
    text = BASE.replace("density = 1000.0\n", "density = 1000.0\ngravity = [0.0, 0.0, -9.81]\n", 1)
    err = error_of(text)
    assert err.key == "body.gravity" and err.line == line_of(text, "gravity = [0.0, 0.0, -9.81]")
    assert "gravity is a key of [loads]" in str(err)


def test_built_run_simulate_takes_overrides():
    """``run.simulate`` uses the scene's settings, and a step count or end time given replaces them."""
    run = parse_scene(BASE).build(["fem"])[0]
    assert run.steps == 5  # duration 0.05 s at dt 0.01 s
    assert run.simulate().steps == 5
    assert run.simulate(steps=2).steps == 2
    traj = run.simulate(t_end=0.03, record_every=3)
    assert traj.steps == 3 and traj.times.size == 2
