"""Fused numba kernels for the elastic energy, force and tangent of quadratic (P2) tets.

Imported only by :func:`fem_elastic.discretization.fused.kernels_for` for a space of
order 2, i.e. only where numba imports. The numpy path of
:class:`fem_elastic.physics.elastic_body.ElasticPotential` builds F, P (and for the
tangent ``C = dP/dF``) at every quadrature point as ``(3, 3, ne, nq)`` and
``(3, 3, 3, 3, ne, nq)`` arrays and the element matrices as ``(30, 30, ne)``: at 30,000
P2 tets the element matrices alone are 206 MiB of float64. Here one pass over the
elements does, per tet and per quadrature point q (the 4-point degree-2 rule of
:class:`~fem_elastic.discretization.space.Discretization`, ``intorder = 2``),

    dN_q = G_q Dm^-1               (10 x 3: reference gradients G_q times d xi / d x),
    F_q = I + sum_a u_a (x) dN_qa,  u = x - X,
    g_ai += w_q P(F_q)_ij dN_qa,j,                       (force)
    E += w_q psi(F_q),                                  (energy)
    C_q = dP/dF(F_q), C_q <- nearest PSD matrix of C_q  (optional, per point),
    K_e[3 a + i, 3 b + k] += w_q sum_jl dN_qa,j C_q[3 i + j, 3 k + l] dN_qb,l,

with ``w_q`` scikit-fem's weight times the Jacobian (``space.dx``). A P2 tet on a
straight-edged (affine) mesh has one Jacobian, so the geometry is 9 numbers per element
(``Dm^-1``, as for P1) plus the 4 weights, not the 120 gradients per element the numpy
path reads: the physical gradients are rebuilt per point (360 multiplications, against
~10,000 for the element matrix). They agree with scikit-fem's to round-off.

The pointwise materials are :mod:`._fused_kernels`' ``psi`` and ``P`` and
:mod:`._fused_tangent_kernels`' ``tangent`` and ``project_psd`` (the per-point
projection the numpy path does in ``Material.d2psi_dF2_psd``), called, not copied.
The element matrix is built on its block upper triangle (b >= a) and mirrored, as
:meth:`~fem_elastic.physics.elastic_body.ElasticPotential.element_stiffness` does, and
added straight into the CSR data of the space's
:class:`~fem_elastic.discretization.space.SparsityPattern`: entry ``(3 n + i, 3 m + k)``
of node rows n, m sits at ``indptr[3 n + i] + off + k``, ``off`` the position of column
``3 m`` in row ``3 n`` (the three rows of a node list the same columns). ``off`` is a
``(ne, 10, 10)`` int32 map built once per pattern by binary search (400 bytes an
element, against the 7.2 kB of the pattern's int64 ``scatter``, which this path never
reads). Only a 30x30, a 9x9 and a few 10x3 buffers exist. Serial loops.
"""

from __future__ import annotations

import math
import weakref

import numba
import numpy as np

from . import _fused_kernels as _k
from . import _fused_tangent_kernels
from ._fused_tangent_kernels import element_offsets, project_psd, tangent  # offsets: any node count
from .fused import _REGISTRY, _frozen, _out_array, _readonly
from .space import Discretization

_k.drop_stale_caches(__file__, _k.__file__, _fused_tangent_kernels.__file__)  # laws, tangents

_jit = numba.njit(cache=True, error_model="numpy", nogil=True)
#: Per-point helpers inlined into the element loops at numba's IR level (as
#: :mod:`._fused_kernels` does for the P1 deformation gradient).
_jit_inline = numba.njit(cache=True, error_model="numpy", nogil=True, inline="always")

NLOC = 10  # scalar nodes of a P2 tet: 4 vertices, then 6 edge midpoints (scikit-fem's order)


# per point ------------------------------------------------------------------------------
@_jit_inline
def _point_gradients(G, q, D, dN):
    """dN[a, j] = sum_m G[q, a, m] D[m, j]: the physical shape-function gradients at point q."""
    for a in range(NLOC):
        g0, g1, g2 = G[q, a, 0], G[q, a, 1], G[q, a, 2]
        for j in range(3):
            dN[a, j] = g0 * D[0, j] + g1 * D[1, j] + g2 * D[2, j]


@_jit_inline
def _gather(x, X, nodes, e, u):
    """u[a, i] = x - X at the element's node a, component i."""
    for a in range(NLOC):
        k = 3 * nodes[e, a]
        for i in range(3):
            u[a, i] = x[k + i] - X[k + i]


@_jit_inline
def _point_F(u, dN):
    """F = I + sum_a u_a (x) dN_a as a row-major 9-tuple (the sum over a in order, as numpy's einsum)."""
    f00 = f01 = f02 = f10 = f11 = f12 = f20 = f21 = f22 = 0.0
    for a in range(NLOC):
        u0, u1, u2 = u[a, 0], u[a, 1], u[a, 2]
        d0, d1, d2 = dN[a, 0], dN[a, 1], dN[a, 2]
        f00 += u0 * d0
        f01 += u0 * d1
        f02 += u0 * d2
        f10 += u1 * d0
        f11 += u1 * d1
        f12 += u1 * d2
        f20 += u2 * d0
        f21 += u2 * d1
        f22 += u2 * d2
    return (f00 + 1.0, f01, f02, f10, f11 + 1.0, f12, f20, f21, f22 + 1.0)


