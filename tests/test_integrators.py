"""Time integrators: order of accuracy, energy behaviour, momentum, step maps."""

import numpy as np
import pytest
import scipy.linalg as sl
from skfem import MeshTet

import fem_elastic as fe

ALL = [fe.ExplicitEuler, fe.SymplecticEuler, fe.Midpoint, fe.RK4, fe.ImplicitEuler,
       fe.LinearizedImplicitEuler, fe.Newmark, fe.Trapezoid, fe.VelocityVerlet]


# -- a single mass on a spring: one tet with three vertices held --------------------------
@pytest.fixture(scope="module")
def oscillator():
    """A linear-elastic tet whose fourth vertex is the only free node: a 3-DOF mass on springs.

    Its exact motion is the matrix exponential of the first-order system
    (u, v)' = [[0, I], [-K/m, 0]] (u, v), so the error of each scheme at a
    fixed time can be measured against a closed form.
    """
    mesh = MeshTet(np.array([[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]]), np.array([[0], [1], [2], [3]]))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.LinearElastic(E=1e3, nu=0.3)),
                     fixed=np.array([0, 1, 2]))
    free = model.free
    K = model.rest_stiffness.toarray()[np.ix_(free, free)]
    m = model.lumped_mass[free]
    A = np.block([[np.zeros((3, 3)), np.eye(3)], [-K / m[:, None], np.zeros((3, 3))]])
    return model, A


@pytest.mark.parametrize(
    "integrator, order, dts",
    [
        (fe.ExplicitEuler(), 1, (1 / 100, 1 / 200, 1 / 400)),
        (fe.SymplecticEuler(), 1, (1 / 100, 1 / 200, 1 / 400)),
        (fe.Midpoint(), 2, (1 / 50, 1 / 100, 1 / 200)),
        (fe.RK4(), 4, (1 / 25, 1 / 50, 1 / 100)),
        (fe.ImplicitEuler(), 1, (1 / 50, 1 / 100, 1 / 200)),
        (fe.LinearizedImplicitEuler(), 1, (1 / 50, 1 / 100, 1 / 200)),
        (fe.Newmark(), 2, (1 / 25, 1 / 50, 1 / 100)),
        (fe.Trapezoid(), 2, (1 / 25, 1 / 50, 1 / 100)),
        (fe.VelocityVerlet(), 2, (1 / 25, 1 / 50, 1 / 100)),
    ],
    ids=lambda p: getattr(p, "name", ""),
)
def test_order_of_accuracy_on_a_mass_on_a_spring(oscillator, integrator, order, dts):
    model, A = oscillator
    free = model.free
    u0 = np.array([0.01, 0.02, 0.05])
    T = 1.0  # omega = 1.24 and 2.32 rad/s: a third of a period and more
    exact = sl.expm(A * T) @ np.r_[u0, np.zeros(3)]
    x = model.X.copy()
    x[free] += u0
    errors = []
    for dt in dts:
        run = fe.simulate(model, integrator, dt, t_end=T, state=fe.State(x, np.zeros_like(x)),
                          check_stability=False)
        s = run.final_state
        errors.append(np.linalg.norm(np.r_[s.x[free] - model.X[free] - exact[:3], s.v[free] - exact[3:]]))
    slope = np.polyfit(np.log(dts), np.log(errors), 1)[0]
    # measured 0.98-1.02, 1.99-2.00, 3.99: within 0.15 of the theoretical order is
    # the asymptotic regime (higher-order terms shift a 3-point fit by a few 0.01)
    assert abs(slope - order) < 0.15, (errors, slope)


