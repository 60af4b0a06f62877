"""Explicit integrators: explicit Euler, symplectic Euler, midpoint, RK4.

All four see the model only through its force, ``f = -dPi/dx - C v``, and
the lumped mass ``m`` (kg per DOF), so a step costs one (Euler, symplectic
Euler), two (midpoint) or four (RK4) force evaluations and no matrix. With
``a(x, v) = f(x, v) / m`` on the free DOFs (0 on held ones, whose motion is
prescribed):

- explicit Euler: ``x1 = x + h v``, ``v1 = v + h a(x, v)``; first order;
  unstable for an undamped oscillator at every h (the amplification is
  ``sqrt(1 + (omega h)^2) > 1``), so its energy always grows;
- symplectic (semi-implicit) Euler: ``v1 = v + h a(x, v)``, ``x1 = x + h
  v1``; first order, symplectic, stable for ``h <= 2 / omega_max``;
  conserves linear and angular momentum exactly;
- midpoint (explicit RK2): second order; weakly unstable for an undamped
  oscillator (amplification ``sqrt(1 + (omega h)^4 / 4)``);
- classical RK4: fourth order; stable for ``h <= 2 sqrt(2) / omega_max``
  on the imaginary axis.

Adaptive sub-stepping
---------------------
With ``substep=True`` a step of any size dt is taken as ``n`` equal
sub-steps of the scheme, ``n = ceil(dt / (safety * dt_crit))``, where
``dt_crit`` is the scheme's critical time step
(:func:`fe.critical_time_step`) at the current configuration: stiffening
materials and contact raise the highest frequency under strain, so it is
re-estimated every ``recheck_every`` steps. After the sub-steps the step is
judged; it is discarded and retried from its start with (at least) twice as
many sub-steps, and ``dt_crit`` re-estimated there, when

- a position or velocity is not finite,
- the model's energy at the end is not finite (an inverted element), or
- the energy grew by more than :data:`ENERGY_GROWTH` times its scale (the
  larger of the kinetic energy, ``|Pi|`` and the work of the dead loads over
  the body's size) since the steps began to be held to it (the first step,
  the last change of the sub-step, or the end of a boundary's driven
  motion, which feeds energy in and is not judged). Damping and impulse
  contacts only remove energy, so growth is an instability. The schemes
  are judged by ``KE + Pi``, which they do not increase at a stable step,
  except symplectic Euler: its ``KE + Pi`` swings by up to ``(1 + r) / (1 -
  r)`` times the energy of a mode, ``r = h w / 2``, near the limit, while
  it conserves the modified energy ``KE + Pi - (h/2) v . dPi/dx`` (h the
  sub-step; exactly, for a linear undamped body), which is judged instead.
  On a linear body that one is conserved even where the scheme is unstable
  (it is then indefinite), so a symplectic Euler step is also rejected
  when its ``KE + Pi`` grows by more than the swing of a stable mode allows,
  ``(1 + r) / (1 - r) - 1 + ENERGY_GROWTH`` times the scale, with
  ``r = h / dt_crit``. Velocity Verlet (:mod:`fem_elastic.dynamics.integrators.verlet`)
  shares this machinery and is judged the same way by its own modified energy.

Every failed attempt is recorded in ``last_stats.cuts`` as ``(t, dt_sub,
reason)``; ``last_stats.dt_cuts`` counts them and ``last_stats.substeps`` is
the ``n`` finally used. The sub-step size in force is remembered between
steps (a retried step keeps its smaller sub-step until the next
re-estimate, which lets it grow back by at most a factor 2); with the
estimate, the steps since it and the energy reference it is part of
:meth:`checkpoint_state`, so that a resumed run repeats the uninterrupted one
bit for bit. More than ``max_substeps`` sub-steps in one step raises
:class:`fe.Diverged`.

The default ``safety`` is 0.8: near its limit symplectic Euler on a
nonlinear body is parametrically unstable below the linearized estimate
(measured on a Neo-Hookean cantilever with random nodal displacements, its
energy mostly in the top modes: a plain run at 0.9 x dt_crit of the start
blows up within 400 steps from displacements of 0.5 mm, one at 0.85 from
5 mm within 30; at 0.8 the first stays within 3 % over 1000 steps, and the
second grows slowly, which the energy check catches).

The sub-stepped scheme has no stability limit on dt, but its one-step map
on a modal oscillator depends on the model's highest frequency (through n),
which ``step_matrix(h, omega, zeta)`` cannot know: ``step_matrix`` stays the
map of one sub-step of size h, so ``fe.critical_time_step`` of a
sub-stepping integrator is the sub-step limit (equal to the plain scheme's),
the step it divides dt by. A scheme with no stable step (explicit Euler or
midpoint on an undamped body, ``dt_crit = 0``) cannot be sub-stepped:
:class:`fe.InvalidParameter` at its first step.
"""

