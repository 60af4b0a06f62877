"""Contact with fixed obstacles: a ground plane, a solid sphere, a solid box.

An :class:`Obstacle` is a rigid, fixed solid described by its signed distance
``d(p)`` (m): positive outside, zero on the surface, negative inside, with the
outward unit normal ``n(p) = grad d``. Every node of the body (the P1
vertices, and for P2 tets the edge nodes too) is kept outside it, in one of
three ways, chosen by ``method``:

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
    No potential: after each step the integrator calls :meth:`Obstacle.respond`,
    which projects penetrating nodes back onto the surface and reflects their
    normal velocity with a coefficient of restitution ``e``, with Coulomb
    friction on the tangential velocity (the particle-plane collision response
    of the lecture notes, ``v+ = v- + j / m`` with ``j = -(1 + e) m (v- . n) n``).

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
``dt < 2 / omega``. :meth:`Obstacle.critical_omega` returns the largest
``omega_i``; since the contact adds a positive semi-definite term to the
stiffness, ``sqrt(omega_body^2 + omega_contact^2)`` bounds the largest
frequency of the whole system (Weyl's inequality) for a stable-step estimate.

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
    "Obstacle",
    "Ground",
    "Sphere",
    "Box",
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


def _vector3(value, name: str, unit: str) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        v = None
    if v is None or v.shape != (3,) or not np.all(np.isfinite(v)):
        raise InvalidParameter(f"{name} must be three finite numbers ({unit}); got {value!r}.")
    return v


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
    obstacle : Obstacle
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

    def linearize(self, x: np.ndarray, project: bool = False):
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
    obstacle : Obstacle
    X : numpy.ndarray
        ``(ndofs,)`` DOF positions (m); only their number is used.
    stiffness : float or numpy.ndarray
        Per-node spring stiffness ``k_i`` (N/m), scalar or ``(nnodes,)``.
    nodal_mass : numpy.ndarray, optional
        ``(nnodes,)`` (kg), for :meth:`critical_omega`.

    Examples
    --------
    >>> import numpy as np
    >>> import fem_elastic.physics.contact as fc
    >>> pot = fc.PenaltyContact(fc.Ground(), np.zeros(6), stiffness=100.0)
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
    obstacle : Obstacle
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
    >>> import fem_elastic.physics.contact as fc
    >>> pot = fc.BarrierContact(fc.Ground(), np.zeros(3), kappa=1.0, dhat=1e-3)
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


# ---------------------------------------------------------------------------------------
class Obstacle:
    """A fixed rigid solid that the body's nodes must stay outside of.

    Subclasses define the geometry (:meth:`signed_distance`, :meth:`normal`);
    this class turns it into a contact Potential (:meth:`build`) or an
    impulse response (:meth:`respond`). See the module notes for the methods
    and how their stiffness is chosen.

    The parameters are keyword-only and shared by :class:`Ground`,
    :class:`Sphere` and :class:`Box`.

    Parameters
    ----------
    method : {"penalty", "barrier", "impulse"}
        How contact is enforced.
    stiffness : float or None
        Per-node stiffness (N/m) overriding the rule: ``k`` for the penalty,
        ``kappa`` for the barrier.
    penetration : float
        Penalty: the design resting penetration (m), an upper bound on any
        node's penetration for a body resting under its weight ``M |g|``.
    dhat : float
        Barrier: activation distance (m); loaded nodes rest at
        ``dhat / 2 <= d < dhat``.
    restitution : float
        Impulse: coefficient of restitution ``e`` in [0, 1] (0 plastic, 1 elastic).
    friction : float
        Impulse: Coulomb friction coefficient ``mu >= 0``.
    gravity : float or None
        Magnitude of the acceleration (m/s^2) whose weight the penalty and
        barrier stiffness are designed to carry. None (default): the model's
        ``|g|``, or 9.81 when the model has no gravity.

    Examples
    --------
    >>> import numpy as np
    >>> obstacles = [Ground(), Sphere((0, 0, -1), 1.0), Box((-1, -1, -1), (1, 1, 0))]
    >>> [float(o.signed_distance(np.array([[0.0, 0.0, 0.5]]))[0]) for o in obstacles]  # m
    [0.5, 0.5, 0.5]
    """

    def __init__(self, *, method="penalty", stiffness=None, penetration=1e-3, dhat=1e-3,
                 restitution=0.0, friction=0.0, gravity=None):
        if not isinstance(method, str) or method not in METHODS:
            raise InvalidParameter(
                f"method must be one of {METHODS!r}, got {method!r}: 'penalty' (springs, "
                "small penetration), 'barrier' (log barrier, never penetrates, implicit "
                "integrators) or 'impulse' (velocity response after each step)."
            )
        self.method = method
        self.stiffness = None if stiffness is None else _positive(stiffness, "stiffness", "N/m", "1e4")
        self.penetration = _positive(penetration, "penetration", "m", "1e-3")
        self.dhat = _positive(dhat, "dhat", "m", "1e-3")
        self.gravity = None if gravity is None else _positive(gravity, "gravity", "m/s^2", "9.81")
        if isinstance(restitution, bool) or not isinstance(restitution, (int, float, np.number)) \
                or not 0.0 <= float(restitution) <= 1.0:
            raise InvalidParameter(
                f"restitution must be a number in [0, 1] (0: no bounce, 1: elastic bounce), "
                f"got {restitution!r}."
            )
        if isinstance(friction, bool) or not isinstance(friction, (int, float, np.number)) \
                or not (math.isfinite(float(friction)) and float(friction) >= 0.0):
            raise InvalidParameter(
                f"friction must be a finite Coulomb coefficient >= 0 (e.g. 0.5), got {friction!r}."
            )
        self.restitution = float(restitution)
        self.friction = float(friction)
        if method != "impulse" and (self.restitution != 0.0 or self.friction != 0.0):
            raise InvalidParameter(
                f"restitution and friction are only built for method='impulse'; the {method} "
                "contact is frictionless and its bounce comes from the integrator and damping. "
                "Pass method='impulse', or leave restitution=0 and friction=0."
            )

    # geometry: subclasses ----------------------------------------------------------------
    def signed_distance(self, p) -> np.ndarray:  # pragma: no cover - abstract
        """Signed distance (m) of points ``p`` ``(n, 3)``: > 0 outside, < 0 inside; ``(n,)``."""
        raise NotImplementedError

    def _derivatives(self, p):  # pragma: no cover - abstract
        """(d (n,), n (n, 3), Hd (n, 3, 3) or None where it is zero)."""
        raise NotImplementedError

    def normal(self, p) -> np.ndarray:
        """Outward unit normals ``grad d`` at points ``p`` ``(n, 3)``, shape ``(n, 3)``."""
        return self._derivatives(_as_points(p))[1]

    # stiffness rules ----------------------------------------------------------------------
    def _check_mass(self, nodal_mass, nnodes=None) -> np.ndarray:
        m = np.asarray(nodal_mass, dtype=float)
        if m.ndim != 1 or (nnodes is not None and m.size != nnodes):
            raise InvalidParameter(
                f"nodal_mass must have one entry per node ({nnodes}), got shape {m.shape}; "
                "pass model.lumped_mass[0::3]."
            )
        if not np.all(np.isfinite(m)) or np.any(m <= 0):
            raise InvalidParameter("nodal_mass must be finite and > 0 kg at every node.")
        return m

    def _g(self, gravity) -> float:
        """|g| (m/s^2) of the stiffness rule: the obstacle's own, else the model's, else 9.81."""
        if self.gravity is not None:
            return self.gravity
        return float(gravity) if gravity else 9.81

    def node_stiffness(self, nodal_mass, gravity=None) -> float:
        """The per-node stiffness (N/m) the rules give a body with these nodal masses.

        Penalty: ``k = M |g| / penetration``; barrier:
        ``kappa = M |g| / ((1/2 + ln 2) dhat)``; ``stiffness`` overrides
        either; 0.0 for the impulse method. ``M = sum(nodal_mass)`` (kg).

        Examples
        --------
        >>> import fem_elastic.physics.contact as fc
        >>> fc.Ground(penetration=1e-3).node_stiffness([0.25, 0.25, 0.5])  # 1 kg: 9.81 N / 1 mm
        9810.0
        """
        M = float(self._check_mass(nodal_mass).sum())
        if self.method == "impulse":
            return 0.0
        if self.stiffness is not None:
            return self.stiffness
        if self.method == "penalty":
            return M * self._g(gravity) / self.penetration
        return M * self._g(gravity) / (_BARRIER_SLOPE_AT_HALF * self.dhat)

    def critical_omega(self, nodal_mass, gravity=None) -> float:
        """Largest angular frequency (rad/s) of a node on its contact spring.

        ``max_i sqrt(k / m_i)`` for the penalty (the barrier: its stiffness at
        the design gap ``dhat / 2``), 0.0 for the impulse method. An explicit
        scheme such as symplectic Euler needs ``dt < 2 / omega`` with
        ``omega^2 <= omega_body^2 + critical_omega^2``.

        Parameters
        ----------
        nodal_mass : array_like
            ``(nnodes,)`` lumped mass per node (kg).

        Examples
        --------
        >>> import fem_elastic.physics.contact as fc
        >>> round(fc.Ground(penetration=1e-3).critical_omega([0.5, 0.5]), 3)  # sqrt(9810 / 0.5)
        140.071
        """
        m = self._check_mass(nodal_mass)
        if self.method == "impulse":
            return 0.0
        c = 1.0
        if self.method == "barrier":
            c = float(_barrier_profile(np.array(0.5 * self.dhat), self.dhat)[2])
        return float(np.sqrt(c * self.node_stiffness(m, gravity) / m.min()))

    # the two responses ---------------------------------------------------------------------
    def build(self, space, nodal_mass, gravity=None):
        """The contact Potential on every node of ``space``, or None for ``method="impulse"``.

        Parameters
        ----------
        space : Discretization
            The body's finite element space (its ``X``, ``(ndofs,)``, m).
        nodal_mass : array_like
            ``(nnodes,)`` lumped mass per node (kg), e.g. ``model.lumped_mass[0::3]``.
        gravity : float, optional
            The model's ``|g|`` (m/s^2), used unless the obstacle was given its own.

        Returns
        -------
        PenaltyContact, BarrierContact or None

        Raises
        ------
        InvalidParameter
            For the barrier, when a node of the reference configuration is not
            strictly outside the obstacle (its energy would be +inf); for the
            penalty and the impulse response, when one starts deep inside it
            (see :meth:`_check_start`).

        Examples
        --------
        >>> import fem_elastic as fe
        >>> from fem_elastic.discretization import Discretization
        >>> from fem_elastic.discretization.mass import lumped_mass
        >>> space = Discretization(fe.beam_mesh(0.1, 0.1, 0.1, cells=(1, 1, 1)), order=1)
        >>> m = lumped_mass(space, density=1000.0)[0::3]  # 1 kg in all
        >>> pot = Ground(z=1e-4).build(space, m)  # the bottom face 0.1 mm below the plane
        >>> float(pot.contact_force(space.X)[2::3].sum().round(6))  # N: 4 nodes * 9810 N/m * 0.1 mm
        3.924
        """
        X = np.asarray(space.X, dtype=float)
        m = self._check_mass(nodal_mass, X.size // 3)
        d = self.signed_distance(X.reshape(-1, 3))
        if self.method != "barrier":
            self._check_start(d, space, m, gravity)
        if self.method == "impulse":
            return None
        k = self.node_stiffness(m, gravity)
        if self.method == "penalty":
            return PenaltyContact(self, X, k, nodal_mass=m)
        if np.any(d <= 0.0):
            bad = np.flatnonzero(d <= 0.0)
            raise InvalidParameter(
                f"{bad.size} node(s) of the reference configuration (first: node {bad[0]}, "
                f"signed distance {d[bad[0]]:.3e} m) are not strictly outside {self!r}, where "
                "the barrier energy is +inf. Move the mesh (mesh.translated(...)) or the "
                "obstacle so the body starts with a gap, e.g. dhat / 2."
            )
        return BarrierContact(self, X, k, self.dhat, nodal_mass=m)

    def _check_start(self, d, space, nodal_mass, gravity) -> None:
        """:class:`InvalidParameter` when the reference configuration starts deep inside the obstacle.

        A body that starts through an obstacle is a placement mistake (a
        ground above the body's bottom, a sphere around it), and neither
        method resolves it as contact:

        - the penalty springs push a node at depth ``delta`` with
          ``k delta``; a body resting under its weight has no node deeper than
          ``M |g| / k`` (the design ``penetration``, see the module notes), so a
          node ten times deeper pushes with ten times the body's whole weight
          and its spring stores ``50 M |g| penetration``: the body is thrown
          out (a 0.1 m beam started 5 cm through a 1 mm ground flies 0.6 m up).
          Ten keeps every start a resting or slightly pressed body could have.
        - the impulse response projects each penetrating node onto the
          surface at the first step, straining its elements by about
          ``delta / edge``; beyond 1 % of the shortest edge that is a crush
          of the elements (energy put in from nowhere), not a contact.
        """
        if d.size == 0 or d.min() >= 0.0:
            return
        depth = -float(d.min())
        if self.method == "penalty":
            rest = float(nodal_mass.sum()) * self._g(gravity) / self.node_stiffness(nodal_mass, gravity)
            limit = 10.0 * rest
            scale = (f"10 x the {rest:.3g} m a node of the body at rest under its weight can reach: "
                     "the contact springs would throw the body out")
        else:
            mesh = space.mesh
            edges = np.asarray(mesh.edges)
            lengths = np.linalg.norm(mesh.p[:, edges[0]] - mesh.p[:, edges[1]], axis=0)
            limit = 0.01 * float(lengths.min())
            scale = ("1 % of the shortest edge: the first step would project those nodes onto the "
                     "surface and crush their elements")
        if depth <= limit:
            return
        bad = np.flatnonzero(-d > limit)
        raise InvalidParameter(
            f"{bad.size} node(s) of the reference configuration start inside {self!r} (node "
            f"{bad[np.argmin(d[bad])]} is {depth:.3g} m deep), deeper than {limit:.3g} m, "
            f"{scale}. Move the mesh (mesh.translated(...)) or the obstacle so the body starts "
            "outside it or just touching it."
        )

    def respond(self, x, v, nodal_mass=None):
        """Impulse response of penetrating nodes (``method="impulse"``).

        For every node with ``d < 0``: the position is projected onto the
        surface (``p - d n``); if it moves inward (``v . n < 0``) the normal
        velocity becomes ``-e (v . n)``, and Coulomb friction removes up to
        ``mu (1 + e) |v . n|`` of the tangential speed (the friction impulse is
        at most ``mu`` times the normal impulse ``(1 + e) m |v . n|``), never
        reversing it. Other nodes are untouched. For the penalty and barrier
        methods this returns copies of ``x`` and ``v``.

        Parameters
        ----------
        x, v : numpy.ndarray
            ``(ndofs,)`` positions (m) and velocities (m/s); not modified.
        nodal_mass : array_like, optional
            ``(nnodes,)`` (kg). Each node's response is independent of its
            mass (the impulse is ``m dv``); it is checked for shape only.

        Returns
        -------
        x, v : numpy.ndarray
            New arrays.

        Examples
        --------
        >>> import numpy as np
        >>> g = Ground(method="impulse", restitution=0.5, friction=0.25)
        >>> x, v = g.respond(np.array([0.0, 0.0, -0.01]), np.array([1.0, 0.0, -2.0]))
        >>> x.tolist(), v.tolist()  # back on the plane; v_n: -2 -> 1; v_t: 1 - 0.25 * 1.5 * 2
        ([0.0, 0.0, 0.0], [0.25, 0.0, 1.0])
        """
        x = np.array(x, dtype=float)
        v = np.array(v, dtype=float)
        if x.shape != v.shape or x.ndim != 1 or x.size % 3:
            raise InvalidParameter(
                f"x and v must be flat DOF vectors of equal length 3 * nnodes, got shapes "
                f"{x.shape} and {v.shape}."
            )
        if nodal_mass is not None:
            self._check_mass(nodal_mass, x.size // 3)
        if self.method != "impulse":
            return x, v
        p, vel = x.reshape(-1, 3), v.reshape(-1, 3)  # views into the new arrays
        d = self.signed_distance(p)
        act = np.flatnonzero(d < 0.0)
        if act.size == 0:
            return x, v
        da, n, _ = self._derivatives(p[act])
        p[act] -= da[:, None] * n
        va = vel[act]
        vn = np.einsum("ij,ij->i", va, n)
        inward = vn < 0.0
        vt = va - vn[:, None] * n
        speed_t = np.linalg.norm(vt, axis=1)
        dv_t = self.friction * (1.0 + self.restitution) * np.abs(vn)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(speed_t > dv_t, 1.0 - dv_t / speed_t, 0.0)
        new = scale[:, None] * vt - self.restitution * vn[:, None] * n
        vel[act] = np.where(inward[:, None], new, va)
        return x, v

    def _params_repr(self) -> str:
        s = f"method={self.method!r}"
        if self.method == "penalty":
            s += f", penetration={self.penetration!r}"
        elif self.method == "barrier":
            s += f", dhat={self.dhat!r}"
        else:
            s += f", restitution={self.restitution!r}, friction={self.friction!r}"
        if self.stiffness is not None and self.method != "impulse":
            s += f", stiffness={self.stiffness!r}"
        return s


class Ground(Obstacle):
    """The half-space below a plane: the ground.

    The plane passes through ``point`` (default ``(0, 0, z)``) with outward
    (upward) normal ``normal``; ``d(p) = (p - point) . normal``.

    Parameters
    ----------
    z : float
        Height of the plane on the z axis (m) when ``point`` is not given.
    normal : array_like
        Outward normal, normalised inside; default ``(0, 0, 1)``.
    point : array_like, optional
        A point of the plane (m), instead of ``z``.
    **options
        ``method``, ``stiffness``, ``penetration``, ``dhat``, ``restitution``,
        ``friction``, ``gravity``: see :class:`Obstacle`.

    Examples
    --------
    >>> import numpy as np
    >>> g = Ground(z=1.0, normal=(0, 0, 2))
    >>> g.signed_distance(np.array([[0.0, 0.0, 3.0], [5.0, 1.0, 0.5]])).tolist()  # m
    [2.0, -0.5]
    >>> g
    Ground(point=(0.0, 0.0, 1.0), normal=(0.0, 0.0, 1.0), method='penalty', penetration=0.001)
    """

    def __init__(self, z=0.0, *, normal=(0.0, 0.0, 1.0), point=None, **options):
        super().__init__(**options)
        nrm = _vector3(normal, "normal", "a direction")
        length = float(np.linalg.norm(nrm))
        if length == 0.0:
            raise InvalidParameter(
                "normal must be a nonzero direction (the outward, upward normal of the "
                "ground), e.g. normal=(0, 0, 1)."
            )
        if point is None:
            if isinstance(z, bool) or not isinstance(z, (int, float, np.number)) \
                    or not math.isfinite(z):
                raise InvalidParameter(f"z must be a finite height (m), got {z!r}.")
            point = (0.0, 0.0, float(z))
        elif z != 0.0:
            raise InvalidParameter("give the plane by z or by point, not both.")
        self.point = _vector3(point, "point", "m")
        self.unit_normal = nrm / length
        for arr in (self.point, self.unit_normal):
            arr.setflags(write=False)

    def signed_distance(self, p) -> np.ndarray:
        return (_as_points(p) - self.point) @ self.unit_normal

    def _derivatives(self, p):
        d = (p - self.point) @ self.unit_normal
        return d, np.broadcast_to(self.unit_normal, p.shape).copy(), None

    def __repr__(self):
        pt = tuple(float(c) for c in self.point)
        nr = tuple(float(c) for c in self.unit_normal)
        return f"Ground(point={pt}, normal={nr}, {self._params_repr()})"


class Sphere(Obstacle):
    """A fixed solid ball: ``d(p) = |p - center| - radius``.

    Parameters
    ----------
    center : array_like
        Centre (m).
    radius : float
        Radius (m), > 0.
    **options
        ``method``, ``stiffness``, ``penetration``, ``dhat``, ``restitution``,
        ``friction``, ``gravity``: see :class:`Obstacle`.

    Examples
    --------
    >>> import numpy as np
    >>> s = Sphere((0, 0, 0), 1.0)
    >>> s.signed_distance(np.array([[0.0, 2.0, 0.0], [0.5, 0.0, 0.0]])).tolist()  # m
    [1.0, -0.5]
    >>> s.normal(np.array([[0.0, 2.0, 0.0]])).tolist()
    [[0.0, 1.0, 0.0]]
    """

    def __init__(self, center, radius, **options):
        super().__init__(**options)
        self.center = _vector3(center, "center", "m")
        self.center.setflags(write=False)
        self.radius = _positive(radius, "radius", "m", "0.1")

    def signed_distance(self, p) -> np.ndarray:
        r = _as_points(p) - self.center
        return np.sqrt(np.einsum("ij,ij->i", r, r)) - self.radius

    def _derivatives(self, p):
        r = p - self.center
        rho = np.linalg.norm(r, axis=1)
        at_center = rho == 0.0
        safe = np.where(at_center, 1.0, rho)
        n = r / safe[:, None]
        n[at_center] = (0.0, 0.0, 1.0)  # any direction leads out of the centre
        P = np.eye(3) - n[:, :, None] * n[:, None, :]
        Hd = np.where(at_center[:, None, None], 0.0, P / safe[:, None, None])
        return rho - self.radius, n, Hd

    def __repr__(self):
        c = tuple(float(v) for v in self.center)
        return f"Sphere(center={c}, radius={self.radius!r}, {self._params_repr()})"


class Box(Obstacle):
    """A fixed solid axis-aligned box between corners ``lower`` and ``upper``.

    Outside, ``d`` is the distance to the nearest point of the box (its face,
    edge or corner); inside, minus the distance to the nearest face.

    Parameters
    ----------
    lower, upper : array_like
        Opposite corners (m), ``lower < upper`` in every coordinate.
    **options
        ``method``, ``stiffness``, ``penetration``, ``dhat``, ``restitution``,
        ``friction``, ``gravity``: see :class:`Obstacle`.

    Examples
    --------
    >>> import numpy as np
    >>> b = Box((0, 0, 0), (1, 1, 1))
    >>> b.signed_distance(np.array([[2.0, 0.5, 0.5], [2.0, 2.0, 0.5], [0.5, 0.5, 0.9]])).round(6).tolist()
    [1.0, 1.414214, -0.1]
    >>> b.normal(np.array([[0.5, 0.5, 0.9]])).tolist()  # out through the nearest face
    [[0.0, 0.0, 1.0]]
    """

    def __init__(self, lower, upper, **options):
        super().__init__(**options)
        lo = _vector3(lower, "lower", "m")
        hi = _vector3(upper, "upper", "m")
        if np.any(lo >= hi):
            raise InvalidParameter(
                f"the box needs lower < upper in every coordinate, got lower={lo.tolist()} and "
                f"upper={hi.tolist()}; swap them or give the box a positive size."
            )
        self.lower, self.upper = lo, hi
        for arr in (lo, hi):
            arr.setflags(write=False)

    def signed_distance(self, p) -> np.ndarray:
        p = _as_points(p)
        below, above = self.lower - p, p - self.upper  # > 0 outside a slab, (n, 3)
        m = np.maximum(below, above)
        r = np.maximum(m, 0.0)
        outside = np.sqrt(np.einsum("ij,ij->i", r, r))
        # minus the distance to the nearest face (columns: numpy's axis-1 max is slow on 3 columns)
        inside = np.maximum(np.maximum(m[:, 0], m[:, 1]), m[:, 2])
        return np.where(outside > 0.0, outside, inside)

    def _derivatives(self, p):
        npts = p.shape[0]
        r = p - np.clip(p, self.lower, self.upper)
        dist = np.linalg.norm(r, axis=1)
        out = dist > 0.0
        d = np.empty(npts)
        n = np.zeros((npts, 3))
        Hd = np.zeros((npts, 3, 3))
        # outside: d = |r| over the coordinates outside the slabs, Hd = (P_out - n n^T) / d
        if out.any():
            ro, do = r[out], dist[out]
            no = ro / do[:, None]
            d[out], n[out] = do, no
            P = np.zeros((ro.shape[0], 3, 3))
            idx = np.arange(3)
            P[:, idx, idx] = (ro != 0.0)
            Hd[out] = (P - no[:, :, None] * no[:, None, :]) / do[:, None, None]
        # inside (or on the surface): minus the distance to the nearest face, Hd = 0
        ins = ~out
        if ins.any():
            pi = p[ins]
            gaps = np.concatenate([pi - self.lower, self.upper - pi], axis=1)  # (m, 6)
            face = gaps.argmin(axis=1)
            d[ins] = -gaps[np.arange(pi.shape[0]), face]
            ni = np.zeros((pi.shape[0], 3))
            ni[np.arange(pi.shape[0]), face % 3] = np.where(face < 3, -1.0, 1.0)
            n[ins] = ni
        return d, n, Hd

    def __repr__(self):
        lo = tuple(float(v) for v in self.lower)
        hi = tuple(float(v) for v in self.upper)
        return f"Box(lower={lo}, upper={hi}, {self._params_repr()})"
