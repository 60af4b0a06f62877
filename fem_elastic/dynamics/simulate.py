"""The simulation loop: take a step, hand it to the observers, repeat.

``simulate`` advances a State with an integrator. Everything else it does
with a step is an observer (:mod:`fem_elastic.dynamics.observers`): the
blow-up watch (non-finite values, an inverted element, energy growth with no
energy source; its bound is explained there), the recorder of the
Trajectory's frames, the user's callback and observers, checkpoints and the
progress bar. A step the integrator cannot take (an implicit step that fails
even after cutting dt) and a step the watch rejects both end the run with one
:class:`fe.Diverged`, built by :meth:`Run.diverged`, which carries the step,
time, reason, the last good state and the trajectory recorded so far.

Any other error raised inside a step (a user motion that raises, a linear
solver that gives up, a contact routine's error, a ``LinAlgError``: anything
but ``KeyboardInterrupt`` and ``SystemExit``) ends the run the same way, as a
:class:`fe.StepFailed` (a subclass of ``Diverged``, built by :meth:`Run.failed`)
whose ``__cause__`` is the original error. Whatever ends the run with a
``Diverged``, every observer's ``on_failure(run, err)`` hook is called first
(the checkpoint of the last good step is written, a ``SeriesWriter`` finishes
its series as ``"diverged"`` or ``"failed"``).
"""

from __future__ import annotations

import logging
import math
import numbers
import time
import warnings
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

import numpy as np

from ..errors import Diverged, InvalidMesh, InvalidParameter, StepFailed
from .checkpoint import Checkpoint, restore_model_state, trajectory_from_records
from .contact_watch import ContactWatch, contact_stats, has_contact_diagnostics
from .integrators.base import check_dt, check_state
from .observers import (BlowUpWatch, Callback, CheckpointWriter, InversionWatch, ProgressBar, Recorder,
                        StepEvent)
from .state import State
from .trajectory import COUNT_FIELDS, STEP_FIELDS, Trajectory

if TYPE_CHECKING:  # for annotations only
    from ..physics.multibody import AnyModel
    from .integrators.base import Integrator
    from .observers import Observer

__all__ = ["simulate", "StabilityWarning", "Run", "MAX_STEPS"]

log = logging.getLogger(__name__)


class StabilityWarning(UserWarning):
    """An explicit time step above the scheme's stability limit."""


class SimulateOptions(TypedDict, total=False):
    """The keywords of :func:`simulate` (for ``BuiltRun.simulate(**options)``)."""

    t_end: float | None
    steps: int | None
    state: State | None
    record_every: int
    progress: bool
    check_stability: bool
    energy_growth: float
    callback: Callable[[int, State], object] | None
    checkpoint_dir: str | os.PathLike[str] | None
    checkpoint_every: int
    resume: bool | Checkpoint
    observers: Sequence[Observer]