from __future__ import annotations

import logging
import math
import numbers
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import Diverged, InvalidParameter
from ..state import State
from .base import Integrator, StepStats, check_dt, check_state

if TYPE_CHECKING:  # for annotations only
    from ...physics.multibody import AnyModel

__all__ = ["ExplicitEuler", "SymplecticEuler", "Midpoint", "RK4", "ENERGY_GROWTH", "RECHECK_EVERY"]

log = logging.getLogger(__name__)

#: A sub-stepped step is rejected when its judged energy (see the module notes) exceeds the
#: reference by more than this many times the energy scale. Largest benign growth measured over
#: 100 steps of 10 x the critical step at safety 0.8 on a soft cantilever (sagging, random nodal
#: displacements, a drop onto a penalty ground): 1e-14 of the scale for symplectic Euler on a
#: linear body (its modified energy is exact there), 1.3 % on a Neo-Hookean one, 0.3 % at the
#: ground impact (RK4: 2 %); the modified energy's O(h^2) wander under 5 mm random displacements
#: is 4 % at safety 0.5. An instability passes the bound within a step or two of becoming
#: visible: it multiplies its mode's energy by rho^2 every sub-step (3.5 for symplectic Euler 5 %
#: above its limit), and the parametric growth of those 5 mm displacements at safety 0.8 reaches
#: 85 % of the scale in 100 steps when unchecked.
ENERGY_GROWTH = 0.25

#: Default steps between re-estimates of the critical time step. An estimate
#: (fe.critical_time_step: a Hessian, Lanczos for omega_max, a scan over the modal oscillators)
#: costs as much as 3-11 sub-stepped steps of 13 sub-steps (dt = 10 x critical) on Neo-Hookean
#: cantilevers of 567 (P1) and 3 075 (P1, P2) DOFs, symplectic Euler and RK4 alike (measured:
#: 33-234 ms against 3-81 ms a step); every 50 steps that adds 6-22 %. A body that stiffens
#: faster than that is caught by the judge of each step and re-estimated then.
RECHECK_EVERY = 50

# ceil(dt / h_max) with this relative slack, so that a sub-step limit set to dt / (2 n) gives
# exactly 2 n sub-steps despite the round-off of the division (a sub-step at most 1e-9 relative
# above the limit, far inside the safety factor).
_CEIL_SLACK = 1e-9


#: The largest ``max_substeps`` accepted: sub-steps of one step, a finite bound.
MAX_SUBSTEPS = 1_000_000


class _Work:
    """What the steps on one model reuse: the inverse lumped mass, held DOFs, a force buffer.

    Built at the first step on a model and kept while the integrator steps
    that model (a Model is immutable, so nothing here goes stale). The held
    DOFs are cached only when no driven boundary may change them
    (``free`` is None otherwise, and every step asks the model).
    """

    def __init__(self, model):
        self.model = model
        self.inv_mass = 1.0 / model.lumped_mass
        self.buffer = np.empty(model.ndofs)  # the force / acceleration
        self.x_next = np.empty(model.ndofs)  # a step's x1 and v1, which State copies
        self.v_next = np.empty(model.ndofs)
        #: the last State the fused symplectic update returned with every entry finite: the next
        #: step from it skips check_state's finiteness scan (the update tested it in its pass)
        self.finite_state = None
        #: whether impulse contacts change x1, v1 after the update (then it cannot vouch for them)
        self.responds = model.has_impulse_response
        #: (potential, factor) of the loads and contacts, which :meth:`gradient` adds to the body's
        #: fused force: listed at its first use (a single-body Model's path only)
        self.other_terms: list | None = None
        if model.driven:
            self.free = self.held = self.x_held = self.v_held = None
        else:
            self.held, self.x_held, self.v_held = model.constraints(0.0)
            self.free = np.ones(model.ndofs, dtype=bool)
            self.free[self.held] = False

    def gradient(self, x, out=None):
        """dPi/dx at x (N), as ``model.gradient(x)`` (the same bits); into ``out`` if given.

        The body's fused kernel writes straight into ``out``; loads and
        contacts, if any, are added to it as :meth:`Model.gradient` does.
        """
        model = self.model
        if out is None:
            return model.gradient(x)
        body = model.body_potential
        kernels = _fused_kernels_of(body)
        if kernels is None:
            out[:] = model.gradient(x)
            return out
        kernels.gradient(x, out=out)
        if self.other_terms is None:
            self.other_terms = model._scaled_terms(1.0)[1:]
        for term, c in self.other_terms:
            out += c * term.gradient(x)
        return out


