"""Common base of the hyperelastic materials, and the elastic constants they are built from.

Conventions (used by every material module)
-------------------------------------------
F : (3, 3, ...) deformation gradient, scikit-fem's layout: the two tensor
    indices first, then any batch axes, typically ``(nelems, nqp)``.
P : (3, 3, ...) first Piola-Kirchhoff stress, ``P = dpsi_dF``, in Pa.
C : (3, 3, 3, 3, ...) the linearization ``C[i, j, k, l] = dP_ij / dF_kl`` (Pa).
J : det F.
psi : strain-energy density per unit reference volume (J/m^3 = Pa).
mu, lam : Lame parameters (Pa): the shear modulus and the first Lame parameter.
K : bulk modulus (Pa), ``lam + 2/3 mu``.

Every material is given by exactly one pair of elastic constants: Young's
modulus E (Pa) and Poisson's ratio nu, the Lame parameters (mu, lam), or the
shear and bulk moduli (mu, K). :func:`elastic_constants` checks the pair and
converts it into all the others; it is the one place where these conversions
are written.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, NamedTuple

import numpy as np

from ..errors import InvalidParameter

__all__ = ["Material", "ElasticConstants", "elastic_constants", "lame_parameters", "PAIRS_HELP"]

#: The allowed ways to give a material's stiffness, as error messages name them.
PAIRS_HELP = "exactly one pair of (E, nu), (mu, lam) or (mu, K), e.g. E=1e6, nu=0.45 or mu=3.4e5, lam=3.1e6"


def lame_parameters(E: float, nu: float) -> tuple[float, float]:
    """Lame parameters from Young's modulus and Poisson's ratio.

    Parameters
    ----------
    E : float
        Young's modulus (Pa), > 0.
    nu : float
        Poisson's ratio, in (-1, 0.5).

    Returns
    -------
    mu, lam : float
        Shear modulus and first Lame parameter (Pa).

    Examples
    --------
    >>> mu, lam = lame_parameters(1.0e6, 0.25)
    >>> round(mu), round(lam)
    (400000, 400000)
    """
    _check_E_nu(E, nu)
    mu = E / (2.0 * (1.0 + nu))
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    return mu, lam


class ElasticConstants(NamedTuple):
    """Every elastic constant of an isotropic material, and the pair it was given by.

    Attributes
    ----------
    E : float
        Young's modulus (Pa), as given when ``given == ("E", "nu")``.
    nu : float
        Poisson's ratio, as given when ``given == ("E", "nu")``.
    mu : float
        Shear modulus (Pa).
    lam : float
        First Lame parameter (Pa).
    K : float
        Bulk modulus ``lam + 2/3 mu`` (Pa).
    given : tuple of str
        The pair the material was built from: ``("E", "nu")``, ``("mu", "lam")``
        or ``("mu", "K")``.
    """

    E: float
    nu: float
    mu: float
    lam: float
    K: float
    given: tuple


def elastic_constants(E=None, nu=None, *, mu=None, lam=None, K=None,
                      who: str = "a material") -> ElasticConstants:
    """Check one pair of elastic constants and convert it into all the others.

    Exactly one pair must be given: (E, nu), (mu, lam) or (mu, K). Any other
    combination (two pairs, a lone value, E with lam, ...) and any value out of
    its range is :class:`~fem_elastic.errors.InvalidParameter`, whose message
    names the allowed pairs. The ranges are those of a stable isotropic solid:
    ``mu > 0`` and ``K > 0`` (equivalently ``E > 0`` and ``-1 < nu < 0.5``).

    Parameters
    ----------
    E : float, optional
        Young's modulus (Pa), > 0.
    nu : float, optional
        Poisson's ratio, -1 < nu < 0.5.
    mu : float, optional
        Shear modulus (Pa), > 0.
    lam : float, optional
        First Lame parameter (Pa), > -2/3 mu (it may be negative: auxetic solids).
    K : float, optional
        Bulk modulus (Pa), > 0.
    who : str
        What is being built, for the messages (e.g. ``"NeoHookean"``).

    Returns
    -------
    ElasticConstants
        ``(E, nu, mu, lam, K, given)``. From (E, nu), ``mu`` and ``lam`` are
        :func:`lame_parameters` bit for bit; a given mu, lam or K is returned as given.

    Examples
    --------
    >>> c = elastic_constants(mu=4.0e5, lam=4.0e5)
    >>> round(c.E), c.nu, c.given
    (1000000, 0.25, ('mu', 'lam'))
    >>> round(elastic_constants(mu=4.0e5, K=2.0e6 / 3.0).lam)
    400000
    >>> elastic_constants(E=1e6, mu=4e5)
    Traceback (most recent call last):
    ...
    fem_elastic.errors.InvalidParameter: a material got E and mu: give exactly one pair of (E, nu), (mu, lam) or (mu, K), e.g. E=1e6, nu=0.45 or mu=3.4e5, lam=3.1e6.
    """
    values = {"E": E, "nu": nu, "mu": mu, "lam": lam, "K": K}
    given = tuple(name for name, value in values.items() if value is not None)
    if given not in (("E", "nu"), ("mu", "lam"), ("mu", "K")):
        got = "no elastic constant" if not given else " and ".join(given)
        raise InvalidParameter(f"{who} got {got}: give {PAIRS_HELP}.")
    if given == ("E", "nu"):
        mu_, lam_ = lame_parameters(E, nu)  # checks E and nu (_check_E_nu)
        return ElasticConstants(E, nu, mu_, lam_, E / (3.0 * (1.0 - 2.0 * nu)), given)
    for name in given:
        _check_real(name, values[name])
    if not mu > 0:
        raise InvalidParameter(
            f"the shear modulus mu must be > 0 Pa, got mu = {mu!r} ({who}). "
            "Pass it in pascals, e.g. mu=3.4e5 for a soft rubber, mu=8e10 for steel."
        )
    if given == ("mu", "lam"):
        K_ = lam + 2.0 * mu / 3.0
        if not (K_ > 0 and math.isfinite(K_)):
            raise InvalidParameter(
                f"the first Lame parameter lam must be > -2/3 mu = {-2.0 * mu / 3.0!r} Pa, got "
                f"lam = {lam!r} ({who}): the bulk modulus K = lam + 2/3 mu must be positive "
                "(nu > -1) for the solid to resist compression."
            )
        E_ = mu * (3.0 * lam + 2.0 * mu) / (lam + mu)
        nu_ = lam / (2.0 * (lam + mu))
        return ElasticConstants(E_, nu_, mu, lam, K_, given)
    if not (K > 0 and math.isfinite(K - 2.0 * mu / 3.0)):
        raise InvalidParameter(
            f"the bulk modulus K must be > 0 Pa, got K = {K!r} ({who}): a solid of K <= 0 does not "
            "resist compression. Pass it in pascals, e.g. K=1e9 for a nearly incompressible rubber."
        )
    E_ = 9.0 * K * mu / (3.0 * K + mu)
    nu_ = (3.0 * K - 2.0 * mu) / (2.0 * (3.0 * K + mu))
    return ElasticConstants(E_, nu_, mu, K - 2.0 * mu / 3.0, K, given)


def _check_real(name, value) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InvalidParameter(
            f"{name} must be a real number, got {value!r} of type {type(value).__name__}."
        )
    try:
        finite = math.isfinite(float(value))
    except OverflowError:  # an int beyond the float range
        finite = False
    if not finite:
        raise InvalidParameter(f"{name} must be finite, got {value!r}.")


def _check_E_nu(E, nu) -> None:
    for name, value in (("E", E), ("nu", nu)):
        _check_real(name, value)
    if E <= 0:
        raise InvalidParameter(
            f"Young's modulus E must be > 0 Pa, got E = {E!r}. "
            "Pass the stiffness in pascals, e.g. E=1e6 for a soft rubber, E=2e11 for steel."
        )
    if nu <= -1.0:
        raise InvalidParameter(
            f"Poisson's ratio nu must be > -1 (the bound of positive bulk modulus), got nu = {nu!r}."
        )
    if nu >= 0.5:
        raise InvalidParameter(
            f"Poisson's ratio nu must be < 0.5, got nu = {nu!r}: nu = 0.5 is exactly incompressible "
            "and the first Lame parameter lam = E nu / ((1 + nu)(1 - 2 nu)) is infinite there. "
            "Use a value such as 0.49 or 0.499 for a nearly incompressible solid."
        )


@dataclass(frozen=True, init=False, repr=False)
class Material:
    """An isotropic hyperelastic material given by one pair of elastic constants.

    Subclasses implement ``psi``, ``dpsi_dF`` and ``d2psi_dF2`` on
    deformation gradients of shape ``(3, 3, ...)``, and ``d2psi_dF2_psd``,
    the linearization projected to positive semi-definite at every point
    (what Newton's method needs for a descent direction).

    Parameters
    ----------
    E : float, optional
        Young's modulus (Pa), > 0.
    nu : float, optional
        Poisson's ratio, -1 < nu < 0.5.
    mu : float, optional (keyword only)
        Shear modulus (Pa), > 0.
    lam : float, optional (keyword only)
        First Lame parameter (Pa), > -2/3 mu.
    K : float, optional (keyword only)
        Bulk modulus (Pa), > 0.

    Exactly one pair: (E, nu), (mu, lam) or (mu, K) (see
    :func:`elastic_constants`); anything else is
    :class:`~fem_elastic.errors.InvalidParameter`. The fields are always E and
    nu (derived from the pair given), and ``mu``, ``lam``, ``K`` are there
    whatever the pair; a given value is kept exactly. The repr shows the
    pair given.

    Examples
    --------
    >>> from fem_elastic.materials import NeoHookean
    >>> NeoHookean(E=1e6, nu=0.25)
    NeoHookean(E=1000000.0, nu=0.25)
    >>> m = NeoHookean(mu=4e5, lam=4e5)
    >>> m, round(m.E), m.nu
    (NeoHookean(mu=400000.0, lam=400000.0), 1000000, 0.25)
    """

    E: float
    nu: float
    #: psi is a quadratic form in F (so the elastic energy is quadratic in the positions and
    #: its Hessian the same matrix at every state): only :class:`LinearElastic`. Read from the
    #: material's own class only (a subclass must declare it again to keep it).
    quadratic: ClassVar[bool] = False
    if TYPE_CHECKING:  # set in __init__ by object.__setattr__; not dataclass fields
        _mu: float
        _lam: float
        _K: float

    def __init__(self, E: float | None = None, nu: float | None = None, *,
                 mu: float | None = None, lam: float | None = None,
                 K: float | None = None) -> None:
        c = elastic_constants(E, nu, mu=mu, lam=lam, K=K, who=type(self).__name__)
        object.__setattr__(self, "E", c.E)
        object.__setattr__(self, "nu", c.nu)
        self._set_constants(c)

    def __post_init__(self):
        # run only by the dataclass-made __init__(E, nu) of a user's subclass
        self._set_constants(elastic_constants(self.E, self.nu, who=type(self).__name__))

    def _set_constants(self, c: ElasticConstants) -> None:
        # private (underscored) attributes: checkpoints describe a material by its public ones
        object.__setattr__(self, "_mu", c.mu)
        object.__setattr__(self, "_lam", c.lam)
        object.__setattr__(self, "_K", c.K)
        object.__setattr__(self, "_given", c.given)

    def __repr__(self) -> str:
        given = getattr(self, "_given", ("E", "nu"))
        values = {"E": self.E, "nu": self.nu, "mu": self.mu, "lam": self.lam, "K": self.K}
        inner = ", ".join(f"{name}={values[name]!r}" for name in given)
        return f"{type(self).__qualname__}({inner})"

    @property
    def mu(self) -> float:
        """Shear modulus (Pa)."""
        return self._mu

    @property
    def lam(self) -> float:
        """First Lame parameter (Pa)."""
        return self._lam

    @property
    def K(self) -> float:
        """Bulk modulus ``lam + 2/3 mu`` (Pa)."""
        return self._K

    # The four methods every material provides -------------------------------
    def psi(self, F: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        """Strain-energy density (J/m^3) at each point, shape ``F.shape[2:]``."""
        raise NotImplementedError

    def dpsi_dF(self, F: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        """First Piola-Kirchhoff stress P (Pa), shape ``F.shape``."""
        raise NotImplementedError

    def d2psi_dF2(self, F: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        """Linearization dP/dF (Pa), shape ``(3, 3) + F.shape``."""
        raise NotImplementedError

    def d2psi_dF2_psd(self, F: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        """dP/dF with negative eigenvalues (as a 9x9 map) clamped to zero."""
        raise NotImplementedError

    def stress_and_tangent(self, F: np.ndarray,
                           project: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """``(P, C)`` at once, C projected to PSD when ``project``: what Newton needs.

        Materials whose stress and tangent share expensive work (an SVD)
        override this to do it once.
        """
        return self.dpsi_dF(F), self.d2psi_dF2_psd(F) if project else self.d2psi_dF2(F)


# Shared helpers for the material modules -------------------------------------
def _flat(F) -> tuple[np.ndarray, tuple[int, ...]]:
    """F as (3, 3, N) float array, and its batch shape (any, possibly ())."""
    F = np.asarray(F, dtype=float)
    if F.ndim < 2 or F.shape[:2] != (3, 3):
        raise InvalidParameter(
            f"F must have shape (3, 3, ...) (scikit-fem's layout, tensor indices first), "
            f"got shape {F.shape}."
        )
    batch = F.shape[2:]
    return F.reshape(3, 3, int(np.prod(batch, dtype=np.int64))), batch


def _right_cauchy_green(F: np.ndarray) -> np.ndarray:
    """F^T F of (3, 3, N) F, as (3, 3, N)."""
    A = np.empty_like(F)
    for a in range(3):
        for b in range(a, 3):
            A[a, b] = F[0, a] * F[0, b] + F[1, a] * F[1, b] + F[2, a] * F[2, b]
            A[b, a] = A[a, b]
    return A


def _cofactor(F: np.ndarray) -> np.ndarray:
    """Cofactor matrix K = dJ/dF = J F^-T of (3, 3, N) F; J = sum(F[0] * K[0])."""
    K = np.empty_like(F)
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            K[i, j] = F[i1, j1] * F[i2, j2] - F[i1, j2] * F[i2, j1]
    return K


def _det(F: np.ndarray, K: np.ndarray | None = None) -> np.ndarray:
    """det F of (3, 3, N) F (using its cofactor K if given)."""
    if K is None:
        return (
            F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1])
            - F[0, 1] * (F[1, 0] * F[2, 2] - F[1, 2] * F[2, 0])
            + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0])
        )
    return F[0, 0] * K[0, 0] + F[0, 1] * K[0, 1] + F[0, 2] * K[0, 2]


def _scaled_det(F: np.ndarray, idx: np.ndarray):
    """``ln |det F|``, ``sign det F`` and ``F^-T`` at the points ``idx`` through ``F / c``.

    ``c = max |F_ij|`` per point: ``det(F / c)`` and ``cof(F / c)`` are O(1) at most,
    so they neither over- nor underflow, and ``ln |J| = 3 ln c + ln |det(F / c)|``,
    ``F^-T = cof(F / c) / (det(F / c) c)``. Used where ``J`` itself left the float
    range (``|F|`` beyond ~1e102 or below ~1e-102), so that an energy that is
    representable is not turned into NaN or +-inf by its intermediate ``J``.

    Parameters
    ----------
    F : numpy.ndarray, shape (3, 3, N)
        Deformation gradients.
    idx : numpy.ndarray of int
        The points to redo.

    Returns
    -------
    log_abs_J, sign, G : numpy.ndarray
        Shapes ``(len(idx),)``, ``(len(idx),)`` (+1, -1 or 0) and ``(3, 3, len(idx))``.
    """
    Fi = F[..., idx]
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.abs(Fi).max(axis=(0, 1))
        Fh = Fi / c
        Kh = _cofactor(Fh)
        Jh = _det(Fh, Kh)
        log_abs_J = 3.0 * np.log(c) + np.log(np.abs(Jh))
        G = Kh / (Jh * c)
    return log_abs_J, np.sign(Jh), G


def _out_of_range(J: np.ndarray) -> np.ndarray:
    """Indices where ``J`` is not a normal float: 0 or subnormal (underflow), +-inf
    (overflow) or NaN (``inf - inf`` in the expansion of det F)."""
    a = np.abs(J)
    return np.flatnonzero(~((a >= np.finfo(float).tiny) & (a < np.inf)))


def _overflow_to_inf(out: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Energies that came out NaN at finite F set to +inf, in place; returns ``out``.

    Each energy here is a sum of terms whose sum is positive and grows like ``|F|^2``
    or faster; NaN at finite F is ``inf - inf`` (a positive term overflowed and a
    negative one, of a negative Lame parameter or a logarithm, did too), i.e. an
    energy beyond the float range. +inf says so (and keeps comparisons and sums
    meaningful), where NaN would poison them.
    """
    bad = np.isnan(out)
    if bad.any():
        bad &= np.isfinite(F).all(axis=(0, 1))
        out[bad] = np.inf
    return out


def _outer(A: np.ndarray, B: np.ndarray, scale=1.0) -> np.ndarray:
    """(scale A)_ij B_kl of (3, 3, N) arrays, as a new (3, 3, 3, 3, N) array."""
    return (scale * A)[:, :, None, None] * B[None, None]


def _add_outer(C: np.ndarray, A: np.ndarray, B: np.ndarray, scale) -> None:
    """C += scale A_ij B_kl, in place, without a (3, 3, 3, 3, N) temporary."""
    sA = scale * A
    for i in range(3):
        for j in range(3):
            C[i, j] += sA[i, j] * B


def _add_identity_term(C: np.ndarray, value) -> None:
    """C_ijkl += value delta_ik delta_jl (value a scalar or an (N,) slab)."""
    for i in range(3):
        for j in range(3):
            C[i, j, i, j] += value


_LEVI = np.zeros((3, 3, 3))
_LEVI[0, 1, 2] = _LEVI[1, 2, 0] = _LEVI[2, 0, 1] = 1.0
_LEVI[0, 2, 1] = _LEVI[2, 1, 0] = _LEVI[1, 0, 2] = -1.0
# dK_ij/dF_kl = eps_ikn eps_jlq F_nq: 36 non-zero (i, j, k, l), each +-F_nq.
_DCOF = [
    (i, j, k, l, _LEVI[i, k, n] * _LEVI[j, l, q], n, q)
    for i in range(3) for j in range(3) for k in range(3) for l in range(3)
    for n in range(3) for q in range(3)
    if _LEVI[i, k, n] * _LEVI[j, l, q] != 0.0
]


def _add_cofactor_derivative(C: np.ndarray, F: np.ndarray, scale: np.ndarray) -> None:
    """C_ijkl += scale d(cof F)_ij / dF_kl = scale eps_ikn eps_jlq F_nq, in place."""
    sF = {}
    for i, j, k, l, sign, n, q in _DCOF:
        if (n, q) not in sF:
            sF[(n, q)] = scale * F[n, q]
        if sign > 0:
            C[i, j, k, l] += sF[(n, q)]
        else:
            C[i, j, k, l] -= sF[(n, q)]
