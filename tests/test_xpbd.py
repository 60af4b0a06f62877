"""fe.XPBD: compliance from the material, convergence to implicit Euler, and its energy.

What XPBD's steps converge to: a fixed point of the sweeps satisfies C + (alpha / h^2) lam = 0
and M (x - x*) = sum_j G_j(x_j)^T dlam_j, the gradients taken where each correction was made
(Macklin et al. 2016 drop the residual g). That is implicit Euler's step when the gradients
change little within the step. For springs and volumes (rest value 0, multipliers as small as
the stresses) it holds at any step size, and the tests below show the steps approaching
implicit Euler on the same energy as the iterations grow, at ten steps of 0.01 s on a stiff
cantilever. The stable Neo-Hookean constraints of Macklin and Mueller (2021) are another
matter: C_D = sqrt(I_C) is sqrt(3) at rest, so every tet carries rest multipliers of size
sqrt(3) mu V h^2 whose forces cancel only at F = I; the body's shear stiffness is the
geometric stiffness of those multipliers, which the XPBD update leaves out. The sweeps still
converge (in a few iterations), but to a point that differs from implicit Euler by an amount
that grows with h omega_max: the tests measure it shrinking as the step does, and the warning
XPBD logs when h omega_max is past what the form takes (scripts/xpbd_convergence.py prints
the tables).
"""

from __future__ import annotations

import logging

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.dynamics.position_based import TetNeoHookean

G = (0.0, 0.0, -9.81)


