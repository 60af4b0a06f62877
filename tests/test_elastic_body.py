"""Tests of fem_elastic.physics.elastic_body: the vectorized kernel against plain scikit-fem forms,
finite differences, PSD projection, admissibility, the CSR pattern and invariance.

Every test runs on a small distorted mesh (12 tets of a 2x1x1 box whose vertices are moved
by up to 20 % of the cell size), in P1 and P2, at a random admissible deformed state.
"""

from functools import lru_cache

import numpy as np
import pytest
import scipy.sparse as sp
import skfem

import fem_elastic as fe
from fem_elastic.discretization import Discretization
from fem_elastic.physics.elastic_body import ElasticPotential
from fem_elastic.discretization.skfem_forms import assemble_reference

E, NU = 1.0e6, 0.4  # rubber-like; mu = 3.6e5 Pa, lam = 1.4e6 Pa
MATERIALS = [fe.LinearElastic, fe.StVK, fe.NeoHookean, fe.StableNeoHookean, fe.Corotated]
ORDERS = [1, 2]
H_CELL = 0.1  # cell size of the mesh (m)


def ids(cls):
    return cls.__name__


@lru_cache(maxsize=None)
def distorted_space(order: int) -> Discretization:
    """P1/P2 space on a 0.2 x 0.1 x 0.1 m box of 12 tets, vertices moved by <= 0.02 m."""
    mesh = fe.beam_mesh(0.2, 0.1, 0.1, cells=(2, 1, 1))
    rng = np.random.default_rng(1)
    mesh = skfem.MeshTet(mesh.p + rng.uniform(-0.02, 0.02, mesh.p.shape), mesh.t)
    fe.validate_mesh(mesh)  # still positively oriented (min volume ~0.6 of the mean)
    return Discretization(mesh, order)


def det3(F):
    return np.linalg.det(np.moveaxis(F, (0, 1), (-2, -1)))


@lru_cache(maxsize=None)
def random_state(order: int) -> np.ndarray:
    """x = X + random displacement of ~10 % of the cell size; det F in ~[0.8, 1.3].

    Large enough that most quadrature points of the nonlinear materials have an
    indefinite tangent (so the projection does something), small enough that
    no element inverts.
    """
    space = distorted_space(order)
    rng = np.random.default_rng(2 + order)
    while True:
        x = space.X + 0.01 * rng.standard_normal(space.ndofs)
        if det3(space.deformation_gradient(x - space.X)).min() > 0.5:
            x.setflags(write=False)
            return x


def potential(material_cls, order) -> ElasticPotential:
    return ElasticPotential(material_cls(E=E, nu=NU), distorted_space(order))


@lru_cache(maxsize=None)
def reference(material_cls, order, project):
    return assemble_reference(distorted_space(order), material_cls(E=E, nu=NU),
                              random_state(order), project=project)


def rel_err(a, b) -> float:
    """max |a - b| / max |b| for arrays or sparse matrices."""
    if sp.issparse(a) or sp.issparse(b):
        return abs(sp.csr_matrix(a) - sp.csr_matrix(b)).max() / abs(sp.csr_matrix(b)).max()
    a, b = np.asarray(a), np.asarray(b)
    return float(np.abs(a - b).max() / np.abs(b).max())


