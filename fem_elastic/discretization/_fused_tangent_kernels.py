"""Fused numba kernels for the P1 elastic tangent (Hessian), scattered straight into CSR data.

Imported only by :meth:`fem_elastic.discretization.fused.FusedP1.hessian`, i.e. only where
numba imports. The numpy path of
:meth:`fem_elastic.physics.elastic_body.ElasticPotential.hessian` builds ``C = dP/dF``
at every point ``(3, 3, 3, 3, ne, nq)``, then every element matrix ``(12, 12, ne)``,
then sums them with ``np.bincount``: at 153,600 tets the element matrices alone are
169 MiB of float64 (and the process peaks ~610 MiB above the model, measured by
``scripts/bench_fused_tangent.py``). Here
one pass over the elements does, per tet,

    F_e = I + Ds Dm^-1,   C_e = dP/dF(F_e)  (9x9, ``C[3 i + j, 3 k + l] = dP_ij/dF_kl``),
    C_e <- nearest PSD matrix of C_e  (optional),
    K_e[3 a + i, 3 b + k] = V_e sum_jl dN_a,j C_e[3 i + j, 3 k + l] dN_b,l,
    data[indptr[3 n_a + i] + off[e, a, b] + k] += K_e[3 a + i, 3 b + k],

into the CSR data of the space's fixed
:class:`~fem_elastic.discretization.space.SparsityPattern`: the three rows of a node
list the same columns, so ``off[e, a, b]``, the position of column ``3 n_b`` in row
``3 n_a`` from its start, places the whole 3x3 block. ``off`` is an ``(ne, 4, 4)``
int32 map built once per pattern by binary search (:func:`block_offsets`; 64 bytes an
element: 9.4 MiB at 153,600 tets, where an ``(ne, 12, 12)`` map of every entry took
84 MiB and the pattern's int64 ``scatter``, which this path never builds, 169 MiB).
Only one 9x9 and a few small buffers exist.

Projection: the numpy path projects **per quadrature point**, on the 9x9 ``dP/dF``
(``Material.d2psi_dF2_psd``: the points already PSD keep the exact tangent, the
others get their negative eigenvalues clamped to zero, which is the nearest PSD
matrix in the Frobenius norm of the 9x9 matrix), never the 12x12 element
matrix. The same is done here: a P1 tet has one F, so one 9x9 per element. A
Cholesky factorisation decides whether C is positive definite (cheap: no
eigen-decomposition for the usual case); where it fails, an eigen-decomposition
of the symmetrised 9x9 (Householder + implicit QL, no allocation) clamps the
negative eigenvalues. Both paths compute the
same matrix, the nearest PSD one, to round-off; a tangent that is PSD with a
zero eigenvalue (StVK's rotations at rest) may go through the eigen-decomposition here, and
changes by the clamping of an eigenvalue of round-off size only.
:class:`~fem_elastic.materials.LinearElastic` is never projected: its tangent is
PSD for every admissible (E, nu), and its ``d2psi_dF2_psd`` is ``d2psi_dF2``.
Non-finite tangents (a Neo-Hookean tet with det F <= 0) stay NaN, as on the numpy path.

The pointwise tangents repeat the closed forms of the material modules
(:mod:`fem_elastic.materials.linear`, ``stvk``, ``neohookean``, ``stable_neohookean``);
the element loops take the ``kind`` constants and the ``prm`` tuples of
:mod:`._fused_kernels`. Serial loop, for the same reasons as the force kernel.
"""

from __future__ import annotations

import math
import weakref

import numba
import numpy as np

from . import _fused_kernels
from ._fused_kernels import (
    LINEAR,
    NEOHOOKEAN,
    STVK,
    _cofactor,
    _deformation_gradient,
    _frobenius2,
    drop_stale_caches,
)

drop_stale_caches(__file__, _fused_kernels.__file__)  # F and the cofactor are inlined from there

_jit = numba.njit(cache=True, error_model="numpy", nogil=True)


