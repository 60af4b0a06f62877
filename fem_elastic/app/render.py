"""Off-screen pictures and movies of run directories, drawn with pyvista.

A run directory (written by :class:`fem_elastic.app.output.SeriesWriter`) holds a
VTU series of the deformed mesh. This module draws it without a display:
the deformed surface coloured by von Mises stress (Pa) or displacement
magnitude (m) over the grey outline of the undeformed body, the displacement
magnified when it is too small to see (``warp``, stated on the picture), a
colour bar with its unit in a band below the scene, the ground plane (whole)
when the run had one, the scene's name and a time label (a run that blew up or failed says
"diverged at step N: reason" under its title on every frame, from its ``summary.json``),
as PNG frames, a GIF or an MP4 (H.264). Several runs
of the same scene (FEM beside its mass-spring copy, say) are drawn side by
side, one viewport each, with one colour range and one camera for all.

Two choices make the frames of a movie comparable, so both are made before
the first frame is drawn, from every frame of every run:

- **The colour range is fixed.** Both fields are magnitudes, so the range
  starts at 0. Its top is the 99th percentile of the finite values shown
  (the surface tets or vertices, over all frames and runs), not the
  maximum: the stress at the re-entrant edges of a clamp is singular in the
  continuum and grows without bound under refinement, and a diverging run's
  last frames spike, so the maximum would push the rest of the body into
  the bottom colour. The top percent is drawn in the top colour; NaN or
  inf values are ignored by the range and drawn in red, which viridis
  never uses.
- **The camera is fixed.** It looks at the centre of the union of the
  bounds of every frame of every run (and the ground) from the front,
  a little above and to the side, from the nearest distance at which that
  box fits the viewport; a body that moves therefore moves across a still
  picture, and runs side by side are drawn at the same scale.

Only the surface triangles of the tets are drawn, and each frame only
updates the point coordinates and the scalars of actors built once (the
PyVista gallery's frame loop); the plotter lives for the whole movie.
Movies are drawn without anti-aliasing: with a software OpenGL
(llvmpipe, as on a headless server) 4x multisampling halves the frame rate,
and VTK's EGL and OSMesa builds have no FXAA. Single pictures
(:func:`render_frame`) take 8 samples.

pyvista, imageio and imageio-ffmpeg are optional (``pip install
"fem_elastic[render]"``) and imported inside the functions, so ``import
fem_elastic`` works without them; without them rendering raises
:class:`MissingDependency`, which says what to install.

The scene itself (surfaces, colour range, camera, the plotter) is built in
:mod:`fem_elastic.app.render_scene`.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Literal, Union

import numpy as np

from ..errors import InvalidParameter, MissingDependency
from ..files import _atomic_write, write_failed
from .render_scene import FIELDS, _Run, _run_from_series, _Scene, color_range
from .vtu import SeriesData

#: One run to draw: its directory (``series.pvd``, ``frames/``, ``summary.json``) or its series.
RunSource = Union[str, os.PathLike, SeriesData]

__all__ = ["render_runs", "render_frame", "color_range", "MissingDependency", "FORMATS", "FIELDS"]

logger = logging.getLogger(__name__)

#: Output formats of :func:`render_runs`.
FORMATS = ("mp4", "gif", "png")

_INSTALL = 'pip install "fem_elastic[render]"'


def _require(module: str):
    """Import ``module`` or raise MissingDependency with the install command."""
    import importlib

    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as err:
        raise MissingDependency(
            f"Rendering needs {module.split('.')[0]}, which is not installed ({err}). "
            f'Install the rendering extras with: {_INSTALL}',
            name=err.name,
        ) from err


# --- loading runs ------------------------------------------------------------------------------


def _as_list(run_dirs) -> list:
    if isinstance(run_dirs, (str, os.PathLike)) or hasattr(run_dirs, "displacement"):
        return [run_dirs]
    run_dirs = list(run_dirs)
    if not run_dirs:
        raise InvalidParameter("No run to render: pass a run directory or a list of them.")
    return run_dirs


def _load_runs(run_dirs, titles, color_by: str, every: int) -> list[_Run]:
    """Read each run's series and check that they can share one movie."""
    if color_by not in FIELDS:
        raise InvalidParameter(
            f"Unknown color_by={color_by!r}; colour by one of {', '.join(map(repr, FIELDS))}."
        )
    if not (isinstance(every, (int, np.integer)) and every >= 1):
        raise InvalidParameter(
            f"every={every!r} must be a positive integer (draw every k-th frame)."
        )
    sources = _as_list(run_dirs)
    if titles is not None:
        titles = [titles] if isinstance(titles, str) else list(titles)
        if len(titles) != len(sources):
            raise InvalidParameter(
                f"{len(titles)} titles for {len(sources)} runs; give one title per run (or none)."
            )
    runs = []
    for i, source in enumerate(sources):
        series = source if hasattr(source, "displacement") else _read_series(Path(source))
        summary = getattr(series, "summary", None) or {}
        if titles is not None:
            title = titles[i]
        else:
            title = summary.get("variant") or (
                Path(source).name if isinstance(source, (str, os.PathLike)) else f"run {i}"
            )
        runs.append(_run_from_series(series, str(title), color_by))
    _check_times(runs)
    if every > 1:
        runs = [_every(run, every) for run in runs]
    return runs