def simulate(
    model: AnyModel,
    integrator: Integrator,
    dt: float,
    *,
    t_end: float | None = None,
    steps: int | None = None,
    state: State | None = None,
    record_every: int = 1,
    progress: bool = False,
    check_stability: bool = True,
    energy_growth: float = 1.0,
    callback: Callable[[int, State], object] | None = None,
    checkpoint_dir: str | os.PathLike[str] | None = None,
    checkpoint_every: int = 0,
    resume: bool | Checkpoint = False,
    observers: Sequence[Observer] = (),
) -> Trajectory:
    """Integrate ``model`` in time.

    Parameters
    ----------
    model : Model
    integrator : Integrator
        e.g. ``fe.ImplicitEuler()`` or ``fe.SymplecticEuler()``.
    dt : float
        Time step (s), > 0.
    t_end : float, optional
        End time (s), absolute: the run takes ``ceil((t_end - t0) / dt)``
        steps from the initial state's time ``t0`` (ending on the first
        multiple of dt at or after ``t_end``). Give exactly one of ``t_end`` and ``steps``.
    steps : int, optional
        Number of steps.
    state : State, optional
        Initial state; default ``fe.State.rest(model)`` (a ``fe.MultiBody``: its bodies'
        initial velocities).
    record_every : int
        Record a frame every this many steps (the first and last are always recorded).
    progress : bool
        Show a tqdm progress bar (needs ``pip install fem_elastic[cli]``).
    check_stability : bool
        For explicit schemes, estimate the critical time step
        (:func:`fe.critical_time_step`) and warn (:class:`StabilityWarning`)
        when ``dt`` exceeds it (not for schemes that sub-step, ``substep=True``).
    energy_growth : float
        Divergence bound on the energy growth, in units of the scene's
        energy scale (:mod:`fem_elastic.dynamics.observers`); ``inf`` switches the check off.
    callback : callable, optional
        ``callback(step, state)`` after every step (e.g. to write output);
        an exception raised there stops the run and propagates.
    checkpoint_dir : str or os.PathLike, optional
        Write checkpoints to this directory (:mod:`fem_elastic.dynamics.checkpoint`):
        every ``checkpoint_every`` steps, on Ctrl-C (the last step completed)
        and at the end. Each is written atomically; the recorded history is
        appended, not rewritten.
    checkpoint_every : int
        Steps between checkpoints (0: only on Ctrl-C and at the end).
    resume : bool or Checkpoint
        Continue from the checkpoint in ``checkpoint_dir`` if there is one
        (else start afresh), or from this :class:`fe.Checkpoint` of it, read
        already with :func:`fe.load_checkpoint`. It must come from the same run: the same model,
        integrator and settings, dt, steps, ``record_every`` and initial
        state (else :class:`fe.InvalidParameter`). The Trajectory returned is
        the whole run's, bit for bit what the uninterrupted run records
        (wall times aside); a finished checkpoint returns it at once.
        Without ``resume`` an earlier checkpoint there is replaced.
    observers : sequence of Observer
        More :class:`fem_elastic.dynamics.Observer` objects to hand every
        accepted step to, after the blow-up watch, the recorder and the callback,
        before the checkpoint (e.g. a :class:`fem_elastic.app.output.SeriesWriter`).

    Returns
    -------
    Trajectory
        ``cuts`` lists every failed attempt of a step (implicit Newton
        failures halve dt, explicit sub-stepping re-estimates its step) and
        ``dt_cuts`` counts the steps that needed one.

    Raises
    ------
    Diverged
        With ``step``, ``time``, ``reason``, ``last_good_state`` and
        ``trajectory`` (the frames recorded up to the last good state).
    StepFailed
        (a ``Diverged``) when the step raised an error of its own (a user
        motion, a linear solver, a contact routine): the same attributes, and
        the original error as ``__cause__``. With ``checkpoint_dir``, a
        checkpoint of the last good step is written before either is raised.
    InversionWarning
        (a warning, the run goes on) when accepted steps had inverted elements
        (det F <= 0); ``step_stats["min_det_F"]`` holds each step's minimum.
    KeyboardInterrupt
        Ctrl-C, after writing a checkpoint of the last step completed (with ``checkpoint_dir``).

    Examples
    --------
    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
    ...                  fixed="left", gravity=(0, 0, -9.81))
    >>> run = fe.simulate(model, fe.ImplicitEuler(), dt=0.01, steps=5)
    >>> run.times.shape, run.displacement.shape, bool(run.displacement[-1, :, 2].min() < 0)
    ((6,), (6, 20, 3), True)
    """
    h = check_dt(dt)
    if state is None:  # a MultiBody starts its bodies with their initial velocities
        v0 = getattr(model, "initial_velocity", None)
        state = State.rest(model) if v0 is None else State.rest(model, velocity=v0().reshape(-1, 3))
    check_state(model, state)
    n_steps = _n_steps(h, t_end, steps, state.t)
    _check_options(integrator, callback, record_every, energy_growth, observers)
    # before the first step: a Newton-based scheme assembles the tangent and solves with it
    memory_check = getattr(model, "check_tangent_memory", None)
    if memory_check is not None and not getattr(integrator, "explicit", True) and hasattr(integrator, "linear_solver"):
        memory_check("auto")
    if check_stability and getattr(integrator, "explicit", False) and not getattr(integrator, "substep", False):
        _warn_if_unstable(model, integrator, h)
    ckpt, start = _checkpointer(model, integrator, h, n_steps, int(record_every), state, energy_growth,
                                checkpoint_dir, checkpoint_every, resume, 9 + 6 * model.mesh.p.shape[1])
    run = Run(model, integrator, h, n_steps, int(record_every), state, start)
    watch = BlowUpWatch(energy_growth, check_every=min(int(record_every), 10))
    contact_watch = [ContactWatch()] if has_contact_diagnostics(model) else []  # before the writers
    chain = [watch, InversionWatch(), Recorder(), *contact_watch,
             *([Callback(callback)] if callback is not None else []),
             *observers,
             *([CheckpointWriter(ckpt, watch)] if ckpt is not None else []),
             *([ProgressBar()] if progress else [])]
    if start is not None:
        log.info("resuming at step %d of %d (t = %.6g s) from %s", start.step, n_steps, start.time,
                 ckpt.directory)
    try:
        for obs in chain:
            obs.on_start(run)
        for k in range(run.steps_done, n_steps):
            new = run.take_step(k)
            event = StepEvent(k, run.state, new, last=k == n_steps - 1,
                              record=(k + 1) % run.record_every == 0 or k == n_steps - 1, _run=run)
            for obs in chain:
                obs.on_step(run, event)
            run.state, run.steps_done = new, k + 1
        run.stop_clock()
        for obs in chain:
            obs.on_finish(run)
    except Diverged as err:  # StepFailed too: the observers keep what can be kept, then it propagates
        run.stop_clock()
        for obs in chain:
            hook = getattr(obs, "on_failure", None)  # optional: observers written before it existed
            if hook is None:
                continue
            try:
                hook(run, err)
            except Exception as exc:  # never hide the error that ended the run behind this one
                log.error("%s.on_failure failed (%s: %s) after: %s", type(obs).__name__,
                          type(exc).__name__, exc, err.reason)
        raise
    except KeyboardInterrupt:
        for obs in chain:
            obs.on_interrupt(run)
        raise
    finally:
        for obs in chain:
            obs.on_close(run)
    return run.trajectory(completed=True)


