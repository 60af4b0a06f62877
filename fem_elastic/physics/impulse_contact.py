"""Impulse collisions between bodies and of a body with itself: the lecture notes' response.

The notes' collision response (``seeds/004_c7ec6aa2b510111b.txt``,
"Particle-Particle Collisions"; ``seeds/001_08e353bc5290ec50.txt``, "impulse
j = -(1+e) m (v.n) n, restitution 0 <= e <= 1"; ``seeds/003_fa0e65673940b383.txt``,
"Collision Response for Particles", "Collisions - Overshooting"), applied after
each explicit or position-based step:

**Detection.** The broad phase (:mod:`fem_elastic.physics.broad_phase`, a
tree of bounding spheres) gives the candidate pairs; the narrow phase
measures them exactly:

- *vertex-triangle*: every vertex of the model's collision surface against
  every surface triangle that is not incident to it, the closest point ``q``
  of the triangle with barycentric weights ``(w0, w1, w2)``. A pair is in
  contact when ``|p - q| < thickness``. Pairs of one body already closer than
  ``thickness`` in the reference configuration (neighbours across a sharp
  edge of a fine mesh) never collide: they are left out once, at binding, as
  IPC leaves out pairs within ``dhat`` at rest. Pairs of *different* bodies
  (``surface.body``) closer than that at rest are kept, with a
  :class:`RestContactWarning`: they are bodies placed touching, in contact
  from the start. (One ``fe.Model`` is one body, even of disjoint parts.)
- *particle-particle* (:func:`collide_particles`): spheres of radius ``r``
  overlap when ``|x_i - x_j| < r_i + r_j``.

**Response.** A contact is a set of nodes ``a`` with weights ``w_a`` summing
to zero (``(1, -w0, -w1, -w2)`` for vertex-triangle, ``(1, -1)`` for a pair
of particles) and a normal ``n``. Its relative velocity is
``u = sum_a w_a v_a``, ``u_n = u . n``; an impulse ``J`` changes each node's
velocity by ``w_a J / m_a``, so the total momentum changes by ``J sum_a w_a =
0``: momentum is conserved by construction, to round-off. With the effective
inverse mass ``k = sum_a w_a^2 / m_a``, an approaching contact (``u_n < 0``)
gets the normal impulse ``j_n = (1 + e) (-u_n) / k`` (the notes'
frictionless response: ``u_n -> -e u_n``; for two particles it is the notes'
formula) and a tangential impulse opposite the tangential relative velocity
``u_t`` of magnitude ``min(mu j_n, |u_t| / k)``: Coulomb friction, the
tangential relative speed drops by at most ``mu`` times the normal velocity
change and stops (sticks) rather than reverse. Contacts sharing a node are
solved together, with Poisson's restitution (:func:`resolve_impulses`):
first the inelastic (``e = 0``) problem, by projected Jacobi rounds on the
accumulated impulses (each round moves every contact's impulse towards
``u_n = 0`` scaled by ``1 / (the most contacts any of its nodes is in)``,
then clips it to ``j_n >= 0`` and the Coulomb disc, so an overshoot is
pulled back; ``iterations`` rounds at most), then ``e`` times those normal
impulses once more. For one contact that is the formula above; for coupled
contacts it never creates kinetic energy for ``e <= 1`` (a per-contact
target ``-e u_n`` would: coupled elastic contacts gained 1 % in a test).

**Overshoot.** The notes' "quick and dirty" fix, projecting back: after the
velocities, contacts closer than their target distance (``thickness`` for
vertex-triangle, ``r_i + r_j`` for particles) are pushed apart along ``n``
by the same weights over the masses, which keeps the centre of mass where
it was. Held nodes (a model's fixed DOFs) have infinite mass: they take
impulses without moving, and then momentum is not conserved (the support
took the rest), as for the fixed obstacles.

A vertex that crosses a triangle by more than ``thickness`` within one step
is not seen (no continuous detection): choose ``dt`` so that the relative
speed times ``dt`` stays below ``thickness``, or use :class:`fe.IPCContact`,
whose line search is bounded by continuous collision detection. Edge-edge
contacts are not treated; a vertex-triangle test on both sides catches
every face-on collision of closed meshes.
"""

from __future__ import annotations

import logging
import math
import numbers
import warnings

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InvalidParameter
from .broad_phase import BoundingSpheres, sphere_pairs, triangle_spheres

if TYPE_CHECKING:  # for annotations only (the model imports this module)
    from .collision_surface import CollisionSurface
    from .multibody import AnyModel

