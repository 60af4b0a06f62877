"""Fuzzing the materials with hypothesis: random F, including near-singular, inverted and
strongly stretched ones, and random (E, nu).

Properties, for every material the package exports:

- ``psi`` is finite or ``+inf``, never NaN and never ``-inf``;
- ``dpsi_dF`` is finite wherever ``psi`` is finite (and the stress itself, of size
  ``S / ell`` in the error model below, is within the float range); where ``psi`` is ``+inf`` (only
  :class:`NeoHookean`, at ``det F <= 0``) no entry of ``P`` is finite, as documented
  (``P`` and ``C`` are NaN there: no finite but meaningless stress is returned);
- ``dpsi_dF`` matches central differences of ``psi``, and ``d2psi_dF2`` central
  differences of ``dpsi_dF``, within the error model below;
- ``d2psi_dF2_psd`` is symmetric positive semi-definite as a 9x9 matrix, and equal to
  ``d2psi_dF2`` where that is already PSD;

and through the assembled body (:class:`fe.ElasticBody` on one tet, P1 and P2):
``Model.energy`` is finite or ``+inf``, never NaN, and ``Model.gradient`` matches
central differences of it wherever it is finite.

Error model of the central differences
--------------------------------------
Each energy is a sum of terms whose size is at most ``S`` (Pa) and whose
derivatives vary over a distance ``ell`` in F (dimensionless): the k-th derivative
is at most ~ ``S / ell^k``. ``S`` and ``ell`` per material are in :func:`scales`
(e.g. Neo-Hookean: ``ell`` = the smallest singular value, since ``F^-T`` and
``ln J`` change on that scale; Corotated: ``ell = s_1 + s_2``, the distance to
the set where the polar rotation is not differentiable). psi as computed carries
a round-off ``eps R``: ``R = S`` for most energies, more where ``det F`` cancels
(``J`` has an absolute error ``eps sum |cof F : F|``, which is ``1e7 eps J`` at
``J ~ 1e-7``, and Neo-Hookean's ``ln J`` turns it into an absolute ``eps kappa``)
or where the polar rotation is ill-conditioned (Corotated, ``|F| / ell``).
A central difference with step ``h`` then has

- round-off ~ ``eps R / h``, and
- truncation ~ ``h^2 S / ell^3`` (the remainder ``h^2 f''' / 6``),

balanced at ``h = (eps R ell^3 / 2 S)^(1/3)`` (at most ``ell / 10``); for ``R = S``
that is ``h ~ 5e-6 ell`` and a total ~ ``eps^(2/3) S / ell``, a relative accuracy of
~1e-10 against a derivative of size up to ``S / ell``. Comparing ``dpsi_dF`` with
it, a difference is accepted up to

    FD_SAFETY * (eps R / h + h^2 S / ell^3 + eps |F| S / 2 ell^2) + (RTOL + 10 eps kappa) |P|,

where ``h >= 8 eps |F|`` so that ``F +- h`` differ from F, the third term is the
first-order error left by the realized steps ``fl(F + h) - F`` and ``F - fl(F - h)``
differing by up to ``eps |F|`` (the difference is divided by their sum), and the
last is the analytic formula's own round-off (``RTOL = 1e-8``
relative; Neo-Hookean divides by ``J``, which is off by ``eps kappa``). The tangent
is checked the same way one derivative up (divided by ``ell`` once more).
``FD_SAFETY = 30``: over 20000 random examples the worst error was 0.28 times the
model's estimate (which leaves out constants such as the 1/6 of the remainder), so
the model is a true bound and 30 leaves a 10x margin; a wrong term (a sign, a
missing factor 2) is an error of the size of the derivative itself, ``~ S / ell``,
some 1e8 times the bound.
"""

import math
from typing import NamedTuple

import numpy as np
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

import fem_elastic as fe
import fem_elastic.materials as M
from fem_elastic.materials.corotated import TWIST_EPS

#: every material the package exports (so a new one is fuzzed without editing this file)
MATERIALS = [
    getattr(M, name) for name in M.__all__
    if isinstance(getattr(M, name), type) and issubclass(getattr(M, name), M.Material)
    and getattr(M, name) is not M.Material
]
#: materials whose psi is +inf somewhere (a barrier): Neo-Hookean at det F <= 0
BARRIER = {M.NeoHookean}

