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


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("boundary", ["right", "top", "front"])
def test_closed_form_facet_integrals_equal_scikit_fem_quadrature(order, boundary):
    """The closed form (A/3 per corner for P1; A/3 per edge midpoint, 0 per corner for P2)
    against scikit-fem's FacetBasis quadrature of int N_a dA, node by node, on a skewed mesh
    (random interior and in-plane boundary moves keep the facets flat but of unequal shapes):
    the two agree to round-off (1e-13 relative: sums of ~1e2 terms of 1e-16 relative error,
    with 100x slack), which also checks the closed form's node numbering."""
    from skfem import FacetBasis, LinearForm

    from fem_elastic.geometry.mesh import boundary_facets
    from fem_elastic.physics.loads import facet_shape_integrals

    @LinearForm
    def shape_integral(v, w):
        return v  # int N_a dA over the facets

    mesh = fe.beam_mesh(L, W, H, cells=(4, 3, 2))
    rng = np.random.default_rng(1)
    p = mesh.p.copy()
    lo, hi = p.min(axis=1, keepdims=True), p.max(axis=1, keepdims=True)
    on_side = np.isclose(p, lo) | np.isclose(p, hi)
    # moves of 2 mm, 4 % of the smallest cell size (0.05 m): no tet inverts; each side stays flat
    p += np.where(on_side, 0.0, 0.002 * rng.standard_normal(p.shape))
    mesh = type(mesh)(p, mesh.t, _boundaries=mesh.boundaries)
    space = Discretization(mesh, order)
    facets = boundary_facets(mesh, boundary, what="traction")
    fb = FacetBasis(mesh, space.element, facets=facets, intorder=2 * order)
    ref = shape_integral.assemble(fb)
    got = facet_shape_integrals(space, facets)
    assert np.max(np.abs(got - ref)) <= 1e-13 * np.max(np.abs(ref))


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
