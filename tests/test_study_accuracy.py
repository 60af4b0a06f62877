"""The accuracy study: well-formed outputs, errors that agree with direct runs, resume.

The study runs here on a subset of its quick sweep, in this process (serial executor), so the
test takes seconds; ``tests/test_study_executor.py`` covers the parallel executors.
"""

import csv
import json
import math

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.physics.loads import traction_load
from fem_elastic.study.accuracy import (
    PROBLEMS,
    accuracy_cases,
    prony_frequency,
    run_accuracy_study,
)

pytest.importorskip("matplotlib", reason="the study's figure needs the [study] extra (matplotlib)")

SUBSET = {
    "static_tip/linear/P2/10x1x1",
    "static_tip/linear/P1/20x1x1",
    "static_tip/springs/20x1x1",
    "self_weight/linear/P2/10x1x1",
    "modal/linear/P2/10x1x1",
    "large_deflection/linear/P2/10x1x1",
    "large_deflection/neo_hookean/P2/10x1x1",
    "dynamic/linear/P2/5x1x1/ExplicitEuler/c0.9",
    "dynamic/linear/P2/5x1x1/ImplicitEuler/N16",
    "dynamic/linear/P2/5x1x1/Newmark/N16",
    "linearized/neo_hookean/P2/5x1x1/reference",
    "linearized/neo_hookean/P2/5x1x1/N8",
}


def _subset(case):
    return case.id in SUBSET


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("accuracy")
    result = run_accuracy_study(out, quick=True, executor="serial", progress=False, _case_filter=_subset)
    return out, result


def _row(result, cid):
    return next(r for r in result.rows if r["id"] == cid)


def test_quick_sweep_covers_every_problem_with_unique_ids():
    cases = accuracy_cases(quick=True)
    ids = [c.id for c in cases]
    assert len(set(ids)) == len(ids)
    # the methods of issue 16 are their own problem (tests/test_study_methods.py)
    assert {c.params["problem"] for c in cases} == set(PROBLEMS) | {"methods"}
    assert SUBSET <= set(ids)
    json.dumps([c.params for c in cases])  # JSON-able
    full = accuracy_cases(quick=False)
    assert len(full) > 3 * len(cases)
    integrators = {c.params.get("integrator") for c in full if c.params["problem"] == "dynamic"}
    assert {c.params["method"] for c in full if c.params["problem"] == "methods"} == {
        "Trapezoid", "VelocityVerlet", "PBD", "XPBD", "XPBD edge_volume", "ShapeMatching", "ProjectiveDynamics"}
    assert integrators == {"ExplicitEuler", "SymplecticEuler", "Midpoint", "RK4", "ImplicitEuler",
                           "LinearizedImplicitEuler", "Newmark"}
    assert {c.params["body"] for c in full if c.params["problem"] != "methods"} == {
        "springs", "linear", "corotated", "stvk", "neo_hookean"}


