"""Hessians of isotropic energies from their singular-value eigensystem, and PSD projection.

An isotropic energy ``psi(F) = psihat(s0, s1, s2)`` of the signed singular
values of ``F = U diag(s) V^T`` (see :mod:`.svd`) has a Hessian
``C = d2psi/dF2`` that is block diagonal in the rotated frame
``dF' = U^T dF V`` (Irving, Teran, Fedkiw 2004; Teran, Sifakis, Irving,
Fedkiw 2005; Smith, de Goes, Kim 2019):

- a 3x3 block on ``(dF'_00, dF'_11, dF'_22)``: ``H_ab = d2psihat / ds_a ds_b``;
- for each pair ``(i, j)`` in ``(0, 1), (0, 2), (1, 2)`` a 2x2 block on
  ``(dF'_ij, dF'_ji)`` with eigenvector ``(1, -1)/sqrt(2)`` ("twist", an
  infinitesimal rotation) of eigenvalue
  ``lam_twist = (psi_i + psi_j) / (s_i + s_j)`` and eigenvector
  ``(1, 1)/sqrt(2)`` ("flip") of eigenvalue
  ``lam_flip = (psi_i - psi_j) / (s_i - s_j)``, ``psi_i = dpsihat/ds_i``.

Each material supplies ``H``, ``lam_twist`` and ``lam_flip`` in a closed form
that does not divide by ``s_i - s_j`` (repeated singular values are the rule,
not the exception: ``F = I``). Clamping the 3x3 block's eigenvalues and the
six 2x2 eigenvalues at zero and rotating back gives the nearest positive
semi-definite Hessian (in the Frobenius norm of the 9x9 matrix), which
Newton's method needs for a descent direction.

Rotating back, ``C_ijkl = sum U_ia V_jb U_kc V_ld C'_abcd``, dominates the
cost. It is done as ``C = M C' M^T`` with ``M = U (x) V`` the 9x9 rotation
of each point (``M[3i+j, 3a+b] = U_ia V_jb``): ``M C'`` combines at most
three columns of ``M`` per column (``C'`` has 21 non-zeros), and the final
``(M C') M^T`` is one batched 9x9 matmul.

An energy that is not isotropic has no such eigensystem: :func:`project_psd_9x9`
eigen-decomposes its 9x9 tangent at each point instead (``numpy.linalg.eigh``,
a few microseconds a point).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .base import Material, _flat
from .svd import signed_svd

__all__ = [
    "PAIRS", "DENSE_FRACTION", "IsotropicMaterial", "isotropic_hessian", "project_psd", "is_psd_3x3",
    "project_psd_9x9",
]

#: Points per chunk of :func:`project_psd_9x9`'s batched eigen-decompositions (bounds the temporaries).
_CHUNK_9x9 = 65536

#: Fraction of indefinite points above which :func:`project_psd` rebuilds every
#: point from the eigensystem (measured break-even on 150k points: ~0.2-0.3).
DENSE_FRACTION = 0.25

#: The index pairs of the 2x2 blocks, in the order of ``lam_twist``/``lam_flip`` rows,
#: with the third index ``k``: ``(i, j, k)``.
PAIRS = ((0, 1, 2), (0, 2, 1), (1, 2, 0))


def is_psd_3x3(H: np.ndarray) -> np.ndarray:
    """Whether each symmetric 3x3 matrix is positive semi-definite (all principal minors >= 0).

    Parameters
    ----------
    H : numpy.ndarray, shape (3, 3, N)
        Symmetric matrices.

    Returns
    -------
    numpy.ndarray of bool, shape (N,)

    Examples
    --------
    >>> import numpy as np
    >>> H = np.stack([np.eye(3), np.diag([1.0, -1.0, 1.0])], axis=-1)
    >>> is_psd_3x3(H)
    array([ True, False])
    """
    h00, h11, h22, h01, h02, h12 = H[0, 0], H[1, 1], H[2, 2], H[0, 1], H[0, 2], H[1, 2]
    m01 = h00 * h11 - h01 * h01
    m02 = h00 * h22 - h02 * h02
    m12 = h11 * h22 - h12 * h12
    det = h00 * m12 - h01 * (h01 * h22 - h12 * h02) + h02 * (h01 * h12 - h11 * h02)
    return (
        (h00 >= 0) & (h11 >= 0) & (h22 >= 0) & (m01 >= 0) & (m02 >= 0) & (m12 >= 0) & (det >= 0)
    )


def _clamp_3x3(H: np.ndarray) -> np.ndarray:
    """Copy of H (3, 3, N) with negative eigenvalues set to zero (eigh only where needed).

    Points with a non-finite entry (an inadmissible F of a barrier energy) come out
    all NaN: LAPACK's eigh cannot take them (it raises for the whole batch).
    """
    H = H.copy()
    finite = np.isfinite(H).all(axis=(0, 1))
    H[..., ~finite] = np.nan
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(~is_psd_3x3(H) & finite)
    if bad.size:
        w, Q = np.linalg.eigh(np.moveaxis(H[..., bad], -1, 0))
        np.maximum(w, 0.0, out=w)
        H[..., bad] = np.moveaxis((Q * w[:, None, :]) @ np.swapaxes(Q, -1, -2), 0, -1)
    return H


def isotropic_hessian(
    U: np.ndarray,
    s: np.ndarray,
    V: np.ndarray,
    d2psi_ds2: np.ndarray,
    lam_twist: np.ndarray,
    lam_flip: np.ndarray,
    clamp: bool,
) -> np.ndarray:
    """Assemble ``C = d2psi/dF2`` of an isotropic energy from its singular-value eigensystem.

    Parameters
    ----------
    U, V : numpy.ndarray, shape (3, 3, N)
        Rotations of the signed SVD ``F = U diag(s) V^T`` (:func:`.svd.signed_svd`).
    s : numpy.ndarray, shape (3, N)
        Signed singular values (only carried for the caller's convenience; the
        eigenvalues below already depend on them).
    d2psi_ds2 : numpy.ndarray, shape (3, 3, N)
        ``d2psihat / ds_a ds_b`` (Pa), symmetric.
    lam_twist, lam_flip : numpy.ndarray, shape (3, N)
        Eigenvalues (Pa) of the 2x2 blocks, rows in the order of :data:`PAIRS`.
    clamp : bool
        True: clamp every negative eigenvalue to zero (the PSD projection).
        False: the exact Hessian.

    Returns
    -------
    C : numpy.ndarray, shape (3, 3, 3, 3, N)
        ``C[i, j, k, l] = d2psi / dF_ij dF_kl`` (Pa).

    Examples
    --------
    A pure quadratic ``psihat = sum (s_i - 1)^2`` at ``F = I`` (twist 0, flip 2)
    is ``||dF||^2`` on symmetric and 0 on skew perturbations:

    >>> import numpy as np
    >>> I = np.eye(3)[:, :, None]
    >>> C = isotropic_hessian(I, np.ones((3, 1)), I, 2 * I, np.zeros((3, 1)),
    ...                       np.full((3, 1), 2.0), clamp=False)
    >>> C.shape
    (3, 3, 3, 3, 1)
    >>> float(C[0, 1, 0, 1, 0]), float(C[0, 1, 1, 0, 0]), float(C[0, 0, 0, 0, 0])
    (1.0, 1.0, 2.0)
    """
    n = s.shape[-1]
    if clamp:
        d2psi_ds2 = _clamp_3x3(d2psi_ds2)
        lam_twist = np.maximum(lam_twist, 0.0)
        lam_flip = np.maximum(lam_flip, 0.0)
    Un = np.moveaxis(U, -1, 0)
    Vn = np.moveaxis(V, -1, 0)
    # M[n, 3i+j, 3a+b] = U_ia V_jb: the 9x9 rotation U (x) V of each point.
    M = (Un[:, :, None, :, None] * Vn[:, None, :, None, :]).reshape(n, 9, 9)
    T = np.empty((n, 9, 9))  # T = M C'
    D = [M[:, :, 4 * a] for a in range(3)]  # the columns (a, a) of M
    for c in range(3):
        T[:, :, 4 * c] = (
            d2psi_ds2[0, c][:, None] * D[0]
            + d2psi_ds2[1, c][:, None] * D[1]
            + d2psi_ds2[2, c][:, None] * D[2]
        )
    for row, (i, j, _k) in enumerate(PAIRS):
        # block [[a, b], [b, a]] on (ij, ji): (1,-1) -> a - b = twist, (1,1) -> a + b = flip
        a = (0.5 * (lam_flip[row] + lam_twist[row]))[:, None]
        b = (0.5 * (lam_flip[row] - lam_twist[row]))[:, None]
        mij, mji = M[:, :, 3 * i + j], M[:, :, 3 * j + i]
        T[:, :, 3 * i + j] = a * mij + b * mji
        T[:, :, 3 * j + i] = b * mij + a * mji
    Cn = T @ np.swapaxes(M, -1, -2)
    C = np.empty((3, 3, 3, 3, n))
    C.reshape(81, n)[...] = Cn.reshape(n, 81).T
    return C


def project_psd(
    F: np.ndarray,
    eigensystem: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]],
    hessian: Callable[[np.ndarray], np.ndarray],
) -> np.ndarray:
    """Hessian of an isotropic energy projected to positive semi-definite at each point.

    Points whose eigenvalues are all >= 0 keep the exact Hessian (the usual
    case near the rest shape); the others are rebuilt with
    :func:`isotropic_hessian` and ``clamp=True``. When more than
    ``DENSE_FRACTION`` of the points need it, every point is rebuilt from the
    eigensystem (the same numbers to round-off), which is cheaper than the
    analytic Hessian plus a gather/scatter of most of it.

    Parameters
    ----------
    F : numpy.ndarray, shape (3, 3, N)
        Deformation gradients.
    eigensystem : callable
        ``eigensystem(s) -> (d2psi_ds2 (3, 3, N), lam_twist (3, N), lam_flip (3, N))``
        for signed singular values ``s`` (3, N), e.g. a material's
        ``singular_value_hessian``.
    hessian : callable
        ``hessian(F) -> C`` (3, 3, 3, 3, N), the exact Hessian (Pa), e.g. a
        material's ``d2psi_dF2``.

    Returns
    -------
    C : numpy.ndarray, shape (3, 3, 3, 3, N)
        The projected Hessian (Pa).

    Examples
    --------
    >>> import numpy as np
    >>> from fem_elastic.materials import NeoHookean
    >>> m = NeoHookean(E=1.0, nu=0.45)
    >>> F = np.diag([0.5, 0.6, 0.7])[:, :, None]   # compressed: twist modes go negative
    >>> C = project_psd(F, m.singular_value_hessian, m.d2psi_dF2)
    >>> bool(np.linalg.eigvalsh(C[..., 0].reshape(9, 9)).min() > -1e-12)
    True
    """
    U, s, V = signed_svd(F)
    # NaN at inadmissible points (Neo-Hookean at det F <= 0) stays NaN, quietly
    with np.errstate(invalid="ignore"):
        H, lt, lf = eigensystem(s)
        bad = np.flatnonzero((lt < 0).any(axis=0) | (lf < 0).any(axis=0) | ~is_psd_3x3(H))
        if bad.size > DENSE_FRACTION * s.shape[-1]:
            return isotropic_hessian(U, s, V, H, lt, lf, clamp=True)
        C = hessian(F)
        if bad.size:
            C[..., bad] = isotropic_hessian(
                U[..., bad], s[:, bad], V[..., bad], H[..., bad], lt[:, bad], lf[:, bad], clamp=True
            )
    return C


def project_psd_9x9(C: np.ndarray) -> np.ndarray:
    """The nearest PSD tangent at each point, by eigen-decomposition of the 9x9 matrix.

    Points already PSD are returned unchanged; at the others the negative
    eigenvalues are set to zero. Non-finite points stay NaN.

    Parameters
    ----------
    C : numpy.ndarray, shape (3, 3, 3, 3, N)
        Symmetric tangents (Pa).

    Returns
    -------
    numpy.ndarray, shape (3, 3, 3, 3, N)
        A new array.

    Examples
    --------
    >>> import numpy as np
    >>> C = np.diag([1.0, -2.0] + [1.0] * 7).reshape(3, 3, 3, 3, 1)
    >>> float(project_psd_9x9(C).reshape(9, 9)[1, 1])
    0.0
    """
    n = C.shape[-1]
    out = C.copy()
    flat = out.reshape(81, n)
    finite = np.isfinite(flat).all(axis=0)
    flat[:, ~finite] = np.nan
    idx = np.flatnonzero(finite)
    for start in range(0, idx.size, _CHUNK_9x9):
        sel = idx[start:start + _CHUNK_9x9]
        A = flat[:, sel].T.reshape(-1, 9, 9)
        A = 0.5 * (A + A.transpose(0, 2, 1))
        w, Q = np.linalg.eigh(A)
        neg = np.flatnonzero(w[:, 0] < 0.0)
        if neg.size:
            wp = np.maximum(w[neg], 0.0)
            fixed = (Q[neg] * wp[:, None, :]) @ Q[neg].transpose(0, 2, 1)
            flat[:, sel[neg]] = fixed.reshape(-1, 81).T
    return out


@dataclass(frozen=True, init=False, repr=False)
class IsotropicMaterial(Material):
    """A material whose energy depends on F only through its singular values.

    Subclasses give the closed-form eigensystem of their Hessian in
    ``singular_value_hessian(s) -> (d2psi_ds2 (3, 3, N), lam_twist (3, N),
    lam_flip (3, N))``, from which :meth:`d2psi_dF2_psd` is built.
    """

    def singular_value_hessian(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - abstract
        raise NotImplementedError

    def d2psi_dF2_psd(self, F: np.ndarray) -> np.ndarray:
        """Tangent projected to positive semi-definite (negative eigenvalues set to 0).

        Equal to :meth:`d2psi_dF2` wherever that is already PSD (see
        :func:`project_psd`).

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
        >>> from fem_elastic.materials import NeoHookean
        >>> C = NeoHookean(E=1.0, nu=0.45).d2psi_dF2_psd(np.diag([0.5, 0.6, 0.7]))
        >>> bool(np.linalg.eigvalsh(C.reshape(9, 9)).min() >= -1e-12)
        True
        """
        Ff, batch = _flat(F)
        C = project_psd(Ff, self.singular_value_hessian, self.d2psi_dF2)
        return C.reshape((3, 3, 3, 3) + batch)
