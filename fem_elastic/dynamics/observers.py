"""Observers of a simulation: what :func:`fe.simulate` does with each accepted step.

``simulate`` is a loop that takes a step with the integrator and hands it to
its observers, in order. Each is an :class:`Observer` with these hooks:

- ``on_start(run)``: before the first step (after a resume, at the checkpoint's step);
- ``on_step(run, event)``: after every accepted step; raising
  ``run.diverged(reason)`` there stops the run with :class:`fe.Diverged`;
- ``on_finish(run)``: after the last step, or ``on_interrupt(run)`` on Ctrl-C,
  or ``on_failure(run, err)`` when a :class:`fe.Diverged` ends the run (a
  :class:`fe.StepFailed` too: a step that raised), before it propagates;
  ``run.state`` is then the last good state. ``on_failure`` is optional: an
  observer without it (written before it existed) is skipped;
- ``on_close(run)``: always, last (release a progress bar or a file).

The built-in ones, in the order simulate calls them:

- :class:`BlowUpWatch`: non-finite states, non-finite energy (an inverted
  element), and energy growth beyond a bound (the work of driven boundaries
  counted in); the one place a finished step is judged diverged;
- :class:`InversionWatch`: the smallest det F of every accepted step
  (``step_stats["min_det_F"]``), and an :class:`InversionWarning` at the end
  of a run that had inverted elements;
- :class:`Recorder`: the frames of the Trajectory;
- :class:`Callback`: the user's ``callback(step, state)``;
- any observers the caller passes (``simulate(..., observers=[...])``, e.g. a
  :class:`fem_elastic.app.output.SeriesWriter`);
- :class:`CheckpointWriter`: checkpoints every N steps, on Ctrl-C, on failure
  (the last good step) and at the end;
- :class:`ProgressBar`: a tqdm bar.

The energy bound of :class:`BlowUpWatch`: with ``E_0`` the total energy at
the start (or when the last driven boundary stops moving or is released) and
``S`` an energy scale of the scene (the largest of the initial kinetic,
potential and elastic energies, the work of the loads over the body's size,
and the work of the loads carrying the body onto each obstacle), the run
diverges when ``E > E_0 + energy_growth * S``. Damping and implicit schemes
only lose energy; an unstable scheme multiplies it every step. A symplectic
scheme below its stability limit conserves a modified energy, not the measured
one: the measured energy of a mode swings by a factor up to
``1 / (1 - (h omega / 2)^2)``, a few percent well below the limit but unbounded
as ``h omega -> 2``. Close to the limit, with kinetic energy dominating the
scale, a bounded run can exceed the bound: raise ``energy_growth`` (or lower
dt) there (the stability study measured a false verdict at 0.93 x the limit on
a kicked 100 GPa beam).

A driven boundary that moves feeds energy in (or takes it out), and the bound
counts it: ``E <= E_0 + W + energy_growth * max(S, |W|_1)``, with ``W`` the
work the drive has done on the body and ``|W|_1`` the sum of the magnitudes of
its per-step increments (the energy that passed through the drive, which
also scales the allowance). Every integrator holds a driven DOF at its
prescribed position and velocity at the end of each step (they are not
unknowns), so the body's energy ``E = 1/2 v^T M v + Pi(x)`` (every DOF, the
held ones included) changes over a step by the work of the forces that hold
them, less what damping dissipates. On the held DOFs the equation of motion
does not hold; the force the drive applies there is what it would take:
``f_drive = M a + dPi/dx - f_damping`` on those rows. Its work over a step,
with the end states of the step (trapezoid rule, second order like the
schemes whose energy it checks):

- ``W_pi = 1/2 (g_n + g_{n+1}) . (x_{n+1} - x_n)`` on the held DOFs, with
  ``g = dPi/dx - f_damping`` (the potential's part, loads and contact
  included, and the dashpots' reaction);
- ``W_M = (M (v_{n+1} - v_n)) . (v_n + v_{n+1}) / 2`` on the held DOFs (the
  inertial part: with a lumped mass exactly the change of the held DOFs'
  kinetic energy, which ``E`` counts).

Only DOFs held at both ends of the step count (a boundary released during
the step moves freely from then on; fixed DOFs do no work). It is evaluated
on every step while a drive may be moving (one extra gradient per step), and
the bound is checked on the same steps as without drives. When the last
drive stops moving or is released, the energy then becomes the new
reference, as before. A drive held still does no work, so a crushed body
held still is bounded by the energy it was given.

Examples
--------
An observer that keeps the tip's height after every step:

>>> import fem_elastic as fe
>>> class TipHeight(fe.dynamics.Observer):
...     def on_start(self, run):
...         self.z = []
...     def on_step(self, run, event):
...         self.z.append(run.model.to_vertices(event.after.x)[-1, 2])
>>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
...                  body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
...                  fixed="left", gravity=(0, 0, -9.81))
>>> tip = TipHeight()
>>> _ = fe.simulate(model, fe.ImplicitEuler(), dt=0.01, steps=3, observers=[tip])
>>> len(tip.z), bool(tip.z[2] < tip.z[1] < tip.z[0])  # falling
(3, True)
"""

