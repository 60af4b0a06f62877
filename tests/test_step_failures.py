"""Every step failure is honest: an error raised inside a step ends the run like a divergence.

Whatever raises inside ``integrator.step`` (a user motion, a linear solver
that gives up, a contact routine, numpy's LinAlgError) ends ``fe.simulate``
with a ``fe.StepFailed`` (a ``fe.Diverged``) carrying the step, the time, the
reason, the last good state and the frames so far, the original error as its
cause; a checkpoint of the last good step is written and a ``SeriesWriter``
finishes its series as "failed".
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.app.output import SeriesWriter
from fem_elastic.app.vtu import read_series

DT = 0.01
FAIL_AT = 3  # the step whose computation raises: it starts at t = 0.03 s


def _beam(**options):
    return fe.Model(fe.beam_mesh(cells=(3, 1, 1)), density=1000.0,
                    body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left", **options)


def _motion_that_raises():
    def pull(X, t):
        if t > (FAIL_AT + 0.5) * DT:
            raise ValueError("the motion table ends at 0.035 s")
        return np.outer(np.ones(len(X)), (0.05 * t, 0.0, 0.0))

    return _beam(driven={"right": fe.Prescribed(pull)}), fe.ImplicitEuler(), ValueError


class _GivesUp:
    """A linear solver that gives up at its n-th solve (as an iterative solver can)."""

    def __init__(self, n, error):
        self.calls, self.n, self.error = 0, n, error

    def solve(self, A, b, near_null=None):
        self.calls += 1
        if self.calls >= self.n:
            raise self.error
        return fe.DirectSolver().solve(A, b, near_null)


def _solver_that_gives_up(error):
    def make():
        counting = _GivesUp(np.inf, error)  # how many solves the first FAIL_AT steps take
        fe.simulate(_beam(gravity=(0.0, 0.0, -9.81)), fe.ImplicitEuler(linear_solver=counting), DT,
                    steps=FAIL_AT)
        integrator = fe.ImplicitEuler(linear_solver=_GivesUp(counting.calls + 1, error))
        return _beam(gravity=(0.0, 0.0, -9.81)), integrator, type(error)

    return make


class _BrokenGround(fe.Ground):
    """An impulse ground whose response raises on its FAIL_AT + 1-th call (a contact library's error)."""

    calls = 0

    def respond(self, x, v, nodal_mass=None):
        type(self).calls += 1
        if type(self).calls > FAIL_AT:
            raise RuntimeError("contact routine: no convergence in the friction cone")
        return super().respond(x, v, nodal_mass)


def _contact_that_raises():
    _BrokenGround.calls = 0
    model = _beam(gravity=(0.0, 0.0, -9.81), ground=_BrokenGround(z=-1.0, method="impulse"))
    return model, fe.SymplecticEuler(), RuntimeError


CASES = {
    "a user motion that raises": _motion_that_raises,
    "a linear solver that gives up": _solver_that_gives_up(fe.LinearSolverFailed("AMG-CG stalled")),
    "numpy LinAlgError in a solve": _solver_that_gives_up(np.linalg.LinAlgError("Singular matrix")),
    "a contact routine that raises": _contact_that_raises,
}


@pytest.mark.parametrize("case", CASES)
def test_a_step_that_raises_ends_the_run_with_everything_kept(case, tmp_path):
    model, integrator, cause = CASES[case]()
    dt = DT if integrator.name != "SymplecticEuler" else 1e-4
    writer = SeriesWriter(model, tmp_path / "run", every=1, n_steps=8)
    writer.write_state(fe.State.rest(model))
    with pytest.raises(fe.StepFailed) as info:
        fe.simulate(model, integrator, dt, steps=8, check_stability=False, observers=[writer],
                    checkpoint_dir=tmp_path / "ck")
    err = info.value
    assert isinstance(err, fe.Diverged)  # `except fe.Diverged` keeps catching every failed run
    assert isinstance(err.__cause__, cause) and err.original is err.__cause__
    assert err.step == FAIL_AT and err.time == pytest.approx(FAIL_AT * dt, rel=1e-12)
    assert err.reason.startswith(cause.__name__) and f"step {FAIL_AT}" in str(err)
    assert err.last_good_state.t == err.time and np.isfinite(err.last_good_state.x).all()
    traj = err.trajectory  # every step recorded: the initial frame and FAIL_AT more
    assert traj.times.size == FAIL_AT + 1 and traj.final_state is err.last_good_state
    assert "failed at step" in traj.message
    # the checkpoint of the last good step
    ck = fe.load_checkpoint(tmp_path / "ck")
    assert ck.step == FAIL_AT and np.array_equal(ck.state.x, err.last_good_state.x)
    # the series stays readable and its summary says what happened
    assert writer.finished
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["status"] == "failed" and summary["failed_step"] == FAIL_AT
    assert summary["reason"] == err.reason
    series = read_series(tmp_path / "run")
    assert np.array_equal(series.times, traj.times)


def test_ctrl_c_and_system_exit_are_not_step_failures():
    def stop(X, t):
        if t > 0.015:
            raise KeyboardInterrupt
        return np.zeros_like(X)

    model = _beam(driven={"right": fe.Prescribed(stop)})
    with pytest.raises(KeyboardInterrupt):
        fe.simulate(model, fe.ImplicitEuler(), DT, steps=4)


class _OldObserver:
    """An observer written before ``on_failure`` existed (no Observer base)."""

    def __init__(self):
        self.seen = []

    def on_start(self, run):
        pass

    def on_step(self, run, event):
        self.seen.append(event.k)

    def on_finish(self, run):
        pass

    def on_interrupt(self, run):
        pass

    def on_close(self, run):
        self.closed = True


def test_observers_without_on_failure_still_work_and_a_failing_hook_hides_nothing(tmp_path):
    model, integrator, _ = _motion_that_raises()

    class Broken(fe.dynamics.Observer):
        def on_failure(self, run, error):
            raise OSError("disk full")

    old = _OldObserver()
    with pytest.raises(fe.StepFailed) as info:
        fe.simulate(model, integrator, DT, steps=8, observers=[old, Broken()])
    assert isinstance(info.value.__cause__, ValueError)  # not the hook's OSError
    assert old.seen == list(range(FAIL_AT)) and old.closed


def test_a_divergence_also_writes_the_checkpoint_of_the_last_good_step(tmp_path):
    model = _beam(gravity=(0.0, 0.0, -9.81))
    with pytest.raises(fe.Diverged) as info:  # symplectic Euler far above its stable step
        fe.simulate(model, fe.SymplecticEuler(), 0.01, steps=200, check_stability=False,
                    checkpoint_dir=tmp_path / "ck")
    err = info.value
    assert not isinstance(err, fe.StepFailed)
    ck = fe.load_checkpoint(tmp_path / "ck")
    assert ck.step == err.step and np.array_equal(ck.state.x, err.last_good_state.x)
