"""The distributed backend on 2 MPI ranks (issue 21): same answers as the serial solves, the
command line under mpiexec, and the typed errors of a bad set-up.

Every test here starts ``mpiexec -n 2`` (tests/mpi_support.py); without the [mpi] extra they
skip, except under FEM_ELASTIC_REQUIRE_MPI=1 (CI), where they fail.
"""

import json

import numpy as np

import fem_elastic as fe
from mpi_support import ROOT, require_mpi, run_mpi
from small_scene import small_scene


def _result(proc):
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert len(lines) == 1, proc.stdout  # rank 0 alone prints
    return json.loads(lines[0][len("RESULT "):])


def test_two_ranks_agree_with_the_serial_solves():
    require_mpi()
    out = _result(run_mpi(2, ["python", ROOT / "tests" / "mpi" / "compare_serial.py"]))
    assert out["ranks"] == 2
    # Issue 21 asks for 1e-8 relative. Both solves stop at ||g|| <= 1e-11 of the force scale, so
    # their displacements differ by about that over the smallest stiffness scale (measured
    # 1e-12 .. 5e-14): 1e-8 has four orders of room and still catches any wrong entry, which moves
    # the answer by far more (a dropped element moves it by ~1e-3 here).
    for key in ("linear", "linear_reaction", "neohookean", "p2_prescribed", "p2_reaction"):
        assert out[key] < 1e-8, (key, out[key])
    # the Neo-Hookean case is large deflection, not a linear solve in disguise
    assert out["neohookean_tip"] > 0.05 and out["neohookean_iterations"] > 2
    # two implicit Euler steps: the same minimiser to the Newton tolerance (1e-11 of the step's force)
    assert out["implicit_x"] < 1e-8 and out["implicit_v"] < 1e-8
    assert out["same_on_every_rank"]


_ONE_TET = """
import sys
import numpy as np, fem_elastic as fe
from petsc4py import PETSc
from skfem import MeshTet
mesh = MeshTet(np.array([[0., 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]), np.array([[0], [1], [2], [3]]))
model = fe.Model(mesh, 1000.0, fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)),
                 fixed=[(np.array([0, 1, 2]), "xyz")], gravity=(0, 0, -9.81))
try:
    fe.solve_static(model, linear_solver=fe.PETScSolver())
except fe.InvalidParameter as e:  # each rank writes its own file: mpiexec interleaves stdout
    with open(f"{sys.argv[1]}/rank{PETSc.COMM_WORLD.getRank()}.txt", "w") as f:
        f.write(str(e))
"""


def test_more_ranks_than_tets_is_a_typed_error_on_every_rank(tmp_path):
    require_mpi()
    proc = run_mpi(2, ["python", "-c", _ONE_TET, tmp_path], timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    # both ranks raise fe.InvalidParameter (neither waits for the other forever)
    for rank in (0, 1):
        message = (tmp_path / f"rank{rank}.txt").read_text()
        assert "cannot split 1 tets among 2 MPI ranks" in message and "mpiexec -n 1" in message


def _vertices_of_last_frame(run_dir):
    return np.asarray(fe.read_series(run_dir).displacement[-1])


def test_the_command_line_on_two_ranks_writes_once_and_matches_one_rank(tmp_path):
    require_mpi()
    scene = ROOT / "scenes" / "cantilever_mpi.toml"
    two = run_mpi(2, ["python", "-m", "fem_elastic", "run", scene, "--out", tmp_path / "two"])
    assert two.returncode == 0, two.stdout[-3000:] + two.stderr[-3000:]
    assert two.stdout.count("written to") == 1 and "on 2 MPI ranks" in two.stdout  # rank 0 prints
    model = fe.load_scene(scene).build()[0].model  # the same scene, solved serially here
    one = fe.solve_static(model, steps=4, stability=False)
    summary = json.loads((tmp_path / "two" / "fem" / "summary.json").read_text())
    assert summary["status"] == "completed"
    u_two = _vertices_of_last_frame(tmp_path / "two" / "fem")
    # both stop at the scene's default rtol, 1e-8 of the load, on a soft beam sagging 0.49 m:
    # their answers differ by that over the tangent's smallest stiffness (measured 1.4e-13 of |u|);
    # 1e-8 still fails for any wrong element, which moves the tip by ~1e-3 of |u|
    assert np.abs(u_two - one.displacement).max() < 1e-8 * np.abs(one.displacement).max()


_DYNAMIC = small_scene("mpi_dynamic", material="neo_hookean", E="1.0e6", cells=(8, 2, 2),
                       duration=0.05, integrator_options='linear_solver = "petsc"\nrtol = 1e-10')


def test_implicit_euler_scene_on_two_ranks_matches_the_serial_run(tmp_path):
    require_mpi()
    path = tmp_path / "dyn.toml"
    path.write_text(_DYNAMIC)
    proc = run_mpi(2, ["python", "-m", "fem_elastic", "run", path, "--out", tmp_path / "two"])
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    serial = path.with_name("serial.toml")
    serial.write_text(_DYNAMIC.replace('linear_solver = "petsc"', 'linear_solver = "direct"'))
    from fem_elastic.app.cli import main

    assert main(["run", str(serial), "--out", str(tmp_path / "one"), "--quiet", "--no-render"]) == 0
    u2 = _vertices_of_last_frame(tmp_path / "two" / "fem")
    u1 = _vertices_of_last_frame(tmp_path / "one" / "fem")
    # five steps, each converged to rtol = 1e-10 of the step's force scale: the two runs differ
    # by that over the step's stiffness (M / h^2 + K), compounded over the steps (measured
    # 2.5e-13 of |u|); 1e-7 leaves room for CG's stopping point to differ between the runs and
    # still fails for any wrong element or exchange, which moves the beam by ~1e-3 of |u|
    assert np.abs(u2 - u1).max() < 1e-7 * np.abs(u1).max()
    assert np.abs(u1).max() > 1e-3  # it moved


def test_a_serial_scene_under_mpiexec_is_refused_with_the_fix(tmp_path):
    require_mpi()
    proc = run_mpi(2, ["python", "-m", "fem_elastic", "run", ROOT / "scenes" / "uniaxial_static.toml",
                       "--out", tmp_path / "o"], timeout=120)
    assert proc.returncode == 2
    assert 'linear_solver = "petsc"' in proc.stderr
    assert not (tmp_path / "o").exists()