# (a) kernel == plain scikit-fem forms ------------------------------------------------------
# Both sum exactly the same quadrature terms (same basis, same points, same weights, same
# material calls); only the order of the floating-point additions differs, so they agree to
# a few ulps of the largest entry. 1e-12 relative leaves a factor ~1e3 of margin over the
# ~2e-16 .. 7e-16 observed.
ROUNDOFF = 1e-12


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("material_cls", MATERIALS, ids=ids)
def test_kernel_matches_skfem_forms(material_cls, order):
    pot = potential(material_cls, order)
    x = random_state(order)
    e_ref, g_ref, K_ref = reference(material_cls, order, False)
    _, _, Kp_ref = reference(material_cls, order, True)
    assert abs(pot.energy(x) - e_ref) <= ROUNDOFF * abs(e_ref)
    assert rel_err(pot.gradient(x), g_ref) <= ROUNDOFF
    assert rel_err(pot.hessian(x), K_ref) <= ROUNDOFF
    assert rel_err(pot.hessian(x, project=True), Kp_ref) <= ROUNDOFF
    for project, K_expected in ((False, K_ref), (True, Kp_ref)):
        g, K = pot.linearize(x, project=project)
        assert rel_err(g, g_ref) <= ROUNDOFF
        assert rel_err(K, K_expected) <= ROUNDOFF
    if material_cls in (fe.StVK, fe.NeoHookean, fe.StableNeoHookean):
        # the state is compressed enough that the projection changes the tangent
        assert rel_err(Kp_ref, K_ref) > 1e-3


# (b) central finite differences ---------------------------------------------------------------
# Directions d have entries of the cell size times N(0, 1), so h d perturbs F by ~h; with
# h = 1e-6 the truncation error is O(h^2) ~ 1e-12 relative and the cancellation error of the
# energy differences is ~eps |E| / (h |dE|) ~ 1e-10 relative. 1e-6 is far above both and far
# below any real error (a wrong term is O(1) relative).
FD_H = 1e-6
FD_TOL = 1e-6


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("material_cls", MATERIALS, ids=ids)
def test_gradient_and_hessian_by_central_differences(material_cls, order):
    pot = potential(material_cls, order)
    x = random_state(order)
    g, K = pot.linearize(x)
    rng = np.random.default_rng(7)
    for _ in range(3):
        d = H_CELL * rng.standard_normal(x.size)
        slope_fd = (pot.energy(x + FD_H * d) - pot.energy(x - FD_H * d)) / (2 * FD_H)
        assert abs(slope_fd - g @ d) <= FD_TOL * np.abs(g).sum() * np.abs(d).max()
        Kd_fd = (pot.gradient(x + FD_H * d) - pot.gradient(x - FD_H * d)) / (2 * FD_H)
        assert rel_err(Kd_fd, K @ d) <= FD_TOL


# (c) PSD projection -------------------------------------------------------------------------
@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("material_cls", MATERIALS, ids=ids)
def test_projected_hessian_is_psd(material_cls, order):
    pot = potential(material_cls, order)
    x = random_state(order)
    K = pot.hessian(x, project=True).toarray()
    assert np.array_equal(K, K.T) or rel_err(K, K.T) <= ROUNDOFF
    w = np.linalg.eigvalsh(0.5 * (K + K.T))
    # a sum of PSD element matrices: negative only by round-off of the largest eigenvalue
    assert w.min() >= -1e-12 * w.max()
    # clamping adds a PSD matrix at every point, so K_psd - K is PSD and the smallest
    # eigenvalue can only go up (the exact K is indefinite here for NeoHookean, P1)
    w_exact = np.linalg.eigvalsh(pot.hessian(x).toarray())
    assert w.min() >= w_exact.min() - 1e-12 * w.max()
    if material_cls is fe.NeoHookean and order == 1:
        assert w_exact.min() < -1e-6 * w_exact.max()


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("material_cls", MATERIALS, ids=ids)
def test_projection_is_identity_in_pure_stretch(material_cls, order):
    space = distorted_space(order)
    pot = potential(material_cls, order)
    x = (space.X.reshape(-1, 3) @ np.diag([1.15, 1.10, 1.05])).ravel()  # F = diag exactly
    C = pot.material.d2psi_dF2(pot.F(x))
    w = np.linalg.eigvalsh(np.moveaxis(C.reshape(9, 9, -1), -1, 0))
    assert w.min() >= -1e-12 * w.max()  # precondition: C is PSD at every point
    assert rel_err(pot.hessian(x, project=True), pot.hessian(x)) <= ROUNDOFF


