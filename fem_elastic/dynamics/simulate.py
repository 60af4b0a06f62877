"""The simulation loop: step, record, watch for blow-up.

``simulate`` advances a State with an integrator, records frames, and stops
with :class:`fe.Diverged` (carrying the step, time, reason, the last good
state and the trajectory recorded so far) when

- the state stops being finite,
- the total energy grows beyond a bound while nothing feeds energy in
  (no driven boundary is moving the body), or
- an implicit step fails even after cutting the step.

The energy bound: with ``E_0`` the total energy at the start (or when the
last driven boundary stops moving or is released) and ``S`` an energy scale
of the scene (the largest of the initial kinetic, potential and elastic
energies, the work of the loads over the body's size, and the work of the
loads carrying the body onto each obstacle), the run diverges when
``E > E_0 + energy_growth * S``. Damping and implicit schemes only lose
energy; an unstable scheme multiplies it every step. A symplectic scheme below
its stability limit conserves a modified energy, not the measured one: the
measured energy of a mode swings by a factor up to ``1 / (1 - (h omega / 2)^2)``,
a few percent well below the limit but unbounded as ``h omega -> 2``. Close
to the limit, with kinetic energy dominating the scale, a bounded run can
exceed the bound: raise ``energy_growth`` (or lower dt) there (the stability
study measured a false verdict at 0.93 x the limit on a kicked 100 GPa beam).
While a driven boundary moves it feeds energy in, and only non-finite values
are checked.
"""

from __future__ import annotations

import logging
import math
import numbers
import time
import warnings
from pathlib import Path

import numpy as np

from .errors import Diverged, InvalidParameter
from .integrators.base import check_dt, check_state
from .checkpoint import Checkpoint, _Snapshot, frame_record, trajectory_from_records
from .state import State
from .trajectory import COUNT_FIELDS, STEP_FIELDS, Trajectory

__all__ = ["simulate", "StabilityWarning"]

log = logging.getLogger(__name__)



class StabilityWarning(UserWarning):
    """An explicit time step above the scheme's stability limit."""


