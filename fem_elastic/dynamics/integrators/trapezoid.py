"""The trapezoidal rule on positions and velocities, as energy minimisation.

The trapezoidal rule (Crank-Nicolson) applied to ``x' = v``, ``M v' = f(x, v)``
with ``f(x, v) = -dPi/dx(x) - C v``:

    x1 = x0 + h/2 (v0 + v1),
    M v1 = M v0 + h/2 (f(x0, v0) + f(x1, v1)).

Its incremental potential
-------------------------
The first line gives the velocity update ``v1 = 2 (x1 - x0) / h - v0``. Put
into the second and multiplied by 2/h:

    4/h^2 M (x1 - x0 - h v0) = f(x0, v0) + f(x1, v1).

Damping: the rule asks for ``-C(x0) v0 - C(x1) v1``; a C at the unknown x1
would make the equations unsymmetric (``dC/dx v``). Both terms take one
matrix instead, ``C_m = C(x0 + h/2 v0)``, frozen at the predicted midpoint.
Their sum is then ``-C_m (v0 + v1) = -(2/h) C_m (x1 - x0)``: the start
velocity drops out, the damping's work on a step, ``-(h/4) (v0 + v1) . C_m
(v0 + v1)``, only dissipates, and it differs from the rule's ``h/2 (C(x0) v0
+ C(x1) v1)`` by O(h^3) a step, so the scheme stays second order when C
depends on the configuration (stiffness-proportional Rayleigh damping: the
element stiffness rotates with the elements). With a constant C
(mass-proportional damping) it is the trapezoidal rule exactly. Frozen at x0,
as implicit Euler and Newmark freeze it, that term would be first order
(tests/test_trapezoid.py measures both). With ``g0 = dPi/dx(x0)`` the
equation for x1 is

    4/h^2 M (x1 - x0 - h v0) + dPi/dx(x1) + g0 + (2/h) C_m (x1 - x0) = 0,

which is ``dG/dx(x1) = 0`` for

    G(x) = 2/h^2 ||x - x0 - h v0||_M^2 + Pi(x) + g0 . (x - x0) + 1/h ||x - x0||_C_m^2.

That is the implicit-Euler potential
(:mod:`fem_elastic.dynamics.integrators.incremental`) with ``k = c = h/2``,
target ``y = x0 + h v0`` and damping reference ``z = x0``, plus the force at
the start of the step as a dead load (the linear term). Its Hessian
``4/h^2 M + K(x) + (2/h) C_m`` is symmetric, so x1 is a stationary point of G
and the static problem's Newton solver with line search finds it; near a
stable equilibrium it is a minimum. No mass matrix is solved and no damping
force evaluated: a step costs the Newton iterations, one damping matrix (if
any) and the force at x0, which is remembered from the end of the previous
step (the last gradient Newton evaluated is at x1) and saved in checkpoints.

Accuracy and energy: second order, A-stable (no critical time step; on the
modal oscillator the map is the Cayley transform
``(I - h/2 A)^-1 (I + h/2 A)``, every undamped mode keeps its amplitude at
any h). For a linear undamped body ``KE + Pi`` is conserved exactly: the
energy change of a step is ``1/2 R . (x1 - x0)``, R Newton's residual, so to
Newton's tolerance. For a nonlinear body it is not conserved (the rule is
not symplectic), and strongly nonlinear motion at a large step can gain
energy: a soft Neo-Hookean cantilever (E = 100 kPa) sagging 1 m under
gravity diverges at 100 times the explicit limit (Newmark alike), while at
10 times it, or a stiff one (10 MPa, 3 cm sag) at 1000 times, stays bounded.

Relation to Newmark
-------------------
Newmark's average-acceleration rule (:class:`fe.Newmark`) applied to the same
equations gives the same ``x1`` and the same ``v1`` in exact arithmetic
whenever its acceleration ``a0`` equals ``M^-1 f(x0, v0)`` (and, with
damping, C is constant): substituting
``a1 = 4/h^2 (x1 - x0 - h v0) - a0`` into its velocity update gives
``v1 = 2 (x1 - x0) / h - v0``. They differ in what they carry between steps.
Newmark keeps a third state variable, the kinematic acceleration ``a1``,
which differs from ``M^-1 f(x1, v1)`` by M^-1 times Newton's residual and
carries that difference into the next step (and needs ``M a = f`` solved
for a state it did not produce). The trapezoid rule here is a map of
``(x, v)`` alone: it uses the actual force at x0, so a step from any State
with the same x and v gives the same bits, and its step never involves an
acceleration. With configuration-dependent damping they also differ in
accuracy: Newmark's C is frozen at the start of each step and its carried
acceleration holds the damping force of the previous step's matrix, which
makes it first order in that term; the midpoint matrix above keeps the
trapezoid rule second order.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from .base import restored_gradient
from .implicit import ImplicitEuler
from .incremental import IncrementalPotential

if TYPE_CHECKING:  # for annotations only
    from ...solvers.solver_types import LinearSolver
    from ..state import State

__all__ = ["Trapezoid", "TrapezoidPotential"]

_EPS = np.finfo(float).eps


class TrapezoidPotential(IncrementalPotential):
    """G(x) of one trapezoid step (see the module notes).

    Parameters
    ----------
    model : Model
    state : State
        The start of the step.
    h : float
        Time step (s).
    mass : {"lumped", "consistent"}
    g0 : numpy.ndarray
        ``dPi/dx`` at ``state.x`` (N).

    Attributes
    ----------
    body_gradient : tuple
        ``(x, dPi/dx(x))`` of the last :meth:`gradient` call (a copy of x and
        the model's own array), so the step can keep the force at its end.
    """

    def __init__(self, model, state, h, mass, g0):
        x_mid = state.x + (0.5 * h) * state.v  # where C is frozen (see the module notes)
        super().__init__(model, state.x + h * state.v, 0.5 * h, mass, x_mid, z=state.x, c=0.5 * h)
        self.g0 = g0
        self.x_start = state.x
        self.body_gradient = (None, None)

    def energy(self, x) -> float:
        e = super().energy(x)
        if not math.isfinite(e):
            return math.inf
        e += float(self.g0 @ (x - self.x_start))
        return e if math.isfinite(e) else math.inf

    def gradient(self, x) -> np.ndarray:
        gb = self.model.gradient(x)
        self.body_gradient = (x.copy(), gb)
        g = gb + self._M(x - self.y) / self.k2
        if self.C is not None:
            g += (self.C @ (x - self.z)) / self.c
        g += self.g0
        return g

    def linearize(self, x, project=True, body=None):
        g, H = super().linearize(x, project, body)
        g += self.g0  # a new array: the model's gradient is not touched
        return g, H

    def scale(self, state, free) -> float:
        """Force scale (N): that of implicit Euler's potential, or the force at x0 if larger."""
        return max(super().scale(state, free), float(np.linalg.norm(self.g0[free])))

    def gradient_roundoff(self, x) -> float:
        return super().gradient_roundoff(x) + _EPS * float(np.linalg.norm(self.g0))

    def energy_roundoff(self, x) -> float:
        lin = _EPS * float(np.abs(self.g0) @ np.abs(x - self.x_start))
        return super().energy_roundoff(x) + lin


class Trapezoid(ImplicitEuler):
    """The trapezoidal rule on (x, v), solved by Newton on its own incremental potential.

    ``x1 = x0 + h/2 (v0 + v1)``, ``M v1 = M v0 + h/2 (f(x0, v0) + f(x1, v1))``:
    second order, A-stable, energy-conserving for a linear undamped body (to
    Newton's tolerance). How it is solved and how it differs from
    :class:`fe.Newmark`: :mod:`fem_elastic.dynamics.integrators.trapezoid`.
    When Newton fails the step is retried as two halves, recursively
    (``max_dt_cuts``), recorded in ``last_stats.cuts``.

    Parameters are those of :class:`fe.ImplicitEuler`: ``rtol``, ``max_iter``,
    ``mass``, ``max_dt_cuts``, ``project``, ``linear_solver``, ``velocity_tol``.

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> M = fe.Trapezoid().step_matrix(10.0, 1.0)  # any h: |eigenvalues| = 1 for an undamped mode
    >>> np.round(abs(np.linalg.eigvals(M)), 12)
    array([1., 1.])
    >>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
    ...                  fixed="left", gravity=(0, 0, -9.81))
    >>> tr = fe.Trapezoid()
    >>> s = tr.step(model, fe.State.rest(model), 0.01)
    >>> sorted(tr.checkpoint_state(s))  # the force at the end, for the next step
    ['gradient']
    """

    order = 2
    _step_per_velocity = 0.5  # v1 = 2 (x1 - x0) / h - v0: a position error counts twice
    # (model or None: the next one, positions, dPi/dx there), all None when nothing is remembered
    _force: tuple[Any, Any, Any]

    def __init__(self, rtol: float = 1e-8, max_iter: int = 30,
                 mass: Literal["lumped", "consistent"] = "lumped", max_dt_cuts: int = 4,
                 project: bool = True, linear_solver: LinearSolver | str | None = None,
                 velocity_tol: float = 0.0) -> None:
        super().__init__(rtol, max_iter, mass, max_dt_cuts, project, linear_solver, velocity_tol)
        self._force = (None, None, None)  # (model or None: the next one, positions, dPi/dx there)
        self._g0 = None  # dPi/dx at the start of the step being taken
        self._G = None  # its potential

    # -- what it remembers -------------------------------------------------------------------
    def checkpoint_state(self, state: State) -> dict:
        """``gradient``: dPi/dx at ``state.x`` (N), if remembered from the step that ended there.

        Without it a resumed step evaluates the force itself: the same bits,
        but one more gradient evaluation in the step's count.
        """
        _, at, g = self._force
        return {"gradient": g.copy()} if at is state.x else {}

    def restore_state(self, state: State, saved: dict) -> None:
        """Remember ``saved["gradient"]`` as dPi/dx at ``state.x`` (if saved)."""
        g = restored_gradient(self.name, state, saved, self._forget_force)
        if g is not None:
            self._force = (None, state.x, g)

    def _forget_force(self) -> None:
        self._force = (None, None, None)

    def _start_gradient(self, model, state, stats) -> np.ndarray:
        """dPi/dx at ``state.x``: remembered from the step that ended there, else evaluated."""
        owner, at, g = self._force
        if at is state.x and (owner is model or owner is None):
            self._force = (model, at, g)
            return g
        g = model.gradient(state.x)
        stats.gradient_evaluations += 1
        self._force = (model, state.x, g)
        return g

    # -- the step ----------------------------------------------------------------------------
    def _objective(self, model, state, h):
        self._G = TrapezoidPotential(model, state, h, self.mass, self._g0)
        return self._G

    def _prediction(self, G, state, h):
        # the explicit second-order guess x0 + h v0 + h^2/2 a0, a0 = -g0 / m (lumped, undamped)
        return state.x + h * state.v - (0.5 * h * h) * (G.g0 / G.model.lumped_mass)

    def _velocity(self, state, x1, h):
        return (x1 - state.x) * (2.0 / h) - state.v

    def _try(self, model, state, h, stats):
        g0 = self._start_gradient(model, state, stats)
        if not np.isfinite(g0).all():
            return None, "the force at the start of the step is not finite (an inverted element)"
        self._g0 = g0
        try:
            out, why = super()._try(model, state, h, stats)
            if out is not None:
                at, gb = self._G.body_gradient
                if at is not None and np.array_equal(at, out.x):  # Newton's last gradient is at x1
                    self._force = (model, out.x, gb)
            return out, why
        finally:
            self._g0 = self._G = None

    def step_matrix(self, h: float, omega: float, zeta: float = 0.0) -> np.ndarray:
        """``(I - h/2 A)^-1 (I + h/2 A)`` on the modal oscillator (its step, for a constant C)."""
        A = self._oscillator(omega, zeta)
        return np.linalg.solve(np.eye(2) - 0.5 * h * A, np.eye(2) + 0.5 * h * A)
