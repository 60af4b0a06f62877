"""The stability study: its scenes, its verdicts against direct runs, its outputs and resume.

The study runs here on a handful of its quick cases (serial, ~10 s), chosen
to give the verdicts stable, diverged, rejected and work limit, and every
kind of case (sweep, critical, extreme). The quick study's one Newton
failure costs 5 s and is left out; its classification is tested on the
errors that carry it.
"""

import csv
import json
import math

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.study import stability as st
from fem_elastic.study import stability_cases as sc
from fem_elastic.study import stability_methods as sm
from fem_elastic.study import stability_run as sr

# The subset of the quick study that the tests run.
_IDS = {
    "sweep/SymplecticEuler/linear/E=1e+07/nu=0.3/dt=0.001",   # 1.75 x its critical dt: diverges
    "sweep/SymplecticEuler/linear/E=1e+07/nu=0.3/dt=1e-05",   # 0.02 x: stable
    "sweep/ImplicitEuler/linear/E=1e+07/nu=0.3/dt=0.0416667",    # frame-rate step: stable
    "sweep/ImplicitEuler/corotated/E=1000/nu=0.3/dt=0.01",    # runs into the work limit
    "critical/SymplecticEuler/linear/E=1e+07/nu=0.3",
    "critical/RK4/linear/E=1e+07/nu=0.3",
    "extreme/crush/ImplicitEuler/neohookean/dt=0.0416667",
    "extreme/drop/SymplecticEuler/neohookean/dt=auto",
    "extreme/degenerate sliver/SymplecticEuler/neohookean/dt=auto",
}


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("stability")
    res = st.run_stability_study(out, quick=True, executor="serial", progress=False,
                                 _case_filter=lambda c: c.id in _IDS)
    return out, res


def _row(res, case_id):
    return next(r for r in res.rows if r["id"] == case_id)


# --- the cases and scenes -------------------------------------------------------------------


def test_case_lists():
    full, quick = st.study_cases(False), st.study_cases(True)
    for cases in (full, quick):
        ids = [c.id for c in cases]
        assert len(set(ids)) == len(ids)
        assert {c.params["integrator"] for c in cases if c.params["kind"] != "methods"} == set(st.INTEGRATORS)
        assert {c.params["integrator"] for c in cases if c.params["kind"] == "methods"} == set(sm.METHODS)
        assert {c.params["case"] for c in cases if c.params["kind"] == "extreme"} == set(sc.EXTREME_CASES)
        json.dumps([c.params for c in cases])  # the executor needs JSON-able params
    assert _IDS <= {c.id for c in quick}
    full_sweep = [c.params for c in full if c.params["kind"] == "sweep"]
    assert {p["body"] for p in full_sweep} == set(sc.BODIES)
    assert min(p["E"] for p in full_sweep) == 1e3 and max(p["E"] for p in full_sweep) == 1e11
    assert max(p["nu"] for p in full_sweep) == 0.4999 and max(p["dt"] for p in full_sweep) == 1 / 24
    # every explicit scheme has its bisection on every body of the E sweep, and on the nu sweep (linear)
    crit = {(p["integrator"], p["body"], p["E"], p["nu"]) for c in full if (p := c.params)["kind"] == "critical"}
    swept = {(p["integrator"], p["body"], p["E"], p["nu"]) for p in full_sweep if p["integrator"] in st.EXPLICIT
             and (p["nu"] in (0.3, 0.25) or p["body"] == "linear")}
    assert crit == swept


def test_sliver_mesh_has_flat_tets_in_an_unchanged_beam():
    beam = fe.beam_mesh(cells=(6, 2, 2))
    for rel in (1e-3, 1e-12):
        m = sc.sliver_mesh(rel)
        v = fe.signed_volumes(m)
        assert v.min() > 0  # nearly flat, not inverted
        # a volume is a difference of products of coordinates: its round-off is a few eps of the
        # element's own scale (the mean volume), 1e-14 of it with margin
        np.testing.assert_allclose(v.min() / v.mean(), rel, rtol=1e-6, atol=1e-14)
        assert np.count_nonzero(v < 0.01 * v.mean()) == 6  # two tets share each flattened plane
        # only interior vertices moved: the outer shape (every boundary vertex) is the beam's
        moved = np.flatnonzero(np.any(m.p != beam.p, axis=0))
        assert moved.size == 3
        assert np.all((m.p[:, moved] > 0) & (m.p[:, moved] < beam.p.max(axis=1)[:, None]))
    assert fe.validate_mesh(sc.sliver_mesh(1e-3)) is not None
    with pytest.raises(fe.InvalidMesh, match="zero volume"):  # 1e-12 < DEGENERATE_TOL = 1e-10
        fe.validate_mesh(sc.sliver_mesh(1e-12))


