"""Explicit integrators: explicit Euler, symplectic Euler, midpoint, RK4.

All four see the model only through its force, ``f = -dPi/dx - C v``, and
the lumped mass ``m`` (kg per DOF), so a step costs one (Euler, symplectic
Euler), two (midpoint) or four (RK4) force evaluations and no matrix. With
``a(x, v) = f(x, v) / m`` on the free DOFs (0 on held ones, whose motion is
prescribed):

- explicit Euler: ``x1 = x + h v``, ``v1 = v + h a(x, v)``; first order;
  unstable for an undamped oscillator at every h (the amplification is
  ``sqrt(1 + (omega h)^2) > 1``), so its energy always grows;
- symplectic (semi-implicit) Euler: ``v1 = v + h a(x, v)``, ``x1 = x + h
  v1``; first order, symplectic, stable for ``h <= 2 / omega_max``;
  conserves linear and angular momentum exactly;
- midpoint (explicit RK2): second order; weakly unstable for an undamped
  oscillator (amplification ``sqrt(1 + (omega h)^4 / 4)``);
- classical RK4: fourth order; stable for ``h <= 2 sqrt(2) / omega_max``
  on the imaginary axis.
"""

from __future__ import annotations

import numpy as np

from ..state import State
from .base import Integrator, StepStats, check_dt, check_state

__all__ = ["ExplicitEuler", "SymplecticEuler", "Midpoint", "RK4"]


class _Explicit(Integrator):
    explicit = True

    def _acceleration(self, model, x, v, free, stats):
        f = model.gradient(x)
        np.negative(f, out=f)
        fd = model.damping_force(x, v, "lumped")
        if fd is not None:
            f += fd
        f /= model.lumped_mass
        f[~free] = 0.0
        stats.gradient_evaluations += 1
        return f

    def _held(self, model, x, v, t):
        """Copies of x, v with the held DOFs at their prescription at time t, and the free mask."""
        dofs, xc, vc = model.constraints(t)
        x = x.copy()
        v = v.copy()
        x[dofs], v[dofs] = xc, vc
        free = np.ones(model.ndofs, dtype=bool)
        free[dofs] = False
        return x, v, free


class ExplicitEuler(_Explicit):
    """Forward Euler: ``x1 = x + h v``, ``v1 = v + h a(x, v)`` (first order).

    Examples
    --------
    >>> import fem_elastic as fe
    >>> fe.ExplicitEuler().step_matrix(0.1, 1.0)  # I + h A for q'' = -q
    array([[ 1. ,  0.1],
           [-0.1,  1. ]])
    """

    order = 1

    def step(self, model, state: State, dt: float) -> State:
        h = check_dt(dt)
        check_state(model, state)
        stats = self.last_stats = StepStats()
        x, v, free = state.x, state.v, model.free_at(state.t)
        a = self._acceleration(model, x, v, free, stats)
        return self._finish(model, x + h * v, v + h * a, state.t + h)

    def step_matrix(self, h, omega, zeta=0.0):
        return np.eye(2) + h * self._oscillator(omega, zeta)


class SymplecticEuler(_Explicit):
    """Semi-implicit Euler: ``v1 = v + h a(x, v)``, then ``x1 = x + h v1``.

    Stable up to ``h = 2 / omega_max`` on an undamped body; its energy
    error stays bounded (it is symplectic), and it conserves linear and
    angular momentum exactly.

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> [round(float(max(abs(np.linalg.eigvals(fe.SymplecticEuler().step_matrix(h, 1.0))))), 12)
    ...  for h in (1.9, 2.1)]  # below and above h = 2 / omega
    [1.0, 1.87732804493]
    """

    order = 1

    def step(self, model, state: State, dt: float) -> State:
        h = check_dt(dt)
        check_state(model, state)
        stats = self.last_stats = StepStats()
        free = model.free_at(state.t)
        a = self._acceleration(model, state.x, state.v, free, stats)
        a *= h
        a += state.v  # v1, in place of a temporary
        x1 = state.x + h * a
        return self._finish(model, x1, a, state.t + h)

    def step_matrix(self, h, omega, zeta=0.0):
        w2, c = omega * omega, 2.0 * zeta * omega
        # v1 = v + h (-w2 q - c v);  q1 = q + h v1
        return np.array([[1.0 - h * h * w2, h * (1.0 - h * c)], [-h * w2, 1.0 - h * c]])


class Midpoint(_Explicit):
    """Explicit midpoint (RK2): a half Euler step, then the full step with midpoint rates.

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> M = fe.Midpoint().step_matrix(0.1, 1.0)
    >>> round(float(abs(np.linalg.eigvals(M)).max()) - 1.0, 8)  # sqrt(1 + (wh)^4/4) - 1
    1.25e-05
    """

    order = 2

    def step(self, model, state: State, dt: float) -> State:
        h = check_dt(dt)
        check_state(model, state)
        stats = self.last_stats = StepStats()
        t = state.t
        x, v, free = state.x, state.v, model.free_at(t)
        a = self._acceleration(model, x, v, free, stats)
        xm, vm, free_m = self._held(model, x + 0.5 * h * v, v + 0.5 * h * a, t + 0.5 * h)
        am = self._acceleration(model, xm, vm, free_m, stats)
        return self._finish(model, x + h * vm, v + h * am, t + h)

    def step_matrix(self, h, omega, zeta=0.0):
        hA = h * self._oscillator(omega, zeta)
        return np.eye(2) + hA + hA @ hA / 2.0


class RK4(_Explicit):
    """Classical fourth-order Runge-Kutta on ``(x, v)``.

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> M = fe.RK4().step_matrix(2 * np.sqrt(2), 1.0)  # on the imaginary-axis limit
    >>> round(float(abs(np.linalg.eigvals(M)).max()), 12)
    1.0
    """

    order = 4

    def step(self, model, state: State, dt: float) -> State:
        h = check_dt(dt)
        check_state(model, state)
        stats = self.last_stats = StepStats()
        t = state.t
        x1, v1, free = state.x, state.v, model.free_at(t)
        a1 = self._acceleration(model, x1, v1, free, stats)
        x2, v2, free2 = self._held(model, x1 + 0.5 * h * v1, v1 + 0.5 * h * a1, t + 0.5 * h)
        a2 = self._acceleration(model, x2, v2, free2, stats)
        x3, v3, _ = self._held(model, x1 + 0.5 * h * v2, v1 + 0.5 * h * a2, t + 0.5 * h)
        a3 = self._acceleration(model, x3, v3, free2, stats)
        x4, v4, free4 = self._held(model, x1 + h * v3, v1 + h * a3, t + h)
        a4 = self._acceleration(model, x4, v4, free4, stats)
        x = x1 + (h / 6.0) * (v1 + 2.0 * v2 + 2.0 * v3 + v4)
        v = v1 + (h / 6.0) * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        return self._finish(model, x, v, t + h)

    def step_matrix(self, h, omega, zeta=0.0):
        hA = h * self._oscillator(omega, zeta)
        hA2 = hA @ hA
        return np.eye(2) + hA + hA2 / 2.0 + hA2 @ hA / 6.0 + hA2 @ hA2 / 24.0