# (d) inadmissible states ------------------------------------------------------------------
@pytest.mark.parametrize("order", ORDERS)
def test_inverted_neohookean_energy_is_inf_not_nan(order):
    space = distorted_space(order)
    pot = potential(fe.NeoHookean, order)
    mirrored = space.X.reshape(-1, 3) * np.array([1.0, 1.0, -1.0])  # every element inverted
    flat = space.X.reshape(-1, 3) * np.array([1.0, 1.0, 0.0])  # every element J = 0
    one = space.X.reshape(-1, 3).copy()
    v = space.mesh.t[0, 0]  # push one vertex of element 0 through its opposite face
    opposite = space.mesh.p[:, space.mesh.t[1:, 0]].mean(axis=1)
    one[v] = space.mesh.p[:, v] + 2.0 * (opposite - space.mesh.p[:, v])
    assert det3(pot.F(one.ravel())).min() < 0
    for y in (mirrored, flat, one):
        e = pot.energy(y.ravel())
        assert e == np.inf


# (e) CSR pattern assembly ------------------------------------------------------------------
@pytest.mark.parametrize("order", ORDERS)
def test_pattern_assembly_equals_coo_sum(order):
    space = distorted_space(order)
    ed = space.element_dofs
    n = ed.shape[0]
    Ke = np.random.default_rng(3).standard_normal((n, n, ed.shape[1]))
    A = space.pattern.assemble(Ke)
    rows = np.broadcast_to(ed[:, None, :], Ke.shape).ravel()
    cols = np.broadcast_to(ed[None, :, :], Ke.shape).ravel()
    B = sp.coo_matrix((Ke.ravel(), (rows, cols)), shape=A.shape).tocsr()
    B.sum_duplicates()
    B.sort_indices()
    assert A.has_sorted_indices and A.nnz == B.nnz
    np.testing.assert_array_equal(A.indptr, B.indptr)
    np.testing.assert_array_equal(A.indices, B.indices)
    assert np.abs(A.data - B.data).max() <= 1e-13 * np.abs(B.data).max()


# (f) rest state and rigid motions ------------------------------------------------------------
FORCE_SCALE = E * H_CELL**2  # N: the nodal force of an O(1) strain


def rotation(angle, axis):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    Kx = np.cross(np.eye(3), axis)
    return np.eye(3) + np.sin(angle) * Kx + (1 - np.cos(angle)) * Kx @ Kx


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("material_cls", MATERIALS, ids=ids)
def test_rest_state_and_rigid_motions(material_cls, order):
    space = distorted_space(order)
    pot = potential(material_cls, order)
    volume = space.dx.sum()
    Xp = space.X.reshape(-1, 3)
    # psi(I) = 0 for every material (StableNeoHookean subtracts the paper's rest constant)
    e_rest = float(pot.material.psi(np.eye(3))) * volume
    assert e_rest == 0.0
    assert abs(pot.energy(space.X) - e_rest) <= 1e-14 * E * volume
    assert np.abs(pot.gradient(space.X)).max() <= 1e-14 * FORCE_SCALE
    # grad of a translation is sum_a t dN_a = 0 up to round-off eps |t| / h
    translated = (Xp + np.array([0.3, -0.2, 0.5])).ravel()
    assert abs(pot.energy(translated) - e_rest) <= 1e-12 * E * volume
    assert np.abs(pot.gradient(translated)).max() <= 1e-12 * FORCE_SCALE
    R = rotation(0.6, (1.0, 2.0, 3.0))  # a 34 degree rotation
    rotated = (Xp @ R.T + np.array([0.1, 0.0, -0.1])).ravel()
    f_rot = np.abs(pot.gradient(rotated)).max()
    if material_cls is fe.LinearElastic:
        # not frame indifferent: eps = sym(R) - I != 0 gives a spurious force
        assert f_rot > 1e-3 * FORCE_SCALE
    else:
        assert abs(pot.energy(rotated) - e_rest) <= 1e-12 * E * volume
        assert f_rot <= 1e-12 * FORCE_SCALE