def test_inverted_scene_starts_with_inverted_tets():
    s = sc.inverted("linear", 1e5, 0.3)
    p = s.model.mesh.p.T + s.state.displacement(s.model)
    v = fe.signed_volumes(fe.mesh_from_arrays(p, s.model.mesh.t.T, validate=False))
    assert np.count_nonzero(v < 0) == 3
    assert np.isclose(np.abs(v).sum(), 0.01)  # the flip moves vertices, not volume


def test_classify():
    assert sr._classify(fe.Diverged("x", reason="Newton did not converge (line search failed)")) == "newton failed"
    assert sr._classify(fe.Diverged("x", reason="non-finite positions or velocities")) == "diverged"
    assert sr._classify(fe.NotConverged("linear solver")) == "newton failed"


# --- the study's outputs --------------------------------------------------------------------


def test_outputs_are_well_formed(study):
    out, res = study
    assert len(res.rows) == len(_IDS) and res.n_run == len(_IDS)
    with open(res.csv_path, newline="") as fh:
        table = list(csv.DictReader(fh))
    assert len(table) == len(_IDS)
    for col in ("id", "kind", "case", "integrator", "body", "E", "nu", "dt", "verdict", "step", "reason",
                "min_J", "energy_drift_pct", "dt_predicted", "dt_observed_lo", "dt_observed_hi", "ratio_lo"):
        assert col in table[0], col
    for r in table:
        if r["kind"] == "critical":
            assert r["verdict"] == "bracketed"
        else:
            assert r["verdict"] in st.VERDICTS and r["verdict"] != "error", (r["id"], r["reason"])
    assert {r["verdict"] for r in table} >= {"stable", "diverged", "work limit", "rejected"}
    for r in table:  # a stable run has its drift; a failed one its step
        if r["verdict"] == "stable":
            assert math.isfinite(float(r["energy_drift_pct"])) and math.isfinite(float(r["min_J"]))
        elif r["verdict"] in ("diverged", "newton failed"):
            assert int(r["step"]) >= 0 and r["reason"]
    for fig in res.figures:
        data = fig.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    assert {f.name for f in res.figures} == {"stability_map.png", "extreme.png"}
    report = res.report_path.read_text()
    for heading in ("## Verdicts", "## Predicted against observed critical dt", "## Sweep: largest stable dt",
                    "## Extreme cases", "## Conclusions"):
        assert heading in report
    assert "| integrator | stable | diverged | newton failed | rejected | work limit | error |" in report
    assert "| crush | Neo-Hookean |" in report


def test_resume_runs_nothing(study):
    out, res = study
    lines = (out / "results.jsonl").read_text().splitlines()
    again = st.run_stability_study(out, quick=True, executor="serial", progress=False,
                                   _case_filter=lambda c: c.id in _IDS)
    assert again.n_run == 0
    assert (out / "results.jsonl").read_text().splitlines() == lines
    assert [r["seconds"] for r in again.rows] == [r["seconds"] for r in res.rows]


# --- the verdicts against direct runs through the Python API --------------------------------


