"""A deformed body as a pyvista ``UnstructuredGrid``, and its off-screen plot.

:func:`body_grid` turns a model and its DOF positions into the grid that
``to_pyvista`` of :class:`fe.Model`, :class:`fe.Trajectory` and
:class:`fe.StaticResult` return: the REFERENCE positions of every node, the
tets (VTK type 10, or type 24 with the mid-edge nodes of a P2 body), point
data ``displacement`` (m) and ``velocity`` (m/s), cell data ``von_mises``
(Pa) and ``energy_density`` (J/m^3). ``grid.warp_by_vector("displacement")``
is the deformed body, as ParaView's Warp By Vector on the files
:mod:`fem_elastic.app.output` writes.

:func:`plot_grid` draws such a grid off screen or in a window, with the
undeformed outline and a magnification of the displacement that
:func:`auto_magnification` chooses when the deflection is too small to see
(under 5 % of the body's size); the picture says so.

pyvista is optional and imported inside the functions (``pip install
"fem_elastic[render]"``); without it they raise :class:`fe.MissingDependency`.
"""

from __future__ import annotations

import math
import os
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Literal, TypedDict

import numpy as np

from ..errors import InvalidParameter, MissingDependency

if TYPE_CHECKING:  # pyvista is optional: imported on first use
    import pyvista

__all__ = ["body_grid", "plot_grid", "auto_magnification", "nodal_positions",
           "FrameOptions", "PlotOptions"]


class FrameOptions(TypedDict, total=False):
    """Keywords of :func:`plot_grid` besides the colours and the magnification (``.plot(**kw)``)."""

    outline: bool
    title: str | None
    off_screen: bool | None
    screenshot: str | os.PathLike[str] | None
    window_size: tuple[int, int]
    show: bool


class PlotOptions(FrameOptions, total=False):
    """Every keyword of :func:`plot_grid` (``Model.plot(x, **kw)``)."""

    scalars: str
    magnification: Literal["auto"] | float

#: A deflection under this fraction of the body's size is magnified by default.
SMALL_DEFLECTION = 0.05

#: The magnified deflection drawn: this fraction of the body's size (then rounded down to 1-2-5).
SHOWN_DEFLECTION = 0.15

#: VTK cell types of linear and quadratic tetrahedra.
VTK_TETRA, VTK_QUADRATIC_TETRA = 10, 24

# the vertex pairs of a quadratic tet's edge nodes 4..9 (scikit-fem's P2 order, VTK's too)
_EDGES = np.array([[0, 1], [1, 2], [2, 0], [0, 3], [1, 3], [2, 3]])


def _pyvista():
    try:
        import pyvista
    except ModuleNotFoundError as err:
        raise MissingDependency(
            f"Drawing needs pyvista, which is not installed ({err}). Install the rendering "
            'extras with: pip install "fem_elastic[render]"', name=err.name,
        ) from err
    return pyvista


def _cells(model) -> tuple[np.ndarray, int]:
    """``(m, 4)`` or ``(m, 10)`` node indices of the tets and their VTK type."""
    order = getattr(model.space, "order", 1)
    dofs = getattr(model.space, "dofs", None)  # scikit-fem's DOF map (not its basis: built on demand)
    if order != 1 and dofs is None:  # several bodies (fe.MultiBody), P2 or of mixed orders (None):
        # no one basis over all of them, and their nodes are not the stacked mesh's vertices
        raise InvalidParameter(
            "to_pyvista of a fe.MultiBody takes linear bodies only (order=1); draw a "
            "quadratic body from its own model, model.models[b].to_pyvista(x[model.body_slice(b)])."
        )
    if order == 2:
        assert dofs is not None  # order 2 without a DOF map was refused above
        return np.asarray(dofs.element_dofs, dtype=np.int64).T, VTK_QUADRATIC_TETRA
    return np.asarray(model.mesh.t, dtype=np.int64).T, VTK_TETRA


