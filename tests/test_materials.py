"""Tests of fem_elastic.materials: derivatives by finite differences, physics by closed forms."""

import math

import numpy as np
import pytest

import fem_elastic.materials as M
from fem_elastic.errors import InvalidParameter
from fem_elastic.materials.isotropic import isotropic_hessian
from fem_elastic.materials.svd import polar_rotation, signed_svd

E, NU = 1.0e6, 0.4  # a rubber-like solid; mu = 3.57e5 Pa, lam = 1.43e6 Pa

NONLINEAR = [M.StVK, M.NeoHookean, M.StableNeoHookean, M.Corotated]
ALL = [M.LinearElastic] + NONLINEAR
ISOTROPIC_ANALYTIC = [M.StVK, M.NeoHookean, M.StableNeoHookean]  # analytic C + eigensystem
I3 = np.eye(3)


def rotation(rng):
    """A uniformly random proper rotation (QR of a Gaussian matrix, signs fixed)."""
    Q, R = np.linalg.qr(rng.standard_normal((3, 3)))
    Q = Q * np.sign(np.diag(R))
    return Q * np.sign(np.linalg.det(Q))


def sample_F(seed=0):
    """Batch (3, 3, 2, 4) of deformation gradients with det F > 0: near I, far from I,
    and strongly compressed, with a rotation mixed in. Batch shape (nelems, nqp) = (2, 4)."""
    rng = np.random.default_rng(seed)
    Fs = []
    for scale in (0.05, 0.05, 0.3, 0.3, 0.5):
        while True:
            F = I3 + scale * rng.standard_normal((3, 3))
            if np.linalg.det(F) > 0.2:
                Fs.append(F)
                break
    Fs.append(rotation(rng) @ np.diag([0.4, 0.5, 0.6]))  # compressed to 12 % volume
    Fs.append(np.diag([0.3, 1.0, 1.0]))  # uniaxially crushed to 30 %
    Fs.append(rotation(rng) @ np.diag([1.8, 1.2, 0.7]) @ rotation(rng))  # large stretch
    return np.stack(Fs, axis=-1).reshape(3, 3, 2, 4)


def fd_gradient(f, F, h):
    """Central differences of f (batch-valued) w.r.t. each F_kl: (3, 3) + f(F).shape."""
    out = None
    for k in range(3):
        for l in range(3):
            Fp, Fm = F.copy(), F.copy()
            Fp[k, l] += h
            Fm[k, l] -= h
            d = (f(Fp) - f(Fm)) / (2.0 * h)
            if out is None:
                out = np.empty((3, 3) + d.shape)
            out[k, l] = d
    return out


# Step and tolerance of the central differences. F is O(1) (dimensionless), so
# h = 1e-6 is relative; the truncation error is O(h^2 * psi''') ~ 1e-12 * E and
# the round-off O(eps * psi / h) ~ 1e-16 * E / 1e-6 = 1e-10 * E. Compared with
# the stress scale E (1e6 Pa) a relative tolerance of 1e-6 has 4 decades of margin.
H = 1e-6
RTOL_FD = 1e-6


@pytest.mark.parametrize("cls", ALL)
def test_stress_is_gradient_of_energy(cls):
    m = cls(E=E, nu=NU)
    F = sample_F()
    P_fd = fd_gradient(m.psi, F, H)
    np.testing.assert_allclose(m.dpsi_dF(F), P_fd, rtol=0, atol=RTOL_FD * E)


@pytest.mark.parametrize("cls", ALL)
def test_tangent_is_gradient_of_stress(cls):
    m = cls(E=E, nu=NU)
    F = sample_F(1)
    C_fd = np.moveaxis(fd_gradient(m.dpsi_dF, F, H), (0, 1), (2, 3))  # C[i,j,k,l]=dP_ij/dF_kl
    C = m.d2psi_dF2(F)
    assert C.shape == (3, 3, 3, 3, 2, 4)
    np.testing.assert_allclose(C, C_fd, rtol=0, atol=RTOL_FD * E)
    # major symmetry C_ijkl = C_klij (a Hessian), to round-off of the O(E) entries
    np.testing.assert_allclose(C, np.moveaxis(C, (0, 1), (2, 3)), rtol=0, atol=1e-9 * E)