EPS = np.finfo(float).eps
FD_SAFETY = 30.0  # worst measured error / model estimate: 0.28 (module docstring)
RTOL = 1e-8  # round-off of the analytic stress/tangent relative to its own size
# Eigenvalues of the projected tangent: eigvalsh is backward stable, so a PSD 9x9 matrix
# gets eigenvalues >= -(a few) n eps ||C||; 1e-12 ||C|| is ~500 eps with n = 9.
PSD_TOL = 1e-12

SETTINGS = dict(deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


def test_every_exported_material_is_fuzzed():
    """The list above really picks up the package's materials (five today)."""
    assert {m.__name__ for m in MATERIALS} >= {
        "LinearElastic", "StVK", "NeoHookean", "StableNeoHookean", "Corotated"}


# ---------------------------------------------------------------------------------------
# strategies


def _rotation(q) -> np.ndarray:
    """Rotation matrix of the (not necessarily unit) quaternion q; identity for q ~ 0."""
    q = np.asarray(q, dtype=float)
    n = np.linalg.norm(q)
    if n < 1e-3:
        return np.eye(3)
    w, x, y, z = q / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


quaternions = st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4)
log_floats = st.floats(-1.0, 1.0)


def _stretch(lo: float, hi: float):
    """A singular value log-uniform in [10^lo, 10^hi]."""
    return st.floats(lo, hi).map(lambda e: 10.0 ** e)


@st.composite
def singular_values(draw):
    """Three (signed) principal stretches from one of the regimes that break materials."""
    kind = draw(st.sampled_from(
        ["near_identity", "moderate", "large", "near_singular", "inverted", "inverted_tiny",
         "repeated", "singular"]))
    if kind == "near_identity":
        s = [1.0 + draw(st.floats(-1e-3, 1e-3)) for _ in range(3)]
    elif kind == "moderate":
        s = [draw(_stretch(-0.7, 0.7)) for _ in range(3)]
    elif kind == "large":  # up to 100x stretch, the others anything from crushed to stretched
        s = [draw(_stretch(0.5, 2.0)), draw(_stretch(-1.0, 2.0)), draw(_stretch(-1.0, 2.0))]
    elif kind == "near_singular":  # det F ~ 1e-8: one direction crushed to ~1e-8
        s = [draw(_stretch(-0.3, 0.5)), draw(_stretch(-0.3, 0.5)), draw(_stretch(-9.0, -7.0))]
    elif kind == "inverted":
        s = [draw(_stretch(-1.0, 1.0)), draw(_stretch(-1.0, 1.0)), -draw(_stretch(-1.0, 0.5))]
    elif kind == "inverted_tiny":  # just through the singular state
        s = [draw(_stretch(-0.3, 0.5)), draw(_stretch(-0.3, 0.5)), -draw(_stretch(-9.0, -7.0))]
    elif kind == "repeated":  # equal stretches: the eigensystem formulas must not divide by 0
        a = draw(_stretch(-1.0, 1.0))
        s = [a, a, draw(st.sampled_from([a, -a, 1.0]))]
    else:  # exactly singular: crushed flat
        s = [draw(_stretch(-0.5, 0.5)), draw(_stretch(-0.5, 0.5)), 0.0]
    return np.array(s)


@st.composite
def deformation_gradients(draw):
    """F = U diag(s) V^T with random rotations, or a general matrix of random entries."""
    if draw(st.booleans()):
        U, V = _rotation(draw(quaternions)), _rotation(draw(quaternions))
        s = draw(singular_values())
        return U @ np.diag(s) @ V.T
    return np.array(draw(st.lists(st.floats(-3.0, 3.0), min_size=9, max_size=9))).reshape(3, 3)


@st.composite
def materials(draw, classes=tuple(MATERIALS)):
    cls = draw(st.sampled_from(classes))
    E = 10.0 ** draw(st.floats(3.0, 12.0))  # Pa: foam to diamond
    nu = draw(st.floats(-0.99, 0.4999))
    return cls(E=E, nu=nu)