def _checkpointer(model, integrator, h, n_steps, record_every, state0, energy_growth, directory,
                  every, resume, frame_size):
    """The run's Checkpointer and the checkpoint it resumes from (None, None without a directory)."""
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 0:
        raise InvalidParameter(
            f"checkpoint_every must be an integer >= 0 (steps; 0: only on Ctrl-C and at the end), "
            f"got {every!r}."
        )
    if directory is None:
        if every or resume:
            raise InvalidParameter(
                "checkpoint_every and resume need checkpoint_dir=DIR, the directory the "
                "checkpoints are written to (and resumed from)."
            )
        return None, None
    from .checkpoint import CHECKPOINT_NAME, Checkpointer, check_resumable, load_checkpoint, run_fingerprint

    d = Path(directory)
    if d.exists() and not d.is_dir():
        raise InvalidParameter(f"checkpoint_dir {d} is a file; give a directory.")
    fingerprint = run_fingerprint(model, integrator, h, n_steps, record_every, state0, energy_growth)
    start = None
    if isinstance(resume, Checkpoint):  # read already by the caller
        start = resume
        check_resumable(start, fingerprint)
    elif resume and (d / CHECKPOINT_NAME).is_file():
        start = load_checkpoint(d)
        check_resumable(start, fingerprint)
    elif resume:
        log.info("no checkpoint in %s: starting the run from its initial state", d)
    return Checkpointer(d, int(every), fingerprint, frame_size, resume=start), start


