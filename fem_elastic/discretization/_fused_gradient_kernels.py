"""The P1 force loop of :mod:`fem_elastic.discretization.fused`, in blocks the CPU can vectorise.

``out = dE/dx``: for each tet, ``g_ai += V P_ij dN_aj`` with ``F = I + Ds Dm^-1``
(conventions: :mod:`._fused_kernels`). The elements are taken :data:`BLOCK` at
a time (:func:`_block`), in passes over the block:

1. Dm^-1 and V of the block, stored once in this layout by :func:`blocks`,
   copied into a buffer on the stack (one contiguous copy);
2. gather (scalar): the edge displacements ``Ds`` (9 numbers) of each element,
   from ``u = x - X`` formed once per call (12 loads per element instead of 24:
   5.6 -> 4.8 ms);
3. F and J (vectorised);
4. ln J for the Neo-Hookean material (scalar: numba has no vector ``log``
   without Intel's SVML);
5. ``V P Dm^-T`` (vectorised), one loop per material;
6. scatter (scalar), element by element in the serial order.

Passes 3 and 5 are plain loops over the block of unit stride with compile-time
row offsets (``row * BLOCK + j``), which LLVM turns into AVX code. Two things
make that happen, both measured on the 153,600-tet beam (one thread):

- the buffers are the function's own (``alloca`` on the stack, :func:`_stack`),
  so LLVM knows that they alias nothing. Buffers handed in as arguments, or
  Dm^-1 read in place from :func:`blocks`' array, leave it to runtime alias
  checks over ~30 rows, and the loops stayed scalar: 7.4-7.9 ms against 5.5 ms.
  (Heap buffers made per call would do as well, but allocate on every step.)
- the passes are written out in one function: the same passes as separate
  functions, called per block, measured 7.0-8.3 ms.

The element-at-a-time loop this replaces (``_fused_kernels`` before issue 19's
second pass) could not be vectorised because of the gather and the scatter
inside it: 9.2-10.5 ms. Each value is computed with the same operations in the
same order as that loop and the numpy materials (no ``fastmath``, so no
reassociation and no FMA contraction), and the scatter keeps the element order:
**the same bits** as the element-at-a-time loop for every finite result, and NaN
in the same places (a NaN's sign bit may differ: the vector code orders NaN
operands otherwise), checked by ``tests/test_explicit_fast.py``.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from . import _fused_kernels
from ._fused_kernels import (
    LINEAR,
    NEOHOOKEAN,
    STVK,
    _jit,
    _jit_inline,
    _pjit,
    drop_stale_caches,
    linear_P,
    stable_neohookean_P,
    stvk_P,
)

drop_stale_caches(__file__, _fused_kernels.__file__)  # the laws are inlined from there

#: Elements per block: the stack buffers (30 x BLOCK doubles, 15 KiB) stay in L1.
BLOCK = 64
#: Rows of a block of the stored geometry: Dm^-1 row by row (9), V (1).
ROWS = 10
_NA, _NF, _ND = 9 * BLOCK, 11 * BLOCK, ROWS * BLOCK  # Ds then forces; F, J, ln J; Dm^-1, V


def blocks(Dm_inv: np.ndarray, V: np.ndarray, starts) -> tuple[np.ndarray, np.ndarray]:
    """Dm^-1 and V of the ranges ``starts[r]:starts[r + 1]`` in the kernels' block layout.

    Each range is cut into blocks of :data:`BLOCK` elements from its own start
    (the last one padded with zeros); block b is row ``DB[b]``, holding
    ``Dm_inv[e].ravel()[k]`` at ``k * BLOCK + j`` and ``V[e]`` at
    ``9 * BLOCK + j`` for the element e = (its range's start) + (block's offset) + j.

    Parameters
    ----------
    Dm_inv : ndarray, ``(ne, 3, 3)``
    V : ndarray, ``(ne,)``
        Volumes (m^3).
    starts : sequence of int
        The ranges' boundaries, increasing, from 0 to ne.

    Returns
    -------
    DB : ndarray, ``(n_blocks, ROWS * BLOCK)``
        80 bytes per element, plus the padding.
    first_block : ndarray of int64, ``(len(starts),)``
        The block of each range's first element; the last entry is ``n_blocks``.
    """
    starts = np.asarray(starts, dtype=np.int64)
    counts = -(-np.diff(starts) // BLOCK)
    first_block = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
    DB = np.zeros((int(first_block[-1]), ROWS, BLOCK))
    D = Dm_inv.reshape(-1, 9)
    for r in range(len(starts) - 1):
        a, b = int(starts[r]), int(starts[r + 1])
        slots = np.arange(b - a)
        blk, j = first_block[r] + slots // BLOCK, slots % BLOCK
        DB[blk, :9, j] = D[a:b]
        DB[blk, 9, j] = V[a:b]
    return DB.reshape(len(DB), ROWS * BLOCK), first_block


@intrinsic
def _stack_pointer(typingctx, n):
    """A pointer to ``n`` (a compile-time constant) float64 on the calling function's stack."""
    if not isinstance(n, types.IntegerLiteral):
        return None
    size = n.literal_value

    def codegen(context, builder, signature, args):
        return cgutils.alloca_once(builder, context.get_value_type(types.float64), size=size)

    return types.CPointer(types.float64)(n), codegen


