"""The position-based loop shared by PBD and XPBD: predict, project, update, correct.

One step of ``h`` from ``(x, v)`` at time t (the lecture notes' "Position Based
Integration", ``seeds/002_942bade499ba35f4.txt``; Mueller et al. 2007, Algorithm 1):

1. **prediction** ``p = x + h v*``, ``v* = v + h M^-1 f_ext``: the dead loads
   of the model (gravity, tractions) act as external forces; the body's
   elastic energy does not (the constraints are the elasticity). The notes
   list the external forces under velocity correction; putting them in the
   prediction, as Mueller et al.'s Algorithm 1 does, lets the constraints
   carry the load within the step it is applied in. Held DOFs
   (fixed, prescribed, driven: ``model.constraints(t + h)``) are put at
   their prescription and get zero inverse mass, so no projection moves them.
2. **position correction**: ``iterations`` sweeps over the constraint sets
   (Gauss-Seidel in colour order, or Jacobi; see
   :mod:`~fem_elastic.dynamics.position_based.constraints`), each followed by
   the projection of the vertices that are inside an obstacle onto its surface
   (``p - d n``, the obstacle's signed distance d and normal n: every obstacle
   of the model acts as a hard contact constraint here, whatever its
   ``method``).
3. **velocity update** ``u = (p - x) / h``.
4. **velocity correction**: the integrator's ``damping`` (Mueller et al. 2007,
   section 3.5: each velocity moves by the fraction ``damping`` towards the
   body's rigid motion ``v_cm + omega x r``; linear and angular momentum are
   kept), then friction and restitution at the vertices in contact with an
   obstacle (below), then the held DOFs' prescribed velocities.

Contact response: a vertex that the projections pushed out of an obstacle
during the step (n the obstacle's normal at its end position) and whose
predicted velocity approached it (``v*.n < 0``) leaves with normal velocity
``max(u.n, -e v*.n)`` (the obstacle's ``restitution`` e; no bounce when
``|v*.n| <= 2 |g| h``, a resting contact, as in Mueller et al. 2020), and Coulomb friction (the obstacle's ``friction`` mu) removes up to
``mu dv_n`` from its tangential velocity, never reversing it, with ``dv_n``
the normal velocity change the contact gave it: the depth its projections
moved it out over ``h`` (a vertex carrying the weight of others above it is
pushed out further each step, so its friction grows with the load, as
Coulomb's does), plus the bounce. This is the impulse rule of
:meth:`fem_elastic.physics.obstacles.Obstacle.respond`, with the normal
impulse the projections applied. Penalty and barrier obstacles have
``e = mu = 0``. Restitution acts on the vertices in contact, as a particle's
does; the rest of a stiff body, stopped by the constraints, keeps them from
carrying the whole body back up (a bounce of a deformable body comes from
its compliance: XPBD's).

Mass-proportional Rayleigh damping of the model (``fe.Rayleigh(alpha, 0)``) is
taken exactly as implicit Euler takes it: the incremental potential's
``1/(2 h^2) |x - y|_M^2 + alpha/(2 h) |x - x_n|_M^2`` is the mass term of
the mass ``(1 + alpha h) M`` about the target ``x_n + h v* / (1 + alpha h)``,
so the prediction's velocity is divided by ``1 + alpha h`` and so are the
inverse masses. Stiffness-proportional damping (beta) has no position-based
form here: :class:`fe.InvalidParameter`.

What the step records (``last_stats``): ``linear_iterations`` is the number of
sweeps, ``seconds["solve"]`` their time. Nothing is carried from one step to
the next (XPBD's multipliers start at zero every step), so checkpoints hold
no integrator state. ``explicit`` is False: the schemes have no step-size
limit, and :func:`fe.simulate` estimates no critical time step for them;
``mass = "lumped"``: the kinetic energy :func:`fe.simulate` records is the
lumped one, the mass the schemes use.

References: M. Mueller, B. Heidelberger, M. Hennix, J. Ratcliff, "Position
based dynamics", JVCIR 18(2), 2007. M. Mueller, M. Macklin, N. Chentanez,
S. Jeschke, T.-Y. Kim, "Detailed rigid body simulation with extended position
based dynamics", SCA 2020. M. Macklin, K. Storey, M. Lu, P. Terdiman,
N. Chentanez, S. Jeschke, M. Mueller, "Small steps in physics simulation",
SCA 2019 (``substeps``).
"""

