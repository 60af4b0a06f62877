"""Incremental potential contact (IPC, Li et al. 2020) through the IPC Toolkit (``ipctk``).

Contact between bodies, and of a body with itself, on the model's
:class:`~fem_elastic.physics.collision_surface.CollisionSurface`. Every pair
of surface primitives (vertex-triangle, edge-edge, and their degenerate
cases) closer than the activation distance ``dhat`` (m) adds the barrier

    B(x) = kappa * sum_k b(d_k^2, dhat^2),   b(s, t) = -(s - t)^2 ln(s / t) for s < t,

with ``d_k`` the pair's distance (ipctk's barrier acts on squared
distances, so ``kappa`` is in J/m^4 = N/m^3). B grows without bound as a
distance goes to zero, and the line search never crosses zero: every
Newton step is first cut to its collision-free fraction by continuous
collision detection (:meth:`BoundIPCContact.max_step`, ipctk's
``compute_collision_free_stepsize`` with additive CCD, which is conservative
by construction), so no iterate,
and hence no time step, ever intersects.

Gradient and Hessian come from ipctk on the ``(n_s, 3)`` surface vertex
positions and are scattered onto the model's flat DOF vector through the
surface's ``vertex_dofs`` (a sparse index map; P2 edge nodes take no part).

Adaptive barrier stiffness (``kappa="auto"``): IPC's rule (ipctk's
``initial_barrier_stiffness`` / ``update_barrier_stiffness``). At binding
kappa is the smallest stiffness ipctk admits for the mean nodal mass and the
scene's bounding-box diagonal; the first linearization with active contacts
(once per bound contact) sets it to balance the barrier's gradient against
the rest of the objective (clamped to ``[kappa_min, 100 kappa_min]``); after
that it changes only between solves (:meth:`BoundIPCContact.begin_solve`,
called by implicit Euler at each step with the step's start), doubling while
the minimum distance keeps shrinking below ``1e-9`` of the diagonal, so the
objective a Newton solve minimises does not change under it. Kappa is state:
checkpoints store it (:meth:`BoundIPCContact.checkpoint_state`), so a resumed
run continues with the kappa the uninterrupted run had there. ipctk sums the
pairs' contributions on several threads in a varying order, so two runs of one
IPC scene, resumed or not, agree to round-off (3e-17 m measured on a 0.1 m cube
drop), and bit for bit with ``ipctk.set_num_threads(1)``.

Friction (``friction = mu > 0``): lagged IPC friction. An implicit step calls
:meth:`BoundIPCContact.lag_friction` with the step's start ``x_n``, the
lagged positions and ``h``; the friction dissipation potential
``D(x) = h * Phi((x - x_n) / h)`` (ipctk's ``FrictionPotential`` of the
velocities, smoothed below the slip speed ``epsv`` m/s) then uses the
normal forces and tangent bases of the lagged state. Implicit Euler solves
the step, re-lags at the new positions and solves again,
``friction_iterations`` times in all (1: normal forces from the start of
the step; IPC's own default).

The fixed obstacles (``fe.Ground``, ``fe.Sphere``, ``fe.Box``) keep their own
contact potentials (penalty or barrier, :mod:`.contact`); they are not added
to the ipctk collision mesh.
"""

from __future__ import annotations

import logging
import math
import warnings
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Literal, cast

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidMesh, InvalidParameter, MissingDependency
from .potential import Potential

if TYPE_CHECKING:  # for annotations only (the model imports this module)
    from .multibody import AnyModel

__all__ = ["IPCContact", "BoundIPCContact"]

log = logging.getLogger(__name__)

_BROAD_PHASES = {
    "bvh": "LBVH", "hash_grid": "HashGrid", "spatial_hash": "SpatialHash",
    "sweep_and_prune": "SweepAndPrune", "brute_force": "BruteForce",
}
#: ipctk's PSD projection of a pair's Hessian, by ``IPCContact(projection=...)``
_PROJECTIONS = {"abs": "ABS", "clamp": "CLAMP"}


def _ipctk():
    try:
        import ipctk
    except ImportError as err:  # pragma: no cover - the extra is installed in the test env
        raise MissingDependency(
            "IPC contact needs the IPC Toolkit: pip install 'fem_elastic[contact]' (ipctk)."
        ) from err
    return ipctk


def _positive(name, value, unit):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) \
            or not math.isfinite(value) or value <= 0:
        raise InvalidParameter(f"{name} must be a finite number > 0 ({unit}), got {value!r}.")
    return float(value)