def _read_series(run_dir: Path):
    """``fem_elastic.app.vtu.read_series``, after checking that ``run_dir`` is a directory."""
    from .vtu import read_series

    if not run_dir.is_dir():
        raise InvalidParameter(
            f"{str(run_dir)!r} is not a directory. Pass a run directory, one that "
            "`fem-elastic run` or fem_elastic.app.output.SeriesWriter wrote (it holds series.pvd)."
        )
    if not (run_dir / "series.pvd").is_file():
        inside = sorted(p.parent.name for p in run_dir.glob("*/series.pvd"))
        if inside:  # a scene's output folder: one run directory per variant
            raise InvalidParameter(
                f"{str(run_dir)!r} holds no series.pvd, but its folders {', '.join(inside)} do: "
                f"it is a scene's output folder. Pass those run directories, e.g. "
                f"{[str(run_dir / name) for name in inside]}."
            )
    return read_series(run_dir)


def _check_times(runs: Sequence[_Run]) -> None:
    """Runs drawn side by side must share their frame times.

    A run that stopped early (diverged or interrupted) may hold fewer frames,
    provided its times are the first ones of the others: it then holds its last
    frame while the others go on.
    """
    longest = max(runs, key=lambda r: len(r.times))
    for run in runs:
        ref = longest.times[: len(run.times)]
        # frame times are written with float64 round-off; a relative 1e-6 of the span (and an
        # absolute 1e-12 s for single-frame runs) separates equal clocks from different ones
        tol = 1e-6 * max(float(np.ptp(longest.times)), 0.0) + 1e-12
        if not np.allclose(run.times, ref, rtol=0.0, atol=tol):
            raise InvalidParameter(
                f"Runs {longest.title!r} and {run.title!r} cannot share one movie: their frame "
                f"times differ ({len(longest.times)} frames over [{longest.times[0]:.6g}, "
                f"{longest.times[-1]:.6g}] s against {len(run.times)} over [{run.times[0]:.6g}, "
                f"{run.times[-1]:.6g}] s). Render them separately, or record them with the same "
                "dt and record_every."
            )


def _every(run: _Run, every: int) -> _Run:
    """Keep every ``every``-th frame, and the last one (where a run ends matters)."""
    keep = np.arange(0, len(run.times), every)
    if keep[-1] != len(run.times) - 1:
        keep = np.append(keep, len(run.times) - 1)
    return replace(run, times=run.times[keep], displacement=run.displacement[keep],
                   values=run.values[keep])



# --- writers -----------------------------------------------------------------------------------


def _check_size(size, fmt: str) -> tuple[int, int]:
    try:
        w, h = (int(s) for s in size)
    except (TypeError, ValueError):
        raise InvalidParameter(f"size={size!r} must be (width, height) in pixels.") from None
    if w < 16 or h < 16:
        raise InvalidParameter(f"size={size!r} is too small; give at least 16 x 16 pixels.")
    if fmt == "mp4" and (w % 2 or h % 2):
        raise InvalidParameter(
            f"size={size!r}: an MP4 (H.264, yuv420p) needs an even width and height; "
            f"use e.g. ({w + w % 2}, {h + h % 2})."
        )
    return w, h


def _write_png(path: Path, image: np.ndarray) -> Path:
    """Write an RGB image as a PNG, atomically."""
    iio = _require("imageio.v3")
    return _atomic_write(path, lambda tmp: iio.imwrite(tmp, image, extension=".png"))


def _progress(total: int, enabled: bool, desc: str):
    if not enabled:
        return None
    try:
        from tqdm.auto import tqdm
    except ModuleNotFoundError:
        logger.info("tqdm is not installed; rendering without a progress bar.")
        return None
    return tqdm(total=total, desc=desc, unit="frame")


