"""Stable Neo-Hookean material (Smith, de Goes and Kim 2018, "Stable Neo-Hookean Flesh Simulation").

With ``I_C = tr(F^T F)``, ``J = det F`` and the cofactor ``K = dJ/dF = J F^-T``,

    psi = mu'/2 (I_C - 3) + lam'/2 (J - alpha)^2 - mu'/2 ln(I_C + 1) - psi_rest,
    P   = mu' (1 - 1/(I_C + 1)) F + lam' (J - alpha) K,
    C   = mu' (1 - 1/(I_C + 1)) d_ik d_jl + 2 mu'/(I_C + 1)^2 F_ij F_kl
          + lam' K_ij K_kl + lam' (J - alpha) dK_ij/dF_kl,

with ``mu' = 4/3 mu``, ``lam' = lam + 5/6 mu``, ``alpha = 1 + 3 mu'/(4 lam')``
and ``psi_rest = lam'/2 (1 - alpha)^2 - mu'/2 ln 4`` (so that psi(I) = 0): these make ``P(I) = 0`` and the linearization at ``I`` that of linear
elasticity with (mu, lam). No logarithm of J: the energy, stress and tangent
are finite and smooth through inversion (``J <= 0``), so a simulation can
recover from inverted elements.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import (
    _add_cofactor_derivative,
    _add_identity_term,
    _add_outer,
    _cofactor,
    _det,
    _flat,
    _outer,
    _overflow_to_inf,
)
from .isotropic import PAIRS, IsotropicMaterial

__all__ = ["StableNeoHookean"]


@dataclass(frozen=True, init=False, repr=False)
class StableNeoHookean(IsotropicMaterial):
    """Stable Neo-Hookean material of Smith, de Goes and Kim (2018).

    ``psi = mu'/2 (I_C - 3) + lam'/2 (J - alpha)^2 - mu'/2 ln(I_C + 1)``,
    finite for any F (inversion included).

    Parameters
    ----------
    E : float
        Young's modulus (Pa), > 0.
    nu : float
        Poisson's ratio, -1 < nu < 0.5.
    mu, lam, K : float, keyword only
        Instead of (E, nu): the shear modulus and the first Lame parameter
        (``mu=..., lam=...``) or the shear and bulk moduli (``mu=..., K=...``),
        in Pa. Exactly one pair (see :func:`.base.elastic_constants`).

    Examples
    --------
    >>> import numpy as np
    >>> m = StableNeoHookean(E=1.0e6, nu=0.45)
    >>> bool(np.isfinite(m.psi(np.diag([1.0, 1.0, -1.0]))))   # inverted: still finite
    True
    >>> float(np.abs(m.dpsi_dF(np.eye(3))).max()) < 1e-9       # stress free at rest
    True
    """

    @property
    def mu_snh(self) -> float:
        """``mu' = 4/3 mu`` (Pa)."""
        return 4.0 / 3.0 * self.mu

    @property
    def lam_snh(self) -> float:
        """``lam' = lam + 5/6 mu`` (Pa)."""
        return self.lam + 5.0 / 6.0 * self.mu

    @property
    def alpha(self) -> float:
        """Rest volume ratio of the volume term, ``1 + 3 mu' / (4 lam')``."""
        return 1.0 + 0.75 * self.mu_snh / self.lam_snh

    def psi(self, F: np.ndarray) -> np.ndarray:
        """Strain-energy density (J/m^3), finite for any F.

        Parameters
        ----------
        F : numpy.ndarray, shape (3, 3, ...)
            Deformation gradients.

        Returns
        -------
        psi : numpy.ndarray, shape F.shape[2:]
            Energy density (J/m^3).

        Examples
        --------
        The paper's energy has the constant value
        ``lam'/2 (1 - alpha)^2 - mu'/2 ln 4`` at rest; it is subtracted here so
        that psi(I) = 0 like every other material (energies and energy plots
        then compare directly, and no derivative changes):

        >>> import numpy as np
        >>> m = StableNeoHookean(E=1.0, nu=0.3)
        >>> float(m.psi(np.eye(3)))
        0.0
        """
        F, batch = _flat(F)
        mu_, lam_ = self.mu_snh, self.lam_snh
        IC = np.einsum("ijn,ijn->n", F, F)
        dJ = _det(F) - self.alpha
        d0 = 1.0 - self.alpha  # J - alpha at rest
        with np.errstate(invalid="ignore", over="ignore"):
            out = (
                0.5 * mu_ * (IC - 3.0)
                + 0.5 * lam_ * (dJ - d0) * (dJ + d0)
                - 0.5 * mu_ * np.log1p((IC - 3.0) / 4.0)  # ln((I_C + 1) / 4)
            )
        return _overflow_to_inf(out, F).reshape(batch)

    def dpsi_dF(self, F: np.ndarray) -> np.ndarray:
        """First Piola-Kirchhoff stress ``mu' (1 - 1/(I_C + 1)) F + lam' (J - alpha) cof F`` (Pa).

        Parameters
        ----------
        F : numpy.ndarray, shape (3, 3, ...)
            Deformation gradients.

        Returns
        -------
        P : numpy.ndarray, shape F.shape
            Stress (Pa).

        Examples
        --------
        >>> import numpy as np
        >>> StableNeoHookean(E=1.0, nu=0.3).dpsi_dF(np.zeros((3, 3, 5))).shape
        (3, 3, 5)
        """
        F, batch = _flat(F)
        mu_, lam_ = self.mu_snh, self.lam_snh
        IC = np.einsum("ijn,ijn->n", F, F)
        K = _cofactor(F)
        J = _det(F, K)
        P = (mu_ * (1.0 - 1.0 / (IC + 1.0))) * F + (lam_ * (J - self.alpha)) * K
        return P.reshape((3, 3) + batch)

    def d2psi_dF2(self, F: np.ndarray) -> np.ndarray:
        """Analytic tangent ``dP/dF`` (Pa), see the module docstring.

        Parameters
        ----------
        F : numpy.ndarray, shape (3, 3, ...)
            Deformation gradients.

        Returns
        -------
        C : numpy.ndarray, shape (3, 3, 3, 3) + F.shape[2:]
            ``dP_ij/dF_kl`` (Pa).

        Examples
        --------
        >>> import numpy as np
        >>> C = StableNeoHookean(E=1.0e6, nu=0.25).d2psi_dF2(np.eye(3))
        >>> round(float(C[0, 0, 0, 0])), round(float(C[0, 1, 1, 0]))   # 2 mu + lam, mu
        (1200000, 400000)
        """
        F, batch = _flat(F)
        mu_, lam_ = self.mu_snh, self.lam_snh
        IC = np.einsum("ijn,ijn->n", F, F)
        K = _cofactor(F)
        J = _det(F, K)
        ic1 = 1.0 / (IC + 1.0)
        C = _outer(F, F * (2.0 * mu_ * ic1 * ic1))
        _add_outer(C, K, K, lam_)
        _add_cofactor_derivative(C, F, lam_ * (J - self.alpha))
        _add_identity_term(C, mu_ * (1.0 - ic1))
        return C.reshape((3, 3, 3, 3) + batch)

    def singular_value_hessian(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Eigensystem of the Hessian in terms of the signed singular values.

        With ``m = mu' (1 - 1/(I_C + 1))`` and ``h = lam' (J - alpha)``
        (``psi_i = m s_i + h J / s_i``), ``k`` the third index:
        ``H_ab = d_ab m + 2 mu' s_a s_b / (I_C + 1)^2 + lam' (J/s_a)(J/s_b) + (1 - d_ab) h s_k``,
        ``lam_twist = m + h s_k``, ``lam_flip = m - h s_k``. No division by s.

        Parameters
        ----------
        s : numpy.ndarray, shape (3, N)
            Signed singular values.

        Returns
        -------
        d2psi_ds2 : numpy.ndarray, shape (3, 3, N)
            Pa.
        lam_twist, lam_flip : numpy.ndarray, shape (3, N)
            Pa, rows for the pairs (0, 1), (0, 2), (1, 2).

        Examples
        --------
        >>> import numpy as np
        >>> H, lt, lf = StableNeoHookean(E=1.0e6, nu=0.25).singular_value_hessian(np.ones((3, 1)))
        >>> round(float(lt[0, 0])), round(float(lf[0, 0]))    # 0 and 2 mu at rest
        (0, 800000)
        """
        mu_, lam_ = self.mu_snh, self.lam_snh
        IC = s[0] * s[0] + s[1] * s[1] + s[2] * s[2]
        ic1 = 1.0 / (IC + 1.0)
        m = mu_ * (1.0 - ic1)
        J = s[0] * s[1] * s[2]
        h = lam_ * (J - self.alpha)
        Js = np.array([s[1] * s[2], s[0] * s[2], s[0] * s[1]])  # J / s_a
        H = (2.0 * mu_ * ic1 * ic1) * s[:, None] * s[None, :] + lam_ * Js[:, None] * Js[None, :]
        lt, lf = np.empty_like(s), np.empty_like(s)
        for a in range(3):
            H[a, a] += m
        for row, (i, j, k) in enumerate(PAIRS):
            hs = h * s[k]
            H[i, j] += hs
            H[j, i] += hs
            lt[row] = m + hs
            lf[row] = m - hs
        return H, lt, lf
