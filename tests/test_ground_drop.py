"""A cube dropped on the ground comes to rest on it, with each contact method."""

import numpy as np
import pytest

import fem_elastic as fe

DROP = 0.05  # m, height of the cube's bottom face above the ground at the start


@pytest.mark.parametrize(
    "ground, integrator, dt, damping",
    [
        (fe.Ground(0.0, method="penalty", penetration=1e-3), fe.ImplicitEuler(), 1 / 100, None),
        (fe.Ground(0.0, method="barrier", dhat=1e-3), fe.ImplicitEuler(), 1 / 100, None),
        # explicit + impulses: the elastic vibrations need damping to settle
        (fe.Ground(0.0, method="impulse", friction=0.5), fe.SymplecticEuler(), 5e-4,
         fe.Rayleigh(alpha=5.0, beta=1e-3)),
    ],
    ids=["penalty-implicit", "barrier-implicit", "impulse-symplectic"],
)
def test_dropped_cube_comes_to_rest(ground, integrator, dt, damping):
    cube = fe.beam_mesh(length=0.1, width=0.1, height=0.1, cells=(2, 2, 2)).translated((0, 0, DROP))
    model = fe.Model(cube, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
                     gravity=(0, 0, -9.81), ground=ground, damping=damping)
    run = fe.simulate(model, integrator, dt, t_end=1.5, record_every=10)
    z = run.displacement[:, :, 2] + cube.p[2][None, :]  # vertex heights (m) at every frame
    m_g_h = model.total_mass * 9.81 * DROP  # J, the energy released by the fall
    # at rest: the kinetic energy is a round-off fraction of what the fall released
    assert run.kinetic[-1] < 1e-9 * m_g_h
    lowest = z.min(axis=1)
    if ground.method == "penalty":
        # the documented bound: at rest no node deeper than `penetration` (the depths
        # of the contact nodes add up to it); during the impact it may go deeper
        assert -1e-3 <= lowest[-1] < 0
    elif ground.method == "barrier":
        assert lowest.min() > 0  # never through, at any frame
        assert 0.5e-3 <= lowest[-1] < 1e-3  # resting gap in [dhat/2, dhat), as documented
    else:
        assert lowest.min() >= 0  # projected onto the plane after every step
        assert lowest[-1] < 1e-9  # and lying on it
    # it lies flat on the ground: the top face is a cube height above the bottom
    np.testing.assert_allclose(z[-1].max() - lowest[-1], 0.1, rtol=0.02)  # 2 %: squashed by its weight
