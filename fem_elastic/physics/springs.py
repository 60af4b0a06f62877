"""The mass-spring body: springs on the edges of a tet mesh, calibrated from E.

A mass-spring body puts one spring on every edge ``e = (i, j)`` of the tet
mesh, with stiffness ``k_e`` (N/m) and rest length ``l0_e`` (m, the reference
edge length). Its energy is (``seeds/000``, "Spring Energy")

    E(x) = sum_e 1/2 k_e (l_e - l0_e)^2,      l_e = |x_j - x_i|,  n_e = (x_j - x_i) / l_e,

and its gradient and Hessian, per spring, are

    dE/dx_j = -dE/dx_i = k (l - l0) n,
    d2E/dx_j^2 = k [ n n^T + (1 - l0 / l) (I - n n^T) ]      (3x3 block B; the 6x6
                                                          matrix is [[B, -B], [-B, B]]).

B has the eigenvalue k along n and ``k (1 - l0/l)`` twice across it: the
transverse term is negative under compression (l < l0), so the projected
Hessian (``project=True``) clamps ``1 - l0/l`` at zero, which makes every
6x6 spring matrix, and their sum, positive semi-definite.

Damping along the spring (the spring-damper of ``seeds/002``): the force on i
is ``f_i = -k_d ((v_i - v_j) . n) n`` and ``f_j = -f_i``, i.e. ``f = -D(x) v``
with D assembled from the blocks ``k_d n n^T`` (symmetric, PSD). Like Rayleigh
damping it is dissipation, not energy, so it is not part of the Potential's
energy; integrators call :meth:`SpringPotential.damping_force` and
:meth:`SpringPotential.damping_matrix`. ``k_d`` (N s/m) is per spring, so the
body's total damping grows with the number of springs (mesh refinement).

The mass is the Model's (``model.lumped_mass``, from the density), the same
as for an FEM body on the same mesh: only the stiffness differs.

Calibration: what springs can and cannot represent
--------------------------------------------------
Under a small homogeneous strain ``eps`` a spring stretches by
``l0 n . eps n``, so the network's energy density is that of a material with
stiffness tensor

    C_ijkl = (1 / V) sum_e k_e l0_e^2 n_i n_j n_k n_l.

This tensor is symmetric in all four indices: ``C_1122 = C_1212`` (the Cauchy
relation), so for an isotropic network ``lam = mu``, i.e. ``nu = 1/4``. A
spring network cannot represent any other Poisson ratio, and on a real mesh
it is not even isotropic: its moduli depend on the edge directions of the
mesh. Two calibrations of ``k_e`` from Young's modulus E are provided, each a
function ``calibration(mesh, E, nu) -> k`` (N/m, one per ``mesh.edges``)
that :class:`MassSpring` takes as its ``calibration`` argument:

- :func:`van_gelder_stiffness` (van Gelder 1998, the 3-D form):
  ``k_e = E sum_{t ∋ e} V_t / l0_e^2``. It ignores nu (a warning is logged if
  nu != 1/4).
- :func:`lloyd_stiffness` (in the spirit of Lloyd, Szekely and Harders 2007):
  per tet, the six edge stiffnesses whose spring matrices best match the
  tet's linear-elastic stiffness matrix ``K_t(E, nu)`` in the Frobenius
  norm; each edge sums its tets' values, and negative sums are clamped to
  zero (counted in a log warning; an edge left without a spring can leave
  a poorly shaped tet free to deform at no cost). nu enters only as the
  target of the fit: the network's Poisson ratio is set by the mesh, not by
  nu (a warning is logged if nu != 1/4).

Both are exact sums of per-tet terms, and the six edge lengths of a tet
are a function of its (constant) deformation gradient F, so the network is
a P1 finite element body with an anisotropic material per tet; like P1
FEM it locks in bending. :func:`fem_elastic.beam_mesh`
cuts every cube into the same six tets, all sharing the cube's (1, 1, 1)
diagonal: every vertex has the same neighbourhood (a Bravais lattice), so a
homogeneous strain is in equilibrium away from the free surfaces and the
formula for ``C`` above gives the network's moduli. Along the mesh axes,
under uniaxial stress (the other five stresses zero), they are (exact
fractions from the formula, asserted in ``tests/test_springs.py``):

=================================  ==================  ===================
calibration                         E_eff / E (x axis)  nu_eff (y and z)
=================================  ==================  ===================
van_gelder_stiffness                30/29 = 1.0345      1/29 = 0.0345
lloyd_stiffness, nu = 1/4           1.2868              0.0164
lloyd_stiffness, nu = 0             1.1246              0.0171
lloyd_stiffness, nu = 0.45          3.7788              0.0152
fe.ElasticBody (any P1 mesh)        1                   nu
=================================  ==================  ===================

The network is far from isotropic: with van Gelder's constants the Young
modulus is 10/7 E = 1.43 E along the (1, 1, 1) diagonal that every cell's
six tets share, 5/6 E along the face diagonal (1, 1, 0), and 3/8 E along
(1, -1, 0), where no spring runs; its Poisson ratio along the axes is 1/29,
not 1/4 (exact fractions from the same formula, asserted in the tests). The Lloyd fit to a nearly incompressible target (nu -> 1/2) raises
every constant, since springs cannot stiffen the volume alone: with
nu = 0.45 the axial modulus is 3.8 E. This is why :class:`MassSpring`
defaults to van Gelder's constants and nu = 1/4.

References: A. van Gelder, "Approximate simulation of elastic membranes by
triangulated spring meshes", J. Graphics Tools 3(2), 1998. B. Lloyd,
G. Szekely, M. Harders, "Identification of spring parameters for deformable
object simulation", IEEE TVCG 13(5), 2007.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike
from skfem import MeshTet

from ..discretization.space import Discretization, SparsityPattern
from ..errors import InvalidParameter
from ..materials.base import lame_parameters
from ..geometry.mesh import signed_volumes
from .potential import Potential

__all__ = [
    "MassSpring",
    "SpringPotential",
    "SPRING_POISSON_RATIO",
    "lloyd_stiffness",
    "van_gelder_stiffness",
]

log = logging.getLogger(__name__)

#: The Poisson ratio of an isotropic spring network in 3-D (the Cauchy
#: relation lam = mu): the only value springs represent.
SPRING_POISSON_RATIO = 0.25

_EPS = np.finfo(float).eps
# local vertex pairs of the six edges of a tet; edge m and edge 5 - m are opposite
_TET_EDGES = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])


# --------------------------------------------------------------------------------------
# The potential
# --------------------------------------------------------------------------------------
class SpringPotential(Potential):
    """Energy of a set of springs (J) as a function of the DOF positions x (m).

    Parameters
    ----------
    X : numpy.ndarray
        ``(ndofs,)`` reference positions (m), node-major interleaved
        (DOF ``3 * node + component``).
    edges : array_like of int
        ``(2, n_springs)`` node indices ``(i, j)`` of each spring, ``i != j``.
    stiffness : array_like
        ``(n_springs,)`` spring constants k (N/m), >= 0, or one value for all.
    rest_length : array_like, optional
        ``(n_springs,)`` rest lengths l0 (m), >= 0; default: the lengths in X.
    k_d : float or array_like, optional
        Damping coefficient along each spring (N s/m), >= 0; default 0 (none).
    pattern : SparsityPattern, optional
        A CSR pattern whose node graph contains every spring (e.g. the tet
        pattern ``space.pattern``, since springs sit on tet edges). Hessians
        and damping matrices are then assembled on it, so they share its
        index arrays (``pattern.owns(H)``) and add to FEM matrices cheaply.
        Without it the springs' own pattern is used.

    Attributes
    ----------
    edges : numpy.ndarray
        ``(2, n_springs)`` node indices.
    stiffness, rest_length, k_d : numpy.ndarray
        ``(n_springs,)`` k (N/m), l0 (m) and k_d (N s/m).

    Examples
    --------
    Two nodes 1 m apart on a 100 N/m spring, stretched by 1 cm:

    >>> import numpy as np
    >>> s = SpringPotential(np.array([0., 0, 0, 1, 0, 0]), [[0], [1]], [100.0])
    >>> x = np.array([0., 0, 0, 1.01, 0, 0])
    >>> round(s.energy(x), 9), s.gradient(x).round(9)  # 1/2 k dl^2 (J), dE/dx (N)
    (0.005, array([-1.,  0.,  0.,  1.,  0.,  0.]))
    >>> float(s.hessian(x).toarray()[3, 3])  # k along the spring (N/m)
    100.0
    """

    def __init__(self, X: ArrayLike, edges: ArrayLike, stiffness: ArrayLike,
                 rest_length: ArrayLike | None = None, k_d: float = 0.0,
                 pattern: SparsityPattern | None = None) -> None:
        self.X = np.asarray(X, dtype=float)
        if self.X.ndim != 1 or self.X.size % 3:
            raise InvalidParameter(
                f"X must be a flat (ndofs,) vector with 3 DOFs per node, got shape {self.X.shape}."
            )
        self.ndofs = self.X.size
        nn = self.ndofs // 3
        edges = np.asarray(edges)
        if edges.ndim != 2 or edges.shape[0] != 2 or not np.issubdtype(edges.dtype, np.integer):
            raise InvalidParameter(
                f"edges must be a (2, n_springs) integer array of node indices, got {edges!r}."
            )
        if edges.size and (edges.min() < 0 or edges.max() >= nn):
            raise InvalidParameter(f"edge node indices must lie in [0, {nn - 1}].")
        if np.any(edges[0] == edges[1]):
            raise InvalidParameter("a spring must join two different nodes (edges[0] == edges[1]).")
        self.edges = edges.astype(np.int64)
        ns = self.edges.shape[1]
        Xp = self.X.reshape(-1, 3)
        if rest_length is None:
            rest_length = np.linalg.norm(Xp[self.edges[1]] - Xp[self.edges[0]], axis=1)
        self.stiffness = _per_spring("stiffness", stiffness, ns, "N/m")
        self.rest_length = _per_spring("rest_length", rest_length, ns, "m")
        self.k_d = _per_spring("k_d", k_d, ns, "N s/m")
        for arr in (self.X, self.edges, self.stiffness, self.rest_length, self.k_d):
            arr.setflags(write=False)
        # the three DOFs of each end, (2, ns, 3)
        self._dofs = 3 * self.edges[:, :, None] + np.arange(3)
        self._build_pattern(pattern)

    # pattern ---------------------------------------------------------------
    def _build_pattern(self, pattern) -> None:
        """Data-array position of every entry of every spring's four 3x3 blocks.

        ``_pos`` has shape ``(4, n_springs, 3, 3)`` for the blocks (i, i),
        (i, j), (j, i), (j, j), so assembly is one bincount.
        """
        n = self.ndofs
        i, j = self._dofs  # (ns, 3) each
        rows = np.stack([i, i, j, j])[:, :, :, None]
        cols = np.stack([i, j, i, j])[:, :, None, :]
        want = (rows * n + cols).astype(np.int64)  # (4, ns, 3, 3)
        if pattern is None:
            keys = np.unique(want)
            r = keys // n
            indptr = np.searchsorted(r, np.arange(n + 1))
            indices = keys % n
            itype = np.int32 if keys.size < 2**31 - 1 else np.int64
            self._indptr, self._indices = indptr.astype(itype), indices.astype(itype)
            self._pos = np.searchsorted(keys, want)
        else:
            if tuple(pattern.shape) != (n, n):
                raise InvalidParameter(
                    f"the pattern is {pattern.shape}, but the springs have {n} DOFs."
                )
            self._indptr, self._indices = pattern.indptr, pattern.indices
            row_of = np.repeat(np.arange(n, dtype=np.int64), np.diff(self._indptr))
            keys = row_of * n + self._indices.astype(np.int64)
            order = None if np.all(np.diff(keys) > 0) else np.argsort(keys)
            sorted_keys = keys if order is None else keys[order]
            pos = np.minimum(np.searchsorted(sorted_keys, want), keys.size - 1)
            if not np.array_equal(sorted_keys[pos], want):
                raise InvalidParameter(
                    "the given pattern lacks some spring entries: springs must join nodes of "
                    "one element (mesh edges)."
                )
            self._pos = pos if order is None else order[pos]
        self._nnz = int(self._indices.size)

    def _assemble(self, B: np.ndarray) -> sp.csr_matrix:
        """Sum the spring matrices [[B, -B], [-B, B]], B ``(ns, 3, 3)``, into CSR."""
        w = np.stack([B, -B, -B, B])
        data = np.bincount(self._pos.ravel(), weights=w.ravel(), minlength=self._nnz)
        n = self.ndofs
        return sp.csr_matrix((data, self._indices, self._indptr), shape=(n, n), copy=False)

    def _scatter(self, f_j: np.ndarray) -> np.ndarray:
        """Flat vector with ``-f_j`` on node i and ``f_j`` on node j of each spring."""
        w = np.stack([-f_j, f_j])
        return np.bincount(self._dofs.ravel(), weights=w.ravel(), minlength=self.ndofs)

    # geometry ----------------------------------------------------------------
    def lengths(self, x: np.ndarray) -> np.ndarray:
        """Current spring lengths l (m), ``(n_springs,)``."""
        return self._geometry(x)[0]

    def _geometry(self, x):
        """Lengths l ``(ns,)`` and unit directions n ``(ns, 3)``, i -> j.

        A spring of zero length has no direction; n is set to 0 there (its
        force is then zero, a subgradient of the energy's cone point).
        """
        xp = np.asarray(x, dtype=float).reshape(-1, 3)
        d = xp[self.edges[1]] - xp[self.edges[0]]
        l = np.sqrt(np.einsum("si,si->s", d, d))
        safe = np.where(l > 0.0, l, 1.0)
        return l, d / safe[:, None]

    # the Potential protocol ----------------------------------------------------
    def energy(self, x: np.ndarray) -> float:
        """Spring energy sum 1/2 k (l - l0)^2 (J) at positions x (m); always finite."""
        l, _ = self._geometry(x)
        return float(0.5 * np.sum(self.stiffness * (l - self.rest_length) ** 2))

    def gradient(self, x: np.ndarray) -> np.ndarray:
        """dE/dx (N), ``(ndofs,)``: k (l - l0) n on node j, its negative on node i."""
        l, n = self._geometry(x)
        return self._scatter((self.stiffness * (l - self.rest_length))[:, None] * n)

    def hessian(self, x: np.ndarray, project: bool = False) -> sp.csr_matrix:
        """d2E/dx2 (N/m), CSR ``(ndofs, ndofs)``; PSD when ``project`` (see the module).

        The exact transverse stiffness k (1 - l0/l) goes to -inf as a spring
        shrinks to zero length; the projected one never is negative.
        """
        l, n = self._geometry(x)
        return self._assemble(self._blocks(l, n, project))

    def linearize(self, x: np.ndarray,
                  project: bool = False) -> tuple[np.ndarray, sp.spmatrix | None]:
        """``(gradient, hessian)`` at once, sharing the lengths and directions."""
        l, n = self._geometry(x)
        g = self._scatter((self.stiffness * (l - self.rest_length))[:, None] * n)
        return g, self._assemble(self._blocks(l, n, project))

    def _blocks(self, l, n, project):
        """B = k [c (I - n n^T) + n n^T] with c = 1 - l0/l (clamped at 0 if project)."""
        k = self.stiffness
        c = np.zeros_like(l)
        np.divide(self.rest_length, l, out=c, where=l > 0.0)
        c = np.where(l > 0.0, 1.0 - c, 0.0)
        if project:
            c = np.maximum(c, 0.0)
        B = (k * (1.0 - c))[:, None, None] * _outer(n)
        for a in range(3):
            B[:, a, a] += k * c
        return B

    def energy_roundoff(self) -> float:
        """Absolute round-off of :meth:`energy` (J), the analogue of ElasticPotential's.

        Each length l is computed from coordinates with an absolute error
        of about eps l0, so each term 1/2 k (l - l0)^2 of a spring strained
        by O(1) carries ~ eps k l0^2; summed over the springs. (k l0^2 is the
        spring's energy scale, the counterpart of (mu + lam) V_t for a tet.)
        """
        return float(_EPS * np.sum(self.stiffness * self.rest_length**2))

    def gradient_roundoff(self) -> float:
        """Norm of the round-off in :meth:`gradient` (N): the floor under ||g||.

        The stretch l - l0 carries an absolute error of about eps l0 whatever
        the load, so each spring force k (l - l0) carries ~ eps k l0; summed
        per node over its springs and taken as a norm over the three
        components (as ``ElasticPotential.gradient_roundoff``).
        """
        w = self.stiffness * self.rest_length
        per_node = np.bincount(self.edges.ravel(), weights=np.concatenate([w, w]),
                               minlength=self.ndofs // 3)
        return float(_EPS * math.sqrt(3.0) * np.linalg.norm(per_node))

    # damping -------------------------------------------------------------------
    def damping_force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Damping force along the springs (N), ``(ndofs,)``.

        ``f_i = -k_d ((v_i - v_j) . n) n`` and ``f_j = -f_i`` for each spring,
        with n its current direction; zeros when k_d = 0.

        Parameters
        ----------
        x : numpy.ndarray
            ``(ndofs,)`` positions (m).
        v : numpy.ndarray
            ``(ndofs,)`` velocities (m/s).
        """
        if not np.any(self.k_d):
            return np.zeros(self.ndofs)
        _, n = self._geometry(x)
        vp = np.asarray(v, dtype=float).reshape(-1, 3)
        s = self.k_d * np.einsum("si,si->s", vp[self.edges[1]] - vp[self.edges[0]], n)
        return -self._scatter(s[:, None] * n)

    def damping_matrix(self, x: np.ndarray) -> sp.csr_matrix | None:
        """Damping matrix D (N s/m), symmetric PSD, with force ``-D v``; None if k_d = 0.

        Assembled from the blocks ``k_d n n^T`` on the same pattern as the
        Hessian. D depends on x (through n) but not on v.
        """
        if not np.any(self.k_d):
            return None
        _, n = self._geometry(x)
        return self._assemble(self.k_d[:, None, None] * _outer(n))


def _outer(n: np.ndarray) -> np.ndarray:
    """n n^T per spring, ``(ns, 3, 3)``; exactly symmetric (so are the matrices built on it)."""
    return n[:, :, None] * n[:, None, :]


def _per_spring(name, value, ns, unit) -> np.ndarray:
    """A finite, non-negative ``(ns,)`` float array from a scalar or an array."""
    try:
        arr = np.broadcast_to(np.asarray(value, dtype=float), (ns,)).copy()
    except (ValueError, TypeError):
        raise InvalidParameter(
            f"{name} must be one number or one per spring ({ns}), in {unit}; got {value!r}."
        ) from None
    if not np.all(np.isfinite(arr)) or np.any(arr < 0.0):
        raise InvalidParameter(f"{name} must be finite and >= 0 {unit}; got {value!r}.")
    return arr


# --------------------------------------------------------------------------------------
# Calibrations: k (N/m) per mesh edge from Young's modulus
# --------------------------------------------------------------------------------------
def _tet_edge_index(mesh) -> np.ndarray:
    """Index into ``mesh.edges`` of each tet's six local edges ``_TET_EDGES``, ``(6, ne)``."""
    t = np.asarray(mesh.t, dtype=np.int64)
    nv = mesh.p.shape[1]
    edges = np.sort(np.asarray(mesh.edges, dtype=np.int64), axis=0)
    ekeys = edges[0] * nv + edges[1]
    order = np.argsort(ekeys)
    a, b = t[_TET_EDGES[:, 0]], t[_TET_EDGES[:, 1]]
    keys = np.minimum(a, b) * nv + np.maximum(a, b)
    return order[np.searchsorted(ekeys[order], keys)]


def _edge_lengths(mesh) -> np.ndarray:
    p = np.asarray(mesh.p, dtype=float)
    return np.linalg.norm(p[:, mesh.edges[1]] - p[:, mesh.edges[0]], axis=0)


def _warn_nu(nu, what):
    if nu != SPRING_POISSON_RATIO:
        log.warning(
            "a spring network cannot represent nu = %g: its Poisson ratio is set by the mesh "
            "geometry (1/4 for an isotropic network, the Cauchy relation lam = mu; about 0.03 "
            "along the axes of fe.beam_mesh); %s. Use fe.ElasticBody to set nu.", nu, what,
        )


def van_gelder_stiffness(mesh: MeshTet, E: float, nu: float = SPRING_POISSON_RATIO) -> np.ndarray:
    """Spring constants of van Gelder (1998), 3-D form: ``k_e = E sum_{t ∋ e} V_t / l0_e^2``.

    The sum runs over the tets t that contain edge e, V_t their volumes.
    Each tet thus adds the energy ``1/2 E V_t sum_{e in t} (n_e . eps n_e)^2``
    under a homogeneous strain eps: the formula fixes the scale of the
    stiffness, not its anisotropy or its Poisson ratio (see the module
    docstring for the moduli it gives).

    Parameters
    ----------
    mesh : skfem.MeshTet
        Reference configuration (m).
    E : float
        Young's modulus (Pa).
    nu : float, optional
        Not used by the formula (kept for the common calibration
        signature); a warning is logged if it is not 1/4.

    Returns
    -------
    numpy.ndarray
        ``(n_edges,)`` k (N/m), in the order of ``mesh.edges``.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> mesh = fe.beam_mesh(1.0, 1.0, 1.0, cells=(1, 1, 1))  # a unit cube cut into 6 tets
    >>> k = van_gelder_stiffness(mesh, E=3.0e6)
    >>> k.size, round(float(k.max()))  # the body diagonal: E (6 tets x 1/6 m^3) / (3 m^2)
    (19, 1000000)
    """
    lame_parameters(E, nu)  # validates E and nu
    _warn_nu(nu, "van_gelder_stiffness ignores nu")
    V = np.abs(signed_volumes(mesh))
    e_of_t = _tet_edge_index(mesh)
    sumV = np.bincount(e_of_t.ravel(), weights=np.tile(V, 6), minlength=mesh.edges.shape[1])
    return E * sumV / _edge_lengths(mesh) ** 2


def lloyd_stiffness(mesh: MeshTet, E: float, nu: float = SPRING_POISSON_RATIO) -> np.ndarray:
    """Spring constants fitted per tet to the linear FEM stiffness (after Lloyd et al. 2007).

    For each tet t, the six constants ``k^t`` minimise the Frobenius norm::

        || sum_{e in t} k^t_e S_e - K_t ||_F,

    where ``K_t`` is the 12x12 stiffness matrix of the linear-elastic P1 tet
    (Lame mu, lam from E and nu) and ``S_e`` the 12x12 matrix of a unit
    spring on edge e at rest (blocks ``+-n n^T``). The normal equations are
    ``G k^t = b`` with ``G_ee = 4``, ``G_ef = (n_e . n_f)^2`` for edges that
    share a vertex, 0 for opposite edges, and::

        b_e = <S_e, K_t> = V_t [mu (|g|^2 + (n . g)^2) + lam (n . g)^2],
        g = grad N_j - grad N_i  (so n . g = 2 / l0).

    Each edge's k is the sum of its tets' ``k^t_e``; a negative sum is
    clamped to zero (the count is logged as a warning). nu enters only the
    target ``K_t``: the network's Poisson ratio is set by the mesh, and a
    target with nu near 1/2 stiffens every spring (see the module
    docstring); a warning is logged if nu != 1/4.

    Parameters
    ----------
    mesh : skfem.MeshTet
        Reference configuration (m).
    E : float
        Young's modulus (Pa).
    nu : float, optional
        Poisson's ratio of the target stiffness, default 1/4 (what springs
        represent).

    Returns
    -------
    numpy.ndarray
        ``(n_edges,)`` k (N/m), in the order of ``mesh.edges``.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> k = lloyd_stiffness(fe.beam_mesh(1.0, 1.0, 1.0, cells=(1, 1, 1)), E=1.0e6)
    >>> bool(k.min() > 0), k.size
    (True, 19)
    """
    mu, lam = lame_parameters(E, nu)
    _warn_nu(nu, "lloyd_stiffness uses nu only in the target of its least-squares fit")
    p = np.asarray(mesh.p, dtype=float).T
    t = np.asarray(mesh.t, dtype=np.int64)
    Xt = p[t]  # (4, ne, 3)
    Jac = np.stack([Xt[1] - Xt[0], Xt[2] - Xt[0], Xt[3] - Xt[0]], axis=2)  # columns
    V = np.abs(np.linalg.det(Jac)) / 6.0
    Ginv = np.linalg.inv(Jac)  # rows: grad N_1..3
    dN = np.concatenate([-Ginv.sum(axis=1)[:, None, :], Ginv], axis=1)  # (ne, 4, 3)
    a, b = _TET_EDGES[:, 0], _TET_EDGES[:, 1]
    d = Xt[b] - Xt[a]  # (6, ne, 3)
    n = d / np.linalg.norm(d, axis=2, keepdims=True)
    g = dN[:, b, :].transpose(1, 0, 2) - dN[:, a, :].transpose(1, 0, 2)  # (6, ne, 3)
    ng = np.einsum("mei,mei->me", n, g)
    rhs = V * (mu * (np.einsum("mei,mei->me", g, g) + ng**2) + lam * ng**2)  # (6, ne)
    G = np.einsum("mei,fei->emf", n, n) ** 2  # (ne, 6, 6)
    G[:, np.arange(6), 5 - np.arange(6)] = 0.0  # opposite edges share no block
    G[:, np.arange(6), np.arange(6)] = 4.0
    kt = np.linalg.solve(G, rhs.T[:, :, None])[:, :, 0]  # (ne, 6)
    k = np.bincount(_tet_edge_index(mesh).ravel(), weights=kt.T.ravel(),
                    minlength=mesh.edges.shape[1])
    negative = k < 0.0
    if negative.any():
        log.warning(
            "lloyd_stiffness: %d of %d fitted spring constants were negative and are set to 0 "
            "(poorly shaped tets); those edges carry no spring.", int(negative.sum()), k.size,
        )
        k[negative] = 0.0
    return k


# --------------------------------------------------------------------------------------
# The body
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MassSpring:
    """A mass-spring body: one spring per edge of the tet mesh, k calibrated from E.

    Interchangeable with :class:`fem_elastic.ElasticBody` in
    :class:`fem_elastic.Model`: the Model supplies the mesh and the (lumped)
    mass from the density, so the springs and an FEM body on the same mesh
    have the same mass. The built potential is a :class:`SpringPotential`
    (``model.body_potential``), which also gives the spring damping forces.

    What is honoured: E sets the scale of every spring constant, so
    stiffness is proportional to E; the moduli the network actually has
    depend on the calibration and on the mesh (on :func:`fe.beam_mesh`, van
    Gelder's constants give 30/29 E along the axes, 10/7 E along the cells'
    shared diagonal and 3/8 E across it: see the module docstring). nu is
    not representable (see below).

    Parameters
    ----------
    E : float
        Young's modulus (Pa), > 0, the target of the calibration.
    nu : float, optional
        Poisson's ratio, -1 < nu < 0.5. A spring network cannot represent
        it: its Poisson ratio is 1/4 (:attr:`effective_poisson_ratio`) for an
        isotropic network and set by the mesh otherwise (1/29 along the
        axes of :func:`fe.beam_mesh` with van Gelder's constants).
        :func:`van_gelder_stiffness` ignores nu, :func:`lloyd_stiffness`
        uses it as the target of its fit; either logs a warning when
        nu != 1/4 (:attr:`note` says which). Default 1/4.
    calibration : callable, optional
        ``calibration(mesh, E, nu) -> k`` (N/m per ``mesh.edges``):
        :func:`van_gelder_stiffness` (default: its axial modulus on
        :func:`fe.beam_mesh` is within 3.5 % of E) or :func:`lloyd_stiffness`,
        or any function of that signature (``functools.partial`` for extra
        arguments).
    k_d : float, optional
        Damping coefficient along each spring (N s/m), >= 0; default 0 (no
        spring damping). Per spring: the body's total damping grows with
        the number of edges; ``fe.Rayleigh`` damping on the Model does not.
    order : int, optional
        Must be 1: springs live on the mesh vertices.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> from fem_elastic.physics.springs import MassSpring, lloyd_stiffness
    >>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
    ...                  body=MassSpring(E=1e6, k_d=0.1), fixed="left")
    >>> springs = model.body_potential  # one spring per mesh edge
    >>> springs.stiffness.shape, round(float(springs.rest_length.max()), 4)  # (m)
    ((61,), 0.2872)
    >>> static = fe.solve_static(model)  # nothing loads it: it stays at rest
    >>> float(abs(static.displacement).max())
    0.0
    >>> MassSpring(E=1e6, calibration=lloyd_stiffness).note
    'springs calibrated by lloyd_stiffness to E = 1e+06 Pa; nu = 0.25 is used only as the target of the fit (a spring network has a Poisson ratio set by the mesh: 1/4 if isotropic).'
    """

    E: float
    nu: float = SPRING_POISSON_RATIO
    calibration: Callable = van_gelder_stiffness
    k_d: float = 0.0
    order: int = 1

    #: Poisson ratio of an isotropic spring network (Cauchy relation lam = mu);
    #: on a given mesh the measured value differs (see the module docstring).
    effective_poisson_ratio = SPRING_POISSON_RATIO

    def __post_init__(self):
        lame_parameters(self.E, self.nu)  # validates E and nu
        if not callable(self.calibration):
            raise InvalidParameter(
                "calibration must be a function calibration(mesh, E, nu) -> k, e.g. "
                f"fe.lloyd_stiffness or fe.van_gelder_stiffness; got {self.calibration!r}."
            )
        kd = self.k_d
        if isinstance(kd, bool) or not isinstance(kd, (int, float, np.integer, np.floating)) \
                or not math.isfinite(kd) or kd < 0:
            raise InvalidParameter(
                f"k_d (spring damping, N s/m) must be a finite number >= 0, got {kd!r}; "
                "use 0 for no damping."
            )
        if isinstance(self.order, bool) or self.order != 1:
            raise InvalidParameter(
                f"MassSpring has order 1 only (springs join mesh vertices), got order={self.order!r}; "
                "use fe.ElasticBody(material, order=2) for quadratic tets."
            )

    @property
    def note(self) -> str:
        """What of (E, nu) this body honours, in words."""
        name = getattr(self.calibration, "__name__", repr(self.calibration))
        use = ("ignored" if self.calibration is van_gelder_stiffness
               else "used only as the target of the fit" if self.calibration is lloyd_stiffness
               else "passed to the calibration")
        return (
            f"springs calibrated by {name} to E = {self.E:g} Pa; nu = {self.nu:g} is {use} "
            "(a spring network has a Poisson ratio set by the mesh: 1/4 if isotropic)."
        )

    def build(self, space: Discretization) -> SpringPotential:
        """The springs on the edges of ``space.mesh``, assembled on ``space.pattern``."""
        if space.order != 1:
            raise InvalidParameter(
                f"MassSpring needs a linear (order 1) discretization, got order {space.order}."
            )
        mesh = space.mesh
        try:
            k = np.asarray(self.calibration(mesh, self.E, self.nu), dtype=float)
        except TypeError as exc:
            raise InvalidParameter(
                f"the calibration must be a function (mesh, E, nu) -> k per edge, e.g. "
                f"fe.van_gelder_stiffness; calling {self.calibration!r} failed: {exc}."
            ) from None
        n_edges = mesh.edges.shape[1]
        if k.shape != (n_edges,) or not np.all(np.isfinite(k)) or np.any(k < 0):
            raise InvalidParameter(
                f"the calibration must return {n_edges} finite spring constants >= 0 (N/m), "
                f"one per mesh edge; got shape {k.shape}."
            )
        node = space.vertex_dofs[:, 0] // 3
        return SpringPotential(space.X, node[np.asarray(mesh.edges)], k,
                               k_d=self.k_d, pattern=space.pattern)