from __future__ import annotations

import logging
import math
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..physics.inversion import DetF
from .checkpoint import _Snapshot, frame_record, model_checkpoint_state
from .state import State

if TYPE_CHECKING:  # for annotations only (simulate imports this module)
    from ..errors import Diverged
    from .simulate import Run

__all__ = ["Observer", "StepEvent", "BlowUpWatch", "InversionWatch", "InversionWarning", "Recorder",
           "Callback", "CheckpointWriter", "ProgressBar"]

log = logging.getLogger(__name__)


class Observer:
    """What :func:`fe.simulate` calls around every accepted step; override the hooks you need.

    ``run`` is the loop's context: ``run.model``, ``run.integrator``,
    ``run.dt`` (s), ``run.n_steps``, ``run.state`` (the last accepted State;
    in ``on_step``, the state before the step: ``event.after`` is the new one),
    ``run.steps_done``, ``run.energies(state)`` (kinetic, potential, total in J),
    ``run.frames``, ``run.stats``, ``run.cuts`` and ``run.diverged(reason)``,
    which builds the :class:`fe.Diverged` to raise.
    """

    def on_start(self, run: Run) -> None:
        """Before the first step of this call (``run.steps_done`` > 0 after a resume)."""

    def on_step(self, run: Run, event: StepEvent) -> None:
        """After step ``event.k`` was accepted; ``event.after`` is the new state."""

    def on_finish(self, run: Run) -> None:
        """After the last step."""

    def on_interrupt(self, run: Run) -> None:
        """On Ctrl-C, after the last step completed (``run.state``)."""

    def on_failure(self, run: Run, error: Diverged) -> None:
        """When ``error`` (a :class:`fe.Diverged` or :class:`fe.StepFailed`) ends the run.

        ``run.state`` is the last good state; ``error.trajectory`` the frames so
        far. The error propagates after every observer's hook (an exception
        raised here is logged, never raised in its place).
        """

    def on_close(self, run: Run) -> None:
        """Always, last: release what the observer holds (a progress bar, a file)."""


@dataclass
class StepEvent:
    """One accepted step, as the observers see it.

    Attributes
    ----------
    k : int
        Index of the step (0-based): ``k + 1`` steps are done.
    before, after : State
        The states before and after it.
    last : bool
        True for the run's last step.
    record : bool
        True when a frame is recorded after it (every ``record_every`` steps and the last).
    """

    k: int
    before: State
    after: State
    last: bool
    record: bool
    _run: Any = None  # the run (fem_elastic.dynamics.run) that made the event
    _energies: tuple | None = None

    def energies(self) -> tuple[float, float, float]:
        """Kinetic, potential and total energy (J) after the step, computed once per step."""
        if self._energies is None:
            self._energies = self._run.energies(self.after)
        return self._energies


