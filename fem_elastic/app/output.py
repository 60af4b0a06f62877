"""Writing a run to disk as it goes: a VTU time series, its PVD collection, summary.json.

A run directory ``DIR`` holds

- ``DIR/series.pvd``: the ParaView collection of every frame written, with its time (s);
- ``DIR/frames/frame_%06d.vtu``: the mesh nodes at their REFERENCE positions and the
  tets (linear, VTK type 10, or quadratic for P2 bodies, type 24, with their mid-edge
  nodes), with point data ``displacement`` (m) and ``velocity`` (m/s), cell data
  ``von_mises`` (Pa) and ``energy_density`` (J/m^3) (see :mod:`fem_elastic.physics.fields`),
  and field data ``TimeValue`` (s) and ``units``: ParaView's Warp By Vector on
  ``displacement`` draws the deformed body (felupe's, SfePy's and FEniCS's convention);
- ``DIR/summary.json``: the run's figures, written when the run ends (completed,
  diverged, failed (a step raised an error, :class:`fe.StepFailed`) or interrupted);
  a run that diverged or failed says at which step (``failed_step``, ``failed_time``)
  and why (``reason``).

Each file is written atomically (:mod:`fem_elastic.files`), and the PVD is rewritten after
every frame, so the directory is a readable series at any moment: a crash or Ctrl-C loses
at most the frame being written. :func:`fem_elastic.app.vtu.read_series` reads it back.
:func:`~fem_elastic.app.vtu.read_series` returns the vertex values (the ones ``fe.simulate``
records) of P2 bodies too.
"""

from __future__ import annotations

import json
import logging
import math
import numbers
import time
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from ..dynamics.observers import Observer
from ..errors import Diverged, InvalidParameter, StepFailed
from ..physics.fields import CellFields
from ..physics.pyvista_grid import _cells
from .vtu import REFERENCE_POINTS, write_pvd, write_vtu_frame
from ..files import write_text_atomic

if TYPE_CHECKING:  # for annotations only
    from ..dynamics.checkpoint import Checkpoint
    from ..dynamics.observers import StepEvent
    from ..dynamics.simulate import Run
    from ..dynamics.state import State
    from ..dynamics.trajectory import Trajectory
    from ..physics.multibody import AnyModel

__all__ = ["SeriesWriter", "write_summary", "to_json"]

log = logging.getLogger(__name__)

#: Names inside a run directory (the output contract).
PVD_NAME = "series.pvd"
FRAMES_DIR = "frames"
SUMMARY_NAME = "summary.json"
FRAME_PATTERN = "frame_{:06d}.vtu"

STATUSES = ("completed", "interrupted", "diverged", "failed")

#: The units of a frame's arrays, stored in each VTU (``fem_elastic.app.vtu.vtu_units``).
FRAME_UNITS = {"points": REFERENCE_POINTS, "displacement": "m", "velocity": "m/s",
               "von_mises": "Pa", "energy_density": "J/m^3", "TimeValue": "s"}
#: The unit of ``TimeValue`` in a static run's frames: their "time" is the load factor.
LOAD_FACTOR_UNIT = "1 (load factor)"


def frame_grid(model) -> tuple[np.ndarray, np.ndarray]:
    """The nodes and cells a frame of ``model`` is written on.

    Returns
    -------
    nodes : numpy.ndarray
        ``(N, 3)`` reference positions (m) of every DOF node: the vertices, then
        (P2) the mid-edge nodes, in the model's DOF order.
    cells : numpy.ndarray
        ``(m, 4)`` vertex indices (P1, springs) or ``(m, 10)`` node indices of
        quadratic tets, whose order (vertices, then edges 01, 12, 20, 03, 13, 23)
        is both scikit-fem's P2 order and VTK's (cell type 24).
    """
    if getattr(model, "models", None) is not None and model.space.order != 1:
        raise InvalidParameter(
            "VTU output of a fe.MultiBody takes linear bodies only (its nodes are written body "
            "after body, and a reader takes the vertices first); build every body with "
            "fe.ElasticBody(material, order=1), or write each P2 body as its own fe.Model run."
        )
    nodes = np.asarray(model.X, dtype=np.float64).reshape(-1, 3)
    cells, _ = _cells(model)  # the cells of the model's pyvista grid, the same ones
    return nodes, cells