@pytest.mark.parametrize("cls", ALL, ids=lambda c: c.__name__)
def test_step_matrix_matches_a_step_on_the_linear_oscillator(oscillator, cls):
    """The modal step map each scheme reports is the map its step() applies to a linear mode."""
    model, A = oscillator
    free = model.free
    K = -A[3:, :3]  # K/m
    w2, Q = np.linalg.eigh(K)
    h = 0.05
    q0, v0 = 0.01, -0.02
    u = Q[:, 0] * q0
    x = model.X.copy()
    x[free] += u
    v = np.zeros_like(x)
    v[free] = Q[:, 0] * v0
    integ = cls()
    s = integ.step(model, fe.State(x, v), h)
    q1 = Q[:, 0] @ (s.x[free] - model.X[free])
    p1 = Q[:, 0] @ s.v[free]
    expected = integ.step_matrix(h, np.sqrt(w2[0])) @ np.array([q0, v0])
    # Newton stops at rtol 1e-8 of the step's force: the implicit maps agree to ~1e-10 m
    np.testing.assert_allclose([q1, p1], expected, rtol=0, atol=1e-9)


# -- a vibrating cantilever ------------------------------------------------------------
def _released_beam(material, cells=(6, 1, 1)):
    """A cantilever bent by a tip load, then released: a state rich in the first bending mode."""
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=cells)
    body = fe.ElasticBody(material, order=1)
    loaded = fe.Model(mesh, density=1000.0, body=body, fixed="left", traction={"right": (0, 0, -2e3)})
    static = fe.solve_static(loaded)
    model = fe.Model(mesh, density=1000.0, body=body, fixed="left")
    return model, fe.State(static.x, np.zeros_like(static.x))


@pytest.fixture(scope="module")
def linear_beam():
    return _released_beam(fe.LinearElastic(E=1e6, nu=0.3))


def test_energy_behaviour_on_a_vibrating_beam(linear_beam):
    """Explicit Euler gains energy, symplectic Euler keeps it bounded,
    implicit Euler loses it, Newmark conserves it (linear elasticity)."""
    model, s0 = linear_beam
    dt_c = fe.critical_time_step(model, fe.SymplecticEuler())
    dt = 0.5 * dt_c
    steps = 200
    e0 = model.energy(s0.x)
    runs = {}
    for integ in (fe.ExplicitEuler(), fe.SymplecticEuler()):
        runs[integ.name] = fe.simulate(model, integ, dt, steps=steps, state=s0, check_stability=False,
                                       energy_growth=np.inf)
    # the implicit schemes are stable at any dt: 20 steps per period of the first mode, 3 periods
    period = 1.0 / fe.natural_frequencies(model, 1, mass="lumped")[0]
    for integ in (fe.ImplicitEuler(), fe.Newmark()):
        runs[integ.name] = fe.simulate(model, integ, period / 20, steps=60, state=s0)
    ee = runs["ExplicitEuler"].total
    assert ee[-1] > 1.5 * e0 and np.all(np.diff(ee) > 0)  # grows at every step
    se = runs["SymplecticEuler"].total
    # symplectic Euler's energy error oscillates, O(omega h) for the modes excited, without a
    # trend; the released static shape is mostly the slow first mode: measured 0.4-0.7 %
    assert np.abs(se - e0).max() < 0.02 * e0
    assert abs(se[-20:].mean() - e0) < 0.02 * e0
    ie = runs["ImplicitEuler"].total
    # amplification 1/sqrt(1 + (omega h)^2) per step at omega h = 2 pi / 20: the first mode
    # keeps (1 + 0.099)^-60 = 0.4 % of its energy; monotone to Newton's tolerance
    assert ie[-1] < 0.05 * e0 and np.all(np.diff(ie) <= 1e-9 * e0)
    nm = runs["Newmark"].total
    # trapezoidal rule on a linear system: exact energy conservation up to Newton's
    # tolerance (rtol 1e-8 on forces -> ~1e-8 relative in energy per step)
    np.testing.assert_allclose(nm, e0, rtol=1e-6)