class BlowUpWatch(Observer):
    """Stops a run whose state or energy blows up (see the module notes for the bound).

    Parameters
    ----------
    energy_growth : float
        The bound on the energy growth in units of the scene's energy scale;
        ``inf`` switches the energy check off (non-finite values are still caught).
    check_every : int
        Steps between energy checks (frames and the release of a drive are always checked).

    Attributes
    ----------
    e_ref, scale : float
        The bound's reference energy and scale (J).
    driving : bool
        Whether a driven boundary is moving the body.
    work, work_abs : float
        The work the driven boundaries did on the body since ``e_ref`` (J),
        and the sum of the magnitudes of its per-step increments (J).
    """

    def __init__(self, energy_growth: float = 1.0, check_every: int = 1):
        self.energy_growth = energy_growth
        self.check_every = max(1, int(check_every))
        self.e_ref = self.scale = 0.0
        self.work = self.work_abs = 0.0
        self.driving = False
        self._force: tuple[State, np.ndarray] | None = None  # (state, drive force on every DOF (N)) of the last state it was needed at

    def on_start(self, run) -> None:
        self._force = None
        if run.resumed_from is not None:  # the bookkeeping the checkpoint carried
            ck = run.resumed_from
            self.e_ref, self.scale, self.driving = ck.e_ref, ck.scale, ck.driving
            self.work, self.work_abs = ck.work, ck.work_abs
            return
        e0 = run.energies(run.state)
        self.e_ref, self.scale = e0[2], energy_scale(run.model, run.state, e0)
        self.work = self.work_abs = 0.0
        self.driving = run.model.driving(run.state.t)

    def on_step(self, run, event: StepEvent) -> None:
        new = event.after
        if not (np.isfinite(new.x).all() and np.isfinite(new.v).all()):
            raise run.diverged("non-finite positions or velocities")
        driving = run.model.driving(new.t)
        if self.driving or driving:
            dw = self._drive_work(run, event.before, new)
            self.work += dw
            self.work_abs += abs(dw)
        was_driving, self.driving = self.driving, driving
        released = was_driving and not self.driving
        if not (event.record or released or (event.k + 1) % self.check_every == 0):
            return
        e = event.energies()[2]
        if not math.isfinite(e):
            raise run.diverged("the energy is not finite (an inverted element?)")
        scale = max(self.scale, self.work_abs)
        if e > self.e_ref + self.work + self.energy_growth * scale:
            fed = f" plus the {self.work:.6g} J the driven boundaries did" if self.work_abs else ""
            source = "" if self.work_abs else " with no energy source"
            raise run.diverged(
                f"the total energy grew from {self.e_ref:.6g} J{fed} to {e:.6g} J (more than "
                f"{self.energy_growth:g} x the scene's energy scale {scale:.3g} J){source}"
            )
        if released:  # the drive stopped: the energy from here on is the budget
            self.e_ref, self.scale, self.work = e, max(scale, abs(e)), 0.0
            self.work_abs = 0.0

    def _drive_work(self, run, before: State, after: State) -> float:
        """The work (J) the driven boundaries did on the body over one step (module notes)."""
        model = run.model
        # the DOFs each drive holds (only its driven components); a node on two driven
        # boundaries is counted once
        dofs = [d.ravel()[c.ravel()] for (motion, _, d), c in zip(model.driven, model._driven_components)
                if motion.active(before.t) and motion.active(after.t)]
        if not dofs:
            return 0.0
        held = np.unique(np.concatenate(dofs))
        g0 = self._drive_force(run, before)[held]
        g1 = self._drive_force(run, after)[held]
        w_pi = 0.5 * float((g0 + g1) @ (after.x[held] - before.x[held]))
        dv = after.v - before.v
        m_dv = model.lumped_mass * dv if run.mass == "lumped" else model.mass_matrix @ dv
        w_m = 0.5 * float(m_dv[held] @ (before.v[held] + after.v[held]))
        return w_pi + w_m

    def _drive_force(self, run, state: State) -> np.ndarray:
        """``dPi/dx - f_damping`` (N) at ``state``, every DOF; kept for the next step's start."""
        if self._force is not None and self._force[0] is state:
            return self._force[1]
        g = run.model.gradient(state.x)
        fd = run.model.damping_force(state.x, state.v, run.mass)
        if fd is not None:
            g = g - fd
        self._force = (state, g)
        return g


