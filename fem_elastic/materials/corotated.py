"""Corotated linear elasticity (fixed corotated, Stomakhin et al. 2012).

With the polar decomposition ``F = R S`` computed from the signed SVD
``F = U diag(s) V^T`` (``det U = det V = +1``, ``R = U V^T`` a proper
rotation even for inverted F, ``s[2] < 0`` there):

    psi = mu ||F - R||_F^2 + lam/2 tr(R^T F - I)^2
        = mu sum_i (s_i - 1)^2 + lam/2 (sum_i s_i - 3)^2,
    P   = 2 mu (F - R) + lam tr(R^T F - I) R.

The tangent C is built from the singular-value eigensystem
(:func:`.isotropic.isotropic_hessian`): ``H_ab = 2 mu d_ab + lam``,
``lam_flip = 2 mu`` and ``lam_twist = (psi_i + psi_j) / (s_i + s_j)``. The
twist denominator vanishes when two singular values cancel (``s_1 = -s_2``,
an element inverted through a line); there R itself is not differentiable.
As Stomakhin et al. (2012) do, the denominator is clamped to
``max(s_i + s_j, TWIST_EPS)``, so C stays finite (but is no longer the
exact derivative) within ``TWIST_EPS`` of that set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import _flat, _overflow_to_inf
from .isotropic import PAIRS, IsotropicMaterial, isotropic_hessian
from .svd import signed_svd

__all__ = ["Corotated", "TWIST_EPS"]

#: Lower clamp of ``s_i + s_j`` in the twist eigenvalue (dimensionless, like s).
TWIST_EPS = 1e-6


@dataclass(frozen=True, init=False, repr=False)
class Corotated(IsotropicMaterial):
    """Fixed corotated material ``psi = mu ||F - R||^2 + lam/2 tr(R^T F - I)^2``.

    Frame-indifferent, finite and continuous through inversion (R stays a
    proper rotation; the inversion shows as a negative singular value).

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
    >>> m = Corotated(E=1.0e6, nu=0.25)
    >>> c, s = np.cos(0.7), np.sin(0.7)
    >>> Q = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])   # a rigid rotation
    >>> float(m.psi(Q)) < 1e-9, float(np.abs(m.dpsi_dF(Q)).max()) < 1e-9
    (True, True)
    """

    def psi(self, F: np.ndarray) -> np.ndarray:
        """Strain-energy density ``mu sum (s_i - 1)^2 + lam/2 (sum s_i - 3)^2`` (J/m^3).

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
        >>> float(Corotated(E=1.0, nu=0.0).psi(np.diag([1.0, 1.0, -1.0])))  # mu (-2)^2 + 0
        2.0
        """
        F, batch = _flat(F)
        _, s, _ = signed_svd(F)
        d = s - 1.0
        tr = d[0] + d[1] + d[2]
        with np.errstate(invalid="ignore", over="ignore"):
            out = self.mu * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) + 0.5 * self.lam * tr * tr
        return _overflow_to_inf(out, F).reshape(batch)

    def dpsi_dF(self, F: np.ndarray) -> np.ndarray:
        """First Piola-Kirchhoff stress ``2 mu (F - R) + lam tr(R^T F - I) R`` (Pa).

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
        >>> P = Corotated(E=1.0, nu=0.0).dpsi_dF(np.diag([2.0, 1.0, 1.0]))   # mu = 0.5
        >>> float(P[0, 0])
        1.0
        """
        F, batch = _flat(F)
        return self._stress(F, *signed_svd(F)).reshape((3, 3) + batch)

    def _stress(self, F, U, s, V):
        R = np.einsum("ian,jan->ijn", U, V)
        return 2.0 * self.mu * (F - R) + self._volume_stress(s) * R

    # the volume term, the one part a subclass (ProjectiveCorotated) changes ------------
    def _volume_stress(self, s):
        """The volume term's ``dpsi/ds_i`` (the same for each i): ``lam (sum s - 3)`` (Pa)."""
        return self.lam * (s[0] + s[1] + s[2] - 3.0)

    def _volume_stiffness(self, s):
        """The volume term's ``d2psi/ds_a ds_b`` (the same for each a, b): ``lam`` (Pa)."""
        return self.lam

    def singular_value_hessian(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Eigensystem of the Hessian in terms of the signed singular values.

        ``H_ab = 2 mu d_ab + lam``; ``lam_flip = 2 mu``;
        ``lam_twist = (psi_i + psi_j) / max(s_i + s_j, TWIST_EPS)`` with
        ``psi_i = 2 mu (s_i - 1) + lam (sum s - 3)``. (The volume term's parts,
        ``lam`` and ``lam (sum s - 3)``, come from ``_volume_stiffness`` and
        ``_volume_stress``, which :class:`.ProjectiveCorotated` overrides.)

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
        >>> H, lt, lf = Corotated(E=1.0e6, nu=0.25).singular_value_hessian(np.ones((3, 1)))
        >>> round(float(lt[0, 0])), round(float(lf[0, 0]))    # 0 and 2 mu at rest
        (0, 800000)
        """
        mu = self.mu
        n = s.shape[-1]
        H = np.empty((3, 3, n))
        H[...] = self._volume_stiffness(s)
        for a in range(3):
            H[a, a] += 2.0 * mu
        g = self._volume_stress(s)
        lt = np.empty_like(s)
        for row, (i, j, _k) in enumerate(PAIRS):
            lt[row] = (2.0 * mu * (s[i] + s[j] - 2.0) + 2.0 * g) / np.maximum(s[i] + s[j], TWIST_EPS)
        lf = np.full_like(s, 2.0 * mu)
        return H, lt, lf

    def _hessian(self, F, clamp):
        return self.stress_and_tangent(F, project=clamp)[1]

    def stress_and_tangent(self, F: np.ndarray,
                           project: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """``(P, C)`` from one signed SVD (the stress alone needs one too)."""
        F, batch = _flat(F)
        U, s, V = signed_svd(F)
        H, lt, lf = self.singular_value_hessian(s)
        C = isotropic_hessian(U, s, V, H, lt, lf, clamp=project)
        return self._stress(F, U, s, V).reshape((3, 3) + batch), C.reshape((3, 3, 3, 3) + batch)

    def d2psi_dF2(self, F: np.ndarray) -> np.ndarray:
        """Tangent ``dP/dF`` from the singular-value eigensystem (Pa).

        Exact except within ``TWIST_EPS`` of ``s_i + s_j = 0``, where the twist
        denominator is clamped (see the module docstring).

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
        >>> C = Corotated(E=1.0e6, nu=0.25).d2psi_dF2(np.eye(3))
        >>> round(float(C[0, 0, 0, 0])), round(float(C[0, 1, 1, 0]))   # 2 mu + lam, mu
        (1200000, 400000)
        """
        return self._hessian(F, clamp=False)

    def d2psi_dF2_psd(self, F: np.ndarray) -> np.ndarray:
        """Tangent with negative eigenvalues (only ever twist modes) clamped to 0 (Pa).

        Parameters
        ----------
        F : numpy.ndarray, shape (3, 3, ...)
            Deformation gradients.

        Returns
        -------
        C : numpy.ndarray, shape (3, 3, 3, 3) + F.shape[2:]
            Projected tangent (Pa).

        Examples
        --------
        >>> import numpy as np
        >>> C = Corotated(E=1.0, nu=0.3).d2psi_dF2_psd(np.diag([0.5, 0.5, 0.5]))
        >>> bool(np.linalg.eigvalsh(C.reshape(9, 9)).min() >= -1e-12)
        True
        """
        return self._hessian(F, clamp=True)
