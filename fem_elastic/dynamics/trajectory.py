"""The record of a simulation: a Trajectory.

Frames are recorded every ``record_every`` steps (and at the end); the
per-step solver statistics are kept for every step, with the smallest
det F of the body after it (``min_det_F``: <= 0 means an inverted element).
"""

from __future__ import annotations

from dataclasses import dataclass, field
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from ..errors import InvalidParameter
from ..physics import result_view as _view
from ..solvers.static_view import save_sections

if TYPE_CHECKING:  # for annotations only (pyvista and matplotlib are optional)
    from typing import Unpack  # Python >= 3.11

    import pyvista
    from matplotlib.axes import Axes

    from ..physics.multibody import AnyModel
    from ..physics.pyvista_grid import FrameOptions

__all__ = ["Trajectory", "STEP_FIELDS", "COUNT_FIELDS"]

#: The per-step statistics of a run (``Trajectory.step_stats``): counts, then seconds.
STEP_FIELDS = ("gradient_evaluations", "newton_iterations", "line_search_cuts",
               "linear_iterations", "dt_cuts", "substeps", "seconds_linearize", "seconds_solve",
               "seconds_line_search", "seconds_step", "min_det_F")
COUNT_FIELDS = STEP_FIELDS[:6]


#: Per-step fields that are not work done (a sum of them means nothing).
_NOT_SUMMED = ("min_det_F", "contact_min_distance", "contact_active", "contact_force",
               "contact_intersecting")

_CUTS_LISTED = 50  # a summary lists the first failed attempts, and counts the rest


