"""Time integrators: ``step(model, state, dt) -> State``.

Explicit (lumped mass, no Hessian): :class:`ExplicitEuler`,
:class:`SymplecticEuler`, :class:`Midpoint`, :class:`RK4`,
:class:`VelocityVerlet`. Implicit (Newton on the incremental potential):
:class:`ImplicitEuler`, :class:`LinearizedImplicitEuler` (one Newton step;
stiffness warping for a corotated body), :class:`Newmark` (average
acceleration), :class:`Trapezoid` (the trapezoidal rule on x and v).
"""

from .base import Integrator, StepStats
from .explicit import RK4, ExplicitEuler, Midpoint, SymplecticEuler
from .implicit import ImplicitEuler, LinearizedImplicitEuler
from .newmark import Newmark
from .trapezoid import Trapezoid
from .verlet import VelocityVerlet

__all__ = [
    "ExplicitEuler", "ImplicitEuler", "Integrator", "LinearizedImplicitEuler", "Midpoint",
    "Newmark", "RK4", "StepStats", "SymplecticEuler", "Trapezoid", "VelocityVerlet",
]