def _update_kernel():
    """The numba symplectic Euler update, or None without numba (or with ``FEM_ELASTIC_NUMBA=0``)."""
    from ...discretization import fused

    if not fused.available():
        return None
    from ._symplectic_kernel import symplectic_update

    return symplectic_update


def _fused_kernels_of(body):
    """The fused P1 kernels that compute ``body.gradient`` exactly, or None."""
    from ...physics.elastic_body import ElasticPotential

    if type(body) is not ElasticPotential:  # a subclass may change its gradient
        return None
    return body._fused()


class _Explicit(Integrator):
    """Shared: the force, held DOFs, and adaptive sub-stepping from the critical time step.

    Parameters
    ----------
    substep : bool
        Take each step as ``n`` stable sub-steps (see the module notes); False
        (default): one step of dt, limited by the critical time step.
    safety : float
        Fraction of the critical time step a sub-step may use, in (0, 1];
        default 0.8 (why: the module notes).
    recheck_every : int
        Steps between re-estimates of the critical time step at the current
        configuration, >= 1; default :data:`RECHECK_EVERY` (only with ``substep``).
    max_substeps : int
        Most sub-steps in one step, >= 1; a step that needs more raises
        :class:`fe.Diverged` (only with ``substep``). The default, 1000, is a
        dt a thousand times the stable one: past it an implicit integrator
        is the cheaper tool.
    """

    explicit = True
    #: whether a sub-stepped step is judged by the scheme's modified energy (symplectic Euler)
    _modified_energy = False
    # the settings and the sub-stepping memory (set in __init__ and _forget), for type checkers
    substep: bool
    safety: float
    recheck_every: int
    max_substeps: int
    _dt_crit: float | None
    _h_max: float | None
    _anchor: tuple[float, ...] | None
    _gradient: tuple[Any, Any]
    _workspace: _Work | None
    _model: AnyModel | None  # the model all this is of (None: the next one stepped)

    def __init__(self, substep: bool = False, safety: float = 0.8, recheck_every: int = RECHECK_EVERY,
                 max_substeps: int = 1000) -> None:
        super().__init__()
        if not isinstance(substep, (bool, np.bool_)):
            raise InvalidParameter(f"substep must be True or False, got {substep!r}.")
        if (isinstance(safety, bool) or not isinstance(safety, numbers.Real) or not math.isfinite(safety)
                or not 0 < safety <= 1):
            raise InvalidParameter(
                f"safety must be a number in (0, 1] (the fraction of the critical time step a "
                f"sub-step uses), got {safety!r}; e.g. safety=0.8."
            )
        for name, value in (("recheck_every", recheck_every), ("max_substeps", max_substeps)):
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
                raise InvalidParameter(f"{name} must be an integer >= 1, got {value!r}.")
        if max_substeps > MAX_SUBSTEPS:  # a finite bound: a step never runs for hours
            raise InvalidParameter(
                f"max_substeps must be at most {MAX_SUBSTEPS:,}, got {max_substeps!r}; a step that needs "
                "more sub-steps wants a smaller dt or an implicit integrator.")
        self.substep = bool(substep)
        self.safety = float(safety)
        self.recheck_every = int(recheck_every)
        self.max_substeps = int(max_substeps)
        self._forget()

    def __getstate__(self) -> dict:
        """Pickled without the workspace: buffers the next step on a model rebuilds."""
        state = self.__dict__.copy()
        state["_workspace"] = None
        return state

    def __repr__(self) -> str:
        if not self.substep:
            return f"fe.{self.name}()"
        return (f"fe.{self.name}(substep=True, safety={self.safety:g}, "
                f"recheck_every={self.recheck_every}, max_substeps={self.max_substeps})")

    # -- what a sub-stepping integrator remembers ------------------------------------------
    def _forget(self) -> None:
        self._dt_crit = None  # critical time step of the plain scheme at the last estimate (s)
        self._h_max = None  # largest sub-step in force (s)
        self._since = 0  # steps taken since that estimate
        self._anchor = None  # (judged energy (J), energy scale (J), sub-step (s)) the steps are held to
        self._last_energy = (None, None)  # (state returned last, its energies: see _energies)
        self._gradient = (None, None)  # (positions, dPi/dx there): for the next force evaluation
        self._model = None  # the model all this is of (None: the next one stepped, e.g. after a restore)
        self._scale_of = (None, 0.0)  # (model, its load and round-off energy scale): a cache
        self._workspace = None  # _Work: the model's inverse mass, held DOFs, a force buffer

    def checkpoint_state(self, state: State) -> dict:
        """The sub-stepping memory, for a checkpoint at ``state``.

        Returns
        -------
        dict of str to numpy.ndarray
            ``dt_crit`` (s, the last estimate), ``h_max`` (s, the sub-step
            limit in force), ``since_estimate`` (steps), ``energy_anchor``
            (the judged energy (J), its scale (J) and sub-step (s) the steps
            are held to; NaN when none) and, for symplectic Euler, ``gradient``
            (N, dPi/dx at ``state.x``, which its next step reuses; so the
            resumed run's force count is the uninterrupted one's too). Empty
            without ``substep`` or before the first step.
        """
        if not self.substep or self._dt_crit is None:
            return {}
        anchor = np.full(3, np.nan) if self._anchor is None else np.array(self._anchor, dtype=float)
        out = {"dt_crit": np.array(self._dt_crit), "h_max": np.array(self._h_max),
               "since_estimate": np.array(self._since, dtype=np.int64), "energy_anchor": anchor}
        at, g = self._gradient
        if at is state.x:
            out["gradient"] = g.copy()
        return out

    def restore_state(self, state: State, saved: dict) -> None:
        """Take back what :meth:`checkpoint_state` returned (an empty dict starts afresh)."""
        if not self.substep:
            return super().restore_state(state, saved)
        keys = {"dt_crit", "h_max", "since_estimate", "energy_anchor"}
        if saved and not keys <= set(saved) <= keys | {"gradient"}:
            raise InvalidParameter(
                f"{self.name}(substep=True) restores {sorted(keys)} (and a gradient) from a "
                f"checkpoint, got {sorted(saved)}: it was written by another integrator."
            )
        self._forget()
        if not saved:
            return
        dt_crit, h_max = float(saved["dt_crit"]), float(saved["h_max"])
        since = int(saved["since_estimate"])
        anchor = np.asarray(saved["energy_anchor"], dtype=float)
        g = np.array(saved["gradient"], dtype=float) if "gradient" in saved else None
        if not (dt_crit > 0 and h_max > 0 and since >= 0 and anchor.shape == (3,)
                and (g is None or g.shape == state.x.shape)):
            raise InvalidParameter(
                f"the checkpoint's sub-stepping state is invalid (dt_crit = {dt_crit!r} s, "
                f"h_max = {h_max!r} s, since_estimate = {since}, energy_anchor of shape "
                f"{anchor.shape}, gradient of shape {None if g is None else g.shape} for "
                f"{state.x.size} DOFs): it is damaged or of another model; resume from an earlier "
                "checkpoint."
            )
        self._dt_crit, self._h_max, self._since = dt_crit, h_max, since
        self._anchor = None if np.isnan(anchor).any() else tuple(float(a) for a in anchor)
        if g is not None:
            self._gradient = (state.x, g)

    # -- the scheme ------------------------------------------------------------------------
    def step(self, model: AnyModel, state: State, dt: float) -> State:
        """Advance ``state`` by ``dt`` (s): one step of the scheme, or ``n`` sub-steps with ``substep``."""
        h = check_dt(dt)
        w = self._workspace
        if w is None or w.model is not model or state is not w.finite_state:
            check_state(model, state)  # (a state this integrator made and found finite needs no scan)
        stats = self.last_stats = StepStats()
        if not self.substep:
            return self._advance(model, state, h, state.t + h, stats)
        return self._substepped(model, state, h, stats)

    def _advance(self, model, state, h, t1, stats) -> State:  # pragma: no cover - abstract
        """One step of the scheme from ``state`` by ``h`` (s), ending at time ``t1`` (s)."""
        raise NotImplementedError

    def _work(self, model) -> _Work:
        """The per-model constants and buffers of the steps (rebuilt when the model changes)."""
        w = self._workspace
        if w is None or w.model is not model:
            w = self._workspace = _Work(model)
        return w

    def _free(self, model, t):
        """The free-DOF mask at time t: the cached one unless a driven boundary may change it."""
        w = self._work(model)
        return w.free if w.free is not None else model.free_at(t)

    def _acceleration(self, model, x, v, free, stats, out=None):
        """``f(x, v) / m`` on the free DOFs, 0 on the held ones; into ``out`` if given (m/s^2)."""
        w = self._work(model)
        at, g = self._gradient
        if at is x:  # computed to judge the step that ended at x
            f = np.negative(g, out=out)
        else:
            f = w.gradient(x, out)
            np.negative(f, out=f)
            stats.gradient_evaluations += 1
        fd = model.damping_force(x, v, "lumped")
        if fd is not None:
            f += fd
        f *= w.inv_mass  # the cached inverse: within 1 ulp of f / m
        if free is w.free:
            f[w.held] = 0.0
        else:
            f[~free] = 0.0
        return f

    def _finish(self, model, x, v, t):
        """As :meth:`Integrator._finish`, with the cached held DOFs where nothing is driven."""
        w = self._work(model)
        if w.free is None:
            return super()._finish(model, x, v, t)
        x, v = model.respond_contacts(x, v)
        x[w.held] = w.x_held
        v[w.held] = w.v_held
        return State(x, v, t)

    def _held(self, model, x, v, t):
        """Copies of x, v with the held DOFs at their prescription at time t, and the free mask."""
        dofs, xc, vc = model.constraints(t)
        x = x.copy()
        v = v.copy()
        x[dofs], v[dofs] = xc, vc
        free = np.ones(model.ndofs, dtype=bool)
        free[dofs] = False
        return x, v, free

    # -- sub-stepping ----------------------------------------------------------------------
    def _plain(self):
        """The same scheme without sub-stepping (what the critical time step is of)."""
        return type(self)()

    def _estimate(self, model, state, h_cap) -> None:
        """Critical time step at ``state.x``; the sub-step limit becomes safety x it, at most h_cap."""
        from ...solvers.modal import critical_time_step

        dt_crit = critical_time_step(model, self._plain(), x=state.x)
        if dt_crit == 0.0:
            raise InvalidParameter(
                f"{self.name} has no stable time step on this model (critical time step 0: an "
                "undamped body, where its energy grows at every step size), so it cannot be "
                "sub-stepped. Add damping (fe.Rayleigh), or use fe.SymplecticEuler or fe.RK4 "
                "(substep=True), or an implicit integrator (fe.ImplicitEuler)."
            )
        self._dt_crit, self._since = float(dt_crit), 0
        self._h_max = min(self.safety * self._dt_crit, h_cap)
        log.debug("%s: critical time step %.6g s at t = %.6g s; sub-step limit %.6g s",
                  self.name, self._dt_crit, state.t, self._h_max)

    def _count(self, h) -> int:
        """Sub-steps for a step of h (s) under the sub-step limit in force."""
        assert self._h_max is not None  # set by _estimate before any sub-step is counted
        if not math.isfinite(self._h_max):
            return 1
        return max(1, math.ceil(h / self._h_max * (1.0 - _CEIL_SLACK)))

    def _energy_scale(self, model, ke, pe) -> float:
        """The step's energy scale (J): kinetic, |Pi|, the loads' work over the body, round-off."""
        cached_model, base = self._scale_of
        if cached_model is not model:
            base = 1e3 * model.energy_roundoff()
            if model.loads:
                f = model.external_force()
                load = max(float(np.linalg.norm(f.reshape(-1, 3).sum(axis=0))), float(np.abs(f).sum()) / 3.0)
                size = float(np.ptp(model.X.reshape(-1, 3), axis=0).max())
                base = max(base, load * size)  # the work of the loads over the body's size
            self._scale_of = (model, base)
        return max(base, abs(ke), abs(pe))

    def _energies(self, model, state, stats):
        """``(kinetic, potential, v . dPi/dx)`` of ``state`` (J); remembered for the state returned last.

        The last term is computed for schemes judged by a modified energy only
        (else None); its gradient is kept for the first force evaluation of the
        step that starts from ``state``, so it costs nothing extra.
        """
        last, energies = self._last_energy
        if last is state:
            return energies
        vg = None
        if self._modified_energy:
            at, g = self._gradient
            if at is not state.x:
                g = model.gradient(state.x)
                stats.gradient_evaluations += 1
                self._gradient = (state.x, g)
            vg = self._energy_term(model, state, g)
        return model.kinetic_energy(state.v, "lumped"), model.energy(state.x), vg

    def _energy_term(self, model, state, g) -> float:
        """The term of the modified energy from dPi/dx ``g`` at ``state``: here ``v . g`` (W)."""
        return float(state.v @ g)

    def _swing(self, r) -> float:
        """Most ``KE + Pi`` of a stable mode over its modified energy, at ``r = h / dt_crit``."""
        return (1.0 + r) / (1.0 - r) if r < 1.0 else math.inf  # safety = 1: no bound

    def _judged(self, energies, hs) -> float:
        """The energy a step is judged by (J): kinetic plus potential, or the modified energy."""
        ke, pe, vg = energies
        return ke + pe if vg is None else ke + pe - 0.5 * hs * vg

    def _judge(self, model, start, end, hs, anchor) -> str:
        """Why the energies at the end of a step of sub-step hs (s) reject it; "" if they do not."""
        e_ref, scale, _ = anchor
        e1 = self._judged(end, hs)
        if e1 > e_ref + ENERGY_GROWTH * scale:
            what = "modified energy" if end[2] is not None else "total energy"
            return (f"the {what} grew from {e_ref:.6g} J to {e1:.6g} J (more than {ENERGY_GROWTH:g} x "
                    f"its scale {scale:.3g} J) with no energy source")
        if end[2] is not None:
            # symplectic Euler conserves its modified energy exactly on a linear body even where
            # unstable (it is then indefinite), so the blow-up shows only in KE + Pi; a stable
            # mode swings that by (1 + r) / (1 - r) at most, r = h w / 2 = hs / dt_crit
            # (velocity Verlet: 1 / (1 - r^2), see _swing)
            swing = self._swing(hs / self._dt_crit)
            e0, e1 = start[0] + start[1], end[0] + end[1]
            step_scale = self._energy_scale(model, start[0], start[1])
            if e1 > e0 + (swing - 1.0 + ENERGY_GROWTH) * step_scale:
                return (f"the total energy grew from {e0:.6g} J to {e1:.6g} J within the step, more "
                        f"than a stable step's swing allows ({swing - 1.0 + ENERGY_GROWTH:.3g} x its "
                        f"scale {step_scale:.3g} J)")
        return ""

    def _substepped(self, model, state, h, stats) -> State:
        if self._model is not model:  # the memory is of another model: start afresh
            if self._model is not None:
                self._forget()
            self._model = model
        t0 = state.t
        start = self._energies(model, state, stats)
        if not math.isfinite(start[0] + start[1]):
            raise Diverged(
                f"{self.name}: the energy of the state at t = {t0:.6g} s is not finite (an inverted "
                "element, or non-finite positions), so a sub-stepped step cannot be judged. Start "
                "from an admissible state.",
                time=t0, reason="the energy at the start of the step is not finite",
                last_good_state=state,
            )
        judge_energy = not (model.driving(t0) or model.driving(t0 + h))
        if not judge_energy:
            self._anchor = None  # a driven boundary feeds energy in: judged again once it stops
        fresh = False  # whether the estimate in force is at this step's start
        if self._dt_crit is None or self._since >= self.recheck_every:
            cap = math.inf if self._h_max is None else 2.0 * self._h_max
            self._estimate(model, state, cap)
            fresh = True
        n = self._count(h)
        reasons: list[str] = []
        while True:
            if n > self.max_substeps:
                after = f" after {len(reasons)} failed attempt(s): {'; '.join(reasons)}" if reasons else ""
                raise Diverged(
                    f"{self.name} needs {n} sub-steps for dt = {h:.4g} s at t = {t0:.6g} s (critical "
                    f"time step {self._dt_crit:.4g} s, safety {self.safety:g}){after}, more than "
                    f"max_substeps = {self.max_substeps}. Raise max_substeps, lower dt, or use an "
                    "implicit integrator (fe.ImplicitEuler).",
                    time=t0, reason=f"more than max_substeps = {self.max_substeps} sub-steps needed",
                    last_good_state=state,
                )
            out, why = self._attempt(model, state, h, n, stats, start, judge_energy)
            if out is not None:
                break
            reasons.append(why)
            stats.dt_cuts += 1
            stats.cuts.append((float(t0), h / n, why))
            log.info("%s: step at t=%.6g s in %d sub-steps of %.3g s failed (%s); retrying with more",
                     self.name, t0, n, h / n, why)
            cap = h / (2 * n)
            if fresh:
                self._h_max = min(self._h_max, cap)
            else:
                self._estimate(model, state, cap)
                fresh = True
            n = self._count(h)
        self._since += 1
        stats.substeps = n
        return out

    def _attempt(self, model, state, h, n, stats, start, judge_energy):
        """n sub-steps of h / n from ``state``: (the new State, "") or (None, why it failed)."""
        t0, hs = state.t, h / n
        anchor = self._anchor
        if judge_energy and (anchor is None or anchor[2] != hs):  # the judged energy depends on hs
            anchor = (self._judged(start, hs), self._energy_scale(model, start[0], start[1]), hs)
        s = state
        for k in range(1, n + 1):
            t1 = t0 + h if k == n else t0 + k * hs
            s = self._advance(model, s, hs, t1, stats)
            w = self._workspace  # the fused update tested the States it vouches for
            if not (w is not None and s is w.finite_state) and not (
                    np.isfinite(s.x).all() and np.isfinite(s.v).all()):
                return None, f"non-finite positions or velocities after sub-step {k} of {n}"
        pe = model.energy(s.x)
        if not math.isfinite(pe):
            return None, "the energy at the end of the step is not finite (an inverted element)"
        ke, vg, g = model.kinetic_energy(s.v, "lumped"), None, None
        if self._modified_energy:
            at, g = self._gradient
            if at is not s.x:  # unless the scheme's last sub-step took it there (velocity Verlet)
                g = model.gradient(s.x)
                stats.gradient_evaluations += 1
            vg = self._energy_term(model, s, g)
        end = (ke, pe, vg)
        if judge_energy:
            why = self._judge(model, start, end, hs, anchor)
            if why:
                return None, why
            self._anchor = anchor
        self._last_energy = (s, end)
        if g is not None:
            self._gradient = (s.x, g)
        return s, ""


