"""The trapezoidal rule (fe.Trapezoid): order, energy, stability, its relation to Newmark,
cut-back, what it remembers, and a resumed run bit for bit."""

import math

import numpy as np
import pytest
import scipy.linalg as sl
from test_checkpoint import _beam, _kicked, _StopAt, assert_same_run

import fem_elastic as fe
from fem_elastic.app.scene_schema import integrator_options, make_integrator
from one_mode import in_mode as _in_mode
from one_mode import modal as _modal
from one_mode import one_mode as _one_mode

TR = fe.Trapezoid


# -- order of accuracy ---------------------------------------------------------------------------
@pytest.mark.parametrize("alpha", [0.0, 2.0])
def test_second_order_on_one_mode_against_the_closed_form(alpha):
    model, w, phi = _one_mode(alpha)
    T = 2 * math.pi / w  # one period of the first mode (0.66 s)
    zeta = alpha / (2 * w)  # 0.105 with alpha = 2
    q0 = 0.01 / np.abs(phi).max()  # 1 cm at the tip
    exact = sl.expm(np.array([[0, 1], [-w * w, -2 * zeta * w]]) * T) @ [q0, 0.0]
    s0 = _in_mode(model, phi, q0, 0.0)
    dts = [T / 20, T / 40, T / 80]  # 16, 8, 4 times the explicit limit
    errors = []
    for dt in dts:
        q, v = _modal(model, phi, fe.simulate(model, TR(), dt, steps=round(T / dt), state=s0).final_state)
        errors.append(math.hypot(q - exact[0], (v - exact[1]) / w) / q0)
    slope = np.polyfit(np.log(dts), np.log(errors), 1)[0]
    # measured 1.990 (undamped: phase error (w h)^2 / 12 per radian, 5 % at T / 20) and 1.997
    # (damped); the next term of the error is O(h^4), a 2 % shift of a fit over these steps
    assert abs(slope - 2.0) < 0.05, (errors, slope)
    assert errors[-1] < 5e-3


def test_second_order_against_a_fine_run_on_a_sagging_beam():
    """Neo-Hookean, large sag: the order in the nonlinear regime, against the scheme's own fine run."""
    model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left", gravity=(0, 0, -9.81))
    T, n_ref = 0.1, 160
    ref = fe.simulate(model, TR(), T / n_ref, steps=n_ref, record_every=n_ref).final_state
    ns = (10, 20, 40)
    errors = []
    for n in ns:
        s = fe.simulate(model, TR(), T / n, steps=n, record_every=n).final_state
        errors.append(np.linalg.norm(s.x - ref.x) / np.linalg.norm(ref.x - model.X))
    slope = -np.polyfit(np.log(ns), np.log(errors), 1)[0]
    # measured 2.049 (errors 0.16 % .. 0.009 %): the reference's own error, (n / 160)^2 of each
    # (the same direction), lowers the finest one by 1/16 and tilts the fit by +0.046 (2.008
    # against a reference at n = 640); higher-order terms tilt it by less
    assert abs(slope - 2.0) < 0.1, (errors, slope)


# -- energy and stability ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def released():
    """A linear cantilever bent by a tip load, then released (mostly its first mode)."""
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(6, 1, 1))
    body = fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3))
    static = fe.solve_static(fe.Model(mesh, density=1000.0, body=body, fixed="left",
                                      traction={"right": (0, 0, -2e3)}))
    model = fe.Model(mesh, density=1000.0, body=body, fixed="left")
    return model, fe.State(static.x, np.zeros_like(static.x))


@pytest.mark.parametrize("factor", [3.0, 50.0, 1000.0])
def test_energy_conserved_on_a_linear_body_per_step_to_newtons_tolerance(released, factor):
    """dE of a step is exactly 1/2 R . (x1 - x0), R = 2/h M (v1 - v0) - f0 - f1 the residual of
    the trapezoid equations; Newton makes R small, so dE is, at any dt (A-stability)."""
    model, s = released
    free, m = model.free, model.lumped_mass
    h = factor * fe.critical_time_step(model, fe.SymplecticEuler())
    e0 = model.energy(s.x)
    tr = TR()
    for _ in range(20):
        s1 = tr.step(model, s, h)
        R = (2.0 / h) * m * (s1.v - s.v) + model.gradient(s.x) + model.gradient(s1.x)
        dE = model.energy(s1.x) + model.kinetic_energy(s1.v) - model.energy(s.x) - model.kinetic_energy(s.v)
        # the identity holds to round-off (measured 3e-15 of E)
        assert abs(dE - 0.5 * R[free] @ (s1.x - s.x)[free]) < 1e-12 * e0
        # Newton's tolerance: rtol 1e-8 of the force scale (10 N here: the force at x0); one
        # iteration on a linear body leaves the direct solve's round-off, measured 3e-11 N
        assert np.linalg.norm(R[free]) < 1e-8 * np.linalg.norm(model.gradient(s.x)[free]) + 1e-9
        # so the energy per step: measured 3e-15 .. 3e-12 of E
        assert abs(dE) < 1e-10 * e0
        s = s1
    assert tr.last_stats.newton_iterations == 1


