"""Shape matching (Müller, Heidelberger, Teschner and Gross 2005): deformation without a mesh.

Each cluster of points remembers its rest shape ``x0_i`` (masses ``m_i``).
At every step the rest shape is matched to the current positions ``x_i``
by the optimal translation and linear map, and each point is pulled
towards its **goal position** ``g_i``:

- translation: the centres of mass, ``q_i = x0_i - x0_cm`` and ``p_i = x_i - x_cm``;
- ``A_pq = sum m_i p_i q_i^T``, ``A_qq = (sum m_i q_i q_i^T)^-1``;
- ``mode="rigid"``: ``g_i = R q_i + x_cm`` with R the rotation of the polar
  decomposition ``A_pq = R S`` (:func:`fem_elastic.materials.svd.polar_rotation`,
  a proper rotation even for an inverted cluster);
- ``mode="linear"``: ``A = A_pq A_qq`` scaled to ``det A = 1`` (volume
  preservation; ``R`` where ``det A <= 0``), ``g_i = (beta A + (1 - beta) R) q_i + x_cm``;
- ``mode="quadratic"``: the 9-term ``q~ = (q_x, q_y, q_z, q_x^2, q_y^2, q_z^2,
  q_x q_y, q_y q_z, q_z q_x)``, ``A~ = (sum m p q~^T)(sum m q~ q~^T)^-1`` (3 x 9)
  and ``g_i = (beta A~ + (1 - beta) [R 0 0]) q~_i + x_cm``; its quadratic
  terms let a cluster bend and twist. Unlike the paper, the quadratic terms
  are centred (their mass-weighted mean over the cluster subtracted): with
  ``sum m q~ = 0`` the goals keep the cluster's centre of mass, so momentum is
  conserved (the paper's uncentred terms push every cluster along the mean of
  ``A~``'s quadratic part), and the fit is the least-squares fit with a free
  translation. (No volume normalisation here: the paper's ``det A = 1``
  applies to a 3 x 3 map.)

The integration is the paper's (explicit in the goals, unconditionally
stable for ``alpha <= 1``):

    v <- v + alpha (g - x) / h + h f_ext / m,      x <- x + h v,

``alpha`` in (0, 1] the stiffness (1: the goals are reached in one step).
The scheme by itself is undamped (for a linear deviation it is symplectic
Euler on an oscillator of ``omega^2 h^2 = alpha (1 - beta)``); ``damping``
in [0, 1] removes that fraction of each cluster's non-rigid velocity
before the goal pull (Müller, Heidelberger, Hennix and Ratcliff 2007:
``v_i += k (v_cm + omega x r_i - v_i)``), which leaves linear and angular
momentum unchanged.

**Clusters** for large deformation: ``clusters = n`` cuts the bounding box of
the rest shape into a regular grid of cubic cells, ``n`` along its longest
side; each cell grown by ``overlap`` cell sizes on every side is a cluster
(clusters of fewer than 4 points, or flat ones, are dropped; a point left
in none joins the nearest). A point's goal is the average of its
clusters' goals. Each cluster matches with the masses ``m_i / n_i`` (``n_i``
the clusters point ``i`` is in), so the pulls of all clusters sum to zero:
linear momentum is conserved exactly, with clusters too.

**Held points** (fixed or driven) keep their prescribed motion, and enter
the matches with :data:`HELD_WEIGHT` times their mass: they anchor their
clusters' fits, as the paper's fixed particles of infinite mass do (with
their own mass only, a cantilever's one cluster would turn about its
support and tear it).

On a :class:`fe.Model` the points are the nodes of the mesh (vertices, and
edge nodes for P2 tets) with their lumped masses; the model gives the
external forces (gravity, tractions, and penalty or barrier contact as
explicit forces: the impulse method suits the scheme better), its Rayleigh
damping (an explicit force), the held and driven nodes
(``model.constraints``, imposed after the step) and the obstacles' impulse
response. The model's own energy is not the scheme's: ``fe.simulate``
records it as a diagnostic, and its blow-up watch judges the run by it. The
goal pull is stiff (``alpha m / h^2`` per point, a potential ``alpha / (2
h^2) sum m |g - x|^2``), so a body released from a large deformation turns
more energy into motion than a soft body's elastic energy was: pass
``energy_growth=math.inf`` to ``fe.simulate`` for such runs.

**Why a point cloud goes through** :class:`ShapeMatcher` **and not a Model**:
shape matching needs no mesh (:class:`ShapeMatcher` works on arrays of
points and masses, see its ``step``), whereas a Model is a finite element
body whose energies, frames and output are of a mesh. Building a tet mesh
of the cloud's hull only to run a scheme that never uses it would invent a
body (its masses from tet volumes, not the cloud's; a hull that fills
concavities; Delaunay slivers that mesh validation rejects).
"""