def to_json(value):
    """``value`` with numpy scalars and arrays turned into plain Python, for :mod:`json`.

    Non-finite floats (NaN, inf) become ``None``, so the file is strict JSON
    that every parser reads; dict keys become strings; Paths become strings.

    Parameters
    ----------
    value : object
        Nested dicts, lists, tuples, numpy arrays and scalars, numbers, strings, None.

    Returns
    -------
    object
        The same structure of dict, list, str, int, float, bool and None.

    Raises
    ------
    InvalidParameter
        A value that has no JSON form (e.g. an arbitrary object).

    Examples
    --------
    >>> import numpy as np
    >>> to_json({"a": np.float64(1.5), "b": np.array([1, 2]), "c": float("nan")})
    {'a': 1.5, 'b': [1, 2], 'c': None}
    """
    if value is None or isinstance(value, (str, bool)):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, (numbers.Integral, np.integer)):
        return int(value)
    if isinstance(value, (numbers.Real, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else None
    if isinstance(value, np.ndarray):
        return to_json(value.tolist())
    if isinstance(value, dict):
        return {str(k): to_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_json(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    raise InvalidParameter(
        f"summary value {value!r} of type {type(value).__name__} has no JSON form; pass "
        "numbers, strings, lists or dicts of them."
    )


def write_summary(path: str | os.PathLike[str], summary: dict[str, Any]) -> Path:
    """Write a run's figures as strict JSON (non-finite numbers as null), atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Destination, usually ``DIR/summary.json``.
    summary : dict
        Values as accepted by :func:`to_json` (numpy scalars and arrays included).

    Returns
    -------
    pathlib.Path
        ``path``.

    Examples
    --------
    >>> import json, tempfile, pathlib
    >>> import numpy as np
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     p = write_summary(pathlib.Path(tmp) / "summary.json", {"steps": np.int64(3)})
    ...     json.loads(p.read_text())
    {'steps': 3}
    """
    text = json.dumps(to_json(summary), indent=2, allow_nan=False)
    return write_text_atomic(path, text + "\n")


def remove_temporary_files(run_dir) -> None:
    """Remove what atomic writes cut short by a kill left in a run directory.

    :func:`fem_elastic.files._atomic_write` writes each file to ``.NAME.XXXX.tmp`` beside it and
    renames it; only a process killed outright (no handler runs) leaves one.
    """
    run_dir = Path(run_dir)
    ours = [run_dir.glob(f".{PVD_NAME}.*.tmp"), run_dir.glob(f".{SUMMARY_NAME}.*.tmp"),
            (run_dir / FRAMES_DIR).glob(".frame_*.vtu.*.tmp")]
    for tmp in [p for found in ours for p in found]:
        tmp.unlink(missing_ok=True)


def _field_range(values: np.ndarray) -> tuple[float | None, float | None]:
    """(min, max) over the finite values (NaN marks inverted tets); None if there are none."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return None, None
    return float(finite.min()), float(finite.max())


def _ground_info(model):
    """``{"kind": "plane", "z": ..}`` for a model's ground plane, or None."""
    from ..physics.obstacles import Ground

    for obstacle in getattr(model, "obstacles", ()):
        if isinstance(obstacle, Ground):
            return {"kind": "plane", "z": float(obstacle.point[2]),
                    "point": [float(c) for c in obstacle.point],
                    "normal": [float(c) for c in obstacle.unit_normal]}
    return None


class SeriesWriter(Observer):
    """Write a simulation to a run directory frame by frame (see the module notes).

    Use it as one of ``fe.simulate``'s observers (``observers=[writer]``; or
    its callback, ``callback=writer.callback``): write the initial state, let
    it write every ``every``-th step, then :meth:`finish` with the
    trajectory. With ``every`` equal to simulate's ``record_every`` the frames
    are exactly the Trajectory's. When a :class:`fe.Diverged` ends the run it
    finishes the series itself (its ``on_failure`` hook: the last good state is
    the last frame, the summary says ``"diverged"``, or ``"failed"`` for a
    :class:`fe.StepFailed`, with the step and the reason). As a context
    manager, leaving the block on an exception finishes the run the same way,
    or as ``"interrupted"`` (Ctrl-C or any other error), and re-raises it.

    Parameters
    ----------
    model : Model
        With an ``fe.ElasticBody`` (P1 or P2) or ``fe.MassSpring`` body.
    run_dir : str or os.PathLike
        Directory to write (created if missing). Files of an earlier series
        there (``series.pvd``, ``summary.json``, ``frames/frame_*.vtu``) are
        removed first, so that nothing stale reads as part of this run.
    every : int
        Write a frame after every ``every``-th step (``(k + 1) % every == 0``).
    n_steps : int, optional
        The number of steps the run will take, so the callback writes the
        last one; without it :meth:`finish` writes the final state.
    info : dict, optional
        Scene information copied into ``summary.json`` (e.g. ``name``,
        ``variant``, ``body``, ``ground``).
    compression : {"zlib", "lzma", None}
        Of the VTU arrays (:func:`fem_elastic.app.vtu.write_vtu_frame`): None
        writes ~7x faster and ~2x bigger files than zlib.
    resume_from : Checkpoint, optional
        Continue the series already in ``run_dir`` from this checkpoint of the
        same run (:func:`fe.load_checkpoint`): its frames are kept, frames
        written after it (by the run that was stopped) are removed, and the
        next frame written is the checkpoint's next one.
    time_unit : str
        The unit of the frames' ``TimeValue`` recorded in their ``units``: ``"s"``,
        or :data:`LOAD_FACTOR_UNIT` for a static load path (time = load factor).

    Attributes
    ----------
    run_dir : pathlib.Path
    frames : list of (float, str)
        ``(time in s, file relative to run_dir)`` of every frame written.
    seconds_output : float
        Wall time spent writing so far (s): fields, VTU, PVD and summary.
    steps_taken : int
        Steps the callback has seen so far.

    Examples
    --------
    >>> import tempfile
    >>> import fem_elastic as fe
    >>> from fem_elastic.app.output import SeriesWriter
    >>> from fem_elastic.app.vtu import read_series
    >>> model = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
    ...                  fixed="left", gravity=(0, 0, -9.81))
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     writer = SeriesWriter(model, tmp, every=2)
    ...     state = fe.State.rest(model)
    ...     _ = writer.write_state(state)
    ...     run = fe.simulate(model, fe.ImplicitEuler(), dt=0.01, steps=5, state=state,
    ...                       record_every=2, observers=[writer])
    ...     _ = writer.finish(run)
    ...     series = read_series(tmp)
    >>> series.times.round(2), series.summary["status"], series.summary["frames"]
    (array([0.  , 0.02, 0.04, 0.05]), 'completed', 4)
    """

    _last_state: State | None  # the last state seen (written or not)

    def __init__(self, model: AnyModel, run_dir: str | os.PathLike[str], *, every: int = 1,
                 n_steps: int | None = None, info: dict[str, Any] | None = None,
                 compression: Literal["zlib", "lzma"] | None = "zlib",
                 resume_from: Checkpoint | None = None, time_unit: str = "s") -> None:
        if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
            raise InvalidParameter(
                f"every must be an integer >= 1 (steps per frame), got {every!r}."
            )
        if n_steps is not None and (isinstance(n_steps, bool)
                                    or not isinstance(n_steps, (int, np.integer)) or n_steps < 1):
            raise InvalidParameter(f"n_steps must be an integer >= 1 or None, got {n_steps!r}.")
        if compression not in ("zlib", "lzma", None):
            raise InvalidParameter(
                f"compression must be 'zlib', 'lzma' or None, got {compression!r}."
            )
        if info is not None and not isinstance(info, dict):
            raise InvalidParameter(f"info must be a dict of scene figures, got {info!r}.")
        t0 = time.perf_counter()
        self.model = model
        self.run_dir = Path(run_dir)
        self.every = int(every)
        self.n_steps = None if n_steps is None else int(n_steps)
        self.info = dict(info or {})
        self.compression = compression
        self.units = {**FRAME_UNITS, "TimeValue": str(time_unit)}
        self.frames: list[tuple[float, str]] = []
        self.fields = CellFields(model)
        # the nodes written: every DOF node (P2: vertices first, then edge nodes) and the cells
        # over them, (n_tets, 4) or (n_tets, 10) in VTK's quadratic-tet order
        self._nodes, self._cells = frame_grid(model)
        self._last_fields: dict | None = None
        self._last_state = None  # the last state seen (written or not) and its step
        self._last_step = -1
        self._next_index = 0  # the number of the next frame file
        self._start = time.perf_counter()
        self.finished = False
        self.run_dir.mkdir(parents=True, exist_ok=True)
        (self.run_dir / FRAMES_DIR).mkdir(exist_ok=True)
        remove_temporary_files(self.run_dir)
        if resume_from is None:
            self._clear_stale()
        else:
            self._keep(resume_from)
        self.seconds_output = time.perf_counter() - t0

    def _clear_stale(self):
        stale = [self.run_dir / PVD_NAME, self.run_dir / SUMMARY_NAME,
                 *sorted((self.run_dir / FRAMES_DIR).glob("frame_*.vtu"))]
        stale = [p for p in stale if p.is_file()]
        if stale:
            log.info("%s: removing %d files of an earlier series", self.run_dir, len(stale))
            # the PVD first: from then on no reader sees a half-removed series as whole
            for p in stale:
                p.unlink(missing_ok=True)

    def _keep(self, ck):
        """Keep the frames of checkpoint ``ck`` and remove what a stopped run wrote after it."""
        times = [float(t) for t in ck.frames[:, 0]]
        n = len(times)
        (self.run_dir / SUMMARY_NAME).unlink(missing_ok=True)
        for p in sorted((self.run_dir / FRAMES_DIR).glob("frame_*.vtu")):
            try:
                index = int(p.stem.split("_")[1])
            except (IndexError, ValueError):
                continue
            if index >= n:
                p.unlink(missing_ok=True)
        entries, missing = [], []
        for i, t in enumerate(times):
            name = f"{FRAMES_DIR}/{FRAME_PATTERN.format(i)}"
            if (self.run_dir / name).is_file():
                entries.append((t, name))
            else:
                missing.append(name)
        if missing:  # removed by hand, or by [output] vtu = false after a finished run
            log.warning("%s: %d of the checkpoint's %d frames are missing (first %s); the series goes "
                        "on without them", self.run_dir, len(missing), n, missing[0])
        write_pvd(self.run_dir / PVD_NAME, entries)
        # numbering goes on from the checkpoint's frame count even if a file was missing
        self.frames = entries
        self._next_index = n
        self._last_state, self._last_step = ck.state, ck.step - 1
        if n and times[-1] == ck.state.t:  # the summary's field ranges are the last frame's
            self._last_fields = self.fields(ck.state.x)

    @property
    def steps_taken(self) -> int:
        """Steps the callback has seen so far (int)."""
        return self._last_step + 1

    # frames ---------------------------------------------------------------------------
    def write_state(self, state: State) -> Path:
        """Write ``state`` as the next frame and rewrite the PVD.

        Parameters
        ----------
        state : State
            Positions (m), velocities (m/s) and time (s) of every DOF.

        Returns
        -------
        pathlib.Path
            The frame file written.
        """
        if self.finished:
            raise InvalidParameter("this SeriesWriter has finished; make a new one for a new run.")
        t0 = time.perf_counter()
        m = self.model
        u = (state.x - m.X).reshape(-1, 3)  # every node's displacement (m)
        v = np.reshape(state.v, (-1, 3))
        fields = self.fields(state.x)
        name = f"{FRAMES_DIR}/{FRAME_PATTERN.format(self._next_index)}"
        path = write_vtu_frame(self.run_dir / name, self._nodes, self._cells,
                               {"displacement": u, "velocity": v}, fields,
                               compression=self.compression,
                               field_data={"TimeValue": [float(state.t)]}, units=self.units)
        entries = self.frames + [(float(state.t), name)]
        write_pvd(self.run_dir / PVD_NAME, entries)
        self.frames = entries  # only now: a failed write leaves the series as it was
        self._next_index += 1
        self._last_fields = fields
        if self._last_state is None:
            self._last_state = state
        self.seconds_output += time.perf_counter() - t0
        return path

    def on_step(self, run: Run, event: StepEvent) -> None:
        """:class:`fem_elastic.dynamics.Observer` hook: :meth:`callback` with the step taken."""
        self.callback(event.k, event.after)

    def on_failure(self, run: Run, error: Diverged) -> None:
        """:class:`fem_elastic.dynamics.Observer` hook: finish the series of a run that
        diverged or failed (:meth:`finish_failed`)."""
        if not self.finished:
            self.finish_failed(error)

    def finish_failed(self, error: Diverged) -> Path:
        """Finish the series of a run that ``error`` (a :class:`fe.Diverged`) ended.

        The last good state (``error.last_good_state``) is the last frame, and
        the summary says ``"failed"`` for a :class:`fe.StepFailed` (a step
        raised an error), else ``"diverged"``, with the error's message, the
        step (``failed_step``), its start time (``failed_time``, s) and the reason.

        Returns
        -------
        pathlib.Path
            ``run_dir / "summary.json"``.
        """
        status = "failed" if isinstance(error, StepFailed) else "diverged"
        extra = {"failed_step": getattr(error, "step", None), "failed_time": getattr(error, "time", None),
                 "reason": getattr(error, "reason", None)}
        return self.finish(getattr(error, "trajectory", None), status=status, message=str(error),
                           extra=extra, final_state=getattr(error, "last_good_state", None))

    def callback(self, k: int, state: State) -> None:
        """``fe.simulate`` callback: write a frame after every ``every``-th step (and the last).

        Parameters
        ----------
        k : int
            Index of the step just taken (0-based).
        state : State
            The state after it.
        """
        self._last_state, self._last_step = state, int(k)
        last = self.n_steps is not None and k == self.n_steps - 1
        if (k + 1) % self.every == 0 or last:
            self.write_state(state)

    # the end ----------------------------------------------------------------------------
    def finish(self, trajectory: Trajectory | None = None,
               status: str = "completed",
               message: str = "", extra: dict[str, Any] | None = None, *,
               final_state: State | None = None) -> Path:
        """Write the final frame if it is not written yet, then ``summary.json``.

        Parameters
        ----------
        trajectory : Trajectory, optional
            What ``fe.simulate`` returned (or ``err.trajectory`` of a
            :class:`fe.Diverged`); its ``final_state`` is the last frame and
            its ``summary()`` the run's figures. Without it (an interrupted
            run) the last state the callback saw is used.
        status : {"completed", "interrupted", "diverged", "failed"}
        message : str
            How the run ended, in words; default the trajectory's message.
        extra : dict, optional
            More figures for the summary (e.g. a tip deflection, m).
        final_state : State, optional
            The state to end the series on (e.g. ``err.last_good_state``),
            instead of the trajectory's final state or the last one seen.

        Returns
        -------
        pathlib.Path
            ``run_dir / "summary.json"``.
        """
        if status not in STATUSES:
            raise InvalidParameter(f"status must be one of {STATUSES}, got {status!r}.")
        if self.finished:
            raise InvalidParameter("finish was called already for this run.")
        final = final_state
        if final is None:
            final = getattr(trajectory, "final_state", None)
        if final is None:
            final = self._last_state
        if final is not None and (not self.frames or float(final.t) != self.frames[-1][0]):
            self.write_state(final)
        t0 = time.perf_counter()
        summary = self._summary(trajectory, final, status, message, extra)
        path = self.run_dir / SUMMARY_NAME
        self.seconds_output += time.perf_counter() - t0
        summary["seconds_output"] = self.seconds_output  # the summary's own write: ~1 ms, left out
        write_summary(path, summary)
        self.finished = True
        log.info("%s: %d frames, %s, %.3g s spent writing", self.run_dir, len(self.frames),
                 status, self.seconds_output)
        return path

    def _summary(self, trajectory, final, status, message, extra) -> dict:
        m = self.model
        # the scene's description first, then what the run did: a figure of the run (steps
        # taken, t_end, ...) must never be overwritten by a planned value of the same name
        out = dict(self.info)
        if trajectory is not None:
            out.update(trajectory.summary())
        else:  # interrupted: what the writer itself saw
            out.update({"steps": self.steps_taken,
                        "t_end": None if final is None else float(final.t),
                        "wall_time": time.perf_counter() - self._start})
            if final is not None:
                out["energy_final"] = self._energy(final)
        out["status"] = status
        out["message"] = message or out.get("message", "") or status
        out.setdefault("ground", _ground_info(m))
        out["n_vertices"] = int(m.mesh.p.shape[1])
        out["n_tets"] = int(m.mesh.t.shape[1])
        out["frames"] = len(self.frames)
        out["record_every"] = self.every
        if self._last_fields is not None:
            for name, values in self._last_fields.items():
                out[f"{name}_min"], out[f"{name}_max"] = _field_range(values)
        out.update(extra or {})
        return out

    def _energy(self, state):
        """Total energy (J) of ``state`` for an interrupted run's summary, or None.

        Lumped-mass kinetic energy (the integrator's mass is not known here).
        The run was stopped at an arbitrary point (Ctrl-C may even have cut an
        import short), so a failure here is logged and the figure left out:
        the summary, which says how the run ended, matters more.
        """
        try:
            return self.model.kinetic_energy(state.v, "lumped") + self.model.energy(state.x)
        except Exception as err:
            log.warning("%s: energy of the last state not evaluated (%s: %s)", self.run_dir,
                        type(err).__name__, err)
            return None

    # context manager ------------------------------------------------------------------
    def __enter__(self) -> "SeriesWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> Literal[False]:
        if self.finished:
            return False
        if exc is None:
            self.finish()
        elif isinstance(exc, Diverged):
            self.finish_failed(exc)
        else:
            what = "interrupted (Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else \
                f"stopped by {type(exc).__name__}: {exc}"
            step = f" after step {self._last_step}" if self._last_step >= 0 else ""
            try:
                self.finish(status="interrupted", message=f"{what}{step}")
            except Exception as err:  # never hide the original error behind this one
                log.error("%s: could not finish the series after %s: %s", self.run_dir, what, err)
        return False