def _rel(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def _run(model, integrator, dt, steps, state=None):
    s = fe.State.rest(model) if state is None else state
    for _ in range(steps):
        s = integrator.step(model, s, dt)
    return s


# -- the constraint form of stable Neo-Hookean and its energy --------------------------------------
def _sample_F():
    rng = np.random.default_rng(0)
    Fs = [np.eye(3) + s * rng.standard_normal((3, 3)) for s in (0.02, 0.2, 0.4)]
    Fs.append(np.diag([0.5, 1.0, 1.2]))
    return np.stack(Fs, axis=-1)


def test_constraint_neohookean_derivatives_match_finite_differences():
    m = fe.ConstraintNeoHookean(E=1e6, nu=0.4)
    F = _sample_F()
    h = 1e-6
    P, C = m.dpsi_dF(F), m.d2psi_dF2(F)
    for k in range(3):
        for l in range(3):
            d = np.zeros_like(F)
            d[k, l] = h
            assert np.abs((m.psi(F + d) - m.psi(F - d)) / (2 * h) - P[k, l]).max() < 1e-6 * m.E
            assert np.abs((m.dpsi_dF(F + d) - m.dpsi_dF(F - d)) / (2 * h) - C[:, :, k, l]).max() < 1e-6 * m.E
    assert np.abs(m.d2psi_dF2_psd(np.eye(3)) - m.d2psi_dF2(np.eye(3))).max() < 1e-9 * m.E


def test_constraint_neohookean_linearizes_to_the_materials_lame_parameters():
    I = np.eye(3)
    for nu in (0.0, 0.3, 0.45):
        m = fe.ConstraintNeoHookean(E=1e6, nu=nu)
        assert np.abs(m.dpsi_dF(I)).max() < 1e-9 * m.E
        lin = fe.LinearElastic(E=1e6, nu=nu)
        assert np.abs(m.d2psi_dF2(I) - lin.d2psi_dF2(I)).max() < 1e-9 * m.E
    # the paper's formulas with the material's lam as is: small-strain Lame parameters (mu, lam - mu)
    raw = fe.ConstraintNeoHookean(E=1e6, nu=0.3, consistent_lame=False)
    shifted = fe.LinearElastic(mu=raw.mu, lam=raw.lam - raw.mu)
    assert np.abs(raw.d2psi_dF2(I) - shifted.d2psi_dF2(I)).max() < 1e-9 * raw.E


def test_stable_neohookean_is_another_energy_with_the_same_small_strain_limit():
    """fe.StableNeoHookean (Smith et al.: log term, mu' = 4/3 mu) is not the constraints' energy."""
    c, s = fe.ConstraintNeoHookean(E=1e6, nu=0.3), fe.StableNeoHookean(E=1e6, nu=0.3)
    small = np.eye(3) + 1e-4 * np.arange(9.0).reshape(3, 3) / 9.0
    assert c.psi(small) == pytest.approx(float(s.psi(small)), rel=1e-3)
    large = np.array([[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])  # 50 % shear
    assert abs(float(c.psi(large)) / float(s.psi(large)) - 1.0) > 0.005


def test_constraint_neohookean_is_the_log_free_energy_of_smith_et_al():
    """The same energy as fe.energies.stable_neo_hookean with lam -> lam + mu, up to a constant."""
    c = fe.ConstraintNeoHookean(mu=4e5, lam=6e5)
    m = fe.material_from_energy(fe.energies.stable_neo_hookean, mu=4e5, lam=1e6)
    F = _sample_F()
    offset = m.psi(F) - c.psi(F)
    assert np.allclose(offset, 4e5**2 / (2 * 1e6), rtol=1e-10)  # mu^2 / (2 lam_c) at rest
    assert np.abs(m.dpsi_dF(F) - c.dpsi_dF(F)).max() < 1e-9 * c.E
    assert np.abs(m.d2psi_dF2(F) - c.d2psi_dF2(F)).max() < 1e-9 * c.E


def test_the_constraint_energy_is_the_fem_energy_of_the_material():
    """sum over tets of C_D^2 / (2 alpha_D) + C_H^2 / (2 alpha_H), less its rest value, is E(x)."""
    mesh = fe.beam_mesh(0.3, 0.1, 0.1, cells=(3, 1, 1))
    material = fe.ConstraintNeoHookean(E=1e6, nu=0.35)
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(material))
    tets = TetNeoHookean(mesh, material.mu_c, material.lam_c)
    x = model.X + 0.01 * np.random.default_rng(1).standard_normal(model.ndofs)

    def U(y):
        return 0.5 * float((tets.values(y) ** 2 / tets.compliance).sum())

    assert U(x) - U(model.X) == pytest.approx(model.energy(x), rel=1e-10)


def test_energy_material_is_the_xpbd_energy_of_the_body():
    mesh = fe.beam_mesh(cells=(2, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.StableNeoHookean(E=2e6, nu=0.4)))
    m = fe.XPBD().energy_material(model)
    assert isinstance(m, fe.ConstraintNeoHookean) and (m.E, m.nu, m.consistent_lame) == (2e6, 0.4, True)
    assert fe.XPBD(consistent_lame=False).energy_material(model).lam_c == pytest.approx(m.lam)
    own = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(m))
    assert fe.XPBD(consistent_lame=False).energy_material(own) is m


# -- convergence to implicit Euler -----------------------------------------------------------------
def _stiff_cantilever(body, damping=None):
    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells=(10, 2, 2))
    return fe.Model(mesh, density=1000.0, body=body, fixed="left", gravity=G, damping=damping)


@pytest.mark.parametrize("alpha", [0.0, 5.0])
def test_xpbd_approaches_implicit_euler_with_the_iterations(alpha):
    """Ten steps of 0.01 s on a 10 MPa cantilever (small strain; h omega_max = 48).

    Springs at nu = 1/4 (no volume term) are exactly the energy of fe.MassSpring(E), which
    implicit Euler integrates on the same mesh, mass and loads (and the same mass-proportional
    damping, taken exactly: see position_based/base.py). The difference falls with the
    iterations (fitted log-log slope), within 5 % at 200 iterations, to a floor below 0.1 %.
    """
    E = 1e7
    damping = fe.Rayleigh(alpha, 0.0) if alpha else None
    springs = _stiff_cantilever(fe.MassSpring(E=E), damping)
    xpbd_model = _stiff_cantilever(fe.ElasticBody(fe.LinearElastic(E=E, nu=0.25)), damping)
    dt, steps = 0.01, 10
    ref = _run(springs, fe.ImplicitEuler(rtol=1e-12), dt, steps)
    iterations = np.array([50, 100, 200, 400, 1600])
    err = np.array([_rel(_run(xpbd_model, fe.XPBD(iterations=int(n), constraints="edge_volume"), dt,
                              steps).x - xpbd_model.X, ref.x - springs.X) for n in iterations])
    slope = np.polyfit(np.log(iterations[:4]), np.log(err[:4]), 1)[0]
    assert slope < -1.0, (err, slope)
    assert np.all(np.diff(err[:4]) < 0.0)
    assert err[2] < 0.05
    assert err[-1] < 1e-3


