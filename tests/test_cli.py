"""The fem-elastic command, run as a user runs it: in a subprocess, on tiny scenes."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.app.vtu import read_series

ROOT = Path(__file__).resolve().parent.parent

# A tiny scene: a 4-cell cantilever under gravity, FEM beside springs, 10 implicit steps.
TINY = """\
[scene]
name = "tiny"
description = "a tiny cantilever for the command's tests"

[mesh]
kind = "beam"
length = 0.4
width = 0.1
height = 0.1
cells = [4, 1, 1]

[body]
type = "fem"
material = "neo_hookean"
E = 1e5
nu = 0.3
density = 1000.0

[boundary]
fixed = ["left"]

[loads]
gravity = [0.0, 0.0, -9.81]

[integrator]
type = "implicit_euler"

[time]
dt = 0.01
duration = 0.1

[output]
every = 2
render = ["gif", "png"]
size = [160, 120]
fps = 10

[[compare]]
name = "springs"
body = { type = "springs", E = 1e5, nu = 0.25, density = 1000.0 }
"""


# The timeout only catches a hung command: the whole suite, this test included, takes ~370 s on
# an idle 2-core machine, but 300 s for one command was exceeded once when the suite ran at a load of 12.
def run(*args, timeout=900, **kwargs):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.run(
        [sys.executable, "-m", "fem_elastic.app.cli", *map(str, args)],
        capture_output=True, text=True, timeout=timeout, env=env, **kwargs,
    )


def clean_error(r, *phrases):
    """A user error: a non-zero exit, one message naming the problem, no traceback."""
    assert r.returncode != 0
    assert "Traceback" not in r.stderr and "Traceback" not in r.stdout, r.stderr
    for phrase in phrases:
        assert phrase in r.stderr, f"{phrase!r} not in:\n{r.stderr}"


@pytest.fixture
def tiny(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path


def test_no_command_prints_help_and_fails():
    r = run()
    assert r.returncode == 2 and "demo" in r.stdout and "study" in r.stdout


@pytest.mark.parametrize("command", ["demo", "run", "render", "info", "study"])
def test_help_everywhere(command):
    r = run(command, "--help")
    assert r.returncode == 0 and "usage: fem-elastic" in r.stdout


def test_run_help_documents_the_scene_schema():
    r = run("run", "--help")
    for table in ("[mesh]", "[body]", "[time]", "[output]", "[[compare]]"):
        assert table in r.stdout, table


def test_bad_option_is_a_clean_error():
    r = run("render", "x", "--fps", "-5")
    assert r.returncode == 2 and "must be >= 1" in r.stderr and "Traceback" not in r.stderr


def test_run_writes_series_summary_and_renders(tiny, tmp_path):
    out = tmp_path / "out"
    r = run("run", tiny, "--out", out)
    assert r.returncode == 0, r.stderr
    assert "fem" in r.stdout and "springs" in r.stdout and "completed" in r.stdout
    for variant in ("fem", "springs"):
        series = read_series(out / variant)
        # 10 steps recorded every 2: the initial frame and 5 more
        assert series.times.size == 6 and np.allclose(series.times[-1], 0.1)
        assert series.displacement[-1, :, 2].min() < 0  # it sags under gravity
        summary = json.loads((out / variant / "summary.json").read_text())
        assert summary["status"] == "completed" and summary["steps"] == 10
    top = json.loads((out / "summary.json").read_text())
    assert list(top["variants"]) == ["fem", "springs"]
    assert (out / "movie.gif").stat().st_size > 0
    assert len(list((out / "png").glob("*.png"))) == 6


def test_run_quiet_prints_nothing(tiny, tmp_path):
    r = run("run", tiny, "--out", tmp_path / "q", "--quiet", "--no-render")
    assert r.returncode == 0, r.stderr
    assert r.stdout == ""
    assert (tmp_path / "q" / "fem" / "series.pvd").is_file()
    assert not (tmp_path / "q" / "movie.gif").exists()


def test_run_matches_the_python_api(tiny, tmp_path):
    """The command's VTU series holds the displacements fe.simulate computes for the same scene."""
    out = tmp_path / "api"
    assert run("run", tiny, "--out", out, "--quiet", "--no-render", "--variant", "fem").returncode == 0
    mesh = fe.beam_mesh(length=0.4, width=0.1, height=0.1, cells=(4, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
                     fixed="left", gravity=(0.0, 0.0, -9.81))
    traj = fe.simulate(model, fe.ImplicitEuler(), dt=0.01, steps=10, record_every=2)
    series = read_series(out / "fem")
    np.testing.assert_allclose(series.times, traj.times, rtol=0, atol=1e-12)
    # same arithmetic in both processes; the VTU stores float64
    np.testing.assert_allclose(series.displacement, traj.displacement, rtol=0, atol=1e-12)
    assert not (out / "springs").exists()


BAD_SCENES = {
    "unknown key with a near miss": (TINY.replace("E = 1e5\nnu = 0.3", "Young = 1e5\nnu = 0.3"),
                                     ["Young", "line 15"]),
    "misspelt material": (TINY.replace('"neo_hookean"', '"neohookean"'), ["neohookean", "neo_hookean"]),
    "wrong type": (TINY.replace("dt = 0.01", 'dt = "fast"'), ["dt", "line 29"]),
    "missing field": (TINY.replace("dt = 0.01\n", ""), ["dt"]),
    "out of range": (TINY.replace("nu = 0.3", "nu = 0.5"), ["nu", "0.5"]),
    "syntax error": (TINY.replace("[time]", "[time"), ["line"]),
    "unknown table": (TINY + "\n[grond]\nz = 0.0\n", ["grond", "ground"]),
    "unknown boundary": (TINY.replace('fixed = ["left"]', 'fixed = ["lefft"]'), ["lefft", "left"]),
}


@pytest.mark.parametrize("case", sorted(BAD_SCENES))
def test_bad_scene_files_are_clean_errors(case, tmp_path):
    text, phrases = BAD_SCENES[case]
    path = tmp_path / "bad.toml"
    path.write_text(text)
    r = run("run", path, "--out", tmp_path / "o", "--quiet")
    assert r.returncode == 2, (r.returncode, r.stderr)
    clean_error(r, *phrases)
    assert not (tmp_path / "o" / "fem" / "series.pvd").exists()


def test_missing_scene_file_is_a_clean_error(tmp_path):
    clean_error(run("run", tmp_path / "nope.toml", "--out", tmp_path / "o"), "nope.toml")


def test_paths_that_cannot_be_used_are_clean_errors(tiny, tmp_path):
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    # an output directory under a file: mkdir fails with NotADirectoryError
    clean_error(run("run", tiny, "--out", a_file / "out", "--quiet"), "Not a directory", "a_file")
    # a mesh file meshio cannot read (meshio itself would call sys.exit), a directory
    (tmp_path / "broken.vtu").write_text("garbage")
    r = run("info", tmp_path / "broken.vtu")
    assert r.returncode == 2
    clean_error(r, "could not read", "broken.vtu")
    clean_error(run("info", tmp_path), "Is a directory")


def test_vtu_false_keeps_only_the_summary(tiny, tmp_path):
    tiny.write_text(TINY.replace("every = 2", "every = 2\nvtu = false").replace(
        'render = ["gif", "png"]', 'render = ["gif"]'))
    out = tmp_path / "o"
    r = run("run", tiny, "--out", out, "--quiet")
    assert r.returncode == 0, r.stderr
    for variant in ("fem", "springs"):
        assert not (out / variant / "series.pvd").exists()
        assert not (out / variant / "frames").exists()
        assert json.loads((out / variant / "summary.json").read_text())["status"] == "completed"
    assert (out / "movie.gif").stat().st_size > 0  # rendered from the series before it went


def test_render_each_format(tiny, tmp_path):
    out = tmp_path / "r"
    assert run("run", tiny, "--out", out, "--quiet", "--no-render").returncode == 0
    for fmt in ("png", "gif", "mp4"):
        r = run("render", out, "--format", fmt, "--size", "160", "120", "--quiet")
        assert r.returncode == 0, r.stderr
    assert len(list((out / "png").glob("*.png"))) == 6
    assert (out / "movie.gif").stat().st_size > 0 and (out / "movie.mp4").stat().st_size > 0
    # a single run directory renders too, to a chosen path
    r = run("render", out / "springs", "--format", "gif", "-o", tmp_path / "s.gif", "--size", "160", "120")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "s.gif").is_file()