class InversionWarning(UserWarning):
    """Accepted steps of a run had inverted elements (det F <= 0) (see :class:`InversionWatch`)."""


class InversionWatch(Observer):
    """Measures the smallest det F after every accepted step, and warns about inversions.

    The minimum over the body's quadrature points (per tet for P1 and spring
    bodies, :class:`fem_elastic.physics.inversion.DetF`) goes to
    ``run.stats["min_det_F"]`` (``Trajectory.step_stats``, its summary and
    ``summary.json`` carry it). A run that completes after steps with
    inverted elements (det F <= 0) gets one :class:`InversionWarning` with
    their count: a material whose energy is +inf there (Neo-Hookean) forbids
    them, and a finite one (linear, StVK, corotated, stable Neo-Hookean)
    passes through them silently otherwise.

    Attributes
    ----------
    worst : int
        The most inverted points (or tets) after one step, in this session.
    final : int
        Inverted points after the last step observed.
    """

    def __init__(self):
        self.det = None
        self.worst = self.final = 0

    def on_start(self, run) -> None:
        self.det = DetF(run.model)
        self.worst = self.final = 0

    def on_step(self, run, event: StepEvent) -> None:
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            J = self.det(event.after.x)
        run.stats["min_det_F"][event.k] = float(J.min()) if J.size else 1.0
        self.final = int(np.count_nonzero(J <= 0.0))
        self.worst = max(self.worst, self.final)

    def on_finish(self, run) -> None:
        det = run.stats["min_det_F"][:run.steps_done]
        steps = int(np.count_nonzero(det <= 0.0))  # every session of a resumed run
        if not steps:
            return
        k = int(np.argmin(det))
        where = self.det.where
        e = run.model.energy(run.state.x)
        ends = (f"the final state has {self.final} inverted {where}" if self.final
                else "the final state has none")
        material = type(getattr(run.model.body_potential, "material", run.model.body_potential)).__name__
        allows = ("its energy is +inf there: the material forbids inversion" if not math.isfinite(e)
                  else f"{material} gives inverted elements a finite energy, so nothing else stops it")
        warnings.warn(
            f"{steps} of {run.steps_done} steps ended with inverted elements (det F <= 0; at most "
            f"{self.worst} {where} at once, the smallest det F = {det[k]:.3g} after step {k}); "
            f"{ends} ({allows}). The results there are not physical: refine the mesh, lower dt, or "
            "use a material that resists inversion (fe.StableNeoHookean with a larger nu, fe.NeoHookean "
            "with an implicit integrator).",
            InversionWarning, stacklevel=3,
        )


def energy_scale(model, state, energies) -> float:
    """The scene's energy scale (J) for :class:`BlowUpWatch`'s bound (see the module notes)."""
    ke, pe, _ = energies
    el = model.body_potential.energy(state.x)
    scale = max(abs(ke), abs(pe), abs(el) if math.isfinite(el) else 0.0)
    if model.loads:
        load = float(np.linalg.norm(model.external_force().reshape(-1, 3).sum(axis=0)))
        load = max(load, float(np.abs(model.external_force()).sum()) / 3.0)
        nodes = state.x.reshape(-1, 3)
        size = float(np.ptp(nodes, axis=0).max())
        scale = max(scale, load * size)  # the work of the loads over the body's size
        for obstacle in model.obstacles:  # ... and carrying the body onto each obstacle
            reach = float(np.max(obstacle.signed_distance(nodes)))
            scale = max(scale, load * (reach + size))
    return max(scale, 1e3 * model.energy_roundoff())


class Recorder(Observer):
    """Records the Trajectory's frames: the initial state, then every ``record_every`` steps.

    Each frame is one flat record (:func:`fem_elastic.dynamics.checkpoint.frame_record`)
    appended to ``run.frames``: time, energies, momenta, vertex displacements and velocities.
    """

    def on_start(self, run) -> None:
        if run.resumed_from is None:
            self.record(run, run.state, run.energies(run.state))

    def on_step(self, run, event: StepEvent) -> None:
        if event.record:
            self.record(run, event.after, event.energies())

    @staticmethod
    def record(run, state, e) -> None:
        m = run.model
        run.frames.append(frame_record(
            state.t, m.to_vertices(state.x - m.X), m.to_vertices(state.v), e[0], e[1],
            m.linear_momentum(state.v), m.angular_momentum(state.x, state.v),
        ))


