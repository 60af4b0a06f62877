"""Constraints of position-based dynamics on a tet mesh, and their projection.

Conventions
-----------
x, X : ``(ndofs,)`` current and reference positions (m) of the mesh vertices,
    node-major (``x[3 v + i]``), as every flat vector of the package (P1 only).
w : ``(ndofs,)`` inverse mass per DOF (1/kg); 0 on a held DOF, which then never moves.
C_j(x) : the value of constraint j (the rest state is not always ``C = 0``:
    see :class:`TetNeoHookean`); ``G_j = dC_j/dx`` its gradient.
alpha_j : compliance (the inverse stiffness of the energy ``U = C^2 / (2 alpha)``),
    ``at = alpha / h^2`` its time-step form (Macklin, Mueller and Chentanez 2016).
lam_j : the Lagrange multiplier of XPBD (``lam / h^2`` is the constraint force).

One projection of a constraint (or of the ``m`` constraints of one element,
solved together) from positions x:

    A = G W G^T + diag(at),   dlam = A^-1 (-C - at lam),   dx = W G^T dlam,

which is the position-based projection of the lecture notes
(``seeds/002_942bade499ba35f4.txt``, "General Position Correction":
``dx_i = -s w_i grad_i C``, ``s = C / sum_j w_j |grad_j C|^2``) when
``at = 0`` and ``lam = 0`` (PBD), and the XPBD update of Macklin et al.
(2016) otherwise. A constraint of a rigid-motion invariant function
(a distance, a volume, an isotropic energy of F) has ``sum_i grad_i C = 0``
and ``sum_i x_i x grad_i C = 0``: since ``m_i dx_i = grad_i C dlam`` on free
vertices, every projection leaves the linear and angular momentum of the
corrections, ``sum m_i dx_i`` and ``sum m_i x_i x dx_i``, at zero.

Three kinds of constraint, each a :class:`ConstraintSet` on vertex tuples:

- :class:`EdgeDistance`: ``C = |x_b - x_a| - l0`` on every mesh edge;
- :class:`TetVolume`: ``C = J - 1 = V / V0 - 1`` on every tet (the notes'
  ``[(x2 - x1) x (x3 - x1)] . (x4 - x1) - 6 V0``, divided by ``6 V0``, which
  changes no PBD projection and makes the compliance a bulk modulus);
- :class:`TetNeoHookean`: the deviatoric and hydrostatic constraints of the
  stable Neo-Hookean energy of Macklin and Mueller (2021), two per tet,
  projected together (a 2x2 block).

A sweep over a set is Gauss-Seidel (constraint after constraint, each from
the positions the previous ones left, in the colour order of
:mod:`~fem_elastic.dynamics.position_based.coloring`: vectorised over one
colour at a time) or Jacobi (every constraint from the same positions, the
corrections added together, each scaled by ``relaxation / n`` with ``n`` the
largest number of constraints of the set at any of its vertices: a uniform
factor per constraint keeps the momentum of every correction at zero, which
the per-vertex averaging of Macklin et al. 2014, "Unified particle physics
for real-time applications", does not). With numba
importable (and ``FEM_ELASTIC_NUMBA`` not ``0``) the sweeps run as one
compiled loop over the same order (:mod:`._kernels`); the numpy path below is
the reference and the fallback, and both agree to round-off.

References: M. Mueller, B. Heidelberger, M. Hennix, J. Ratcliff, "Position
based dynamics", JVCIR 18(2), 2007. M. Macklin, M. Mueller, N. Chentanez,
"XPBD: position-based simulation of compliant constrained dynamics", MIG
2016. M. Macklin, M. Mueller, "A constraint-based formulation of stable
Neo-Hookean materials", MIG 2021.
"""

from __future__ import annotations

import logging
import os

import numpy as np

from ...errors import InvalidParameter
from .coloring import color_constraints, color_order

__all__ = ["ConstraintSet", "EdgeDistance", "TetNeoHookean", "TetVolume", "numba_kernels"]

log = logging.getLogger(__name__)