# element loops ----------------------------------------------------------------------------
@_jit
def gradient_p2(x, X, nodes, Dm_inv, dx, G, kind, prm, out):
    """out = dE/dx: per tet and point, g_ai += w_q P_ij dN_aj, scattered per element.

    x, X ``(ndofs,)``; nodes ``(ne, 10)``; Dm_inv ``(ne, 3, 3)`` (d xi / d x);
    dx ``(ne, nq)`` weights times Jacobian (m^3); G ``(nq, 10, 3)`` reference
    gradients; out ``(ndofs,)``, overwritten.
    """
    out[:] = 0.0
    u = np.empty((NLOC, 3))
    dN = np.empty((NLOC, 3))
    g = np.empty((NLOC, 3))
    for e in range(nodes.shape[0]):
        _gather(x, X, nodes, e, u)
        g[:, :] = 0.0
        D = Dm_inv[e]
        for q in range(G.shape[0]):
            _point_gradients(G, q, D, dN)
            p = _k.P(kind, _point_F(u, dN), prm)
            w = dx[e, q]
            for i in range(3):
                q0, q1, q2 = p[3 * i] * w, p[3 * i + 1] * w, p[3 * i + 2] * w
                for a in range(NLOC):
                    g[a, i] += q0 * dN[a, 0] + q1 * dN[a, 1] + q2 * dN[a, 2]
        for a in range(NLOC):
            k = 3 * nodes[e, a]
            out[k] += g[a, 0]
            out[k + 1] += g[a, 1]
            out[k + 2] += g[a, 2]


@_jit
def energy_p2(x, X, nodes, Dm_inv, dx, G, kind, prm):
    """E = sum_e sum_q w_q psi(F_q); +inf as soon as one psi is not finite (inadmissible).

    Summed in blocks of 1024 elements (as the P1 kernel), so the round-off grows like
    that of numpy's pairwise sum rather than with the number of elements.
    """
    u = np.empty((NLOC, 3))
    dN = np.empty((NLOC, 3))
    total = 0.0
    block = 0.0
    for e in range(nodes.shape[0]):
        _gather(x, X, nodes, e, u)
        D = Dm_inv[e]
        for q in range(G.shape[0]):
            _point_gradients(G, q, D, dN)
            w = _k.psi(kind, _point_F(u, dN), prm)
            if not math.isfinite(w):
                return np.inf
            block += w * dx[e, q]
        if (e & 1023) == 1023:
            total += block
            block = 0.0
    return total + block


@_jit_inline
def _add_linear_block(K, dN, wlam, wmu):
    """K[3a+i, 3b+k] += w (lam dN_a,i dN_b,k + mu dN_a,k dN_b,i + mu delta_ik dN_a . dN_b), b >= a.

    The linear elastic tangent at one quadrature point, ``wlam = w lam`` and ``wmu = w mu``
    (w the point's weight times volume, m^3; lam, mu in Pa; dN in 1/m): ``B^T C B`` written out
    for the isotropic ``C = lam I (x) I + 2 mu sym``, the same terms as the general path sums,
    in another order.
    """
    for a in range(NLOC):
        for b in range(a, NLOC):
            dot = wmu * (dN[a, 0] * dN[b, 0] + dN[a, 1] * dN[b, 1] + dN[a, 2] * dN[b, 2])
            for i in range(3):
                row = 3 * a + i
                for k in range(3):
                    v = wlam * dN[a, i] * dN[b, k] + wmu * dN[a, k] * dN[b, i]
                    if i == k:
                        v += dot
                    K[row, 3 * b + k] += v