def test_xpbd_static_sag_matches_solve_static_and_not_the_time_step():
    """Damped to rest (mass-proportional damping), XPBD's sag is the static one of its energy.

    The stiffness is in the compliance: the steady sag is the same at dt = 0.01 and 0.02 s
    (PBD's grows as dt^2, test_pbd.py), and approaches fe.solve_static with the iterations.
    """
    mesh = fe.beam_mesh(0.5, 0.1, 0.1, cells=(5, 1, 1))
    kw = dict(density=1000.0, fixed="left", gravity=G, damping=fe.Rayleigh(30.0, 0.0))
    springs = fe.Model(mesh, body=fe.MassSpring(E=1e6), **kw)
    model = fe.Model(mesh, body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.25)), **kw)
    sag = -fe.solve_static(springs).displacement[:, 2].min()

    def steady(iterations, dt):
        s = _run(model, fe.XPBD(iterations=iterations, constraints="edge_volume"), dt, int(round(2.0 / dt)))
        assert np.abs(s.v).max() < 1e-6
        return -(s.x - model.X)[2::3].min()

    errors = [abs(steady(n, 0.01) / sag - 1.0) for n in (10, 20, 50)]
    assert errors[0] > errors[1] > errors[2] and errors[2] < 0.005
    assert steady(200, 0.02) == pytest.approx(steady(200, 0.01), rel=0.002)


def test_neohookean_xpbd_approaches_implicit_euler_as_the_step_shrinks():
    """Macklin and Mueller's constraints: the converged step's distance to implicit Euler shrinks with h.

    A 0.5 m cantilever of the constraints' own energy released under gravity, 0.1 s. At
    h omega_max = 1.8 the distance is 1.7 %, and it falls as h^1.6 (fitted; 11 % at
    h omega_max = 3.6); the iterations change nothing past a few (the sweeps converge
    quickly at such steps).
    """
    mesh = fe.beam_mesh(0.5, 0.1, 0.1, cells=(5, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.ConstraintNeoHookean(E=1e5, nu=0.3)),
                     fixed="left", gravity=G)
    omega = 2.0 / fe.critical_time_step(model, fe.SymplecticEuler())
    dts = np.array([0.005, 0.0025, 0.00125])
    err = []
    for dt in dts:
        steps = int(round(0.1 / dt))
        ref = _run(model, fe.ImplicitEuler(rtol=1e-12), dt, steps)
        x200 = _run(model, fe.XPBD(iterations=200), dt, steps).x
        x20 = _run(model, fe.XPBD(iterations=20), dt, steps).x
        assert _rel(x20 - model.X, x200 - model.X) < 1e-4  # converged long before 200
        err.append(_rel(x200 - model.X, ref.x - model.X))
    err = np.array(err)
    slope = np.polyfit(np.log(dts), np.log(err), 1)[0]
    assert slope > 1.2, (err, slope)
    assert dts[0] * omega < 2.0 and err[0] < 0.05
    assert err[-1] < 0.005


def test_neohookean_static_sag_approaches_solve_static_as_the_step_shrinks():
    mesh = fe.beam_mesh(0.5, 0.1, 0.1, cells=(5, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.ConstraintNeoHookean(E=1e6, nu=0.3)),
                     fixed="left", gravity=G, damping=fe.Rayleigh(30.0, 0.0))
    sag = -fe.solve_static(model).displacement[:, 2].min()
    dts = np.array([0.002, 0.001, 0.0005])
    err = []
    for dt in dts:
        s = _run(model, fe.XPBD(iterations=10), dt, int(round(1.2 / dt)))
        assert np.abs(s.v).max() < 1e-5
        err.append(abs(-(s.x - model.X)[2::3].min() / sag - 1.0))
    slope = np.polyfit(np.log(dts), np.log(err), 1)[0]
    assert slope > 1.0 and err[1] < 0.05, (err, slope)


