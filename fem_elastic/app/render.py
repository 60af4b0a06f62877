"""Off-screen pictures and movies of run directories, drawn with pyvista.

A run directory (written by :class:`fem_elastic.app.output.SeriesWriter`) holds a
VTU series of the deformed mesh. This module draws it without a display:
the deformed surface coloured by von Mises stress (Pa) or displacement
magnitude (m), a scalar bar with its unit, the ground plane when the run had
one, and a time label, as PNG frames, a GIF or an MP4 (H.264). Several runs
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

Notes
-----
On headless Linux (no ``DISPLAY``) VTK's render-window factory first tries
X, logs ``bad X server connection`` to stderr, then falls back to EGL (or
OSMesa). The warning is harmless but alarming, so while the first render
window is created the stderr threshold of VTK's logger is raised to errors
and then restored: VTK still picks the window and falls back as usual, and
real errors still show. Naming the window class in
``VTK_DEFAULT_OPENGL_WINDOW`` (``vtkEGLRenderWindow``) would also skip X,
but gives up the fallback: with a class that cannot be created, VTK 9.7
tried OSMesa only and crashed the process where libOSMesa is missing. A
value the user sets there is respected, and the logger then left alone.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import FemElasticError, InvalidParameter
from ..files import _atomic_write

__all__ = ["render_runs", "render_frame", "color_range", "MissingDependency", "FORMATS", "FIELDS"]

logger = logging.getLogger(__name__)

#: Output formats of :func:`render_runs`.
FORMATS = ("mp4", "gif", "png")

#: Fields to colour by: name -> (label, unit, where the values live).
FIELDS = {
    "von_mises": ("von Mises stress", "Pa", "cell"),
    "displacement": ("displacement", "m", "point"),
}

# From the focal point towards the camera: in front (-y), a little above (+z) and to the
# side of the clamped end (-x), low enough that a deflection in z shows.
VIEW_DIRECTION = (-0.3, -1.0, 0.3)

# The top of the colour range is this percentile of the values shown (see the module docstring).
COLOR_PERCENTILE = 99.0

_INSTALL = 'pip install "fem_elastic[render]"'


class MissingDependency(FemElasticError, ModuleNotFoundError):
    """An optional package that rendering needs is not installed.

    It is a :class:`ModuleNotFoundError` (so ``except ImportError`` catches it)
    and a :class:`~fem_elastic.FemElasticError` (so the command line reports it
    without a traceback); the message says what to install.
    """


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


# --- the data drawn: surfaces and scalars, as arrays ------------------------------------------


def _boundary_faces(tets: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles on the surface of a tet mesh, oriented outwards.

    A face lies on the surface when exactly one tet has it. Only the surface
    is drawn (the interior is hidden anyway), so the frame loop never runs
    VTK's surface filter.

    Parameters
    ----------
    tets : numpy.ndarray
        ``(m, 4)`` vertex indices.
    points : numpy.ndarray
        ``(n, 3)`` reference positions (m), for the orientation.

    Returns
    -------
    faces : numpy.ndarray
        ``(f, 3)`` vertex indices, counter-clockwise seen from outside.
    face_tet : numpy.ndarray
        ``(f,)`` the tet each face belongs to (its cell data colours the face).
    """
    tets = np.asarray(tets, dtype=np.int64)
    # face k of a tet leaves out vertex k
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    faces = tets[:, local].reshape(-1, 3)
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    on_surface = counts[inverse.ravel()] == 1
    faces = faces[on_surface]
    face_tet = np.repeat(np.arange(len(tets)), 4)[on_surface]
    opposite = tets[face_tet, np.tile(np.arange(4), len(tets))[on_surface]]
    # orient: the normal points away from the tet's fourth vertex
    a, b, c = (points[faces[:, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    inward = np.einsum("ij,ij->i", normal, points[opposite] - a) > 0
    faces[inward] = faces[inward][:, [0, 2, 1]]
    return faces, face_tet


@dataclass(frozen=True)
class _Run:
    """One run as the renderer sees it: reference surface, motion and scalars."""

    title: str
    times: np.ndarray  # (T,) s
    points_ref: np.ndarray  # (n, 3) m
    displacement: np.ndarray  # (T, n, 3) m
    faces: np.ndarray  # (f, 3) surface triangles
    values: np.ndarray  # (T, f) on faces or (T, n) on vertices, in the field's unit
    association: str  # "cell" or "point"
    shown: np.ndarray  # indices into values[t] of the entities seen (range statistics)
    ground_z: float | None  # m, height of the ground plane or None
    status: str  # "completed", "interrupted", "diverged" or "" when unknown

    def points(self, k: int) -> np.ndarray:
        """Deformed positions (m), ``(n, 3)``, of frame ``k``."""
        return self.points_ref + self.displacement[k]


def _run_from_series(series, title: str, color_by: str) -> _Run:
    """Turn a SeriesData (anything with its fields) into what the renderer draws."""
    times = np.asarray(series.times, dtype=float)
    points_ref = np.asarray(series.points_ref, dtype=float)
    tets = np.asarray(series.tets)
    displacement = np.asarray(series.displacement, dtype=float)
    if len(times) == 0:
        raise InvalidParameter(
            f"Run {title!r} has no frames to draw. Run the simulation (or let it record at "
            "least one frame) before rendering."
        )
    if displacement.shape != (len(times), len(points_ref), 3):
        raise InvalidParameter(
            f"Run {title!r}: displacement has shape {displacement.shape}, expected "
            f"{(len(times), len(points_ref), 3)} (frames, vertices, 3); the series is "
            "inconsistent: rewrite it with SeriesWriter."
        )
    faces, face_tet = _boundary_faces(tets, points_ref)
    _, _, association = FIELDS[color_by]
    if association == "cell":
        cell_data = getattr(series, "cell_data", None) or {}
        if color_by not in cell_data:
            raise InvalidParameter(
                f"Run {title!r} has no cell data {color_by!r} (it has "
                f"{sorted(cell_data) or 'none'}); colour by one of those, e.g. "
                'color_by="displacement", or write the series with SeriesWriter, which stores it.'
            )
        per_tet = np.asarray(cell_data[color_by], dtype=float)
        if per_tet.shape != (len(times), len(tets)):
            raise InvalidParameter(
                f"Run {title!r}: cell data {color_by!r} has shape {per_tet.shape}, expected "
                f"{(len(times), len(tets))} (frames, tets)."
            )
        values = per_tet[:, face_tet]
        shown = np.unique(face_tet, return_index=True)[1]  # one face per surface tet
    else:
        values = np.linalg.norm(displacement, axis=2)
        shown = np.unique(faces)
    summary = getattr(series, "summary", None) or {}
    ground = summary.get("ground")
    is_plane = isinstance(ground, dict) and ground.get("kind") == "plane"
    ground_z = float(ground["z"]) if is_plane else None
    return _Run(
        title=title, times=times, points_ref=points_ref, displacement=displacement, faces=faces,
        values=values, association=association, shown=shown, ground_z=ground_z,
        status=str(summary.get("status", "")),
    )


def color_range(values, percentile: float = COLOR_PERCENTILE) -> tuple[float, float]:
    """Fixed colour range of a non-negative field over whole runs.

    Parameters
    ----------
    values : iterable of array_like
        Field values (any shapes, in the field's unit), e.g. one array per run.
        NaN and inf are ignored.
    percentile : float, default 99
        The top of the range is this percentile of the finite values, so a
        few spiking elements (a clamp's singular corners, a diverging run)
        do not squeeze the rest of the body into the bottom colour.

    Returns
    -------
    (float, float)
        ``(0, top)`` with ``top > 0``: the percentile; the maximum where the
        percentile is 0 (a field zero almost everywhere); 1 where every value
        is 0 or none is finite.

    Examples
    --------
    >>> from fem_elastic.app.render import color_range
    >>> color_range([[0.0, 1.0, 2.0, float("nan")], [3.0, float("inf")]], percentile=100)
    (0.0, 3.0)
    >>> color_range([[0.0, 0.0]])
    (0.0, 1.0)
    """
    finite = [v[np.isfinite(v)] for v in (np.asarray(a, dtype=float).ravel() for a in values)]
    finite = np.concatenate(finite) if finite else np.empty(0)
    if finite.size == 0:
        return 0.0, 1.0
    top = float(np.percentile(finite, percentile))
    if not top > 0:
        top = float(finite.max())
    if not top > 0:
        top = 1.0
    return 0.0, top


def _union_bounds(runs: Sequence[_Run]) -> np.ndarray:
    """``(2, 3)`` lower and upper corner (m) of every frame of every run and its ground."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for run in runs:
        x = run.points_ref[None] + run.displacement  # (T, n, 3)
        ok = np.isfinite(x).all(axis=2)
        if ok.any():
            lo = np.minimum(lo, x[ok].min(axis=0))
            hi = np.maximum(hi, x[ok].max(axis=0))
    if not np.isfinite(lo).all():
        raise InvalidParameter(
            "No frame of the runs has finite positions, so there is nothing to draw; "
            "check the runs' summary.json for how they ended."
        )
    for run in runs:
        if run.ground_z is not None:
            lo[2] = min(lo[2], run.ground_z)
            hi[2] = max(hi[2], run.ground_z)
    return np.array([lo, hi])


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


# --- the plotter -------------------------------------------------------------------------------


@contextmanager
def _quiet_window_probe():
    """Hide VTK's ``bad X server connection`` warning on headless Linux (see module Notes)."""
    headless = (
        sys.platform.startswith("linux")
        and not os.environ.get("DISPLAY")
        and not os.environ.get("WAYLAND_DISPLAY")
        and "VTK_DEFAULT_OPENGL_WINDOW" not in os.environ
    )
    if not headless:
        yield
        return
    from vtkmodules.vtkCommonCore import vtkLogger

    before = vtkLogger.GetCurrentVerbosityCutoff()
    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)
    try:
        yield
    finally:
        vtkLogger.SetStderrVerbosity(before)


def _camera(bounds: np.ndarray, aspect: float, view_angle: float = 30.0):
    """Fixed camera that fits ``bounds`` in a viewport: position, focal point, view up (m).

    The view comes from the front (-y), above (+z) and the clamped end's side
    (-x), so a cantilever along x that bends in z shows its length and its
    deflection. The camera looks at the centre of the bounds from the nearest
    distance at which all eight corners of the box lie inside the perspective
    frustum (vertical ``view_angle`` in degrees, VTK's default 30, and the
    horizontal one that the viewport's ``aspect`` = width / height gives),
    with a 10 % margin.
    """
    center = bounds.mean(axis=0)
    forward = -np.asarray(VIEW_DIRECTION, dtype=float)  # from the camera to the focal point
    forward /= np.linalg.norm(forward)
    up = np.array([0.0, 0.0, 1.0])
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    corners = np.array(
        [[x, y, z] for x in bounds[:, 0] for y in bounds[:, 1] for z in bounds[:, 2]]
    )
    rel = corners - center
    a, b, c = rel @ right, rel @ up, rel @ -forward  # c: towards the camera
    tan_v = np.tan(np.radians(view_angle) / 2.0)
    tan_h = tan_v * aspect
    distance = float(np.max(c + np.maximum(np.abs(a) / tan_h, np.abs(b) / tan_v)))
    size = float(np.linalg.norm(bounds[1] - bounds[0]))
    distance = 1.1 * distance if distance > 0 else max(size, 1.0)
    position = center - distance * forward
    return [tuple(position), tuple(center), tuple(up)]


class _Scene:
    """A plotter with one viewport per run, built once; ``draw(k)`` shows frame ``k``."""

    def __init__(self, runs: Sequence[_Run], color_by: str, size, *, rows: int = 1,
                 multi_samples: int = 0):
        pv = _require("pyvista")
        self.runs = list(runs)
        self.color_by = color_by
        label, unit, _ = FIELDS[color_by]
        self.clim = color_range(run.values[:, run.shown] for run in self.runs)
        bounds = _union_bounds(self.runs)
        cols = len(self.runs)
        camera = _camera(bounds, aspect=(size[0] / cols) / (size[1] / rows))
        with _quiet_window_probe():
            self.plotter = pv.Plotter(
                off_screen=True, shape=(rows, cols), window_size=list(size), border=False,
            )
        p = self.plotter
        # Multisample anti-aliasing costs half the frame rate of a software (llvmpipe) GL
        # and FXAA is not supported by VTK's EGL/OSMesa builds, so movies go without and
        # single pictures take 8 samples.
        p.ren_win.SetMultiSamples(multi_samples)
        # text height in pixels: a 20th of a viewport's height, kept between 8 and 24 px
        row_height = size[1] / rows
        font = int(np.clip(row_height / 20.0, 8, 24))
        self._views = []  # (row, run, surface PolyData, time label) per viewport
        for r in range(rows):
            for c, run in enumerate(self.runs):
                p.subplot(r, c)
                p.set_background("white")
                poly = pv.PolyData(
                    run.points(0).copy(),
                    np.hstack([np.full((len(run.faces), 1), 3), run.faces]).ravel(),
                )
                data = poly.cell_data if run.association == "cell" else poly.point_data
                data[color_by] = run.values[0].copy()
                body = p.add_mesh(
                    poly, scalars=color_by, clim=self.clim, cmap="viridis", show_edges=True,
                    edge_color="black", edge_opacity=0.15, show_scalar_bar=False,
                    nan_color="red", lighting=True,
                )
                if run.ground_z is not None:
                    self._add_ground(pv, p, bounds, run.ground_z)
                title = run.title
                self._text(p, title, (0.5, 0.97), font, "center", "top")
                stamp = self._text(p, " ", (0.02, 0.03), font, "left", "bottom")
                if r == rows - 1 and c == cols - 1:
                    p.add_scalar_bar(
                        title=f"{label} ({unit})", mapper=body.mapper, color="black", fmt="%.3g",
                        n_labels=2, vertical=False, position_x=0.42, position_y=0.02, width=0.44,
                        height=min(0.4, 3.5 * font / row_height),
                        title_font_size=font, label_font_size=int(0.85 * font),
                    )
                p.camera_position = camera
                p.camera.clipping_range = self._clipping(camera, bounds)
                self._views.append((r, run, poly, stamp))

    @staticmethod
    def _text(p, text, position, font, horizontal, vertical):
        """A text actor at ``position`` (fraction of the viewport), ``font`` pixels high."""
        actor = p.add_text(text, position=position, viewport=True, color="black")
        prop = actor.GetTextProperty()
        prop.SetFontSize(font)
        if horizontal == "center":
            prop.SetJustificationToCentered()
        if vertical == "top":
            prop.SetVerticalJustificationToTop()
        return actor

    @staticmethod
    def _add_ground(pv, p, bounds, z):
        """A grey rectangle at height ``z`` under the bounds, padded by a tenth of their extent."""
        extent = bounds[1] - bounds[0]
        pad = 0.1 * float(max(extent[0], extent[1], extent[2], 1e-12))
        center = (float(bounds[:, 0].mean()), float(bounds[:, 1].mean()), z)
        plane = pv.Plane(center=center, direction=(0, 0, 1), i_size=extent[0] + 2 * pad,
                         j_size=extent[1] + 2 * pad, i_resolution=1, j_resolution=1)
        # opaque: a translucent plane needs depth sorting, a third of the frame time
        p.add_mesh(plane, color=(0.8, 0.8, 0.78), lighting=False)

    @staticmethod
    def _clipping(camera, bounds):
        """Near and far planes (m) enclosing the bounds' sphere, padded, for every frame alike."""
        pos, focal = np.array(camera[0]), np.array(camera[1])
        d = float(np.linalg.norm(pos - focal))
        radius = 0.5 * float(np.linalg.norm(bounds[1] - bounds[0])) * 1.5 + 1e-9
        return (max(d - radius, 1e-3 * d), d + radius)

    @property
    def n_frames(self) -> int:
        return max(len(run.times) for run in self.runs)

    def draw(self, k) -> np.ndarray:
        """Show frame ``k`` (one per row when ``k`` is a sequence); the RGB image (h, w, 3)."""
        ks = list(k) if isinstance(k, Sequence) else [k]
        for r, run, poly, stamp in self._views:
            j = ks[r] if len(ks) > 1 else ks[0]
            j = min(j, len(run.times) - 1) if j >= 0 else len(run.times) + j
            pts = poly.GetPoints()
            np.copyto(_numpy_view(pts.GetData()), run.points(j))
            pts.Modified()
            data = poly.GetCellData() if run.association == "cell" else poly.GetPointData()
            arr = data.GetArray(self.color_by)
            np.copyto(_numpy_view(arr), run.values[j])
            arr.Modified()
            text = f"t = {run.times[j]:.3f} s"
            if j == len(run.times) - 1 and run.status in ("diverged", "interrupted"):
                text += f" ({run.status})"
            stamp.SetInput(text)
        # screenshot() reads the window without drawing again (after the first frame)
        self.plotter.render()
        return self.plotter.screenshot(return_img=True)

    def close(self):
        self.plotter.close()


def _numpy_view(vtk_array) -> np.ndarray:
    from vtkmodules.util.numpy_support import vtk_to_numpy

    return vtk_to_numpy(vtk_array)


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


def render_runs(run_dirs, out, *, format: str = "mp4", size=(960, 540),
                color_by: str = "von_mises", fps: float = 30, titles=None, every: int = 1,
                progress: bool = False) -> list[Path]:
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
    _require("pyvista")
    _require("imageio.v3")
    if format == "mp4":
        _require("imageio_ffmpeg")
    runs = _load_runs(run_dirs, titles, color_by, every)
    t0 = time.perf_counter()
    scene = _Scene(runs, color_by, (w, h))
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
        writer.send(None)  # start ffmpeg
        try:
            for k in range(scene.n_frames):
                writer.send(np.ascontiguousarray(scene.draw(k)))
                if bar is not None:
                    bar.update()
        finally:
            writer.close()

    return _atomic_write(out, write)


def render_frame(run_dirs, path, *, frame=-1, size=(960, 540), color_by: str = "von_mises",
                 titles=None) -> Path:
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
    _require("pyvista")
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
    scene = _Scene(runs, color_by, (w, h), rows=len(frames), multi_samples=8)
    try:
        image = scene.draw(frames)
    finally:
        scene.close()
    return _write_png(path, image)
