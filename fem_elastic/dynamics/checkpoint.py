"""Checkpoints of a simulation: stop a long run anywhere and continue it bit for bit.

:func:`fe.simulate` with ``checkpoint_dir=DIR`` writes a checkpoint every
``checkpoint_every`` steps, when the run is interrupted (Ctrl-C) and when it
completes; ``resume=True`` continues from the last one, and the resumed run
records exactly (bit for bit) the trajectory the uninterrupted run records.
(IPC contact through ipctk sums on several threads in a varying order: there
two runs agree to round-off, resumed or not, and bit for bit with
``ipctk.set_num_threads(1)``; see :mod:`fem_elastic.physics.ipc_contact`.)

A checkpoint directory holds

- ``checkpoint.npz``: the state (``x``, ``v``, ``t``), what the integrator
  remembers between steps (:meth:`Integrator.checkpoint_state`, e.g.
  Newmark's acceleration) and what the model does (IPC's adaptive barrier
  stiffness, :func:`model_checkpoint_state`), the loop's own bookkeeping (the energy bound's
  reference and scale, whether a driven boundary was moving, the wall time so
  far) and the counts of records below that belong to it; plus a description
  of the run (model, integrator and settings) that a resume must match.
  Written to a temporary file, fsynced and renamed over the old one: it is
  always a whole checkpoint, the new or the previous.
- ``frames.f64``: the recorded frames, appended (one fixed-size record of
  float64 per frame: t, kinetic and potential energy (J), linear (kg m/s)
  and angular (kg m^2/s) momentum, vertex displacements (m) and velocities (m/s));
- ``steps.f64``: the per-step solver statistics, appended (one record per step, the
  fields of ``Trajectory.step_stats`` in the order of ``trajectory.STEP_FIELDS``;
  counts are stored as float64, exact below 2^53); ``checkpoint.npz`` names the
  fields, and a checkpoint whose records hold other fields (written by an
  earlier version, before ``min_det_F``) is refused with a typed error;
- ``cuts.jsonl``: every failed attempt of a step (step, t, dt, reason), appended, one
  JSON object per line.

The appended files are fsynced before ``checkpoint.npz`` is replaced, and
only the first records it counts are read back: a crash mid-write leaves a
longer file whose tail is ignored and cut off by the next write. So the
history is written once, not again at every checkpoint.

Each checkpoint records the CRC-32 of the bytes it counts in each appended
file (``crc32`` in its description; ``checkpoint.npz`` itself is a zip whose
members carry their own CRC-32), and reading it back checks them: a frame
record changed on disk, a file cut short (torn) or replaced, a file in
another encoding is a typed error that names the file and says to start the
run afresh, never a resume from altered data. (Checkpoints written before the
checksums are read without that check.)

Examples
--------
>>> import tempfile
>>> import fem_elastic as fe
>>> model = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1000.0,
...                  body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
...                  fixed="left", gravity=(0, 0, -9.81))
>>> with tempfile.TemporaryDirectory() as tmp:
...     full = fe.simulate(model, fe.Newmark(), 0.01, steps=6, checkpoint_dir=tmp,
...                        checkpoint_every=2)
...     ck = fe.load_checkpoint(tmp)
>>> ck.step, ck.n_steps, ck.complete, ck.trajectory().times.size
(6, 6, True, 7)
"""

from __future__ import annotations

import hashlib
import io as _io
import zipfile
import zlib
import json
import logging
import math
import os
import types
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InvalidParameter
from ..files import _atomic_write, write_failed
from .state import State
from .trajectory import COUNT_FIELDS, STEP_FIELDS, Trajectory

__all__ = ["Checkpoint", "load_checkpoint", "CHECKPOINT_NAME"]

log = logging.getLogger(__name__)

CHECKPOINT_NAME = "checkpoint.npz"
FRAMES_NAME = "frames.f64"
STEPS_NAME = "steps.f64"
CUTS_NAME = "cuts.jsonl"
FORMAT = 1



