"""Running a scene: simulate each of its variants and write what it asks for.

The glue between the scene layer (:mod:`fem_elastic.scene`), the time loop
(:func:`fem_elastic.simulate`), the output series (:mod:`fem_elastic.output`)
and the renderer (:mod:`fem_elastic.render`). An output directory holds one
run directory per variant (``OUT/<variant>/series.pvd``, ``frames/``,
``summary.json``), the movies and frames rendered from them side by side, and
``OUT/summary.json`` with every variant's figures.

A run that diverges or is interrupted (Ctrl-C) still leaves every frame
written so far readable and a ``summary.json`` that says how it ended.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

from .errors import Diverged, InvalidParameter

log = logging.getLogger(__name__)

__all__ = ["RunOutcome", "SceneInterrupted", "run_scene", "run_variant", "render_outputs"]


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
        ``"completed"``, ``"diverged"`` or ``"interrupted"``.
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
    """

    name: str
    run_dir: Path
    status: str
    message: str
    trajectory: object = None
    seconds_simulate: float = 0.0
    seconds_output: float = 0.0
    run: object = None


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


def run_variant(run, out_dir, *, progress: bool = False) -> RunOutcome:
    """Simulate one built variant of a scene and write its series.

    Parameters
    ----------
    run : BuiltRun
        From :meth:`fe.Scene.build`.
    out_dir : path-like
        The scene's output directory; the run goes to ``out_dir / run.name``.
    progress : bool
        Show a tqdm progress bar.

    Returns
    -------
    RunOutcome
        ``status`` is ``"completed"`` or ``"diverged"`` (a :class:`fe.Diverged`
        is caught, recorded in ``summary.json`` and reported here).

    Raises
    ------
    SceneInterrupted
        On Ctrl-C, after the frames so far and ``summary.json`` are written.
    """
    from .output import SeriesWriter
    from .simulate import simulate

    run_dir = Path(out_dir) / run.name
    writer = SeriesWriter(run.model, run_dir, every=run.record_every, info=run.info)
    t0 = time.perf_counter()
    writer.write_state(run.state)
    try:
        traj = simulate(
            run.model, run.integrator, run.dt, steps=run.steps, state=run.state,
            record_every=run.record_every, progress=progress, callback=writer.callback,
        )
    except Diverged as err:
        elapsed = time.perf_counter() - t0
        msg = f"diverged at step {err.step} (t = {err.time:.6g} s): {err.reason}"
        writer.finish(err.trajectory, status="diverged", message=msg, final_state=err.last_good_state)
        log.warning("%s: %s", run.name, msg)
        return RunOutcome(run.name, run_dir, "diverged", msg, err.trajectory, elapsed, writer.seconds_output, run)
    except KeyboardInterrupt:
        elapsed = time.perf_counter() - t0
        msg = (f"interrupted after {writer.steps_taken} of {run.steps} steps; the frames written so far in "
               f"{run_dir} are complete and readable")
        writer.finish(None, status="interrupted", message=msg)
        raise SceneInterrupted(
            RunOutcome(run.name, run_dir, "interrupted", msg, None, elapsed, writer.seconds_output, run)
        ) from None
    elapsed = time.perf_counter() - t0
    writer.finish(traj, status="completed", message=traj.message)
    return RunOutcome(run.name, run_dir, "completed", traj.message, traj, elapsed, writer.seconds_output, run)


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


def run_scene(scene, out_dir, *, variants=None, progress: bool = False, render: bool = True):
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

    Returns
    -------
    (list of RunOutcome, list of Path)
        The outcomes in the scene's order, and the rendered files.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InvalidParameter(f"--out {out_dir} is a file; give a directory for the run's output.")
    out_dir.mkdir(parents=True, exist_ok=True)
    runs = scene.build(variants)
    outcomes = []
    for run in runs:
        try:
            outcomes.append(run_variant(run, out_dir, progress=progress))
        except SceneInterrupted as stop:
            raise SceneInterrupted(stop.outcome, outcomes + [stop.outcome]) from None
    rendered = []
    if render and runs:
        try:
            rendered = render_outputs(out_dir, [o.run_dir for o in outcomes], runs[0].output,
                                      progress=progress)
        except KeyboardInterrupt:
            stop = RunOutcome("render", out_dir, "interrupted", (
                f"interrupted while rendering; the VTU series are complete: `fem-elastic render "
                f"{out_dir}` renders them"))
            raise SceneInterrupted(stop, outcomes) from None
    if runs and not runs[0].output.get("vtu", True):
        for o in outcomes:
            _remove_series(o.run_dir)
    return outcomes, rendered


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
