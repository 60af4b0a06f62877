"""The pyvista scene of a render: surfaces, colours, camera, and the plotter that draws them.

:func:`fem_elastic.app.render.render_runs` and
:func:`~fem_elastic.app.render.render_frame` read the runs into :class:`_Run`
(the surface triangles of the tets, their motion and the scalars shown), fix
one colour range (:func:`color_range`) and one camera (:func:`_camera`) over
every frame of every run, and draw the frames with a :class:`_Scene`, built
once; the module docstring of :mod:`fem_elastic.app.render` says why both are
fixed. pyvista is optional: :class:`_Scene` is handed the module by the
caller, which imports it (:func:`fem_elastic.app.render._require`), and VTK
is imported only inside functions.

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

import re
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InvalidParameter
from ..physics.pyvista_grid import _quiet_window_probe  # see the Notes above
from ..physics.collision_surface import surface_triangles

#: Fields to colour by: name -> (label, unit, where the values live).
FIELDS = {
    "von_mises": ("von Mises stress", "Pa", "cell"),
    "displacement": ("displacement", "m", "point"),
    "body": ("body", "index", "cell"),  # a fe.MultiBody's series: each body in its own colour
}

# From the focal point towards the camera: in front (-y), a little above (+z) and to the
# side of the clamped end (-x), low enough that a deflection in z shows.
VIEW_DIRECTION = (-0.3, -1.0, 0.3)

# The bottom fraction of each viewport kept for the colour bar and the clock: the camera
# frames the scene in the rest.
BAR_BAND = 0.16

# The top of the colour range is this percentile of the values shown (see the docstring of
# fem_elastic.app.render).
COLOR_PERCENTILE = 99.0


# --- the data drawn: surfaces and scalars, as arrays ------------------------------------------


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
    status: str  # "completed", "interrupted", "diverged", "failed" or "" when unknown
    scene: str = ""  # the scene's name (summary "scene"), the picture's title
    failure: str = ""  # a run that blew up or failed: "diverged at step 13: <reason>", else ""

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
    # only the surface is drawn (the interior is hidden anyway): the frame loop never runs
    # VTK's surface filter
    faces, face_tet = surface_triangles(tets, points_ref, return_tets=True)
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
    ground_z = float(ground["z"]) if isinstance(ground, dict) and ground.get("kind") == "plane" else None
    return _Run(
        title=title, times=times, points_ref=points_ref, displacement=displacement, faces=faces,
        values=values, association=association, shown=shown, ground_z=ground_z,
        status=str(summary.get("status", "")), scene=str(summary.get("scene") or ""),
        failure=failure_line(summary),
    )


#: A failure's reason is cut to this many characters on the pictures (summary.json has it whole).
REASON_CHARS = 60


def failure_line(summary: dict) -> str:
    """What a failed run's frames say, e.g. ``"diverged at step 13: energy grew ..."``; "" if none.

    For ``summary["status"]`` ``"diverged"`` or ``"failed"`` (``fe.Diverged``,
    ``fe.StepFailed``): the step and reason the command records (``failed_step``,
    ``reason``), else those of the trajectory's message (``"diverged at step 13:
    ..."``, what ``Trajectory.save`` writes), else the status alone. The reason is
    cut to :data:`REASON_CHARS` characters.
    """
    status = summary.get("status")
    if status not in ("diverged", "failed"):
        return ""
    step, reason = summary.get("failed_step"), summary.get("reason")
    if step is None:
        found = re.match(r"(?:diverged|failed) at step (\d+): (.*)", str(summary.get("message") or ""),
                         re.S)
        if found:
            step, reason = int(found.group(1)), found.group(2)
    line = status if step is None else f"{status} at step {step}"
    reason = " ".join(str(reason or "").split())  # one line
    if len(reason) > REASON_CHARS:
        reason = reason[:REASON_CHARS - 3].rstrip() + "..."
    return f"{line}: {reason}" if reason else line


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
    parts = [v[np.isfinite(v)] for v in (np.asarray(a, dtype=float).ravel() for a in values)]
    finite = np.concatenate(parts) if parts else np.empty(0)
    if finite.size == 0:
        return 0.0, 1.0
    top = float(np.percentile(finite, percentile))
    if not top > 0:
        top = float(finite.max())
    if not top > 0:
        top = 1.0
    return 0.0, top


def warp_factor(runs: Sequence[_Run], warp="auto") -> float:
    """The factor the displacements of a render are drawn magnified by.

    ``warp="auto"``: :func:`fem_elastic.physics.pyvista_grid.auto_magnification`
    of the largest displacement over every frame and run against the body's
    size (the largest extent of the reference bounds): a deflection under 5 %
    of it is magnified to about 15 %, by 1, 2 or 5 times a power of ten. Runs
    with a ground are drawn as they are (magnifying a body near contact would
    push it through the ground). A number: that factor (> 0).
    """
    from ..physics.pyvista_grid import auto_magnification

    if warp == "auto":
        if any(run.ground_z is not None for run in runs):
            return 1.0
        u = max((float(np.nanmax(np.linalg.norm(run.displacement, axis=2), initial=0.0))
                 for run in runs), default=0.0)
        size = max(float(np.max(np.ptp(run.points_ref, axis=0))) for run in runs)
        return auto_magnification(u, size)
    if isinstance(warp, bool) or not isinstance(warp, (int, float, np.number)) or not warp > 0 \
            or not np.isfinite(warp):
        raise InvalidParameter(
            f"warp={warp!r}: give 'auto' or a magnification > 0 of the displacement (1: as it is)."
        )
    return float(warp)


def _ground_pad(bounds: np.ndarray) -> float:
    """The margin (m) of the ground plane around the bodies: a tenth of their largest extent."""
    return 0.1 * float(max(np.max(bounds[1] - bounds[0]), 1e-12))


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


# --- the plotter -------------------------------------------------------------------------------


def _camera(bounds: np.ndarray, aspect: float, view_angle: float = 30.0, fill: float = 1.0):
    """Fixed camera that fits ``bounds`` in a viewport: position, focal point, view up (m).

    The view comes from the front (-y), above (+z) and the clamped end's side
    (-x), so a cantilever along x that bends in z shows its length and its
    deflection. The camera looks at the centre of the bounds from the nearest
    distance at which all eight corners of the box lie inside the perspective
    frustum (vertical ``view_angle`` in degrees, VTK's default 30, and the
    horizontal one that the viewport's ``aspect`` = width / height gives),
    with a 10 % margin; ``fill`` < 1 keeps the box within that fraction of the
    height (the rest is the colour bar's band).
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
    tan_h = np.tan(np.radians(view_angle) / 2.0) * aspect
    tan_v = np.tan(np.radians(view_angle) / 2.0) * fill  # the scene fills this part of the height
    distance = float(np.max(c + np.maximum(np.abs(a) / tan_h, np.abs(b) / tan_v)))
    size = float(np.linalg.norm(bounds[1] - bounds[0]))
    distance = 1.1 * distance if distance > 0 else max(size, 1.0)
    position = center - distance * forward
    return [tuple(position), tuple(center), tuple(up)]


class _Scene:
    """A plotter with one viewport per run, built once; ``draw(k)`` shows frame ``k``.

    ``pv`` is the pyvista module, imported by the caller (which says what to
    install when it is missing); ``rows`` viewports per run show ``rows``
    frames at once (:func:`fem_elastic.app.render.render_frame`).
    """

    def __init__(self, pv, runs: Sequence[_Run], color_by: str, size, *, rows: int = 1,
                 multi_samples: int = 0, warp="auto"):
        self.runs = list(runs)
        self.color_by = color_by
        label, unit, _ = FIELDS[color_by]
        self.clim = color_range(run.values[:, run.shown] for run in self.runs)
        # bodies by index: one colour of a qualitative map each (tab10: ten distinct colours,
        # the range centred on the integers so that body i takes the i-th colour)
        self.cmap = "tab10" if color_by == "body" else "viridis"
        if color_by == "body":
            self.clim = (-0.5, 9.5)
        self.warp = warp_factor(self.runs, warp)
        if self.warp != 1.0:  # the colours stay those of the true displacement
            self.runs = [replace(run, displacement=self.warp * run.displacement)
                         for run in self.runs]
        bounds = _union_bounds(self.runs)
        # the ground plane reaches a pad beyond the bodies: the camera frames it whole
        framed = bounds.copy()
        if any(run.ground_z is not None for run in self.runs):
            pad = _ground_pad(bounds)
            framed[0, :2] -= pad
            framed[1, :2] += pad
        cols = len(self.runs)
        camera = _camera(framed, aspect=(size[0] / cols) / (size[1] / rows), fill=1.0 - BAR_BAND)
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
        # ... and a 28th of its width, so that titles of side-by-side panels stay apart
        font = int(np.clip(min(row_height / 20.0, size[0] / cols / 28.0), 8, 24))
        # the undeformed bodies: their feature edges, drawn grey in every row
        outlines = [
            pv.PolyData(
                run.points_ref, np.hstack([np.full((len(run.faces), 1), 3), run.faces]).ravel()
            ).extract_feature_edges(feature_angle=30.0, boundary_edges=True,
                                    non_manifold_edges=False, manifold_edges=False)
            for run in self.runs
        ]
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
                    poly, scalars=color_by, clim=self.clim, cmap=self.cmap, show_edges=True,
                    edge_color="black", edge_opacity=0.15, show_scalar_bar=False,
                    nan_color="red", lighting=True,
                )
                if run.ground_z is not None:
                    self._add_ground(pv, p, bounds, run.ground_z)
                outline = outlines[c]
                if outline.n_points:
                    p.add_mesh(outline, color=(0.45, 0.45, 0.45), line_width=1, lighting=False)
                # the scene's name and the magnification once, top left of the first panel;
                # each panel's variant centred on the line below
                head = [run.scene] if run.scene and run.scene != run.title else []
                if self.warp != 1.0:
                    head.append(f"displacement x {self.warp:g}")
                if r == 0 and c == 0 and head:
                    self._text(p, "\n".join(head), (0.02, 0.98), font, "left", "top")
                self._text(p, run.title, (0.5, 0.98 - (len(head) + 0.2) * 1.25 * font / row_height),
                           font, "center", "top")
                if run.failure:  # on every frame, under the title: the run did not finish
                    self._text(p, failure_text(run.failure, size[0] / cols, font),
                               (0.5, 0.98 - (len(head) + 1.2) * 1.25 * font / row_height),
                               font, "center", "top")
                stamp = self._text(p, " ", (0.02, 0.03), font, "left", "bottom")
                if r == rows - 1 and c == cols - 1 and color_by != "body":
                    # in the band under the scene (the camera leaves it free), right of the clock
                    p.add_scalar_bar(
                        title=f"{label} ({unit})", mapper=body.mapper, color="black", fmt="%.3g",
                        n_labels=3, vertical=False, position_x=0.42, position_y=0.01, width=0.46,
                        height=BAR_BAND - 0.02, title_font_size=font,
                        label_font_size=int(0.85 * font),
                    )
                p.camera_position = camera
                # shift the picture up by half the band: the scene fills the rest of the viewport
                p.camera.SetWindowCenter(0.0, -BAR_BAND)
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
        pad = _ground_pad(bounds)
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
            stamp.SetInput(time_stamp(run, j))
        # screenshot() reads the window without drawing again (after the first frame)
        self.plotter.render()
        return self.plotter.screenshot(return_img=True)

    def close(self):
        self.plotter.close()


def failure_text(failure: str, width: float, font: int) -> str:
    """``failure`` (see :func:`failure_line`) wrapped to a viewport ``width`` pixels wide, 2 lines at most.

    A character of the default font is about 0.6 of the font's height (``font``, pixels) wide.
    """
    lines = textwrap.wrap(failure, max(16, int(width / (0.6 * font))))
    if len(lines) > 2:
        lines = lines[:2]
        lines[1] = lines[1][: max(len(lines[1]) - 3, 1)].rstrip() + "..."
    return "\n".join(lines)


def time_stamp(run: _Run, j: int) -> str:
    """The clock of frame ``j`` of ``run``: ``"t = 0.120 s"``.

    Every frame of a run that blew up or failed also shows the failure under its
    title (:func:`failure_text`); its last frame, the last good state, says so here.
    The last frame of an interrupted run says that.
    """
    text = f"t = {run.times[j]:.3f} s"
    if j == len(run.times) - 1:
        if run.failure:
            text += " (last good state)"
        elif run.status == "interrupted":
            text += " (interrupted)"
    return text


def _numpy_view(vtk_array) -> np.ndarray:
    from vtkmodules.util.numpy_support import vtk_to_numpy

    return vtk_to_numpy(vtk_array)