# pointwise tangents: C[3 i + j, 3 k + l] = dP_ij / dF_kl ----------------------------
@_jit
def _linear_C(C, prm):
    """mu (d_ik d_jl + d_il d_jk) + lam d_ij d_kl (materials.linear)."""
    mu, lam = prm[0], prm[1]
    C[:, :] = 0.0
    for i in range(3):
        for j in range(3):
            C[3 * i + j, 3 * i + j] += mu
            C[3 * i + j, 3 * j + i] += mu
        for k in range(3):
            C[4 * i, 4 * k] += lam


@_jit
def _stvk_C(C, F, prm):
    """d_ik S_jl + mu B_ik d_jl + mu F_il F_kj + lam F_ij F_kl (materials.stvk)."""
    mu, lam = prm[0], prm[1]
    S = np.empty((3, 3))
    B = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            cab = F[a] * F[b] + F[3 + a] * F[3 + b] + F[6 + a] * F[6 + b]  # (F^T F)_ab
            S[a, b] = mu * cab
            B[a, b] = F[3 * a] * F[3 * b] + F[3 * a + 1] * F[3 * b + 1] + F[3 * a + 2] * F[3 * b + 2]
    trE = 0.5 * (_frobenius2(F) - 3.0)  # tr(F^T F) = |F|^2
    for a in range(3):
        S[a, a] += lam * trE - mu  # S = 2 mu E + lam tr(E) I = mu (F^T F - I) + lam trE I
    for i in range(3):
        for j in range(3):
            for k in range(3):
                for l in range(3):
                    v = mu * F[3 * i + l] * F[3 * k + j] + lam * F[3 * i + j] * F[3 * k + l]
                    if i == k:
                        v += S[j, l]
                    if j == l:
                        v += mu * B[i, k]
                    C[3 * i + j, 3 * k + l] = v


@_jit
def _neohookean_C(C, F, prm):
    """mu d_ik d_jl + lam G_ij G_kl + (mu - lam ln J) G_il G_kj, G = F^-T (materials.neohookean)."""
    mu, lam = prm[0], prm[1]
    K = _cofactor(F)
    J = F[0] * K[0] + F[1] * K[1] + F[2] * K[2]
    lnJ = np.log(J)  # NaN for J < 0, -inf at 0: the tangent is NaN, as on the numpy path
    c = mu - lam * lnJ
    for i in range(3):
        for j in range(3):
            gij = K[3 * i + j] / J
            for k in range(3):
                for l in range(3):
                    v = lam * gij * (K[3 * k + l] / J) + c * (K[3 * i + l] / J) * (K[3 * k + j] / J)
                    if i == k and j == l:
                        v += mu
                    C[3 * i + j, 3 * k + l] = v


@_jit
def _stable_neohookean_C(C, F, prm):
    """2 mu' F (x) F / (I_C + 1)^2 + lam' K (x) K + lam' (J - alpha) dK/dF + mu' (1 - 1/(I_C + 1)) I.

    ``K = cof F``, ``dK_ij/dF_kl = e_ikn e_jlq F_nq`` (materials.stable_neohookean).
    """
    mu_, lam_, alpha = prm
    IC = _frobenius2(F)
    K = _cofactor(F)
    J = F[0] * K[0] + F[1] * K[1] + F[2] * K[2]
    ic1 = 1.0 / (IC + 1.0)
    f = 2.0 * mu_ * ic1 * ic1
    h = lam_ * (J - alpha)
    m = mu_ * (1.0 - ic1)
    for i in range(3):
        for j in range(3):
            for k in range(3):
                for l in range(3):
                    v = f * F[3 * i + j] * F[3 * k + l] + lam_ * K[3 * i + j] * K[3 * k + l]
                    if i != k and j != l:
                        s = 1.0 if (k - i) % 3 == 1 else -1.0
                        if (l - j) % 3 != 1:
                            s = -s
                        v += h * s * F[3 * (3 - i - k) + (3 - j - l)]
                    if i == k and j == l:
                        v += m
                    C[3 * i + j, 3 * k + l] = v


@_jit
def tangent(kind, F, prm, C):
    """C = dP/dF (9x9) of the material ``kind`` at F (a row-major 9-tuple), written into C."""
    if kind == LINEAR:
        _linear_C(C, prm)
    elif kind == STVK:
        _stvk_C(C, F, prm)
    elif kind == NEOHOOKEAN:
        _neohookean_C(C, F, prm)
    else:
        _stable_neohookean_C(C, F, prm)


