"""Tests of fem_elastic.discretization._fused_p2_kernels: the fused P2 energy, force and tangent.

For every registered material, exact and projected, stretched and compressed, on a small
distorted P2 mesh, the fused kernels must equal the numpy path (``Material`` at the
quadrature points, ``ElasticPotential._force`` / ``element_stiffness``,
``SparsityPattern.assemble``); the gradient must be the derivative of the energy and the
tangent that of the gradient (central differences); a P2 Newton solve must not change.
Tests that need numba are skipped without it.
"""

import numpy as np
import pytest
from test_fused import E, NU, REGISTERED, ids, needs_numba
from test_fused import space as fused_space
from test_fused_tangent import assert_newton_unchanged, assert_projection_exercised_and_psd, numpy_path
from test_fused_tangent import states as deformed_states

import fem_elastic as fe
from fem_elastic.discretization import Discretization, fused
from fem_elastic.physics.elastic_body import ElasticPotential

# Both paths evaluate the same closed forms with another order of operations (the fused
# one rebuilds dN from the reference gradients and d xi / d x, and sums the element
# matrices in another order): they differ by a few eps of the largest entry, far below
# 1e-12 relative.
RTOL = 1e-12


def space() -> Discretization:
    """A 0.3 x 0.1 x 0.1 m box of 2 x 1 x 1 cells (12 P2 tets, 375 DOFs), vertices moved by <= 10 %."""
    return fused_space(2, (2, 1, 1))


def states():
    """A stretched-sheared-rotated state and a compressed one (indefinite tangents), J > 0."""
    return deformed_states(space(), noise=0.002)


@needs_numba
def test_p2_spaces_get_the_fused_p2_kernels():
    from fem_elastic.discretization import _fused_p2_kernels as p2

    k = fused.kernels_for(fe.NeoHookean(E, NU), space())
    assert isinstance(k, p2.FusedP2)
    assert fused.kernels_for(fe.NeoHookean(E, NU), space()) is k  # cached per space and material
    assert fused.kernels_for(fe.Corotated(E, NU), space()) is None  # not registered: numpy path
    # the rebuilt physical gradients are scikit-fem's: dN = G Dm^-1 per point, to round-off
    geo = k.geo
    dN = np.einsum("qam,emj->ajeq", geo.G, geo.Dm_inv)
    assert np.abs(dN - space().dN).max() <= RTOL * np.abs(space().dN).max()


@needs_numba
@pytest.mark.parametrize("project", [False, True], ids=["exact", "projected"])
@pytest.mark.parametrize("material_cls", REGISTERED, ids=ids)
def test_fused_p2_matches_the_numpy_path(material_cls, project, monkeypatch):
    pot = ElasticPotential(material_cls(E, NU), space())
    assert pot._fused() is not None
    for x in states():
        e, g, H = pot.energy(x), pot.gradient(x), pot.hessian(x, project=project)
        e_np, g_np, H_np = numpy_path(monkeypatch, pot, x, project)
        assert space().pattern.owns(H)
        assert abs(e - e_np) <= RTOL * abs(e_np)
        assert np.abs(g - g_np).max() <= RTOL * np.abs(g_np).max()
        assert np.abs((H - H_np).toarray()).max() <= RTOL * np.abs(H_np.toarray()).max()


@needs_numba
def test_p2_projection_is_exercised_and_psd():
    """The compressed state has indefinite Neo-Hookean tangents: the projection changes them."""
    assert_projection_exercised_and_psd(ElasticPotential(fe.NeoHookean(E, NU), space()), states()[1])


@needs_numba
@pytest.mark.parametrize("material_cls", REGISTERED, ids=ids)
def test_fused_p2_tangent_is_the_derivative_of_the_gradient(material_cls):
    pot = ElasticPotential(material_cls(E, NU), space())
    rng = np.random.default_rng(3)
    for x in states():
        v = rng.standard_normal(space().ndofs)
        h = 1e-6  # m: central difference error ~ h^2 |g'''| vs round-off eps |g| / h
        fd = (pot.gradient(x + h * v) - pot.gradient(x - h * v)) / (2 * h)
        Hv = pot.hessian(x) @ v
        # truncation O(h^2 / L^2) ~ 1e-8 relative for strains of O(1) on 0.01 m node
        # spacings, round-off eps |g| / h ~ 1e-10 relative: 1e-6 leaves a margin of 100
        assert np.linalg.norm(Hv - fd) <= 1e-6 * np.linalg.norm(Hv)


@needs_numba
@pytest.mark.parametrize("material_cls", REGISTERED, ids=ids)
def test_fused_p2_gradient_is_the_derivative_of_the_energy(material_cls):
    pot = ElasticPotential(material_cls(E, NU), space())
    rng = np.random.default_rng(4)
    for x in states():
        v = rng.standard_normal(space().ndofs)
        h = 1e-6  # m, as above
        fd = (pot.energy(x + h * v) - pot.energy(x - h * v)) / (2 * h)
        gv = pot.gradient(x) @ v
        # truncation ~1e-8 relative (as above); round-off eps E / h ~ 1e-9 of g.v here
        assert abs(gv - fd) <= 1e-6 * abs(gv)


@needs_numba
def test_inverted_p2_point_gives_inf_energy_and_nan_tangent(monkeypatch):
    s = space()
    pot = ElasticPotential(fe.NeoHookean(E, NU), s)
    x = s.X.copy()
    n0 = s.element_dofs[0, 0] // 3
    x[3 * n0:3 * n0 + 3] += 1.0  # drags a vertex 1 m away: its tets invert
    assert pot.energy(x) == np.inf
    for project in (False, True):
        H = pot.hessian(x, project=project)
        _, _, H_np = numpy_path(monkeypatch, pot, x, project)
        assert np.isnan(H.data).any()
        assert np.array_equal(np.isnan(H.data), np.isnan(H_np.data))


@needs_numba
def test_gradient_into_out_and_bad_out():
    k = fused.kernels_for(fe.StVK(E, NU), space())
    x = states()[0]
    out = np.empty(space().ndofs)
    assert k.gradient(x, out=out) is out
    assert np.array_equal(out, k.gradient(x))
    with pytest.raises(ValueError, match="C-contiguous float64"):
        k.gradient(x, out=np.empty(space().ndofs + 3))


@needs_numba
@pytest.mark.parametrize("material_cls", [fe.NeoHookean, fe.LinearElastic], ids=ids)
def test_p2_newton_result_unchanged(material_cls, monkeypatch):
    """A P2 cantilever under a tip load solved by Newton on both paths: the same equilibrium."""
    assert_newton_unchanged(material_cls, 2, (3, 1, 1), monkeypatch)