def _sha(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str(a.dtype).encode() + str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:20]


def _describe(value, depth: int = 0):
    """A plain, exact description of a setting: numbers (floats in hex), strings, arrays by hash,
    and objects by their class and public attributes (recursively, a few levels deep)."""
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, np.generic):
        value = value.item()
        if not isinstance(value, (bool, int, float, str)):
            return str(value)
    if isinstance(value, float):
        return value.hex()
    if isinstance(value, np.ndarray):
        return "array:" + _sha(value)
    if isinstance(value, (list, tuple)):
        return [_describe(v, depth + 1) for v in value]
    if isinstance(value, dict):
        return {str(k): _describe(v, depth + 1) for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))}
    if isinstance(value, types.FunctionType):
        # by name and by what it computes (code, constants, defaults, captured values); never
        # by repr, which holds an address that differs from process to process
        code = value.__code__
        cells = [c.cell_contents for c in (value.__closure__ or ()) if _cell_has_value(c)]
        return {"function": f"{value.__module__}.{value.__qualname__}",
                "code": _sha(np.frombuffer(code.co_code, dtype=np.uint8)),
                "names": list(code.co_names),  # the globals and attributes it uses (np.sin, np.tan)
                "constants": _describe([c for c in code.co_consts if not isinstance(c, types.CodeType)],
                                       depth + 1),
                "defaults": _describe(list(value.__defaults__ or ()), depth + 1),
                "closure": _describe(cells, depth + 1)}
    if isinstance(value, (types.BuiltinFunctionType, types.MethodType, type)):
        return f"{getattr(value, '__module__', '')}.{getattr(value, '__qualname__', type(value).__name__)}"
    fields = getattr(value, "__dict__", None)
    if fields is None or depth > 3:
        return type(value).__name__
    return {"class": type(value).__name__,
            **{k: _describe(v, depth + 1) for k, v in sorted(fields.items()) if not k.startswith("_")}}


def _cell_has_value(cell) -> bool:
    try:
        cell.cell_contents
    except ValueError:  # an empty cell (a name not yet bound)
        return False
    return True


def _settings(integrator) -> dict:
    """The integrator's settings (its public attributes, the linear solver's included)."""
    return {k: _describe(v) for k, v in sorted(vars(integrator).items())
            if not k.startswith("_") and k != "last_stats"}


def run_fingerprint(model, integrator, h, n_steps, record_every, state0, energy_growth) -> dict:
    """What a checkpoint must match to be resumed: the model, the integrator and the run's settings.

    Parameters
    ----------
    model : Model
    integrator : Integrator
    h : float
        Time step (s).
    n_steps, record_every : int
    state0 : State
        The initial state of the whole run.
    energy_growth : float
        simulate's divergence bound.

    Returns
    -------
    dict
        Plain values: class names and reprs of the body and of every term, hashes
        of the reference positions, masses, held DOFs and loads, the integrator's
        settings, and the run's dt, steps, recording interval, initial state and
        energy bound.
    """
    dofs, xc, vc = model.constraints(state0.t)
    return {
        "ndofs": int(model.ndofs),
        "body": _describe(model.body),
        "density": _describe(model.density),  # a float's hex; a fe.MultiBody's: one per body
        "terms": [type(p).__name__ for p in model.potentials],
        "damping": _describe(model.damping),
        "obstacles": [_describe(o) for o in model.obstacles],
        "driven": [_describe(motion) for motion, _, _ in model.driven],
        "driven_dofs": _sha(*[np.asarray(dofs) for _, _, dofs in model.driven]),
        "model_arrays": _sha(model.X, model.lumped_mass, np.asarray(dofs), model.external_force()),
        "integrator": getattr(integrator, "name", type(integrator).__name__),
        "integrator_settings": _settings(integrator),
        "dt": float(h).hex(),
        "n_steps": int(n_steps),
        "record_every": int(record_every),
        "initial_state": _sha(state0.x, state0.v, np.array([state0.t])),
        "energy_growth": float(energy_growth).hex() if math.isfinite(energy_growth) else "inf",
    }