@_jit_inline
def _stack(n):
    """A float64 array of ``n`` entries on the stack of the function it is inlined into (no heap
    allocation, and private to the thread).

    Only for jitted callers that do not let the array escape: ``inline="always"`` is what puts
    the ``alloca`` in the caller's frame (called on its own, it would point into a dead frame).
    """
    return numba.carray(_stack_pointer(n), n)


@_jit_inline
def _load_F(Fb, j):
    return (Fb[j], Fb[BLOCK + j], Fb[2 * BLOCK + j], Fb[3 * BLOCK + j], Fb[4 * BLOCK + j],
            Fb[5 * BLOCK + j], Fb[6 * BLOCK + j], Fb[7 * BLOCK + j], Fb[8 * BLOCK + j])


@_jit_inline
def _store_force(p, v, j, Dd, A):
    """A[3 i + b] = V P_ik dN_{b+1, k}: node b+1's force, component i (as _fused_kernels did).

    Written out (no loop over i): numba's range loop is not unrolled before LLVM's vectoriser.
    """
    d00, d01, d02 = Dd[j], Dd[BLOCK + j], Dd[2 * BLOCK + j]
    d10, d11, d12 = Dd[3 * BLOCK + j], Dd[4 * BLOCK + j], Dd[5 * BLOCK + j]
    d20, d21, d22 = Dd[6 * BLOCK + j], Dd[7 * BLOCK + j], Dd[8 * BLOCK + j]
    q0, q1, q2 = p[0] * v, p[1] * v, p[2] * v
    A[j] = q0 * d00 + q1 * d01 + q2 * d02
    A[BLOCK + j] = q0 * d10 + q1 * d11 + q2 * d12
    A[2 * BLOCK + j] = q0 * d20 + q1 * d21 + q2 * d22
    q0, q1, q2 = p[3] * v, p[4] * v, p[5] * v
    A[3 * BLOCK + j] = q0 * d00 + q1 * d01 + q2 * d02
    A[4 * BLOCK + j] = q0 * d10 + q1 * d11 + q2 * d12
    A[5 * BLOCK + j] = q0 * d20 + q1 * d21 + q2 * d22
    q0, q1, q2 = p[6] * v, p[7] * v, p[8] * v
    A[6 * BLOCK + j] = q0 * d00 + q1 * d01 + q2 * d02
    A[7 * BLOCK + j] = q0 * d10 + q1 * d11 + q2 * d12
    A[8 * BLOCK + j] = q0 * d20 + q1 * d21 + q2 * d22