@_jit
def hessian_p2(x, X, nodes, Dm_inv, dx, G, kind, prm, project, indptr, off, data):
    """data = the CSR data of sum_e K_e (overwritten), K_e added through ``indptr`` and ``off``.

    ``project``: each point's C replaced by its nearest PSD matrix (not for LINEAR,
    whose tangent is PSD).
    """
    data[:] = 0.0
    u = np.empty((NLOC, 3))
    dN = np.empty((NLOC, 3))
    C = np.empty((9, 9))
    L = np.zeros((9, 9))
    Q = np.empty((9, 9))
    w9 = np.empty(9)
    T = np.empty((3, 3, NLOC, 3))  # T[i, j, b, k] = w sum_l C[3 i + j, 3 k + l] dN_b,l
    K = np.empty((3 * NLOC, 3 * NLOC))
    for e in range(nodes.shape[0]):
        if kind != _k.LINEAR:  # the linear tangent does not depend on x
            _gather(x, X, nodes, e, u)
        K[:, :] = 0.0
        D = Dm_inv[e]
        for q in range(G.shape[0]):
            _point_gradients(G, q, D, dN)
            if kind == _k.LINEAR:  # C = lam I (x) I + 2 mu sym: K_e in closed form, 3x fewer flops
                _add_linear_block(K, dN, dx[e, q] * prm[1], dx[e, q] * prm[0])
                continue
            tangent(kind, _point_F(u, dN), prm, C)
            if project:  # (never for LINEAR, whose tangent is PSD: it took the branch above)
                project_psd(C, L, Q, w9)
            w = dx[e, q]
            for i in range(3):
                for j in range(3):
                    r = 3 * i + j
                    for b in range(NLOC):
                        for k in range(3):
                            c = 3 * k
                            T[i, j, b, k] = w * (C[r, c] * dN[b, 0] + C[r, c + 1] * dN[b, 1]
                                                 + C[r, c + 2] * dN[b, 2])
            for a in range(NLOC):
                a0, a1, a2 = dN[a, 0], dN[a, 1], dN[a, 2]
                for i in range(3):
                    row = 3 * a + i
                    for b in range(a, NLOC):
                        for k in range(3):
                            K[row, 3 * b + k] += a0 * T[i, 0, b, k] + a1 * T[i, 1, b, k] + a2 * T[i, 2, b, k]
        for a in range(NLOC):
            na = 3 * nodes[e, a]
            for i in range(3):
                start = indptr[na + i]
                for b in range(NLOC):
                    base = start + off[e, a, b]
                    for k in range(3):
                        if b >= a:
                            data[base + k] += K[3 * a + i, 3 * b + k]
                        else:  # the mirror of the upper block triangle (C has major symmetry)
                            data[base + k] += K[3 * b + k, 3 * a + i]


# the Python side --------------------------------------------------------------------------
class _P2Geometry:
    """What the P2 kernels need of a Discretization: read-only, C-contiguous, element-major."""

    def __init__(self, space: Discretization):
        if space.order != 2:
            raise ValueError(f"the P2 kernels need a space of order 2, got {space.order}")
        nodes = space.element_dofs[0::3] // 3  # (10, ne)
        self.nodes = _frozen(nodes.T, np.int64)
        # d xi / d x of the element's affine map xi -> x0 + Dm xi: scikit-fem's own inverse
        # Jacobian (MappingAffine.invA, (3, 3, ne)), not a second inversion of the edge matrices
        self.Dm_inv = _frozen(np.asarray(space.mapping.invA).transpose(2, 0, 1), float)
        self.dx = _frozen(space.dx, float)  # (ne, nq)
        self.G = _frozen(space.ref_gradients.transpose(2, 0, 1), float)  # (nq, 10, 3)
        self.X = _frozen(space.X, float)
        self.ndofs = space.ndofs


#: Discretization -> its P2 geometry; dropped with the Discretization.
_geometry_cache: "weakref.WeakKeyDictionary[Discretization, _P2Geometry]" = weakref.WeakKeyDictionary()


def geometry(space: Discretization) -> _P2Geometry:
    """The cached P2 geometry of a space (built on first use)."""
    geo = _geometry_cache.get(space)
    if geo is None:
        geo = _geometry_cache[space] = _P2Geometry(space)
    return geo


class FusedP2:
    """Energy, gradient and tangent of one material on one P2 discretization, fused.

    Build it with :func:`fem_elastic.discretization.fused.kernels_for`, which returns
    None where the numpy path must be used.

    Parameters
    ----------
    material : Material
        One of the classes of :func:`fem_elastic.discretization.fused.registry`.
    space : Discretization
        Of order 2.
    """

    def __init__(self, material, space: Discretization):
        name, params = _REGISTRY[type(material)]
        self.kind = getattr(_k, name.upper())
        self.prm = params(material)
        self.geo = geometry(space)

    def _x(self, x) -> np.ndarray:
        """x as a read-only, C-contiguous float view (one numba specialisation, as FusedP1._x)."""
        return _readonly(x, self.geo.ndofs, "x")

    def energy(self, x: np.ndarray) -> float:
        """Elastic energy (J); +inf if any quadrature point is inadmissible."""
        g = self.geo
        return float(energy_p2(self._x(x), g.X, g.nodes, g.Dm_inv, g.dx, g.G, self.kind, self.prm))

    def gradient(self, x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """dE/dx (N), ``(ndofs,)``: into ``out`` if given (C-contiguous float64), else a new array."""
        g = self.geo
        out = _out_array(out, g.ndofs)
        gradient_p2(self._x(x), g.X, g.nodes, g.Dm_inv, g.dx, g.G, self.kind, self.prm, out)
        return out

    def hessian(self, x: np.ndarray, pattern, project: bool = False):
        """d2E/dx2 (N/m) on the space's CSR ``pattern``, a CSR matrix sharing its index arrays.

        ``project`` makes each point's dP/dF PSD as ``Material.d2psi_dF2_psd`` does.
        """
        import scipy.sparse as sp

        g = self.geo
        data = np.empty(pattern.nnz)
        hessian_p2(self._x(x), g.X, g.nodes, g.Dm_inv, g.dx, g.G, self.kind, self.prm,
                   bool(project), pattern.indptr, element_offsets(pattern, g.nodes), data)
        return sp.csr_matrix((data, pattern.indices, pattern.indptr), shape=pattern.shape, copy=False)