# ---------------------------------------------------------------------------------------
# the error model


def _signed_singular_values(F: np.ndarray) -> np.ndarray:
    """s0 >= s1 >= |s2|, sign(s2) = sign(det F).

    LAPACK gives s2 only to an absolute eps s0; below that, ``|det F| / (s0 s1)`` may be
    the better (smaller) estimate (F = [[0, 0, 1e-308], ...] has s2 ~ 1e-308, not the
    2e-16 LAPACK returns): the smaller of the two is taken, which only makes the error
    model more cautious.
    """
    s = np.linalg.svd(F, compute_uv=False)
    c = np.abs(F).max()
    rdet = _relative_det(F)
    if s[1] > 0:
        with np.errstate(all="ignore"):
            s[2] = min(s[2], abs(rdet) * c / ((s[0] / c) * (s[1] / c)))
    if rdet < 0:
        s[2] = -s[2]
    return s


class Scales(NamedTuple):
    """The error model's sizes at one F (see the module docstring)."""

    S: float  #: Pa, bound on the terms of psi: the k-th derivative is <~ S / ell^k
    R: float  #: Pa, round-off of psi as computed, over eps (S, or more where det F cancels)
    ell: float  #: distance in F (dimensionless) over which the derivatives change by O(1)
    kappa: float  #: condition number of det F, sum |cof F : F| / |det F| (0 if unused)


def _cofactor_condition(F: np.ndarray) -> float:
    """sum_ij |K_ij F_ij| / |det F|: det F is computed with an absolute error ~ eps times
    the numerator, so this is its relative error over eps (1e7 at det F ~ 1e-7 |F|^3)."""
    F = F / np.abs(F).max()  # kappa is scale-free; this keeps K and J in range
    K = np.array([np.cross(F[(i + 1) % 3], F[(i + 2) % 3]) for i in range(3)])  # cof F
    return float(np.abs(K * F).sum() / abs(np.sum(K[0] * F[0])))


def scales(m, F: np.ndarray) -> Scales:
    """The error model's :class:`Scales` for material ``m`` at ``F`` (inf or NaN where
    F is on a non-smooth set, ell = 0, or beyond the float range: no check there)."""
    with np.errstate(all="ignore"):
        return _scales(m, F)


def _scales(m, F: np.ndarray) -> Scales:
    mu, lam = m.mu, abs(m.lam)
    nF = np.linalg.norm(F)  # numpy floats: a scale beyond the float range is inf, no error
    s = _signed_singular_values(F)
    if isinstance(m, M.NeoHookean):
        if not s[2] > 0.0:  # inadmissible: no derivative to check
            return Scales(math.inf, math.inf, min(float(s[2]), 0.0), math.inf)
        lnJ = abs(float(np.log(s).sum()))  # not log(prod): J may leave the float range
        kappa = _cofactor_condition(F)
        S = mu * (nF ** 2 + 3.0) + mu * (1.0 + lnJ) + lam * (1.0 + lnJ) ** 2
        # ln J carries an absolute error eps kappa, multiplied by d psi / d ln J = lam ln J - mu
        return Scales(S, S + (mu + lam * lnJ) * kappa, float(s[2]), kappa)
    if isinstance(m, M.Corotated):
        S = (mu + lam) * (nF + 3.0) ** 2
        ell = min(float(s[1] + s[2]), nF + 1.0)
        # P = 2 mu (F - R) + lam tr(R^T F - I) R: the polar rotation R is conditioned by
        # |F| / ell (and signed_svd's Gram-Schmidt adds eps s0 / s1, LAPACK below
        # s1 = 1e-6 s0), so P carries eps (2 mu + lam (|F| + 3)) (|F| + 3) (s0/ell + s0/s1),
        # which R / ell must cover
        cond = s[0] / ell + (min(float(s[0] / s[1]), 1e6) if s[1] > 0 else 1e6)
        return Scales(S, S + (2.0 * mu + lam * (nF + 3.0)) * (nF + 3.0) * cond * ell, ell, 0.0)
    if isinstance(m, M.StableNeoHookean):
        J = abs(np.prod(s))
        S = m.mu_snh * (nF ** 2 + 3.0) + m.lam_snh * (J + m.alpha) ** 2
        # det F's absolute error dJ = eps sum |K F| <= 3 eps |F|^3 enters lam'/2 (J - alpha)^2
        # as lam' |J - alpha| dJ + lam'/2 dJ^2 (the second matters where J ~ 0 but |F| ~ 1e85)
        dJ = 3.0 * nF ** 3
        R = S + m.lam_snh * (J + m.alpha) * dJ + m.lam_snh * EPS * dJ ** 2
        return Scales(S, R, nF + 1.0, 0.0)
    if isinstance(m, M.StVK):
        S = (mu + lam) * (nF ** 2 + 3.0) ** 2
        return Scales(S, S, nF + 1.0, 0.0)
    S = (mu + lam) * (nF + 3.0) ** 2  # LinearElastic (and any quadratic energy)
    return Scales(S, S, nF + 1.0, 0.0)