def test_free_body_conserves_momentum():
    """No gravity, nothing fixed: linear momentum is conserved by every scheme, angular
    momentum exactly by symplectic Euler (x_{n+1} x m v_{n+1} = x_n x m v_{n+1}) and velocity
    Verlet (its kicks add no torque, its drift moves along the momentum)."""
    mesh = fe.beam_mesh(length=0.3, width=0.1, height=0.1, cells=(3, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)))
    rng = np.random.default_rng(0)

    def velocity(X):
        spin = np.cross([0.3, -0.2, 1.0], X - X.mean(axis=0))
        return np.array([0.1, 0.0, -0.2]) + spin + 0.05 * rng.standard_normal(X.shape)

    s0 = fe.State.rest(model, velocity=velocity)
    P0 = model.linear_momentum(s0.v)
    L0 = model.angular_momentum(s0.x, s0.v)
    for cls in ALL:
        run = fe.simulate(model, cls(), 1e-3, steps=20, state=s0, check_stability=False,
                          energy_growth=np.inf)  # explicit Euler gains energy; not the point here
        # internal forces sum to zero at every evaluation: round-off level, and Newton's
        # tolerance for the implicit ones (force residual 1e-8 relative)
        np.testing.assert_allclose(run.linear_momentum, np.broadcast_to(P0, run.linear_momentum.shape),
                                   atol=1e-7 * np.abs(P0).max(), err_msg=cls.__name__)
        if cls in (fe.SymplecticEuler, fe.VelocityVerlet):
            # exact in exact arithmetic; 20 steps of round-off on sums over 32 nodes
            np.testing.assert_allclose(run.angular_momentum,
                                       np.broadcast_to(L0, run.angular_momentum.shape),
                                       rtol=0, atol=1e-12 * np.abs(L0).max())


def test_explicit_euler_above_the_critical_step_is_caught_as_diverged(linear_beam):
    model, s0 = linear_beam
    dt_c = fe.critical_time_step(model, fe.SymplecticEuler())
    with pytest.warns(fe.StabilityWarning, match="unstable at every time step"):
        with pytest.raises(fe.Diverged) as info:
            fe.simulate(model, fe.ExplicitEuler(), 2.0 * dt_c, steps=200, state=s0)
    err = info.value
    assert err.step < 20  # a few steps: energy x 17 per step in the top mode at omega h = 4
    assert "energy" in err.reason
    assert np.isfinite(err.last_good_state.x).all()
    assert err.trajectory.times[-1] <= err.last_good_state.t


def test_symplectic_euler_above_its_limit_warns_and_diverges(linear_beam):
    model, s0 = linear_beam
    dt_c = fe.critical_time_step(model, fe.SymplecticEuler())
    with pytest.warns(fe.StabilityWarning, match="critical time step"):
        with pytest.raises(fe.Diverged):
            fe.simulate(model, fe.SymplecticEuler(), 1.2 * dt_c, steps=300, state=s0)
    # and below it runs to the end
    fe.simulate(model, fe.SymplecticEuler(), 0.9 * dt_c, steps=300, state=s0)


def test_rayleigh_damping_dissipates(linear_beam):
    """5 % damping on the first mode: its energy decays as exp(-2 zeta omega t)."""
    model, s0 = linear_beam
    f1 = fe.natural_frequencies(model, 1, mass="lumped")[0]
    damping = fe.Rayleigh.from_damping_ratios(0.05, f1, 0.05, 10 * f1)
    damped = fe.Model(model.mesh, density=1000.0, body=model.body, fixed="left", damping=damping)
    t_end = 3.0 / f1
    expected = np.exp(-2 * 0.05 * 2 * np.pi * f1 * t_end)  # 0.15
    for integ, dt in ((fe.SymplecticEuler(), 0.5 * fe.critical_time_step(damped, fe.SymplecticEuler())),
                      (fe.Newmark(), 1 / (40 * f1))):
        free_run = fe.simulate(model, integ, dt, t_end=t_end, state=s0, record_every=10)
        run = fe.simulate(damped, integ, dt, t_end=t_end, state=s0, record_every=10)
        ratio = run.total[-1] / free_run.total[-1]
        # the released static shape is mostly the first mode; the rest (a few % of the
        # energy) is damped faster, and the end phase of the oscillation moves energy
        # between kinetic and potential: within a factor 1.5 of the modal prediction
        assert expected / 1.5 < ratio < expected * 1.5, (integ.name, ratio, expected)


@pytest.mark.parametrize("dt", [0.0, -1e-3, np.nan, np.inf, "0.1", True])
def test_bad_dt_is_refused(linear_beam, dt):
    model, s0 = linear_beam
    with pytest.raises(fe.InvalidParameter, match="dt"):
        fe.simulate(model, fe.ImplicitEuler(), dt, steps=1)