from __future__ import annotations

import math
import numbers
import weakref
from typing import TYPE_CHECKING, Literal

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from ..errors import Diverged, InvalidParameter
from ..materials.svd import polar_rotation
from .integrators.base import Integrator, StepStats, check_dt, check_state
from .position_based.base import check_one_body
from .state import State

if TYPE_CHECKING:  # for annotations only
    from ..physics.multibody import AnyModel

__all__ = ["HELD_WEIGHT", "MODES", "ShapeMatcher", "ShapeMatching"]

#: The matching modes.
MODES = ("rigid", "linear", "quadratic")

#: Held points enter the matches with this many times their mass: they anchor the fit of
#: their clusters (the paper's fixed particles of infinite mass, kept finite so that a fit
#: anchored on a planar face stays well conditioned).
HELD_WEIGHT = 1e3

# A cluster whose smallest principal second moment is below this fraction of its largest is
# flat (its points nearly coplanar): its linear fit is ill-conditioned, and it is dropped.
_FLAT = 1e-8


def _check_unit(name, value, low_open=True):
    ok = not isinstance(value, bool) and isinstance(value, numbers.Real) and math.isfinite(value)
    if not ok or not ((0.0 < value <= 1.0) if low_open else (0.0 <= value <= 1.0)):
        interval = "(0, 1]" if low_open else "[0, 1]"
        raise InvalidParameter(f"{name} must be a number in {interval}, got {value!r}.")
    return float(value)


def _check_settings(mode, beta, clusters, overlap):
    """``(mode, beta, clusters, overlap)`` checked and converted."""
    if mode not in MODES:
        raise InvalidParameter(f"mode must be one of {MODES}, got {mode!r}.")
    beta = _check_unit("beta", beta, low_open=False)
    if isinstance(clusters, bool) or not isinstance(clusters, numbers.Integral) or clusters < 1:
        raise InvalidParameter(
            f"clusters must be an integer >= 1 (grid cells along the longest side), got {clusters!r}."
        )
    if (isinstance(overlap, bool) or not isinstance(overlap, numbers.Real) or not math.isfinite(overlap)
            or not 0 <= overlap <= 4):
        raise InvalidParameter(f"overlap must be a number in [0, 4] (cell sizes), got {overlap!r}.")
    return mode, beta, int(clusters), float(overlap)


def _quadratic_terms(q: np.ndarray) -> np.ndarray:
    """The 9-term ``q~`` of (k, 3) vectors, (k, 9)."""
    x, y, z = q[:, 0], q[:, 1], q[:, 2]
    return np.stack([x, y, z, x * x, y * y, z * z, x * y, y * z, z * x], axis=1)


def grid_clusters(points: np.ndarray, clusters: int, overlap: float):
    """Overlapping clusters of ``points`` (n, 3) from a regular grid: ``(node, cluster)`` pairs.

    Cells are cubes, ``clusters`` along the longest side of the bounding box;
    a cluster is its cell grown by ``overlap`` cell sizes on each side. Empty
    clusters are left out; cluster numbers are consecutive.

    Returns
    -------
    node, cluster : numpy.ndarray of int
        One entry per membership, sorted by cluster.

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.array([[x, 0.0, 0.0] for x in np.linspace(0.0, 1.0, 5)])
    >>> node, cluster = grid_clusters(pts, 2, 0.25)
    >>> [node[cluster == c].tolist() for c in range(cluster.max() + 1)]
    [[0, 1, 2], [2, 3, 4]]
    """
    n = points.shape[0]
    if clusters == 1:
        return np.arange(n), np.zeros(n, dtype=np.int64)
    lo = points.min(axis=0)
    extent = np.ptp(points, axis=0)
    size = extent.max() / clusters
    if size <= 0.0:
        return np.arange(n), np.zeros(n, dtype=np.int64)
    cells = np.maximum(1, np.ceil(extent / size - 1e-9).astype(np.int64))  # per axis
    u = (points - lo) / size  # position in cell units
    slack = 1e-9
    first = np.clip(np.ceil(u - 1.0 - overlap - slack), 0, cells - 1).astype(np.int64)  # (n, 3)
    last = np.clip(np.floor(u + overlap + slack), 0, cells - 1).astype(np.int64)
    span = int((last - first).max()) + 1
    offsets = np.arange(span)
    nodes, ids = [], []
    for ox in offsets:  # at most (1 + 2 overlap + 1)^3 combinations: a handful of array passes
        for oy in offsets:
            for oz in offsets:
                k = first + np.array([ox, oy, oz])
                ok = np.all(k <= last, axis=1)
                nodes.append(np.flatnonzero(ok))
                ids.append((k[ok, 0] * cells[1] + k[ok, 1]) * cells[2] + k[ok, 2])
    node, cid = np.concatenate(nodes), np.concatenate(ids)
    _, cluster = np.unique(cid, return_inverse=True)
    order = np.lexsort((node, cluster))
    return node[order], cluster[order].astype(np.int64)