# projection -------------------------------------------------------------------------
@_jit
def _positive_definite(C, L):
    """Whether the symmetric 9x9 C is positive definite (Cholesky into the scratch L)."""
    for i in range(9):
        for j in range(i + 1):
            s = C[i, j]
            for p in range(j):
                s -= L[i, p] * L[j, p]
            if i == j:
                if not s > 0.0:  # also False for NaN
                    return False
                L[i, i] = np.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    return True


@_jit
def _eigh_tridiagonal_ql(V, d, e):
    """Symmetric eigen-decomposition in place, without allocation: ``V <- Q``, ``d <- w``.

    On entry V holds the symmetric matrix, on return its orthonormal eigenvectors
    (columns) with ``d`` the eigenvalues (unsorted); ``e`` is scratch. Householder
    tridiagonalisation, then the implicit QL iteration (EISPACK's tred2 and tql2 as
    in JAMA). numba's ``np.linalg.eigh`` spends most of its ~25 us a 9x9 in LAPACK's
    workspace queries and copies; this does the same arithmetic in about half that.
    """
    n = V.shape[0]
    for j in range(n):
        d[j] = V[n - 1, j]
    for i in range(n - 1, 0, -1):
        scale = 0.0
        h = 0.0
        for k in range(i):
            scale += abs(d[k])
        if scale == 0.0:
            e[i] = d[i - 1]
            for j in range(i):
                d[j] = V[i - 1, j]
                V[i, j] = 0.0
                V[j, i] = 0.0
        else:
            for k in range(i):
                d[k] /= scale
                h += d[k] * d[k]
            f = d[i - 1]
            g = math.sqrt(h)
            if f > 0:
                g = -g
            e[i] = scale * g
            h = h - f * g
            d[i - 1] = f - g
            for j in range(i):
                e[j] = 0.0
            for j in range(i):
                f = d[j]
                V[j, i] = f
                g = e[j] + V[j, j] * f
                for k in range(j + 1, i):
                    g += V[k, j] * d[k]
                    e[k] += V[k, j] * f
                e[j] = g
            f = 0.0
            for j in range(i):
                e[j] /= h
                f += e[j] * d[j]
            hh = f / (h + h)
            for j in range(i):
                e[j] -= hh * d[j]
            for j in range(i):
                f = d[j]
                g = e[j]
                for k in range(j, i):
                    V[k, j] -= f * e[k] + g * d[k]
                d[j] = V[i - 1, j]
                V[i, j] = 0.0
        d[i] = h
    for i in range(n - 1):
        V[n - 1, i] = V[i, i]
        V[i, i] = 1.0
        h = d[i + 1]
        if h != 0.0:
            for k in range(i + 1):
                d[k] = V[k, i + 1] / h
            for j in range(i + 1):
                g = 0.0
                for k in range(i + 1):
                    g += V[k, i + 1] * V[k, j]
                for k in range(i + 1):
                    V[k, j] -= g * d[k]
        for k in range(i + 1):
            V[k, i + 1] = 0.0
    for j in range(n):
        d[j] = V[n - 1, j]
        V[n - 1, j] = 0.0
    V[n - 1, n - 1] = 1.0
    e[0] = 0.0
    # tql2
    for i in range(1, n):
        e[i - 1] = e[i]
    e[n - 1] = 0.0
    f = 0.0
    tst1 = 0.0
    eps = 2.0 ** -52
    for l in range(n):
        tst1 = max(tst1, abs(d[l]) + abs(e[l]))
        m = l
        while m < n - 1:
            if abs(e[m]) <= eps * tst1:
                break
            m += 1
        if m > l:
            for _it in range(100):
                g = d[l]
                p = (d[l + 1] - g) / (2.0 * e[l])
                r = math.hypot(p, 1.0)
                if p < 0:
                    r = -r
                d[l] = e[l] / (p + r)
                d[l + 1] = e[l] * (p + r)
                dl1 = d[l + 1]
                h = g - d[l]
                for i in range(l + 2, n):
                    d[i] -= h
                f += h
                p = d[m]
                c = 1.0
                c2 = c
                c3 = c
                el1 = e[l + 1]
                s = 0.0
                s2 = 0.0
                for i in range(m - 1, l - 1, -1):
                    c3 = c2
                    c2 = c
                    s2 = s
                    g = c * e[i]
                    h = c * p
                    r = math.hypot(p, e[i])
                    e[i + 1] = s * r
                    s = e[i] / r
                    c = p / r
                    p = c * d[i] - s * g
                    d[i + 1] = h + s * (c * g + s * d[i])
                    for k in range(n):
                        h = V[k, i + 1]
                        V[k, i + 1] = s * V[k, i] + c * h
                        V[k, i] = c * V[k, i] - s * h
                p = -s * s2 * c3 * el1 * e[l] / dl1
                e[l] = s * p
                d[l] = c * p
                if not abs(e[l]) > eps * tst1:
                    break
        d[l] = d[l] + f
        e[l] = 0.0