class IPCContact:
    """IPC barrier contact with self-contact, CCD and lagged friction; pass as ``fe.Model(contact=...)``.

    Parameters
    ----------
    dhat : float
        Activation distance of the barrier (m), > 0: pairs closer than this
        repel. Keep it below the smallest distance between surface primitives
        that should not interact at rest (about the surface edge length for
        self-contact).
    kappa : float or "auto"
        Barrier stiffness (N/m^3, see the module notes), or ``"auto"`` for
        IPC's adaptive stiffness. It sets how far apart bodies rest: the
        pairs' barrier forces carry the load (each ``2 kappa dhat^4 / d`` at a
        gap d << dhat), so a stiffer barrier holds the surfaces at a larger
        gap, always below ``dhat``. The pairs are not weighted by area, so at
        one kappa the gap grows with the number of pairs, that is with the
        surface mesh. IPC's rule keeps the resting gap tiny (1.1e-5 m for the
        ball of ``scenes/two_bodies.toml`` refined to 21,870 tets, with dhat =
        1 mm; its kappa falls with the mean nodal mass, to 9.8e4 there), where
        the barrier's force changes by its own size over a fraction of the gap
        and Newton takes many short steps; ``kappa = 1e7`` holds that ball
        0.7 mm above the block and the drop runs in half the time (the user
        guide's "Choosing kappa"). :meth:`BoundIPCContact.diagnostics` gives
        the gap (``min_distance``), and the trajectory records it each step
        (``contact_min_distance``).
    friction : float
        Coulomb coefficient mu >= 0 (0: frictionless).
    epsv : float
        Friction's smoothing velocity (m/s), > 0: below it sliding is
        resisted like a viscous stick.
    self_contact : bool
        Whether surface primitives of one body collide with each other
        (a mesh with two disjoint pieces in one model needs True).
    broad_phase : {"bvh", "hash_grid", "spatial_hash", "sweep_and_prune", "brute_force"}
        ipctk's broad phase.
    friction_iterations : int
        Lagged friction solves per implicit step (>= 1).
    projection : {"clamp", "abs"}
        How each pair's Hessian is made positive semi-definite when Newton
        asks for a projected tangent: ``"clamp"`` sets its negative
        eigenvalues to 0 (IPC's rule), ``"abs"`` flips their sign (Chen et al.
        2024, "Trust-region eigenvalue filtering for projected Newton"). A
        clamped pair leaves the directions along which the barrier curves down
        with only the inertia's ``m / h^2`` (far softer than the barrier near
        contact), so projected steps along them are long; the absolute value
        keeps a stiffness there. Neither wins everywhere: on the first step of
        ``scripts/bench_ipc.py``'s aligned cubes (``--cubes --projection``) "abs" took
        11, 16, 12 and 37 Newton iterations at 2, 3, 4 and 5 cells per edge
        against 12, 12, 21 and 18 clamped (with Newton's saddle extension;
        11, 17, 12 and 59 against 12, 12, 23 and 18 before it, and another
        process gave 56 against 20 at 2 cells: ipctk sums the pair Hessians
        in parallel, and near the scene's saddle the Newton path follows the
        round-off), so
        the default stays IPC's.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> contact = fe.IPCContact(dhat=1e-3, friction=0.3)
    >>> contact.dhat, contact.friction
    (0.001, 0.3)
    """

    kappa: float | Literal["auto"]  # N/m^3, or "auto" (chosen when bound)

    def __init__(self, dhat: float, kappa: float | Literal["auto"] = "auto", friction: float = 0.0,
                 epsv: float = 1e-3, self_contact: bool = True,
                 broad_phase: Literal["bvh", "hash_grid", "spatial_hash", "sweep_and_prune",
                                      "brute_force"] = "bvh",
                 friction_iterations: int = 1,
                 projection: Literal["clamp", "abs"] = "clamp") -> None:
        self.dhat = _positive("dhat", dhat, "m; e.g. 1e-3 for a body of about 1 m")
        if isinstance(kappa, str):
            if kappa != "auto":
                raise InvalidParameter(f"kappa must be a number > 0 (N/m^3) or 'auto', got {kappa!r}.")
            self.kappa = "auto"
        else:
            self.kappa = _positive("kappa", kappa, "N/m^3")
        if isinstance(friction, bool) or not isinstance(friction, (int, float, np.number)) \
                or not math.isfinite(friction) or friction < 0:
            raise InvalidParameter(f"friction must be a Coulomb coefficient >= 0, got {friction!r}.")
        self.friction = float(friction)
        self.epsv = _positive("epsv", epsv, "m/s; e.g. 1e-3")
        self.self_contact = bool(self_contact)
        if broad_phase not in _BROAD_PHASES:
            raise InvalidParameter(
                f"broad_phase must be one of {sorted(_BROAD_PHASES)}, got {broad_phase!r}."
            )
        self.broad_phase = broad_phase
        if isinstance(friction_iterations, bool) or not isinstance(friction_iterations, int) \
                or friction_iterations < 1:
            raise InvalidParameter(
                f"friction_iterations must be an integer >= 1, got {friction_iterations!r}."
            )
        self.friction_iterations = friction_iterations
        if projection not in _PROJECTIONS:
            raise InvalidParameter(
                f"projection must be one of {sorted(_PROJECTIONS)}, got {projection!r}."
            )
        self.projection = projection

    def __repr__(self):
        return (f"IPCContact(dhat={self.dhat!r}, kappa={self.kappa!r}, friction={self.friction!r}, "
                f"epsv={self.epsv!r}, self_contact={self.self_contact!r}, "
                f"broad_phase={self.broad_phase!r}, projection={self.projection!r})")

    def bind(self, model: AnyModel) -> "BoundIPCContact":
        """The contact potential on ``model``'s collision surface (see :class:`BoundIPCContact`)."""
        return BoundIPCContact(self, model)