@dataclass
class Checkpoint:
    """A checkpoint read back from a directory (:func:`load_checkpoint`).

    Attributes
    ----------
    directory : pathlib.Path
    step : int
        Steps taken when it was written.
    n_steps : int
        Steps the run was asked for.
    state : State
        The state after ``step`` steps.
    complete : bool
        True when the run had finished (``step == n_steps``).
    integrator_state : dict of numpy.ndarray
        What the integrator remembered (:meth:`Integrator.checkpoint_state`).
    fingerprint : dict
        The run it belongs to (see :func:`run_fingerprint`).
    e_ref, scale : float
        The energy bound's reference (J) and scale (J) at that point.
    work, work_abs : float
        The work driven boundaries had done since ``e_ref`` (J) and the sum of
        its per-step magnitudes (J) (:class:`fem_elastic.dynamics.observers.BlowUpWatch`).
    driving : bool
        Whether a driven boundary was moving at ``state.t``.
    wall_time : float
        Wall time of the run so far (s), over every session.
    frames : numpy.ndarray
        ``(n_frames, record)`` the recorded frames (see the module notes).
    step_stats : dict of numpy.ndarray
        ``(step,)`` per-step statistics.
    cuts : list of dict
        Failed attempts: ``step``, ``t`` (s), ``dt`` (s), ``reason``.
    integrator : str
        The integrator's name.
    dt : float
        Time step (s).
    cuts_bytes : int
        Bytes of ``cuts.jsonl`` that belong to this checkpoint.
    crc32 : dict of str to int
        CRC-32 of the bytes of each appended file that belong to this checkpoint
        (checked when it was read).
    model_state : dict of numpy.ndarray
        What the model remembered (:func:`model_checkpoint_state`: IPC's adaptive
        kappa); empty for most models and for checkpoints written before it was kept.
    """

    directory: Path
    step: int
    n_steps: int
    state: State
    integrator_state: dict
    fingerprint: dict
    e_ref: float
    scale: float
    driving: bool
    wall_time: float
    frames: np.ndarray
    step_stats: dict
    cuts: list = field(default_factory=list)
    integrator: str = ""
    dt: float = 0.0
    cuts_bytes: int = 0
    work: float = 0.0
    work_abs: float = 0.0
    crc32: dict = field(default_factory=dict)
    model_state: dict = field(default_factory=dict)

    @property
    def complete(self) -> bool:
        return self.step >= self.n_steps

    @property
    def time(self) -> float:
        """Simulation time of the checkpoint (s)."""
        return self.state.t

    def trajectory(self) -> Trajectory:
        """The frames recorded up to this checkpoint, as a :class:`Trajectory`."""
        traj = trajectory_from_records(
            self.frames, step_stats=dict(self.step_stats), wall_time=self.wall_time, steps=self.step,
            dt=self.dt, integrator=self.integrator, final_state=self.state, cuts=list(self.cuts),
        )
        traj.message = (f"completed {self.step} steps to t = {self.state.t:.6g} s" if self.complete
                        else f"checkpoint after {self.step} of {self.n_steps} steps")
        return traj


def frame_record(t, u, v, kin, pot, lin, ang) -> np.ndarray:
    """One ``frames.f64`` record from a frame's values (see the module notes)."""
    return np.concatenate(([t, kin, pot], lin, ang, np.ravel(u), np.ravel(v)))


def trajectory_from_records(frames, **fields) -> Trajectory:
    """A :class:`Trajectory` from frame records (:func:`frame_record`) and its other ``fields``.

    Parameters
    ----------
    frames : array_like
        ``(T, 9 + 6 n_vertices)`` records.
    **fields
        The Trajectory's other attributes (``step_stats``, ``wall_time``, ...).
    """
    f = np.asarray(frames, dtype=float)
    T = len(f)
    nv3 = (f.shape[1] - 9) // 2
    kin, pot = f[:, 1].copy(), f[:, 2].copy()
    return Trajectory(
        times=f[:, 0].copy(), displacement=f[:, 9:9 + nv3].reshape(T, -1, 3),
        velocity=f[:, 9 + nv3:].reshape(T, -1, 3), kinetic=kin, potential=pot, total=kin + pot,
        linear_momentum=f[:, 3:6].copy(), angular_momentum=f[:, 6:9].copy(), **fields,
    )