class ExplicitEuler(_Explicit):
    """Forward Euler: ``x1 = x + h v``, ``v1 = v + h a(x, v)`` (first order).

    Parameters are those of the explicit schemes' sub-stepping (see
    :mod:`fem_elastic.dynamics.integrators.explicit`): ``substep``, ``safety``,
    ``recheck_every``, ``max_substeps``. Sub-stepping needs damping: on an
    undamped body explicit Euler has no stable step.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> fe.ExplicitEuler().step_matrix(0.1, 1.0)  # I + h A for q'' = -q
    array([[ 1. ,  0.1],
           [-0.1,  1. ]])
    """

    order = 1

    def _advance(self, model, state, h, t1, stats):
        x, v, free = state.x, state.v, self._free(model, state.t)
        a = self._acceleration(model, x, v, free, stats, out=self._work(model).buffer)
        return self._finish(model, x + h * v, v + h * a, t1)

    def step_matrix(self, h: float, omega: float, zeta: float = 0.0) -> np.ndarray:
        """One-step map of (q, v) on the modal oscillator; of one sub-step with ``substep``."""
        return np.eye(2) + h * self._oscillator(omega, zeta)


class SymplecticEuler(_Explicit):
    """Semi-implicit Euler: ``v1 = v + h a(x, v)``, then ``x1 = x + h v1``.

    Stable up to ``h = 2 / omega_max`` on an undamped body; its energy
    error stays bounded (it is symplectic), and it conserves linear and
    angular momentum exactly. With ``substep=True`` any dt is taken in
    stable sub-steps (see :mod:`fem_elastic.dynamics.integrators.explicit`).

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> [round(float(max(abs(np.linalg.eigvals(fe.SymplecticEuler().step_matrix(h, 1.0))))), 12)
    ...  for h in (1.9, 2.1)]  # below and above h = 2 / omega
    [1.0, 1.87732804493]

    Sub-stepped, a step 20 times the critical one is taken in
    ``ceil(20 / 0.8) = 25`` sub-steps:

    >>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left")
    >>> se = fe.SymplecticEuler(substep=True)
    >>> s = se.step(model, fe.State.rest(model), 20 * fe.critical_time_step(model, fe.SymplecticEuler()))
    >>> se.last_stats.substeps, se.last_stats.dt_cuts
    (25, 0)
    """

    order = 1
    _modified_energy = True

    def _advance(self, model, state, h, t1, stats):
        w = self._work(model)
        update = _update_kernel() if w.free is not None and not w.responds else None
        if update is not None:
            return self._advance_fused(model, state, h, t1, stats, w, update)
        free = self._free(model, state.t)
        # in the cached buffers: the new State's own copies of x1 and v1 are the step's only arrays
        a = self._acceleration(model, state.x, state.v, free, stats, out=w.buffer)
        v1 = np.multiply(a, h, out=w.v_next)
        v1 += state.v  # v + h a, as before
        x1 = np.multiply(v1, h, out=w.x_next)
        x1 += state.x  # x + h v1
        return self._finish(model, x1, v1, t1)

    def _advance_fused(self, model, state, h, t1, stats, w, update):
        """:meth:`_advance` in one numba pass (``update``, :func:`_update_kernel`'s) after the force
        (the same bits), into the new State's own arrays (no copies); for models with no driven
        boundary and no impulse contact."""
        at, g = self._gradient
        if at is state.x:  # computed to judge the step that ended at state.x
            f = g
        else:
            f = w.gradient(state.x, w.buffer)
            stats.gradient_evaluations += 1
        fd = model.damping_force(state.x, state.v, "lumped")
        negate = fd is None
        if not negate:
            f = np.negative(f, out=w.buffer)
            f += fd
        x1, v1 = np.empty(model.ndofs), np.empty(model.ndofs)
        finite = update(f, negate, w.inv_mass, h, state.x, state.v, w.held, w.x_held, w.v_held, x1, v1)
        out = State._adopt(x1, v1, t1)
        w.finite_state = out if finite else None
        return out

    def step_matrix(self, h: float, omega: float, zeta: float = 0.0) -> np.ndarray:
        """One-step map of (q, v) on the modal oscillator; of one sub-step with ``substep``."""
        w2, c = omega * omega, 2.0 * zeta * omega
        # v1 = v + h (-w2 q - c v);  q1 = q + h v1
        return np.array([[1.0 - h * h * w2, h * (1.0 - h * c)], [-h * w2, 1.0 - h * c]])


