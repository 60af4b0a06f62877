"""Tests of fem_elastic.discretization._fused_tangent_kernels: the fused P1 tangent.

The fused Hessian of ``ElasticPotential`` (element by element, scattered into the CSR
data) must equal the numpy path (``Material.d2psi_dF2`` / ``d2psi_dF2_psd`` at the
points, element matrices, ``SparsityPattern.assemble``) for every registered material,
exact and projected, on a small distorted mesh; be the derivative of the fused gradient
(central differences); and leave a Newton solve unchanged. Tests that need numba are skipped without it.
"""

import numpy as np
import pytest
from test_fused import E, NU, REGISTERED, ids, needs_numba, space  # space(): 72 distorted P1 tets

import fem_elastic as fe
from fem_elastic.discretization import Discretization, fused
from fem_elastic.physics.elastic_body import ElasticPotential

# Both paths evaluate the same closed forms in a different order of operations (and the
# fused one sums the element matrices in another order): they differ by round-off, a few
# eps times the largest entry, far below 1e-12 relative to the matrix's norm.
RTOL = 1e-12


def states(s: Discretization | None = None, noise: float = 0.003) -> list[np.ndarray]:
    """A stretched-sheared-rotated state and a compressed one (indefinite tangents), J > 0.

    On ``s`` (default: the P1 ``space()``), plus nodal noise of ``noise`` m (tests/test_fused_p2.py
    takes these states on its P2 space).
    """
    s = space() if s is None else s
    rng = np.random.default_rng(11)
    Xp = s.X.reshape(-1, 3)
    out = []
    for A in (np.eye(3) + 0.3 * rng.standard_normal((3, 3)),
              np.diag([0.55, 0.7, 0.8]) + 0.05 * rng.standard_normal((3, 3))):
        x = (Xp @ A.T).ravel() + noise * rng.standard_normal(s.ndofs)
        F = s.deformation_gradient(x - s.X)
        assert np.linalg.det(np.moveaxis(F, (0, 1), (-2, -1))).min() > 0.1  # admissible (J > 0 with a margin)
        out.append(x)
    return out


def numpy_path(monkeypatch, pot, x, project):
    """Energy, gradient and tangent of the numpy path (``FEM_ELASTIC_NUMBA=0``)."""
    with monkeypatch.context() as m:
        m.setenv(fused.ENV, "0")
        assert pot._fused() is None
        return pot.energy(x), pot.gradient(x), pot.hessian(x, project=project)


def numpy_hessian(monkeypatch, pot, x, project):
    return numpy_path(monkeypatch, pot, x, project)[2]


def assert_projection_exercised_and_psd(pot, x):
    """The projected tangent differs from the exact one at x, and is PSD to round-off."""
    exact = pot.hessian(x).toarray()
    proj = pot.hessian(x, project=True).toarray()
    # precondition of the comparison tests: projection did something there
    assert np.abs(proj - exact).max() > 1e-3 * np.abs(exact).max()
    # a sum of PSD element (point) contributions is PSD; eigenvalue round-off ~ eps * largest eigenvalue
    w = np.linalg.eigvalsh(0.5 * (proj + proj.T))
    assert w.min() >= -1e-12 * w.max()


def assert_newton_unchanged(material_cls, order, cells, monkeypatch):
    """A 0.3 m cantilever of ``cells`` under a tip load, solved by Newton on both paths: the same equilibrium."""
    def solve():
        model = fe.Model(fe.beam_mesh(0.3, 0.1, 0.1, cells=cells), 1000.0,
                         body=fe.ElasticBody(material_cls(E, NU), order=order), fixed="left",
                         traction={"right": (0.0, 0.0, -2.0e4)})
        return fe.solve_static(model)

    r = solve()
    with monkeypatch.context() as m:
        m.setenv(fused.ENV, "0")
        r_np = solve()
    u, u_np = r.displacement, r_np.displacement
    assert r.converged and r_np.converged
    assert r.iterations == r_np.iterations  # round-off apart tangents: the same Newton path
    assert np.abs(u).max() > 1e-3  # precondition: a visibly nonlinear deflection (m)
    # Newton stops at rtol 1e-8 on the residual; both paths converge to the same root and
    # the remaining difference is that tolerance times the compliance, well below 1e-7 relative
    assert np.abs(u - u_np).max() <= 1e-7 * np.abs(u).max()


@needs_numba
@pytest.mark.parametrize("project", [False, True], ids=["exact", "projected"])
@pytest.mark.parametrize("material_cls", REGISTERED, ids=ids)
def test_fused_tangent_matches_the_numpy_path(material_cls, project, monkeypatch):
    pot = ElasticPotential(material_cls(E, NU), space())
    assert pot._fused() is not None
    for x in states():
        H = pot.hessian(x, project=project)
        H_np = numpy_hessian(monkeypatch, pot, x, project)
        assert space().pattern.owns(H)
        d = (H - H_np).toarray()
        assert np.abs(d).max() <= RTOL * np.abs(H_np.toarray()).max()


@needs_numba
def test_projection_is_exercised_and_psd():
    """The compressed state has indefinite Neo-Hookean tangents: the projection changes them."""
    assert_projection_exercised_and_psd(ElasticPotential(fe.NeoHookean(E, NU), space()), states()[1])


