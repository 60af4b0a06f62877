"""The fixed obstacles of contact: a ground plane, a solid sphere, a solid box.

An :class:`Obstacle` is a rigid, fixed solid given by its signed distance
``d(p)`` (m, positive outside) and outward normal; it turns into a contact
potential (:meth:`Obstacle.build`: penalty or barrier) or applies the impulse
response after each step (:meth:`Obstacle.respond`). The potentials, the
methods and how their stiffness is chosen are in :mod:`fem_elastic.physics.contact`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Literal, TypedDict

import numpy as np
from numpy.typing import ArrayLike

from ..discretization.space import Discretization
from ..errors import InvalidParameter
from .contact import (
    _BARRIER_SLOPE_AT_HALF,
    METHODS,
    BarrierContact,
    PenaltyContact,
    _as_points,
    _barrier_profile,
    _positive,
)

if TYPE_CHECKING:
    from typing import Unpack  # Python >= 3.11

__all__ = ["Box", "Ground", "Obstacle", "Sphere"]


class ObstacleOptions(TypedDict, total=False):
    """The keywords every obstacle takes (:class:`Obstacle`'s parameters), for ``**options``."""

    method: Literal["penalty", "barrier", "impulse"]
    stiffness: float | None
    penetration: float
    dhat: float
    restitution: float
    friction: float
    gravity: float | None


# ---------------------------------------------------------------------------------------
# parameter checks
def _vector3(value, name: str, unit: str) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        v = None
    if v is None or v.shape != (3,) or not np.all(np.isfinite(v)):
        raise InvalidParameter(f"{name} must be three finite numbers ({unit}); got {value!r}.")
    return v


# ---------------------------------------------------------------------------------------
class Obstacle:
    """A fixed rigid solid that the body's nodes must stay outside of.

    Subclasses define the geometry (:meth:`signed_distance`, :meth:`normal`);
    this class turns it into a contact Potential (:meth:`build`) or an
    impulse response (:meth:`respond`). See the notes of
    :mod:`fem_elastic.physics.contact` for the methods and how their stiffness
    is chosen.

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

    def __init__(self, *, method: Literal["penalty", "barrier", "impulse"] = "penalty",
                 stiffness: float | None = None, penetration: float = 1e-3, dhat: float = 1e-3,
                 restitution: float = 0.0, friction: float = 0.0,
                 gravity: float | None = None) -> None:
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
    def signed_distance(self, p: ArrayLike) -> np.ndarray:  # pragma: no cover - abstract
        """Signed distance (m) of points ``p`` ``(n, 3)``: > 0 outside, < 0 inside; ``(n,)``."""
        raise NotImplementedError

    def _derivatives(self, p):  # pragma: no cover - abstract
        """(d (n,), n (n, 3), Hd (n, 3, 3) or None where it is zero)."""
        raise NotImplementedError

    def normal(self, p: ArrayLike) -> np.ndarray:
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

    def node_stiffness(self, nodal_mass: ArrayLike, gravity: float | None = None) -> float:
        """The per-node stiffness (N/m) the rules give a body with these nodal masses.

        Penalty: ``k = M |g| / penetration``; barrier:
        ``kappa = M |g| / ((1/2 + ln 2) dhat)``; ``stiffness`` overrides
        either; 0.0 for the impulse method. ``M = sum(nodal_mass)`` (kg).

        Examples
        --------
        >>> Ground(penetration=1e-3).node_stiffness([0.25, 0.25, 0.5])  # 1 kg: 9.81 N / 1 mm
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

    def critical_omega(self, nodal_mass: ArrayLike, gravity: float | None = None) -> float:
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
        >>> round(Ground(penetration=1e-3).critical_omega([0.5, 0.5]), 3)  # sqrt(9810 / 0.5)
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
    def build(self, space: Discretization, nodal_mass: ArrayLike,
              gravity: float | None = None) -> PenaltyContact | BarrierContact | None:
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
          ``M |g| / k`` (the design ``penetration``, see
          :mod:`fem_elastic.physics.contact`), so a
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

    def respond(self, x: ArrayLike, v: ArrayLike,
                nodal_mass: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
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

    def __init__(self, z: float = 0.0, *, normal: ArrayLike = (0.0, 0.0, 1.0),
                 point: ArrayLike | None = None, **options: Unpack[ObstacleOptions]) -> None:
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

    def signed_distance(self, p: ArrayLike) -> np.ndarray:
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

    def __init__(self, center: ArrayLike, radius: float, **options: Unpack[ObstacleOptions]) -> None:
        super().__init__(**options)
        self.center = _vector3(center, "center", "m")
        self.center.setflags(write=False)
        self.radius = _positive(radius, "radius", "m", "0.1")

    def signed_distance(self, p: ArrayLike) -> np.ndarray:
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

    def __init__(self, lower: ArrayLike, upper: ArrayLike,
                 **options: Unpack[ObstacleOptions]) -> None:
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

    def signed_distance(self, p: ArrayLike) -> np.ndarray:
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