from __future__ import annotations

import logging
import math
import numbers
import time
from typing import TYPE_CHECKING

import numpy as np

from ...errors import InvalidParameter
from ..integrators.base import Integrator, StepStats, check_dt, check_state
from ..state import State

if TYPE_CHECKING:  # for annotations only
    from ...physics.multibody import AnyModel

__all__ = ["PositionBased", "METHODS", "check_one_body", "check_p1_body"]

log = logging.getLogger(__name__)

#: The sweeps a position-based integrator can take.
METHODS = ("gauss_seidel", "jacobi")


def _number(value, name, low, high, *, low_open=False, high_open=False, example="") -> float:
    bad = isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value)
    if not bad:
        v = float(value)
        bad = v < low or v > high or (low_open and v == low) or (high_open and v == high)
    if bad:
        lo = "(" if low_open else "["
        hi = ")" if high_open else "]"
        raise InvalidParameter(f"{name} must be a number in {lo}{low:g}, {high:g}{hi}, got {value!r}{example}.")
    return float(value)


def check_one_body(model, who: str) -> None:
    """InvalidParameter if ``model`` is a ``fe.MultiBody``: ``who`` (a scheme's name) takes one body."""
    if getattr(model, "models", None) is not None:
        raise InvalidParameter(
            f"{who} takes one body (a fe.Model); a fe.MultiBody of {len(model.models)} bodies is "
            "not supported by it: simulate several bodies with fe.ImplicitEuler, fe.SymplecticEuler, "
            "fe.Newmark or the other force-based integrators, or put the pieces in one mesh."
        )


def check_p1_body(model, who: str):
    """The model's finite element body if it is a P1 ``fe.ElasticBody``; else InvalidParameter."""
    from ...physics.elastic_body import ElasticBody

    check_one_body(model, who)
    body = model.body
    if not isinstance(body, ElasticBody):
        raise InvalidParameter(
            f"{who} works on the vertices of a P1 finite element body, fe.ElasticBody(material, "
            f"order=1); got {type(body).__name__}. A mass-spring body already is springs on the "
            "edges: simulate it with fe.SymplecticEuler or fe.ImplicitEuler, or use "
            f"fe.ElasticBody(...) with {who}."
        )
    if model.space.order != 1:
        raise InvalidParameter(
            f"{who} supports linear tets (fe.ElasticBody(material, order=1)) only: its constraints "
            f"live on the mesh vertices; got order {model.space.order}. Build the model with order=1."
        )
    return body


class _Setup:
    """What the steps of one model share: constraint sets, masses, loads, obstacles."""

    def __init__(self, model, sets):
        self.sets = sets
        self.mass = np.asarray(model.lumped_mass, dtype=float)  # per DOF (kg)
        self.f_ext = model.external_force()  # dead loads (N)
        self.n_vertices = model.mesh.p.shape[1]
        self.obstacles = tuple(model.obstacles)
        self.g = float(getattr(model, "gravity_magnitude", 0.0) or 0.0)
        damping = model.damping
        self.alpha = 0.0
        if damping is not None:
            if damping.beta:
                raise InvalidParameter(
                    f"position-based integrators take mass-proportional damping (fe.Rayleigh(alpha, "
                    f"0)) only; the model has beta = {damping.beta!r} s. Use the integrator's "
                    "damping=... (velocity damping towards the rigid motion) instead of beta."
                )
            self.alpha = float(damping.alpha)
        if getattr(model.body_potential, "damping_force", None) is not None:
            raise InvalidParameter("the body has its own dashpots, which position-based schemes do not take.")