def _cantilever_model(body):
    """The sweep's scene, built here with the public API (fe.Model, fe.State.rest): a random
    velocity field (seed 0) with kinetic energy 1e-3 of the weight times the length (1 m)."""
    mesh = fe.beam_mesh(cells=(6, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=body, fixed="left", gravity=(0, 0, -9.81))
    v = fe.State.rest(model, velocity=np.random.default_rng(0).standard_normal((mesh.p.shape[1], 3))).v
    v = v * math.sqrt(1e-3 * model.total_mass * 9.81 * 1.0 / model.kinetic_energy(v))
    return model, fe.State.rest(model, velocity=model.to_vertices(v))


def test_explicit_divergence_agrees_with_a_direct_run(study):
    _, res = study
    row = _row(res, "sweep/SymplecticEuler/linear/E=1e+07/nu=0.3/dt=0.001")
    model, state = _cantilever_model(fe.ElasticBody(fe.LinearElastic(E=1e7, nu=0.3)))
    dt_crit = fe.critical_time_step(model, fe.SymplecticEuler())
    crit = _row(res, "critical/SymplecticEuler/linear/E=1e+07/nu=0.3")
    assert crit["dt_predicted"] == pytest.approx(dt_crit, rel=1e-9)
    assert 1.5 < 1e-3 / dt_crit < 2.0  # the run is well above the limit
    with pytest.raises(fe.Diverged) as err:
        fe.simulate(model, fe.SymplecticEuler(), 1e-3, steps=100, state=state, check_stability=False)
    assert row["verdict"] == "diverged" and row["step"] == err.value.step
    assert row["reason"] == err.value.reason
    stable = _row(res, "sweep/SymplecticEuler/linear/E=1e+07/nu=0.3/dt=1e-05")
    run = fe.simulate(model, fe.SymplecticEuler(), 1e-5, steps=100, state=state, check_stability=False)
    assert stable["verdict"] == "stable"
    assert stable["energy_final"] == pytest.approx(run.total[-1], rel=1e-12)


def test_implicit_stable_run_agrees_with_a_direct_run(study):
    _, res = study
    row = _row(res, "sweep/ImplicitEuler/linear/E=1e+07/nu=0.3/dt=0.0416667")
    model, state = _cantilever_model(fe.ElasticBody(fe.LinearElastic(E=1e7, nu=0.3)))
    run = fe.simulate(model, fe.ImplicitEuler(), 1 / 24, steps=100, state=state)
    assert row["verdict"] == "stable"
    # the same code on the same input: equal to round-off of the Newton solves' order of operations
    assert row["energy_final"] == pytest.approx(run.total[-1], rel=1e-9)
    assert row["energy_initial"] == pytest.approx(run.total[0], rel=1e-12)
    assert row["energy_drift_pct"] < 0  # implicit Euler dissipates


def test_extreme_crush_agrees_with_a_direct_run(study):
    _, res = study
    row = _row(res, "extreme/crush/ImplicitEuler/neohookean/dt=0.0416667")
    cube = fe.beam_mesh(length=0.1, width=0.1, height=0.1, cells=(2, 2, 2))
    model = fe.Model(cube, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="bottom",
                     driven={"top": fe.Translate((0, 0, -0.09), duration=0.2, release=0.25)})
    run = fe.simulate(model, fe.ImplicitEuler(), 1 / 24, t_end=0.5)
    V0 = fe.signed_volumes(cube)
    J = [fe.signed_volumes(fe.mesh_from_arrays(cube.p.T + u, cube.t.T, validate=False)) / V0
         for u in run.displacement]
    assert row["verdict"] == "stable"
    # the top face is held at 10 % of the height: det F ~ 0.1, and Neo-Hookean keeps it > 0
    assert row["min_J"] == pytest.approx(min(j.min() for j in J), rel=1e-9)
    assert 0.05 < row["min_J"] < 0.15
    assert row["t_reached"] == pytest.approx(run.times[-1])


def test_rejected_and_work_limit_rows(study):
    _, res = study
    rej = _row(res, "extreme/degenerate sliver/SymplecticEuler/neohookean/dt=auto")
    assert rej["verdict"] == "rejected" and rej["reason"].startswith("InvalidMesh")
    with pytest.raises(fe.InvalidMesh) as err:  # what fe.Model says of that mesh
        fe.Model(sc.sliver_mesh(1e-12), density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)))
    assert rej["reason"] == f"InvalidMesh: {err.value}"
    wl = _row(res, "sweep/ImplicitEuler/corotated/E=1000/nu=0.3/dt=0.01")
    assert wl["verdict"] == "work limit" and wl["step"] < 100
    assert f"(limit {st.WORK_LIMIT})" in wl["reason"]


