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
import skfem

import fem_elastic as fe
from fem_elastic.discretization import Discretization, fused
from fem_elastic.physics.elastic_body import ElasticPotential

E, NU = 1.0e6, 0.4
REGISTERED = [fe.LinearElastic, fe.StVK, fe.NeoHookean, fe.StableNeoHookean]
# Both paths evaluate the same closed forms with another order of operations (the fused
# one rebuilds dN from the reference gradients and d xi / d x, and sums the element
# matrices in another order): they differ by a few eps of the largest entry, far below
# 1e-12 relative.
RTOL = 1e-12

needs_numba = pytest.mark.skipif(
    not fused.available(), reason="numba not installed (or FEM_ELASTIC_NUMBA=0)"
)


def ids(cls):
    return cls.__name__


_SPACE = []


def space() -> Discretization:
    """A 0.3 x 0.1 x 0.1 m box of 2 x 1 x 1 cells (12 P2 tets, 375 DOFs), vertices moved by <= 10 %."""
    if not _SPACE:
        mesh = fe.beam_mesh(0.3, 0.1, 0.1, cells=(2, 1, 1))
        rng = np.random.default_rng(7)
        mesh = skfem.MeshTet(mesh.p + rng.uniform(-0.005, 0.005, mesh.p.shape), mesh.t)
        fe.validate_mesh(mesh)
        _SPACE.append(Discretization(mesh, 2))
    return _SPACE[0]


def states():
    """A stretched-sheared-rotated state and a compressed one (indefinite tangents), J > 0."""
    s = space()
    rng = np.random.default_rng(11)
    Xp = s.X.reshape(-1, 3)
    out = []
    for A in (np.eye(3) + 0.3 * rng.standard_normal((3, 3)),
              np.diag([0.55, 0.7, 0.8]) + 0.05 * rng.standard_normal((3, 3))):
        x = (Xp @ A.T).ravel() + 0.002 * rng.standard_normal(s.ndofs)
        F = s.deformation_gradient(x - s.X)
        assert np.linalg.det(np.moveaxis(F, (0, 1), (-2, -1))).min() > 0.1  # admissible, with a margin
        out.append(x)
    return out


def numpy_path(monkeypatch, pot, x, project):
    """Energy, gradient and tangent of the numpy path."""
    with monkeypatch.context() as m:
        m.setenv(fused.ENV, "0")
        assert pot._fused() is None
        return pot.energy(x), pot.gradient(x), pot.hessian(x, project=project)


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
    pot = ElasticPotential(fe.NeoHookean(E, NU), space())
    x = states()[1]
    exact = pot.hessian(x).toarray()
    proj = pot.hessian(x, project=True).toarray()
    # precondition of the comparison test above: projection did something there
    assert np.abs(proj - exact).max() > 1e-3 * np.abs(exact).max()
    # a sum of PSD point contributions is PSD; eigenvalue round-off ~ eps * largest eigenvalue
    w = np.linalg.eigvalsh(0.5 * (proj + proj.T))
    assert w.min() >= -1e-12 * w.max()


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
    def solve():
        model = fe.Model(fe.beam_mesh(0.3, 0.1, 0.1, cells=(3, 1, 1)), 1000.0,
                         body=fe.ElasticBody(material_cls(E, NU), order=2), fixed="left",
                         traction={"right": (0.0, 0.0, -2.0e4)})
        return fe.solve_static(model)

    r = solve()
    with monkeypatch.context() as m:
        m.setenv(fused.ENV, "0")
        r_np = solve()
    u, u_np = r.displacement, r_np.displacement
    assert r.converged and r_np.converged
    assert r.iterations == r_np.iterations  # round-off apart tangents: the same Newton path
    assert np.abs(u).max() > 1e-3  # precondition: a visible deflection (m)
    # Newton stops at rtol 1e-8 on the residual; both paths converge to the same root and
    # the remaining difference is that tolerance times the compliance, well below 1e-7 relative
    assert np.abs(u - u_np).max() <= 1e-7 * np.abs(u).max()