class ShapeMatcher:
    """Shape matching of a point set: rest shape, masses and clusters, built once.

    Parameters
    ----------
    rest : array_like, shape (n, 3)
        Rest positions (m).
    masses : array_like, shape (n,)
        Point masses (kg), > 0.
    mode : {"rigid", "linear", "quadratic"}
    beta : float
        In [0, 1]: the share of the linear (quadratic) fit in the goal
        against the rotation (``mode="rigid"`` ignores it).
    clusters : int
        Grid cells along the longest side of the bounding box (1: one cluster of all points).
    overlap : float
        How far each cluster reaches past its cell, in cell sizes, in [0, 4];
        1 (the default): a cell and its neighbours.
    held : array_like of bool, shape (n,), optional
        Points held in place: :meth:`step` leaves them where they are, with
        zero velocity, and they anchor the matches (:data:`HELD_WEIGHT` times
        their mass there).

    Examples
    --------
    A point cloud, no mesh: a deformed shape pulled back in one step (alpha = 1,
    rigid, at rest), to a rigid motion of the rest shape:

    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> rest = rng.random((50, 3))
    >>> sm = ShapeMatcher(rest, np.ones(50), mode="rigid")
    >>> x = rest @ np.diag([1.3, 0.8, 1.0]) + rng.normal(0.0, 0.01, (50, 3))
    >>> x1, v1 = sm.step(x, np.zeros((50, 3)), dt=0.01, alpha=1.0)
    >>> A = np.linalg.lstsq(np.c_[rest, np.ones(50)], x1, rcond=None)[0][:3]
    >>> bool(np.allclose(A.T @ A, np.eye(3), atol=1e-12))   # x1 = Q rest + c, Q a rotation
    True
    """

    def __init__(self, rest: ArrayLike, masses: ArrayLike,
                 mode: Literal["rigid", "linear", "quadratic"] = "linear", beta: float = 0.5,
                 clusters: int = 1, overlap: float = 1.0, held: ArrayLike | None = None) -> None:
        rest = np.array(rest, dtype=float)
        masses = np.array(masses, dtype=float)
        if rest.ndim != 2 or rest.shape[1] != 3 or rest.shape[0] < 4 or not np.isfinite(rest).all():
            raise InvalidParameter(
                f"rest must be finite (n, 3) point positions with n >= 4, got shape {rest.shape}."
            )
        if masses.shape != (rest.shape[0],) or not np.isfinite(masses).all() or (masses <= 0).any():
            raise InvalidParameter(f"masses must be {rest.shape[0]} finite numbers > 0 (kg).")
        self.mode, self.beta, clusters, overlap = _check_settings(mode, beta, clusters, overlap)
        self.held = np.zeros(rest.shape[0], dtype=bool) if held is None else np.array(held, dtype=bool)
        if self.held.shape != (rest.shape[0],):
            raise InvalidParameter(f"held must be {rest.shape[0]} booleans, got shape {self.held.shape}.")
        self.rest, self.masses = rest, masses
        self._weights = np.where(self.held, HELD_WEIGHT * masses, masses)  # in the matches
        node, cluster = grid_clusters(rest, clusters, overlap)
        node, cluster = self._drop_flat(rest, self._weights, node, cluster)
        self._build(node, cluster)

    # clusters -------------------------------------------------------------------------
    @staticmethod
    def _moments(rest, m, node, cluster, nc):
        """(centres (nc, 3), second moments sum m q q^T (nc, 3, 3)) with masses m per membership."""
        S = sp.csr_matrix((np.ones(node.size), (cluster, np.arange(node.size))), shape=(nc, node.size))
        M = S @ m
        cm = (S @ (m[:, None] * rest[node])) / M[:, None]
        q = rest[node] - cm[cluster]
        mom = (S @ (m[:, None] * (q[:, :, None] * q[:, None, :]).reshape(-1, 9))).reshape(nc, 3, 3)
        return cm, mom

    def _drop_flat(self, rest, masses, node, cluster):
        nc = int(cluster.max()) + 1
        count = np.bincount(cluster, minlength=nc)
        cm, mom = self._moments(rest, masses[node], node, cluster, nc)
        w = np.linalg.eigvalsh(mom)
        keep = (count >= 4) & (w[:, 0] > _FLAT * w[:, 2])
        if not keep.any():
            raise InvalidParameter(
                "the points are (nearly) coplanar or collinear: shape matching needs a 3-D point "
                "set (each cluster at least 4 points not on one plane)."
            )
        renumber = np.cumsum(keep) - 1
        inside = keep[cluster]
        node, cluster = node[inside], renumber[cluster[inside]]
        orphans = np.setdiff1d(np.arange(rest.shape[0]), node)
        if orphans.size:  # join the cluster with the nearest centre
            centres = cm[keep]
            d = ((rest[orphans, None, :] - centres[None]) ** 2).sum(axis=2)
            node = np.concatenate([node, orphans])
            cluster = np.concatenate([cluster, d.argmin(axis=1)])
        order = np.lexsort((node, cluster))
        return node[order], cluster[order]

    def _build(self, node, cluster):
        n = self.rest.shape[0]
        k = node.size
        nc = int(cluster.max()) + 1
        self.n_clusters = nc
        self._node, self._cluster = node, cluster
        per_node = np.bincount(node, minlength=n).astype(float)
        self._mt = self._weights[node] / per_node[node]  # mass split among a node's clusters
        # S sums memberships per cluster; Avg averages them per node
        self._S = sp.csr_matrix((np.ones(k), (cluster, np.arange(k))), shape=(nc, k))
        self._avg = sp.csr_matrix((1.0 / per_node[node], (node, np.arange(k))), shape=(n, k))
        self._M = self._S @ self._mt
        cm0 = (self._S @ (self._mt[:, None] * self.rest[node])) / self._M[:, None]
        self._q = self.rest[node] - cm0[cluster]  # (k, 3)
        if self.mode == "quadratic":
            qt = _quadratic_terms(self._q)  # (k, 9)
            # centred per cluster (the linear terms are already): sum m q~ = 0, so the goals keep
            # the centre of mass and the fit is the least-squares one with a free translation
            mean = (self._S @ (self._mt[:, None] * qt)) / self._M[:, None]
            self._qt = qt - mean[cluster]
            outer = (self._qt[:, :, None] * self._qt[:, None, :]).reshape(k, 81)
            Aqq = (self._S @ (self._mt[:, None] * outer)).reshape(nc, 9, 9)
            self._Aqq_inv = np.linalg.pinv(Aqq, hermitian=True)
        else:
            self._qt = self._q
            outer = (self._q[:, :, None] * self._q[:, None, :]).reshape(k, 9)
            Aqq = (self._S @ (self._mt[:, None] * outer)).reshape(nc, 3, 3)
            self._Aqq_inv = np.linalg.inv(Aqq)

    @property
    def cluster_sizes(self) -> np.ndarray:
        """Points per cluster, ``(n_clusters,)``."""
        return np.bincount(self._cluster, minlength=self.n_clusters)

    # matching -------------------------------------------------------------------------
    def _centres(self, x):
        return (self._S @ (self._mt[:, None] * x[self._node])) / self._M[:, None]

    def goals(self, x: ArrayLike) -> np.ndarray:
        """Goal positions ``(n, 3)`` (m) of the points at positions ``x`` (n, 3).

        Examples
        --------
        >>> import numpy as np
        >>> rest = np.random.default_rng(1).random((20, 3))
        >>> c, s = np.cos(0.4), np.sin(0.4)
        >>> Q = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        >>> x = rest @ Q.T + 2.0                               # a rigid motion of the rest shape
        >>> bool(np.allclose(ShapeMatcher(rest, np.ones(20), "quadratic").goals(x), x, atol=1e-12))
        True
        """
        x = np.asarray(x, dtype=float)
        node, cluster = self._node, self._cluster
        cm = self._centres(x)
        p = x[node] - cm[cluster]  # (k, 3)
        k = node.size
        w = self._mt[:, None] * p
        nt = self._qt.shape[1]
        Apq = (self._S @ (w[:, :, None] * self._qt[:, None, :]).reshape(k, 3 * nt)).reshape(-1, 3, nt)
        R = np.moveaxis(polar_rotation(np.moveaxis(Apq[:, :, :3], 0, -1)), -1, 0)  # (nc, 3, 3)
        if self.mode == "rigid" or self.beta == 0.0:
            T = R
        elif self.mode == "linear":
            A = Apq @ self._Aqq_inv
            det = np.linalg.det(A)
            good = det > np.finfo(float).tiny
            A[good] /= np.cbrt(det[good])[:, None, None]
            A[~good] = R[~good]  # flat or inverted fit: no volume-preserving linear map
            T = self.beta * A + (1.0 - self.beta) * R
        else:
            A = Apq @ self._Aqq_inv  # (nc, 3, 9)
            T = self.beta * A
            T[:, :, :3] += (1.0 - self.beta) * R
        g = np.einsum("kij,kj->ki", T[cluster], self._qt) + cm[cluster]
        return self._avg @ g

    def rigid_velocity_damping(self, x: np.ndarray, v: np.ndarray, k: float) -> np.ndarray:
        """The velocity change ``k (v_cm + omega x r - v)`` averaged over each point's clusters.

        Examples
        --------
        >>> import numpy as np
        >>> rest = np.random.default_rng(2).random((30, 3))
        >>> sm = ShapeMatcher(rest, np.ones(30))
        >>> spin = np.cross([0.0, 0.0, 1.0], rest - rest.mean(axis=0)) + [1.0, 0.0, 0.0]
        >>> bool(np.abs(sm.rigid_velocity_damping(rest, spin, 1.0)).max() < 1e-12)  # rigid: kept
        True
        """
        node, cluster, mt = self._node, self._cluster, self._mt
        cm = self._centres(x)
        vcm = (self._S @ (mt[:, None] * v[node])) / self._M[:, None]
        r = x[node] - cm[cluster]
        L = self._S @ (mt[:, None] * np.cross(r, v[node]))
        rr = (r[:, :, None] * r[:, None, :]).reshape(-1, 9)
        inertia = -(self._S @ (mt[:, None] * rr)).reshape(-1, 3, 3)
        trace = -(inertia[:, 0, 0] + inertia[:, 1, 1] + inertia[:, 2, 2])
        for a in range(3):
            inertia[:, a, a] += trace
        omega = np.einsum("cij,cj->ci", np.linalg.pinv(inertia, hermitian=True), L)
        rigid = vcm[cluster] + np.cross(omega[cluster], r)
        return k * (self._avg @ (rigid - v[node]))

    def step(self, x: ArrayLike, v: ArrayLike, dt: float, alpha: float = 1.0, damping: float = 0.0,
             force: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
        """One step of shape matching on arrays: ``(x1, v1)``, each (n, 3).

        ``v += damping-change; v += alpha (g - x) / dt + dt force / m; x += dt v``.

        Parameters
        ----------
        x, v : array_like, shape (n, 3)
            Positions (m) and velocities (m/s).
        dt : float
            Time step (s).
        alpha : float
            Stiffness in (0, 1].
        damping : float
            Fraction in [0, 1] of the clusters' non-rigid velocity removed first.
        force : array_like, shape (n, 3), optional
            External force per point (N), e.g. ``masses[:, None] * gravity``.
        """
        h = check_dt(dt)
        alpha = _check_unit("alpha", alpha)
        damping = _check_unit("damping", damping, low_open=False)
        x = np.array(x, dtype=float)
        v = np.array(v, dtype=float)
        if damping:
            v += self.rigid_velocity_damping(x, v, damping)
        v += (alpha / h) * (self.goals(x) - x)
        if force is not None:
            v += (h / self.masses)[:, None] * np.asarray(force, dtype=float)
        v[self.held] = 0.0
        return x + h * v, v


class ShapeMatching(Integrator):
    """Shape matching as an integrator on the nodes of a model (see the module notes).

    Parameters
    ----------
    mode : {"rigid", "linear", "quadratic"}
        What a cluster may do besides rotating and translating.
    beta : float
        In [0, 1]: how much of the linear/quadratic fit enters the goals (0: rigid).
    alpha : float
        Stiffness in (0, 1]: the fraction of the way to the goals pulled per step.
    damping : float
        In [0, 1]: fraction of each cluster's non-rigid velocity removed every step.
    clusters : int
        Grid cells along the longest side of the body (1: one cluster, the paper's basic method).
    overlap : float
        Reach of each cluster past its cell, in cell sizes.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(6, 1, 1)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.Corotated(E=1e5, nu=0.3)),
    ...                  fixed="left", gravity=(0, 0, -9.81))
    >>> run = fe.simulate(model, fe.ShapeMatching(mode="linear", damping=0.2), dt=0.01, steps=20)
    >>> bool(run.displacement[-1, :, 2].min() < 0.0), float(run.displacement[-1, 0, 2])  # sags, held
    (True, 0.0)
    """

    explicit = False
    order = 1
    mass = "lumped"

    def __init__(self, mode: Literal["rigid", "linear", "quadratic"] = "linear", beta: float = 0.5,
                 alpha: float = 0.5, damping: float = 0.0, clusters: int = 1,
                 overlap: float = 1.0) -> None:
        super().__init__()
        self.mode, self.beta, self.clusters, self.overlap = _check_settings(mode, beta, clusters, overlap)
        self.alpha = _check_unit("alpha", alpha)
        self.damping = _check_unit("damping", damping, low_open=False)
        self._model_ref: weakref.ref | None = None  # weak reference to the model the matchers below are of
        self._matchers: dict[bytes, ShapeMatcher] = {}  # held nodes (bytes) -> ShapeMatcher: a cache, not a setting

    def __repr__(self) -> str:
        return (f"fe.ShapeMatching(mode={self.mode!r}, beta={self.beta:g}, alpha={self.alpha:g}, "
                f"damping={self.damping:g}, clusters={self.clusters}, overlap={self.overlap:g})")

    def matcher(self, model: AnyModel, t: float = 0.0) -> ShapeMatcher:
        """The :class:`ShapeMatcher` of ``model``'s nodes, with the nodes held at time ``t`` (s).

        Built on first use and kept (one per set of held nodes: a driven
        boundary's release changes it).
        """
        if self._model_ref is None or self._model_ref() is not model:
            self._model_ref, self._matchers = weakref.ref(model), {}
        held_dofs = np.zeros(model.ndofs, dtype=bool)
        held_dofs[model.constraints(t)[0]] = True
        held = held_dofs.reshape(-1, 3).all(axis=1)
        key = held.tobytes()
        matcher = self._matchers.get(key)
        if matcher is None:
            if len(self._matchers) >= 4:
                self._matchers.pop(next(iter(self._matchers)))
            matcher = ShapeMatcher(model.X.reshape(-1, 3), model.lumped_mass[0::3], self.mode,
                                   self.beta, self.clusters, self.overlap, held=held)
            self._matchers[key] = matcher
        return matcher

    def step(self, model: AnyModel, state: State, dt: float) -> State:
        h = check_dt(dt)
        check_state(model, state)
        check_one_body(model, "ShapeMatching")
        stats = self.last_stats = StepStats()
        sm = self.matcher(model, state.t + h)
        f = model.external_force()
        for term in model.contacts:  # penalty / barrier contact, as explicit forces
            f -= term.gradient(state.x)
            stats.gradient_evaluations += 1
        fd = model.damping_force(state.x, state.v)
        if fd is not None:
            f += fd
        x1, v1 = sm.step(state.x.reshape(-1, 3), state.v.reshape(-1, 3), h, self.alpha,
                         self.damping, f.reshape(-1, 3))
        x1, v1 = x1.ravel(), v1.ravel()
        if not (np.isfinite(x1).all() and np.isfinite(v1).all()):
            raise Diverged(
                f"ShapeMatching produced non-finite positions at t = {state.t:.6g} s (a contact "
                "or damping force too stiff for an explicit force at this dt?).",
                time=state.t, reason="non-finite state", last_good_state=state,
            )
        return self._finish(model, x1, v1, state.t + h)