class Midpoint(_Explicit):
    """Explicit midpoint (RK2): a half Euler step, then the full step with midpoint rates.

    Parameters: see :class:`ExplicitEuler` (sub-stepping needs damping).

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> M = fe.Midpoint().step_matrix(0.1, 1.0)
    >>> round(float(abs(np.linalg.eigvals(M)).max()) - 1.0, 8)  # sqrt(1 + (wh)^4/4) - 1
    1.25e-05
    """

    order = 2

    def _advance(self, model, state, h, t1, stats):
        t = state.t
        x, v, free = state.x, state.v, self._free(model, t)
        a = self._acceleration(model, x, v, free, stats)
        xm, vm, free_m = self._held(model, x + 0.5 * h * v, v + 0.5 * h * a, t + 0.5 * h)
        am = self._acceleration(model, xm, vm, free_m, stats)
        return self._finish(model, x + h * vm, v + h * am, t1)

    def step_matrix(self, h: float, omega: float, zeta: float = 0.0) -> np.ndarray:
        """One-step map of (q, v) on the modal oscillator; of one sub-step with ``substep``."""
        hA = h * self._oscillator(omega, zeta)
        return np.eye(2) + hA + hA @ hA / 2.0


class RK4(_Explicit):
    """Classical fourth-order Runge-Kutta on ``(x, v)``.

    Parameters: see :class:`SymplecticEuler` (``substep`` and its options).

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> M = fe.RK4().step_matrix(2 * np.sqrt(2), 1.0)  # on the imaginary-axis limit
    >>> round(float(abs(np.linalg.eigvals(M)).max()), 12)
    1.0
    """

    order = 4

    def _advance(self, model, state, h, t1, stats):
        t = state.t
        x1, v1, free = state.x, state.v, self._free(model, t)
        a1 = self._acceleration(model, x1, v1, free, stats)
        x2, v2, free2 = self._held(model, x1 + 0.5 * h * v1, v1 + 0.5 * h * a1, t + 0.5 * h)
        a2 = self._acceleration(model, x2, v2, free2, stats)
        x3, v3, _ = self._held(model, x1 + 0.5 * h * v2, v1 + 0.5 * h * a2, t + 0.5 * h)
        a3 = self._acceleration(model, x3, v3, free2, stats)
        x4, v4, free4 = self._held(model, x1 + h * v3, v1 + h * a3, t1)
        a4 = self._acceleration(model, x4, v4, free4, stats)
        x = x1 + (h / 6.0) * (v1 + 2.0 * v2 + 2.0 * v3 + v4)
        v = v1 + (h / 6.0) * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        return self._finish(model, x, v, t1)

    def step_matrix(self, h: float, omega: float, zeta: float = 0.0) -> np.ndarray:
        """One-step map of (q, v) on the modal oscillator; of one sub-step with ``substep``."""
        hA = h * self._oscillator(omega, zeta)
        hA2 = hA @ hA
        return np.eye(2) + hA + hA2 / 2.0 + hA2 @ hA / 6.0 + hA2 @ hA2 / 24.0
