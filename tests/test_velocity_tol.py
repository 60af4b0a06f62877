"""IPC's step rule for Newton: ``newton_minimize(step_tol=...)``, ``fe.ImplicitEuler(velocity_tol=...)``.

Newton also stops after a whole step (not cut by the line search or the CCD) that moves no DOF
by more than ``step_tol`` (an implicit step passes ``velocity_tol * h``). In Newton's quadratic
regime the error left after a step of size s is of order s^2 / (the problem's length scale), so
the answer lies within ``step_tol`` of the force-converged one.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import fem_elastic as fe
from fem_elastic.solvers.newton import newton_minimize
from test_newton_saddle import _energy as saddle_energy  # x^2/2 - y^2/2 + y^4/4, minimiser y = 1
from test_newton_saddle import _linearize as saddle_linearize  # with IPC's clamp, c = 5

TARGET = np.array([0.3, -0.2, 0.5])  # the minimiser of the model problem


def _energy(x):
    r = x - TARGET
    return float(np.sum(0.5 * r * r + 0.25 * r ** 4))


def _linearize(x, project):
    r = x - TARGET
    return r + r ** 3, sp.csr_matrix(np.diag(1.0 + 3.0 * r * r))


def _solve(step_tol=0.0, max_step=None):
    return newton_minimize(_energy, _linearize, TARGET + 1.0, np.ones(3, dtype=bool), rtol=1e-14,
                           g_scale=1.0, max_iter=50, linear_solver="direct", max_step=max_step,
                           step_tol=step_tol)


def test_a_full_step_below_step_tol_ends_newton_within_the_tolerance():
    strict, loose = _solve(), _solve(step_tol=1e-2)
    assert strict.converged and loose.converged
    assert "step_tol" in loose.message and "step_tol" not in strict.message
    assert loose.iterations < strict.iterations, (loose.iterations, strict.iterations)
    # the last step moved 5.5e-3 <= 1e-2, and Newton squares the error on this unit-curvature
    # problem: what is left is 3.3e-7, well inside the tolerance
    assert np.abs(loose.x - TARGET).max() <= 1e-2
    np.testing.assert_allclose(strict.x, TARGET, atol=1e-12)


def test_a_step_the_ccd_cut_never_counts_as_converged():
    """A short step because a contact blocks it is not convergence, however loose step_tol is."""
    bounds = iter([0.5, 0.5, 0.5])  # the CCD cuts the first three steps to half

    def max_step(x, dx):
        return next(bounds, 1.0)

    res = _solve(step_tol=1e6, max_step=max_step)
    assert res.converged and "step_tol" in res.message
    # three cut steps (projected), one whole projected step, then the first whole step on the
    # exact tangent ends it
    assert res.iterations == 5
    # uncut: the first step is projected (it never counts), the second, exact, ends it
    assert _solve(step_tol=1e6, max_step=lambda x, dx: 1.0).iterations == 2


@pytest.mark.parametrize("project", [True, False])
def test_a_small_step_at_a_saddle_does_not_end_newton(project):
    """The saddle model of tests/test_newton_saddle.py. Beside the saddle at the origin every
    step is small (1e-4 m here), but Newton is not converged: projected steps are small because
    the clamp hides the negative curvature, exact ones because the tangent is indefinite (no
    descent: steepest descent). Neither may end the solve; it goes on to the minimiser y = 1."""
    res = newton_minimize(saddle_energy, saddle_linearize, np.array([0.0, 1e-4]),
                          np.ones(2, dtype=bool), rtol=1e-10, g_scale=1.0, max_iter=200,
                          linear_solver="direct", project=project, step_tol=1e-3)
    assert res.converged
    # within step_tol of the minimiser (0, 1); a stop at the saddle would leave y ~ 1e-4
    np.testing.assert_allclose(res.x, [0.0, 1.0], atol=1e-3)


def _beam():
    return fe.Model(fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(8, 1, 1)), density=1000.0,
                    body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left",
                    gravity=(0.0, 0.0, -9.81))


def test_implicit_euler_with_velocity_tol_takes_fewer_iterations_and_stays_within_it():
    # h = 0.05 s: the sagging beam takes 3-4 Newton iterations a step (2 at h = 0.01 s, where the
    # force rule's last test costs a gradient only and the rule has nothing to save)
    model, h, v_tol = _beam(), 0.05, 1e-3
    strict, loose = fe.ImplicitEuler(), fe.ImplicitEuler(velocity_tol=v_tol)
    state = fe.State.rest(model)
    its_strict = its_loose = 0
    for _ in range(4):  # the beam sags: each step a few Newton iterations
        a, b = strict.step(model, state, h), loose.step(model, state, h)
        its_strict += strict.last_stats.newton_iterations
        its_loose += loose.last_stats.newton_iterations
        # from the same state: the rule's answer is within velocity_tol * h of the strict one
        # (the last whole step moved <= 5e-5 m; what it leaves is quadratically smaller)
        assert np.abs(b.x - a.x).max() <= v_tol * h
        state = a
    assert its_loose < its_strict, (its_loose, its_strict)


@pytest.mark.parametrize("bad", [-1e-3, float("nan"), float("inf"), True, "1e-3"])
def test_bad_velocity_tol_is_refused(bad):
    with pytest.raises(fe.InvalidParameter, match="velocity_tol must be a finite number >= 0"):
        fe.ImplicitEuler(velocity_tol=bad)


@pytest.mark.parametrize("cls", [fe.Newmark, fe.Trapezoid])
def test_newmark_and_trapezoid_take_velocity_tol_too(cls):
    """Their end velocity is 2 (x1 - x0) / h - v0: the rule's step is velocity_tol * h / 2, so
    the velocity, not only the position, stays within velocity_tol of the strict answer."""
    # h = 0.1 s: 4-5 Newton iterations a step (at 0.05 s the rule, on the exact tangent only,
    # saves none)
    model, h, v_tol = _beam(), 0.1, 1e-3
    loose, strict = cls(velocity_tol=v_tol), cls()
    assert loose.velocity_tol == v_tol
    state, its_loose, its_strict = fe.State.rest(model), 0, 0
    for _ in range(4):
        out, ref = loose.step(model, state, h), strict.step(model, state, h)
        its_loose += loose.last_stats.newton_iterations
        its_strict += strict.last_stats.newton_iterations
        assert np.abs(out.v - ref.v).max() <= v_tol
        state = ref
    assert its_loose < its_strict, (its_loose, its_strict)


def test_velocity_tol_is_refused_with_the_distributed_newton():
    pytest.importorskip("petsc4py")
    with pytest.raises(fe.InvalidParameter, match="solve serially"):
        fe.ImplicitEuler(velocity_tol=1e-3, linear_solver=fe.PETScSolver())


def test_a_scene_sets_velocity_tol():
    from fem_elastic.app.scene import load_scene

    scene = load_scene(Path(__file__).resolve().parent.parent / "scenes" / "two_bodies.toml")
    scene.spec["integrator"]["velocity_tol"] = 2e-3
    assert scene.build()[0].integrator.velocity_tol == 2e-3


def test_the_two_body_drop_with_velocity_tol_never_intersects_and_iterates_less():
    """IPC's rule on the IPC scene: every step stays intersection-free (the CCD bounds every
    step, and a cut step never ends Newton), with fewer Newton iterations than the force rule."""
    pytest.importorskip("ipctk")
    from fem_elastic.app.scene import load_scene

    totals = []
    for ie in (fe.ImplicitEuler(max_iter=200), fe.ImplicitEuler(max_iter=200, velocity_tol=1e-3)):
        # a fresh build each: the contact's state starts as the scene starts it
        run = load_scene(Path(__file__).resolve().parent.parent / "scenes" / "two_bodies.toml").build()[0]
        state, its, touched = run.state, 0, False
        for _ in range(20):  # 0.2 s: the flight, the impact at 0.13 s and the first rebound
            state = ie.step(run.model, state, run.dt)
            its += ie.last_stats.newton_iterations
            assert not run.model.contact.has_intersections(state.x)
            touched |= run.model.contact.diagnostics(state.x)["active_contacts"] > 0
        assert touched  # the steps reach the contact
        totals.append(its)
    assert totals[1] < totals[0], totals
