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
    for integ, tol in ((fe.RK4(), 1e-9), (fe.Newmark(), 1e-4)):
        run = fe.simulate(model, integ, 1e-3, t_end=0.5, state=s0, check_stability=False)
        # RK4: local error (alpha h)^5/120 per step; Newmark (trapezoid): (alpha h)^2 / 12 relative
        np.testing.assert_allclose(run.final_state.v[0::3], math.exp(-1.5), rtol=tol)


def test_stiffness_damping_does_not_damp_rigid_motion():
    mesh = fe.beam_mesh(length=0.2, width=0.1, height=0.1, cells=(2, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.LinearElastic(E=1e5, nu=0.3)),
                     damping=fe.Rayleigh(beta=1e-3))
    s0 = fe.State.rest(model, velocity=(0.0, 1.0, 0.0))
    run = fe.simulate(model, fe.ImplicitEuler(), 1e-3, steps=10, state=s0)
    # K_0 annihilates translations: the velocity stays 1 to Newton's tolerance
    np.testing.assert_allclose(run.final_state.v[1::3], 1.0, rtol=1e-7)
