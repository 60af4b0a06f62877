"""Step cut-back: an implicit step whose Newton solve fails is halved and retried, to a limit.

The scene: a soft Neo-Hookean cantilever (E = 100 kPa) released under gravity with a large
step (0.2 s, a third of its first period). From rest Newton needs 7 iterations at 0.2 s, 4 at
0.1 s: with ``max_iter=5`` the full step fails and both halves converge; with ``max_iter=4``
the second half (from a moving state) fails again and is taken as two quarters.
"""

import numpy as np
import pytest

import fem_elastic as fe

DT = 0.2


@pytest.fixture(scope="module")
def sagging():
    return fe.Model(fe.beam_mesh(cells=(6, 1, 1)), density=1000.0,
                    body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left",
                    gravity=(0.0, 0.0, -9.81))


@pytest.mark.parametrize("max_iter, failed, pieces", [
    (5, [(0.0, DT)], (DT / 2, DT / 2)),  # the full step fails, both halves converge
    (4, [(0.0, DT), (DT / 2, DT / 2)], (DT / 2, DT / 4, DT / 4)),  # the second half is halved again
])
def test_a_failed_step_is_halved_recorded_and_equal_to_the_manual_halves(sagging, max_iter, failed, pieces):
    model = sagging
    s0 = fe.State.rest(model)
    ie = fe.ImplicitEuler(max_iter=max_iter)
    s = ie.step(model, s0, DT)
    st = ie.last_stats
    # every failed attempt: where it started (s), the step that failed (s), why
    assert [c[:2] for c in st.cuts] == failed
    prefix = f"Newton did not converge (no convergence in {max_iter} iterations"
    assert all(c[2].startswith(prefix) for c in st.cuts)
    assert st.dt_cuts == len(st.cuts) == len(failed)
    assert st.substeps == len(pieces)
    assert s.t == DT

    # the same sub-steps by hand, each converging without a cut: the same state, bit for bit
    # (each attempt is a pure function of its start state and step)
    by_hand = fe.ImplicitEuler(max_iter=max_iter)
    s1 = s0
    for h in pieces:
        s1 = by_hand.step(model, s1, h)
        assert by_hand.last_stats.dt_cuts == 0 and by_hand.last_stats.cuts == []
    assert np.array_equal(s1.x, s.x) and np.array_equal(s1.v, s.v) and s1.t == s.t


@pytest.mark.parametrize("max_dt_cuts", [0, 1])
def test_when_the_cuts_run_out_the_step_diverges_with_its_reason(sagging, max_dt_cuts):
    model = sagging
    s0 = fe.State.rest(model)
    ie = fe.ImplicitEuler(max_iter=4, max_dt_cuts=max_dt_cuts)
    with pytest.raises(fe.Diverged) as info:
        ie.step(model, s0, DT)
    err = info.value
    assert err.reason.startswith("Newton did not converge")
    assert err.time == 0.0 and err.last_good_state is s0
    assert f"even after halving dt {max_dt_cuts} times (to {DT / 2 ** max_dt_cuts:.3g} s)" in str(err)
    assert "more Newton iterations" in str(err)  # the way out
    # the cuts made before giving up: the full step (when one was allowed)
    assert ie.last_stats.dt_cuts == max_dt_cuts
    assert [c[:2] for c in ie.last_stats.cuts[:max_dt_cuts]] == [(0.0, DT)][:max_dt_cuts]
    # ... and the attempt that gave up, at the smallest step allowed
    assert ie.last_stats.cuts[-1][1] == DT / 2 ** max_dt_cuts
    assert ie.last_stats.cuts[-1][2] == err.reason


def test_simulate_reports_the_cuts_of_an_implicit_run(sagging):
    model = sagging
    run = fe.simulate(model, fe.ImplicitEuler(max_iter=4), DT, steps=3)
    first = [c for c in run.cuts if c["step"] == 0]
    assert [(c["t"], c["dt"]) for c in first] == [(0.0, DT), (DT / 2, DT / 2)]
    assert all(c["reason"].startswith("Newton did not converge") for c in run.cuts)
    cut_steps = sorted({c["step"] for c in run.cuts})
    assert run.step_stats["dt_cuts"][0] == 2 and run.step_stats["substeps"][0] == 3
    assert list(np.flatnonzero(run.step_stats["dt_cuts"])) == cut_steps
    assert all(c["t"] >= c["step"] * DT - 1e-12 for c in run.cuts)  # within their own step
    summary = run.summary()
    assert summary["steps_cut"] == len(cut_steps) >= 1
    assert summary["cuts"][0] == {"step": 0, "t": 0.0, "dt": DT, "reason": run.cuts[0]["reason"]}


def test_simulate_reports_the_cuts_of_a_substepped_explicit_run(sagging):
    """A kicked corner makes the first sub-stepped attempt invert an element; simulate lists it."""
    model = sagging
    X = model.X.reshape(-1, 3)
    v = np.zeros_like(X)
    v[np.argmax(X.sum(axis=1)), 2] = -20.0
    dt = 3.0 * fe.critical_time_step(model, fe.SymplecticEuler())
    run = fe.simulate(model, fe.SymplecticEuler(substep=True), dt, steps=3,
                      state=fe.State.rest(model, velocity=v))
    assert run.cuts and run.cuts[0]["step"] == 0 and run.cuts[0]["t"] == 0.0
    assert run.cuts[0]["dt"] == dt / 4  # ceil(3 / 0.8) sub-steps tried first
    assert "finite" in run.cuts[0]["reason"]
    assert run.step_stats["substeps"][0] == 4 * 2 ** run.step_stats["dt_cuts"][0]
    assert run.summary()["steps_cut"] == int(np.count_nonzero(run.step_stats["dt_cuts"])) >= 1


def test_a_run_that_runs_out_of_cuts_carries_them_in_its_error(sagging):
    model = sagging
    with pytest.raises(fe.Diverged) as info:
        fe.simulate(model, fe.ImplicitEuler(max_iter=4, max_dt_cuts=1), DT, steps=2)
    err = info.value
    assert err.step == 0 and err.reason.startswith("Newton did not converge")
    assert [(c["step"], c["t"], c["dt"]) for c in err.trajectory.cuts][:1] == [(0, 0.0, DT)]
    assert err.trajectory.cuts[-1]["dt"] == DT / 2 and err.trajectory.cuts[-1]["step"] == 0
