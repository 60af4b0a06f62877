"""Contact with fixed obstacles: the contact potentials, and the notes on the three methods.

The obstacles themselves (:class:`~fem_elastic.physics.obstacles.Ground`,
:class:`~fem_elastic.physics.obstacles.Sphere`,
:class:`~fem_elastic.physics.obstacles.Box`) are in
:mod:`fem_elastic.physics.obstacles`; ``obstacle.build(space, nodal_mass)``
makes the potential of this module that enforces them.

An obstacle is a rigid, fixed solid described by its signed distance ``d(p)``
(m): positive outside, zero on the surface, negative inside, with the outward
unit normal ``n(p) = grad d``. Every node of the body (the P1 vertices, and for
P2 tets the edge nodes too) is kept outside it, in one of three ways, chosen
by ``method``:

``"penalty"``
    A spring on the penetration ``delta_i = max(0, -d_i)`` of every node,

        E = sum_i 1/2 k delta_i^2,

    C1 in x, so Newton and the implicit integrators see a smooth energy with
    a piecewise-constant Hessian. Nodes do penetrate, by a bounded amount
    (see *Penalty stiffness* below).
``"barrier"``
    The log barrier of Incremental Potential Contact (Li et al. 2020),

        b(d) = -kappa (d - dhat)^2 log(d / dhat)   for 0 < d < dhat,
        b(d) = 0 for d >= dhat,   b(d) = +inf for d <= 0,

    C2 at ``d = dhat``. The energy is +inf at any penetration, so Newton's
    backtracking line search (which backs off from +inf) never ends a step
    with a node inside, and a loaded node rests at a gap between
    ``dhat / 2`` and ``dhat`` (see *Barrier stiffness*). There is no
    continuous collision detection: only the end of each step is tested,
    so a node fast enough to cross a *thin* obstacle (a slab, a small box
    or sphere) within one step passes through it. The ground, a half-space,
    cannot be crossed this way.
``"impulse"``
    No potential: after each step the integrator calls
    :meth:`~fem_elastic.physics.obstacles.Obstacle.respond`, which projects
    penetrating nodes back onto the surface and reflects their normal velocity
    with a coefficient of restitution ``e``, with Coulomb friction on the
    tangential velocity (the particle-plane collision response of the lecture
    notes, ``v+ = v- + j / m`` with ``j = -(1 + e) m (v- . n) n``).

Penalty stiffness
-----------------
Every node gets the same spring, ``k = M |g| / penetration`` (N/m), with ``M``
the body's total mass (kg), ``|g|`` the model's gravity (9.81 m/s^2 for a
model without gravity; the obstacle's ``gravity`` keyword overrides it) and
``penetration`` (m) the design tolerance: one node alone would
carry the body's whole weight at that depth. A body resting on a plane under
its own weight pushes on it with non-negative nodal forces ``k delta_i`` that
add up to ``M |g|``, so **every node penetrates at most ``penetration``**,
whatever the mesh; more precisely the depths of the contact nodes add up to
exactly ``penetration`` (``sum k delta_i = M |g|``), so when ``N`` nodes share
the weight they penetrate ``penetration / N`` on average. (A stiffness proportional to each node's mass would not
give such a bound: the weight of the whole body rests on the few bottom nodes,
whose share of the mass shrinks as the mesh is refined.) ``stiffness=``
overrides ``k``. Other loads push harder: the bound scales with the total
normal load over ``M |g|``, and an impact at speed ``v`` penetrates about
``v sqrt(penetration / (N |g|))``.

The stiff springs limit explicit time steps: a node of mass ``m_i`` on its
spring oscillates at ``omega_i = sqrt(k / m_i)``, and symplectic Euler needs
``dt < 2 / omega``. :meth:`~fem_elastic.physics.obstacles.Obstacle.critical_omega`
returns the largest ``omega_i``; since the contact adds a positive
semi-definite term to the stiffness, ``sqrt(omega_body^2 + omega_contact^2)``
bounds the largest frequency of the whole system (Weyl's inequality) for a
stable-step estimate.

Barrier stiffness
-----------------
Every node gets the same ``kappa`` (N/m), chosen so that the barrier force
``-kappa b'(d)`` of one node equals the body's weight ``M |g|`` at
``d = dhat / 2``: ``kappa = M |g| / ((1/2 + ln 2) dhat)``. The force decreases
with ``d``, so a node carrying at most the whole weight rests at
``dhat / 2 <= d < dhat``; a body resting on a plane floats at most ``dhat``
above it and never touches it. ``stiffness=`` overrides ``kappa``. The barrier
stiffens without bound as ``d -> 0``: use it with implicit integrators.

Friction and restitution are only built for ``method="impulse"``; the penalty
and barrier forms are frictionless, and the bounce of a penalty contact is set
by the integrator (and any damping), so passing ``friction`` or
``restitution`` with them raises :class:`InvalidParameter` rather than being
ignored.

Symbols: ``d`` signed distance (m), ``n`` outward unit normal, ``Hd`` the
Hessian of ``d`` (1/m, the surface curvature), ``k``/``kappa`` per-node
stiffness (N/m), ``dhat`` barrier activation distance (m), ``e`` restitution,
``mu`` friction coefficient.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidParameter
from .potential import Potential

__all__ = [
    "ContactPotential",
    "PenaltyContact",
    "BarrierContact",
]

METHODS = ("penalty", "barrier", "impulse")

# b'(dhat / 2) = -(1/2 + ln 2) dhat: the slope of the barrier profile at the design gap
_BARRIER_SLOPE_AT_HALF = 0.5 + math.log(2.0)


# ---------------------------------------------------------------------------------------
# parameter checks
def _positive(value, name: str, unit: str, example: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
        raise InvalidParameter(f"{name} must be a number ({unit}), e.g. {example}; got {value!r}.")
    value = float(value)
    if not math.isfinite(value) or value <= 0.0:
        raise InvalidParameter(
            f"{name} must be finite and > 0 {unit}, got {value!r}; pass e.g. {name}={example}."
        )
    return value


def _as_points(p) -> np.ndarray:
    """(n, 3) float points; a flat (3n,) DOF vector is read as n points."""
    p = np.asarray(p, dtype=float)
    if p.ndim == 1 and p.size % 3 == 0:
        p = p.reshape(-1, 3)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InvalidParameter(f"points must have shape (n, 3), got {p.shape}.")
    return p


# ---------------------------------------------------------------------------------------
# the per-node energy profiles phi(d) and their derivatives in d
def _penalty_profile(d: np.ndarray):
    """phi = 1/2 d^2 (for d < 0), phi', phi''."""
    return 0.5 * d * d, d, np.ones_like(d)