@pytest.mark.parametrize("cls", ALL)
def test_any_batch_shape(cls):
    m = cls(E=E, nu=NU)
    F = sample_F()
    F0 = F[..., 1, 2]
    assert m.psi(F0).shape == ()
    assert m.dpsi_dF(F0).shape == (3, 3)
    assert m.d2psi_dF2_psd(F0).shape == (3, 3, 3, 3)
    # the same point inside a batch gives the same numbers (to round-off)
    np.testing.assert_allclose(m.d2psi_dF2(F0), m.d2psi_dF2(F)[..., 1, 2], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(m.psi(F.reshape(3, 3, 8)), m.psi(F).ravel(), rtol=1e-13)


@pytest.mark.parametrize("cls", NONLINEAR)
def test_linearization_at_rest_is_linear_elasticity(cls):
    m, lin = cls(E=E, nu=NU), M.LinearElastic(E=E, nu=NU)
    I = I3[:, :, None]
    # round-off of entries of size lam + 2 mu ~ 2e6 Pa (SNH sums terms ~ lam')
    np.testing.assert_allclose(m.dpsi_dF(I), 0.0, atol=1e-9 * E)
    np.testing.assert_allclose(m.d2psi_dF2(I), lin.d2psi_dF2(I), rtol=0, atol=1e-9 * E)
    np.testing.assert_allclose(m.d2psi_dF2_psd(I), lin.d2psi_dF2(I), rtol=0, atol=1e-9 * E)


def test_stable_neohookean_parameters():
    m = M.StableNeoHookean(E=E, nu=NU)
    assert math.isclose(m.mu_snh, 4.0 / 3.0 * m.mu)
    assert math.isclose(m.lam_snh, m.lam + 5.0 / 6.0 * m.mu)
    assert math.isclose(m.alpha, 1.0 + 0.75 * m.mu_snh / m.lam_snh)


@pytest.mark.parametrize("cls", NONLINEAR)
def test_frame_indifference(cls):
    m = cls(E=E, nu=NU)
    rng = np.random.default_rng(3)
    F = sample_F()
    Q = np.stack([rotation(rng) for _ in range(8)], axis=-1).reshape(3, 3, 2, 4)
    QF = np.einsum("ik...,kj...->ij...", Q, F)
    # psi ~ E * strain^2 ~ 1e6 J/m^3: relative round-off 1e-10
    np.testing.assert_allclose(m.psi(QF), m.psi(F), rtol=1e-10, atol=1e-10 * E)
    # and P(QF) = Q P(F)
    np.testing.assert_allclose(
        m.dpsi_dF(QF), np.einsum("ik...,kj...->ij...", Q, m.dpsi_dF(F)), rtol=0, atol=1e-9 * E
    )


def test_linear_elastic_is_not_frame_indifferent():
    m = M.LinearElastic(E=E, nu=NU)
    c, s = math.cos(1.0), math.sin(1.0)
    Q = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    assert float(m.psi(I3)) == 0.0
    # a rigid rotation by 1 rad strains it by eps = cos(1) - 1 ~ -0.46 in two directions
    assert float(m.psi(Q)) > 0.1 * E


# --- closed forms under homogeneous deformation -------------------------------


def dilation_stress(m, s):
    """P_00 at F = s I, from the scalar energy of a pure dilation (hand-derived)."""
    mu, lam = m.mu, m.lam
    if isinstance(m, M.LinearElastic):
        return (2 * mu + 3 * lam) * (s - 1)
    if isinstance(m, M.StVK):
        e = 0.5 * (s * s - 1)
        return s * (2 * mu * e + 3 * lam * e)
    if isinstance(m, M.NeoHookean):
        return mu * (s - 1 / s) + lam * 3 * math.log(s) / s
    if isinstance(m, M.StableNeoHookean):
        return m.mu_snh * s * (1 - 1 / (3 * s * s + 1)) + m.lam_snh * (s**3 - m.alpha) * s * s
    if isinstance(m, M.Corotated):
        return 2 * mu * (s - 1) + lam * 3 * (s - 1)
    raise AssertionError(m)


@pytest.mark.parametrize("cls", ALL)
@pytest.mark.parametrize("s", [0.7, 1.3])
def test_dilation_stress_closed_form(cls, s):
    m = cls(E=E, nu=NU)
    P = m.dpsi_dF(s * I3)
    # hydrostatic: P = p I; round-off relative to the stress ~ E
    np.testing.assert_allclose(P, dilation_stress(m, s) * I3, rtol=1e-12, atol=1e-9 * E)


@pytest.mark.parametrize("cls", ALL)
def test_uniaxial_stretch_closed_form(cls):
    m = cls(E=E, nu=NU)
    mu, lam, a = m.mu, m.lam, 1.2  # F = diag(a, 1, 1)
    expected = {
        M.LinearElastic: ((2 * mu + lam) * (a - 1), lam * (a - 1)),
        M.StVK: (a * (mu + 0.5 * lam) * (a * a - 1), 0.5 * lam * (a * a - 1)),
        M.NeoHookean: (mu * (a - 1 / a) + lam * math.log(a) / a, lam * math.log(a)),
        M.Corotated: ((2 * mu + lam) * (a - 1), lam * (a - 1)),
    }
    if cls is M.StableNeoHookean:
        mp, lp, al = m.mu_snh, m.lam_snh, m.alpha
        g = 1 - 1 / (a * a + 3)
        expected[cls] = (mp * g * a + lp * (a - al), mp * g + lp * (a - al) * a)
    P = m.dpsi_dF(np.diag([a, 1.0, 1.0]))
    P00, P11 = expected[cls]
    np.testing.assert_allclose(np.diag(P), [P00, P11, P11], rtol=1e-12, atol=1e-9 * E)
    assert np.abs(P - np.diag(np.diag(P))).max() < 1e-9 * E


# --- PSD projection ------------------------------------------------------------


def eig9(C):
    """Eigenvalues of C (3,3,3,3,...) as 9x9 matrices: (..., 9)."""
    A = C.reshape((9, 9, -1))
    return np.linalg.eigvalsh(np.moveaxis(A, -1, 0))


def compressed_F():
    rng = np.random.default_rng(7)
    Fs = [rotation(rng) @ np.diag(d) @ rotation(rng) for d in
          ([0.4, 0.5, 0.6], [0.3, 0.9, 1.0], [0.5, 0.5, 0.5], [1.6, 0.6, 0.6])]
    return np.stack(Fs, axis=-1)


@pytest.mark.parametrize("cls", ALL)
def test_projection_is_psd(cls):
    m = cls(E=E, nu=NU)
    F = np.concatenate([sample_F().reshape(3, 3, 8), compressed_F()], axis=-1)
    # eigenvalues are O(E); eigvalsh round-off of a 9x9 is ~1e-15 * E
    assert eig9(m.d2psi_dF2_psd(F)).min() >= -1e-9 * E


@pytest.mark.parametrize("cls", ALL)
def test_projection_keeps_psd_tangent(cls):
    m = cls(E=E, nu=NU)
    rng = np.random.default_rng(11)
    # Rotated mild stretches: every twist eigenvalue is > 0 there. (Any compression,
    # however slight, makes some twist modes negative, since they are 0 at F = I.)
    F = np.stack(
        [rotation(rng) @ np.diag(1.0 + 0.05 * rng.random(3)) @ rotation(rng) for _ in range(6)], -1
    )
    C = m.d2psi_dF2(F)
    assert eig9(C).min() > -1e-9 * E  # C is PSD here (eigvalsh round-off ~1e-15 E)
    np.testing.assert_allclose(m.d2psi_dF2_psd(F), C, rtol=0, atol=1e-9 * E)


@pytest.mark.parametrize("cls", NONLINEAR)
def test_projection_changes_indefinite_tangent(cls):
    m = cls(E=E, nu=NU)
    F = compressed_F()
    C, Cp = m.d2psi_dF2(F), m.d2psi_dF2_psd(F)
    assert eig9(C).min() < -1e-3 * E  # really indefinite under compression
    assert np.abs(C - Cp).max() > 1e-3 * E
    # clamping moves only the negative part: C - Cp is PSD, Cp is PSD
    assert eig9(C - Cp).max() <= 1e-9 * E


@pytest.mark.parametrize("cls", ISOTROPIC_ANALYTIC)
def test_eigensystem_reconstructs_analytic_tangent(cls):
    """The unclamped singular-value eigensystem equals the analytic C to round-off,
    which validates the closed-form H, lam_twist and lam_flip (repeated s included)."""
    m = cls(E=E, nu=NU)
    F = np.concatenate(
        [sample_F(2).reshape(3, 3, 8), compressed_F(), I3[:, :, None], 1.1 * I3[:, :, None]],
        axis=-1,
    )
    U, s, V = signed_svd(F)
    H, lt, lf = m.singular_value_hessian(s)
    C = isotropic_hessian(U, s, V, H, lt, lf, clamp=False)
    # entries up to ~1e2 E at the most compressed points; round-off ~1e-13 of that
    np.testing.assert_allclose(C, m.d2psi_dF2(F), rtol=0, atol=1e-8 * E)


# --- inversion -----------------------------------------------------------------


def test_signed_svd_matches_lapack_and_handles_reflections():
    rng = np.random.default_rng(5)
    F = I3[:, :, None] + 0.5 * rng.standard_normal((3, 3, 200))
    F[:, :, :3] = I3[:, :, None]  # fully repeated singular values
    F[2, :, 3:50] *= -1.0  # reflections
    F[:, :, 50] = 0.0  # rank 0, via the LAPACK fallback
    F[:, :, 51] = np.outer([1.0, 2.0, 3.0], [1.0, 0.0, 1.0])  # rank 1
    U, s, V = signed_svd(F)
    rec = np.einsum("ia...,a...,ja...->ij...", U, s, V)
    np.testing.assert_allclose(rec, F, atol=1e-13)  # backward stable: eps * |F| ~ 1e-15
    np.testing.assert_allclose(np.linalg.det(np.moveaxis(U, -1, 0)), 1.0, atol=1e-13)
    np.testing.assert_allclose(np.linalg.det(np.moveaxis(V, -1, 0)), 1.0, atol=1e-13)
    s_ref = np.linalg.svd(np.moveaxis(F, -1, 0), compute_uv=False).T
    np.testing.assert_allclose(np.abs(s), s_ref, atol=1e-13)
    detF = np.linalg.det(np.moveaxis(F, -1, 0))
    assert np.all(np.sign(s[2][np.abs(detF) > 1e-12]) == np.sign(detF[np.abs(detF) > 1e-12]))


def test_corotated_inverted():
    m = M.Corotated(E=E, nu=NU)
    rng = np.random.default_rng(9)
    # inverted, with s_i + s_j well away from 0 (|s_2| = 0.4 << s_1 = 0.8)
    F = np.stack([rotation(rng) @ np.diag([1.1, 0.8, -0.4]) @ rotation(rng) for _ in range(4)], -1)
    R = polar_rotation(F)
    np.testing.assert_allclose(np.linalg.det(np.moveaxis(R, -1, 0)), 1.0, atol=1e-13)
    assert np.all(np.isfinite(m.psi(F)))
    np.testing.assert_allclose(m.dpsi_dF(F), fd_gradient(m.psi, F, H), atol=RTOL_FD * E)
    C_fd = np.moveaxis(fd_gradient(m.dpsi_dF, F, H), (0, 1), (2, 3))
    np.testing.assert_allclose(m.d2psi_dF2(F), C_fd, atol=RTOL_FD * E)
    assert eig9(m.d2psi_dF2_psd(F)).min() >= -1e-9 * E


def test_corotated_twist_clamp_keeps_tangent_finite():
    m = M.Corotated(E=E, nu=NU)
    F = np.diag([1.0, 0.5, -0.5])  # s_1 + s_2 = 0: R not differentiable there
    assert np.all(np.isfinite(m.d2psi_dF2(F)))
    assert np.all(np.isfinite(m.d2psi_dF2_psd(F)))


def test_neohookean_inadmissible_is_inf_without_warnings():
    m = M.NeoHookean(E=E, nu=NU)
    F = np.stack([np.diag([1.0, 1.0, -1.0]), np.zeros((3, 3)), I3], axis=-1)
    with np.errstate(all="raise"):  # any leaked floating-point warning becomes an error
        psi = m.psi(F)
        m.dpsi_dF(F)
        m.d2psi_dF2(F)
    assert psi[0] == np.inf and psi[1] == np.inf and psi[2] == 0.0


def test_stable_neohookean_finite_when_inverted():
    m = M.StableNeoHookean(E=E, nu=NU)
    F = np.stack([np.diag([1.0, 1.0, -1.0]), np.zeros((3, 3)), np.diag([0.5, 0.5, -0.2])], -1)
    with np.errstate(all="raise"):
        for f in (m.psi, m.dpsi_dF, m.d2psi_dF2, m.d2psi_dF2_psd):
            assert np.all(np.isfinite(f(F)))
    # the derivatives stay exact through inversion (the energy is a polynomial in F
    # plus a log of I_C + 1 >= 1)
    np.testing.assert_allclose(m.dpsi_dF(F), fd_gradient(m.psi, F, H), atol=RTOL_FD * E)


# --- parameters ----------------------------------------------------------------


@pytest.mark.parametrize("cls", ALL)
@pytest.mark.parametrize(
    "kwargs, bound",
    [
        (dict(E=0.0, nu=0.3), "> 0"),
        (dict(E=-1.0, nu=0.3), "> 0"),
        (dict(E=1e6, nu=-1.0), "> -1"),
        (dict(E=1e6, nu=0.5), "< 0.5"),
        (dict(E=1e6, nu=0.7), "< 0.5"),
        (dict(E=float("nan"), nu=0.3), "finite"),
        (dict(E=1e6, nu=float("inf")), "finite"),
        (dict(E="1e6", nu=0.3), "real number"),
    ],
)
def test_invalid_parameters(cls, kwargs, bound):
    with pytest.raises(InvalidParameter, match=bound):
        cls(**kwargs)


def test_lame_parameters_and_immutability():
    mu, lam = M.lame_parameters(E, NU)
    assert math.isclose(mu, E / (2 * (1 + NU)))
    assert math.isclose(lam, E * NU / ((1 + NU) * (1 - 2 * NU)))
    m = M.NeoHookean(E=E, nu=NU)
    with pytest.raises(AttributeError):
        m.E = 2.0


@pytest.mark.parametrize("cls", ISOTROPIC_ANALYTIC)
def test_projection_sparse_and_dense_paths_agree(cls):
    """project_psd rebuilds only the indefinite points when they are few, and every
    point when they are many; both must give the same numbers."""
    from fem_elastic.materials import isotropic

    m = cls(E=E, nu=NU)
    rng = np.random.default_rng(13)
    stretched = [rotation(rng) @ np.diag(1.0 + 0.05 * rng.random(3)) for _ in range(10)]
    F = np.concatenate([np.stack(stretched, -1), compressed_F()[..., :1]], axis=-1)  # 1 of 11
    sparse = m.d2psi_dF2_psd(F)
    old = isotropic.DENSE_FRACTION
    try:
        isotropic.DENSE_FRACTION = 0.0
        dense = m.d2psi_dF2_psd(F)
    finally:
        isotropic.DENSE_FRACTION = old
    np.testing.assert_allclose(sparse, dense, rtol=0, atol=1e-8 * E)  # round-off of O(E) sums
    assert np.abs(sparse[..., -1] - m.d2psi_dF2(F)[..., -1]).max() > 1e-3 * E
