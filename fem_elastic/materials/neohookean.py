"""Compressible Neo-Hookean material (the classic form, e.g. Bonet and Wood).

With ``I1 = tr(F^T F)``, ``J = det F`` and ``G = F^-T``,

    psi = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2,
    P   = mu (F - G) + lam ln J G,
    C_ijkl = mu d_ik d_jl + lam G_ij G_kl + (mu - lam ln J) G_il G_kj.

Only defined for ``J > 0``: ``psi`` is ``+inf`` for ``J <= 0`` (an inverted
element is inadmissible, and a line search backs off), while ``P`` and ``C``
are NaN there (no warning is raised). Use :class:`StableNeoHookean` where
inversion must be recoverable.

Where ``J`` itself leaves the float range while the energy does not (``F = 1e110 I``:
``J = 1e330`` overflows but ``psi ~ mu |F|^2 / 2 = 1.5e220 mu``; ``F = 1e-110 I``:
``J`` underflows to 0 but ``ln J = -760``), ``ln J`` and ``F^-T`` are computed from
``F / max |F_ij|`` instead, so psi, P and C stay finite and correct there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import _add_identity_term, _cofactor, _det, _flat, _out_of_range, _outer, _scaled_det
from .isotropic import PAIRS, IsotropicMaterial

__all__ = ["NeoHookean"]


@dataclass(frozen=True, init=False, repr=False)
class NeoHookean(IsotropicMaterial):
    """Neo-Hookean material ``psi = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2``.

    ``psi = +inf`` where ``J <= 0``; ``P`` and ``C`` (and the projection) are
    NaN there.

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
    >>> m = NeoHookean(E=1.0e6, nu=0.45)
    >>> F = np.stack([np.eye(3), np.diag([1.0, 1.0, -1.0])], axis=-1)   # rest, inverted
    >>> m.psi(F)
    array([ 0., inf])
    """

    def _invariants(self, F):
        with np.errstate(over="ignore", invalid="ignore"):
            K = _cofactor(F)
            J = _det(F, K)
        with np.errstate(divide="ignore", invalid="ignore"):
            lnJ = np.log(J)
            G = K / J
        odd = _out_of_range(J)
        if odd.size:  # J over- or underflowed: ln J and F^-T through F / max |F_ij|
            log_abs_J, sign, G[..., odd] = _scaled_det(F, odd)
            lnJ[odd] = np.where(sign > 0, log_abs_J, np.nan)
        return J, lnJ, G

    def psi(self, F: np.ndarray) -> np.ndarray:
        """Strain-energy density (J/m^3); ``+inf`` where ``det F <= 0``.

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
        >>> float(NeoHookean(E=1.0, nu=0.3).psi(np.zeros((3, 3))))
        inf
        """
        F, batch = _flat(F)
        with np.errstate(over="ignore", invalid="ignore"):
            J = _det(F)
            I1 = np.einsum("ijn,ijn->n", F, F)
        with np.errstate(divide="ignore", invalid="ignore"):
            lnJ = np.log(J)
        admissible = J > 0.0
        odd = _out_of_range(J)
        if odd.size:  # J over- or underflowed: ln J through F / max |F_ij|
            log_abs_J, sign, _ = _scaled_det(F, odd)
            admissible[odd] = sign > 0
            lnJ[odd] = log_abs_J
        with np.errstate(invalid="ignore", over="ignore"):
            out = 0.5 * self.mu * (I1 - 3.0) - self.mu * lnJ + 0.5 * self.lam * lnJ * lnJ
        out[~admissible] = np.inf
        return out.reshape(batch)

    def dpsi_dF(self, F: np.ndarray) -> np.ndarray:
        """First Piola-Kirchhoff stress ``P = mu (F - F^-T) + lam ln J F^-T`` (Pa).

        Parameters
        ----------
        F : numpy.ndarray, shape (3, 3, ...)
            Deformation gradients, ``det F > 0`` (NaN otherwise).

        Returns
        -------
        P : numpy.ndarray, shape F.shape
            Stress (Pa).

        Examples
        --------
        >>> import numpy as np
        >>> P = NeoHookean(E=1.0, nu=0.0).dpsi_dF(2.0 * np.eye(3))   # mu = 0.5, lam = 0
        >>> float(P[0, 0])                                            # mu (2 - 1/2)
        0.75
        """
        F, batch = _flat(F)
        _, lnJ, G = self._invariants(F)
        with np.errstate(invalid="ignore"):
            P = self.mu * F + (self.lam * lnJ - self.mu) * G
        return P.reshape((3, 3) + batch)

    def d2psi_dF2(self, F: np.ndarray) -> np.ndarray:
        """Analytic tangent ``mu d_ik d_jl + lam G_ij G_kl + (mu - lam ln J) G_il G_kj`` (Pa).

        ``G = F^-T``; NaN where ``det F <= 0``.

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
        >>> C = NeoHookean(E=1.0e6, nu=0.25).d2psi_dF2(np.eye(3))
        >>> round(float(C[0, 0, 0, 0])), round(float(C[0, 1, 1, 0]))   # 2 mu + lam, mu
        (1200000, 400000)
        """
        F, batch = _flat(F)
        _, lnJ, G = self._invariants(F)
        with np.errstate(invalid="ignore"):
            C = _outer(G, G, self.lam)
            c = self.mu - self.lam * lnJ
            Gt = G.transpose(1, 0, 2)
            for i in range(3):
                for j in range(3):
                    # c G_il G_kj as a (k, l) matrix: outer(G[:, j], G[i, :])
                    C[i, j] += (c * Gt[j])[:, None] * G[i][None, :]
        _add_identity_term(C, self.mu)
        return C.reshape((3, 3, 3, 3) + batch)

    def singular_value_hessian(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Eigensystem of the Hessian in terms of the signed singular values.

        With ``g = lam ln J - mu`` (so ``psi_i = mu s_i + g / s_i``):
        ``H_ab = d_ab (mu - g / s_a^2) + lam / (s_a s_b)``,
        ``lam_twist = mu + g / (s_i s_j)``, ``lam_flip = mu - g / (s_i s_j)``.

        Parameters
        ----------
        s : numpy.ndarray, shape (3, N)
            Signed singular values, product ``J > 0``.

        Returns
        -------
        d2psi_ds2 : numpy.ndarray, shape (3, 3, N)
            Pa.
        lam_twist, lam_flip : numpy.ndarray, shape (3, N)
            Pa, rows for the pairs (0, 1), (0, 2), (1, 2).

        Examples
        --------
        >>> import numpy as np
        >>> H, lt, lf = NeoHookean(E=1.0e6, nu=0.25).singular_value_hessian(np.ones((3, 1)))
        >>> round(float(lt[0, 0])), round(float(lf[0, 0]))    # 0 and 2 mu at rest
        (0, 800000)
        """
        mu, lam = self.mu, self.lam
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            # ln J as a sum: s_0 s_1 s_2 may over- or underflow where ln J does not
            g = lam * (np.log(s[0]) + np.log(s[1]) + np.log(s[2])) - mu
            inv = 1.0 / s
        H = lam * inv[:, None] * inv[None, :]
        for a in range(3):
            H[a, a] += mu - g * inv[a] * inv[a]
        lt, lf = np.empty_like(s), np.empty_like(s)
        for row, (i, j, _k) in enumerate(PAIRS):
            q = g * inv[i] * inv[j]
            lt[row] = mu + q
            lf[row] = mu - q
        return H, lt, lf