def test_render_without_a_series_is_a_clean_error(tmp_path):
    clean_error(run("render", tmp_path, "--format", "png"), "no VTU series")


def test_info_reports_counts_quality_and_boundaries(tmp_path):
    r = run("info", ROOT / "meshes" / "beam.vtu")
    assert r.returncode == 0, r.stderr
    mesh = fe.load_mesh(ROOT / "meshes" / "beam.vtu")
    q = fe.mesh_quality(mesh)
    assert f"vertices        {q['n_vertices']}" in r.stdout
    assert f"tetrahedra      {q['n_elements']}" in r.stdout
    for name in mesh.boundaries:
        assert name in r.stdout
    assert "validation      ok" in r.stdout


def test_info_flags_an_inverted_mesh(tmp_path):
    mesh = fe.beam_mesh(cells=(2, 1, 1))
    t = mesh.t.copy()
    t[[0, 1], 0] = t[[1, 0], 0]  # swap two vertices of one tet: it is inverted
    bad = fe.mesh_from_arrays(mesh.p.T, t.T, validate=False)
    path = fe.save_mesh(bad, tmp_path / "bad.vtu")
    r = run("info", path)
    assert r.returncode == 1
    assert "inverted tets   1" in r.stdout and "FAILED" in r.stdout and "Traceback" not in r.stderr