class PositionBased(Integrator):
    """Base of :class:`fe.PBD` and :class:`fe.XPBD`: the loop of the module notes.

    Parameters
    ----------
    iterations : int
        Sweeps over the constraints per step, >= 1.
    method : {"gauss_seidel", "jacobi"}
        Gauss-Seidel (graph-coloured) or Jacobi sweeps.
    damping : float
        Velocity damping per step in [0, 1] (Mueller et al. 2007): 0 none, 1
        keeps only the rigid motion.
    relaxation : float
        Jacobi's over-relaxation ``omega`` in (0, 2) on the averaged corrections.
    substeps : int
        Each step of dt is taken as this many steps of ``dt / substeps``, each
        with ``iterations`` sweeps (Macklin et al. 2019, "Small steps in
        physics simulation").
    """

    explicit = False
    mass = "lumped"
    order = 1
    _who = "PositionBased"

    def __init__(self, iterations, method, damping, relaxation, substeps=1):
        super().__init__()
        for name, value in (("iterations", iterations), ("substeps", substeps)):
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
                raise InvalidParameter(f"{name} must be an integer >= 1, got {value!r}; e.g. {name}=20.")
        self.substeps = int(substeps)
        if not isinstance(method, str) or method not in METHODS:
            raise InvalidParameter(f"method must be one of {METHODS}, got {method!r}.")
        self.iterations = int(iterations)
        self.method = method
        self.damping = _number(damping, "damping", 0.0, 1.0, example=" (a fraction per step)")
        self.relaxation = _number(relaxation, "relaxation", 0.0, 2.0, low_open=True, high_open=True)
        self._setup = (None, None)

    # -- what a scheme defines --------------------------------------------------------------
    def _constraint_sets(self, model) -> list:  # pragma: no cover - abstract
        raise NotImplementedError

    def _coefficients(self, sets, h):  # pragma: no cover - abstract
        """Per set: ``(at (n, m), scale (n,))``, the compliances over h^2 and the projection factor."""
        raise NotImplementedError

    # -- the loop ---------------------------------------------------------------------------
    def prepared(self, model: AnyModel) -> _Setup:
        """The constraint sets and data of ``model`` (built on its first step, then reused)."""
        cached_model, setup = self._setup
        if cached_model is not model:
            check_p1_body(model, self._who)
            t0 = time.perf_counter()
            setup = _Setup(model, self._constraint_sets(model))
            self._setup = (model, setup)
            log.debug("%s: %d constraint set(s) built in %.3g s (%s)", self.name, len(setup.sets),
                      time.perf_counter() - t0, ", ".join(f"{len(s)} {type(s).__name__} in "
                                                          f"{s.n_colors} colours" for s in setup.sets))
        return setup

    def step(self, model: AnyModel, state: State, dt: float) -> State:
        """Advance ``state`` by ``dt`` (s): ``substeps`` position-based steps (see the module notes)."""
        h = check_dt(dt)
        check_state(model, state)
        stats = self.last_stats = StepStats()
        setup = self.prepared(model)
        x, v = state.x, state.v
        hs = h / self.substeps
        t0 = time.perf_counter()
        coefficients = self._coefficients(setup.sets, hs)  # the same for every substep
        for k in range(1, self.substeps + 1):
            t1 = state.t + h if k == self.substeps else state.t + k * hs
            x, v = self._substep(model, setup, coefficients, x, v, t1, hs)
        stats.seconds["solve"] = time.perf_counter() - t0
        stats.linear_iterations = self.iterations * self.substeps
        stats.substeps = self.substeps
        return State(x, v, state.t + h)

    def _substep(self, model, setup, coefficients, x0, v0, t1, h):
        """One pass of the loop of the module notes, ending at time ``t1``: ``(x, v)``."""
        dofs, xc, vc = model.constraints(t1)
        c = 1.0 + setup.alpha * h  # mass-proportional damping: mass (1 + alpha h) M
        w = 1.0 / (c * setup.mass)
        w[dofs] = 0.0
        v_pred = (v0 + h * setup.f_ext / setup.mass) / c
        p = x0 + h * v_pred
        p[dofs] = xc
        free = w > 0.0
        free3 = free.reshape(-1, 3)
        lams = [np.zeros((len(s), s.m)) for s in setup.sets]  # XPBD: reset every (sub)step
        # how far each obstacle's contact moved each vertex out (m): one row per obstacle, so a
        # vertex answers with the restitution, friction and normal of the obstacle that pushed it
        push = np.zeros((len(setup.obstacles), setup.n_vertices))
        for _ in range(self.iterations):
            for s, lam, (at, scale) in zip(setup.sets, lams, coefficients):
                s.sweep(p, w, lam, at, scale, self.method, self.relaxation)
            if setup.obstacles:
                _project_out(p, setup.obstacles, free3, push)
        v = (p - x0) / h
        if self.damping:
            _damp(v, p, setup.mass, free, self.damping)
        if push.any():
            _respond(p, v, v_pred, setup, push, free3, h)
        contact = getattr(model, "contact", None)  # fe.ImpulseContact: between parts, self-contact
        if contact is not None and getattr(contact, "kind", None) == "impulse":
            p, v = contact.respond(p, v, setup.mass)
        p[dofs] = xc
        v[dofs] = vc
        return p, v

    def step_matrix(self, h: float, omega: float, zeta: float = 0.0) -> np.ndarray:  # pragma: no cover - documented absence
        raise NotImplementedError(
            f"{self.name} has no closed-form one-step map: its step depends on the iteration "
            "count and the mesh, not on a modal oscillator alone."
        )


