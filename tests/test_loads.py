"""Gravity and traction loads: totals, distribution, energy, bad input."""

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.discretization import Discretization
from fem_elastic.physics.loads import gravity_load, traction_load

L, W, H = 1.0, 0.2, 0.1


@pytest.mark.parametrize("order", [1, 2])
def test_gravity_total_is_weight(order):
    mesh = fe.beam_mesh(L, W, H, cells=(4, 2, 1))
    space = Discretization(mesh, order)
    rho, g = 1200.0, np.array([0.0, -1.0, -9.81])
    load = gravity_load(space, rho, g)
    total = load.force.reshape(-1, 3).sum(axis=0)
    # consistent load vector: partition of unity makes the sum exact up to round-off
    np.testing.assert_allclose(total, rho * g * L * W * H, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("order", [1, 2])
def test_traction_total_is_traction_times_area(order):
    mesh = fe.beam_mesh(L, W, H, cells=(4, 2, 1))
    space = Discretization(mesh, order)
    t = np.array([1.0, 2.0, -3.0e3])
    load = traction_load(space, "right", t)
    f = load.force.reshape(-1, 3)
    np.testing.assert_allclose(f.sum(axis=0), t * W * H, rtol=1e-12)
    # only nodes on the loaded face (x = L) carry force: the shape functions of the other
    # nodes vanish on that face, up to the round-off of evaluating them there
    on_face = np.isclose(space.X.reshape(-1, 3)[:, 0], L)
    assert np.abs(f[~on_face]).max() <= 1e-12 * np.abs(f).max()
    # the face carries the load in the direction of t at every node with a nonzero share
    fz = f[on_face, 2]
    assert np.all(fz[np.abs(fz) > 1e-12 * np.abs(fz).max()] < 0)


def test_load_energy_is_minus_work():
    mesh = fe.beam_mesh(L, W, H, cells=(2, 1, 1))
    space = Discretization(mesh, 1)
    load = gravity_load(space, 1000.0, (0, 0, -9.81))
    x = space.X.copy()
    assert load.energy(x) == 0.0
    x[2::3] -= 0.01  # everything drops 1 cm: the potential falls by m g h
    np.testing.assert_allclose(load.energy(x), -1000.0 * L * W * H * 9.81 * 0.01, rtol=1e-12)
    np.testing.assert_array_equal(load.gradient(x), -load.force)
    assert load.hessian(x) is None


@pytest.mark.parametrize("bad", [(0, 0), (0, 0, np.nan), "down", (0, 0, np.inf)])
def test_bad_vectors_raise(bad):
    mesh = fe.beam_mesh(L, W, H, cells=(2, 1, 1))
    with pytest.raises(fe.InvalidParameter, match="three"):
        gravity_load(Discretization(mesh, 1), 1000.0, bad)


def test_unknown_boundary_names_the_known_ones():
    mesh = fe.beam_mesh(L, W, H, cells=(2, 1, 1))
    with pytest.raises(fe.InvalidParameter, match=r"'rigth'.*\['back', 'bottom'"):
        traction_load(Discretization(mesh, 1), "rigth", (0, 0, 1))