class Callback(Observer):
    """Calls ``callback(k, state)`` after every step; an exception there stops the run."""

    def __init__(self, callback):
        self.callback = callback

    def on_step(self, run, event: StepEvent) -> None:
        self.callback(event.k, event.after)


class CheckpointWriter(Observer):
    """Writes checkpoints (:class:`fem_elastic.dynamics.checkpoint.Checkpointer`) of the run.

    After every step it takes everything the loop holds as one snapshot, so a
    Ctrl-C from then on checkpoints that step, never a half-updated one; it
    writes every ``checkpointer.every`` steps, on Ctrl-C, when a
    :class:`fe.Diverged` or :class:`fe.StepFailed` ends the run (the last good
    step: ``fe.load_checkpoint`` reads it back) and at the end.

    Parameters
    ----------
    checkpointer : Checkpointer
    watch : BlowUpWatch
        Whose energy bound the checkpoint carries.
    """

    def __init__(self, checkpointer, watch: BlowUpWatch):
        self.ckpt, self.watch = checkpointer, watch
        self.snap: _Snapshot | None = None

    def _snapshot(self, run, steps_done: int, state) -> _Snapshot:
        return _Snapshot(steps_done, state, len(run.frames), len(run.cuts), self.watch.e_ref,
                         self.watch.scale, self.watch.driving, run.wall_time(),
                         run.integrator.checkpoint_state(state), self.watch.work, self.watch.work_abs,
                         model_checkpoint_state(run.model))

    def on_start(self, run) -> None:
        self.snap = self._snapshot(run, run.steps_done, run.state)

    def on_step(self, run, event: StepEvent) -> None:
        self.snap = self._snapshot(run, event.k + 1, event.after)
        if self.ckpt.due(event.k + 1) and not event.last:
            self.ckpt.write(self.snap, run.frames, run.stats, run.cuts)

    def on_finish(self, run) -> None:
        if self.ckpt.last_step < run.n_steps:
            assert self.snap is not None  # on_start took the first one
            self.snap.wall_time = run.wall_time()
            self.ckpt.write(self.snap, run.frames, run.stats, run.cuts)

    def on_failure(self, run, error) -> None:
        # the snapshot of the last good step (an observer after this one may have rejected the
        # step this one saw: then its snapshot is not the last good state, and is not written)
        if self.snap is not None and self.snap.step == run.steps_done and self.snap.step > self.ckpt.last_step:
            self.ckpt.write(self.snap, run.frames, run.stats, run.cuts)
            log.info("run stopped at step %d (%s): checkpoint of the last good step (t = %.6g s) in %s",
                     run.steps_done, getattr(error, "reason", error), self.snap.state.t, self.ckpt.directory)

    def on_interrupt(self, run) -> None:
        if self.snap is not None and self.snap.step > self.ckpt.last_step:
            self.ckpt.write(self.snap, run.frames, run.stats, run.cuts)
            log.warning("interrupted: checkpoint after %d of %d steps (t = %.6g s) in %s; "
                        "resume=True continues from it", self.snap.step, run.n_steps,
                        self.snap.state.t, self.ckpt.directory)


class ProgressBar(Observer):
    """A tqdm progress bar over the steps (``pip install fem_elastic[cli]``)."""

    def __init__(self):
        self.bar = None

    def on_start(self, run) -> None:
        try:
            from tqdm.auto import tqdm
        except ImportError:
            log.warning("progress=True needs tqdm (pip install fem_elastic[cli]); running without a bar")
            return
        self.bar = tqdm(total=run.n_steps, initial=run.steps_done, unit="step", desc="simulate")

    def on_step(self, run, event: StepEvent) -> None:
        if self.bar is not None:
            self.bar.update(1)

    def on_close(self, run) -> None:
        if self.bar is not None:
            self.bar.close()
