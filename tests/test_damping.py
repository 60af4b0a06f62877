"""Rayleigh damping: coefficients, damping ratios and the damped oscillator."""

import math

import numpy as np
import pytest

import fem_elastic as fe


def test_damping_ratio_from_two_frequencies():
    d = fe.Rayleigh.from_damping_ratios(0.02, 1.0, 0.1, 30.0)
    assert math.isclose(d.damping_ratio(2 * math.pi * 1.0), 0.02, rel_tol=1e-12)
    assert math.isclose(d.damping_ratio(2 * math.pi * 30.0), 0.1, rel_tol=1e-12)


@pytest.mark.parametrize("kw", [dict(alpha=-1.0), dict(beta=np.nan), dict(alpha="1")])
def test_bad_coefficients(kw):
    with pytest.raises(fe.InvalidParameter, match="Rayleigh"):
        fe.Rayleigh(**kw)


def test_mass_proportional_damping_decays_a_rigid_velocity_at_rate_alpha():
    """C = alpha M: a rigid translation obeys v' = -alpha v, so v(t) = v0 exp(-alpha t)."""
    mesh = fe.beam_mesh(length=0.2, width=0.1, height=0.1, cells=(2, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.LinearElastic(E=1e5, nu=0.3)),
                     damping=fe.Rayleigh(alpha=3.0))
    s0 = fe.State.rest(model, velocity=(1.0, 0.0, 0.0))
    # global relative errors at t = 0.5 s, h = 1e-3 s, alpha h = 3e-3: RK4 500 * (alpha h)^5 / 120
    # = 1e-12; the trapezoidal rule alpha t (alpha h)^2 / 12 = 1.1e-6; tolerances 10x those
    for integ, tol in ((fe.RK4(), 1e-11), (fe.Newmark(), 1.2e-5)):
        run = fe.simulate(model, integ, 1e-3, t_end=0.5, state=s0, check_stability=False)
        np.testing.assert_allclose(run.final_state.v[0::3], math.exp(-1.5), rtol=tol)


def test_stiffness_damping_does_not_damp_rigid_motion():
    mesh = fe.beam_mesh(length=0.2, width=0.1, height=0.1, cells=(2, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.LinearElastic(E=1e5, nu=0.3)),
                     damping=fe.Rayleigh(beta=1e-3))
    s0 = fe.State.rest(model, velocity=(0.0, 1.0, 0.0))
    run = fe.simulate(model, fe.ImplicitEuler(), 1e-3, steps=10, state=s0)
    # K_0 annihilates translations: the velocity stays 1 to Newton's tolerance
    np.testing.assert_allclose(run.final_state.v[1::3], 1.0, rtol=1e-7)


def test_stiffness_damping_does_not_brake_a_spinning_body():
    """beta K(x) uses the rest stiffness rotated with each element: a free cube spinning at
    10 rad/s keeps its spin (the plain rest stiffness K_0 would stop it within a second)."""
    cube = fe.beam_mesh(length=0.1, width=0.1, height=0.1, cells=(2, 2, 2))
    spin = lambda X: np.cross([0.0, 0.0, 10.0], X - X.mean(axis=0))  # noqa: E731
    L = {}
    for beta in (0.0, 1e-3):
        model = fe.Model(cube, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
                         damping=fe.Rayleigh(beta=beta) if beta else None)
        s0 = fe.State.rest(model, velocity=spin)
        for integ, dt in ((fe.SymplecticEuler(), 2e-4), (fe.ImplicitEuler(), 2e-3),
                          (fe.ImplicitEuler(), 1e-3)):
            run = fe.simulate(model, integ, dt, t_end=0.25, state=s0, record_every=50)
            L[beta, integ.name, dt] = run.angular_momentum[-1, 2] / run.angular_momentum[0, 2]
    # symplectic Euler conserves L exactly (round-off over 1250 steps); the damping acts
    # only on the small elastic stretching of the spinning cube (strain rho w^2 a^2/E ~ 1e-4)
    assert abs(L[0.0, "SymplecticEuler", 2e-4] - 1) < 1e-9
    assert abs(L[1e-3, "SymplecticEuler", 2e-4] - 1) < 1e-3
    # implicit Euler freezes K(x) at the step's start while the body turns by w h = 0.02 rad:
    # the damping then sees a small part of the rigid velocity, an error that vanishes as
    # h -> 0 (measured 0.6 % and 0.17 % extra loss: order ~1.8); K_0 would remove all the spin
    extra = {dt: L[0.0, "ImplicitEuler", dt] - L[1e-3, "ImplicitEuler", dt] for dt in (2e-3, 1e-3)}
    assert 0 <= extra[2e-3] < 0.02
    assert extra[1e-3] < 0.4 * extra[2e-3], extra


def test_damping_stiffness_is_the_warped_rest_stiffness():
    mesh = fe.beam_mesh(length=0.2, width=0.1, height=0.1, cells=(2, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
                     damping=fe.Rayleigh(alpha=0.5, beta=1e-3))
    # at rest it is K_0, the linear-elastic stiffness
    K0 = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.LinearElastic(E=1e5, nu=0.3))).rest_stiffness
    np.testing.assert_allclose(model.damping_stiffness(model.X).toarray(), K0.toarray(), atol=1e-9 * abs(K0).max())
    # the matrix-free force equals the assembled matrix times v (explicit and implicit agree)
    rng = np.random.default_rng(3)
    x = model.X + 0.01 * rng.standard_normal(model.ndofs)
    v = rng.standard_normal(model.ndofs)
    C = model.damping_matrix(x, mass="lumped")
    np.testing.assert_allclose(model.damping_force(x, v, mass="lumped"), -(C @ v), rtol=1e-12,
                               atol=1e-12 * np.abs(C @ v).max())