@pytest.mark.parametrize("factor", [100.0, 1000.0])
def test_stable_far_above_the_explicit_limit_on_a_nonlinear_body(factor):
    """A small-strain Neo-Hookean cantilever under gravity (3 cm sag): 40 steps of 100 and 1000
    times the explicit limit (0.27 and 2.7 periods of the first mode a step) stay bounded."""
    model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e7, nu=0.3)), fixed="left", gravity=(0, 0, -9.81))
    dt = factor * fe.critical_time_step(model, fe.SymplecticEuler())
    run = fe.simulate(model, TR(), dt, steps=40)
    mgL = model.lumped_mass.sum() / 3.0 * 9.81 * 1.0
    # measured |KE + Pi| <= 1.1e-4 mgL (from 0 at rest): a nonlinear body is not conserved exactly
    assert np.abs(run.total).max() < 1e-3 * mgL
    assert 0.02 < -run.displacement[:, :, 2].min() < 0.07  # twice the static sag at most (3 cm)
    assert run.step_stats["dt_cuts"].sum() == 0


def test_step_matrix_is_the_observed_amplification_of_a_damped_mode():
    """One step of the top mode (zeta = 0.026) at 50 times the explicit limit, against step_matrix."""
    alpha = 50.0
    model, w, phi = _one_mode(alpha, mode=-1)
    h = 50 * 2.0 / w
    q0, v0 = 1e-4, -0.2
    tr = TR(linear_solver=fe.DirectSolver())
    s1 = tr.step(model, _in_mode(model, phi, q0, v0), h)
    expected = tr.step_matrix(h, w, alpha / (2 * w)) @ [q0, v0]
    # Newton's residual (rtol 1e-8) and the round-off of a 48-DOF solve: measured 4e-14 relative
    np.testing.assert_allclose(_modal(model, phi, s1), expected, rtol=1e-9, atol=1e-14)
    rho = max(abs(np.linalg.eigvals(tr.step_matrix(h, w, 0.0))))
    assert rho == pytest.approx(1.0, abs=1e-12)  # undamped: no amplitude change at any h
    assert fe.critical_time_step(model, tr) == math.inf


def test_second_order_with_stiffness_proportional_damping_where_newmark_is_not():
    """beta damping of a sagging (rotating) body: C depends on the configuration. The trapezoid
    rule freezes it at the predicted midpoint, Newmark at the start of the step (and carries an
    acceleration with the previous step's C): second order against first, at this h."""
    model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left",
                     gravity=(0, 0, -9.81), damping=fe.Rayleigh(beta=0.05))
    T, n_ref, ns = 0.4, 80, (5, 10, 20)
    slopes, finest = {}, {}
    for cls in (TR, fe.Newmark):
        ref = fe.simulate(model, cls(), T / n_ref, steps=n_ref, record_every=n_ref).final_state
        errors = []
        for n in ns:
            s = fe.simulate(model, cls(), T / n, steps=n, record_every=n).final_state
            errors.append(np.linalg.norm(s.x - ref.x) / np.linalg.norm(ref.x - model.X))
        slopes[cls], finest[cls] = -np.polyfit(np.log(ns), np.log(errors), 1)[0], errors[-1]
    # measured 2.14 (the reference's own error, (n / 80)^2 of each, tilts it by +0.1; steps of
    # T / 10 .. T / 40 against n = 320 give 2.03) and 1.32 for Newmark (1.46 there), whose error
    # at T / 20 is 18 x larger
    assert abs(slopes[TR] - 2.0) < 0.25, slopes
    assert slopes[fe.Newmark] < 1.6 and finest[fe.Newmark] > 5 * finest[TR], (slopes, finest)