def load_checkpoint(directory: str | os.PathLike[str]) -> Checkpoint:
    """Read the last checkpoint in ``directory``.

    Parameters
    ----------
    directory : str or os.PathLike
        A ``checkpoint_dir`` of :func:`fe.simulate` (or ``RUN_DIR/checkpoint`` of a
        ``fem-elastic run``).

    Returns
    -------
    Checkpoint

    Raises
    ------
    InvalidParameter
        No checkpoint there, or one that cannot be read (its message says which file and why).
    """
    d = Path(directory)
    path = d / CHECKPOINT_NAME
    if not path.is_file():
        raise InvalidParameter(
            f"no checkpoint in {d} ({CHECKPOINT_NAME} is missing): a run writes one when it is "
            "given checkpoint_dir (fe.simulate) or --checkpoint-every (fem-elastic run)."
        )
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        meta = json.loads(str(arrays.pop("meta")))
        scalars = arrays.pop("scalars")
        x, v = arrays.pop("x"), arrays.pop("v")
        if meta.get("format") != FORMAT:
            raise InvalidParameter(
                f"the checkpoint {path} has format {meta.get('format')!r}, this version reads "
                f"{FORMAT}; remove the directory to start afresh."
            )
        t, e_ref, scale, wall = (float(s) for s in scalars[:4])
        work, work_abs = (float(s) for s in scalars[4:6]) if scalars.size >= 6 else (0.0, 0.0)
        # the per-step fields of steps.f64; before they were named, the ten of format 1's first
        # version (no min_det_F): a different record size, which cannot be appended to
        step_fields = tuple(meta.get("step_fields", _STEP_FIELDS_UNNAMED))
        if step_fields != STEP_FIELDS:
            raise _OldStepFields(path, step_fields)
        n_frames, step, n_cuts, cuts_bytes = (int(meta[k]) for k in ("n_frames", "step", "n_cuts", "cuts_bytes"))
        frame_size, n_steps, driving = int(meta["frame_size"]), int(meta["n_steps"]), bool(meta["driving"])
        fingerprint, dt = meta["fingerprint"], float.fromhex(meta["fingerprint"]["dt"])
        recorded = {str(k): int(v) for k, v in meta.get("crc32", {}).items()}
    except _OldStepFields as old:
        raise InvalidParameter(str(old)) from None
    except (OSError, ValueError, KeyError, TypeError, AttributeError, EOFError, zlib.error,
            zipfile.BadZipFile) as exc:  # a torn or altered zip: its members' CRC-32 fails
        raise InvalidParameter(
            f"the checkpoint {path} cannot be read ({type(exc).__name__}: {exc}); remove the "
            "directory to start the run afresh."
        ) from None
    integ = {k[len("integrator/"):]: a for k, a in arrays.items() if k.startswith("integrator/")}
    model_state = {k[len("model/"):]: a for k, a in arrays.items() if k.startswith("model/")}
    frames = _read_records(d / FRAMES_NAME, n_frames, frame_size)
    steps = _read_records(d / STEPS_NAME, step, len(STEP_FIELDS))
    crc = {FRAMES_NAME: zlib.crc32(frames.astype("<f8").tobytes()),
           STEPS_NAME: zlib.crc32(steps.astype("<f8").tobytes())}
    _check_crc(d, crc, recorded)  # before any value read is used
    stats = {}
    for i, name in enumerate(STEP_FIELDS):
        col = steps[:, i]
        stats[name] = col.astype(np.int64) if name in COUNT_FIELDS else col.copy()
    cuts, crc[CUTS_NAME] = _read_cuts(d / CUTS_NAME, n_cuts, cuts_bytes)
    _check_crc(d, crc, recorded)
    return Checkpoint(
        directory=d, step=step, n_steps=n_steps, state=State(x, v, t),
        integrator_state=integ, fingerprint=fingerprint, e_ref=e_ref, scale=scale,
        driving=driving, wall_time=wall, frames=frames, step_stats=stats, cuts=cuts,
        integrator=fingerprint.get("integrator", ""), dt=dt, cuts_bytes=cuts_bytes,
        work=work, work_abs=work_abs, crc32=crc, model_state=model_state,
    )