def render_runs(run_dirs: RunSource | Sequence[RunSource], out: str | os.PathLike[str], *,
                format: Literal["mp4", "gif", "png"] = "mp4", size: tuple[int, int] = (960, 540),
                color_by: Literal["von_mises", "displacement", "body"] = "von_mises",
                fps: float = 30, titles: Sequence[str] | None = None, every: int = 1,
                progress: bool = False, warp: Literal["auto"] | float = "auto") -> list[Path]:
    """Draw one run, or several side by side, as an MP4, a GIF or PNG frames.

    Parameters
    ----------
    run_dirs : str, os.PathLike, SeriesData or sequence of them
        Run directories (each holds ``series.pvd``, see
        :class:`fem_elastic.app.output.SeriesWriter`), or series already read with
        :func:`fem_elastic.app.vtu.read_series`. Several runs are drawn side by side,
        one viewport each, in the order given; they must share their frame
        times (a run that stopped early holds its last frame).
    out : str or os.PathLike
        The movie file (``format="mp4"`` or ``"gif"``), or the directory that
        receives ``frame_0000.png``, ``frame_0001.png``, ... (``"png"``; created
        when missing). Parent directories must exist.
    format : {"mp4", "gif", "png"}
        MP4 is H.264 (libx264, yuv420p, through imageio-ffmpeg) and needs an
        even width and height; GIF is looped forever.
    size : (int, int)
        Width and height of each picture in pixels; the viewports split the width.
    color_by : {"von_mises", "displacement"}
        von Mises stress (Pa, per tet) or displacement magnitude (m, per vertex).
        The colour range is fixed over all frames and shared by all runs (from
        0 to the 99th percentile, see :func:`color_range`).
    fps : float
        Frames per second of a movie (s^-1); a GIF rounds the frame time to
        10 ms.
    titles : sequence of str, optional
        One title per run; default the summary's ``"variant"`` or the directory name.
    every : int
        Draw every ``every``-th recorded frame, and the last.
    progress : bool
        Show a tqdm progress bar.
    warp : "auto" or float
        Magnification of the displacement drawn (:func:`~fem_elastic.app.render_scene.warp_factor`):
        ``"auto"`` magnifies a deflection under 5 % of the body's size (runs
        without a ground), and the picture states the factor; the undeformed
        outline is drawn in grey either way.

    Returns
    -------
    list of pathlib.Path
        ``[out]`` for a movie, the frame files for PNG.

    Raises
    ------
    InvalidParameter
        Unknown format or field, a bad size, a directory without a series,
        runs whose frame times differ.
    MissingDependency
        pyvista, imageio or imageio-ffmpeg is missing.

    Examples
    --------
    >>> from fem_elastic.app.render import render_runs
    >>> render_runs(["out/fem", "out/springs"], "out/demo.mp4")  # doctest: +SKIP
    [PosixPath('out/demo.mp4')]
    """
    if format not in FORMATS:
        raise InvalidParameter(
            f"Unknown format={format!r}; use one of {', '.join(map(repr, FORMATS))}."
        )
    w, h = _check_size(size, format)
    if not fps > 0:
        raise InvalidParameter(f"fps={fps!r} must be positive (frames per second).")
    out = Path(out)
    if format != "png" and not out.parent.is_dir():
        raise InvalidParameter(f"The directory of {str(out)!r} does not exist; create it first.")
    # import what the writer needs before any work, so a missing package fails fast
    pv = _require("pyvista")
    _require("imageio.v3")
    if format == "mp4":
        _require("imageio_ffmpeg")
    runs = _load_runs(run_dirs, titles, color_by, every)
    t0 = time.perf_counter()
    scene = _Scene(pv, runs, color_by, (w, h), warp=warp)
    bar = _progress(scene.n_frames, progress, f"rendering {out.name}")
    try:
        if format == "png":
            written = _render_pngs(scene, out, bar)
        elif format == "gif":
            written = [_render_gif(scene, out, fps, bar)]
        else:
            written = [_render_mp4(scene, out, fps, bar)]
    finally:
        scene.close()
        if bar is not None:
            bar.close()
    elapsed = time.perf_counter() - t0
    logger.info("rendered %d frames of %d run(s) to %s in %.2f s (%.1f frames/s)", scene.n_frames,
                len(runs), out, elapsed, scene.n_frames / elapsed)
    return written


def _render_pngs(scene: _Scene, out: Path, bar) -> list[Path]:
    out.mkdir(exist_ok=True)
    written = []
    for k in range(scene.n_frames):
        written.append(_write_png(out / f"frame_{k:04d}.png", scene.draw(k)))
        if bar is not None:
            bar.update()
    # frames of an earlier, longer render would read as part of this one
    stale = [p for p in out.glob("frame_*.png")
             if p.stem[6:].isdigit() and int(p.stem[6:]) >= scene.n_frames]
    if stale:
        logger.info("%s: removing %d frames of an earlier render", out, len(stale))
        for p in stale:
            p.unlink(missing_ok=True)
    return written


