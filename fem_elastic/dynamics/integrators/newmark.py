"""Newmark's average-acceleration rule (beta = 1/4, gamma = 1/2).

    x1 = x + h v + h^2/4 (a + a1),      v1 = v + h/2 (a + a1),
    M a1 = f(x1, v1).

Second order, unconditionally stable, and for a linear undamped system it
conserves the energy exactly (it is the trapezoidal rule). The new
positions minimise the incremental potential with ``k = h/2`` and target
``y = x + h v + h^2/4 a`` (:mod:`fem_elastic.dynamics.integrators.incremental`), so the
same Newton solver serves it.

The scheme needs the acceleration of the current state. The integrator
remembers the acceleration of the state it returned last; given any other
state (the first one, or one built by the user) it computes ``a`` from
``M a = f(x, v)`` on the free DOFs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import scipy.sparse.linalg as spla

from ...errors import InvalidParameter
from .implicit import ImplicitEuler
from .incremental import IncrementalPotential

if TYPE_CHECKING:  # for annotations only
    from ...physics.multibody import AnyModel
    from ...solvers.solver_types import LinearSolver
    from ..state import State

__all__ = ["Newmark"]


class Newmark(ImplicitEuler):
    """Average-acceleration Newmark (trapezoidal rule), minimised with Newton.

    Parameters are those of :class:`fe.ImplicitEuler`.

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> M = fe.Newmark().step_matrix(10.0, 1.0)  # any h: |eigenvalues| = 1 for an undamped mode
    >>> np.round(abs(np.linalg.eigvals(M)), 12)
    array([1., 1.])
    """

    order = 2
    _step_per_velocity = 0.5  # v1 = 2 (x1 - x0) / h - v0: a position error counts twice
    _last: tuple[Any, Any]  # (State returned last, its acceleration a, m/s^2), or (None, None)

    def __init__(self, rtol: float = 1e-8, max_iter: int = 30,
                 mass: Literal["lumped", "consistent"] = "lumped", max_dt_cuts: int = 4,
                 project: bool = True, linear_solver: LinearSolver | str | None = None,
                 velocity_tol: float = 0.0) -> None:
        super().__init__(rtol=rtol, max_iter=max_iter, mass=mass, max_dt_cuts=max_dt_cuts,
                         project=project, linear_solver=linear_solver, velocity_tol=velocity_tol)
        self._last = (None, None)  # (state returned last, its acceleration)

    def acceleration(self, model: AnyModel, state: State) -> np.ndarray:
        """``a`` (m/s^2) of ``state``: remembered from the last step, else from M a = f."""
        last_state, a = self._last
        if last_state is state:
            return a
        f = -model.gradient(state.x)
        fd = model.damping_force(state.x, state.v, self.mass)
        if fd is not None:
            f += fd
        free = model.free_at(state.t)
        a = np.zeros(model.ndofs)
        if self.mass == "lumped":
            a[free] = f[free] / model.lumped_mass[free]
        else:
            M = model.mass_matrix[free][:, free].tocsc()
            a[free] = spla.spsolve(M, f[free])
        return a

    def checkpoint_state(self, state: State) -> dict:
        """The remembered acceleration of ``state`` (m/s^2), if it is the state returned last.

        Recomputing it from ``M a = f`` would differ from the scheme's own
        ``a1`` in the last bits, so a checkpoint keeps it.
        """
        last_state, a = self._last
        return {"acceleration": a.copy()} if last_state is state else {}

    def restore_state(self, state: State, saved: dict) -> None:
        """Remember ``saved["acceleration"]`` as the acceleration of ``state`` (if saved)."""
        unknown = set(saved) - {"acceleration"}
        if unknown:
            raise InvalidParameter(f"Newmark cannot restore {sorted(unknown)} from a checkpoint.")
        a = saved.get("acceleration")
        if a is None:
            self._last = (None, None)
            return
        a = np.array(a, dtype=float)
        if a.shape != state.x.shape:
            raise InvalidParameter(
                f"the checkpoint's Newmark acceleration has shape {a.shape}, the state {state.x.shape}."
            )
        self._last = (state, a)

    def _objective(self, model, state, h):
        a = self.acceleration(model, state)
        self._a_n = a
        y = state.x + h * state.v + 0.25 * h * h * a
        # damping: C v1 = C (v + h/2 a) + (2/h) C (x1 - y) = (1/c) C (x1 - z), c = h/2
        z = y - 0.5 * h * (state.v + 0.5 * h * a)
        return IncrementalPotential(model, y, 0.5 * h, self.mass, state.x, z=z, c=0.5 * h)

    def _velocity(self, state, x1, h):
        a = self._a_n
        a1 = 4.0 / (h * h) * (x1 - state.x - h * state.v) - a
        self._a1 = a1
        return state.v + 0.5 * h * (a + a1)

    def _try(self, model, state, h, stats):
        out, why = super()._try(model, state, h, stats)
        if out is None:
            return out, why
        impulses = any(getattr(o, "method", "") == "impulse" for o in model.obstacles)
        if model.driven or impulses:
            # prescribed motion or contact impulses change (x, v) outside the
            # scheme: the next step recomputes the acceleration from the forces
            self._last = (None, None)
        else:
            a1 = self._a1
            a1[~model.free_at(out.t)] = 0.0  # held DOFs do not accelerate
            self._last = (out, a1)
        return out, why

    def step_matrix(self, h: float, omega: float, zeta: float = 0.0) -> np.ndarray:
        A = self._oscillator(omega, zeta)
        return np.linalg.solve(np.eye(2) - 0.5 * h * A, np.eye(2) + 0.5 * h * A)