def _fd_stencil(F: np.ndarray, h: float) -> np.ndarray:
    """(3, 3, 18) batch: F + h e_kl then F - h e_kl for the nine (k, l)."""
    out = np.repeat(F[:, :, None], 18, axis=2)
    for n in range(9):
        k, l = divmod(n, 3)
        out[k, l, n] += h
        out[k, l, 9 + n] -= h
    return out


def fd_step(sc: Scales, size: float) -> float:
    """The step that balances round-off ``eps R / h`` and truncation ``h^2 S / ell^3``.

    At least ``8 eps size`` (``size`` the largest entry perturbed), so that adding it
    changes the entry: the realized steps ``fl(F + h) - F`` then differ from ``h``
    by at most ``eps size / 2`` each (see :func:`fd_bound`).
    """
    h = min((EPS * sc.R * sc.ell ** 3 / (2.0 * sc.S)) ** (1.0 / 3.0), 0.1 * sc.ell)
    return max(h, 8.0 * EPS * size)


def fd_bound(sc: Scales, h: float, order: int, exact_size: float, size: float) -> float:
    """Accepted |analytic - central difference| for the ``order``-th derivative (Pa).

    Besides round-off and truncation, the realized steps ``h+ = fl(F + h) - F`` and
    ``h- = F - fl(F - h)`` may differ by ``eps size``; dividing by ``h+ + h-`` keeps
    the difference consistent, leaving a first-order error ``|h+ - h-| / 2`` times the
    next derivative, ``eps size / 2 * S / ell^(order + 1)``.
    """
    fd_error = (EPS * sc.R / h + h * h * sc.S / sc.ell ** 3
                + 0.5 * EPS * size * sc.S / sc.ell ** 2) / sc.ell ** (order - 1)
    # the analytic formula's own round-off: RTOL, or det F's (eps kappa) where it divides by J
    return FD_SAFETY * fd_error + (RTOL + 10.0 * EPS * sc.kappa) * exact_size


def fd_check(f, df, F, sc: Scales, order: int):
    """Compare ``df(F)`` with central differences of ``f``; returns (error, bound).

    ``order`` is the order of ``df`` (1: stress from psi, 2: tangent from stress).
    """
    size = float(np.abs(F).max())
    h = fd_step(sc, size)
    stencil = _fd_stencil(F, h)
    steps = (stencil[..., :9] - stencil[..., 9:]).reshape(9, 9).max(axis=0)  # h+ + h-, per kl
    values = f(stencil)  # (18,) for psi, (3, 3, 18) for P
    d = (values[..., :9] - values[..., 9:]) / steps  # [..., kl]
    exact = df(F[:, :, None])[..., 0]
    exact = exact.reshape(9) if order == 1 else exact.reshape(3, 3, 9)  # C[i,j,k,l] -> [i,j,kl]
    err = float(np.abs(exact - d).max())
    return err, fd_bound(sc, h, order, float(np.abs(exact).max()), size)


# ---------------------------------------------------------------------------------------
# the properties


