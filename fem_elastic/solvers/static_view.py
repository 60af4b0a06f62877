"""Looking at a static equilibrium: repr, HTML table, pyvista grid and plot, curves, saving.

:class:`StaticResultView` is the part of :class:`fe.StaticResult` that shows it
(mixed in, so the solve's module keeps to the solve): ``repr(result)`` is a
few lines, ``_repr_html_`` the same rows as a table, :meth:`~StaticResultView.to_pyvista`
and :meth:`~StaticResultView.plot` the deformed body (helpers in
:mod:`fem_elastic.physics.pyvista_grid`), :meth:`~StaticResultView.plot_history`
the load path's curves, :meth:`~StaticResultView.save` the run directory.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TypeVar

import numpy as np

from ..errors import InvalidParameter
from ..physics import result_view as _view

if TYPE_CHECKING:  # for annotations only (pyvista and matplotlib are optional)
    from typing import Unpack  # Python >= 3.11

    import pyvista
    from matplotlib.axes import Axes

    from ..physics.multibody import AnyModel
    from ..physics.pyvista_grid import FrameOptions

__all__ = ["StaticResultView", "save_sections"]

#: The numpydoc sections of a result's ``save`` after its summary: :meth:`StaticResultView.save`
#: and :meth:`fem_elastic.Trajectory.save` share them, as they share the writer
#: (:func:`fem_elastic.physics.result_view.save_result`).
_SAVE_SECTIONS = """
        Parameters
        ----------
        run_dir : path-like
            A new or empty directory, or one a result was saved in before (it is
            replaced). One that holds other files is refused
            (:class:`fe.InvalidParameter`) unless ``overwrite``.
        model : Model, optional
            The model, where the result does not know it.
        overwrite : bool
            Write into a directory holding other files all the same: files with a
            run's names (``series.pvd``, ``summary.json``, ``frames/frame_*.vtu``) are
            replaced, the others left alone.

        Returns
        -------
        pathlib.Path
            ``run_dir``.

        Raises
        ------
        InvalidParameter
            ``run_dir`` holds other files, without ``overwrite``.
        OutputInUse
            Another writer holds the directory: it is locked while it is written.
        """

_Method = TypeVar("_Method", bound=Callable[..., Any])


def save_sections(method: _Method) -> _Method:
    """Decorator of a result's ``save``: its docstring (the summary) followed by the shared
    Parameters, Returns and Raises sections."""
    method.__doc__ = (method.__doc__ or "").rstrip() + "\n" + _SAVE_SECTIONS
    return method


class StaticResultView:
    """Display methods of :class:`fe.StaticResult` (which holds the attributes used here)."""

    if TYPE_CHECKING:  # the attributes StaticResult defines, for type checkers
        x: np.ndarray
        displacement: np.ndarray
        converged: bool
        load_factor: float
        iterations: int
        load_steps: list
        residual_history: list
        wall_time: float
        message: str
        reaction_dofs: np.ndarray | None
        min_eigenvalue: float | None
        stable: bool | None
        path: Any
        _model: Any

    def _rows(self) -> list[tuple[str, str]]:
        u = np.linalg.norm(np.asarray(self.displacement), axis=1)
        rows = []
        model = self._model
        if model is not None:
            rows.append(("mesh", f"{model.mesh.p.shape[1]} vertices, {model.mesh.t.shape[1]} tets"))
            material = getattr(model.body, "material", None)
            if material is not None:
                rows.append(("material", repr(material)))
        rows += [
            ("converged", f"{self.converged} (load factor {_view.fmt(self.load_factor)}, "
                          f"{len(self.load_steps)} load steps, {self.iterations} Newton iterations)"),
            ("wall time", _view.fmt(self.wall_time, "s")),
            ("max |u|", _view.fmt(float(u.max()) if u.size else 0.0, "m")),
        ]
        if model is not None and self.reaction_dofs is not None:
            total = np.asarray(self.reaction_dofs).reshape(-1, 3).sum(axis=0)
            rows.append(("total reaction", "(" + ", ".join(f"{c:.4g}" for c in total) + ") N"))
        if self.stable is not None:
            rows.append(("stable", f"{self.stable} (min eigenvalue "
                                   f"{_view.fmt(self.min_eigenvalue, 'N/m')})"))
        if self.message:
            rows.append(("ended", self.message))
        return rows

    def __repr__(self) -> str:
        return _view.text_table("StaticResult", self._rows())

    def _repr_html_(self) -> str:
        return _view.html_table("StaticResult", self._rows())

    def _need_model(self, model):
        model = self._model if model is None else model
        if model is None:
            raise InvalidParameter(
                "this StaticResult does not know its model; pass it, e.g. "
                "result.to_pyvista(model=model)."
            )
        return model

    def to_pyvista(self, point: int = -1, *,
                   model: AnyModel | None = None) -> pyvista.UnstructuredGrid:
        """An equilibrium of the load path as a pyvista ``UnstructuredGrid`` (reference points).

        Point data ``displacement`` (m) and ``velocity`` (zero), cell data
        ``von_mises`` (Pa) and ``energy_density`` (J/m^3); P2 bodies as quadratic
        tets (VTK type 24); field data ``TimeValue``: the load factor.

        Parameters
        ----------
        point : int
            Index into :attr:`path` (``-1``: the last equilibrium, :attr:`x`).
        model : Model, optional
            Default the model solved.

        Returns
        -------
        pyvista.UnstructuredGrid
        """
        from ..physics.pyvista_grid import body_grid

        model = self._need_model(model)
        n = len(self.path)
        if n == 0 or point == -1:
            return body_grid(model, self.x, time=float(self.load_factor))
        if isinstance(point, bool) or not isinstance(point, (int, np.integer)) or not -n <= point < n:
            raise InvalidParameter(
                f"point={point!r} is out of range: the load path has {n} points (0..{n - 1})."
            )
        p = self.path[point]
        return body_grid(model, p.x, time=float(p.load_factor))

    def plot(self, point: int = -1, *, scalars: str = "von_mises",
             magnification: Literal["auto"] | float = "auto", model: AnyModel | None = None,
             **kwargs: Unpack[FrameOptions]) -> pyvista.Plotter:
        """Draw the equilibrium with pyvista over its undeformed outline.

        ``magnification="auto"`` magnifies a deflection under 5 % of the body's
        size (stated on the picture); ``off_screen=True`` or ``screenshot=path``
        draw without a window. Other keywords go to
        :func:`fem_elastic.physics.pyvista_grid.plot_grid`.

        Returns
        -------
        pyvista.Plotter
        """
        from ..physics.pyvista_grid import plot_grid

        grid = self.to_pyvista(point, model=model)
        kwargs.setdefault("title", f"static equilibrium, load factor {self.load_factor:.4g}")
        return plot_grid(grid, scalars=scalars, magnification=magnification, **kwargs)

    def plot_history(self, quantity: str = "max_displacement", ax: Axes | None = None) -> Axes:
        """A curve of the solve, with matplotlib.

        Parameters
        ----------
        quantity : str
            ``"max_displacement"`` (m) or ``"min_eigenvalue"`` (N/m) against the
            load factor; ``"residual"``: ||g|| (N) at every Newton iterate
            (log scale); or a support's name (e.g. ``"left"``): its reaction
            force components (N) against the load factor.
        ax : matplotlib.axes.Axes, optional

        Returns
        -------
        matplotlib.axes.Axes
        """
        s = self.path.load_factors
        if quantity == "max_displacement":
            y = np.linalg.norm(self.path.displacements, axis=-1).max(axis=-1) if len(s) else s
            return _view.line_axes(s, {quantity: y}, xlabel="load factor",
                                   ylabel="max displacement (m)", ax=ax)
        if quantity == "min_eigenvalue":
            return _view.line_axes(s, {quantity: self.path.min_eigenvalues}, xlabel="load factor",
                                   ylabel="min eigenvalue (N/m)", ax=ax)
        if quantity == "residual":
            r = np.asarray(self.residual_history, dtype=float)
            ax = _view.line_axes(np.arange(r.size), {quantity: r}, xlabel="Newton iterate",
                                 ylabel="||g|| on free DOFs (N)", ax=ax)
            if r.size and np.all(r[np.isfinite(r)] > 0):
                ax.set_yscale("log")
            return ax
        if self._model is not None and isinstance(quantity, str):
            try:
                forces = self.path.reaction_forces(quantity)
            except Exception as err:  # not a boundary of the mesh: say what can be plotted
                raise InvalidParameter(
                    f"unknown quantity {quantity!r} ({err}); plot 'max_displacement', "
                    "'min_eigenvalue', 'residual' or a support's boundary name."
                ) from err
            curves = {f"R_{c}": forces[:, i] for i, c in enumerate("xyz")}
            return _view.line_axes(s, curves, xlabel="load factor",
                                   ylabel=f"reaction on {quantity} (N)", ax=ax)
        raise InvalidParameter(
            f"unknown quantity {quantity!r}; plot 'max_displacement', 'min_eigenvalue' or "
            "'residual'."
        )

    @save_sections
    def save(self, run_dir: str | os.PathLike[str], *, model: AnyModel | None = None,
             overwrite: bool = False) -> Path:
        """Write the load path as a run directory (the format ``fem-elastic run`` writes).

        Each converged point is a frame whose "time" is its load factor, and
        ``summary.json`` holds the physical result (largest displacement,
        reactions per support, stability).
        """
        return _view.save_result("static", self, run_dir, self._need_model(model), overwrite=overwrite)