def _barrier_profile(d: np.ndarray, dhat: float):
    """phi = -(d - dhat)^2 log(d / dhat) (for 0 < d < dhat), phi', phi''."""
    s = d - dhat
    lg = np.log(d / dhat)
    phi = -s * s * lg
    dphi = -2.0 * s * lg - s * s / d
    d2phi = -2.0 * lg - 4.0 * s / d + (s / d) ** 2
    return phi, dphi, d2phi


# ---------------------------------------------------------------------------------------
class ContactPotential(Potential):
    """The contact energy of nodes against an obstacle, ``E = sum_i w_i phi(d_i)``.

    Base class of :class:`PenaltyContact` and :class:`BarrierContact`. Only the
    active nodes (``d_i`` below :attr:`reach`) are touched beyond the distance
    evaluation, so a state with nothing in contact costs one vectorized
    distance query and returns an all-zero gradient and an empty Hessian.

    The gradient of node i is ``w_i phi'(d_i) n_i`` and its 3x3 Hessian block
    ``w_i (phi''(d_i) n_i n_i^T + phi'(d_i) Hd_i)``; nodes do not interact, so
    the Hessian is block diagonal. On the active set ``phi' <= 0`` (the
    potential pushes outward) and ``Hd`` is positive semi-definite with
    ``Hd n = 0`` for all three obstacles (plane: 0; sphere: ``(I - n n^T) /
    |p - c|``; box: the same on the distance to its nearest edge or corner
    outside, 0 inside), so the eigenvalue-clamped (``project=True``) block is
    exactly ``w_i phi'' n_i n_i^T``.

    Parameters
    ----------
    obstacle : fem_elastic.physics.obstacles.Obstacle
        The geometry.
    X : numpy.ndarray
        ``(ndofs,)`` reference DOF positions (m); only their number is used.
    weights : numpy.ndarray
        ``(nnodes,)`` per-node stiffness ``k_i`` or ``kappa_i`` (N/m).
    nodal_mass : numpy.ndarray, optional
        ``(nnodes,)`` lumped nodal masses (kg), for :meth:`critical_omega`.

    Examples
    --------
    >>> import numpy as np
    >>> from fem_elastic.physics.obstacles import Sphere
    >>> pot = PenaltyContact(Sphere((0, 0, 0), 1.0), np.zeros(3), stiffness=10.0)
    >>> x = np.array([0.0, 0.0, 0.9])  # 0.1 m inside the ball
    >>> H, P = pot.hessian(x).toarray(), pot.hessian(x, project=True).toarray()
    >>> np.diag(H).round(6).tolist(), np.diag(P).round(6).tolist()  # N/m; curvature clamped
    ([-1.111111, -1.111111, 10.0], [0.0, 0.0, 10.0])
    """

    #: d below which a node is active (m)
    reach: float = 0.0

    def __init__(self, obstacle, X, weights, nodal_mass=None):
        X = np.asarray(X, dtype=float)
        self.obstacle = obstacle
        self.ndofs = X.size
        nn = self.ndofs // 3
        try:
            w = np.broadcast_to(np.asarray(weights, dtype=float), (nn,)).copy()
        except (TypeError, ValueError):
            raise InvalidParameter(
                f"contact stiffness must be a number (N/m) or one per node ({nn}), got {weights!r}."
            ) from None
        if not np.all(np.isfinite(w)) or np.any(w <= 0):
            raise InvalidParameter("contact stiffness must be finite and > 0 N/m at every node.")
        self.weights = w
        self.nodal_mass = None if nodal_mass is None else np.asarray(nodal_mass, dtype=float)
        for arr in (self.weights, self.nodal_mass):
            if arr is not None:
                arr.setflags(write=False)

    # the profile: subclasses -----------------------------------------------------------
    def _profile(self, d):  # pragma: no cover - abstract
        raise NotImplementedError

    # Potential protocol -----------------------------------------------------------------
    def _active(self, x):
        p = _as_points(x)
        d = self.obstacle.signed_distance(p)
        return p, d, np.flatnonzero(d < self.reach)

    def energy(self, x: np.ndarray) -> float:
        """Contact energy (J); +inf where inadmissible (a barrier node at d <= 0)."""
        _, d, act = self._active(x)
        if act.size == 0:
            return 0.0
        da = d[act]
        if self._inadmissible_mask(da).any():
            return math.inf
        phi = self._profile(da)[0]
        return float(self.weights[act] @ phi)

    def _local(self, x, need_hessian: bool, project: bool):
        """Active nodes, their gradients (na, 3) and Hessian blocks (na, 3, 3)."""
        p, d, act = self._active(x)
        if act.size == 0:
            return act, None, None
        dist, n, Hd = self.obstacle._derivatives(p[act])
        w = self.weights[act]
        bad = self._inadmissible_mask(dist)
        if bad.any():  # no force is defined through a barrier: NaN, not a made-up push
            dist = np.where(bad, 0.5 * self.reach, dist)
            w = np.where(bad, np.nan, w)
        _, dphi, d2phi = self._profile(dist)
        g = (w * dphi)[:, None] * n
        if not need_hessian:
            return act, g, None
        H = (w * d2phi)[:, None, None] * (n[:, :, None] * n[:, None, :])
        if Hd is not None and not project:
            H = H + (w * dphi)[:, None, None] * Hd
        return act, g, H

    def _inadmissible_mask(self, d):
        return np.zeros(d.shape, dtype=bool)

    def _scatter_gradient(self, act, g_local) -> np.ndarray:
        g = np.zeros(self.ndofs)
        if act.size:
            g.reshape(-1, 3)[act] = g_local
        return g

    def _block_diagonal(self, act, H_local) -> sp.csr_matrix:
        n = self.ndofs
        if act.size == 0:
            return sp.csr_matrix((n, n))
        counts = np.zeros(n, dtype=np.int64)
        rows = (3 * act[:, None] + np.arange(3)).ravel()  # sorted: act is sorted
        counts[rows] = 3
        indptr = np.concatenate([[0], np.cumsum(counts)])
        indices = np.repeat(3 * act[:, None] + np.arange(3), 3, axis=0).ravel()
        return sp.csr_matrix((H_local.ravel(), indices, indptr), shape=(n, n))

    def gradient(self, x: np.ndarray) -> np.ndarray:
        """dE/dx (N), ``(ndofs,)``; the contact force is its negative."""
        act, gl, _ = self._local(x, False, False)
        return self._scatter_gradient(act, gl)

    def hessian(self, x: np.ndarray, project: bool = False) -> sp.csr_matrix:
        """d2E/dx2 (N/m), block-diagonal CSR ``(ndofs, ndofs)``; PSD with ``project=True``."""
        act, _, Hl = self._local(x, True, project)
        return self._block_diagonal(act, Hl)

    def linearize(self, x: np.ndarray,
                  project: bool = False) -> tuple[np.ndarray, sp.spmatrix | None]:
        """Gradient (N) and Hessian (N/m) at once, sharing the distance queries."""
        act, gl, Hl = self._local(x, True, project)
        return self._scatter_gradient(act, gl), self._block_diagonal(act, Hl)

    def energy_roundoff(self) -> float:
        """Round-off of :meth:`energy` beyond ``eps |E|`` (J): none worth adding, 0.0."""
        return 0.0

    def gradient_roundoff(self) -> float:
        """Round-off floor of ||gradient|| (N): none worth adding, 0.0."""
        return 0.0

    def contact_force(self, x: np.ndarray) -> np.ndarray:
        """The force the obstacle exerts on the nodes (N), ``(ndofs,)``: ``-gradient(x)``."""
        return 0.0 - self.gradient(x)  # not -g: no -0.0 where nothing touches

    def critical_omega(self) -> float:
        """Largest ``sqrt(stiffness_i / m_i)`` (rad/s) of a node on its contact spring.

        Needs the nodal masses given at construction. For the barrier this is
        the stiffness at the design gap ``dhat / 2``; see the module notes.
        """
        if self.nodal_mass is None:
            raise InvalidParameter(
                "critical_omega needs the nodal masses: build the potential with "
                "obstacle.build(space, nodal_mass)."
            )
        return float(np.sqrt(self._design_curvature() * (self.weights / self.nodal_mass)).max())

    def _design_curvature(self) -> float:
        return 1.0