def _relative_det(F) -> float:
    """det(F / max |F_ij|): the sign of det F, and its size relative to its round-off
    (~ eps, the entries of F / c being at most 1), free of over- and underflow."""
    c = np.abs(F).max()
    return float(np.linalg.det(F / c)) if c > 0 else 0.0


def _is_admissible(m, F) -> bool:
    """Whether psi is meant to be finite at F.

    det F is known only to its round-off, ~ eps |F|^3 (a few products of entries):
    within 100 times that of 0 either answer is right.
    """
    return type(m) not in BARRIER or _relative_det(F) > 100.0 * EPS


def _is_inadmissible(m, F) -> bool:
    """Whether psi is meant to be +inf at F (see :func:`_is_admissible`)."""
    return type(m) in BARRIER and _relative_det(F) < -100.0 * EPS


def check_values(m, F: np.ndarray) -> None:
    """psi finite or +inf (never NaN, never -inf); P finite exactly where psi is."""
    with np.errstate(all="ignore"):
        psi = float(m.psi(F))
        P = m.dpsi_dF(F)
    assert not math.isnan(psi) and psi != -np.inf, (m, F, psi)
    if _is_admissible(m, F):
        assert math.isfinite(psi), (m, F, psi)
    if _is_inadmissible(m, F):
        assert psi == np.inf, (m, F, psi)
    if math.isfinite(psi):
        sc = scales(m, F)
        with np.errstate(all="ignore"):
            representable = sc.ell > 0 and sc.S / sc.ell < 1e300  # P ~ S / ell: not at s_min ~ 1e-309
        if representable:
            assert np.isfinite(P).all(), (m, F, P)
    else:
        assert psi == np.inf and type(m) in BARRIER
        assert not np.isfinite(P).any(), (m, F, P)  # documented: NaN, never a finite stress


def check_derivatives(m, F: np.ndarray) -> None:
    """dpsi_dF and d2psi_dF2 against central differences, where they are smooth."""
    sc = scales(m, F)
    ell = sc.ell
    # on (or within round-off, ~eps |F|, of) the non-smooth set (NH: det F <= 0;
    # Corotated: s1 + s2 = 0), where the stencil would straddle it
    if not ell > 1e3 * EPS * (np.linalg.norm(F) + 1.0):
        return
    if isinstance(m, M.Corotated) and ell < 1e3 * TWIST_EPS:
        return  # C's twist denominator is clamped within TWIST_EPS of s1 + s2 = 0
    with np.errstate(all="ignore"):
        err, bound = fd_check(m.psi, m.dpsi_dF, F, sc, order=1)
        assert err <= bound, ("stress", m, F.tolist(), err, bound)
        err, bound = fd_check(m.dpsi_dF, m.d2psi_dF2, F, sc, order=2)
        assert err <= bound, ("tangent", m, F.tolist(), err, bound)


def check_psd(m, F: np.ndarray) -> None:
    """The projected tangent is symmetric PSD, and the exact one where that is PSD.

    F is projected in a batch with the rest state, as an assembly does: whatever F is
    (inverted included), the rest point's tangent comes out as on its own, and no
    exception is raised (LAPACK's eigh raises for a whole batch with one NaN in it).
    """
    with np.errstate(invalid="raise"):  # quietly, too: NaN where inadmissible is documented
        batch = m.d2psi_dF2_psd(np.stack([F, np.eye(3)], axis=-1))
    alone = m.d2psi_dF2_psd(np.eye(3))
    # the same to round-off: with more than DENSE_FRACTION of a batch indefinite, every
    # point is rebuilt from its eigensystem (a few eps of |C| from the analytic tangent)
    assert np.abs(batch[..., 1] - alone).max() <= PSD_TOL * np.abs(alone).max()
    if _is_inadmissible(m, F):
        assert not np.isfinite(batch[..., 0]).any()  # NaN, as documented
    if type(m) in BARRIER and not scales(m, F).ell > 1e3 * EPS * (np.linalg.norm(F) + 1.0):
        return
    C = batch[..., 0].reshape(9, 9)
    size = float(np.abs(C).max())
    assert np.isfinite(C).all()
    assert np.abs(C - C.T).max() <= PSD_TOL * size, (m, F.tolist())
    w = np.linalg.eigvalsh(0.5 * (C + C.T))
    assert w.min() >= -PSD_TOL * size, (m, F.tolist(), w.min(), size)
    exact = m.d2psi_dF2(F[:, :, None])[..., 0].reshape(9, 9)
    if np.linalg.eigvalsh(0.5 * (exact + exact.T)).min() > 1e-6 * size:  # clearly PSD
        # the projection keeps an already PSD tangent (to the round-off of its rebuild)
        assert np.abs(C - exact).max() <= 1e-9 * size, (m, F.tolist())


