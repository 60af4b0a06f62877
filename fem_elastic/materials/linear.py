"""Linear elasticity written as an energy of the deformation gradient.

With the small strain ``eps = (F + F^T)/2 - I``,

    psi = mu eps:eps + lam/2 tr(eps)^2,
    P   = 2 mu eps + lam tr(eps) I,
    C_ijkl = mu (d_ik d_jl + d_il d_jk) + lam d_ij d_kl   (constant).

It is the linearization at ``F = I`` of every other material here. It is NOT
frame-indifferent: a rigid rotation ``F = Q`` gives ``eps = sym(Q) - I != 0``
and a spurious stress (a rotated beam swells), which is why corotated and
hyperelastic models exist.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .base import Material, _flat, _overflow_to_inf

__all__ = ["LinearElastic"]


@dataclass(frozen=True, init=False, repr=False)
class LinearElastic(Material):
    """Small-strain linear elasticity ``psi = mu eps:eps + lam/2 tr(eps)^2``, ``eps = sym(F) - I``.

    Exact only for small displacement gradients; not invariant under rotation
    (use :class:`Corotated` or a hyperelastic model for large rotations). Its
    tangent C is constant and positive semi-definite for any valid E, nu, so
    ``d2psi_dF2_psd`` returns it unchanged.

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
    >>> m = LinearElastic(E=1.0e6, nu=0.25)          # mu = lam = 4e5 Pa
    >>> F = np.diag([1.01, 1.0, 1.0])                 # 1 % uniaxial strain, no batch axes
    >>> P = m.dpsi_dF(F)
    >>> round(float(P[0, 0])), round(float(P[1, 1]))  # (2 mu + lam) eps, lam eps
    (12000, 4000)
    """

    quadratic: ClassVar[bool] = True

    def _tangent(self) -> np.ndarray:
        d = np.eye(3)
        mu, lam = self.mu, self.lam
        return (
            mu * (np.einsum("ik,jl->ijkl", d, d) + np.einsum("il,jk->ijkl", d, d))
            + lam * np.einsum("ij,kl->ijkl", d, d)
        )

    def psi(self, F: np.ndarray) -> np.ndarray:
        """Strain-energy density ``mu eps:eps + lam/2 tr(eps)^2``.

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
        >>> float(LinearElastic(E=1.0, nu=0.0).psi(np.eye(3)))
        0.0
        """
        F, batch = _flat(F)
        mu, lam = self.mu, self.lam
        e00, e11, e22 = F[0, 0] - 1.0, F[1, 1] - 1.0, F[2, 2] - 1.0
        e01, e02, e12 = F[0, 1] + F[1, 0], F[0, 2] + F[2, 0], F[1, 2] + F[2, 1]  # 2 eps_ij
        tr = e00 + e11 + e22
        epseps = e00 * e00 + e11 * e11 + e22 * e22 + 0.5 * (e01 * e01 + e02 * e02 + e12 * e12)
        with np.errstate(invalid="ignore", over="ignore"):
            out = mu * epseps + 0.5 * lam * tr * tr
        return _overflow_to_inf(out, F).reshape(batch)

    def dpsi_dF(self, F: np.ndarray) -> np.ndarray:
        """First Piola-Kirchhoff stress ``P = 2 mu eps + lam tr(eps) I``.

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
        >>> LinearElastic(E=1.0, nu=0.0).dpsi_dF(np.eye(3)[:, :, None]).shape
        (3, 3, 1)
        """
        F, batch = _flat(F)
        mu, lam = self.mu, self.lam
        P = mu * (F + F.transpose(1, 0, 2))
        tr = F[0, 0] + F[1, 1] + F[2, 2] - 3.0
        for i in range(3):
            P[i, i] += lam * tr - 2.0 * mu
        return P.reshape((3, 3) + batch)

    def d2psi_dF2(self, F: np.ndarray) -> np.ndarray:
        """Constant tangent ``C_ijkl = mu (d_ik d_jl + d_il d_jk) + lam d_ij d_kl``.

        Parameters
        ----------
        F : numpy.ndarray, shape (3, 3, ...)
            Deformation gradients (only their batch shape is used).

        Returns
        -------
        C : numpy.ndarray, shape (3, 3, 3, 3) + F.shape[2:]
            ``dP_ij/dF_kl`` (Pa), a new writable array.

        Examples
        --------
        >>> import numpy as np
        >>> C = LinearElastic(E=1.0e6, nu=0.25).d2psi_dF2(np.eye(3))
        >>> round(float(C[0, 0, 0, 0])), round(float(C[0, 1, 1, 0]))   # 2 mu + lam, mu
        (1200000, 400000)
        """
        _, batch = _flat(F)
        C = np.empty((3, 3, 3, 3) + batch)
        C[...] = self._tangent().reshape((3, 3, 3, 3) + (1,) * len(batch))
        return C

    def d2psi_dF2_psd(self, F: np.ndarray) -> np.ndarray:
        """The same as :meth:`d2psi_dF2`: C is PSD for every admissible (E, nu).

        Its eigenvalues are 2 mu (symmetric deviatoric), 0 (skew: rotations
        cost nothing to first order) and 2 mu + 3 lam = 3K (dilation), all >= 0
        when E > 0 and -1 < nu < 0.5.

        Parameters
        ----------
        F : numpy.ndarray, shape (3, 3, ...)
            Deformation gradients.

        Returns
        -------
        C : numpy.ndarray, shape (3, 3, 3, 3) + F.shape[2:]
            Tangent (Pa).

        Examples
        --------
        >>> import numpy as np
        >>> m = LinearElastic(E=1.0, nu=0.3)
        >>> bool(np.array_equal(m.d2psi_dF2_psd(np.eye(3)), m.d2psi_dF2(np.eye(3))))
        True
        """
        return self.d2psi_dF2(F)
