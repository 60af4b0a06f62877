"""St. Venant-Kirchhoff: linear elasticity in the Green strain.

With ``E = (F^T F - I)/2`` and ``S = 2 mu E + lam tr(E) I``,

    psi = mu E:E + lam/2 tr(E)^2,
    P   = F S,
    C_ijkl = d_ik S_jl + mu (F F^T)_ik d_jl + mu F_il F_kj + lam F_ij F_kl.

Frame-indifferent, but it softens and finally collapses under strong
compression (its energy of ``F = s I`` peaks at ``s = 1/sqrt(3)`` and returns
to zero at an inverted ``F = 0``), so its Hessian is indefinite there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import _flat, _outer, _overflow_to_inf, _right_cauchy_green
from .isotropic import PAIRS, IsotropicMaterial

__all__ = ["StVK"]


@dataclass(frozen=True, init=False, repr=False)
class StVK(IsotropicMaterial):
    """St. Venant-Kirchhoff material ``psi = mu E:E + lam/2 tr(E)^2``, ``E = (F^T F - I)/2``.

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
    >>> m = StVK(E=1.0e6, nu=0.25)
    >>> F = np.eye(3)[:, :, None, None] * np.ones((1, 1, 10, 4))   # (nelems, nqp) = (10, 4)
    >>> m.psi(F).shape, m.d2psi_dF2(F).shape
    ((10, 4), (3, 3, 3, 3, 10, 4))
    """

    def _second_piola(self, F):
        A = _right_cauchy_green(F)
        trE = 0.5 * (A[0, 0] + A[1, 1] + A[2, 2] - 3.0)
        S = self.mu * A  # 2 mu E = mu (A - I)
        for i in range(3):
            S[i, i] += self.lam * trE - self.mu
        return A, trE, S

    def psi(self, F: np.ndarray) -> np.ndarray:
        """Strain-energy density ``mu E:E + lam/2 tr(E)^2`` (J/m^3).

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
        >>> import numpy as np
        >>> float(StVK(E=1.0, nu=0.0).psi(np.zeros((3, 3))))   # collapsed: E = -I/2
        0.375
        """
        F, batch = _flat(F)
        A = _right_cauchy_green(F)
        e00, e11, e22 = 0.5 * (A[0, 0] - 1.0), 0.5 * (A[1, 1] - 1.0), 0.5 * (A[2, 2] - 1.0)
        tr = e00 + e11 + e22
        EE = e00 * e00 + e11 * e11 + e22 * e22 + 0.5 * (A[0, 1] ** 2 + A[0, 2] ** 2 + A[1, 2] ** 2)
        with np.errstate(invalid="ignore", over="ignore"):
            out = self.mu * EE + 0.5 * self.lam * tr * tr
        return _overflow_to_inf(out, F).reshape(batch)

    def dpsi_dF(self, F: np.ndarray) -> np.ndarray:
        """First Piola-Kirchhoff stress ``P = F (2 mu E + lam tr(E) I)`` (Pa).

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
        >>> float(np.abs(StVK(E=1.0, nu=0.3).dpsi_dF(np.eye(3))).max())
        0.0
        """
        F, batch = _flat(F)
        _, _, S = self._second_piola(F)
        P = np.einsum("ikn,kjn->ijn", F, S)
        return P.reshape((3, 3) + batch)

    def d2psi_dF2(self, F: np.ndarray) -> np.ndarray:
        """Analytic tangent ``C_ijkl = d_ik S_jl + mu B_ik d_jl + mu F_il F_kj + lam F_ij F_kl``.

        ``B = F F^T``. Indefinite under strong compression; see
        :meth:`d2psi_dF2_psd`.

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
        >>> C = StVK(E=1.0e6, nu=0.25).d2psi_dF2(np.eye(3))
        >>> round(float(C[0, 0, 0, 0]))     # 2 mu + lam, as linear elasticity
        1200000
        """
        F, batch = _flat(F)
        mu, lam = self.mu, self.lam
        _, _, S = self._second_piola(F)
        C = _outer(F, F, lam)
        Ft = F.transpose(1, 0, 2)
        for i in range(3):
            for j in range(3):
                # mu F_il F_kj as a (k, l) matrix: outer(F[:, j], F[i, :])
                C[i, j] += (mu * Ft[j])[:, None] * F[i][None, :]
        B = np.einsum("ikn,jkn->ijn", F, F)
        for i in range(3):
            for j in range(3):
                for l in range(3):
                    C[i, j, i, l] += S[j, l]
                for k in range(3):
                    C[i, j, k, j] += mu * B[i, k]
        return C.reshape((3, 3, 3, 3) + batch)

    def singular_value_hessian(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Eigensystem of the Hessian in terms of the signed singular values.

        With ``psi_i = s_i (mu (s_i^2 - 1) + t)``, ``t = lam/2 sum_k (s_k^2 - 1)``:
        ``H_ab = d_ab (mu (3 s_a^2 - 1) + t) + lam s_a s_b``,
        ``lam_flip = mu (s_i^2 + s_i s_j + s_j^2 - 1) + t``,
        ``lam_twist = mu (s_i^2 - s_i s_j + s_j^2 - 1) + t``.

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
        >>> H, lt, lf = StVK(E=1.0e6, nu=0.25).singular_value_hessian(np.ones((3, 1)))
        >>> round(float(lt[0, 0])), round(float(lf[0, 0]))    # 0 and 2 mu at rest
        (0, 800000)
        """
        mu, lam = self.mu, self.lam
        s2 = s * s
        t = 0.5 * lam * (s2[0] + s2[1] + s2[2] - 3.0)
        H = lam * s[:, None] * s[None, :]
        for a in range(3):
            H[a, a] += mu * (3.0 * s2[a] - 1.0) + t
        lt, lf = np.empty_like(s), np.empty_like(s)
        for row, (i, j, _k) in enumerate(PAIRS):
            base = mu * (s2[i] + s2[j] - 1.0) + t
            lf[row] = base + mu * s[i] * s[j]
            lt[row] = base - mu * s[i] * s[j]
        return H, lt, lf