class PenaltyContact(ContactPotential):
    """Penalty contact: ``E = sum_i 1/2 k_i max(0, -d_i)^2`` (J).

    Usually made by ``obstacle.build(space, nodal_mass)`` with
    ``method="penalty"``; see the module notes for the choice of ``k``.

    Parameters
    ----------
    obstacle : fem_elastic.physics.obstacles.Obstacle
    X : numpy.ndarray
        ``(ndofs,)`` DOF positions (m); only their number is used.
    stiffness : float or numpy.ndarray
        Per-node spring stiffness ``k_i`` (N/m), scalar or ``(nnodes,)``.
    nodal_mass : numpy.ndarray, optional
        ``(nnodes,)`` (kg), for :meth:`critical_omega`.

    Examples
    --------
    >>> import numpy as np
    >>> from fem_elastic.physics.obstacles import Ground
    >>> pot = PenaltyContact(Ground(), np.zeros(6), stiffness=100.0)
    >>> x = np.array([0.0, 0.0, -0.01, 0.0, 0.0, 0.5])  # node 0 is 1 cm deep, node 1 above
    >>> round(pot.energy(x), 6), pot.contact_force(x).round(6).tolist()  # J, N
    (0.005, [0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    """

    reach = 0.0

    def __init__(self, obstacle, X, stiffness, nodal_mass=None):
        super().__init__(obstacle, X, stiffness, nodal_mass)

    def _profile(self, d):
        return _penalty_profile(d)