@_jit
def _block(u, nodes, Dsrc, kind, prm, s, n, out):
    """out += the forces of the elements s:s+n (n <= BLOCK), whose Dm^-1 and V are ``Dsrc``;
    ``u = x - X``."""
    A = _stack(_NA)  # Ds (row-major 3x3: A[3 c + i] = u_{c+1, i} - u_{0, i}), then the forces
    Fb = _stack(_NF)  # F (9 rows), J, ln J
    Dd = _stack(_ND)  # Dm^-1 (9 rows), V
    for k in range(_ND):
        Dd[k] = Dsrc[k]
    # gather: the edges of u = x - X (as _fused_kernels._deformation_gradient9, whose
    # x[k] - X[k] is the same number as u[k])
    for j in range(n):
        e = s + j
        k0, k1, k2, k3 = 3 * nodes[e, 0], 3 * nodes[e, 1], 3 * nodes[e, 2], 3 * nodes[e, 3]
        u0, u1, u2 = u[k0], u[k0 + 1], u[k0 + 2]
        A[j] = u[k1] - u0
        A[BLOCK + j] = u[k1 + 1] - u1
        A[2 * BLOCK + j] = u[k1 + 2] - u2
        A[3 * BLOCK + j] = u[k2] - u0
        A[4 * BLOCK + j] = u[k2 + 1] - u1
        A[5 * BLOCK + j] = u[k2 + 2] - u2
        A[6 * BLOCK + j] = u[k3] - u0
        A[7 * BLOCK + j] = u[k3 + 1] - u1
        A[8 * BLOCK + j] = u[k3 + 2] - u2
    # F = I + Ds Dm^-1 and J = det F (vectorised)
    for j in range(n):
        a0, a1, a2 = A[j], A[BLOCK + j], A[2 * BLOCK + j]
        b0, b1, b2 = A[3 * BLOCK + j], A[4 * BLOCK + j], A[5 * BLOCK + j]
        c0, c1, c2 = A[6 * BLOCK + j], A[7 * BLOCK + j], A[8 * BLOCK + j]
        d00, d01, d02 = Dd[j], Dd[BLOCK + j], Dd[2 * BLOCK + j]
        d10, d11, d12 = Dd[3 * BLOCK + j], Dd[4 * BLOCK + j], Dd[5 * BLOCK + j]
        d20, d21, d22 = Dd[6 * BLOCK + j], Dd[7 * BLOCK + j], Dd[8 * BLOCK + j]
        f0 = a0 * d00 + b0 * d10 + c0 * d20 + 1.0
        f1 = a0 * d01 + b0 * d11 + c0 * d21
        f2 = a0 * d02 + b0 * d12 + c0 * d22
        f3 = a1 * d00 + b1 * d10 + c1 * d20
        f4 = a1 * d01 + b1 * d11 + c1 * d21 + 1.0
        f5 = a1 * d02 + b1 * d12 + c1 * d22
        f6 = a2 * d00 + b2 * d10 + c2 * d20
        f7 = a2 * d01 + b2 * d11 + c2 * d21
        f8 = a2 * d02 + b2 * d12 + c2 * d22 + 1.0
        Fb[j], Fb[BLOCK + j], Fb[2 * BLOCK + j] = f0, f1, f2
        Fb[3 * BLOCK + j], Fb[4 * BLOCK + j], Fb[5 * BLOCK + j] = f3, f4, f5
        Fb[6 * BLOCK + j], Fb[7 * BLOCK + j], Fb[8 * BLOCK + j] = f6, f7, f8
        # J as _fused_kernels.neohookean_P forms it: F_0k times the cofactor's first row
        Fb[9 * BLOCK + j] = f0 * (f4 * f8 - f5 * f7) + f1 * (f5 * f6 - f3 * f8) + f2 * (f3 * f7 - f4 * f6)
    # V P Dm^-T, the forces on nodes 1-3 (vectorised), one loop per material
    if kind == NEOHOOKEAN:
        mu, lam = prm[0], prm[1]
        for j in range(n):  # scalar: ln J; NaN for J < 0, -inf for J = 0
            Fb[10 * BLOCK + j] = np.log(Fb[9 * BLOCK + j])
        for j in range(n):
            f0, f1, f2, f3, f4, f5, f6, f7, f8 = _load_F(Fb, j)
            # as _fused_kernels.neohookean_P, with ln J from the loop above
            c = (lam * Fb[10 * BLOCK + j] - mu) / Fb[9 * BLOCK + j]
            k0, k1, k2 = f4 * f8 - f5 * f7, f5 * f6 - f3 * f8, f3 * f7 - f4 * f6
            k3, k4, k5 = f2 * f7 - f1 * f8, f0 * f8 - f2 * f6, f1 * f6 - f0 * f7
            k6, k7, k8 = f1 * f5 - f2 * f4, f2 * f3 - f0 * f5, f0 * f4 - f1 * f3
            p = (mu * f0 + c * k0, mu * f1 + c * k1, mu * f2 + c * k2,
                 mu * f3 + c * k3, mu * f4 + c * k4, mu * f5 + c * k5,
                 mu * f6 + c * k6, mu * f7 + c * k7, mu * f8 + c * k8)
            _store_force(p, Dd[9 * BLOCK + j], j, Dd, A)
    elif kind == LINEAR:
        for j in range(n):
            _store_force(linear_P(_load_F(Fb, j), prm), Dd[9 * BLOCK + j], j, Dd, A)
    elif kind == STVK:
        for j in range(n):
            _store_force(stvk_P(_load_F(Fb, j), prm), Dd[9 * BLOCK + j], j, Dd, A)
    else:
        for j in range(n):
            _store_force(stable_neohookean_P(_load_F(Fb, j), prm), Dd[9 * BLOCK + j], j, Dd, A)
    # scatter, element by element (node 0 takes minus the others' sum)
    for j in range(n):
        e = s + j
        k0, k1, k2, k3 = 3 * nodes[e, 0], 3 * nodes[e, 1], 3 * nodes[e, 2], 3 * nodes[e, 3]
        for i in range(3):
            f1 = A[3 * i * BLOCK + j]
            f2 = A[(3 * i + 1) * BLOCK + j]
            f3 = A[(3 * i + 2) * BLOCK + j]
            out[k1 + i] += f1
            out[k2 + i] += f2
            out[k3 + i] += f3
            out[k0 + i] -= f1 + f2 + f3