# -- not a re-label of Newmark -----------------------------------------------------------------
def test_same_motion_as_newmark_on_a_linear_body_both_conserving_energy(released):
    """In exact arithmetic the two are the same map when Newmark's a = M^-1 f (the module notes)."""
    model, s0 = released
    dt = 20 * fe.critical_time_step(model, fe.SymplecticEuler())
    tr = fe.simulate(model, TR(), dt, steps=30, state=s0)
    nm = fe.simulate(model, fe.Newmark(), dt, steps=30, state=s0)
    e0 = tr.total[0]
    # measured 7e-13 and 2e-13 of E over 30 steps (one Newton iteration each: the solve's round-off)
    np.testing.assert_allclose(tr.total, e0, rtol=1e-9)
    np.testing.assert_allclose(nm.total, e0, rtol=1e-9)
    # the round-off of the two ways of computing the same map: measured 3e-14 m of 0.12 m
    assert np.abs(tr.displacement - nm.displacement).max() < 1e-9 * np.abs(tr.displacement).max()


def test_a_map_of_x_and_v_where_newmark_carries_an_acceleration():
    """A loose Newton tolerance on a nonlinear body: the trapezoid's step from a State rebuilt
    from (x, v) is its continuing step bit for bit; Newmark's is not, because its remembered
    acceleration differs from M^-1 f(x, v) by Newton's residual."""
    model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left", gravity=(0, 0, -9.81))
    for cls, same in ((TR, True), (fe.Newmark, False)):
        integ = cls(rtol=1e-3)
        s = fe.State.rest(model)
        for _ in range(3):
            s = integ.step(model, s, 0.02)
        cont = integ.step(model, s, 0.02)
        rebuilt = cls(rtol=1e-3).step(model, fe.State(s.x.copy(), s.v.copy(), s.t), 0.02)
        assert (np.array_equal(cont.x, rebuilt.x) and np.array_equal(cont.v, rebuilt.v)) is same, cls
    a_kept = integ.acceleration(model, cont)  # Newmark's, remembered for the state it returned
    free = model.free
    a_forces = -model.gradient(cont.x)[free] / model.lumped_mass[free]
    # they differ by M^-1 times Newton's residual (rtol 1e-3 of the step's force scale)
    diff = np.abs(a_kept[free] - a_forces).max()
    assert 0.0 < diff < 1e-2 * np.abs(a_forces).max()


# -- cut-back ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sagging():
    return fe.Model(fe.beam_mesh(cells=(6, 1, 1)), density=1000.0,
                    body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left",
                    gravity=(0.0, 0.0, -9.81))


def test_a_failed_newton_solve_is_halved_recorded_and_equal_to_the_manual_halves(sagging):
    """From rest Newton needs 5 iterations at 0.2 s and 4 at 0.1 s: max_iter=4 fails the full
    step once and takes two halves."""
    model, DT = sagging, 0.2
    s0 = fe.State.rest(model)
    tr = TR(max_iter=4)
    s = tr.step(model, s0, DT)
    st = tr.last_stats
    assert [c[:2] for c in st.cuts] == [(0.0, DT)]
    assert st.cuts[0][2].startswith("Newton did not converge (no convergence in 4 iterations")
    assert st.dt_cuts == 1 and st.substeps == 2 and s.t == DT
    by_hand, s1 = TR(max_iter=4), s0
    for _ in range(2):
        s1 = by_hand.step(model, s1, DT / 2)
        assert by_hand.last_stats.cuts == []
    assert np.array_equal(s1.x, s.x) and np.array_equal(s1.v, s.v)
    # every Newton iteration, failed ones included, evaluates the force twice (once with the
    # Hessian, once alone to test the iterate); the force at x0, kept through the failed
    # attempt, serves the retry, and the end of the first half starts the second: one more
    assert st.gradient_evaluations == 2 * st.newton_iterations + 1
    with pytest.raises(fe.Diverged, match="even after halving dt 0 times"):
        TR(max_iter=4, max_dt_cuts=0).step(model, s0, DT)
    run = fe.simulate(model, TR(max_iter=4), DT, steps=2)
    assert run.cuts[0]["step"] == 0 and run.cuts[0]["dt"] == DT and run.step_stats["dt_cuts"][0] == 1


