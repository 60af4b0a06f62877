"""Running a scene: simulate each of its variants and write what it asks for.

The glue between the scene layer (:mod:`fem_elastic.app.scene`), the time loop
(:func:`fem_elastic.dynamics.simulate`), the output series (:mod:`fem_elastic.app.output`)
and the renderer (:mod:`fem_elastic.app.render`). An output directory holds one
run directory per variant (``OUT/<variant>/series.pvd``, ``frames/``,
``summary.json``), the movies and frames rendered from them side by side, and
``OUT/summary.json`` with every variant's figures.

A run that diverges, fails (a step raised an error: :class:`fe.StepFailed`)
or is interrupted (Ctrl-C) still leaves every frame written so far readable,
a checkpoint of its last good step and a ``summary.json`` that says how it
ended (for a failure: at which step, and why).

Each run directory also holds ``checkpoint/`` (:mod:`fem_elastic.dynamics.checkpoint`):
written every ``[output] checkpoint_every`` steps, on Ctrl-C and at the end.
The output directory keeps a copy of the scene (``scene.toml``) and how it was
run (``run.json``), so ``fem-elastic run --resume OUT`` (:func:`resume_scene`)
continues every variant from its last checkpoint, bit for bit as if it had
never stopped.
"""

from __future__ import annotations

import hashlib
import json
import logging
import shlex
import time
from dataclasses import dataclass
from pathlib import Path

from ..errors import Diverged, InvalidParameter, StepFailed

log = logging.getLogger(__name__)

__all__ = ["RunOutcome", "SceneInterrupted", "run_scene", "write_scene_summary", "run_variant", "render_outputs",
           "read_resumable", "resume_scene", "CHECKPOINT_DIR", "output_bytes"]

#: The checkpoint directory inside a run directory.
CHECKPOINT_DIR = "checkpoint"
#: The copy of the scene, and how it was run, in an output directory (for --resume).
SCENE_COPY, RUN_RECORD = "scene.toml", "run.json"


@dataclass
class RunOutcome:
    """How one variant's run ended.

    Attributes
    ----------
    name : str
        The variant's name (its run directory under the output directory).
    run_dir : Path
        Where its series and ``summary.json`` are.
    status : str
        ``"completed"``, ``"diverged"``, ``"failed"`` (a step raised an error) or ``"interrupted"``.
    message : str
        How it ended, in words.
    trajectory : Trajectory or None
        What :func:`fe.simulate` recorded (the frames up to the last good state
        when it diverged; None when interrupted).
    seconds_simulate : float
        Wall time of the time loop, output writing included (s).
    seconds_output : float
        Of which writing the VTU series (s).
    run : BuiltRun or None
        The variant as built (model, integrator, dt, steps, ...).
    result : StaticResult or None
        A static run's result (``[solve] kind = "static"``, :mod:`fem_elastic.app.static_run`).
    figures : dict or None
        A static run's physical result: largest displacement (m), reaction on each support (N).
    physics : dict or None
        A completed time-stepping run's physical result
        (:func:`fem_elastic.app.result_files.dynamic_figures`): largest displacement (m),
        final reactions (N), probe points.
    """

    name: str
    run_dir: Path
    status: str
    message: str
    trajectory: object = None
    seconds_simulate: float = 0.0
    seconds_output: float = 0.0
    run: object = None
    result: object = None
    figures: dict | None = None
    physics: dict | None = None


class SceneInterrupted(KeyboardInterrupt):
    """Ctrl-C during a scene.

    Attributes
    ----------
    outcome : RunOutcome
        What was stopped: a run (its frames so far are readable), or the rendering.
    outcomes : list of RunOutcome
        Every run of the scene so far, the stopped one included.
    """

    def __init__(self, outcome: RunOutcome, outcomes=None):
        super().__init__(outcome.message)
        self.outcome = outcome
        self.outcomes = list(outcomes) if outcomes is not None else [outcome]