def test_a_step_past_what_the_neohookean_form_takes_is_logged(caplog):
    model = _stiff_cantilever(fe.ElasticBody(fe.StableNeoHookean(E=1e7, nu=0.3)))
    with caplog.at_level(logging.WARNING, logger="fem_elastic.dynamics.position_based.xpbd"):
        fe.XPBD(iterations=2).step(model, fe.State.rest(model), 0.01)
    assert "substeps >=" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="fem_elastic.dynamics.position_based.xpbd"):
        fe.XPBD(iterations=2, constraints="edge_volume").step(model, fe.State.rest(model), 0.01)
        fe.XPBD(iterations=2).step(model, fe.State.rest(model), 1e-5)
    assert caplog.text == ""


# -- what a step carries ----------------------------------------------------------------------------------
def test_multipliers_reset_every_step():
    """A step depends only on the state it starts from: no multipliers carried, no checkpoint state."""
    model = _stiff_cantilever(fe.ElasticBody(fe.StableNeoHookean(E=1e5, nu=0.3)))
    integ = fe.XPBD(iterations=10)
    s1 = integ.step(model, fe.State.rest(model), 0.002)
    s2 = integ.step(model, s1, 0.002)
    again = fe.XPBD(iterations=10).step(model, s1, 0.002)
    assert np.array_equal(s2.x, again.x) and np.array_equal(s2.v, again.v)
    assert integ.checkpoint_state(s2) == {}


def test_jacobi_sweeps_converge_to_a_nearby_step():
    model = _stiff_cantilever(fe.ElasticBody(fe.StableNeoHookean(E=1e5, nu=0.3)))
    gs = _run(model, fe.XPBD(iterations=50), 0.002, 5)
    jac = _run(model, fe.XPBD(iterations=400, method="jacobi"), 0.002, 5)
    more = _run(model, fe.XPBD(iterations=800, method="jacobi"), 0.002, 5)
    assert _rel(jac.x - model.X, more.x - model.X) < 1e-6  # converged
    assert _rel(jac.x - model.X, gs.x - model.X) < 0.01  # to nearly the same point


def test_neohookean_xpbd_keeps_linear_momentum_of_a_free_body():
    mesh = fe.beam_mesh(0.3, 0.1, 0.1, cells=(3, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.StableNeoHookean(E=1e4, nu=0.3)))
    rng = np.random.default_rng(3)
    s = fe.State(model.X + 0.005 * rng.standard_normal(model.ndofs), rng.standard_normal(model.ndofs))
    P0 = model.linear_momentum(s.v)
    scale = float((model.lumped_mass * np.abs(s.v)).sum())
    for method in ("gauss_seidel", "jacobi"):
        t = _run(model, fe.XPBD(iterations=10, method=method, damping=0.1), 0.005, 20, s)
        assert np.abs(model.linear_momentum(t.v) - P0).max() < 1e-13 * scale


@pytest.mark.parametrize("kwargs, word", [
    ({"constraints": "springs"}, "constraints"), ({"consistent_lame": 1}, "consistent_lame"),
    ({"iterations": -1}, "iterations"), ({"method": "GS"}, "method"),
])
def test_bad_parameters_are_refused(kwargs, word):
    with pytest.raises(fe.InvalidParameter, match=word):
        fe.XPBD(**kwargs)


def test_the_convergence_script_prints_its_tables():
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parent.parent / "scripts" / "xpbd_convergence.py"
    r = subprocess.run([sys.executable, str(script), "--quick"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    for line in ("1. cantilever", "fitted slope of the edge_volume distance", "2. Neo-Hookean constraints",
                 "substeps", "3. static sag"):
        assert line in r.stdout
    slope = float(r.stdout.split("over 50-400 iterations:")[1].split()[0])
    assert slope < -1.0