@settings(max_examples=400, **SETTINGS)
@given(m=materials(), F=deformation_gradients())
@example(m=M.NeoHookean(E=1e6, nu=0.3), F=np.diag([1.0, 1.0, -1.0]))
@example(m=M.NeoHookean(E=1e6, nu=0.3), F=np.diag([1.0, 1.0, 0.0]))
@example(m=M.NeoHookean(E=1e6, nu=0.3), F=np.zeros((3, 3)))
@example(m=M.Corotated(E=1e6, nu=0.3), F=np.diag([1.0, 1.0, -1.0]))  # s1 + s2 = 0
@example(m=M.StVK(E=1e6, nu=-0.9), F=np.diag([100.0, 1e-8, 1e-8]))
@example(m=M.NeoHookean(E=1e6, nu=0.3), F=np.diag([1.0, 1.0, -0.5]))  # eigh raised LinAlgError
def test_material_at_random_F(m, F):
    check_values(m, F)
    check_derivatives(m, F)
    check_psd(m, F)


@st.composite
def extreme_gradients(draw):
    """F far outside any physical range: singular values from 1e-150 to 1e150, signed."""
    U, V = _rotation(draw(quaternions)), _rotation(draw(quaternions))
    s = np.array([draw(_stretch(-150.0, 150.0)) for _ in range(3)])
    s[2] *= draw(st.sampled_from([1.0, -1.0]))
    return U @ np.diag(s) @ V.T


@settings(max_examples=200, **SETTINGS)
@given(m=materials(), F=extreme_gradients())
@example(m=M.NeoHookean(E=1e6, nu=0.3), F=np.diag([1e110, 1e110, 1e110]))  # J overflows
@example(m=M.NeoHookean(E=1e6, nu=-0.5), F=np.diag([1e110, 1e110, 1e110]))
@example(m=M.NeoHookean(E=1e6, nu=0.3), F=np.diag([1e-110, 1e-110, 1e-110]))  # J underflows
@example(m=M.NeoHookean(E=1e6, nu=0.3), F=np.diag([1e-110, 1e-110, -1e-110]))
@example(m=M.NeoHookean(E=1e6, nu=0.3), F=np.diag([1e160, 1e160, 1e160]))  # I1 overflows too
@example(m=M.StVK(E=1e6, nu=-0.5), F=np.diag([1e160, 1e160, 1e160]))  # inf + (-inf)
@example(m=M.LinearElastic(E=1e6, nu=-0.5), F=np.diag([1e160, 1e160, 1e160]))
@example(m=M.Corotated(E=1e6, nu=-0.5), F=np.diag([1e160, 1e160, 1e160]))
@example(m=M.StableNeoHookean(E=1e6, nu=0.3), F=np.diag([1e160, 1e160, 1e160]))
def test_psi_never_nan_at_extreme_F(m, F):
    """Far outside the physical range: never NaN or -inf, and finite where representable.

    Where the terms of an energy overflow, the energy (positive, growing like |F|^2 or
    faster) is beyond the float range and +inf says so; where its terms are all
    representable, round-off included (``S, R < 1e300`` in the error model: det F of a
    nearly singular F of entries ~1e130 may come out ~1e243 from round-off alone, and
    Stable Neo-Hookean squares it), psi and P must be finite, also
    when J alone leaves the range (Neo-Hookean at F = 1e110 I: J = 1e330 but
    psi ~ mu |F|^2 / 2 = 1.5e220 mu; at F = 1e-110 I: J = 1e-330 but ln J = -760).
    """
    with np.errstate(all="ignore"):  # overflow is the point here
        psi = float(m.psi(F))
        P = m.dpsi_dF(F)
        sc = scales(m, F)
        representable = max(sc.S, sc.R) < 1e300  # the terms, with their round-off
    assert not math.isnan(psi) and psi != -np.inf, (m, F.tolist(), psi)
    if _is_inadmissible(m, F):
        assert psi == np.inf
    elif _is_admissible(m, F) and representable:
        assert math.isfinite(psi), (m, F.tolist(), psi)
        assert np.isfinite(P).all(), (m, F.tolist(), P)