@_jit
def project_psd(C, L, Q, w):
    """C <- the nearest PSD matrix (negative eigenvalues set to 0); non-finite C -> all NaN.

    ``L`` (9x9), ``Q`` (9x9) and ``w`` (9,) are scratch arrays.
    """
    finite = True
    for r in range(9):
        for c in range(9):
            if not np.isfinite(C[r, c]):
                finite = False
    if not finite:
        C[:, :] = np.nan
        return
    if _positive_definite(C, L):
        return
    for r in range(9):  # Q <- the symmetrised C, decomposed in place (L: scratch)
        for c in range(9):
            Q[r, c] = 0.5 * (C[r, c] + C[c, r])
    _eigh_tridiagonal_ql(Q, w, L[0])
    if w.min() >= 0.0:
        return  # PSD with a zero eigenvalue: keep the exact tangent, as the numpy path
    for r in range(9):
        for c in range(r + 1):
            s = 0.0
            for p in range(9):
                if w[p] > 0.0:
                    s += Q[r, p] * w[p] * Q[c, p]
            C[r, c] = s
            C[c, r] = s


@_jit
def tangent_points(kind, F, prm, project, out):
    """C (9x9) at each of N points, F ``(9, N)``, out ``(N, 9, 9)`` (tests compare with the materials)."""
    L = np.zeros((9, 9))
    Q = np.empty((9, 9))
    w = np.empty(9)
    for n in range(F.shape[1]):
        Fn = (F[0, n], F[1, n], F[2, n], F[3, n], F[4, n], F[5, n], F[6, n], F[7, n], F[8, n])
        tangent(kind, Fn, prm, out[n])
        if project and kind != LINEAR:
            project_psd(out[n], L, Q, w)


# element loop -------------------------------------------------------------------------
@_jit
def hessian_p1(x, X, nodes, Dm_inv, V, kind, prm, project, indptr, off, data):
    """data = the CSR data of sum_e K_e, K_e's 3x3 blocks placed by ``off`` (ne, 4, 4) in the rows
    of ``indptr`` (see the module notes).

    ``project``: replace each element's C by its nearest PSD matrix (not for LINEAR,
    whose tangent is PSD). data is overwritten.
    """
    data[:] = 0.0
    C = np.empty((9, 9))
    L = np.zeros((9, 9))
    Q = np.empty((9, 9))
    w = np.empty(9)
    T = np.empty((3, 3, 4, 3))  # T[i, j, b, k] = sum_l C[3 i + j, 3 k + l] dN_b,l
    dN = np.empty((4, 3))
    for e in range(nodes.shape[0]):
        F = _deformation_gradient(x, X, nodes, Dm_inv, e)
        tangent(kind, F, prm, C)
        if project and kind != LINEAR:
            project_psd(C, L, Q, w)
        d = Dm_inv[e]
        v = V[e]
        for j in range(3):
            dN[1, j], dN[2, j], dN[3, j] = d[0, j], d[1, j], d[2, j]
            dN[0, j] = -(d[0, j] + d[1, j] + d[2, j])
        for i in range(3):
            for j in range(3):
                r = 3 * i + j
                for b in range(4):
                    for k in range(3):
                        c = 3 * k
                        T[i, j, b, k] = v * (C[r, c] * dN[b, 0] + C[r, c + 1] * dN[b, 1]
                                             + C[r, c + 2] * dN[b, 2])
        for a in range(4):
            for i in range(3):
                start = indptr[3 * nodes[e, a] + i]
                for b in range(4):
                    pos = start + off[e, a, b]
                    for k in range(3):
                        data[pos + k] += (dN[a, 0] * T[i, 0, b, k] + dN[a, 1] * T[i, 1, b, k]
                                          + dN[a, 2] * T[i, 2, b, k])