class BarrierContact(ContactPotential):
    """IPC log-barrier contact: ``E = sum_i -kappa_i (d_i - dhat)^2 log(d_i / dhat)`` (J).

    Summed over nodes with ``0 < d_i < dhat``; +inf if any node has
    ``d_i <= 0``, where the gradient is not defined (NaN). Usually made by
    ``obstacle.build(space, nodal_mass)`` with ``method="barrier"``.

    Parameters
    ----------
    obstacle : fem_elastic.physics.obstacles.Obstacle
    X : numpy.ndarray
        ``(ndofs,)`` DOF positions (m); only their number is used.
    kappa : float or numpy.ndarray
        Per-node barrier stiffness (N/m), scalar or ``(nnodes,)``.
    dhat : float
        Activation distance (m): nodes farther than this feel nothing.
    nodal_mass : numpy.ndarray, optional
        ``(nnodes,)`` (kg), for :meth:`critical_omega`.

    Examples
    --------
    >>> import numpy as np
    >>> from fem_elastic.physics.obstacles import Ground
    >>> pot = BarrierContact(Ground(), np.zeros(3), kappa=1.0, dhat=1e-3)
    >>> pot.energy(np.array([0.0, 0.0, 2e-3])), pot.energy(np.array([0.0, 0.0, -1e-6]))
    (0.0, inf)
    >>> bool(pot.gradient(np.array([0.0, 0.0, 5e-4]))[2] < 0)  # pushes up: force = -gradient
    True
    """

    def __init__(self, obstacle, X, kappa, dhat, nodal_mass=None):
        super().__init__(obstacle, X, kappa, nodal_mass)
        self.dhat = _positive(dhat, "dhat", "m", "1e-3")
        self.reach = self.dhat

    def _profile(self, d):
        return _barrier_profile(d, self.dhat)

    def _inadmissible_mask(self, d):
        return d <= 0.0

    def _design_curvature(self) -> float:
        return float(_barrier_profile(np.array(0.5 * self.dhat), self.dhat)[2])