@dataclass
class Trajectory:
    """What :func:`fe.simulate` recorded.

    Attributes
    ----------
    times : numpy.ndarray
        ``(T,)`` times of the recorded frames (s).
    displacement, velocity : numpy.ndarray
        ``(T, n_vertices, 3)`` vertex displacements (m) and velocities (m/s).
    kinetic, potential, total : numpy.ndarray
        ``(T,)`` energies (J): ``1/2 v^T M v`` with the integrator's mass,
        the model's total potential energy (elastic, loads, contact), and their sum.
    linear_momentum, angular_momentum : numpy.ndarray
        ``(T, 3)`` (kg m/s) and about the origin (kg m^2/s), with the lumped mass.
    step_stats : dict of numpy.ndarray
        Per step ``(steps,)``: ``gradient_evaluations``, ``newton_iterations``,
        ``line_search_cuts``, ``linear_iterations``, ``dt_cuts`` (failed attempts
        before the step succeeded), ``substeps`` (sub-steps it was taken in),
        ``seconds_linearize``, ``seconds_solve``, ``seconds_line_search``, ``seconds_step``,
        and ``min_det_F``: the smallest det F over the body's quadrature points
        after the step (per tet for P1 and spring bodies; <= 0: an element is inverted).
    cuts : list of dict
        Every failed attempt of a step, where and why: ``step`` (index),
        ``t`` (s, where the attempt started), ``dt`` (s, the step size that
        failed) and ``reason``.
    wall_time : float
        Wall time of the whole run (s), recording included.
    steps : int
        Steps taken.
    dt : float
        Time step (s).
    integrator : str
        The integrator's name.
    final_state : State
        The state after the last step taken.
    message : str
        How the run ended.
    resumed_from_step : int or None
        The step a resumed run continued from (its checkpoint), else None.
    model : Model or None
        The model simulated (set by :func:`fe.simulate`), for :meth:`to_pyvista`,
        :meth:`plot` and :meth:`save`.

    Notes
    -----
    ``repr(traj)`` is a few lines (size, method, timings, energies, the largest
    displacement); in Jupyter the same rows show as a table (``_repr_html_``).
    """

    times: np.ndarray
    displacement: np.ndarray
    velocity: np.ndarray
    kinetic: np.ndarray
    potential: np.ndarray
    total: np.ndarray
    linear_momentum: np.ndarray
    angular_momentum: np.ndarray
    step_stats: dict = field(default_factory=dict)
    wall_time: float = 0.0
    steps: int = 0
    dt: float = 0.0
    integrator: str = ""
    final_state: Any = None
    message: str = ""
    cuts: list = field(default_factory=list)
    resumed_from_step: int | None = None
    model: Any = field(default=None, repr=False, compare=False)

    @property
    def dt_cuts(self) -> int:
        """Steps that had to be cut (Newton failed at the full dt, or an explicit sub-step failed)."""
        return int(np.count_nonzero(self.step_stats.get("dt_cuts", np.zeros(0))))

    def summary(self) -> dict:
        """The run's figures as plain Python values (for JSON)."""
        st = self.step_stats
        out = {
            "integrator": self.integrator,
            "dt": self.dt,
            "steps": self.steps,
            "frames": int(self.times.size),
            "t_end": float(self.times[-1]) if self.times.size else 0.0,
            "wall_time": self.wall_time,
            "energy_initial": float(self.total[0]) if self.total.size else None,
            "energy_final": float(self.total[-1]) if self.total.size else None,
            "message": self.message,
            "steps_cut": self.dt_cuts,
            "cuts": self.cuts[:_CUTS_LISTED],
        }
        if len(self.cuts) > _CUTS_LISTED:
            out["cuts_not_listed"] = len(self.cuts) - _CUTS_LISTED
        if self.resumed_from_step is not None:
            out["resumed_from_step"] = self.resumed_from_step
        for k, v in st.items():
            if k not in _NOT_SUMMED:
                out[f"{k}_total"] = float(np.sum(v))
        det = self._finite_min_det_F()
        # the smallest det F over the run's steps, and how many steps ended with an inverted element
        out["min_det_F"] = float(det.min()) if det.size else None
        out["steps_inverted"] = int(np.count_nonzero(det <= 0.0))
        from .contact_watch import summarize as contact_summary

        out.update(contact_summary(st))  # min distance, contacts, force, intersecting at the end
        return out

    def _finite_min_det_F(self) -> np.ndarray:
        """The steps' ``min_det_F`` that are finite (none for a record without it)."""
        det = np.asarray(self.step_stats.get("min_det_F", np.zeros(0)), dtype=float)
        return det[np.isfinite(det)]

    # looking at it ----------------------------------------------------------------------------
    def _rows(self) -> list[tuple[str, str]]:
        u = np.linalg.norm(self.displacement, axis=-1) if self.displacement.size else np.zeros(1)
        finite = u[np.isfinite(u)]
        det = self._finite_min_det_F()
        rows = [
            ("integrator", f"{self.integrator or '?'}, dt = {_view.fmt(self.dt, 's')}"),
            ("steps", f"{self.steps} ({self.times.size} frames to t = "
                      f"{_view.fmt(float(self.times[-1]) if self.times.size else 0.0, 's')})"),
            ("wall time", _view.fmt(self.wall_time, "s")),
        ]
        if self.model is not None:
            nv, nt = self.model.mesh.p.shape[1], self.model.mesh.t.shape[1]
            rows.insert(0, ("mesh", f"{nv} vertices, {nt} tets"))
        if self.total.size:
            rows.append(("energy", f"{_view.fmt(float(self.total[0]), 'J')} -> "
                                   f"{_view.fmt(float(self.total[-1]), 'J')}"))
        rows.append(("max |u|", _view.fmt(float(finite.max()) if finite.size else None, "m")))
        if det.size:
            rows.append(("min det F", _view.fmt(float(det.min()))))
        if self.dt_cuts:
            rows.append(("steps cut", str(self.dt_cuts)))
        if self.message:
            rows.append(("ended", self.message))
        return rows

    def __repr__(self) -> str:
        return _view.text_table("Trajectory", self._rows())

    def _repr_html_(self) -> str:
        return _view.html_table("Trajectory", self._rows())

    def _need_model(self, model):
        model = self.model if model is None else model
        if model is None:
            raise InvalidParameter(
                "this Trajectory does not know its model (it was not made by fe.simulate); "
                "pass it, e.g. traj.to_pyvista(-1, model=model)."
            )
        return model

    def _frame_index(self, frame: int) -> int:
        n = int(self.times.size)
        if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) or not -n <= frame < n:
            raise InvalidParameter(
                f"frame={frame!r} is out of range: the trajectory has {n} frames (0..{n - 1}, "
                "or -1 for the last)."
            )
        return int(frame) % n

    def to_pyvista(self, frame: int = -1, *,
                   model: AnyModel | None = None) -> pyvista.UnstructuredGrid:
        """Frame ``frame`` as a pyvista ``UnstructuredGrid`` on the reference points.

        Point data ``displacement`` (m) and ``velocity`` (m/s), cell data
        ``von_mises`` (Pa) and ``energy_density`` (J/m^3); P2 bodies as quadratic
        tets (VTK type 24). ``grid.warp_by_vector("displacement")`` is the
        deformed body. The last frame of a run is its final state exactly; the
        frames record vertex values only, so for a P2 body the mid-edge nodes of
        the other frames are put at their edge's mean (a curved edge drawn straight).

        Parameters
        ----------
        frame : int
            Recorded frame index (negative from the end).
        model : Model, optional
            Default the model simulated.

        Returns
        -------
        pyvista.UnstructuredGrid
        """
        from ..physics.pyvista_grid import body_grid

        model = self._need_model(model)
        k = self._frame_index(frame)
        x, v = self._frame_dofs(k, model)
        return body_grid(model, x, v, time=float(self.times[k]))

    def _frame_dofs(self, k: int, model) -> tuple[np.ndarray, np.ndarray]:
        """``(ndofs,)`` DOF positions (m) and velocities (m/s) of frame ``k`` (0 <= k < frames).

        The last frame of a run is its final state exactly; the others are their
        recorded vertex values, P2 mid-edge nodes at their edge's mean
        (:func:`~fem_elastic.physics.pyvista_grid.nodal_positions`). Drawn by
        :meth:`to_pyvista`, written by :meth:`save`.
        """
        from ..physics.pyvista_grid import nodal_positions

        final = self.final_state
        if final is not None and k == self.times.size - 1 and float(final.t) == float(self.times[k]):
            return final.x, final.v
        return (np.asarray(model.X) + nodal_positions(model, self.displacement[k]),
                nodal_positions(model, self.velocity[k]))

    def plot(self, frame: int = -1, *, scalars: str = "von_mises",
             magnification: Literal["auto"] | float = "auto", model: AnyModel | None = None,
             **kwargs: Unpack[FrameOptions]) -> pyvista.Plotter:
        """Draw frame ``frame`` with pyvista: the deformed body over its undeformed outline.

        ``magnification="auto"`` magnifies a deflection under 5 % of the body's
        size (stated on the picture). Off screen: ``off_screen=True``, or
        ``screenshot="frame.png"``. Other keywords go to
        :func:`fem_elastic.physics.pyvista_grid.plot_grid`.

        Returns
        -------
        pyvista.Plotter
        """
        from ..physics.pyvista_grid import plot_grid

        grid = self.to_pyvista(frame, model=model)
        kwargs.setdefault("title", f"{self.integrator}: t = {float(self.times[frame]):.4g} s")
        return plot_grid(grid, scalars=scalars, magnification=magnification, **kwargs)

    def plot_energy(self, ax: Axes | None = None) -> Axes:
        """Kinetic, potential and total energy (J) against time (s), with matplotlib.

        Returns
        -------
        matplotlib.axes.Axes
        """
        return _view.line_axes(
            self.times, {"kinetic": self.kinetic, "potential": self.potential, "total": self.total},
            xlabel="time (s)", ylabel="energy (J)", title=f"{self.integrator}, dt = {self.dt:g} s",
            ax=ax,
        )

    #: quantities of :meth:`plot_history` recorded per frame, with their units
    FRAME_QUANTITIES = {"kinetic": "J", "potential": "J", "total": "J", "max_displacement": "m",
                        "max_speed": "m/s"}

    def plot_history(self, quantity: str, ax: Axes | None = None) -> Axes:
        """One quantity against time (per frame) or step (per-step statistics), with matplotlib.

        Parameters
        ----------
        quantity : str
            Per frame: ``"kinetic"``, ``"potential"``, ``"total"`` (J),
            ``"max_displacement"`` (m), ``"max_speed"`` (m/s); per step: any
            key of :attr:`step_stats` (e.g. ``"newton_iterations"``,
            ``"min_det_F"``, ``"seconds_step"``).
        ax : matplotlib.axes.Axes, optional

        Returns
        -------
        matplotlib.axes.Axes
        """
        if quantity in self.FRAME_QUANTITIES:
            if quantity == "max_displacement":
                y = np.linalg.norm(self.displacement, axis=-1).max(axis=-1)
            elif quantity == "max_speed":
                y = np.linalg.norm(self.velocity, axis=-1).max(axis=-1)
            else:
                y = getattr(self, quantity)
            unit = self.FRAME_QUANTITIES[quantity]
            return _view.line_axes(self.times, {quantity: y}, xlabel="time (s)",
                                   ylabel=f"{quantity.replace('_', ' ')} ({unit})", ax=ax)
        if quantity in self.step_stats:
            y = np.asarray(self.step_stats[quantity], dtype=float)
            unit = " (s)" if quantity.startswith("seconds") else ""
            return _view.line_axes(np.arange(y.size), {quantity: y}, xlabel="step",
                                   ylabel=quantity.replace("_", " ") + unit, ax=ax)
        raise InvalidParameter(
            f"unknown quantity {quantity!r}; plot one of {sorted(self.FRAME_QUANTITIES)} "
            f"or a per-step statistic {sorted(self.step_stats)}."
        )

    @save_sections
    def save(self, run_dir: str | os.PathLike[str], *, model: AnyModel | None = None,
             overwrite: bool = False) -> Path:
        """Write the trajectory as a run directory, the format ``fem-elastic run`` writes.

        ``series.pvd``, ``frames/frame_%06d.vtu`` (reference points,
        ``displacement``, ``velocity``, stresses; P2 edge nodes as in
        :meth:`to_pyvista`) and ``summary.json``; read it back with
        :func:`fe.read_series`, render it with ``fe.render``.
        """
        return _view.save_result("trajectory", self, run_dir, self._need_model(model), overwrite=overwrite)