def _check_crc(d: Path, crc: dict, recorded: dict) -> None:
    """:class:`InvalidParameter` naming the first file whose CRC-32 differs from the recorded one."""
    for name, value in recorded.items():
        if name in crc and crc[name] != value:
            raise InvalidParameter(
                f"{d / name} does not hold what its checkpoint recorded (CRC-32 {crc[name]:08x}, "
                f"recorded {value:08x}): the file was changed or damaged after it was written. Remove "
                f"{d} to start the run afresh (resume=False, or `fem-elastic run` without --resume), "
                "or restore the file."
            )


#: The per-step fields of a checkpoint that does not name them (written before ``min_det_F``).
_STEP_FIELDS_UNNAMED = STEP_FIELDS[:10]


class _OldStepFields(ValueError):
    """A checkpoint whose ``steps.f64`` records hold other per-step fields than this version's."""

    def __init__(self, path, fields):
        missing = [f for f in STEP_FIELDS if f not in fields]
        super().__init__(
            f"the checkpoint {path} was written by another version of fem_elastic: its per-step "
            f"records hold {len(fields)} fields, this version records {len(STEP_FIELDS)}"
            + (f" (it lacks {', '.join(missing)})" if missing else "")
            + "; it cannot be resumed. Start the run afresh (resume=False, or `fem-elastic run` "
            "without --resume), or finish it with the version that wrote it."
        )


def _read_records(path: Path, n: int, size: int) -> np.ndarray:
    if n == 0:
        return np.zeros((0, size))
    try:
        data = np.fromfile(path, dtype="<f8", count=n * size)
    except OSError as exc:
        raise InvalidParameter(f"the checkpoint's {path.name} cannot be read ({exc}).") from None
    if data.size != n * size:
        raise InvalidParameter(
            f"{path} holds {data.size // max(size, 1)} records, the checkpoint counts {n}: the "
            "directory is damaged; remove it to start afresh."
        )
    return data.reshape(n, size)


def _read_cuts(path: Path, n: int, n_bytes: int) -> tuple[list, int]:
    """The first ``n`` failed attempts in ``path`` (``n_bytes`` bytes) and the CRC-32 of those bytes."""
    if n == 0:
        return [], zlib.crc32(b"")
    try:
        with open(path, "rb") as fh:
            data = fh.read(n_bytes)
        lines = data.decode("utf-8").splitlines()
        cuts = [json.loads(line) for line in lines]
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InvalidParameter(
            f"the checkpoint's {path.name} cannot be read ({type(exc).__name__}: {exc}): the "
            "directory is damaged; remove it to start afresh."
        ) from None
    if len(data) != n_bytes or len(cuts) != n:
        raise InvalidParameter(
            f"{path} holds {len(cuts)} failed attempts, the checkpoint counts {n}: the directory is "
            "damaged; remove it to start afresh."
        )
    return cuts, zlib.crc32(data)