@needs_numba
@pytest.mark.parametrize("material_cls", REGISTERED, ids=ids)
def test_fused_tangent_is_the_derivative_of_the_fused_gradient(material_cls):
    pot = ElasticPotential(material_cls(E, NU), space())
    rng = np.random.default_rng(3)
    for x in states():
        v = rng.standard_normal(space().ndofs)
        h = 1e-6  # m: central difference error ~ h^2 |g'''| vs round-off eps |g| / h
        fd = (pot.gradient(x + h * v) - pot.gradient(x - h * v)) / (2 * h)
        Hv = pot.hessian(x) @ v
        # truncation O(h^2 / L^2) ~ 1e-10 relative for strains of O(1) on 0.1 m elements,
        # round-off eps |g| / h ~ 1e-10 relative: 1e-6 leaves a margin of 10^4
        assert np.linalg.norm(Hv - fd) <= 1e-6 * np.linalg.norm(Hv)


@needs_numba
def test_linearize_uses_the_fused_tangent(monkeypatch):
    pot = ElasticPotential(fe.StableNeoHookean(E, NU), space())
    x = states()[0]
    g, H = pot.linearize(x, project=True)
    assert np.array_equal(g, pot.gradient(x))
    assert np.array_equal(H.data, pot.hessian(x, project=True).data)
    with monkeypatch.context() as m:
        m.setenv(fused.ENV, "0")
        g_np, H_np = pot.linearize(x, project=True)
    assert np.linalg.norm(g - g_np) <= RTOL * np.linalg.norm(g_np)
    assert np.abs((H - H_np).toarray()).max() <= RTOL * np.abs(H_np.toarray()).max()


@needs_numba
def test_inverted_neohookean_element_gives_nan_as_the_numpy_path(monkeypatch):
    s = space()
    pot = ElasticPotential(fe.NeoHookean(E, NU), s)
    x = s.X.copy()
    n0 = s.element_dofs[0, 0] // 3
    x[3 * n0:3 * n0 + 3] += 1.0  # drags a vertex 1 m away: its first tet inverts
    for project in (False, True):
        H = pot.hessian(x, project=project)
        H_np = numpy_hessian(monkeypatch, pot, x, project)
        assert np.array_equal(np.isnan(H.data), np.isnan(H_np.data))
        assert np.isnan(H.data).any()


@needs_numba
@pytest.mark.parametrize("material_cls", [fe.NeoHookean, fe.StVK], ids=ids)
def test_newton_result_unchanged(material_cls, monkeypatch):
    """A P1 cantilever under a tip load solved by Newton on both paths: the same equilibrium."""
    assert_newton_unchanged(material_cls, 1, (3, 2, 2), monkeypatch)


def test_hessian_without_numba_is_the_numpy_assembly(monkeypatch):
    """As if numba were not installed: hessian and linearize take the numpy path."""
    monkeypatch.delenv(fused.ENV, raising=False)
    monkeypatch.setattr(fused, "_module", None)
    monkeypatch.setattr(fused, "_import_error", ImportError("No module named 'numba'"))
    pot = ElasticPotential(fe.NeoHookean(E, NU), space())
    assert pot._fused() is None
    x = states()[1]
    for project in (False, True):
        C = pot.material.d2psi_dF2_psd(pot.F(x)) if project else pot.material.d2psi_dF2(pot.F(x))
        expected = space().pattern.assemble(pot.element_stiffness(C))
        np.testing.assert_array_equal(pot.hessian(x, project=project).data, expected.data)
        np.testing.assert_array_equal(pot.linearize(x, project=project)[1].data, expected.data)


@needs_numba
@pytest.mark.parametrize("material_cls", REGISTERED, ids=ids)
def test_pointwise_tangents_match_the_materials(material_cls):
    """dP/dF and its PSD projection at single points, incl. repeated singular values (F = I,
    uniaxial compression: degenerate eigenvalues) and random F, against the material module."""
    from fem_elastic.discretization import _fused_tangent_kernels as tk

    m = material_cls(E, NU)
    kern = fused.registry()[material_cls]
    rng = np.random.default_rng(5)
    Fs = [np.eye(3), np.diag([0.6, 1.0, 1.0]), np.diag([0.7, 0.7, 0.7]), np.diag([1.3, 0.9, 0.9])]
    Fs += [np.eye(3) + 0.3 * rng.standard_normal((3, 3)) for _ in range(20)]
    F = np.stack(Fs, axis=-1)
    assert np.linalg.det(np.moveaxis(F, -1, 0)).min() > 0
    for project in (False, True):
        out = np.empty((F.shape[-1], 9, 9))
        tk.tangent_points(kern.kind, np.ascontiguousarray(F.reshape(9, -1)), kern.params(m),
                          project, out)
        ref = m.d2psi_dF2_psd(F) if project else m.d2psi_dF2(F)
        ref = np.moveaxis(ref.reshape(81, -1), -1, 0).reshape(-1, 9, 9)
        # round-off of a few eps of the largest entry (2 mu + lam ~ 1e6 Pa)
        assert np.abs(out - ref).max() <= RTOL * np.abs(ref).max()