def nodal_positions(model, vertex_values: np.ndarray) -> np.ndarray:
    """A flat DOF vector from values at the vertices: P2 edge nodes at their edge's mean.

    Used where only vertex values were recorded (:class:`fe.Trajectory` frames):
    exact for P1 and spring bodies; for P2 bodies the mid-edge nodes lie on the
    straight edge, so a curved edge of the solution is drawn straight.

    Parameters
    ----------
    model : Model
    vertex_values : numpy.ndarray
        ``(n_vertices, 3)`` values (e.g. displacements, m).

    Returns
    -------
    numpy.ndarray
        ``(ndofs,)``.
    """
    vertex_values = np.asarray(vertex_values, dtype=float)
    nv = model.mesh.p.shape[1]
    if vertex_values.shape != (nv, 3):
        raise InvalidParameter(
            f"vertex values have shape {vertex_values.shape}; the model has {nv} vertices, "
            "so they need shape (n_vertices, 3)."
        )
    cells, kind = _cells(model)
    out = np.zeros((model.ndofs // 3, 3))
    out[:nv] = vertex_values
    if kind == VTK_QUADRATIC_TETRA:
        for j, (a, b) in enumerate(_EDGES):
            out[cells[:, 4 + j]] = 0.5 * (vertex_values[cells[:, a]] + vertex_values[cells[:, b]])
    return out.ravel()


def body_grid(model, x=None, v=None, *, time: float | None = None):
    """The body at DOF positions ``x`` as a pyvista ``UnstructuredGrid`` (reference points).

    Parameters
    ----------
    model : Model
    x : numpy.ndarray, optional
        ``(ndofs,)`` DOF positions (m); default the reference ``model.X``.
    v : numpy.ndarray, optional
        ``(ndofs,)`` DOF velocities (m/s); default zero.
    time : float, optional
        Stored as field data ``TimeValue`` (s).

    Returns
    -------
    pyvista.UnstructuredGrid
        Points: every node's reference position (m; P2: vertices, then mid-edge
        nodes); cells: linear (VTK 10) or quadratic (VTK 24) tets; point data
        ``displacement`` (m), ``velocity`` (m/s); cell data ``von_mises`` (Pa),
        ``energy_density`` (J/m^3).

    Examples
    --------
    >>> import fem_elastic as fe
    >>> from fem_elastic.physics.pyvista_grid import body_grid
    >>> model = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), 1000.0,
    ...                  fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3), order=2), fixed="left")
    >>> grid = body_grid(model)  # doctest: +SKIP
    >>> grid.celltypes[0], grid.n_points  # doctest: +SKIP
    (np.uint8(24), 63)
    """
    pv = _pyvista()
    from .fields import CellFields

    X = np.asarray(model.X, dtype=float)
    x = X if x is None else np.asarray(x, dtype=float)
    v = np.zeros_like(X) if v is None else np.asarray(v, dtype=float)
    if x.shape != X.shape or v.shape != X.shape:
        raise InvalidParameter(
            f"x and v need the model's DOF shape {X.shape}, got {x.shape} and {v.shape}; pass "
            "a State's x and v (or model.X + displacement.ravel() for a P1 body)."
        )
    cells, kind = _cells(model)
    n = cells.shape[1]
    grid = pv.UnstructuredGrid(
        np.hstack([np.full((len(cells), 1), n), cells]).ravel(),
        np.full(len(cells), kind, dtype=np.uint8), X.reshape(-1, 3).copy(),
    )
    grid.point_data["displacement"] = (x - X).reshape(-1, 3)
    grid.point_data["velocity"] = v.reshape(-1, 3)
    for name, values in CellFields(model)(x).items():
        grid.cell_data[name] = np.asarray(values, dtype=float)
    if time is not None:
        grid.field_data["TimeValue"] = np.array([float(time)])
    return grid


def _nice_down(value: float) -> float:
    """The largest 1, 2 or 5 times a power of ten not above ``value`` (> 0)."""
    exponent = math.floor(math.log10(value))
    for mantissa in (5.0, 2.0, 1.0):
        if mantissa * 10.0 ** exponent <= value:
            return mantissa * 10.0 ** exponent
    return 10.0 ** exponent


def auto_magnification(max_displacement: float, size: float) -> float:
    """The factor a deflection is drawn magnified by: 1 unless it is too small to see.

    A largest displacement under :data:`SMALL_DEFLECTION` (5 %) of the body's
    size is drawn at about :data:`SHOWN_DEFLECTION` (15 %) of it, by a factor
    rounded down to 1, 2 or 5 times a power of ten (so it reads well on the
    picture); a zero or non-finite displacement is drawn as it is.

    Parameters
    ----------
    max_displacement : float
        The largest displacement magnitude (m).
    size : float
        The body's size (m), e.g. the largest extent of its bounding box.

    Returns
    -------
    float
        >= 1.

    Examples
    --------
    >>> auto_magnification(1e-4, 1.0), auto_magnification(0.2, 1.0), auto_magnification(0.0, 1.0)
    (1000.0, 1.0, 1.0)
    """
    u, size = float(max_displacement), float(size)
    if not (math.isfinite(u) and u > 0 and size > 0) or u >= SMALL_DEFLECTION * size:
        return 1.0
    return max(1.0, _nice_down(SHOWN_DEFLECTION * size / u))


def _magnification(grid, magnification) -> float:
    if magnification == "auto":
        u = np.linalg.norm(np.asarray(grid.point_data["displacement"]), axis=1)
        finite = u[np.isfinite(u)]
        size = float(np.max(np.ptp(np.asarray(grid.points), axis=0)))
        return auto_magnification(float(finite.max()) if finite.size else 0.0, size)
    if isinstance(magnification, bool) or not isinstance(magnification, (int, float)) \
            or not magnification > 0:
        raise InvalidParameter(
            f"magnification must be 'auto' or a number > 0 (the displacement is drawn "
            f"times it), got {magnification!r}."
        )
    return float(magnification)


@contextmanager
def _quiet_window_probe():
    """Hide VTK's harmless ``bad X server connection`` warning on headless Linux.

    Used here and by :mod:`fem_elastic.app.render_scene` (whose module Notes say
    why): VTK still falls back to EGL or OSMesa, real errors still show.
    """
    headless = (sys.platform.startswith("linux") and not os.environ.get("DISPLAY")
                and not os.environ.get("WAYLAND_DISPLAY")
                and "VTK_DEFAULT_OPENGL_WINDOW" not in os.environ)
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


_UNITS = {"von_mises": "Pa", "energy_density": "J/m^3", "displacement": "m", "velocity": "m/s"}


def plot_grid(grid: pyvista.UnstructuredGrid, *, scalars: str = "von_mises",
              magnification: Literal["auto"] | float = "auto", outline: bool = True,
              title: str | None = None, off_screen: bool | None = None,
              screenshot: str | os.PathLike[str] | None = None,
              window_size: tuple[int, int] = (800, 500), show: bool = True) -> pyvista.Plotter:
    """Draw a grid of :func:`body_grid`: the deformed body, coloured, over its undeformed outline.

    Parameters
    ----------
    grid : pyvista.UnstructuredGrid
        With point data ``displacement`` (m) on reference points.
    scalars : str
        A cell or point array to colour by (``"von_mises"``, Pa; ``"energy_density"``;
        ``"displacement"`` or ``"velocity"``: their magnitude).
    magnification : "auto" or float
        The displacement is drawn times this; ``"auto"``: :func:`auto_magnification`.
        Any factor other than 1 is written on the picture.
    outline : bool
        Draw the undeformed body's edges in grey.
    title : str, optional
        Written at the top.
    off_screen : bool, optional
        Draw without a window (default pyvista's ``OFF_SCREEN`` setting); with
        ``screenshot`` set, always off screen.
    screenshot : str or os.PathLike, optional
        Write the picture to this PNG.
    window_size : (int, int)
        Pixels.
    show : bool
        Show (or, off screen, render) the plotter and close it; False returns it open.

    Returns
    -------
    pyvista.Plotter
        The plotter (closed when ``show``).
    """
    pv = _pyvista()
    if scalars not in grid.point_data and scalars not in grid.cell_data:
        raise InvalidParameter(
            f"the grid has no array {scalars!r}; colour by one of "
            f"{sorted(set(grid.point_data) | set(grid.cell_data))}."
        )
    factor = _magnification(grid, magnification)
    warped = grid.warp_by_vector("displacement", factor=factor)
    if screenshot is not None:
        off_screen = True
        if not Path(screenshot).parent.is_dir():
            raise InvalidParameter(f"the directory of {str(screenshot)!r} does not exist; create it first.")
    with _quiet_window_probe():
        plotter = pv.Plotter(off_screen=off_screen, window_size=list(window_size))
    plotter.set_background("white")
    if outline:
        plotter.add_mesh(grid.extract_feature_edges(), color="grey", line_width=1)
    unit = _UNITS.get(scalars)
    label = f"{scalars.replace('_', ' ')} ({unit})" if unit else scalars
    plotter.add_mesh(warped, scalars=scalars, cmap="viridis", show_edges=False,
                     scalar_bar_args={"title": label, "color": "black", "fmt": "%.3g",
                                      "vertical": False, "position_x": 0.2, "position_y": 0.03,
                                      "width": 0.6, "height": 0.1, "n_labels": 3,
                                      "title_font_size": 14, "label_font_size": 12})
    lines = [title] if title else []
    if factor != 1.0:
        lines.append(f"displacement x {factor:g}")
    if lines:
        plotter.add_text("\n".join(lines), position="upper_left", color="black", font_size=11)
    plotter.camera_position = "xz"
    plotter.camera.elevation = 20.0
    plotter.camera.azimuth = -25.0
    plotter.reset_camera()
    # the colour bar takes the bottom eighth: move the body up into the rest
    plotter.camera.zoom(0.85)
    plotter.set_viewup((0.0, 0.0, 1.0))
    plotter.camera.focal_point = np.asarray(plotter.camera.focal_point) - \
        np.array([0.0, 0.0, 0.08 * float(np.max(np.ptp(np.asarray(warped.points), axis=0)))])
    if show:
        plotter.show(screenshot=None if screenshot is None else str(screenshot))
    return plotter