def test_info_on_a_scene_file(tiny):
    r = run("info", tiny)
    assert r.returncode == 0 and "tetrahedra      24" in r.stdout


def test_sigint_leaves_readable_files_and_a_clear_message(tmp_path):
    scene = tmp_path / "long.toml"
    scene.write_text(
        TINY.replace("duration = 0.1", "duration = 1000.0").replace("every = 2", "every = 1")
        .replace('render = ["gif", "png"]', "render = []")
    )
    out = tmp_path / "long"
    # A background job of a non-interactive shell (CI runners, `cmd &`) inherits SIGINT ignored,
    # and Python then leaves it ignored: give the child the default disposition, as a terminal would.
    proc = subprocess.Popen(
        [sys.executable, "-m", "fem_elastic.app.cli", "run", str(scene), "--out", str(out), "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    frames = out / "fem" / "frames"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list(frames.glob("*.vtu"))) < 5:
        time.sleep(0.1)
    assert len(list(frames.glob("*.vtu"))) >= 5, "the run wrote no frames within 120 s"
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert "interrupted" in stderr and "readable" in stderr and "Traceback" not in stderr
    series = read_series(out / "fem")
    assert series.times.size >= 5 and np.isfinite(series.displacement).all()
    summary = json.loads((out / "fem" / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    scene_summary = json.loads((out / "summary.json").read_text())
    assert scene_summary["status"] == "interrupted"
    assert scene_summary["variants"]["fem"]["status"] == "interrupted"
    # no half-written file is left under a final name
    assert not [p for p in (out / "fem").rglob("*") if p.name.startswith(".") or p.suffix == ".tmp"]


def test_demo_runs_the_default_scene(tmp_path):
    out = tmp_path / "demo"
    t0 = time.perf_counter()
    r = run("demo", "--out", out)
    seconds = time.perf_counter() - t0
    assert r.returncode == 0, r.stderr
    assert "Timoshenko" in r.stdout and "static FE" in r.stdout
    for variant in ("fem", "springs"):
        assert (out / variant / "series.pvd").is_file()
    assert (out / "movie.mp4").stat().st_size > 10_000
    assert list((out / "png").glob("*.png"))
    print(f"demo: {seconds:.1f} s")


def test_demo_prints_its_scene():
    r = run("demo", "--print-scene")
    assert r.returncode == 0 and "[[compare]]" in r.stdout


@pytest.mark.parametrize("which", ["accuracy", "stability"])
def test_study_quick_through_the_command(which, tmp_path):
    out = tmp_path / which
    r = run("study", which, "--quick", "--serial", "--out", out, "--quiet")
    assert r.returncode == 0, r.stderr
    assert (out / "results.csv").is_file() and (out / "report.md").is_file()


@pytest.mark.parametrize("options, said", [
    (["--scheduler", "nonsense"], "cannot use the Dask scheduler at 'nonsense'"),  # no port: ValueError
    (["--scheduler", " "], "needs the scheduler's address"),
    (["--serial", "--scheduler", "tcp://127.0.0.1:8786"], "exclude each other"),
])
def test_study_bad_scheduler_is_a_clean_usage_error(options, said, tmp_path):
    pytest.importorskip("distributed", reason="the --scheduler path needs the [cluster] extra")
    r = run("study", "accuracy", "--quick", "--out", tmp_path / "s", "--quiet", *options)
    assert r.returncode == 2 and said in r.stderr, r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "s").exists()
