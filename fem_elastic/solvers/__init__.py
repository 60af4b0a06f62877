"""Solvers: Newton's method with line search, linear solvers, the static solve, modal analysis.

Holds the minimiser every implicit computation shares
(:mod:`~fem_elastic.solvers.newton`: Newton with backtracking line search on
any energy with a gradient and a Hessian), the sparse linear solvers (direct,
Cholesky by CHOLMOD, AMG-CG, automatic choice, PETSc across MPI ranks), :func:`~fem_elastic.solvers.static.solve_static`
and the eigenvalue problems (:mod:`~fem_elastic.solvers.modal`: natural
frequencies, critical time steps). They see a model only through its energy,
gradient, Hessian, mass and held DOFs. It may import :mod:`fem_elastic.physics`
and the layers below it, never :mod:`fem_elastic.dynamics` or above.
"""

from .linear_solvers import AMGSolver, AutoSolver, DirectSolver, LinearSolverFailed, SingularMatrix
from .cholmod import CholmodSolver  # scikit-sparse is imported only when one is made
from .petsc_solver import PETScSolver  # petsc4py is imported only when one solves
from .modal import critical_time_step, max_frequency, natural_frequencies
from .newton import NewtonResult, newton_minimize
from .stability import UnstableEquilibrium, lowest_eigenpair
from .static import EquilibriumPoint, LoadPath, RoundoffWarning, StaticResult, load_path, solve_static

__all__ = [
    "AMGSolver", "AutoSolver", "CholmodSolver", "DirectSolver", "EquilibriumPoint", "LinearSolverFailed", "LoadPath",
    "NewtonResult", "PETScSolver", "RoundoffWarning", "UnstableEquilibrium", "load_path", "lowest_eigenpair",
    "SingularMatrix", "StaticResult", "critical_time_step", "max_frequency",
    "natural_frequencies", "newton_minimize", "solve_static",
]
