"""The integrator interface and what every scheme shares.

An integrator is a small object with one method, ``step(model, state, dt)
-> State``. It never stores physics (that is the Model's) and keeps only
its settings, the statistics of its last step (``last_stats``) and, for
Newmark, the acceleration of the state it produced last (a cache that is
recomputed whenever it does not match the state given). What a scheme
remembers between steps is saved in checkpoints
(:meth:`Integrator.checkpoint_state`, :meth:`Integrator.restore_state`) so
that a resumed run repeats the uninterrupted one bit for bit.

For the stability analysis, each scheme also gives its one-step map on the
damped modal oscillator ``q'' + 2 zeta omega q' + omega^2 q = 0``
(:meth:`Integrator.step_matrix`); ``fe.critical_time_step`` finds the
largest dt whose map has spectral radius <= 1 at the model's highest
frequency.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ...errors import InvalidParameter
from ..state import State

if TYPE_CHECKING:  # for annotations only
    from ...physics.multibody import AnyModel

__all__ = ["Integrator", "StepStats", "check_dt", "check_state"]


def check_state(model, state) -> None:
    """:class:`InvalidParameter` unless ``state`` is a State of ``model``'s size."""
    if not isinstance(state, State):
        raise InvalidParameter(
            f"state must be a fe.State (e.g. fe.State.rest(model)), got {type(state).__name__}."
        )
    if state.x.shape != (model.ndofs,):
        raise InvalidParameter(
            f"the state has {state.x.size} DOFs but the model has {model.ndofs}; "
            "build it with fe.State.rest(model, ...)."
        )
    bad = np.count_nonzero(~np.isfinite(state.x)) + np.count_nonzero(~np.isfinite(state.v))
    if bad:
        raise InvalidParameter(
            f"the state has {bad} NaN or infinite position/velocity value(s); give a state with "
            "finite values (fe.State.rest(model, ...), or err.last_good_state of a run that diverged)."
        )


#: dt^2 below this is subnormal or zero: 1/dt^2 overflows or loses its precision.
_DT2_MIN = np.finfo(float).tiny
_DT_MIN = math.sqrt(_DT2_MIN)
#: dt^2 above this overflows to inf (and dt^2 times a stiffness long before).
_DT_MAX = math.sqrt(np.finfo(float).max) / 1e4


def check_dt(dt) -> float:
    """``dt`` as a float, or :class:`InvalidParameter` unless it is finite and > 0 (s)."""
    if isinstance(dt, bool) or not isinstance(dt, numbers.Real) or not math.isfinite(dt) or dt <= 0:
        raise InvalidParameter(
            f"the time step dt must be a finite number > 0 (s), got {dt!r}; e.g. dt=1e-3."
        )
    if float(dt) < _DT_MIN:
        raise InvalidParameter(
            f"the time step dt = {dt!r} s is too small: implicit schemes divide by dt^2, which "
            f"underflows below {_DT_MIN:.0e} s; use a dt of at least that (e.g. dt=1e-6)."
        )
    if float(dt) > _DT_MAX:
        raise InvalidParameter(
            f"the time step dt = {dt!r} s is too large: the schemes use dt^2, which overflows "
            f"above {_DT_MAX:.0e} s; give dt in seconds, a fraction of the run's duration (e.g. dt=1e-3)."
        )
    return float(dt)


def restored_gradient(name: str, state: State, saved: dict, forget: Callable[[], None],
                      written_by: str = "another integrator") -> np.ndarray | None:
    """The ``dPi/dx`` at ``state.x`` that a checkpoint saved as ``saved["gradient"]``, or None.

    For the schemes that remember the force at the end of a step (velocity
    Verlet, the trapezoid rule). ``saved`` may hold only ``"gradient"``
    (:class:`InvalidParameter` naming ``written_by`` otherwise); ``forget()``,
    the integrator's reset of that memory, is called once the keys are
    accepted, before the gradient is checked to be a finite ``(ndofs,)`` force.
    """
    if set(saved) - {"gradient"}:
        raise InvalidParameter(
            f"{name} restores a gradient from a checkpoint, got {sorted(saved)}: it was "
            f"written by {written_by}."
        )
    forget()
    if "gradient" not in saved:
        return None
    g = np.array(saved["gradient"], dtype=float)
    if g.shape != state.x.shape or not np.isfinite(g).all():
        raise InvalidParameter(
            f"the checkpoint's {name} gradient (shape {g.shape}) is not a finite force of "
            f"the state's {state.x.size} DOFs: it is damaged or of another model; resume from "
            "an earlier checkpoint."
        )
    return g


