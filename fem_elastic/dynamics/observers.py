"""Observers of a simulation: what :func:`fe.simulate` does with each accepted step.

``simulate`` is a loop that takes a step with the integrator and hands it to
its observers, in order. Each is an :class:`Observer` with three hooks:

- ``on_start(run)``: before the first step (after a resume, at the checkpoint's step);
- ``on_step(run, event)``: after every accepted step; raising
  ``run.diverged(reason)`` there stops the run with :class:`fe.Diverged`;
- ``on_finish(run)``: after the last step, or ``on_interrupt(run)`` on Ctrl-C;
- ``on_close(run)``: always, last (release a progress bar or a file).

The built-in ones, in the order simulate calls them:

- :class:`BlowUpWatch`: non-finite states, non-finite energy (an inverted
  element), and energy growth beyond a bound while nothing feeds energy in;
  the one place a finished step is judged diverged;
- :class:`Recorder`: the frames of the Trajectory;
- :class:`Callback`: the user's ``callback(step, state)``;
- any observers the caller passes (``simulate(..., observers=[...])``, e.g. a
  :class:`fem_elastic.app.output.SeriesWriter`);
- :class:`CheckpointWriter`: checkpoints every N steps, on Ctrl-C and at the end;
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
a kicked 100 GPa beam). While a driven boundary moves it feeds energy in, and
only non-finite values are checked.

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
from dataclasses import dataclass

import numpy as np

from .checkpoint import _Snapshot, frame_record
from .state import State

__all__ = ["Observer", "StepEvent", "BlowUpWatch", "Recorder", "Callback", "CheckpointWriter",
           "ProgressBar"]

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

    def on_start(self, run) -> None:
        """Before the first step of this call (``run.steps_done`` > 0 after a resume)."""

    def on_step(self, run, event: StepEvent) -> None:
        """After step ``event.k`` was accepted; ``event.after`` is the new state."""

    def on_finish(self, run) -> None:
        """After the last step."""

    def on_interrupt(self, run) -> None:
        """On Ctrl-C, after the last step completed (``run.state``)."""

    def on_close(self, run) -> None:
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
    _run: object = None
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
        Whether a driven boundary is moving the body (its energy is then not bounded).
    """

    def __init__(self, energy_growth: float = 1.0, check_every: int = 1):
        self.energy_growth = energy_growth
        self.check_every = max(1, int(check_every))
        self.e_ref = self.scale = 0.0
        self.driving = False

    def on_start(self, run) -> None:
        if run.resumed_from is not None:  # the bookkeeping the checkpoint carried
            ck = run.resumed_from
            self.e_ref, self.scale, self.driving = ck.e_ref, ck.scale, ck.driving
            return
        e0 = run.energies(run.state)
        self.e_ref, self.scale = e0[2], energy_scale(run.model, run.state, e0)
        self.driving = run.model.driving(run.state.t)

    def on_step(self, run, event: StepEvent) -> None:
        new = event.after
        if not (np.isfinite(new.x).all() and np.isfinite(new.v).all()):
            raise run.diverged("non-finite positions or velocities")
        was_driving, self.driving = self.driving, run.model.driving(new.t)
        released = was_driving and not self.driving
        if not (event.record or released or (event.k + 1) % self.check_every == 0):
            return
        e = event.energies()[2]
        if not math.isfinite(e):
            raise run.diverged("the energy is not finite (an inverted element?)")
        if released:  # the drive stopped: the energy from here on is the budget
            self.e_ref, self.scale = e, max(self.scale, abs(e))
        elif not self.driving and e > self.e_ref + self.energy_growth * self.scale:
            raise run.diverged(
                f"the total energy grew from {self.e_ref:.6g} J to {e:.6g} J (more than "
                f"{self.energy_growth:g} x the scene's energy scale {self.scale:.3g} J) with no "
                "energy source"
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
    writes every ``checkpointer.every`` steps, on Ctrl-C and at the end.

    Parameters
    ----------
    checkpointer : Checkpointer
    watch : BlowUpWatch
        Whose energy bound the checkpoint carries.
    """

    def __init__(self, checkpointer, watch: BlowUpWatch):
        self.ckpt, self.watch = checkpointer, watch
        self.snap = None

    def _snapshot(self, run, steps_done: int, state) -> _Snapshot:
        return _Snapshot(steps_done, state, len(run.frames), len(run.cuts), self.watch.e_ref,
                         self.watch.scale, self.watch.driving, run.wall_time(),
                         run.integrator.checkpoint_state(state))

    def on_start(self, run) -> None:
        self.snap = self._snapshot(run, run.steps_done, run.state)

    def on_step(self, run, event: StepEvent) -> None:
        self.snap = self._snapshot(run, event.k + 1, event.after)
        if self.ckpt.due(event.k + 1) and not event.last:
            self.ckpt.write(self.snap, run.frames, run.stats, run.cuts)

    def on_finish(self, run) -> None:
        if self.ckpt.last_step < run.n_steps:
            self.snap.wall_time = run.wall_time()
            self.ckpt.write(self.snap, run.frames, run.stats, run.cuts)

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