def _project_out(x, obstacles, free3, push) -> None:
    """Move the vertices inside an obstacle onto its surface (free DOFs only), adding the depth to
    that obstacle's row of push."""
    P = x.reshape(-1, 3)
    for ob, pushed in zip(obstacles, push):
        d = ob.signed_distance(P)
        inside = np.flatnonzero(d < 0.0)
        if inside.size:
            n = ob.normal(P[inside])
            P[inside] -= (d[inside, None] * n) * free3[inside]
            pushed[inside] -= d[inside]


def _damp(v, x, mass, free, k) -> None:
    """Mueller et al. (2007) 3.5: ``v += k (v_cm + omega x r - v)`` on the free DOFs, in place."""
    m = mass[0::3]
    V, X = v.reshape(-1, 3), x.reshape(-1, 3)
    M = m.sum()
    x_cm = (m[:, None] * X).sum(axis=0) / M
    v_cm = (m[:, None] * V).sum(axis=0) / M
    r = X - x_cm
    L = (m[:, None] * np.cross(r, V)).sum(axis=0)
    inertia = (m * np.einsum("ni,ni->n", r, r)).sum() * np.eye(3) - np.einsum("n,ni,nj->ij", m, r, r)
    omega = np.linalg.lstsq(inertia, L, rcond=None)[0]  # a body on a line has a singular inertia
    dv = (v_cm + np.cross(omega, r) - V).ravel()
    v += k * np.where(free, dv, 0.0)


def _respond(x, v, v_pred, setup, push, free3, h) -> None:
    """Restitution and friction at the vertices in contact (module notes), in place."""
    P, V, Vp = x.reshape(-1, 3), v.reshape(-1, 3), v_pred.reshape(-1, 3)
    for ob, pushed in zip(setup.obstacles, push):
        contact = np.flatnonzero(pushed > 0.0)  # pushed out of this obstacle during the step
        n = ob.normal(P[contact])
        vn_pred = np.einsum("ij,ij->i", Vp[contact], n)
        approach = vn_pred < 0.0
        idx, n, vn_pred = contact[approach], n[approach], vn_pred[approach]
        e = np.where(-vn_pred > 2.0 * setup.g * h, ob.restitution, 0.0)
        vel = V[idx]
        vn = np.einsum("ij,ij->i", vel, n)
        vn_new = np.maximum(vn, -e * vn_pred)
        vt = vel - vn[:, None] * n
        speed_t = np.linalg.norm(vt, axis=1)
        # the normal velocity change of the contact: its projections (push / h), then the bounce
        dv_t = ob.friction * (pushed[idx] / h + vn_new - vn)
        with np.errstate(divide="ignore", invalid="ignore"):
            keep = np.where(speed_t > dv_t, 1.0 - dv_t / speed_t, 0.0)
        new = keep[:, None] * vt + vn_new[:, None] * n
        V[idx] = np.where(free3[idx], new, vel)
