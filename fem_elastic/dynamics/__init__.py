"""Dynamics: time integration of a model, from one step to a whole recorded run.

Holds the :class:`~fem_elastic.dynamics.state.State` ``(x, v, t)``, the
integrators (:mod:`~fem_elastic.dynamics.integrators`: each a small object with
``step(model, state, dt) -> State``), :func:`~fem_elastic.dynamics.simulate.simulate`
(a loop that hands every accepted step to observers:
:mod:`~fem_elastic.dynamics.observers`), the recorded
:class:`~fem_elastic.dynamics.trajectory.Trajectory` and checkpoints. It may
import :mod:`fem_elastic.solvers`, :mod:`fem_elastic.physics` and the layers
below, never :mod:`fem_elastic.study` or :mod:`fem_elastic.app`.
"""

from .checkpoint import Checkpoint, load_checkpoint
from .contact_watch import ContactIntersectionWarning
from .integrators import (
    RK4,
    ExplicitEuler,
    ImplicitEuler,
    Integrator,
    LinearizedImplicitEuler,
    Midpoint,
    Newmark,
    StepStats,
    SymplecticEuler,
    Trapezoid,
    VelocityVerlet,
)
from .observers import InversionWarning, Observer  # noqa: F401
from .position_based import PBD, XPBD, ConstraintNeoHookean
from .projective import ProjectiveDynamics
from .shape_matching import ShapeMatcher, ShapeMatching
from .simulate import StabilityWarning, simulate
from .state import State
from .trajectory import Trajectory

__all__ = [
    "Checkpoint", "ContactIntersectionWarning", "ExplicitEuler", "ImplicitEuler", "Integrator",
    "LinearizedImplicitEuler",
    "ConstraintNeoHookean", "Midpoint", "Newmark", "Observer", "PBD", "XPBD",
    "ProjectiveDynamics", "RK4", "ShapeMatcher", "ShapeMatching",
    "StabilityWarning", "State", "StepStats",
    "SymplecticEuler", "Trajectory", "Trapezoid", "VelocityVerlet", "load_checkpoint", "simulate",
]