# -- what it remembers: the force at the end of the step ---------------------------------------
def test_the_force_at_the_end_of_a_step_starts_the_next(sagging):
    model = sagging
    tr = TR()
    s = tr.step(model, fe.State.rest(model), 0.01)
    first = tr.last_stats
    s = tr.step(model, s, 0.01)
    second = tr.last_stats
    # Newton's iterations each evaluate the force once (with the Hessian or alone, to test the
    # iterate); the first step also evaluates it at x0, the next ones take it from the last
    assert first.gradient_evaluations == 2 * first.newton_iterations + 1
    assert second.gradient_evaluations == 2 * second.newton_iterations
    saved = tr.checkpoint_state(s)
    assert sorted(saved) == ["gradient"] and np.array_equal(saved["gradient"], model.gradient(s.x))
    assert tr.checkpoint_state(fe.State(s.x, s.v, s.t)) == {}  # of another state object: nothing
    other = TR()
    other.restore_state(s, {k: np.array(v) for k, v in saved.items()})
    a, b = tr.step(model, s, 0.01), other.step(model, s, 0.01)
    assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)
    assert tr.last_stats.gradient_evaluations == other.last_stats.gradient_evaluations
    other.restore_state(s, {})  # a checkpoint without it: evaluated again, the same bits
    c = other.step(model, s, 0.01)
    assert np.array_equal(a.x, c.x) and other.last_stats.gradient_evaluations == tr.last_stats.gradient_evaluations + 1
    with pytest.raises(fe.InvalidParameter, match="another integrator"):
        TR().restore_state(s, {"acceleration": np.zeros(model.ndofs)})  # Newmark's
    with pytest.raises(fe.InvalidParameter, match="damaged"):
        TR().restore_state(s, {"gradient": np.zeros(3)})
    with pytest.raises(fe.InvalidParameter, match="damaged"):
        TR().restore_state(s, {"gradient": np.full(model.ndofs, np.nan)})


def test_an_impulse_contact_moves_the_end_positions_so_the_force_is_evaluated_afresh():
    model = _beam(fe.Corotated, gravity=(0, 0, -9.81), ground=fe.Ground(z=-0.06, method="impulse"))
    tr, s = TR(), fe.State.rest(model)
    for k in range(12):  # falls onto the ground at step ~7
        s_prev = s
        s = tr.step(model, s, 0.02)
        rebuilt = TR().step(model, fe.State(s_prev.x.copy(), s_prev.v.copy(), s_prev.t), 0.02)
        assert np.array_equal(s.x, rebuilt.x) and np.array_equal(s.v, rebuilt.v), k
    assert s.x[2::3].min() >= -0.06 - 1e-12


# -- resume bit for bit ------------------------------------------------------------------------
CASES = {
    "Neo-Hookean P1, gravity": (lambda: _beam(gravity=(0, 0, -9.81)), 0.02, None),
    "StVK P2, kicked, damped": (lambda: _beam(fe.StVK, order=2, damping=fe.Rayleigh(0.5, 1e-3)), 0.02, _kicked),
    "twisted end (driven)": (
        lambda: fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
                         body=fe.ElasticBody(fe.NeoHookean(E=2e5, nu=0.3)), fixed="left",
                         driven={"right": fe.Twist(np.pi / 4, duration=0.1, release=0.2)}), 0.02, None),
}


@pytest.mark.parametrize("case", list(CASES))
def test_resumed_run_is_bit_for_bit_the_uninterrupted_one(tmp_path, case):
    make_model, dt, initial = CASES[case]
    model = make_model()
    state = initial(model) if initial else fe.State.rest(model)
    steps = 14
    full = fe.simulate(model, TR(), dt, steps=steps, state=state, record_every=2)
    d = tmp_path / "ck"
    with pytest.raises(KeyboardInterrupt):
        fe.simulate(model, TR(), dt, steps=steps, state=state, record_every=2, checkpoint_dir=d,
                    callback=_StopAt(8))
    assert "gradient" in fe.load_checkpoint(d).integrator_state
    resumed = fe.simulate(make_model(), TR(), dt, steps=steps, state=state, record_every=2,
                          checkpoint_dir=d, resume=True)
    assert resumed.resumed_from_step == 8
    assert_same_run(full, resumed)


# -- scene files -------------------------------------------------------------------------------
def test_scene_files_reach_the_options():
    assert set(integrator_options("trapezoid")) == {"rtol", "max_iter", "mass", "max_dt_cuts", "project",
                                                    "linear_solver", "velocity_tol"}
    tr = make_integrator({"type": "trapezoid", "rtol": 1e-6, "mass": "consistent", "max_dt_cuts": 2,
                          "velocity_tol": 1e-3})
    assert isinstance(tr, TR) and (tr.rtol, tr.mass, tr.max_dt_cuts, tr.velocity_tol) == (
        1e-6, "consistent", 2, 1e-3)
