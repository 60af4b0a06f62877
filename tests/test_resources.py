"""Resources are checked before they are spent, and bounds are finite.

Memory and disk estimates refuse a model or a series that cannot fit, in well
under a second, naming the estimate and what is free (the limits are set
through the documented environment variables, so the tests do not depend on
the machine). Scene paths that are FIFOs, devices or huge files are refused
by type and size before any read; render sizes, dt cuts and sub-steps have
upper bounds; the PVD's times are the exact step times n dt.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fem_elastic as fe
from fem_elastic.app import cli
from fem_elastic.app.vtu import read_series
from fem_elastic.resources import (
    BYTES_PER_TET, DISK_ENV, MEMORY_ENV, MODEL_BYTES_PER_TET, available_memory, check_input_file, format_bytes,
    model_memory,
)
from small_scene import small_scene

SCENE = small_scene("res", integrator="symplectic_euler", dt=0.001, duration=0.01)


def _scene(tmp_path, text=SCENE) -> Path:
    path = tmp_path / "s.toml"
    path.write_text(text, encoding="utf-8")
    return path


@settings(max_examples=30, deadline=None)
@given(n_tets=st.integers(1, 10**8), order=st.sampled_from([1, 2]),
       solver=st.sampled_from(["auto", "direct", "iterative", "none"]))
def test_the_memory_estimate_grows_with_the_model_and_is_at_least_the_measured_part(n_tets, order, solver):
    n_vertices = max(4, n_tets // 5)  # a tet mesh has about 5-6 tets per vertex
    m = model_memory(n_tets, n_vertices, order, solver)
    assert m["total"] >= m["model"] >= BYTES_PER_TET[order] * n_tets
    assert m["ndof"] == 3 * (n_vertices if order == 1 else 2 * n_vertices + n_tets)
    if solver == "auto":  # switches from LU to AMG at 20 000 DOFs, as AutoSolver does: may drop there
        return
    assert model_memory(2 * n_tets, 2 * n_vertices, order, solver)["total"] > m["total"]
    if order == 1:  # quadratic tets cost more per tet
        assert model_memory(n_tets, n_vertices, 2, solver)["total"] > m["total"]


def test_the_estimate_bounds_what_building_a_model_takes():
    # measured: tracemalloc's peak of Model(...) + one linearize, against the estimate (which
    # adds the solver's share on top, so it must exceed the measured model part)
    import tracemalloc

    from fem_elastic.discretization import fused

    def build(cells):
        mesh = fe.beam_mesh(cells=cells)
        model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3)), fixed="left")
        model.linearize(model.X)
        return mesh

    build((2, 1, 1))  # once per process, not per tet: loading the compiled kernels (numba's own objects)
    tracemalloc.start()
    mesh = build((10, 3, 3))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    est = model_memory(mesh.t.shape[1], mesh.p.shape[1], 1, fused=fused.available())
    assert peak <= est["model"] <= 3 * peak  # an upper bound, and not a wild one


def test_a_model_that_cannot_fit_says_so_at_once(monkeypatch):
    mesh = fe.beam_mesh(cells=(10, 3, 3))
    monkeypatch.setenv(MEMORY_ENV, "1M")
    t0 = time.perf_counter()
    with pytest.raises(fe.ResourceLimit, match=r"would need about .* of memory .* DOFs.* only 1 MiB is free "
                                               rf"\(\${MEMORY_ENV}\).*coarser mesh") as err:
        fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3), order=2))
    assert time.perf_counter() - t0 < 1.0  # before any assembly
    assert err.value.available == 2**20 and err.value.needed > 2**20
    assert isinstance(err.value, fe.InvalidParameter)  # the command's exit 2: a setting to change
    monkeypatch.setenv(MEMORY_ENV, "lots")
    with pytest.raises(fe.InvalidParameter, match=f"{MEMORY_ENV}='lots' is not a size"):
        available_memory()
    monkeypatch.delenv(MEMORY_ENV)
    free = available_memory()
    assert free is None or free > 0


def test_a_series_that_cannot_fit_on_disk_is_refused_before_the_run(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv(DISK_ENV, "10K")
    out = tmp_path / "out"
    t0 = time.perf_counter()
    assert cli.main(["run", str(_scene(tmp_path)), "--out", str(out), "--quiet", "--no-render"]) == 2
    err = capsys.readouterr().err
    assert "of disk" in err and "10 KiB is free" in err and "every = N" in err
    assert time.perf_counter() - t0 < 5.0
    assert not (out / "fem" / "frames").exists()  # nothing written for the run


@pytest.mark.parametrize("kind", ["fifo", "device", "directory", "huge"])
def test_a_scene_path_that_is_not_a_small_file_is_refused_before_reading(kind, tmp_path, capsys):
    if kind == "fifo":
        path = tmp_path / "scene.toml"
        os.mkfifo(path)  # reading it would block forever: no writer
        phrase = "FIFO"
    elif kind == "device":
        path = Path("/dev/zero")  # reading it would never end
        if not path.exists():
            pytest.skip("no /dev/zero on this system")
        phrase = "a device"
    elif kind == "directory":
        path = tmp_path
        phrase = "a directory"
    else:
        path = tmp_path / "huge.toml"
        with open(path, "wb") as fh:
            fh.truncate(64 * 2**20)  # sparse: 64 MiB of nothing, no disk used
        phrase = "more than the 4 MiB"
    t0 = time.perf_counter()
    assert cli.main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert phrase in capsys.readouterr().err
    assert time.perf_counter() - t0 < 2.0  # refused, not read


def test_check_input_file_accepts_a_file_and_names_the_size(tmp_path):
    p = tmp_path / "a.toml"
    p.write_text("x = 1\n")
    assert check_input_file(p, 100) == p
    with pytest.raises(fe.InvalidParameter, match=r"is 6 B, more than the 5 B"):
        check_input_file(p, 5)
    assert format_bytes(3 * 2**30) == "3 GiB"


def test_render_sizes_are_bounded_in_the_schema_and_the_command(tmp_path, capsys):
    text = SCENE.replace("render = []", "render = []\nsize = [10000, 540]")
    with pytest.raises(fe.FemElasticError, match="size.*10000 is out of range: it must be <= 8192"):
        fe.load_scene(_scene(tmp_path, text))
    with pytest.raises(SystemExit):
        cli.main(["render", str(tmp_path), "--size", "9000", "100"])
    assert "must be <= 8192 px" in capsys.readouterr().err


def test_dt_cuts_and_substeps_have_finite_bounds():
    fe.ImplicitEuler(max_dt_cuts=20)
    with pytest.raises(fe.InvalidParameter, match="max_dt_cuts must be an integer from 0 to 20"):
        fe.ImplicitEuler(max_dt_cuts=21)
    with pytest.raises(fe.InvalidParameter, match="max_dt_cuts"):
        fe.Newmark(max_dt_cuts=10**6)
    fe.SymplecticEuler(max_substeps=10**6)
    with pytest.raises(fe.InvalidParameter, match="max_substeps must be at most 1,000,000"):
        fe.SymplecticEuler(max_substeps=10**6 + 1)


def test_the_series_times_are_the_exact_step_times(tmp_path):
    out = tmp_path / "out"
    assert cli.main(["run", str(_scene(tmp_path)), "--out", str(out), "--quiet", "--no-render"]) == 0
    series = read_series(out / "fem")
    n = np.arange(series.times.size)
    # t = n dt computed as one product, bit for bit: a running sum of 0.001 drifts in the last bits
    np.testing.assert_array_equal(series.times, n * 0.001)
    assert np.cumsum(np.full(10, 0.001))[-1] != 10 * 0.001  # what the sum would have written


def test_an_explicit_model_is_checked_for_its_own_share_and_the_tangent_where_it_is_built(monkeypatch, caplog):
    # a limit between model + tangent (what an explicit run's critical time step assembles) and
    # model + tangent + LU: the model builds and an explicit run goes, with its stability check;
    # a static solve, an implicit run and modal analysis (which factorize) are refused before
    # any assembly, with advice that applies (no order=1 for a body already of order 1)
    mesh = fe.beam_mesh(cells=(10, 3, 3))
    nt, nv = mesh.t.shape[1], mesh.p.shape[1]
    from fem_elastic.discretization import fused

    own = model_memory(nt, nv, 1, tangent=False)
    tangent = model_memory(nt, nv, 1, "none", fused=fused.available())  # what the model assembles with
    full = model_memory(nt, nv, 1, fused=fused.available())
    assert own["solver"] == 0 and own["total"] == MODEL_BYTES_PER_TET[1] * nt < tangent["total"] < full["total"]
    monkeypatch.setenv(MEMORY_ENV, str(int(0.5 * (tangent["total"] + full["total"]))))
    body = fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3))
    model = fe.Model(mesh, density=1000.0, body=body, fixed="left", gravity=(0, 0, -9.81))
    with caplog.at_level("WARNING"):
        run = fe.simulate(model, fe.SymplecticEuler(), dt=1e-4, steps=3)
    assert np.isfinite(run.final_state.x).all()
    assert "could not estimate the critical time step" not in caplog.text  # its tangent fits
    for work in (lambda: fe.solve_static(model), lambda: fe.simulate(model, fe.ImplicitEuler(), dt=0.01, steps=1),
                 lambda: fe.natural_frequencies(model, 2)):
        with pytest.raises(fe.ResourceLimit, match=r"the tangent of this model .*with its linear solver.*"
                                                   r"explicit integrator") as err:
            work()
        assert "order=1" not in str(err.value)
    # and a quadratic body whose own share (no matrix) does not fit is refused where it is built
    monkeypatch.setenv(MEMORY_ENV, str(int(0.5 * model_memory(nt, nv, 2, tangent=False)["total"])))
    with pytest.raises(fe.ResourceLimit, match=r"this model \(.*order 2\).*for the model, no matrix.*order=1") as err:
        fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3), order=2),
                 fixed="left")
    assert "explicit integrator" not in str(err.value)  # no matrix in that share: no such advice