def test_observed_critical_dt_brackets_the_prediction(study):
    """On the linear body fe.critical_time_step is exact (the highest mode of the lumped-mass
    problem, and each scheme's step map), so the observed limit must sit at the prediction,
    up to the 100-step horizon: a mode growing by rho per step is seen once rho^200 exceeds
    the energy bound over its share of the kick (~1e4, ln ~ 9).

    - symplectic Euler: rho - 1 ~ 2 sqrt(2 eps) at dt = (1 + eps) 2 / omega_max, so 0.27 %
      above (one bisection step) rho^200 ~ e^27: the bracket must close within one bisection
      step above the prediction;
    - RK4: rho - 1 ~ 7 eps near 2 sqrt(2) / omega_max, seen from eps ~ 9 / 1400 = 0.65 %: the
      bracket may sit up to ~1 % above the prediction, never below it.
    """
    _, res = study
    se = _row(res, "critical/SymplecticEuler/linear/E=1e+07/nu=0.3")
    step = 2 ** (1 / 2 ** st.BISECTIONS)
    assert se["verdict"] == "bracketed"
    assert se["dt_observed_hi"] / se["dt_observed_lo"] == pytest.approx(step, rel=1e-12)
    assert se["dt_observed_lo"] >= se["dt_predicted"]           # stable at the prediction
    assert se["ratio_hi"] <= step * (1 + 1e-12)                   # unstable one bisection step above
    assert se["h_omega_lo"] == pytest.approx(2.0, rel=1e-9)       # 2 / omega_max
    rk = _row(res, "critical/RK4/linear/E=1e+07/nu=0.3")
    assert rk["ratio_lo"] >= 1.0 and rk["ratio_hi"] <= 1.02
    assert rk["dt_predicted"] * rk["omega_max"] == pytest.approx(2 * math.sqrt(2), rel=1e-9)
    # the recorded runs: the first at the prediction, every later one within the bracket's history
    assert se["runs"][0][0] == se["dt_predicted"] and se["runs"][0][1] == "stable"
    assert len(se["runs"]) == 2 + st.BISECTIONS


def test_report_lists_errors_and_draws_no_false_conclusion(tmp_path):
    rows = [
        dict(id="a", kind="sweep", case="cantilever", integrator="ImplicitEuler", body="linear", E=1e7,
             nu=0.3, dt=1 / 24, status="ok", verdict="stable", step=None, min_J=0.99, energy_drift_pct=-1.0),
        dict(id="b", kind="sweep", case="cantilever", integrator="ImplicitEuler", body="linear", E=1e7,
             nu=0.3, dt=1e-2, status="error", error="ValueError: boom"),
    ]
    text = st.write_report(rows, tmp_path / "report.md").read_text()
    assert "**Errors (bugs):**" in text and "ValueError: boom" in text
    assert "stable at every dt of the sweep on 0 of 1" in text  # the error counts against it


def test_energy_drift_is_relative_to_the_energy_in_play():
    """RK4 near its limit on the 100 GPa spring beam loses most of the kick's 0.098 J in 100
    steps; the drift must say so (it once read -0.08 %: the scale was floored by the weight
    times the length, 98 J, a thousand times the energy in play)."""
    row = st.run_stability_case(dict(kind="sweep", case="cantilever", integrator="RK4", body="springs",
                                     E=1e11, nu=0.25, dt=1e-5, steps=100))
    assert row["verdict"] == "stable"
    lost = 1.0 - row["energy_final"] / row["energy_initial"]
    assert lost > 0.5  # measured 0.78: RK4's damping of the top modes at h omega near its limit
    # the stiff beam barely sags: the energy exchanged is the kick, S = max kinetic energy ~ 0.098 J
    assert row["energy_scale"] < 2 * row["energy_initial"]
    assert row["energy_drift_pct"] < -0.5 * 100 * lost


def test_report_setup_lists_the_grid_that_ran(tmp_path):
    """The setup names the E, nu and dt values of the rows, not the full study's grid (a quick
    report once claimed dt down to 1e-6 s and E = 1e5, 1e9 Pa that it never ran)."""
    rows = [dict(id=f"s{k}", kind="sweep", case="cantilever", integrator=integ, body="linear", E=1e7, nu=0.3,
                 dt=dt, status="ok", verdict="stable", step=None, min_J=0.99, energy_drift_pct=-1.0)
            for k, (integ, dt) in enumerate((("RK4", 1e-3), ("RK4", 1e-5), ("Newmark", 1 / 24)))]
    text = st.write_report(rows, tmp_path / "report.md", quick=True).read_text()
    assert "E in 1e+07 Pa at nu = 0.3" in text and "nu in none" in text
    assert "Explicit schemes at dt = 1e-03, 1e-05 s, implicit ones at 1/24 s." in text
    assert "1e-06" not in text and "implicit ones at none s." in text  # no extreme rows