class Checkpointer:
    """Writes the checkpoints of one run (used by :func:`fe.simulate`).

    Parameters
    ----------
    directory : path-like
        Created if missing.
    every : int
        Steps between periodic checkpoints (0: none; only on Ctrl-C and at the end).
    fingerprint : dict
        The run's description (:func:`run_fingerprint`).
    frame_size : int
        Floats per frame record.
    resume : Checkpoint or None
        The checkpoint the run continues from (its records are kept), or None
        for a fresh run (earlier checkpoint files are removed).
    """

    def __init__(self, directory, every, fingerprint, frame_size, resume=None):
        self.directory = Path(directory)
        self.every = int(every)
        self.fingerprint = fingerprint
        self.frame_size = int(frame_size)
        self.directory.mkdir(parents=True, exist_ok=True)
        if resume is None:
            for name in (CHECKPOINT_NAME, FRAMES_NAME, STEPS_NAME, CUTS_NAME):
                (self.directory / name).unlink(missing_ok=True)
            self.n_frames = self.last_step = self.n_cuts = self.cuts_bytes = 0
            self.crc = dict.fromkeys((FRAMES_NAME, STEPS_NAME, CUTS_NAME), 0)  # CRC-32 of no bytes
        else:
            self.n_frames, self.last_step, self.n_cuts = len(resume.frames), resume.step, len(resume.cuts)
            self.cuts_bytes = resume.cuts_bytes
            self.crc = dict(resume.crc32)
        for tmp in self.directory.glob(f".{CHECKPOINT_NAME}.*.tmp"):  # what a kill mid-write left
            tmp.unlink(missing_ok=True)

    def due(self, steps_done: int) -> bool:
        """True when a periodic checkpoint is due after ``steps_done`` steps."""
        return self.every > 0 and steps_done % self.every == 0

    def write(self, snapshot, frames, stats, cuts) -> Path:
        """Append the records since the last checkpoint, then replace ``checkpoint.npz``.

        Parameters
        ----------
        snapshot : _Snapshot
            The loop's consistent state after ``snapshot.step`` steps.
        frames : list of numpy.ndarray
            Every frame record of the run so far (at least ``snapshot.n_frames``).
        stats : dict of numpy.ndarray
            Per-step statistics of the whole run (the first ``snapshot.step`` are used).
        cuts : list of dict
            Every failed attempt so far (the first ``snapshot.n_cuts`` are used).
        """
        d = self.directory
        k, nf, nc = snapshot.step, snapshot.n_frames, snapshot.n_cuts
        new_frames = _record_bytes(frames[self.n_frames:nf])
        self._append_bytes(d / FRAMES_NAME, self.n_frames * self.frame_size * 8, new_frames)
        rows: np.ndarray | list = np.column_stack([np.asarray(stats[name][self.last_step:k], dtype=float)
                                for name in STEP_FIELDS]) if k > self.last_step else []
        new_steps = _record_bytes(rows)
        self._append_bytes(d / STEPS_NAME, self.last_step * len(STEP_FIELDS) * 8, new_steps)
        new_cuts = _cut_lines(cuts[self.n_cuts:nc])
        self._append_bytes(d / CUTS_NAME, self.cuts_bytes, new_cuts)
        cuts_bytes = self.cuts_bytes + len(new_cuts)
        crc = {FRAMES_NAME: zlib.crc32(new_frames, self.crc[FRAMES_NAME]),  # running CRC of the prefix
               STEPS_NAME: zlib.crc32(new_steps, self.crc[STEPS_NAME]),
               CUTS_NAME: zlib.crc32(new_cuts, self.crc[CUTS_NAME])}
        meta = {
            "format": FORMAT, "step": k, "n_steps": self.fingerprint["n_steps"], "n_frames": nf,
            "n_cuts": nc, "cuts_bytes": cuts_bytes, "frame_size": self.frame_size,
            "driving": bool(snapshot.driving), "step_fields": list(STEP_FIELDS),
            "fingerprint": self.fingerprint, "crc32": crc,
        }
        s = snapshot.state
        arrays = {
            "x": s.x, "v": s.v, "scalars": np.array([s.t, snapshot.e_ref, snapshot.scale, snapshot.wall_time,
                                                 snapshot.work, snapshot.work_abs]),
            "meta": np.array(json.dumps(meta)),
        }
        for key, a in snapshot.integrator_state.items():
            arrays[f"integrator/{key}"] = np.asarray(a)
        for key, a in snapshot.model_state.items():
            arrays[f"model/{key}"] = np.asarray(a)

        def write(tmp):
            buf = _io.BytesIO()
            np.savez(buf, **arrays)
            with open(tmp, "wb") as fh:
                fh.write(buf.getvalue())

        path = _atomic_write(d / CHECKPOINT_NAME, write)
        self.n_frames, self.n_cuts, self.last_step = nf, nc, k
        self.cuts_bytes, self.crc = cuts_bytes, crc
        log.debug("checkpoint after %d steps (t = %.6g s) in %s", k, s.t, d)
        return path

    @staticmethod
    def _append(path: Path, n_done: int, size: int, records) -> None:
        """Cut ``path`` to its first ``n_done`` records of ``size`` floats, append ``records``, fsync."""
        data = b"".join(np.asarray(r, dtype="<f8").tobytes() for r in records)
        Checkpointer._append_bytes(path, n_done * size * 8, data)

    @staticmethod
    def _append_bytes(path: Path, n_keep: int, data: bytes) -> None:
        """Cut ``path`` to ``n_keep`` bytes (a tail a crash left), append ``data`` and fsync.

        The bytes a committed checkpoint counts are never rewritten, so a crash
        here leaves that checkpoint readable.
        """
        try:
            with open(path, "ab") as fh:
                fh.truncate(n_keep)
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
        except OSError as exc:  # a full disk: the committed records stay as they were
            raise write_failed(path, exc) from exc