#: Most steps one call of simulate takes (its per-step statistics are 10 arrays of this length).
MAX_STEPS = 10**8


def _n_steps(h, t_end, steps, t0):
    if (t_end is None) == (steps is None):
        raise InvalidParameter("give exactly one of t_end (s) and steps, e.g. t_end=1.0.")
    if steps is not None:
        if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
            raise InvalidParameter(f"steps must be an integer >= 1, got {steps!r}.")
        n = int(steps)
    else:
        if isinstance(t_end, bool) or not isinstance(t_end, numbers.Real) or not math.isfinite(t_end):
            raise InvalidParameter(f"t_end must be a finite time (s), got {t_end!r}.")
        if t_end <= t0:
            raise InvalidParameter(
                f"t_end = {t_end} s is not after the initial state's time {t0} s; t_end is the "
                "absolute end time (use steps=N for a number of steps)."
            )
        # the first multiple of dt at or after t_end; 1e-9 absorbs round-off in the division
        ratio = (t_end - t0) / h
        if not ratio <= MAX_STEPS:  # also inf: t_end - t0 overflows, or dt is tiny
            raise InvalidParameter(
                f"{ratio:.3g} steps asked (t_end = {t_end:g} s at dt = {h:g} s); at most "
                f"{MAX_STEPS:.0e} per call: raise dt or split the run (simulate(..., "
                "state=run.final_state))."
            )
        n = int(math.ceil(ratio - 1e-9))
    if n > MAX_STEPS:
        raise InvalidParameter(
            f"{n:.3g} steps asked (t_end / dt); at most {MAX_STEPS:.0e} per call: raise dt or "
            "split the run (simulate(..., state=run.final_state))."
        )
    return n


def _warn_if_unstable(model, integrator, h):
    from ..solvers.modal import critical_time_step

    try:
        dt_crit = critical_time_step(model, integrator)
    except Exception as err:  # an estimate failing must not stop a run; say so
        log.warning("could not estimate the critical time step: %s", err)
        return
    if h > dt_crit:
        if dt_crit == 0.0:
            msg = (f"{integrator.name} is unstable at every time step on an undamped body (its "
                   "energy grows each step); add damping (fe.Rayleigh) or use fe.SymplecticEuler.")
        else:
            msg = (f"dt = {h:.4g} s exceeds {integrator.name}'s critical time step "
                   f"{dt_crit:.4g} s (from the highest natural frequency): expect a blow-up. "
                   f"Use dt <= {dt_crit:.4g} s or an implicit integrator.")
        warnings.warn(msg, StabilityWarning, stacklevel=3)