class BoundIPCContact(Potential):
    """IPC contact bound to a model: a Potential with CCD (``kind = "potential"``).

    Raises
    ------
    InvalidMesh
        The model's mesh has no surface.
    InvalidParameter
        The surface intersects itself (bodies overlapping) or touches at
        distance 0 in the reference configuration.
    """

    kind = "potential"

    def __init__(self, spec: IPCContact, model: AnyModel) -> None:
        ipctk = _ipctk()
        self.spec = spec
        self.dhat = spec.dhat
        self.surface = surface = model.collision_surface()
        if surface.faces.shape[0] == 0:
            raise InvalidMesh("the collision surface has no triangle; give a tet mesh with a boundary.")
        self.ndofs = model.ndofs
        self._idx = surface.vertex_dofs.ravel()
        V0 = np.asfortranarray(surface.rest)
        self.mesh = ipctk.CollisionMesh(
            V0, np.asfortranarray(surface.edges, dtype=np.int32),
            np.asfortranarray(surface.faces, dtype=np.int32),
        )
        if not spec.self_contact:
            body = np.asarray(surface.body)
            if np.unique(body).size < 2:
                log.info("IPC contact without self-contact on a single body: no pair can collide")
            # ipctk's native filter: a Python callable here is called from the parallel
            # broad phase (ipctk warns it is unsafe; it deadlocked in 4 of 6 runs)
            self.mesh.can_collide = ipctk.make_vertex_patches_filter(body.astype(np.int32))
        self._broad_phase = getattr(ipctk, _BROAD_PHASES[spec.broad_phase])()
        # Additive CCD (Li et al. 2021): conservative by construction (it advances by lower
        # bounds of the distance and stops at 0.9 of the remaining gap); measured 30-100x faster
        # than Tight-Inclusion here, whose ipctk default (1e7 iterations per pair) takes
        # minutes on coplanar sliding faces
        self._ccd = ipctk.AdditiveCCD(10_000_000, 0.9)
        self.bbox_diagonal = float(ipctk.world_bbox_diagonal_length(V0))
        if ipctk.has_intersections(self.mesh, V0, self._broad_phase):
            raise InvalidParameter(
                "the bodies' surfaces intersect in the reference configuration (overlapping "
                "bodies at t = 0): IPC contact keeps bodies apart but cannot separate them. Move "
                "the bodies apart (or the pieces of the mesh) so that no surfaces cross."
            )
        # IPC's average nodal mass (kg): of all the model's nodes, as in Li et al. 2020, not of
        # the surface vertices alone (each carries only part of an element's mass, so that mean
        # is lower: 2/3 of it, and so of kappa_min, on scripts/bench_ipc.py's cubes at 2592 tets)
        self.average_mass = float(np.asarray(model.lumped_mass).reshape(-1, 3).mean())
        self.adaptive = spec.kappa == "auto"
        if self.adaptive:
            kappa_min, _ = ipctk.initial_barrier_stiffness(
                self.bbox_diagonal, ipctk.ClampedLogBarrier(), self.dhat, self.average_mass,
                np.zeros(3 * surface.n_vertices), np.zeros(3 * surface.n_vertices),
            )
            self.kappa_min, self.kappa_max = float(kappa_min), 100.0 * float(kappa_min)
            self.kappa = self.kappa_min
        else:
            self.kappa = self.kappa_min = self.kappa_max = cast(float, spec.kappa)  # not "auto" here
        self._kappa_initialized = not self.adaptive
        self._objective_gradient = None
        self._prev_min_distance = math.inf
        self.barrier = ipctk.BarrierPotential(self.dhat, self.kappa)
        self._model_terms = lambda: [p for p in model.potentials if p is not self]
        self._cache_key = None
        self._collisions = None
        # friction (lagged): reference positions x_n, step h, tangential collisions
        self.mu = spec.friction
        self._friction = ipctk.FrictionPotential(spec.epsv) if self.mu > 0 else None
        self._tangential = None
        # The lagged friction's reference surface positions (m, gathered once per lag) and time
        # step (s): set by lag_friction; read only while self._tangential is set.
        self._V_ref: Any = None
        self._h: Any = None
        start = self._collisions_at(V0)
        if len(start):
            dmin = math.sqrt(float(start.compute_minimum_distance(self.mesh, V0)))  # ipctk: squared
            if dmin <= 0.0:
                raise InvalidParameter(
                    "surfaces touch at distance 0 in the reference configuration (bodies in "
                    "contact at t = 0): leave a gap larger than 0 between them, e.g. dhat / 2."
                )
            warnings.warn(
                f"IPC contact: surface primitives are within dhat = {self.dhat:g} m of each other "
                f"at rest (closest {dmin:.3g} m), so the barrier already pushes there; use a dhat "
                "below the surface's edge length or leave a gap of at least dhat.",
                stacklevel=3,
            )

    # collisions at a configuration ----------------------------------------------------
    def _collisions_at(self, V):
        ipctk = _ipctk()
        key = V.tobytes()
        if key != self._cache_key:
            c = ipctk.NormalCollisions()
            c.build(self.mesh, V, self.dhat, broad_phase=self._broad_phase)
            self._collisions, self._cache_key = c, key
        return self._collisions

    def _V(self, x):
        return np.asfortranarray(self.surface.positions(x))

    def _U(self, V):
        """The lagged friction's sliding velocities ``(V - V_ref) / h`` (m/s) of surface positions ``V``."""
        return np.asfortranarray((V - self._V_ref) / self._h)

    def _scatter(self, g_s):
        g = np.zeros(self.ndofs)
        g[self._idx] = g_s  # each surface vertex has its own three DOFs: no index repeats
        return g

    def _scatter_matrix(self, H_s):
        H_s = sp.coo_matrix(H_s)
        return sp.csr_matrix((H_s.data, (self._idx[H_s.row], self._idx[H_s.col])),
                             shape=(self.ndofs, self.ndofs))

    def _set_kappa(self, kappa):
        if kappa != self.kappa:
            self.kappa = float(kappa)
            self.barrier = _ipctk().BarrierPotential(self.dhat, self.kappa)

    # the Potential protocol ----------------------------------------------------------------
    def energy(self, x: np.ndarray) -> float:
        """Barrier (and lagged friction) energy (J)."""
        V = self._V(x)
        c = self._collisions_at(V)
        e = float(self.barrier(c, self.mesh, V)) if not c.empty() else 0.0
        if self._tangential is not None:
            e += self._h * float(self._friction(self._tangential, self.mesh, self._U(V)))
        return e if math.isfinite(e) else math.inf

    def gradient(self, x: np.ndarray) -> np.ndarray:
        """dE/dx (N), ``(ndofs,)``."""
        V = self._V(x)
        c = self._collisions_at(V)
        g = np.zeros(3 * self.surface.n_vertices)
        if not c.empty():
            g += self.barrier.gradient(c, self.mesh, V)
        if self._tangential is not None:
            g += self._friction.gradient(self._tangential, self.mesh, self._U(V))
        return self._scatter(g)

    def hessian(self, x: np.ndarray, project: bool = False) -> sp.csr_matrix:
        """d2E/dx2 (N/m), CSR ``(ndofs, ndofs)``; with ``project`` each pair's Hessian is
        made positive semi-definite (``IPCContact(projection=...)``: absolute or clamped
        eigenvalues)."""
        ipctk = _ipctk()
        V = self._V(x)
        c = self._collisions_at(V)
        method = getattr(ipctk.PSDProjectionMethod, _PROJECTIONS[self.spec.projection] if project else "NONE")
        n = 3 * self.surface.n_vertices
        H = sp.csc_matrix((n, n))
        if not c.empty():
            H = H + self.barrier.hessian(c, self.mesh, V, method)
        if self._tangential is not None:
            H = H + self._friction.hessian(self._tangential, self.mesh, self._U(V), method) / self._h
        return self._scatter_matrix(H)

    def linearize(self, x: np.ndarray,
                  project: bool = False) -> tuple[np.ndarray, sp.spmatrix | None]:
        """Gradient and Hessian, PSD-projected per pair with ``project`` (as in IPC's Newton).

        The barrier's exact Hessian is indefinite for many pairs (the distance
        is not convex in the positions), so far from a solution Newton needs
        the projected one, which is always a descent direction. Near the
        solution, where Newton asks for the exact tangent (``project=False``
        after a full step, see :mod:`fem_elastic.solvers.newton`), the exact
        one restores quadratic convergence; the clamped one converges only
        linearly there (a factor of about 0.3 per iteration measured on the
        aligned cubes of scripts/bench_ipc.py at 2592 tets: 27 Newton
        iterations in their first step against 13 with the exact tangent; 12
        now that Newton also lengthens full projected steps at saddles).
        Newton returns to the projection as soon as the exact direction is
        not a descent direction or is cut by the CCD or the line search. With ``kappa="auto"`` the stiffness is set here at the first
        linearization with active contacts (see the module notes); it does not
        change inside a solve.
        """
        if self.adaptive and not self._kappa_initialized:
            self._init_kappa(x)
        return self.gradient(x), self.hessian(x, project=project)

    def _init_kappa(self, x):
        """IPC's initial stiffness: balance the barrier's gradient against the rest of the objective."""
        ipctk = _ipctk()
        V = self._V(x)
        c = self._collisions_at(V)
        if c.empty():
            return
        if self._objective_gradient is not None:  # the whole objective but the barrier
            g_rest = self._objective_gradient(x) - self.gradient(x)
        else:
            g_rest = np.zeros(self.ndofs)
            for term in self._model_terms():
                g_rest += term.gradient(x)
        unit = ipctk.BarrierPotential(self.dhat, 1.0)
        g_barrier = unit.gradient(c, self.mesh, V)
        kappa, kmax = ipctk.initial_barrier_stiffness(
            self.bbox_diagonal, ipctk.ClampedLogBarrier(), self.dhat, self.average_mass,
            np.ascontiguousarray(g_rest[self._idx]), g_barrier,
        )
        self.kappa_max = float(kmax)
        self._set_kappa(kappa)
        self._kappa_initialized = True
        self._prev_min_distance = float(c.compute_minimum_distance(self.mesh, V))  # squared

    def _update_kappa(self, x):
        """IPC's update between two solves: double kappa while the minimum distance shrinks below 1e-9 diag."""
        ipctk = _ipctk()
        V = self._V(x)
        c = self._collisions_at(V)
        if c.empty():
            self._prev_min_distance = math.inf
            return
        dmin = float(c.compute_minimum_distance(self.mesh, V))  # squared, as ipctk's update takes it
        if math.isfinite(self._prev_min_distance):
            self._set_kappa(ipctk.update_barrier_stiffness(
                self._prev_min_distance, dmin, self.kappa_max, self.kappa, self.bbox_diagonal,
            ))
        self._prev_min_distance = dmin

    def checkpoint_state(self) -> dict:
        """The adaptive stiffness's state, for a checkpoint (:mod:`fem_elastic.dynamics.checkpoint`).

        Kappa, its bound, whether the first linearization set it, and the last minimum distance
        the update compares with: with them a resumed run steps exactly as the uninterrupted one.
        """
        return {"kappa": np.array([self.kappa, self.kappa_max, self._prev_min_distance]),
                "initialized": np.array([int(self._kappa_initialized)])}

    def restore_state(self, saved: dict) -> None:
        """Take back what :meth:`checkpoint_state` returned (a resumed run)."""
        kappa, kappa_max, prev = (float(v) for v in np.asarray(saved["kappa"], dtype=float))
        self.kappa_max, self._prev_min_distance = kappa_max, prev
        self._kappa_initialized = bool(int(np.asarray(saved["initialized"]).ravel()[0]))
        self._set_kappa(kappa)

    def begin_solve(self, objective_gradient: Callable[[np.ndarray], np.ndarray] | None = None,
                    x: np.ndarray | None = None) -> None:
        """Start a minimisation (an implicit step, a load step).

        With ``kappa="auto"``, kappa is set once, at the first linearization
        with active contacts (the first solve that meets a contact), and
        afterwards updated only here, between solves (IPC's rule, ipctk's
        ``update_barrier_stiffness``): doubled, up to ``kappa_max``, while
        the minimum distance at the start of the solve keeps shrinking below
        ``1e-9`` of the bounding-box diagonal. A stiffness that changes inside
        a Newton solve changes the objective under the line search and the
        convergence test.

        Parameters
        ----------
        objective_gradient : callable, optional
            ``x -> dG/dx`` (N) of the whole objective being minimised (the
            incremental potential: inertia included); the initial stiffness
            balances the barrier's gradient against it, less the barrier's own.
            Without it, the rest of the model's potentials are used.
        x : numpy.ndarray, optional
            Positions at the start of the solve (m), ``(ndofs,)``, where the
            minimum distance for the update is measured; without it kappa is
            not updated.
        """
        self._objective_gradient = objective_gradient
        if self.adaptive and self._kappa_initialized and x is not None:
            self._update_kappa(x)

    # CCD -------------------------------------------------------------------------------------
    def max_step(self, x: np.ndarray, dx: np.ndarray) -> float:
        """The largest collision-free fraction in [0, 1] of the step ``x -> x + dx`` (CCD)."""
        ipctk = _ipctk()
        V0 = self._V(x)
        V1 = np.asfortranarray(V0 + self.surface.displacements(dx))
        return float(ipctk.compute_collision_free_stepsize(
            self.mesh, V0, V1, broad_phase=self._broad_phase, narrow_phase_ccd=self._ccd))

    # friction ----------------------------------------------------------------------------------
    def lag_friction(self, x_ref: np.ndarray, x_lag: np.ndarray, h: float) -> None:
        """Lag the friction: normal forces and tangent bases at ``x_lag``, sliding from ``x_ref``.

        Parameters
        ----------
        x_ref : numpy.ndarray
            Positions at the start of the step (m); the sliding velocity is ``(x - x_ref) / h``.
        x_lag : numpy.ndarray
            Positions whose contact forces the friction uses (m).
        h : float
            Time step (s).
        """
        if self._friction is None:
            return
        ipctk = _ipctk()
        V = self._V(x_lag)
        c = self._collisions_at(V)
        t = ipctk.TangentialCollisions()
        if not c.empty():
            t.build(self.mesh, V, c, self.barrier, self.mu)
        self._tangential = None if t.empty() else t
        self._V_ref = self._V(np.asarray(x_ref, dtype=float))
        self._h = float(h)

    def clear_friction(self) -> None:
        """Drop the lagged friction (a static solve or the end of a step)."""
        self._tangential = None

    # diagnostics ---------------------------------------------------------------------------------
    def has_intersections(self, x: np.ndarray) -> bool:
        """Whether the surface at ``x`` intersects itself (ipctk's exact test)."""
        return bool(_ipctk().has_intersections(self.mesh, self._V(x), self._broad_phase))

    def diagnostics(self, x: np.ndarray) -> dict:
        """Contact state at ``x``.

        Returns
        -------
        dict
            ``min_distance`` (m): the smallest distance among the pairs within
            ``dhat`` (``inf`` when no pair is that close); ``active_contacts``:
            the number of such pairs; ``contact_force`` (N): half the sum of the
            nodal barrier-force magnitudes (the force each side of the contact
            receives when the pairs push equally on both); ``kappa`` (N/m^3).
        """
        V = self._V(x)
        c = self._collisions_at(V)
        if c.empty():
            return {"min_distance": math.inf, "active_contacts": 0, "contact_force": 0.0,
                    "kappa": self.kappa}
        g = np.asarray(self.barrier.gradient(c, self.mesh, V)).reshape(-1, 3)
        return {
            # ipctk answers the squared distance
            "min_distance": math.sqrt(float(c.compute_minimum_distance(self.mesh, V))),
            "active_contacts": len(c),
            "contact_force": 0.5 * float(np.linalg.norm(g, axis=1).sum()),
            "kappa": self.kappa,
        }