# ---------------------------------------------------------------------------------------
# through the assembled body


def _tet_model(material, order):
    mesh = fe.mesh_from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]])
    return fe.Model(mesh, density=1000.0, body=fe.ElasticBody(material, order=order))


_MODELS: dict = {}


def tet_model(material, order):
    """One-tet models, cached per (material, order): Model construction dominates otherwise."""
    key = (material, order)
    if key not in _MODELS:
        _MODELS[key] = _tet_model(material, order)
    return _MODELS[key]


@settings(max_examples=150, **SETTINGS)
@given(
    cls=st.sampled_from(MATERIALS),
    nu=st.sampled_from([-0.5, 0.3, 0.4999]),
    order=st.sampled_from([1, 2]),
    u=st.lists(st.floats(-1.5, 1.5), min_size=30, max_size=30),
    direction=st.lists(st.floats(-1.0, 1.0), min_size=30, max_size=30),
)
@example(cls=M.NeoHookean, nu=0.3, order=1, u=[0.0] * 9 + [0.0, 0.0, -1.0] + [0.0] * 18,
         direction=[1.0] * 30)  # the apex on the base plane: J = 0
def test_model_energy_and_gradient_on_a_tet(cls, nu, order, u, direction):
    model = tet_model(cls(E=1e6, nu=nu), order)
    n = model.ndofs
    x = model.X + np.asarray(u[:n])
    d = np.asarray(direction[:n])
    assume(np.linalg.norm(d) > 1e-3)
    d /= np.linalg.norm(d)
    with np.errstate(all="ignore"):
        e = model.energy(x)
    assert not math.isnan(e) and e != -np.inf
    if not math.isfinite(e):
        assert cls in BARRIER  # only a barrier material has inadmissible states
        return
    g = model.gradient(x)
    assert np.isfinite(g).all()
    # the error model per quadrature point, carried to x: a step h along the unit d moves
    # F by at most h |dN| there, so ell_x = min ell / |dN|; the energy's terms and their
    # round-off add up over the points with the weights dx (m^3)
    space = model.space
    F = model.body_potential.F(x).reshape(3, 3, -1)
    dN = np.linalg.norm(space.dN, axis=(0, 1)).ravel()  # (nqp,) with one tet
    dx = space.dx.ravel()
    sc = [scales(model.body_potential.material, F[:, :, q]) for q in range(F.shape[2])]
    ell = np.array([c.ell for c in sc])
    if not ell.min() > 1e3 * EPS * (np.abs(F).max() + 1.0):
        return  # within round-off of a non-smooth set (see check_derivatives)
    if isinstance(model.body_potential.material, M.Corotated) and ell.min() < 1e3 * TWIST_EPS:
        return
    ell_x = float((ell / dN).min())
    sx = Scales(S=float(sum(c.S * w for c, w in zip(sc, dx))),
                R=float(sum(c.R * w for c, w in zip(sc, dx))), ell=ell_x,
                kappa=max(c.kappa for c in sc))
    size = float(np.abs(x).max())
    h = fd_step(sx, size)
    xp, xm = x + h * d, x - h * d  # realized steps: xp - x, x - xm (see fd_bound)
    with np.errstate(all="ignore"):
        fd = (model.energy(xp) - model.energy(xm)) / (2.0 * h)
    exact = g @ (xp - xm) / (2.0 * h)
    bound = fd_bound(sx, h, 1, float(np.abs(g).sum()), size)
    assert abs(fd - exact) <= bound, (cls, nu, order, fd, exact, bound)
