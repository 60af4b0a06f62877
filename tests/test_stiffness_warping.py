"""Tests of fem_elastic.physics.stiffness_warping: the warped force against the exact corotated
force (P1), rigid-motion invariance, the spectrum and symmetry of the warped matrix, its
rest-state value, and its covariance under a rigid rotation of the whole body.

All run on a small distorted mesh (12 tets of a 0.2 x 0.1 x 0.1 m box whose vertices are
moved by up to 20 % of the cell size), in P1 and P2.
"""

from functools import lru_cache

import numpy as np
import pytest
import scipy.sparse as sp
import skfem

import fem_elastic as fe
from fem_elastic.discretization import Discretization
from fem_elastic.physics.elastic_body import ElasticPotential
from fem_elastic.physics.stiffness_warping import WarpedStiffness

E, NU = 1.0e6, 0.4  # mu = 3.6e5 Pa, lam = 1.4e6 Pa
ORDERS = [1, 2]
SIZE = 0.2  # largest extent of the mesh (m)


@lru_cache(maxsize=None)
def space(order: int) -> Discretization:
    mesh = fe.beam_mesh(0.2, 0.1, 0.1, cells=(2, 1, 1))
    rng = np.random.default_rng(1)
    mesh = skfem.MeshTet(mesh.p + rng.uniform(-0.02, 0.02, mesh.p.shape), mesh.t)
    fe.validate_mesh(mesh)
    return Discretization(mesh, order)


def rotation(axis, angle) -> np.ndarray:
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    W = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * W + (1 - np.cos(angle)) * W @ W


Q = rotation([1.0, -2.0, 0.5], 2.3)  # a large rotation about a skew axis
T = np.array([0.4, -1.1, 2.5])  # and a translation (m)


def rigid(x: np.ndarray, Qm=Q, t=T) -> np.ndarray:
    return (x.reshape(-1, 3) @ Qm.T + t).ravel()


def deformed(order: int, scale: float = 0.02) -> np.ndarray:
    """X + a random displacement of `scale` m (up to ~40 % strain), then rotated and moved."""
    s = space(order)
    rng = np.random.default_rng(7 + order)
    return rigid(s.X + scale * rng.standard_normal(s.ndofs))


def warped(order: int, material=fe.Corotated) -> WarpedStiffness:
    return WarpedStiffness(space(order), material(E=E, nu=NU))


