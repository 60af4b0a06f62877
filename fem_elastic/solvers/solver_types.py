"""The types the solvers take, for annotations: what a linear solver must offer.

``fe.solve_static(model, linear_solver=...)`` and the implicit integrators take
any object with the ``solve`` method of :class:`LinearSolver` (the library's
:class:`~fem_elastic.solvers.linear_solvers.DirectSolver`,
:class:`~fem_elastic.solvers.linear_solvers.AMGSolver` and
:class:`~fem_elastic.solvers.linear_solvers.AutoSolver`, or a user's own).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from .linear_solvers import LinearSolve

__all__ = ["LinearSolver", "SteppingScheme"]


class LinearSolver(Protocol):
    """Anything that solves ``A x = b`` for the Newton solver.

    ``solve(A, b, near_null)`` is called with the free-DOF tangent ``A`` (a
    scipy CSR matrix, N/m), the right-hand side ``b`` (N) and the rigid-body
    modes ``near_null`` (``(n, 6)`` or None, for AMG); it may take ``rtol`` as
    a keyword too (then Newton passes its forcing term). It returns a
    :class:`~fem_elastic.solvers.linear_solvers.LinearSolve`.
    """

    def solve(self, A: Any, b: np.ndarray, near_null: np.ndarray | None = None, /) -> LinearSolve:
        """The solution of ``A x = b`` and its statistics."""
        ...


class SteppingScheme(Protocol):
    """A time integrator as the stability analysis sees it (``fe.critical_time_step``).

    ``explicit`` says whether its stable step is bounded; ``step_matrix(h, omega, zeta)``
    is its one-step map of the modal oscillator ``q'' + 2 zeta omega q' + omega^2 q = 0``
    (a 2x2 array on ``(q, q')``, time step ``h`` s, ``omega`` rad/s). Every ``fe`` integrator
    has both.
    """

    @property
    def explicit(self) -> bool:
        """Whether the scheme is explicit (conditionally stable)."""
        ...

    def step_matrix(self, h: float, omega: float, zeta: float = 0.0) -> np.ndarray:
        """The one-step map of the damped modal oscillator, ``(2, 2)``."""
        ...