def test_bad_simulate_arguments(linear_beam):
    model, _ = linear_beam
    with pytest.raises(fe.InvalidParameter, match="exactly one"):
        fe.simulate(model, fe.RK4(), 1e-3)
    with pytest.raises(fe.InvalidParameter, match="exactly one"):
        fe.simulate(model, fe.RK4(), 1e-3, steps=2, t_end=1.0)
    with pytest.raises(fe.InvalidParameter, match="record_every"):
        fe.simulate(model, fe.RK4(), 1e-3, steps=2, record_every=0)
    with pytest.raises(fe.InvalidParameter, match="integrator"):
        fe.simulate(model, "rk4", 1e-3, steps=2)
    with pytest.raises(fe.InvalidParameter, match="mass"):
        fe.ImplicitEuler(mass="diagonal")


def test_record_every_and_statistics(linear_beam):
    model, s0 = linear_beam
    run = fe.simulate(model, fe.ImplicitEuler(), 1e-3, steps=7, state=s0, record_every=3)
    np.testing.assert_allclose(run.times, [0, 3e-3, 6e-3, 7e-3])
    assert run.step_stats["newton_iterations"].shape == (7,)
    assert (run.step_stats["newton_iterations"] >= 1).all()
    assert run.summary()["steps"] == 7
    ex = fe.simulate(model, fe.RK4(), 1e-5, steps=3, state=s0, check_stability=False)
    assert (ex.step_stats["gradient_evaluations"] == 4).all()
    assert (ex.step_stats["newton_iterations"] == 0).all()


def _kicked_stiff_beam(material, speed):
    """A 100 GPa cantilever given a seeded random velocity of ``speed`` m/s per component."""
    model = fe.Model(fe.beam_mesh(cells=(6, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(material(E=1e11, nu=0.3)), fixed="left",
                     gravity=(0.0, 0.0, -9.81))
    rest = fe.State.rest(model)
    v = np.random.default_rng(0).standard_normal(rest.x.shape) * speed
    v[~model.free_at(0.0)] = 0.0
    return model, fe.State(rest.x, v, 0.0)


def test_implicit_euler_does_not_gain_energy_from_a_bad_first_guess():
    """From y = x_n + h v_n (here inverted: 1000 m/s for 1/24 s), Newton once converged to an
    inverted minimum of StVK and took the energy from 1.2e7 J to 3.4e9 J in one step. Starting
    from whichever of y and x_n has the lower incremental potential G, the minimiser has
    G(x_1) <= G(x_0) = E(x_0) + KE_0, so the potential energy cannot exceed the initial total."""
    model, s0 = _kicked_stiff_beam(fe.StVK, 1000.0)
    s1 = fe.ImplicitEuler().step(model, s0, 1 / 24)
    e0 = model.energy(s0.x) + model.kinetic_energy(s0.v)
    # G(x_1) = E(x_1) + 1/2 |v_1 - v_0|_M^2 <= G(x_0); Newton's tolerance is far below 1e-6 of e0
    assert model.energy(s1.x) + model.kinetic_energy(s1.v - s0.v) <= e0 * (1 + 1e-6)
    assert model.energy(s1.x) + model.kinetic_energy(s1.v) < e0


@pytest.mark.parametrize("project", [True, False])
def test_linearized_implicit_euler_from_an_inverted_state_diverges_with_the_reason(project):
    """The tangent of Neo-Hookean is undefined at J <= 0: a clear Diverged, not a LinAlgError
    (projected tangent) or a NaN update (exact tangent)."""
    model = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left")
    state = fe.State.rest(model, displacement=lambda p: p * [-2.5, 0.0, 0.0])  # p: (nodes, 3)
    assert not np.isfinite(model.energy(state.x))  # x -> -1.5 x: every element inverted
    with pytest.raises(fe.Diverged, match="inverted at the start of the step"):
        fe.simulate(model, fe.LinearizedImplicitEuler(project=project), dt=0.01, steps=2, state=state)
