"""Consistent and lumped mass: total mass, symmetry, positivity, exact integrals."""

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.discretization import Discretization
from fem_elastic.discretization.mass import consistent_mass, lumped_mass


@pytest.mark.parametrize("order", [1, 2])
def test_consistent_mass_integrates_quadratics_exactly(order):
    mesh = fe.beam_mesh(2.0, 0.5, 0.25, cells=(4, 2, 2))
    space = Discretization(mesh, order)
    rho = 800.0
    M = consistent_mass(space, rho)
    assert abs(M - M.T).max() < 1e-12 * abs(M).max()  # symmetric to round-off
    ones = np.ones(space.ndofs)
    # 1^T M 1 = 3 * total mass (three components)
    np.testing.assert_allclose(ones @ M @ ones, 3 * rho * 2.0 * 0.5 * 0.25, rtol=1e-12)
    # x^T M x for the x-component field u_x = X: rho * int x^2 dV, exact for P1 and P2
    X = space.X.reshape(-1, 3)
    u = np.zeros((X.shape[0], 3))
    u[:, 0] = X[:, 0]
    exact = rho * (2.0**3 / 3) * 0.5 * 0.25
    np.testing.assert_allclose(u.ravel() @ M @ u.ravel(), exact, rtol=1e-12)


@pytest.mark.parametrize("order", [1, 2])
def test_lumped_mass_positive_and_conserving(order):
    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells=(5, 1, 1))
    space = Discretization(mesh, order)
    m = lumped_mass(space, 1000.0)
    assert m.shape == (space.ndofs,)
    assert np.all(m > 0)  # P2 row sums would give non-positive vertex masses; HRZ does not
    np.testing.assert_allclose(m.sum() / 3, 1000.0 * 0.01, rtol=1e-12)
    # the three components of a node share one mass
    np.testing.assert_array_equal(m[0::3], m[1::3])


def test_p1_lumped_mass_is_row_sum():
    space = Discretization(fe.beam_mesh(cells=(3, 1, 1)), 1)
    M = consistent_mass(space, 500.0)
    np.testing.assert_allclose(lumped_mass(space, 500.0), np.asarray(M.sum(axis=1)).ravel(), rtol=1e-12)