__all__ = ["ImpulseContact", "BoundImpulseContact", "collide_particles", "closest_point_triangle",
           "reject_impulse_contact", "RestContactWarning"]

log = logging.getLogger(__name__)


class RestContactWarning(UserWarning):
    """Surfaces of different bodies are nearer than the contact thickness at rest."""

#: relative velocities below this fraction of the largest one count as resolved (round-off scale)
_VELOCITY_TOL = 1e-12


def _coefficient(value, name, low, high, example):
    bad = isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value)
    if bad or not low <= float(value) <= high:
        where = f"a finite number >= {low:g}" if math.isinf(high) else f"a number in [{low:g}, {high:g}]"
        raise InvalidParameter(f"{name} must be {where}, got {value!r}{example}.")
    return float(value)


def _check_restitution(e):
    return _coefficient(e, "restitution", 0.0, 1.0, " (0: no bounce, 1: elastic bounce)")


def _check_friction(mu):
    return _coefficient(mu, "friction", 0.0, math.inf, " (a Coulomb coefficient >= 0, e.g. 0.5)")


def _check_iterations(iterations):
    if isinstance(iterations, bool) or not isinstance(iterations, numbers.Integral) or iterations < 1:
        raise InvalidParameter(f"iterations must be an integer >= 1, got {iterations!r}; e.g. iterations=50.")
    return int(iterations)


# -- narrow phase ------------------------------------------------------------------------------
def closest_point_triangle(p, a, b, c):
    """Closest points of triangles to points, and their barycentric weights (vectorised).

    Ericson's region test ("Real-Time Collision Detection", 5.1.5): the
    closest point is a corner, a point of an edge or of the interior.

    Parameters
    ----------
    p, a, b, c : numpy.ndarray
        ``(k, 3)`` points and triangle corners (m).

    Returns
    -------
    q : numpy.ndarray
        ``(k, 3)`` closest points (m), ``q = w0 a + w1 b + w2 c``.
    w : numpy.ndarray
        ``(k, 3)`` barycentric weights, >= 0, summing to 1.
    """
    def dot(u, v):
        return np.einsum("ij,ij->i", u, v)

    ab, ac, ap, bp, cp = b - a, c - a, p - a, p - b, p - c
    d1, d2, d3, d4, d5, d6 = dot(ab, ap), dot(ac, ap), dot(ab, bp), dot(ac, bp), dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    k = p.shape[0]
    w = np.empty((k, 3))
    with np.errstate(divide="ignore", invalid="ignore"):
        total = va + vb + vc
        v_in, w_in = vb / total, vc / total
        w[:] = np.stack([1.0 - v_in - w_in, v_in, w_in], axis=1)  # interior, unless a region below
        regions = [  # later entries take precedence: Ericson's order, reversed
            ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
             lambda t: np.stack([0 * t, 1 - t, t], 1), (d4 - d3) / ((d4 - d3) + (d5 - d6))),
            ((vb <= 0) & (d2 >= 0) & (d6 <= 0), lambda t: np.stack([1 - t, 0 * t, t], 1), d2 / (d2 - d6)),
            ((d6 >= 0) & (d5 <= d6), lambda t: np.stack([0 * t, 0 * t, 1 + 0 * t], 1), np.zeros(k)),
            ((vc <= 0) & (d1 >= 0) & (d3 <= 0), lambda t: np.stack([1 - t, t, 0 * t], 1), d1 / (d1 - d3)),
            ((d3 >= 0) & (d4 <= d3), lambda t: np.stack([0 * t, 1 + 0 * t, 0 * t], 1), np.zeros(k)),
            ((d1 <= 0) & (d2 <= 0), lambda t: np.stack([1 + 0 * t, 0 * t, 0 * t], 1), np.zeros(k)),
        ]
        for mask, weights, t in regions:
            if mask.any():
                w[mask] = weights(t[mask])
    w = np.nan_to_num(w, nan=1.0 / 3.0)  # a degenerate (zero-area) triangle: its centroid
    q = w[:, 0:1] * a + w[:, 1:2] * b + w[:, 2:3] * c
    return q, w


# -- response: impulses over contacts of any number of nodes -----------------------------------
def _shares(idx, wts, inv_m, n_nodes):
    """Per contact: 1 / (the most contacts one of its moving nodes is in) (Jacobi scaling)."""
    moving = (wts != 0.0) & (inv_m[idx] > 0.0)
    count = np.bincount(idx[moving], minlength=n_nodes).astype(float)
    worst = np.where(moving, count[idx], 1.0).max(axis=1)
    return 1.0 / np.maximum(worst, 1.0)