def simulate(
    model,
    integrator,
    dt: float,
    *,
    t_end: float | None = None,
    steps: int | None = None,
    state: State | None = None,
    record_every: int = 1,
    progress: bool = False,
    check_stability: bool = True,
    energy_growth: float = 1.0,
    callback=None,
    checkpoint_dir=None,
    checkpoint_every: int = 0,
    resume=False,
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
        Initial state; default ``fe.State.rest(model)``.
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
        energy scale (see the module notes); ``inf`` switches the check off.
    callback : callable, optional
        ``callback(step, state)`` after every step (e.g. to write output);
        an exception raised there stops the run and propagates.
    checkpoint_dir : str or os.PathLike, optional
        Write checkpoints to this directory (:mod:`fem_elastic.checkpoint`):
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
    if state is None:
        state = State.rest(model)
    check_state(model, state)
    n_steps = _n_steps(h, t_end, steps, state.t)
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
    mass = "lumped" if getattr(integrator, "explicit", True) else getattr(integrator, "mass", "lumped")
    if check_stability and getattr(integrator, "explicit", False) and not getattr(integrator, "substep", False):
        _warn_if_unstable(model, integrator, h)

    rec = _Recorder(model, mass)
    ckpt, start = _checkpointer(model, integrator, h, n_steps, int(record_every), state, energy_growth,
                                checkpoint_dir, checkpoint_every, resume, rec.frame_size)
    stats = {k: np.zeros(n_steps, dtype=np.int64) for k in COUNT_FIELDS}
    for k in STEP_FIELDS[len(COUNT_FIELDS):]:
        stats[k] = np.zeros(n_steps)
    cuts: list = []
    t_start = time.perf_counter()
    if start is None:
        e0 = rec.energies(state)
        e_ref, scale = rec.record(state, e0), _energy_scale(model, state, e0)
        driving, k0, wall0 = model.driving(state.t), 0, 0.0
    else:  # continue where the checkpoint left off, with everything the loop had in hand
        rec.frames = list(start.frames)
        for name, values in start.step_stats.items():
            stats[name][:start.step] = values
        cuts = list(start.cuts)
        state, k0, wall0 = start.state, start.step, start.wall_time
        e_ref, scale, driving = start.e_ref, start.scale, start.driving
        integrator.restore_state(state, start.integrator_state)
        log.info("resuming at step %d of %d (t = %.6g s) from %s", k0, n_steps, state.t, ckpt.directory)

    def snapshot(k_done):
        return _Snapshot(k_done, state, len(rec.frames), len(cuts), e_ref, scale, driving,
                         wall0 + time.perf_counter() - t_start, integrator.checkpoint_state(state))

    snap = snapshot(k0) if ckpt is not None else None
    check_every = max(1, min(int(record_every), 10))
    bar = _progress_bar(n_steps, progress, k0)
    try:
        for k in range(k0, n_steps):
            t0 = time.perf_counter()
            try:
                new = integrator.step(model, state, h)
            except Diverged as err:
                _collect_cuts(cuts, k, getattr(integrator, "last_stats", None))
                raise _diverged(err.reason or str(err), k, state, rec, stats, t_start, integrator, h,
                                cuts, str(err), wall0) from err
            stats["seconds_step"][k] = time.perf_counter() - t0
            st = integrator.last_stats
            for name in COUNT_FIELDS:
                stats[name][k] = getattr(st, name, 1 if name == "substeps" else 0)
            for name in ("linearize", "solve", "line_search"):
                stats[f"seconds_{name}"][k] = st.seconds.get(name, 0.0)
            _collect_cuts(cuts, k, st)
            if not (np.isfinite(new.x).all() and np.isfinite(new.v).all()):
                raise _diverged("non-finite positions or velocities", k, state, rec, stats,
                                t_start, integrator, h, cuts, None, wall0)
            last = k == n_steps - 1
            was_driving, driving = driving, model.driving(new.t)
            record = (k + 1) % record_every == 0 or last
            released = was_driving and not driving
            if record or released or (k + 1) % check_every == 0:
                e = rec.energies(new)
                if not math.isfinite(e[2]):
                    raise _diverged("the energy is not finite (an inverted element?)", k, state, rec,
                                    stats, t_start, integrator, h, cuts, None, wall0)
                if released:  # the drive stopped: the energy from here on is the budget
                    e_ref, scale = e[2], max(scale, abs(e[2]))
                elif not driving and e[2] > e_ref + energy_growth * scale:
                    raise _diverged(
                        f"the total energy grew from {e_ref:.6g} J to {e[2]:.6g} J (more than "
                        f"{energy_growth:g} x the scene's energy scale {scale:.3g} J) with no "
                        "energy source", k, state, rec, stats, t_start, integrator, h, cuts, None, wall0,
                    )
                if record:
                    rec.record(new, e)
            state = new
            if callback is not None:
                callback(k, state)
            if ckpt is not None:
                # everything the loop holds after k + 1 steps, taken as one: a Ctrl-C from here
                # on checkpoints this step, never a half-updated one
                snap = snapshot(k + 1)
                if ckpt.due(k + 1) and not last:
                    ckpt.write(snap, rec.frames, stats, cuts)
            if bar is not None:
                bar.update(1)
    except KeyboardInterrupt:
        if ckpt is not None and snap.step > ckpt.last_step:
            ckpt.write(snap, rec.frames, stats, cuts)
            log.warning("interrupted: checkpoint after %d of %d steps (t = %.6g s) in %s; "
                        "resume=True continues from it", snap.step, n_steps, snap.state.t, ckpt.directory)
        raise
    finally:
        if bar is not None:
            bar.close()
    wall = wall0 + time.perf_counter() - t_start
    if ckpt is not None and ckpt.last_step < n_steps:
        snap.wall_time = wall
        ckpt.write(snap, rec.frames, stats, cuts)
    traj = rec.trajectory(stats, n_steps, wall, integrator, h, state, cuts)
    traj.message = f"completed {n_steps} steps to t = {state.t:.6g} s"
    if start is not None:
        traj.resumed_from_step = start.step
        traj.message += f" (resumed at step {start.step})"
    log.info("%s: %s in %.3g s", integrator.name if hasattr(integrator, "name") else integrator,
             traj.message, traj.wall_time)
    return traj


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


def _collect_cuts(cuts, k, stats) -> None:
    for t, dt, reason in getattr(stats, "cuts", ()):
        cuts.append({"step": int(k), "t": float(t), "dt": float(dt), "reason": str(reason)})


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
    from .modal import critical_time_step

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


def _energy_scale(model, state, energies):
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


class _Recorder:
    """The recorded frames, each one flat record (:func:`fem_elastic.checkpoint.frame_record`)."""

    def __init__(self, model, mass):
        self.model, self.mass = model, mass
        self.frames = []
        self.frame_size = 9 + 6 * model.mesh.p.shape[1]

    def energies(self, state):
        ke = self.model.kinetic_energy(state.v, self.mass)
        pe = self.model.energy(state.x)
        return ke, pe, ke + pe

    def record(self, state, e=None):
        e = self.energies(state) if e is None else e
        m = self.model
        self.frames.append(frame_record(
            state.t, m.to_vertices(state.x - m.X), m.to_vertices(state.v), e[0], e[1],
            m.linear_momentum(state.v), m.angular_momentum(state.x, state.v),
        ))
        return e[2]

    def trajectory(self, stats, n, wall, integrator, h, state, cuts):
        return trajectory_from_records(
            np.reshape(self.frames, (len(self.frames), self.frame_size)),
            step_stats={k: v[:n] for k, v in stats.items()}, wall_time=wall, steps=n, dt=h,
            integrator=getattr(integrator, "name", str(integrator)), final_state=state, cuts=list(cuts),
        )


def _diverged(reason, k, state, rec, stats, t_start, integrator, h, cuts, detail=None, wall0=0.0):
    """fe.Diverged at step k, with the frames recorded up to the last good state (k steps taken)."""
    traj = rec.trajectory(stats, k, wall0 + time.perf_counter() - t_start, integrator, h, state, cuts)
    traj.message = f"diverged at step {k}: {reason}"
    if getattr(integrator, "explicit", True):
        advice = "Try a smaller dt, an implicit integrator (fe.ImplicitEuler), or damping."
    elif detail:  # an implicit scheme's own failure carries its advice
        advice = ""
    else:
        advice = "Try a smaller dt or damping."
    err = Diverged(
        f"the simulation diverged at step {k} (t = {state.t:.6g} s): {(detail or reason).rstrip('.')}. The last "
        "good state and the frames recorded so far are attached (err.last_good_state, "
        f"err.trajectory). {advice}".rstrip(),
        step=k, time=state.t, reason=reason, last_good_state=state,
    )
    err.trajectory = traj
    return err


def _progress_bar(n, progress, initial=0):
    if not progress:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:
        log.warning("progress=True needs tqdm (pip install fem_elastic[cli]); running without a bar")
        return None
    return tqdm(total=n, initial=initial, unit="step", desc="simulate")
