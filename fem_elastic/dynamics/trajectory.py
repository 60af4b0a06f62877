"""The record of a simulation: a Trajectory.

Frames are recorded every ``record_every`` steps (and at the end); the
per-step solver statistics are kept for every step, with the smallest
det F of the body after it (``min_det_F``: <= 0 means an inverted element).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Trajectory", "STEP_FIELDS", "COUNT_FIELDS"]

#: The per-step statistics of a run (``Trajectory.step_stats``): counts, then seconds.
STEP_FIELDS = ("gradient_evaluations", "newton_iterations", "line_search_cuts",
               "linear_iterations", "dt_cuts", "substeps", "seconds_linearize", "seconds_solve",
               "seconds_line_search", "seconds_step", "min_det_F")
COUNT_FIELDS = STEP_FIELDS[:6]


#: Per-step fields that are not work done (a sum of them means nothing).
_NOT_SUMMED = ("min_det_F",)

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
    final_state: object = None
    message: str = ""
    cuts: list = field(default_factory=list)
    resumed_from_step: int | None = None

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
        det = np.asarray(st.get("min_det_F", np.zeros(0)), dtype=float)
        det = det[np.isfinite(det)]
        # the smallest det F over the run's steps, and how many steps ended with an inverted element
        out["min_det_F"] = float(det.min()) if det.size else None
        out["steps_inverted"] = int(np.count_nonzero(det <= 0.0))
        return out