_kernels_module = None
_kernels_error = None


def numba_kernels():
    """The compiled sweeps (:mod:`._kernels`, imports numba on first use), or None.

    None when numba is not importable or the environment variable
    ``FEM_ELASTIC_NUMBA`` (read at every call) is ``0``: the numpy path runs.

    Examples
    --------
    >>> k = numba_kernels()
    >>> k is None or callable(k.tet_sweep)
    True
    """
    global _kernels_module, _kernels_error
    from ...discretization.fused import ENV

    if os.environ.get(ENV, "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    if _kernels_module is None and _kernels_error is None:
        try:
            from . import _kernels
        except ImportError as err:  # numba missing
            _kernels_error = err
            log.info("numba is not importable (%s): position-based sweeps use numpy", err)
        else:
            _kernels_module = _kernels
    return _kernels_module


def _frozen(a, dtype) -> np.ndarray:
    out = np.array(a, dtype=dtype, order="C", copy=True)
    out.setflags(write=False)
    return out


class ConstraintSet:
    """Constraints on ``k``-vertex tuples, ``m`` scalar constraints (multipliers) each.

    The constraints are stored in the order of the Gauss-Seidel sweep: colour
    0 first, and within a colour in the order given. A sweep then reads every
    per-constraint array front to back (measured on the 153,600-tet beam, a
    sweep in the given order through a colour index was 6 times slower, its
    reads scattered over the whole mesh). ``source`` maps them back.

    Parameters
    ----------
    nodes : array_like of int, shape (n, k)
        The vertices of each constraint.
    n_vertices : int
    compliance : array_like, shape (n, m) or (n,)
        ``alpha`` of each scalar constraint, in the inverse units of
        ``C^2 / energy``; 0 is a hard constraint. Ignored by PBD.
    **arrays : array_like
        More per-constraint arrays (first axis n) a subclass keeps, stored as
        attributes in the same order.

    Attributes
    ----------
    nodes : numpy.ndarray, shape (n, k)
    compliance : numpy.ndarray, shape (n, m)
    source : numpy.ndarray of int, shape (n,)
        The index, in the order given, of each stored constraint.
    colors : numpy.ndarray of int, shape (n,)
        The colour of each stored constraint (non-decreasing).
    offsets : numpy.ndarray of int, shape (n_colors + 1,)
        Colour c is the slice ``offsets[c]:offsets[c + 1]``.
    jacobi_scale : numpy.ndarray, shape (n,)
        ``1 / n`` with n the largest number of constraints of the set at any
        vertex of the constraint: the Jacobi factor before ``relaxation``.
    """

    m = 1

    def __init__(self, nodes, n_vertices, compliance, **arrays):
        nodes = np.asarray(nodes, dtype=np.int64)
        n = nodes.shape[0]
        self.n_vertices = int(n_vertices)
        c = np.asarray(compliance, dtype=float)
        if c.ndim == 1:
            c = c[:, None]
        if c.shape != (n, self.m) or not np.all(np.isfinite(c)) or np.any(c < 0):
            raise InvalidParameter(
                f"compliance must be {n} x {self.m} finite values >= 0, got shape {c.shape}."
            )
        colors = color_constraints(nodes, self.n_vertices)
        source, self.offsets = color_order(colors)
        self.offsets.setflags(write=False)
        self.source = _frozen(source, np.int64)
        self.colors = _frozen(colors[source], np.int64)
        self.nodes = _frozen(nodes[source], np.int64)
        self.compliance = _frozen(c[source], float)
        for name, value in arrays.items():
            setattr(self, name, _frozen(np.asarray(value, dtype=float)[source], float))
        degree = np.bincount(self.nodes.ravel(), minlength=self.n_vertices)
        self.jacobi_scale = _frozen(1.0 / degree[self.nodes].max(axis=1), float)

    def __len__(self) -> int:
        return self.nodes.shape[0]

    @property
    def n_colors(self) -> int:
        """Number of colours of the Gauss-Seidel sweep."""
        return self.offsets.size - 1

    # -- what a subclass defines ---------------------------------------------------------
    def values_and_gradients(self, x, idx):  # pragma: no cover - abstract
        """``C`` ``(len(idx), m)`` and ``G`` ``(len(idx), m, k, 3)`` of the constraints idx at x."""
        raise NotImplementedError

    def _numba_sweep(self, kernels, x, w, lam, at, scale, jacobi, dx):  # pragma: no cover
        raise NotImplementedError

    # -- shared ----------------------------------------------------------------------------
    def values(self, x) -> np.ndarray:
        """``C(x)`` of every constraint, ``(n, m)``.

        Examples
        --------
        >>> import numpy as np, fem_elastic as fe
        >>> mesh = fe.beam_mesh(cells=(2, 1, 1))
        >>> s = EdgeDistance.of_mesh(mesh)
        >>> float(np.abs(s.values(mesh.p.T.ravel())).max())   # at rest
        0.0
        """
        return self.values_and_gradients(np.asarray(x, dtype=float), np.arange(len(self)))[0]

    def corrections(self, x, w, idx, lam, at):
        """The projection of the constraints ``idx``, each from the same positions x.

        Parameters
        ----------
        x, w : numpy.ndarray, shape (ndofs,)
            Positions (m) and inverse masses (1/kg).
        idx : numpy.ndarray of int, or slice
            The constraints (positions in the stored order).
        lam, at : numpy.ndarray, shape (len(idx), m)
            Their multipliers and ``alpha / h^2`` (zeros for PBD).

        Returns
        -------
        dlam : numpy.ndarray, shape (len(idx), m)
        dx : numpy.ndarray, shape (len(idx), k, 3)
            Position corrections of the constraints' vertices (m).
        """
        C, G = self.values_and_gradients(x, idx)
        W = w.reshape(-1, 3)[self.nodes[idx]]  # (n, k, 3)
        WG = W[:, None] * G  # (n, m, k, 3)
        A = np.einsum("nakc,nbkc->nab", G, WG)
        rhs = -(C + at * lam)
        if self.m == 1:
            den = A[:, 0, 0] + at[:, 0]
            ok = den > 0.0
            dlam = np.where(ok, rhs[:, 0] / np.where(ok, den, 1.0), 0.0)[:, None]
        else:
            a, b, c = A[:, 0, 0], A[:, 0, 1], A[:, 1, 1]
            a0, a1 = at[:, 0], at[:, 1]
            # det of [[a + a0, b], [b, c + a1]]; a c - b^2 >= 0 in exact arithmetic (Cauchy-Schwarz)
            det = np.maximum(a * c - b * b, 0.0) + a0 * c + a1 * a + a0 * a1
            ok = det > 0.0
            inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
            r0, r1 = rhs[:, 0], rhs[:, 1]
            dlam = np.stack([((c + a1) * r0 - b * r1) * inv, ((a + a0) * r1 - b * r0) * inv], axis=1)
        dx = np.einsum("nm,nmkc->nkc", dlam, WG)
        return dlam, dx

    def sweep(self, x, w, lam, at, scale, method="gauss_seidel", relaxation=1.0):
        """One sweep over every constraint of the set; updates ``x`` and ``lam`` in place.

        Parameters
        ----------
        x : numpy.ndarray, shape (ndofs,)
            Positions (m), writable.
        w : numpy.ndarray, shape (ndofs,)
            Inverse masses (1/kg).
        lam : numpy.ndarray, shape (n, m)
            Multipliers (XPBD), writable; zeros for PBD.
        at : numpy.ndarray, shape (n, m)
            ``alpha / h^2``; zeros for PBD.
        scale : numpy.ndarray, shape (n,)
            Factor on each projection: PBD's stiffness, 1 for XPBD.
        method : {"gauss_seidel", "jacobi"}
        relaxation : float
            Jacobi only: the over-relaxation ``omega`` on the averaged corrections.
        """
        jacobi = method == "jacobi"
        s = scale * (relaxation * self.jacobi_scale) if jacobi else scale
        s = np.ascontiguousarray(s, dtype=float)
        kernels = numba_kernels()
        if kernels is not None:
            dx = np.zeros_like(x) if jacobi else np.zeros(0)
            self._numba_sweep(kernels, x, w, lam, at, s, jacobi, dx)
            if jacobi:
                x += dx
            return
        P = x.reshape(-1, 3)
        if jacobi:
            idx = np.arange(len(self))
            dlam, dx = self.corrections(x, w, idx, lam, at)
            lam += s[:, None] * dlam
            acc = np.zeros_like(P)
            for a in range(self.nodes.shape[1]):  # k vertex slots, each a vectorised scatter-add
                np.add.at(acc, self.nodes[:, a], s[:, None] * dx[:, a])
            P += acc
            return
        for c in range(self.n_colors):
            idx = slice(self.offsets[c], self.offsets[c + 1])  # a colour is a contiguous run
            dlam, dx = self.corrections(x, w, idx, lam[idx], at[idx])
            lam[idx] += s[idx, None] * dlam
            # no vertex is shared within a colour: the fancy-indexed update has no duplicates
            P[self.nodes[idx]] += s[idx, None, None] * dx


class EdgeDistance(ConstraintSet):
    """``C = |x_b - x_a| - l0`` on vertex pairs (the notes' "Internal Distance Constraint").

    Parameters
    ----------
    nodes : array_like of int, shape (n, 2)
    X : numpy.ndarray, shape (ndofs,)
        Reference positions (m): the rest lengths ``l0``.
    compliance : array_like, shape (n,)
        m/N (``1 / k`` of a spring of stiffness k).

    Examples
    --------
    Two particles 1 m apart, pulled to 2 m; one projection puts them back
    (each moves by its share ``w_i / (w_a + w_b)``):

    >>> import numpy as np
    >>> s = EdgeDistance([[0, 1]], np.array([0.0, 0, 0, 1, 0, 0]), compliance=[0.0])
    >>> x = np.array([0.0, 0, 0, 2, 0, 0])
    >>> s.sweep(x, np.array([1.0, 1, 1, 3, 3, 3]), np.zeros((1, 1)), np.zeros((1, 1)), np.ones(1))
    >>> x.round(12).tolist()   # the heavier particle (w = 1) moves 1/4, the lighter 3/4
    [0.25, 0.0, 0.0, 1.25, 0.0, 0.0]
    """

    def __init__(self, nodes, X, compliance=None):
        nodes = np.asarray(nodes, dtype=np.int64)
        self.X = _frozen(np.asarray(X, dtype=float).reshape(-1, 3), float)
        d = self.X[nodes[:, 1]] - self.X[nodes[:, 0]]
        rest = np.sqrt(np.einsum("ni,ni->n", d, d))
        if np.any(rest <= 0.0):
            raise InvalidParameter("an edge has zero rest length: two vertices coincide.")
        super().__init__(nodes, self.X.shape[0], np.zeros(len(nodes)) if compliance is None else compliance,
                         rest=rest)

    @classmethod
    def of_mesh(cls, mesh, compliance=None) -> "EdgeDistance":
        """One constraint per edge of a scikit-fem tet mesh (``mesh.edges``)."""
        return cls(np.asarray(mesh.edges).T, np.asarray(mesh.p, dtype=float).T.ravel(), compliance)

    def values_and_gradients(self, x, idx):
        P = x.reshape(-1, 3)
        nd = self.nodes[idx]
        d = P[nd[:, 1]] - P[nd[:, 0]]
        length = np.sqrt(np.einsum("ni,ni->n", d, d))
        safe = np.where(length > 0.0, length, 1.0)
        n = np.where(length[:, None] > 0.0, d / safe[:, None], 0.0)  # no direction: no correction
        G = np.stack([-n, n], axis=1)[:, None]  # (n, 1, 2, 3)
        return (length - self.rest[idx])[:, None], G

    def _numba_sweep(self, kernels, x, w, lam, at, scale, jacobi, dx):
        kernels.edge_sweep(x, w, self.nodes, self.rest, at, lam, scale, jacobi, dx)


class _TetSet(ConstraintSet):
    """Shared: P1 tets, their reference shape and the deformation gradient F = I + H."""

    kind = -1

    def __init__(self, mesh, compliance, shift=None):
        """``compliance``: an array (n_tets, m), or a function of the tets' rest volumes (m^3) giving it."""
        t = np.asarray(mesh.t, dtype=np.int64).T  # (ne, 4)
        X = np.asarray(mesh.p, dtype=float).T  # (nv, 3)
        Dm = (X[t[:, 1:]] - X[t[:, :1]]).transpose(0, 2, 1)  # columns X_b - X_0
        det = np.linalg.det(Dm)
        if np.any(det == 0.0):
            raise InvalidParameter("a tet of the mesh has zero volume.")
        self.X = _frozen(X, float)
        n = t.shape[0]
        volume = np.abs(det) / 6.0
        if callable(compliance):
            compliance = compliance(volume)
        # rows of Dm^-1: the shape-function gradients of nodes 1-3 (node 0's is minus their sum)
        super().__init__(t, X.shape[0], compliance, Dm_inv=np.linalg.inv(Dm), volume=volume,
                         shift=np.zeros(n) if shift is None else np.broadcast_to(shift, (n,)))

    def _H(self, x, idx):
        """``F - I`` ``(n, 3, 3)`` from the displacements (F - I keeps its relative precision)."""
        U = (x.reshape(-1, 3) - self.X)[self.nodes[idx]]  # (n, 4, 3)
        D = U[:, 1:] - U[:, :1]  # D[e, b, i] = u_{b+1, i} - u_{0, i}
        return np.einsum("nbi,nbj->nij", D, self.Dm_inv[idx])

    @staticmethod
    def _jm1_cof(H):
        """``J - 1`` (from the invariants of H, no cancellation) and ``cof F = dJ/dF``."""
        t = H[:, 0, 0] + H[:, 1, 1] + H[:, 2, 2]
        i2 = (H[:, 0, 0] * H[:, 1, 1] + H[:, 0, 0] * H[:, 2, 2] + H[:, 1, 1] * H[:, 2, 2]
              - H[:, 0, 1] * H[:, 1, 0] - H[:, 0, 2] * H[:, 2, 0] - H[:, 1, 2] * H[:, 2, 1])
        F = H + np.eye(3)
        cof = np.empty_like(F)
        for i in range(3):
            i1, i2_ = (i + 1) % 3, (i + 2) % 3
            for j in range(3):
                j1, j2 = (j + 1) % 3, (j + 2) % 3
                cof[:, i, j] = F[:, i1, j1] * F[:, i2_, j2] - F[:, i1, j2] * F[:, i2_, j1]
        return t + i2 + np.linalg.det(H), cof

    def _nodal(self, dCdF, idx):
        """``(n, m, 4, 3)`` vertex gradients from ``dC/dF`` ``(n, m, 3, 3)``."""
        g = np.einsum("nmij,nbj->nmbi", dCdF, self.Dm_inv[idx])  # vertices 1-3
        return np.concatenate([-g.sum(axis=2, keepdims=True), g], axis=2)

    def _numba_sweep(self, kernels, x, w, lam, at, scale, jacobi, dx):
        kernels.tet_sweep(x, w, self.nodes, self.Dm_inv, self.kind, self.shift, at, lam, scale, jacobi, dx)


class TetVolume(_TetSet):
    """``C = J - 1 = V / V0 - 1`` on every tet of a mesh (the notes' volume constraint / 6 V0).

    Parameters
    ----------
    mesh : skfem.MeshTet
        The reference configuration (m).
    compliance : array_like, shape (n_tets,), optional
        ``1 / (K V0)`` for a bulk modulus K (Pa) on a tet of volume ``V0``
        (m^3): the energy ``U = K V0 (J - 1)^2 / 2``. Default 0 (hard).

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> mesh = fe.beam_mesh(cells=(1, 1, 1))
    >>> s = TetVolume(mesh)
    >>> x = 1.1 * mesh.p.T.ravel()   # every volume times 1.331
    >>> bool(np.allclose(s.values(x), 0.331))
    True
    """

    kind = 0

    def __init__(self, mesh, compliance=None):
        super().__init__(mesh, np.zeros(mesh.t.shape[1]) if compliance is None else compliance)

    def values_and_gradients(self, x, idx):
        jm1, cof = self._jm1_cof(self._H(x, idx))
        return jm1[:, None], self._nodal(cof[:, None], idx)


class TetNeoHookean(_TetSet):
    """The deviatoric and hydrostatic constraints of stable Neo-Hookean (Macklin and Mueller 2021).

    Per tet, with ``F = Ds Dm^-1``, ``I_C = tr(F^T F)`` and ``J = det F``:

        C_D = sqrt(I_C),          alpha_D = 1 / (mu V0),
        C_H = J - gamma,          alpha_H = 1 / (lam V0),     gamma = 1 + mu / lam,

    whose constraint energy ``C_D^2 / (2 alpha_D) + C_H^2 / (2 alpha_H)`` is
    ``V0 [mu/2 I_C + lam/2 (J - gamma)^2]``: the log-free stable Neo-Hookean
    energy of Smith et al. (2018) up to a constant, rest stable
    (``P(I) = mu I + lam (1 - gamma) cof I = 0``). ``C_D`` is ``sqrt(I_C)``
    rather than ``sqrt(I_C - 3)``, whose gradient is singular at rest; the
    two differ by a constant in the energy. The two constraints of a tet are
    projected together (the 2x2 block of the module notes): at rest their
    gradients are parallel and their forces cancel, so a projection of C_D
    alone would collapse a stiff tet in its first iteration and C_H restore it
    in the next. (Macklin and Mueller project them one after the other; the
    fixed point of the iteration is the same.)

    Parameters
    ----------
    mesh : skfem.MeshTet
    mu, lam : float
        The Lame parameters of the energy (Pa), > 0. See
        :class:`~fem_elastic.dynamics.position_based.energy.ConstraintNeoHookean`
        for the choice ``lam = lambda + mu`` that makes its small-strain limit
        linear elasticity with the material's (mu, lambda).

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> mesh = fe.beam_mesh(cells=(1, 1, 1))
    >>> s = TetNeoHookean(mesh, mu=1e6, lam=4e6)
    >>> C = s.values(mesh.p.T.ravel())    # at rest: sqrt(3) and 1 - gamma = -mu / lam
    >>> bool(np.allclose(C, [np.sqrt(3.0), -0.25]))
    True
    """

    kind = 1
    m = 2

    def __init__(self, mesh, mu: float, lam: float):
        if not (np.isfinite(mu) and np.isfinite(lam) and mu > 0 and lam > 0):
            raise InvalidParameter(f"mu and lam must be finite and > 0 Pa, got {mu!r} and {lam!r}.")
        self.mu, self.lam = float(mu), float(lam)
        super().__init__(mesh, lambda V: np.stack([1.0 / (self.mu * V), 1.0 / (self.lam * V)], axis=1),
                         shift=self.mu / self.lam)

    def values_and_gradients(self, x, idx):
        H = self._H(x, idx)
        jm1, cof = self._jm1_cof(H)
        tr = H[:, 0, 0] + H[:, 1, 1] + H[:, 2, 2]
        ic = 3.0 + 2.0 * tr + np.einsum("nij,nij->n", H, H)
        r = np.sqrt(np.maximum(ic, 0.0))
        safe = np.where(r > 0.0, r, 1.0)
        F = H + np.eye(3)
        dD = np.where(r[:, None, None] > 0.0, F / safe[:, None, None], 0.0)  # collapsed: no gradient
        C = np.stack([r, jm1 - self.shift[idx]], axis=1)
        return C, self._nodal(np.stack([dD, cof], axis=1), idx)