def _render_gif(scene: _Scene, out: Path, fps: float, bar) -> Path:
    from PIL import Image

    # Pillow writes a GIF in one go: keep each frame as a 1-byte-per-pixel palette image,
    # quantized by octree (ten times faster than Pillow's default median cut, alike here)
    frames = []
    for k in range(scene.n_frames):
        image = Image.fromarray(scene.draw(k))
        frames.append(image.quantize(colors=256, method=Image.Quantize.FASTOCTREE))
        if bar is not None:
            bar.update()
    return _atomic_write(out, lambda tmp: frames[0].save(
        tmp, format="GIF", save_all=True, append_images=frames[1:],
        duration=int(round(1000.0 / fps)), loop=0))


def _render_mp4(scene: _Scene, out: Path, fps: float, bar) -> Path:
    imageio_ffmpeg = _require("imageio_ffmpeg")
    w, h = scene.plotter.window_size

    def write(tmp):
        # H.264 in yuv420p (what browsers and players read), crf 20; frames are even-sized,
        # so no rescaling to ffmpeg's 16-pixel macro blocks; "-f mp4": the temporary name
        # does not end in .mp4
        writer = imageio_ffmpeg.write_frames(
            str(tmp), (w, h), fps=fps, codec="libx264", pix_fmt_out="yuv420p", quality=6,
            macro_block_size=1, ffmpeg_log_level="error", output_params=["-f", "mp4"],
        )
        try:
            writer.send(None)  # start ffmpeg
            try:
                for k in range(scene.n_frames):
                    writer.send(np.ascontiguousarray(scene.draw(k)))
                    if bar is not None:
                        bar.update()
            finally:
                writer.close()  # waits for ffmpeg: its trailer errors surface here
        except (OSError, RuntimeError) as exc:  # ffmpeg failed (a full disk, a codec error)
            raise write_failed(out, exc) from exc
        if os.path.getsize(tmp) == 0:  # ffmpeg exited without writing a movie
            raise write_failed(out, OSError(0, "ffmpeg wrote an empty file"))

    return _atomic_write(out, write)


def render_frame(run_dirs: RunSource | Sequence[RunSource], path: str | os.PathLike[str], *,
                 frame: int | Sequence[int] = -1, size: tuple[int, int] = (960, 540),
                 color_by: Literal["von_mises", "displacement", "body"] = "von_mises",
                 titles: Sequence[str] | None = None,
                 warp: Literal["auto"] | float = "auto") -> Path:
    """Draw frames of one run, or of several side by side, as one PNG.

    The colour range and the camera are those of the whole run (as in
    :func:`render_runs`), so pictures of different frames compare.

    Parameters
    ----------
    run_dirs : str, os.PathLike, SeriesData or sequence of them
        As in :func:`render_runs`.
    path : str or os.PathLike
        The PNG file to write (atomically).
    frame : int or sequence of int
        Recorded frame index (negative counts from the end; ``-1`` is the last).
        A sequence draws one row per index, e.g. ``(T // 2, -1)``.
    size : (int, int)
        Width and height of the picture in pixels.
    color_by : {"von_mises", "displacement"}
        As in :func:`render_runs`.
    titles : sequence of str, optional
        One title per run.
    warp : "auto" or float
        As in :func:`render_runs`.

    Returns
    -------
    pathlib.Path
        ``path``.

    Examples
    --------
    >>> from fem_elastic.app.render import render_frame
    >>> render_frame(["out/fem", "out/springs"], "docs/demo.png")  # doctest: +SKIP
    PosixPath('docs/demo.png')
    """
    w, h = _check_size(size, "png")
    path = Path(path)
    if not path.parent.is_dir():
        raise InvalidParameter(f"The directory of {str(path)!r} does not exist; create it first.")
    pv = _require("pyvista")
    _require("imageio.v3")
    frames = [frame] if isinstance(frame, (int, np.integer)) else list(frame)
    if not frames:
        raise InvalidParameter("frame=[] names no frame; give an index such as -1 (the last).")
    runs = _load_runs(run_dirs, titles, color_by, 1)
    n = max(len(run.times) for run in runs)
    for k in frames:
        if not (isinstance(k, (int, np.integer)) and -n <= k < n):
            raise InvalidParameter(
                f"frame={k!r} is out of range: the runs have {n} frames (0..{n - 1}, or -1 for "
                "the last)."
            )
    frames = [int(k) % n for k in frames]
    scene = _Scene(pv, runs, color_by, (w, h), rows=len(frames), multi_samples=8, warp=warp)
    try:
        image = scene.draw(frames)
    finally:
        scene.close()
    return _write_png(path, image)