def test_outputs_are_well_formed(study):
    out, result = study
    assert len(result.rows) == len(SUBSET) and result.n_run == len(SUBSET)
    with open(out / "results.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert len(table) == len(SUBSET)
    for column in ("id", "problem", "body", "order", "cells", "status", "rel_error", "abs_error",
                   "seconds_solve", "seconds"):
        assert column in table[0], column
    assert not any(k.startswith("tip_history") for k in table[0])  # trajectories stay in results.jsonl
    for row in result.rows:
        assert row["seconds"] >= row["seconds_solve"] > 0, row["id"]
        if row["id"].endswith("ExplicitEuler/c0.9"):
            # undamped explicit Euler amplifies every mode at any dt: it must diverge
            assert row["status"] == "diverged" and row["rel_error"] is None, row
            continue
        assert row["status"] == "ok", row
        assert math.isfinite(row["rel_error"]) and row["abs_error"] == abs(row["rel_error"])
    png = out / "error_vs_time.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
    import matplotlib.image

    image = matplotlib.image.imread(png)
    assert image.shape[0] > 300 and image.shape[1] > 600 and float(image[..., :3].std()) > 0.05
    report = (out / "report.md").read_text()
    for phrase in ("## Conclusions", "| id | status |", "within 10%", "Pareto front", "P1 locking",
                   "Large deflection needs a nonlinear body", "LinearizedImplicitEuler against ImplicitEuler",
                   "diverged in every run"):
        assert phrase in report, phrase
    assert report.count("\n| ") >= len(SUBSET)  # one table line per run at least
    assert result.figures == [png] and result.csv_path == out / "results.csv"


def _tip(model, x, axis=2):
    t = np.zeros(3)
    t[axis] = 1.0
    w = traction_load(model.space, "right", t).force
    return float(w @ (x - model.X)) / w.sum()


def test_static_and_modal_errors_agree_with_direct_runs(study):
    """The same cantilever built by hand through the public API gives the same errors (the static
    solve is deterministic: 1e-9 only absorbs round-off)."""
    _, result = study
    L, b, h, E, nu, rho = 1.0, 0.05, 0.05, 1e9, 0.3, 1000.0
    beam = fe.RectangularCantilever(L, b, h, E, nu)
    mesh = fe.beam_mesh(L, b, h, cells=(10, 1, 1))
    body = fe.ElasticBody(fe.LinearElastic(E=E, nu=nu), order=2)

    model = fe.Model(mesh, rho, body, fixed="left", traction={"right": (0.0, 0.0, -3.0e3)})
    res = fe.solve_static(model, linear_solver=fe.DirectSolver())
    err = -_tip(model, res.x) / beam.tip_load_timoshenko(3.0e3 * b * h) - 1.0
    # the same direct solve repeated outside the study: equal to round-off (1e-9 >> eps, << any physics)
    assert _row(result, "static_tip/linear/P2/10x1x1")["rel_error"] == pytest.approx(err, rel=1e-9)

    model = fe.Model(mesh, rho, body, fixed="left")
    f1 = fe.natural_frequencies(model, 1)[0]
    row = _row(result, "modal/linear/P2/10x1x1")
    # ARPACK starts from a random vector: two solves agree to its tolerance (measured 2e-11), not bit for bit
    assert row["value"] == pytest.approx(f1, rel=1e-9)
    assert row["rel_error"] == pytest.approx(f1 / beam.first_bending_frequency(rho) - 1.0, abs=1e-9)

    alpha = 2.0
    P = alpha * E * beam.second_moment / L**2
    nh = fe.ElasticBody(fe.NeoHookean(E=E, nu=nu), order=2)
    model = fe.Model(mesh, rho, nh, fixed="left", traction={"right": (0.0, 0.0, -P / (b * h))})
    res = fe.solve_static(model, linear_solver=fe.DirectSolver())
    d, _ = fe.elastica_tip(alpha)
    err = -_tip(model, res.x) / (d * L) - 1.0
    row = _row(result, "large_deflection/neo_hookean/P2/10x1x1")
    assert row["rel_error"] == pytest.approx(err, rel=1e-9)  # the same Newton solve: round-off only
    # the physics the report states: the nonlinear body follows the elastica (measured -1.4 % on this
    # coarse mesh; 3 % leaves room for the FE stiffness), linear FEM overshoots by ~ (alpha/3) / d - 1 = +35 %
    assert abs(row["rel_error"]) < 0.03
    assert _row(result, "large_deflection/linear/P2/10x1x1")["rel_error"] > 0.25


def test_dynamic_error_agrees_with_a_direct_run_and_the_schemes_phase_error(study):
    """Newmark by hand from the same release gives the same frequency. And the time-integration
    error alone matches each scheme's closed-form phase error on a modal oscillator, since the
    release is a single (lumped-mass) mode of a linear body: Newmark (trapezoidal rule)
    omega_h = (2 / h) atan(omega h / 2); implicit Euler omega_h = atan(omega h) / h. The Prony fit
    is exact for one mode; 1e-6 covers the Newton tolerance and the eigenvector's accuracy."""
    _, result = study
    L, b, h, E, nu, rho = 1.0, 0.2, 0.2, 1e7, 0.3, 1000.0
    beam = fe.RectangularCantilever(L, b, h, E, nu)
    model = fe.Model(fe.beam_mesh(L, b, h, cells=(5, 1, 1)), rho,
                     fe.ElasticBody(fe.LinearElastic(E=E, nu=nu), order=2), fixed="left")
    f_ref = beam.first_bending_frequency(rho)
    f_h, phi = fe.natural_frequencies(model, 1, mass="lumped", return_modes=True)
    w = traction_load(model.space, "right", (0.0, 0.0, 1.0)).force
    w = w / w.sum()
    x0 = model.X + phi[:, 0] * (-1e-4 / float(w @ phi[:, 0]))
    dt = 1.0 / (16 * f_ref)
    tip = [float(w @ (x0 - model.X))]
    fe.simulate(model, fe.Newmark(), dt, steps=16, state=fe.State(x0, np.zeros(model.ndofs)),
                check_stability=False, callback=lambda k, s: tip.append(float(w @ (s.x - model.X))))
    f_dyn, _ = prony_frequency(tip, dt)
    row = _row(result, "dynamic/linear/P2/5x1x1/Newmark/N16")
    assert row["rel_error"] == pytest.approx(f_dyn / f_ref - 1.0, rel=1e-9)  # the same run, by hand: round-off

    wh = 2 * math.pi * f_h[0] * dt
    assert row["time_error"] == pytest.approx((2 / wh) * math.atan(wh / 2) - 1.0, rel=1e-6)
    ie = _row(result, "dynamic/linear/P2/5x1x1/ImplicitEuler/N16")
    assert ie["time_error"] == pytest.approx(math.atan(wh) / wh - 1.0, rel=1e-6)
    assert ie["decay_rate"] == pytest.approx(math.log1p(wh**2) / (2 * dt), rel=1e-6)  # |z| = 1/sqrt(1 + (wh)^2)


def test_linearized_gap_and_reference_errors(study):
    _, result = study
    row = _row(result, "linearized/neo_hookean/P2/5x1x1/N8")
    # a large swing at 8 steps per period: one Newton step per step departs visibly from converged
    # implicit Euler, and both are far from the Newmark reference (implicit Euler's numerical damping)
    assert 0.01 < row["rel_error"] < 1.0
    assert row["ie_error_vs_reference"] > row["rel_error"]
    assert row["seconds_implicit_euler"] > row["seconds_solve"]  # Newton to convergence costs more
    ref = _row(result, "linearized/neo_hookean/P2/5x1x1/reference")
    assert len(ref["tip_history"]) == 1 + ref["steps"] // ref["sample_every"]


def test_prony_frequency_rejects_non_oscillating_samples():
    with pytest.raises(fe.InvalidParameter, match="oscillate"):
        prony_frequency(np.exp(-np.arange(10.0)), 0.1)
    with pytest.raises(fe.InvalidParameter, match="4 samples"):
        prony_frequency([1.0, 0.0, -1.0], 0.1)


def test_resume_runs_nothing_new(study):
    out, first = study
    lines = (out / "results.jsonl").read_text().splitlines()
    again = run_accuracy_study(out, quick=True, executor="serial", progress=False, _case_filter=_subset)
    assert again.n_run == 0
    assert (out / "results.jsonl").read_text().splitlines() == lines
    assert [r["rel_error"] for r in again.rows] == [r["rel_error"] for r in first.rows]