@_jit
def block_offsets(nodes, indptr, indices, off):
    """off[e, a, b] = position of column ``3 nodes[e, b]`` in CSR row ``3 nodes[e, a]``, from its start.

    Binary search in the sorted column indices of the row; -1 if absent (the
    caller checks: the pattern was not built on these elements).
    """
    for e in range(nodes.shape[0]):
        for a in range(nodes.shape[1]):
            lo0 = indptr[3 * nodes[e, a]]
            hi0 = indptr[3 * nodes[e, a] + 1]
            for b in range(nodes.shape[1]):
                c = 3 * nodes[e, b]
                lo, hi = lo0, hi0
                while lo < hi:
                    mid = (lo + hi) // 2
                    if indices[mid] < c:
                        lo = mid + 1
                    else:
                        hi = mid
                off[e, a, b] = lo - lo0 if lo < hi0 and indices[lo] == c else -1


# the map into the CSR data ------------------------------------------------------------
#: SparsityPattern -> its (ne, nl, nl) block-offset map; dropped with the pattern.
_offset_cache: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def element_offsets(pattern, nodes: np.ndarray) -> np.ndarray:
    """``(ne, nl, nl)`` int32 offset of each element's node blocks within their CSR rows (cached).

    Built once per pattern by :func:`block_offsets` (an element's entry
    ``(3 a + i, 3 b + k)`` sits at ``indptr[3 nodes[e, a] + i] + off[e, a, b] + k``).
    Serves the P1 (``nl = 4``) and the P2 (``nl = 10``, :mod:`._fused_p2_kernels`) tangents.

    Parameters
    ----------
    pattern : SparsityPattern
        Of the space whose element nodes are ``nodes``.
    nodes : numpy.ndarray
        ``(ne, nl)`` scalar node indices (the vertices for P1).

    Returns
    -------
    numpy.ndarray
        Read-only, C-contiguous.
    """
    off = _offset_cache.get(pattern)
    if off is None:
        off = np.empty(nodes.shape + (nodes.shape[1],), dtype=np.int32)
        block_offsets(nodes, pattern.indptr, pattern.indices, off)
        if off.size and off.min() < 0:
            raise ValueError("the sparsity pattern does not hold every element's node pairs: "
                             "it was built for another discretization")
        off.setflags(write=False)
        _offset_cache[pattern] = off
    return off


def hessian(fused, x: np.ndarray, pattern, project: bool):
    """The P1 tangent stiffness (N/m) on ``pattern`` by the fused kernel, a CSR matrix.

    Parameters
    ----------
    fused : FusedP1
        The material's kind and parameters and the P1 geometry.
    x : numpy.ndarray, shape (ndofs,)
        DOF positions (m).
    pattern : SparsityPattern
        The space's pattern; the matrix shares its ``indices`` and ``indptr``.
    project : bool
        Project each element's 9x9 dP/dF to PSD (as ``Material.d2psi_dF2_psd``).

    Returns
    -------
    scipy.sparse.csr_matrix
    """
    import scipy.sparse as sp

    g = fused.geo
    data = np.empty(pattern.nnz)
    hessian_p1(fused._x(x), g.X, g.nodes, g.Dm_inv, g.V, fused.kind, fused.prm, bool(project),
               pattern.indptr, element_offsets(pattern, g.nodes), data)
    return sp.csr_matrix((data, pattern.indices, pattern.indptr), shape=pattern.shape, copy=False)