@_jit
def _displacement(x, X, u):
    """u = x - X, once per call: the gather then reads 12 numbers per element, not 24."""
    for k in range(x.shape[0]):
        u[k] = x[k] - X[k]


@_jit
def gradient_range(u, nodes, DB, b0, kind, prm, start, stop, out):
    """out += dE_e/dx of the elements start:stop, BLOCK at a time (``u = x - X``).

    ``DB[b0 + i]`` is the stored Dm^-1 and V of the block starting at element
    ``start + i * BLOCK`` (:func:`blocks`).
    """
    b = b0
    for s in range(start, stop, BLOCK):
        _block(u, nodes, DB[b], kind, prm, s, min(BLOCK, stop - s), out)
        b += 1


@_jit
def gradient_p1(x, X, u, nodes, DB, kind, prm, out):
    """out = dE/dx: for each tet, g_ai += V P_ij dN_aj.

    Parameters: x, X ``(ndofs,)``; u ``(ndofs,)``, scratch (overwritten with
    x - X); nodes ``(ne, 4)`` vertex indices; DB the stored Dm^-1 and V of
    the range ``0:ne`` (:func:`blocks`), where ``Dm_inv[e, b, j] = dN_{b+1, j}``
    (the gradients of the shape functions of nodes 1-3; node 0's is minus
    their sum) and V the volumes (m^3); out ``(ndofs,)`` (N), overwritten.
    """
    _displacement(x, X, u)
    out[:] = 0.0
    gradient_range(u, nodes, DB, 0, kind, prm, 0, nodes.shape[0], out)


@_pjit
def gradient_p1_parts(x, X, u, nodes, DB, first_block, kind, prm, part_start, out):
    """:func:`gradient_p1` on numba's threads: the interiors of P parts in parallel, then the seams.

    The elements are given grouped: part p's interior is
    ``part_start[p]:part_start[p + 1]`` (p < P = ``len(part_start) - 2``),
    elements none of whose vertices another part touches, so the parts
    scatter into disjoint entries of ``out`` without atomics; the seams (the
    elements with a vertex shared between parts) are the last group,
    ``part_start[P]:part_start[P + 1]``, summed serially afterwards. One
    thread per part and a single synchronisation: a loaded machine that
    deschedules a thread costs one wait, not one per colour. Each group keeps
    the element order, so a vertex inside a part gets its contributions in
    the serial loop's order; a seam vertex gets its seam elements' last.
    ``DB, first_block`` are :func:`blocks` of the groups; u is scratch, as in :func:`gradient_p1`.
    """
    _displacement(x, X, u)
    out[:] = 0.0
    n_parts = part_start.shape[0] - 2
    for p in numba.prange(n_parts):
        gradient_range(u, nodes, DB, first_block[p], kind, prm, part_start[p], part_start[p + 1],
                       out)
    gradient_range(u, nodes, DB, first_block[n_parts], kind, prm, part_start[n_parts],
                   part_start[n_parts + 1], out)