def blockdiag(Qm: np.ndarray, ndofs: int) -> sp.csr_matrix:
    return sp.kron(sp.identity(ndofs // 3), Qm, format="csr")


def dense(K) -> np.ndarray:
    return K.toarray() if sp.issparse(K) else np.asarray(K)


# (1) P1: the warped force is the exact corotated force ----------------------------------
def test_p1_gradient_is_exact_corotated_gradient():
    # For P1, R sigma_lin(R^T F) = P_corotated(F) exactly (R^T F symmetric), see the module
    # docstring; both sides are the same few dozen flops per element, so they agree to
    # round-off: ~1e-15 of the largest force.
    x = deformed(1)
    s = space(1)
    exact = ElasticPotential(fe.Corotated(E=E, nu=NU), s)
    g = warped(1).gradient(x)
    g_ref = exact.gradient(x)
    assert np.abs(g_ref).max() > 1e2  # a real load: forces of hundreds of N
    assert np.abs(g - g_ref).max() < 1e-12 * np.abs(g_ref).max()
    # and the energy is the corotated energy
    assert warped(1).energy(x) == pytest.approx(exact.energy(x), rel=1e-12)


def test_p1_exact_through_inversion():
    # Push one vertex through the opposite face: the signed SVD keeps R proper and the
    # identity R sigma_lin(S) = P still holds (S = V diag(s) V^T with s[2] < 0).
    s = space(1)
    x = s.X.copy()
    tet = s.mesh.t[:, 0]
    p = s.mesh.p[:, tet]
    face_centre = p[:, 1:].mean(axis=1)
    x[3 * tet[0]:3 * tet[0] + 3] = p[:, 0] + 1.6 * (face_centre - p[:, 0])  # through the face
    x = rigid(x)
    F = ElasticPotential(fe.Corotated(E=E, nu=NU), s).F(x)
    assert np.linalg.det(F[:, :, 0, 0]) < 0  # element 0 is inverted
    R = warped(1).rotations(x)
    assert np.allclose(np.linalg.det(np.moveaxis(R, -1, 0)), 1.0, atol=1e-12)
    g_ref = ElasticPotential(fe.Corotated(E=E, nu=NU), s).gradient(x)
    assert np.abs(warped(1).gradient(x) - g_ref).max() < 1e-12 * np.abs(g_ref).max()


def test_p1_gradient_matches_finite_differences_of_energy():
    # For P1 the dR/dx term cancels, so g is the gradient of the warped energy (module
    # docstring). Central differences with step 1e-7 m: truncation ~h^2 E''' ~ 1e-9 of g,
    # round-off ~eps E / h ~ 1e-10 N; 1e-6 relative leaves a wide margin.
    x = deformed(1)
    w = warped(1)
    rng = np.random.default_rng(3)
    v = rng.standard_normal(x.size)
    h = 1e-7
    fd = (w.energy(x + h * v) - w.energy(x - h * v)) / (2 * h)
    assert fd == pytest.approx(w.gradient(x) @ v, rel=1e-6)


def test_p2_affine_deformation_gives_exact_corotated_gradient():
    # Under an affine map F is constant in every element, so the P2 element's single
    # rotation is exact at every quadrature point and the P1 argument applies.
    s = space(2)
    A = Q @ np.array([[1.3, 0.2, -0.1], [0.0, 0.8, 0.15], [0.05, -0.1, 1.1]])
    x = (s.X.reshape(-1, 3) @ A.T + T).ravel()
    g_ref = ElasticPotential(fe.Corotated(E=E, nu=NU), s).gradient(x)
    assert np.abs(warped(2).gradient(x) - g_ref).max() < 1e-11 * np.abs(g_ref).max()


# (2) rigid motions are free --------------------------------------------------------------
@pytest.mark.parametrize("order", ORDERS)
def test_zero_force_under_rigid_motion(order):
    s = space(order)
    w = warped(order)
    x = rigid(s.X)
    g, K = w.linearize(x)
    # Round-off: entries of K (~E h ~ 1e5 N/m) times rounding of positions (~eps * 3 m)
    # ~ 1e-10 N; a real strain of 1e-6 would give ~1e-2 N.
    assert np.abs(g).max() < 1e-9 * abs(K).max() * SIZE
    assert w.energy(x) < 1e-20 * E * SIZE**3


# (3) K is symmetric PSD; six rigid-body zero modes at rest and under rigid motion ----------
@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("state", ["rest", "rigid", "deformed"])
def test_matrix_symmetric_psd_with_rigid_null_space(order, state):
    s = space(order)
    x = {"rest": s.X, "rigid": rigid(s.X), "deformed": deformed(order)}[state]
    K = dense(warped(order).hessian(x))
    assert np.abs(K - K.T).max() <= 1e-14 * np.abs(K).max()  # mirrored blocks: exact up to ulps
    lam = np.linalg.eigvalsh(K)
    tol = 1e-10 * lam[-1]  # round-off of a dense eigensolver is ~1e-15 lam_max
    assert lam[0] > -tol
    # Translations are always free. Rotations are free where every element sees the same
    # rigid frame (rest, rigid motion); a deformed state leaves the three rotation modes
    # with positive stiffness (they rotate the elements' strained shapes against K_e),
    # as the exact Hessian of any frame-indifferent energy does away from equilibrium.
    n_zero = int(np.sum(lam < tol))
    assert n_zero == (3 if state == "deformed" else 6)
    # the null space at the rest state is spanned by the rigid modes
    if state == "rest":
        B = s.rigid_body_modes()
        assert np.abs(K @ B).max() < 1e-9 * np.abs(K).max() * SIZE


# (4) at rest, K is the linear-elastic Hessian -----------------------------------------------
@pytest.mark.parametrize("order", ORDERS)
def test_rest_matrix_is_linear_elastic_hessian(order):
    s = space(order)
    g, K = warped(order).linearize(s.X)
    K_lin = ElasticPotential(fe.LinearElastic(E=E, nu=NU), s).hessian(s.X)
    assert s.pattern.owns(K)
    assert abs(K - K_lin).max() < 1e-12 * abs(K_lin).max()  # R = I to round-off
    assert np.abs(g).max() == 0.0  # R = I exactly at F = I, so d = 0 exactly


def test_only_lame_parameters_matter():
    # Any material with the same (mu, lam) gives the same scheme.
    x = deformed(1)
    a = warped(1, fe.NeoHookean).gradient(x)
    b = warped(1, fe.LinearElastic).gradient(x)
    assert np.array_equal(a, b)


# (5) covariance under a rigid rotation of the whole body -----------------------------------
@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("state", ["rest", "deformed"])
def test_rotation_covariance(order, state):
    # R_e(Q x) = Q R_e(x) (the polar rotation of Q F is Q R), so K(Q x) = Qb K(x) Qb^T
    # and g(Q x) = Qb g(x); both sides differ only by the rounding of the rotations.
    s = space(order)
    w = warped(order)
    x = s.X if state == "rest" else deformed(order)
    Q2 = rotation([0.3, 0.9, -0.4], -1.7)
    Qb = blockdiag(Q2, s.ndofs)
    g0, K0 = w.linearize(x)
    g1, K1 = w.linearize(rigid(x, Q2, np.zeros(3)))
    assert abs(K1 - Qb @ K0 @ Qb.T).max() < 1e-12 * abs(K0).max()
    if state == "deformed":
        assert np.abs(g1 - Qb @ g0).max() < 1e-11 * np.abs(g0).max()


def test_invalid_arguments():
    with pytest.raises(fe.InvalidParameter):
        WarpedStiffness(space(1), object())
    with pytest.raises(fe.InvalidParameter):
        WarpedStiffness(space(1).mesh, fe.Corotated(E=E, nu=NU))


# (6) the matrix-free product K(x) v (the damping force), fused (P1 with numba) and numpy ----
def _path(monkeypatch, path):
    if path == "numpy":
        monkeypatch.setenv("FEM_ELASTIC_NUMBA", "0")


@pytest.mark.parametrize("path", ["default", "numpy"])
@pytest.mark.parametrize("order", ORDERS)
def test_apply_is_the_assembled_matrix_times_v(order, path, monkeypatch):
    _path(monkeypatch, path)
    x = deformed(order)
    v = np.random.default_rng(4).standard_normal(x.size)
    w = warped(order)
    Kv = w.apply(x, v)
    Kv_ref = w.hessian(x) @ v
    assert np.abs(Kv - Kv_ref).max() < 1e-12 * np.abs(Kv_ref).max()


@pytest.mark.parametrize("path", ["default", "numpy"])
@pytest.mark.parametrize("order", ORDERS)
def test_apply_ignores_a_rigid_spin_at_any_orientation(order, path, monkeypatch):
    # x a rigid motion of the body, v the velocity of a rigid spin about a skew axis
    # through a point off the body: K(x) v vanishes to round-off (K(x) V ~ E h |v|
    # for a generic v of the same size).
    _path(monkeypatch, path)
    s = space(order)
    w = warped(order)
    x = rigid(s.X)
    omega = np.array([0.7, -1.3, 2.1])
    spin = np.cross(omega, x.reshape(-1, 3) - [0.5, 0.3, -0.2]).ravel()
    generic = np.random.default_rng(6).standard_normal(x.size) * np.abs(spin).max()
    assert np.abs(w.apply(x, spin)).max() < 1e-12 * np.abs(w.apply(x, generic)).max()