def run_variant(run, out_dir, *, progress: bool = False, checkpoint_every: int | None = None,
                resume: bool = False) -> RunOutcome:
    """Simulate one built variant of a scene and write its series.

    Parameters
    ----------
    run : BuiltRun
        From :meth:`fe.Scene.build`.
    out_dir : path-like
        The scene's output directory; the run goes to ``out_dir / run.name``.
    progress : bool
        Show a tqdm progress bar.
    checkpoint_every : int, optional
        Steps between checkpoints (0: only on Ctrl-C and at the end); default
        the scene's ``[output] checkpoint_every``.
    resume : bool
        Continue from the run directory's checkpoint (if it has one) and keep
        the frames written up to it; else start afresh.

    Returns
    -------
    RunOutcome
        ``status`` is ``"completed"``, ``"diverged"`` or ``"failed"`` (a
        :class:`fe.Diverged`, or a :class:`fe.StepFailed` when a step raised an
        error, is caught, recorded in ``summary.json`` and reported here).

    Raises
    ------
    SceneInterrupted
        On Ctrl-C, after the frames so far, a checkpoint and ``summary.json`` are written.
    """
    if getattr(run, "static", None) is not None:  # [solve] kind = "static": a load path, no time
        from .static_run import run_static_variant

        return run_static_variant(run, out_dir)
    from ..dynamics.checkpoint import CHECKPOINT_NAME, load_checkpoint
    from .output import SUMMARY_NAME, SeriesWriter, remove_temporary_files
    from ..dynamics.simulate import simulate

    run_dir = Path(out_dir) / run.name
    ck_dir = run_dir / CHECKPOINT_DIR
    every = run.output.get("checkpoint_every", 0) if checkpoint_every is None else checkpoint_every
    start = load_checkpoint(ck_dir) if resume and (ck_dir / CHECKPOINT_NAME).is_file() else None
    if start is not None and start.complete and _finished(run_dir / SUMMARY_NAME):
        # finished and written: nothing to redo (its files may have been pruned, [output] vtu = false)
        remove_temporary_files(run_dir)
        traj = simulate(run.model, run.integrator, run.dt, steps=run.steps, state=run.state,
                        record_every=run.record_every, checkpoint_dir=ck_dir, checkpoint_every=every,
                        resume=start)  # checks the checkpoint is this run's, returns its trajectory
        return RunOutcome(run.name, run_dir, "completed", traj.message, traj, 0.0, 0.0, run)
    from ..resources import check_disk

    check_disk(out_dir, output_bytes(run.model, run.steps, run.record_every),
               f"the series of {run.name!r} ({run.steps // run.record_every + 1} frames)")
    # n_steps: the writer writes the last frame, before simulate's final checkpoint
    writer = SeriesWriter(run.model, run_dir, every=run.record_every, n_steps=run.steps, info=run.info,
                          resume_from=start)
    t0 = time.perf_counter()
    if start is None:
        writer.write_state(run.state)
    try:
        traj = simulate(
            run.model, run.integrator, run.dt, steps=run.steps, state=run.state,
            record_every=run.record_every, progress=progress, observers=[writer],
            checkpoint_dir=ck_dir, checkpoint_every=every, resume=start or False,
        )
    except Diverged as err:
        elapsed = time.perf_counter() - t0
        msg = str(err)  # where, why, and what to try
        if not writer.finished:  # the writer's on_failure hook finished it already, as a rule
            writer.finish_failed(err)
        status = "failed" if isinstance(err, StepFailed) else "diverged"
        log.info("%s: %s", run.name, msg)  # the caller reports it (the command on stderr)
        return RunOutcome(run.name, run_dir, status, msg, err.trajectory, elapsed, writer.seconds_output, run)
    except KeyboardInterrupt:
        elapsed = time.perf_counter() - t0
        msg = (f"interrupted after {writer.steps_taken} of {run.steps} steps; the frames written so far in "
               f"{run_dir} are complete and readable, and `{_resume_command(out_dir)}` continues "
               "from the checkpoint")
        writer.finish(None, status="interrupted", message=msg)
        raise SceneInterrupted(
            RunOutcome(run.name, run_dir, "interrupted", msg, None, elapsed, writer.seconds_output, run)
        ) from None
    elapsed = time.perf_counter() - t0
    from .result_files import dynamic_figures

    physics = dynamic_figures(run.model, traj, (run.info or {}).get("probe"))
    writer.finish(traj, status="completed", message=traj.message, extra=physics)
    return RunOutcome(run.name, run_dir, "completed", traj.message, traj, elapsed,
                      writer.seconds_output, run, physics=physics)