class Run:
    """The loop's context, as :func:`simulate` and its observers share it.

    Attributes
    ----------
    model, integrator
    dt : float
        Time step (s).
    n_steps, record_every : int
    state : State
        The last accepted state (during ``on_step``: the state before the step observed).
    steps_done : int
        Steps accepted so far, over every session of a resumed run.
    frames : list of numpy.ndarray
        The recorded frame records (:func:`fem_elastic.dynamics.checkpoint.frame_record`).
    stats : dict of numpy.ndarray
        ``(n_steps,)`` per-step statistics (``Trajectory.step_stats``).
    cuts : list of dict
        Every failed attempt of a step: ``step``, ``t`` (s), ``dt`` (s), ``reason``.
    resumed_from : Checkpoint or None
        The checkpoint the run continues from.
    """

    def __init__(self, model, integrator, dt, n_steps, record_every, state, resumed_from=None):
        self.model, self.integrator, self.dt = model, integrator, dt
        self.n_steps, self.record_every = n_steps, record_every
        self.mass = "lumped" if getattr(integrator, "explicit", True) else getattr(integrator, "mass", "lumped")
        self.stats = {k: np.zeros(n_steps, dtype=np.int64) for k in COUNT_FIELDS}
        self.stats.update({k: np.zeros(n_steps) for k in STEP_FIELDS[len(COUNT_FIELDS):]})
        self.stats["min_det_F"][:] = np.nan  # measured by the InversionWatch on every accepted step
        if has_contact_diagnostics(model):  # min distance, active contacts, force (ContactWatch)
            self.stats.update(contact_stats(n_steps))
        self.resumed_from = resumed_from
        self.t0 = float(state.t)  # the run's start: step k ends at exactly t0 + (k + 1) dt
        self.state, self.steps_done, self.frames, self.cuts, self._wall0 = state, 0, [], [], 0.0
        if resumed_from is not None:  # everything the loop had in hand at the checkpoint
            ck = resumed_from
            self.state, self.steps_done, self._wall0 = ck.state, ck.step, ck.wall_time
            self.frames, self.cuts = list(ck.frames), list(ck.cuts)
            for name, values in ck.step_stats.items():
                self.stats[name][:ck.step] = values
            integrator.restore_state(ck.state, ck.integrator_state)
            restore_model_state(model, ck.model_state)
        self._t_start, self._t_stop = time.perf_counter(), None

    def wall_time(self) -> float:
        """Wall time of the run so far (s), over every session of a resumed run."""
        return self._wall0 + (self._t_stop or time.perf_counter()) - self._t_start

    def stop_clock(self) -> None:
        """End the run's wall time: the checkpoint and the Trajectory report the same."""
        self._t_stop = time.perf_counter()

    def energies(self, state) -> tuple[float, float, float]:
        """Kinetic (with the integrator's mass), potential and total energy of ``state`` (J)."""
        ke = self.model.kinetic_energy(state.v, self.mass)
        pe = self.model.energy(state.x)
        return ke, pe, ke + pe

    def take_step(self, k: int) -> State:
        """Step ``k`` from ``self.state`` with the integrator; its statistics and cuts are kept."""
        t0 = time.perf_counter()
        try:
            new = self.integrator.step(self.model, self.state, self.dt)
        except Diverged as err:
            self._collect_cuts(k, getattr(self.integrator, "last_stats", None))
            raise self.diverged(err.reason or str(err), detail=str(err)) from err
        except (InvalidParameter, InvalidMesh):  # a setting the first step finds wrong: the caller's
            raise
        except Exception as err:  # a step's own error ends the run as honestly (not Ctrl-C)
            self._collect_cuts(k, getattr(self.integrator, "last_stats", None))
            raise self.failed(err) from err
        self.stats["seconds_step"][k] = time.perf_counter() - t0
        t_exact = self.t0 + (k + 1) * self.dt  # the step's time n dt, not a sum of n rounded dt
        if new.t != t_exact:
            # in place, before anyone but the integrator has seen it: integrators that remember
            # their last state (Newmark's acceleration) know it by identity
            object.__setattr__(new, "t", t_exact)
        st = self.integrator.last_stats
        for name in COUNT_FIELDS:
            self.stats[name][k] = getattr(st, name, 1 if name == "substeps" else 0)
        for name in ("linearize", "solve", "line_search"):
            self.stats[f"seconds_{name}"][k] = st.seconds.get(name, 0.0)
        self._collect_cuts(k, st)
        return new

    def _collect_cuts(self, k, stats) -> None:
        for t, dt, reason in getattr(stats, "cuts", ()):
            self.cuts.append({"step": int(k), "t": float(t), "dt": float(dt), "reason": str(reason)})

    def trajectory(self, completed: bool = False) -> Trajectory:
        """The Trajectory of the steps accepted so far (``completed``: the run's final one)."""
        k = self.steps_done
        size = 9 + 6 * self.model.mesh.p.shape[1]
        traj = trajectory_from_records(
            np.reshape(self.frames, (len(self.frames), size)),
            step_stats={name: v[:k] for name, v in self.stats.items()}, wall_time=self.wall_time(),
            steps=k, dt=self.dt, integrator=getattr(self.integrator, "name", str(self.integrator)),
            final_state=self.state, cuts=list(self.cuts),
        )
        traj.model = self.model  # for traj.to_pyvista, plot and save
        if completed:
            traj.message = f"completed {k} steps to t = {self.state.t:.6g} s"
            if self.resumed_from is not None:
                traj.resumed_from_step = self.resumed_from.step
                traj.message += f" (resumed at step {self.resumed_from.step})"
            log.info("%s: %s in %.3g s", getattr(self.integrator, "name", self.integrator),
                     traj.message, traj.wall_time)
        return traj

    def diverged(self, reason: str, detail: str | None = None) -> Diverged:
        """The :class:`fe.Diverged` that ends the run at the step after ``self.state``.

        It carries the frames recorded up to the last good state (``err.trajectory``).
        ``detail``: an integrator's own message, which carries its advice.
        """
        k, state = self.steps_done, self.state
        traj = self.trajectory()
        traj.message = f"diverged at step {k}: {reason}"
        if getattr(self.integrator, "explicit", True):
            advice = "Try a smaller dt, an implicit integrator (fe.ImplicitEuler), or damping."
        elif detail:  # an implicit scheme's own failure carries its advice
            advice = ""
        else:
            advice = "Try a smaller dt or damping."
        err = Diverged(
            f"the simulation diverged at step {k} (t = {state.t:.6g} s): "
            f"{(detail or reason).rstrip('.')}. The last good state and the frames recorded so far "
            f"are attached (err.last_good_state, err.trajectory). {advice}".rstrip(),
            step=k, time=state.t, reason=reason, last_good_state=state,
        )
        err.trajectory = traj
        return err

    def failed(self, error: BaseException) -> StepFailed:
        """The :class:`fe.StepFailed` that ends the run when the step after ``self.state`` raised ``error``.

        Like :meth:`diverged` it carries the step, time, reason (the error's
        type and message), the last good state and the frames recorded so far;
        the caller raises it ``from error``.
        """
        k, state = self.steps_done, self.state
        reason = f"{type(error).__name__}: {error}".rstrip(": ")
        traj = self.trajectory()
        traj.message = f"failed at step {k}: {reason}"
        err = StepFailed(
            f"step {k} (from t = {state.t:.6g} s) failed with {reason.rstrip('.')}. The run stops "
            "there: the last good state and the frames recorded so far are attached "
            "(err.last_good_state, err.trajectory; the original error is err.__cause__). Fix what "
            "raised it (a motion function, the scene's settings) and run again.",
            step=k, time=state.t, reason=reason, last_good_state=state, original=error,
        )
        err.trajectory = traj
        return err