def _node_impulses(idx, wts, J, n_nodes):
    """``(n_nodes, 3)``: the impulse each node receives, ``sum_c w_ac J_c`` (N s)."""
    P = np.zeros((n_nodes, 3))
    np.add.at(P, idx.ravel(), (wts[:, :, None] * J[:, None, :]).reshape(-1, 3))
    return P


def _project_impulses(idx, wts, normal, k_eff, share, V, inv_m, jn, jt, jn_cap, mu, iterations, tol):
    """Projected Jacobi rounds on accumulated impulses (in place on ``V``, ``jn``, ``jt``).

    Each round moves every contact's accumulated normal impulse towards
    ``u_n = 0`` (``jn_cap is None``: the compression phase, ``jn >= 0``) and
    its tangential impulse towards ``u_t = 0`` within the Coulomb disc
    ``|jt| <= mu jn`` (or ``mu jn_cap`` with a fixed normal impulse), by
    ``share`` of the full step, then projects back onto those sets: an
    impulse that overshot is pulled back (never below zero).
    """
    def relative():
        return np.einsum("ks,ksj->kj", wts, V[idx])

    for _ in range(iterations):
        u = relative()
        un = np.einsum("kj,kj->k", u, normal)
        if jn_cap is None:
            jn_new = np.maximum(jn - share * un / k_eff, 0.0)
            cap = mu * jn_new
        else:
            jn_new = jn
            cap = mu * jn_cap
        ut = u - un[:, None] * normal
        jt_new = jt - (share / k_eff)[:, None] * ut
        size = np.linalg.norm(jt_new, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(size > cap, cap / size, 1.0)
        jt_new = jt_new * scale[:, None]
        dJ = (jn_new - jn)[:, None] * normal + (jt_new - jt)
        jn[:], jt[:] = jn_new, jt_new
        V += inv_m[:, None] * _node_impulses(idx, wts, dJ, V.shape[0])
        # converged: no contact's velocity moved by more than round-off in this round
        if (np.linalg.norm(dJ, axis=1) * k_eff).max() <= tol:
            break


def resolve_impulses(idx, wts, normal, V, inv_m, restitution, friction, iterations=50):
    """Apply the module's impulses to the velocities ``V`` (in place); the total impulse (N s).

    Poisson restitution: the compression phase solves the inelastic (``e =
    0``) problem for the impulses ``J0`` (normal ``jn >= 0`` per contact,
    relative normal velocity ``>= 0`` after, Coulomb friction capped per
    contact) by projected Jacobi rounds; the restitution phase adds the
    normal impulses ``e jn`` (with friction again capped at ``mu e jn`` and
    never reversing the sliding). Kinetic energy cannot grow: for a total
    impulse ``s J`` the change is ``s b + s^2 a / 2`` with ``b = J . u^-``
    and ``a = J^T W M^-1 W^T J >= 0``; at the exact inelastic solution ``b =
    -a`` (no work at the contacts after), so ``(1 + e) J0`` changes it by
    ``(e^2 - 1) a / 2 <= 0``. Where the rounds stopped short of that
    solution, the total is scaled down to ``s <= -2 b / a``, which keeps
    the change ``<= 0`` whatever the convergence (momentum is untouched: a
    scaled set of equal and opposite impulses).

    Parameters
    ----------
    idx : numpy.ndarray
        ``(k, s)`` int node indices of each contact.
    wts : numpy.ndarray
        ``(k, s)`` weights, each row summing to 0.
    normal : numpy.ndarray
        ``(k, 3)`` unit normals, pointing from the ``w < 0`` side to the ``w > 0`` side.
    V : numpy.ndarray
        ``(n, 3)`` node velocities (m/s), changed in place.
    inv_m : numpy.ndarray
        ``(n,)`` inverse masses (1/kg), 0 for a held node.
    restitution, friction : float
        ``e`` in [0, 1], Coulomb ``mu >= 0``.
    iterations : int
        Projected Jacobi rounds at most, per phase.

    Returns
    -------
    float
        The sum over contacts of the magnitude of the impulse each received (N s).
    """
    if idx.shape[0] == 0:
        return 0.0
    k_eff = np.einsum("ks,ks->k", wts * wts, inv_m[idx])
    live = k_eff > 0.0
    idx, wts, normal, k_eff = idx[live], wts[live], normal[live], k_eff[live]
    if idx.shape[0] == 0:
        return 0.0
    u0 = np.einsum("ks,ksj->kj", wts, V[idx])
    un0 = np.einsum("kj,kj->k", u0, normal)
    if not (un0 < 0.0).any():  # nothing approaches: no impulse at all
        return 0.0
    share = _shares(idx, wts, inv_m, V.shape[0])
    tol = _VELOCITY_TOL * max(float(np.abs(u0).max()), np.finfo(float).tiny)
    V0 = V.copy()
    k = idx.shape[0]
    jn, jt = np.zeros(k), np.zeros((k, 3))
    # compression: the inelastic problem
    _project_impulses(idx, wts, normal, k_eff, share, V, inv_m, jn, jt, None, friction, iterations, tol)
    J = jn[:, None] * normal + jt
    if restitution > 0.0:  # restitution: e times the compression's normal impulses
        V += inv_m[:, None] * _node_impulses(idx, wts, (restitution * jn)[:, None] * normal, V.shape[0])
        jt2 = np.zeros((k, 3))
        if friction > 0.0:
            _project_impulses(idx, wts, normal, k_eff, share, V, inv_m, restitution * jn, jt2,
                              restitution * jn, friction, iterations, tol)
        J = J + (restitution * jn)[:, None] * normal + jt2
    # the energy guard: dKE(s) = s b + s^2 a / 2 for the total impulse scaled by s
    dV = V - V0
    m = np.where(inv_m > 0.0, 1.0 / np.where(inv_m > 0.0, inv_m, 1.0), 0.0)
    a = float(np.einsum("n,nj,nj->", m, dV, dV))
    b = float(np.einsum("n,nj,nj->", m, V0, dV))
    if a > 0.0 and b + 0.5 * a > 0.0:
        s = max(-2.0 * b / a, 0.0)
        V[:] = V0 + s * dV
        J = s * J
    return float(np.linalg.norm(J, axis=1).sum())


def separate(idx, wts, normal, target, P, inv_m, iterations=10):
    """Push contacts apart along their normals to ``n . sum_a w_a p_a >= target`` (in place).

    The same weights over the masses as the impulses, so the centre of mass
    does not move; Jacobi rounds on the linearised gap.
    """
    if idx.shape[0] == 0:
        return
    k_eff = np.einsum("ks,ks->k", wts * wts, inv_m[idx])
    live = k_eff > 0.0
    idx, wts, normal, target, k_eff = idx[live], wts[live], normal[live], target[live], k_eff[live]
    if idx.shape[0] == 0:
        return
    share = _shares(idx, wts, inv_m, P.shape[0])
    tol = _VELOCITY_TOL * max(float(np.abs(target).max()), np.finfo(float).tiny)
    for _ in range(iterations):
        gap = np.einsum("kj,kj->k", np.einsum("ks,ksj->kj", wts, P[idx]), normal)
        short = target - gap
        act = short > tol
        if not act.any():
            break
        lam = np.where(act, share * short / k_eff, 0.0)
        dP = wts[:, :, None] * (lam[:, None] * normal)[:, None, :] * inv_m[idx][:, :, None]
        np.add.at(P, idx.ravel(), dP.reshape(-1, 3))


# -- particles ---------------------------------------------------------------------------------
def collide_particles(x: ArrayLike, v: ArrayLike, m: ArrayLike, radius: float | ArrayLike,
                      restitution: float = 0.0, friction: float = 0.0,
                      iterations: int = 50) -> tuple[np.ndarray, np.ndarray]:
    """Particle-particle impulse collisions (the notes' response, with radius and friction).

    Particles are spheres of radius ``r``; those that overlap (``|x_i - x_j|
    < r_i + r_j``, found through the bounding-sphere tree, not by testing
    every pair) and approach get equal and opposite impulses along the line
    of centres: relative normal velocity ``u_n -> -e u_n``, Coulomb friction
    on the tangential relative velocity (see the module notes); then the
    overlaps are removed by moving both particles apart in inverse
    proportion to their masses. Momentum and the centre of mass are kept.

    Parameters
    ----------
    x, v : array_like
        ``(n, 3)`` (or flat ``(3 n,)``) positions (m) and velocities (m/s); not modified.
    m : array_like
        ``(n,)`` masses (kg), > 0 (``inf``: an immovable particle).
    radius : float or array_like
        Particle radii (m), > 0.
    restitution : float
        ``e`` in [0, 1].
    friction : float
        Coulomb coefficient ``mu >= 0``.
    iterations : int
        Jacobi rounds at most, for particles in several contacts.

    Returns
    -------
    x, v : numpy.ndarray
        New arrays of the shape given.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.array([[0.0, 0, 0], [0.19, 0, 0]])
    >>> v = np.array([[1.0, 0, 0], [-1.0, 0, 0]])
    >>> x1, v1 = collide_particles(x, v, np.ones(2), 0.1, restitution=0.5)
    >>> v1[:, 0].tolist()   # relative velocity -2 -> 1, momentum 0 kept
    [-0.5, 0.5]
    """
    e, mu = _check_restitution(restitution), _check_friction(friction)
    iterations = _check_iterations(iterations)
    shape = np.shape(x)
    X = np.array(x, dtype=float).reshape(-1, 3)
    V = np.array(v, dtype=float).reshape(-1, 3)
    n = X.shape[0]
    if np.shape(v) != shape or X.size != 3 * n or (len(shape) == 2 and shape[1] != 3):
        raise InvalidParameter(
            f"x and v must both be (n, 3) (or flat 3 n) arrays, got shapes {shape} and {np.shape(v)}."
        )
    mass = np.asarray(m, dtype=float)
    if mass.shape != (n,) or np.isnan(mass).any() or (mass <= 0).any():
        raise InvalidParameter(f"m must be {n} masses > 0 (kg), got {np.shape(m)} / non-positive values.")
    r = np.broadcast_to(np.asarray(radius, dtype=float), (n,))
    if not (np.isfinite(r).all() and (r > 0).all()):
        raise InvalidParameter(f"radius must be finite and > 0 (m), got {radius!r}.")
    if not (np.isfinite(X).all() and np.isfinite(V).all()):
        raise InvalidParameter("x and v must be finite (NaN or inf found).")
    i, j = sphere_pairs(X, r)
    if i.size:
        d = X[i] - X[j]
        dist = np.linalg.norm(d, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            normal = np.where(dist[:, None] > 0.0, d / dist[:, None], np.array([0.0, 0.0, 1.0]))
        idx = np.stack([i, j], axis=1)
        wts = np.tile([1.0, -1.0], (i.size, 1))
        inv_m = 1.0 / mass
        resolve_impulses(idx, wts, normal, V, inv_m, e, mu, iterations)
        separate(idx, wts, normal, r[i] + r[j], X, inv_m, iterations)
    return X.reshape(shape), V.reshape(shape)


# -- the contact of a model --------------------------------------------------------------------
class ImpulseContact:
    """Impulse collisions between the bodies of a model and of each body with itself.

    Pass it as ``fe.Model(..., contact=fe.ImpulseContact(...))``; explicit
    integrators (:class:`fe.SymplecticEuler`, ...), shape matching and the
    position-based methods apply it after every step (the module notes
    describe detection and response). Implicit Euler, Newmark and the static
    solver cannot take impulses: use :class:`fe.IPCContact` there.

    Parameters
    ----------
    restitution : float
        Coefficient of restitution ``e`` in [0, 1]: 0 no bounce, 1 elastic.
    friction : float
        Coulomb friction coefficient ``mu >= 0``.
    thickness : float
        Contact distance (m), > 0: a surface vertex closer than this to a
        triangle is in contact and is pushed out to it. Relative speed times
        dt should stay below it (no continuous detection).
    self_contact : bool
        Also collide surface vertices with triangles of the same body id
        (always the case for one ``fe.Model``, whose parts share body id 0).
    iterations : int
        Jacobi rounds at most per response.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> fe.ImpulseContact(restitution=0.5, friction=0.3, thickness=1e-3)
    fe.ImpulseContact(restitution=0.5, friction=0.3, thickness=0.001)
    """

    kind = "impulse"

    def __init__(self, restitution: float = 0.0, friction: float = 0.0, thickness: float = 1e-3,
                 self_contact: bool = True, iterations: int = 50) -> None:
        self.restitution = _check_restitution(restitution)
        self.friction = _check_friction(friction)
        bad = isinstance(thickness, bool) or not isinstance(thickness, numbers.Real)
        if bad or not math.isfinite(thickness) or thickness <= 0.0:
            raise InvalidParameter(
                f"thickness must be a finite distance > 0 (m), got {thickness!r}; e.g. thickness=1e-3 "
                "(a fraction of the element size, larger than relative speed times dt)."
            )
        self.thickness = float(thickness)
        if not isinstance(self_contact, (bool, np.bool_)):
            raise InvalidParameter(f"self_contact must be True or False, got {self_contact!r}.")
        self.self_contact = bool(self_contact)
        self.iterations = _check_iterations(iterations)

    def __repr__(self) -> str:
        return (f"fe.ImpulseContact(restitution={self.restitution:g}, friction={self.friction:g}, "
                f"thickness={self.thickness:g})")

    def bind(self, model: AnyModel) -> "BoundImpulseContact":
        """The response on ``model``'s collision surface (``model.collision_surface()``)."""
        return BoundImpulseContact(self, model.collision_surface(), model)


class BoundImpulseContact:
    """An :class:`ImpulseContact` on a collision surface: ``respond`` and ``diagnostics``.

    Parameters
    ----------
    settings : ImpulseContact
    surface : CollisionSurface
    model : Model, optional
        Its held DOFs (``model.held_dofs``) make surface vertices immovable.
    """

    kind = "impulse"

    def __init__(self, settings: ImpulseContact, surface: CollisionSurface,
                 model: AnyModel | None = None) -> None:
        self.settings = settings
        self.surface = surface
        self.nodes = np.asarray(surface.vertex_dofs[:, 0] // 3, dtype=np.int64)  # node of each vertex
        held = np.zeros(surface.n_vertices, dtype=bool)
        if model is not None and len(getattr(model, "held_dofs", ())):
            mask = np.zeros(int(model.ndofs), dtype=bool)
            mask[model.held_dofs] = True
            held = mask[surface.vertex_dofs].all(axis=1)
        self.held = held
        #: pairs (vertex, triangle) closer than the thickness at rest: never in contact (keys
        #: ``vertex * n_faces + triangle``); none while they are being found
        self._excluded = np.zeros(0, dtype=np.int64)
        self._excluded = self._rest_exclusions()
        #: total impulse magnitude of the last response (N s)
        self.last_impulse = 0.0
        self.last_contacts = 0
        #: total impulse magnitude of every response since the last diagnostics() read (N s)
        self.impulse_since_read = 0.0

    def __repr__(self) -> str:
        return f"{self.settings!r}.bind(<{self.surface.n_vertices} surface vertices>)"

    # detection ------------------------------------------------------------------------------
    def _candidates(self, P, reach):
        """(vertex, triangle) pairs whose bounding spheres come within ``reach`` (m), filtered."""
        faces = self.surface.faces
        centers, radii = triangle_spheres(P, faces)
        vi, tj = BoundingSpheres(centers, radii).query(P, 0.0, reach)
        keep = ~(faces[tj] == vi[:, None]).any(axis=1)  # a vertex's own incident triangles
        if not self.settings.self_contact:
            body = self.surface.body
            keep &= body[vi] != body[faces[tj, 0]]
        vi, tj = vi[keep], tj[keep]
        if self._excluded.size:
            keep = ~np.isin(vi * len(faces) + tj, self._excluded)
            vi, tj = vi[keep], tj[keep]
        return vi, tj

    def _narrow(self, P, vi, tj):
        """Distances, closest-point weights and contact normals of candidate pairs."""
        tri = P[self.surface.faces[tj]]
        p = P[vi]
        q, w = closest_point_triangle(p, tri[:, 0], tri[:, 1], tri[:, 2])
        d = p - q
        dist = np.linalg.norm(d, axis=1)
        nf = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area2 = np.linalg.norm(nf, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            nf = nf / area2[:, None]
            n = d / dist[:, None]
        interior = (w > 0.0).all(axis=1)
        # inside the triangle's prism: the outward face normal (a vertex that crossed it by less
        # than the thickness is pushed back out); on an edge or a corner: the line to it
        use_face = (interior | (dist <= 1e-12 * np.maximum(np.sqrt(area2), 1e-300))) & (area2 > 0)
        n = np.where(use_face[:, None], nf, n)
        ok = np.isfinite(n).all(axis=1)
        return dist, w, n, ok

    def _rest_exclusions(self):
        """Keys ``vertex * n_faces + triangle`` of the same-body pairs nearer than thickness at rest.

        Only pairs within one body (``surface.body``) are left out: they are
        neighbours across a sharp edge of a fine mesh, in contact with nothing.
        Pairs of *different* bodies nearer than the thickness at rest are bodies
        placed (nearly) touching: leaving them out would let those bodies pass
        through each other, so they stay active and a :class:`RestContactWarning`
        says so. They are not an error, since touching bodies (a stack, a zero
        gap) are a legitimate start: the first response treats them as in
        contact and pushes them apart to ``thickness`` (a jump of at most
        ``thickness`` minus the gap, centre of mass kept).
        """
        rest = self.surface.rest
        vi, tj = self._candidates(rest, self.settings.thickness)
        if vi.size == 0:
            return np.zeros(0, dtype=np.int64)
        dist = self._narrow(rest, vi, tj)[0]
        close = dist < self.settings.thickness
        body = self.surface.body
        same = body[vi] == body[self.surface.faces[tj, 0]]
        across = close & ~same
        if across.any():
            gap = float(dist[across].min())
            msg = (f"fe.ImpulseContact: {int(across.sum())} vertex-triangle pair(s) of different bodies are "
                   f"nearer than thickness = {self.settings.thickness:g} m at rest (smallest gap {gap:.3g} m); "
                   "they are kept in contact and the first response pushes them apart to the thickness. "
                   "To start without that jump, move the bodies apart by more than the thickness or "
                   "choose a smaller thickness.")
            log.warning(msg)
            warnings.warn(msg, RestContactWarning, stacklevel=4)
        close &= same
        return np.unique(vi[close] * len(self.surface.faces) + tj[close])

    def contacts(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                               np.ndarray]:
        """The vertex-triangle contacts at ``x``: ``(vertex, triangle, distance (m), weights, normal)``."""
        P = self.surface.positions(x)
        vi, tj = self._candidates(P, self.settings.thickness)
        dist, w, n, ok = self._narrow(P, vi, tj)
        on = ok & (dist < self.settings.thickness)
        return vi[on], tj[on], dist[on], w[on], n[on]

    # response -------------------------------------------------------------------------------
    def respond(self, x: np.ndarray, v: np.ndarray,
                mass: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Impulses and separation of the surface contacts at ``x`` (module notes); new ``(x, v)``.

        Parameters
        ----------
        x, v : numpy.ndarray
            ``(ndofs,)`` positions (m) and velocities (m/s); not modified.
        mass : numpy.ndarray
            Lumped mass per node ``(nnodes,)`` or per DOF ``(ndofs,)`` (kg).
        """
        x = np.array(x, dtype=float)
        v = np.array(v, dtype=float)
        mass = np.asarray(mass, dtype=float)
        node_mass = mass[0::3] if mass.size == x.size else mass
        if node_mass.size * 3 != x.size:
            raise InvalidParameter(
                f"mass must be the lumped mass per node ({x.size // 3}) or per DOF ({x.size}), "
                f"got {mass.size} values."
            )
        vi, tj, dist, w, n = self.contacts(x)
        self.last_contacts = int(vi.size)
        self.last_impulse = 0.0
        if vi.size == 0:
            return x, v
        m_s = node_mass[self.nodes]
        inv_m = np.where(self.held | ~(m_s > 0), 0.0, 1.0 / np.where(m_s > 0, m_s, 1.0))
        idx = np.concatenate([vi[:, None], self.surface.faces[tj]], axis=1)
        wts = np.concatenate([np.ones((vi.size, 1)), -w], axis=1)
        P = self.surface.positions(x)  # a gather: a new array, moved in place below
        V = v[self.surface.vertex_dofs]
        s = self.settings
        self.last_impulse = resolve_impulses(idx, wts, n, V, inv_m, s.restitution, s.friction, s.iterations)
        self.impulse_since_read += self.last_impulse
        separate(idx, wts, n, np.full(vi.size, s.thickness), P, inv_m, s.iterations)
        x[self.surface.vertex_dofs] = P
        v[self.surface.vertex_dofs] = V
        return x, v

    # diagnostics ----------------------------------------------------------------------------
    def min_distance(self, x: np.ndarray, reach: float | None = None) -> float:
        """Smallest vertex-triangle distance (m) between parts of the surface that may collide.

        Parameters
        ----------
        x : numpy.ndarray
            ``(ndofs,)`` positions (m).
        reach : float or None
            Only pairs nearer than this are searched (m), ``inf`` returned when
            there is none. None: no limit; the tree is searched with a reach
            growing fourfold from ``thickness`` until a pair is found (the
            cost grows with the reach: many candidates far from contact).
        """
        P = self.surface.positions(x)
        span = float(np.ptp(P, axis=0).max()) if P.size else 0.0
        limit = math.inf if reach is None else float(reach)
        r = min(self.settings.thickness, limit)
        best = math.inf
        while True:
            vi, tj = self._candidates(P, r)
            if vi.size:
                best = float(self._narrow(P, vi, tj)[0].min())
                if best <= r:  # every pair nearer than r is among the candidates
                    return best
            if r >= limit or r > 2.0 * span + self.settings.thickness:
                return best if best <= limit else math.inf
            r = min(4.0 * r, limit)

    def has_intersections(self, x: np.ndarray) -> bool:
        """Whether the surface at ``x`` intersects itself: an edge crossing a triangle.

        Every surface edge against the triangles that do not share a vertex
        with it (candidates from the bounding-sphere tree: the edge's sphere
        about its midpoint against the triangles'), by the segment-triangle
        test of Moller and Trumbore; two closed surfaces that intersect have
        an edge of one through a face of the other (a touching, coplanar or
        edge-on-edge configuration of measure zero may be missed).
        """
        P = self.surface.positions(x)
        edges, faces = self.surface.edges, self.surface.faces
        if edges.shape[0] == 0 or faces.shape[0] == 0:
            return False
        a, b = P[edges[:, 0]], P[edges[:, 1]]
        centers, radii = triangle_spheres(P, faces)
        ei, tj = BoundingSpheres(centers, radii).query(0.5 * (a + b), 0.5 * np.linalg.norm(b - a, axis=1))
        tri = faces[tj]
        shared = (tri == edges[ei, 0][:, None]).any(axis=1) | (tri == edges[ei, 1][:, None]).any(axis=1)
        ei, tj = ei[~shared], tj[~shared]
        if ei.size == 0:
            return False
        o, d = P[edges[ei, 0]], P[edges[ei, 1]] - P[edges[ei, 0]]
        t0, t1, t2 = (P[faces[tj, k]] for k in range(3))
        e1, e2 = t1 - t0, t2 - t0
        h = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, h)
        with np.errstate(divide="ignore", invalid="ignore"):
            f = 1.0 / det
            s = o - t0
            u = f * np.einsum("ij,ij->i", s, h)
            q = np.cross(s, e1)
            w = f * np.einsum("ij,ij->i", d, q)
            t = f * np.einsum("ij,ij->i", e2, q)
            hit = (np.abs(det) > 0.0) & (u >= 0.0) & (w >= 0.0) & (u + w <= 1.0) & (t >= 0.0) & (t <= 1.0)
        return bool(hit.any())

    def diagnostics(self, x: np.ndarray) -> dict[str, Any]:
        """Contact state at ``x``.

        Returns
        -------
        dict
            ``min_distance`` (m): the smallest vertex-triangle distance within
            ``10 * thickness`` (:meth:`min_distance` with that reach; ``inf``
            when no pair is that close, as IPC's is within ``dhat``);
            ``active_contacts``: the vertex-triangle pairs closer than
            ``thickness``; ``contact_impulse`` (N s): the summed magnitude of the
            impulses of every :meth:`respond` since the previous call of this
            method (all the sub-steps of an explicit step; the sum restarts at
            each call); ``contact_force``: ``nan``, since an impulse acts in no
            time and :meth:`respond` is not told the step it ends (the average
            force over a step of ``h`` is ``contact_impulse / h``).
        """
        P = self.surface.positions(x)
        reach = 10.0 * self.settings.thickness
        vi, tj = self._candidates(P, reach)
        dist, _, _, ok = self._narrow(P, vi, tj)
        dist = dist[ok]
        near = dist[dist < reach]  # all the pairs within the reach are among the candidates
        return {
            "min_distance": float(near.min()) if near.size else math.inf,
            "active_contacts": int(np.count_nonzero(dist < self.settings.thickness)),
            "contact_force": math.nan,
            "contact_impulse": self._take_impulse(),
        }

    def _take_impulse(self) -> float:
        """The impulse summed since the last read (N s); the sum restarts from zero."""
        total, self.impulse_since_read = float(self.impulse_since_read), 0.0
        return total

    def reset_impulse(self) -> None:
        """Restart the impulse sum of :meth:`diagnostics` (at the start of a run)."""
        self.impulse_since_read = 0.0


def reject_impulse_contact(model, who: str) -> None:
    """:class:`InvalidParameter` if ``model`` has an impulse contact, which ``who`` cannot apply."""
    bound = getattr(model, "contact", None)
    if bound is not None and getattr(bound, "kind", None) == "impulse":
        raise InvalidParameter(
            f"{who} cannot apply fe.ImpulseContact: impulses act between explicit or position-based "
            "steps, not inside an implicit solve. Use contact=fe.IPCContact(dhat=...) with this "
            "solver, or an explicit integrator (fe.SymplecticEuler()), fe.XPBD() or "
            "fe.ShapeMatching() with the impulse contact."
        )