@dataclass
class StepStats:
    """What one step cost.

    Attributes
    ----------
    gradient_evaluations : int
        Residual (force) evaluations of the model.
    newton_iterations, line_search_cuts, linear_iterations : int
        Solver work of implicit schemes (0 for explicit ones).
    linear_solves : int
        Linear solves of implicit schemes, every one (none is thrown away).
    linear_setups : int
        AMG hierarchies and LU factorizations built for them (with the
        default solver above 20k DOFs, one hierarchy per step unless CG
        needed a rebuild).
    extensions : int
        Newton steps lengthened at a saddle under IPC contact
        (:func:`fem_elastic.solvers.newton.saddle_extension_safe`).
    dt_cuts : int
        Times the step was retried smaller: halved because Newton did not
        converge (implicit schemes), or with more sub-steps (explicit
        sub-stepping).
    substeps : int
        Sub-steps the step was finally taken in (1 without cuts).
    cuts : list of (float, float, str)
        Every failed attempt of the step: ``(t, dt, reason)``, the time it
        started from (s), the step size that failed (s) and why.
    seconds : dict
        Wall time (s) by stage: ``"linearize"`` (assembly and projection),
        ``"solve"`` (linear solves), ``"line_search"`` (energy evaluations).
    """

    gradient_evaluations: int = 0
    newton_iterations: int = 0
    line_search_cuts: int = 0
    linear_iterations: int = 0
    dt_cuts: int = 0
    substeps: int = 1
    cuts: list = field(default_factory=list)
    seconds: dict = field(default_factory=lambda: {"linearize": 0.0, "solve": 0.0, "line_search": 0.0})
    linear_solves: int = 0
    linear_setups: int = 0
    extensions: int = 0

    def add(self, other: "StepStats") -> None:
        """Accumulate another step's counts into this one."""
        for name in ("gradient_evaluations", "newton_iterations", "line_search_cuts", "linear_iterations",
                     "linear_solves", "linear_setups", "extensions"):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        for k, v in other.seconds.items():
            self.seconds[k] = self.seconds.get(k, 0.0) + v


class Integrator:
    """Base class of the time integrators.

    Attributes
    ----------
    explicit : bool
        True for schemes with a step-size limit (they use the lumped mass and
        never build a Hessian).
    order : int
        Order of accuracy of the scheme.
    last_stats : StepStats
        Statistics of the last call to :meth:`step`.
    """

    explicit: bool = True
    order: int = 1

    def __init__(self) -> None:
        self.last_stats = StepStats()

    @property
    def name(self) -> str:
        """The class name, for reports."""
        return type(self).__name__

    def __repr__(self) -> str:
        return f"fe.{self.name}()"

    def step(self, model: AnyModel, state: State, dt: float) -> State:  # pragma: no cover - abstract
        """Advance ``state`` by ``dt`` (s) and return the new State."""
        raise NotImplementedError

    def checkpoint_state(self, state: State) -> dict:
        """What the integrator remembers between steps, for a checkpoint at ``state``.

        A resumed run restores it with :meth:`restore_state`, so that the next
        step is computed exactly as it would have been without the stop.

        Parameters
        ----------
        state : State
            The state the next step starts from.

        Returns
        -------
        dict of str to numpy.ndarray
            Arrays of floats or ints; empty for memoryless schemes.
        """
        return {}

    def restore_state(self, state: State, saved: dict) -> None:
        """Take back what :meth:`checkpoint_state` returned, for the next step from ``state``."""
        if saved:
            raise InvalidParameter(
                f"{self.name} keeps no state between steps, but the checkpoint holds "
                f"{sorted(saved)}: it was written by another integrator."
            )

    def step_matrix(self, h: float, omega: float, zeta: float = 0.0) -> np.ndarray:  # pragma: no cover
        """One-step map ``(q, v) -> (q, v)`` on ``q'' + 2 zeta omega q' + omega^2 q = 0``."""
        raise NotImplementedError

    @staticmethod
    def _oscillator(omega: float, zeta: float) -> np.ndarray:
        """The first-order system matrix A of the modal oscillator, y = (q, v)."""
        return np.array([[0.0, 1.0], [-omega * omega, -2.0 * zeta * omega]])

    @staticmethod
    def _finish(model, x: np.ndarray, v: np.ndarray, t: float) -> State:
        """Apply impulse contacts, impose the constraints at time t, return the State.

        Constraints come last: a held DOF follows its prescription even if an
        obstacle would push it.
        """
        x, v = model.respond_contacts(x, v)
        dofs, xc, vc = model.constraints(t)
        x[dofs] = xc
        v[dofs] = vc
        return State(x, v, t)
