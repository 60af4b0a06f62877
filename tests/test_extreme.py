"""Extreme cases that ImplicitEuler with a Neo-Hookean body must survive.

Each runs to the end: finite, no inverted element at any recorded frame,
and the total energy never increases while nothing drives the body
(implicit Euler is dissipative). "Never increases" allows 1e-6 of the
scene's energy per step: Newton stops at a force residual of 1e-8 of the
step's force scale, which perturbs the energy by far less than that.
"""

import numpy as np

import fem_elastic as fe


def _min_J(model, run):
    """Smallest det F over all quadrature points of all recorded frames (P1: x = X + u)."""
    out = np.inf
    for u in run.displacement:
        F = model.space.deformation_gradient(u.ravel())
        out = min(out, float(np.linalg.det(np.moveaxis(F, (0, 1), (-2, -1))).min()))
    return out


def _check(model, run, t_free=0.0):
    assert np.isfinite(run.displacement).all() and np.isfinite(run.total).all()
    assert _min_J(model, run) > 0.0
    after = run.total[run.times >= t_free]
    scale = np.abs(run.total).max()
    assert np.diff(after).max() <= 1e-6 * scale, np.diff(after).max() / scale


def _beam(material, **kw):
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(10, 2, 2))
    return fe.Model(mesh, density=1000.0, body=fe.ElasticBody(material), fixed="left", **kw)


def test_very_stiff_beam_at_a_frame_rate_step():
    model = _beam(fe.NeoHookean(E=1e9, nu=0.3), gravity=(0, 0, -9.81))
    run = fe.simulate(model, fe.ImplicitEuler(), 1 / 30, t_end=1.0)
    _check(model, run)
    assert run.displacement[-1, :, 2].min() < 0  # it sags


def test_nearly_incompressible_beam():
    model = _beam(fe.NeoHookean(E=1e5, nu=0.49), gravity=(0, 0, -9.81))
    run = fe.simulate(model, fe.ImplicitEuler(), 1 / 30, t_end=1.0)
    _check(model, run)
    # large deflection: the soft beam's tip falls by a good part of its length
    assert run.displacement[-1, :, 2].min() < -0.3


def test_cube_crushed_to_a_fifth_and_released():
    cube = fe.beam_mesh(length=0.1, width=0.1, height=0.1, cells=(3, 3, 3))
    release = 0.25
    model = fe.Model(cube, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
                     fixed="bottom",
                     driven={"top": fe.Translate((0, 0, -0.08), duration=0.2, release=release)})
    run = fe.simulate(model, fe.ImplicitEuler(), 1 / 100, t_end=0.5)
    top = np.isclose(cube.p[2], 0.1)
    crushed = run.displacement[np.argmin(abs(run.times - 0.2))][top, 2]
    np.testing.assert_allclose(crushed, -0.08, atol=1e-12)  # held at 20 % of the height
    _check(model, run, t_free=release)
    # it springs back towards its rest height once released
    assert run.displacement[-1][top, 2].min() > -0.01  # back within 1/8 of the 8 cm crush


def test_beam_twisted_a_full_turn():
    release = 0.6
    model = _beam(fe.NeoHookean(E=1e5, nu=0.3),
                  driven={"right": fe.Twist(2 * np.pi, duration=0.5, release=release)})
    run = fe.simulate(model, fe.ImplicitEuler(), 1 / 100, t_end=1.0)
    _check(model, run, t_free=release)
    # at the end of the drive the right face has turned by 360 degrees: back in place
    end = model.mesh.p[0] == 1.0
    i = np.argmin(abs(run.times - 0.5))
    np.testing.assert_allclose(run.displacement[i][end], 0.0, atol=1e-12)
    # while the middle of the beam is turned by about 180 degrees
    mid = np.isclose(model.mesh.p[0], 0.5) & np.isclose(model.mesh.p[2], 0.1)
    # turned by ~180 degrees, the top edge of the 0.1 m section moves down by ~0.1 m
    assert run.displacement[i][mid, 2].max() < -0.05