def _check_options(integrator, callback, record_every, energy_growth, observers) -> None:
    if callback is not None and not callable(callback):
        raise InvalidParameter(f"callback must be a function (step, state), got {callback!r}.")
    if isinstance(record_every, bool) or not isinstance(record_every, (int, np.integer)) or record_every < 1:
        raise InvalidParameter(f"record_every must be an integer >= 1, got {record_every!r}.")
    if not (isinstance(energy_growth, (int, float)) and energy_growth > 0):
        raise InvalidParameter(f"energy_growth must be a number > 0, got {energy_growth!r}.")
    if isinstance(integrator, type):
        raise InvalidParameter(
            f"integrator must be an instance, e.g. fe.{integrator.__name__}(), not the class "
            f"{integrator.__name__}."
        )
    if not hasattr(integrator, "step"):
        raise InvalidParameter(
            f"integrator must be e.g. fe.ImplicitEuler() or fe.SymplecticEuler(), got {integrator!r}."
        )
    for obs in observers:
        if not all(callable(getattr(obs, hook, None)) for hook in
                   ("on_start", "on_step", "on_finish", "on_interrupt", "on_close")):
            raise InvalidParameter(
                f"observers must be fe.dynamics.Observer instances (on_start, on_step, "
                f"on_finish, on_interrupt, on_close), got {obs!r}."
            )