def output_bytes(model, steps: int, record_every: int) -> float:
    """Disk a run's series and checkpoint take at most (bytes), from the model's counts.

    A VTU frame holds, uncompressed, 72 bytes per node (points, displacement
    and velocity: three float64 each) and per tet its
    connectivity (8 bytes per node of the cell), offset, type and three float64
    cell fields; zlib makes it smaller (a 1920-tet P1 frame: 88 kB written
    against 163 kB by this bound), so this is an upper bound. A checkpoint
    record adds ``8 (9 + 6 n_vertices)`` bytes per frame.
    """
    n_nodes = model.X.size // 3
    n_tets = model.mesh.t.shape[1]
    nloc = 4 if n_nodes == model.mesh.p.shape[1] else 10
    frame = 72.0 * n_nodes + (8.0 * nloc + 33.0) * n_tets + 8.0 * (9 + 6 * model.mesh.p.shape[1])
    return frame * (steps // max(int(record_every), 1) + 2)


def _finished(summary_path: Path) -> bool:
    """True when a run's ``summary.json`` says it completed."""
    try:
        return json.loads(summary_path.read_text(encoding="utf-8")).get("status") == "completed"
    except (OSError, ValueError, AttributeError):
        return False


def _resume_command(out_dir) -> str:
    """The command that resumes ``out_dir``, quoted for a POSIX shell."""
    return f"fem-elastic run --resume {shlex.quote(str(out_dir))}"


def render_outputs(out_dir, run_dirs, output: dict, *, progress: bool = False) -> list[Path]:
    """Render the runs side by side in each format the scene asks for.

    Parameters
    ----------
    out_dir : path-like
        Where the movies go: ``movie.mp4``, ``movie.gif``, ``png/frame_0000.png``...
    run_dirs : sequence of path-like
        The run directories, drawn left to right.
    output : dict
        The scene's output settings (``render``, ``size``, ``color_by``, ``fps``).

    Returns
    -------
    list of Path
        The files written.
    """
    formats = list(output.get("render", []))
    if not formats:
        return []
    from .render import render_runs

    out_dir = Path(out_dir)
    written = []
    for fmt in formats:
        target = out_dir / "png" if fmt == "png" else out_dir / f"movie.{fmt}"
        written += render_runs(
            list(run_dirs), target, format=fmt, size=tuple(output.get("size", (960, 540))),
            color_by=output.get("color_by", "von_mises"), fps=int(output.get("fps", 30)),
            progress=progress,
        )
    return written


def run_scene(scene, out_dir, *, variants=None, progress: bool = False, render: bool = True,
              checkpoint_every: int | None = None, resume: bool = False, overwrite: bool = False):
    """Run every variant of a scene into ``out_dir`` and render them.

    Parameters
    ----------
    scene : Scene
        From :func:`fe.load_scene`.
    out_dir : path-like
        Output directory (created).
    variants : sequence of str, optional
        Only these variants (default: all).
    progress : bool
        Progress bars.
    render : bool
        Render the formats the scene's ``[output].render`` lists.
    checkpoint_every : int, optional
        Steps between checkpoints; default the scene's ``[output] checkpoint_every``.
    resume : bool
        Continue each variant from its checkpoint (see :func:`resume_scene`).
    overwrite : bool
        Write into ``out_dir`` even when it holds files a run did not write
        (they are left alone; see :mod:`fem_elastic.app.run_lock`).

    Returns
    -------
    (list of RunOutcome, list of Path)
        The outcomes in the scene's order, and the rendered files.

    Raises
    ------
    OutputInUse
        Another run holds ``out_dir``'s lock.
    InvalidParameter
        ``out_dir`` is empty, a file, or holds files a run did not write (without ``overwrite``).
    """
    from .run_lock import RunLock, check_output_dir, remove_stale_variants

    t0 = time.perf_counter()
    out_dir = check_output_dir(out_dir, overwrite=overwrite or resume)
    runs = scene.build(variants)  # before touching the directory: a bad scene leaves it as it was
    out_dir.mkdir(parents=True, exist_ok=True)
    with RunLock(out_dir):  # one run at a time in a directory; dropped on any exit, Ctrl-C too
        if not resume:  # the folders of variants this scene does not have are another run's
            remove_stale_variants(out_dir, list(scene.variants) + [r.name for r in runs])
        try:
            outcomes, rendered = _run_locked(scene, out_dir, runs, variants, progress, render,
                                             checkpoint_every, resume)
        except SceneInterrupted as stop:  # the scene's summary says so, written under the lock
            write_scene_summary(out_dir, scene, stop.outcomes, [], time.perf_counter() - t0,
                                status="interrupted")
            raise
        write_scene_summary(out_dir, scene, outcomes, rendered, time.perf_counter() - t0)
        return outcomes, rendered


def write_scene_summary(out_dir, scene, outcomes, rendered, seconds, status=None) -> None:
    """Write ``OUT/summary.json``: the scene's status and every variant's figures.

    :func:`run_scene` writes it while it holds the output directory's lock.

    Parameters
    ----------
    out_dir : path-like
    scene : Scene
    outcomes : list of RunOutcome
    rendered : list of path-like
        The rendered files (under ``out_dir``).
    seconds : float
        Wall time of the whole run (s).
    status : str, optional
        Default ``"completed"`` when every variant completed, else ``"failed"``.
    """
    from .output import write_summary

    write_summary(
        Path(out_dir) / "summary.json",
        {
            "scene": scene.name,
            "source": str(scene.source),
            "status": status or ("completed" if all(o.status == "completed" for o in outcomes)
                                 else "failed"),
            "seconds_total": seconds,
            "variants": {
                o.name: {"status": o.status, "message": o.message, "run_dir": o.run_dir.name,
                         "seconds_simulate": o.seconds_simulate, "seconds_output": o.seconds_output,
                         **(o.figures or {})}
                for o in outcomes
            },
            "rendered": [str(Path(p).relative_to(out_dir)) for p in rendered],
        },
    )


def _run_locked(scene, out_dir, runs, variants, progress, render, checkpoint_every, resume):
    """:func:`run_scene` once the output directory is checked and locked."""
    (out_dir / "summary.json").unlink(missing_ok=True)  # an earlier run's: stale from now on
    if not resume:
        _record_run(out_dir, scene, variants, render, checkpoint_every)
    outcomes = []
    for run in runs:
        try:
            outcomes.append(run_variant(run, out_dir, progress=progress,
                                        checkpoint_every=checkpoint_every, resume=resume))
        except SceneInterrupted as stop:
            raise SceneInterrupted(stop.outcome, outcomes + [stop.outcome]) from None
        except KeyboardInterrupt:  # outside the time loop: setting up or finishing the series
            interrupted = RunOutcome(run.name, out_dir / run.name, "interrupted", (
                f"interrupted while writing its series; `{_resume_command(out_dir)}` continues from "
                "the checkpoints"), None, 0.0, 0.0, run)
            raise SceneInterrupted(interrupted, outcomes + [interrupted]) from None
    rendered = []
    if render and runs:
        try:
            rendered = render_outputs(out_dir, [o.run_dir for o in outcomes], runs[0].output,
                                      progress=progress)
        except KeyboardInterrupt:
            interrupted = RunOutcome("render", out_dir, "interrupted", (
                f"interrupted while rendering; the VTU series are complete: `fem-elastic render "
                f"{out_dir}` renders them"))
            raise SceneInterrupted(interrupted, outcomes) from None
    if runs and not runs[0].output.get("vtu", True):
        for o in outcomes:
            _remove_series(o.run_dir)
    return outcomes, rendered


def _record_run(out_dir: Path, scene, variants, render, checkpoint_every) -> None:
    """Keep the scene's text and how it was run in ``out_dir``, for ``--resume``."""
    from ..files import write_text_atomic

    source = Path(scene.source)
    record = {
        "format": 1,
        "source": str(source.resolve()) if source.is_file() else str(scene.source),
        "base_dir": str(Path(scene.base_dir).resolve()),
        "variants": None if variants is None else list(variants),
        "render": bool(render),
        "checkpoint_every": checkpoint_every,
        "scene_sha256": hashlib.sha256(scene.text.encode("utf-8")).hexdigest(),  # edits are refused
    }
    write_text_atomic(out_dir / SCENE_COPY, scene.text)
    write_text_atomic(out_dir / RUN_RECORD, json.dumps(record, indent=2) + "\n")


def read_resumable(out_dir):
    """The scene an output directory was run with, and how (for :func:`resume_scene`).

    Parameters
    ----------
    out_dir : path-like
        The output directory of an earlier ``fem-elastic run`` or :func:`run_scene`.

    Returns
    -------
    (Scene, dict)
        The scene, read from the copy the run kept (``out_dir/scene.toml``, with
        relative mesh paths resolved against the original scene's directory), and
        the run's record: ``variants`` (None for all), ``render`` and ``checkpoint_every``.

    Raises
    ------
    InvalidParameter
        ``out_dir`` is not the output of a scene run.
    """
    from .scene import parse_scene

    out_dir = Path(out_dir)
    copy, record_path = out_dir / SCENE_COPY, out_dir / RUN_RECORD
    if not (copy.is_file() and record_path.is_file()):
        raise InvalidParameter(
            f"{out_dir} is not the output directory of `fem-elastic run` (it has no {SCENE_COPY} and "
            f"{RUN_RECORD}); give the --out directory of the run to resume."
        )
    try:
        record = json.loads(record_path.read_text(encoding="utf-8"))
        source, base_dir = str(record["source"]), str(record["base_dir"])
    except (ValueError, KeyError, TypeError) as exc:
        raise InvalidParameter(f"{record_path} cannot be read ({exc}); start the run afresh.") from None
    raw = copy.read_bytes()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InvalidParameter(
            f"{copy} is not UTF-8 (byte {exc.start}: {raw[exc.start:exc.start + 1]!r}); it was re-saved in "
            "another encoding since the run. Save it as UTF-8 again (the run wrote it so), or start the "
            "run afresh in a new directory."
        ) from None
    digest = record.get("scene_sha256")
    if digest is not None and hashlib.sha256(raw).hexdigest() != digest:
        raise InvalidParameter(
            f"{copy} was edited after the run started (its SHA-256 differs from the one in {record_path}); "
            "a resumed run must continue the same scene. Undo the edit to resume, or run the edited "
            "scene afresh: `fem-elastic run SCENE.toml --out NEW_DIR`."
        )
    scene = parse_scene(text, source=source, base_dir=base_dir)
    return scene, record


def resume_scene(out_dir, *, progress: bool = False, render: bool | None = None):
    """Continue a scene run in ``out_dir`` from its checkpoints (``fem-elastic run --resume``).

    The scene, variants, rendering and checkpoint interval are those the run
    was started with (:func:`read_resumable`). Variants with a checkpoint
    continue from it (a finished one returns at once), the others start
    afresh; the series and summaries end as those of an uninterrupted run.

    Parameters
    ----------
    out_dir : path-like
        The output directory of an earlier ``fem-elastic run`` or :func:`run_scene`.
    progress : bool
    render : bool, optional
        Render afterwards; default as the run did.

    Returns
    -------
    (list of RunOutcome, list of Path)
        As :func:`run_scene`.

    Raises
    ------
    InvalidParameter
        ``out_dir`` is not the output of a scene run.
    SceneInterrupted
        On Ctrl-C (after a new checkpoint).
    """
    scene, record = read_resumable(out_dir)
    render = record.get("render", True) if render is None else render
    return run_scene(scene, out_dir, variants=record.get("variants"), progress=progress,
                     render=render, checkpoint_every=record.get("checkpoint_every"), resume=True)


def _remove_series(run_dir: Path) -> None:
    """Remove a run's VTU series (``[output] vtu = false``), keeping its ``summary.json``.

    The series is written during the run all the same: the renders are drawn
    from it, and it keeps the frames of a run that is interrupted or diverges.
    """
    from .output import FRAMES_DIR, PVD_NAME

    (run_dir / PVD_NAME).unlink(missing_ok=True)  # first: no reader sees a half-removed series
    frames = run_dir / FRAMES_DIR
    for p in sorted(frames.glob("frame_*.vtu")):
        p.unlink(missing_ok=True)
    try:
        frames.rmdir()
    except OSError:  # something else lives there: leave it
        pass