def _record_bytes(records) -> bytes:
    """Records of float64 as the little-endian bytes the appended files hold."""
    return b"".join(np.asarray(r, dtype="<f8").tobytes() for r in records)


def _cut_lines(cuts) -> bytes:
    """``cuts.jsonl`` records: one JSON object per line, UTF-8."""
    return "".join(json.dumps(c) + "\n" for c in cuts).encode("utf-8")


@dataclass
class _Snapshot:
    """The loop's state after ``step`` steps, consistent as a whole (see :func:`fe.simulate`)."""

    step: int
    state: State
    n_frames: int
    n_cuts: int
    e_ref: float
    scale: float
    driving: bool
    wall_time: float
    integrator_state: dict
    work: float = 0.0
    work_abs: float = 0.0
    model_state: dict = field(default_factory=dict)


def model_checkpoint_state(model) -> dict:
    """What the model remembers between steps: its bound contact's state (IPC's adaptive
    kappa), as ``{"contact.<name>": array}``; empty for a model without such state."""
    save = getattr(getattr(model, "contact", None), "checkpoint_state", None)
    return {f"contact.{k}": a for k, a in save().items()} if save is not None else {}


def restore_model_state(model, saved: dict) -> None:
    """Give the model back what :func:`model_checkpoint_state` returned (a resumed run)."""
    contact = {k[len("contact."):]: a for k, a in saved.items() if k.startswith("contact.")}
    if contact:  # the run's fingerprint (its terms) already matched: the model has that contact
        model.contact.restore_state(contact)


def check_resumable(ck: Checkpoint, fingerprint: dict) -> None:
    """:class:`InvalidParameter` unless ``ck`` was written by a run with this fingerprint."""
    if ck.fingerprint == fingerprint:
        return
    diff = sorted(k for k in set(ck.fingerprint) | set(fingerprint)
                  if ck.fingerprint.get(k) != fingerprint.get(k))
    details = []
    for k in diff[:4]:
        a, b = ck.fingerprint.get(k), fingerprint.get(k)
        if k in ("dt", "density", "energy_growth") and isinstance(a, str) and isinstance(b, str):
            a, b = (float.fromhex(a) if a != "inf" else a), (float.fromhex(b) if b != "inf" else b)
        details.append(f"{k}: checkpoint {a!r}, now {b!r}")
    raise InvalidParameter(
        f"the checkpoint in {ck.directory} was written by a different run ({'; '.join(details)}). "
        "Resume with the same model, integrator, dt, steps, record_every and initial state, or "
        "start afresh (resume=False, or remove the directory)."
    )
