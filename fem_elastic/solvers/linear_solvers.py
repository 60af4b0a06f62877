"""Linear solvers for the Newton systems K dx = -g.

Choose behaviour by passing an object: ``fe.DirectSolver()``,
``fe.AMGSolver(rtol=1e-8)`` or ``fe.AutoSolver(max_direct_dofs=...)``, the
default, which picks by size. Each has ``solve(A, b, near_null=None)``
returning a :class:`LinearSolve` with the solution and statistics.

Measured on this project's machines (88k-DOF elasticity system): scipy's
default ``spsolve`` (COLAMD ordering) took 24 s and 3.3 GB; SuperLU with a
symmetric ordering (``MMD_AT_PLUS_A``) halves that; smoothed-aggregation AMG
(pyamg) given the six rigid-body modes and a ``splu`` coarse solver, as a
CG preconditioner, solved it to 1e-8 in 1.3 s. pyamg's defaults were 5x
slower, and its default ``pinv`` coarse solver does a dense SVD.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import FemElasticError, InvalidParameter, NotConverged

__all__ = [
    "LinearSolve", "DirectSolver", "AMGSolver", "AutoSolver", "SingularMatrix", "LinearSolverFailed",
]

log = logging.getLogger(__name__)


class SingularMatrix(FemElasticError, ArithmeticError):
    """The linear system is singular to working precision."""


class LinearSolverFailed(NotConverged):
    """An iterative linear solver missed its tolerance; ``.result`` holds its last iterate."""


@dataclass(frozen=True)
class LinearSolve:
    """One linear solve: solution and statistics.

    Attributes
    ----------
    x : numpy.ndarray
        The solution.
    method : str
        ``"direct"`` or ``"amg-cg"``.
    iterations : int
        Krylov iterations (0 for the direct solver).
    residual : float
        Relative residual ||b - A x|| / ||b||.
    seconds : float
        Wall time of setup and solve (s).
    """

    x: np.ndarray
    method: str
    iterations: int
    residual: float
    seconds: float


def _relative_residual(A, x, b) -> float:
    nb = np.linalg.norm(b)
    return float(np.linalg.norm(b - A @ x) / nb) if nb > 0 else 0.0


class _FactorCache:
    """The last factorization and the matrix it is of (one entry).

    A linear body under an implicit integrator at a fixed dt gives the same
    matrix every step: comparing the CSR arrays (O(nnz)) is far cheaper
    than factorizing again. The comparison is exact, so a reused factor is
    always the factor of the matrix given.
    """

    def __init__(self):
        self.key = None
        self.lu = None

    @staticmethod
    def _arrays(A):
        return (A.shape, A.indptr, A.indices, A.data)

    def get(self, A):
        if self.key is None or self.key[0] != A.shape:
            return None
        _, indptr, indices, data = self.key
        if (np.array_equal(indptr, A.indptr) and np.array_equal(indices, A.indices)
                and np.array_equal(data, A.data)):
            return self.lu
        return None

    def put(self, A, lu):
        self.key = (A.shape, A.indptr.copy(), A.indices.copy(), A.data.copy())
        self.lu = lu


_FACTORS = _FactorCache()
_CACHE_MAX_DOFS = 50_000  # larger factors hold too much memory to keep around


@dataclass(frozen=True)
class DirectSolver:
    """Sparse LU (SuperLU) with a symmetric fill-reducing ordering.

    The last factorization is kept: solving again with an identical matrix
    (a linear body stepped implicitly at a fixed dt) only back-substitutes.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> A = sp.diags([4.0, 5.0, 6.0]).tocsr()
    >>> DirectSolver().solve(A, np.array([4.0, 10.0, 18.0])).x
    array([1., 2., 3.])
    """

    def solve(self, A, b, near_null=None, rtol=None) -> LinearSolve:
        """Solve A x = b exactly (``rtol`` is accepted for a common interface and ignored)."""
        t0 = time.perf_counter()
        A = sp.csr_matrix(A)
        lu = _FACTORS.get(A)
        if lu is None:
            try:
                lu = spla.splu(
                    sp.csc_matrix(A),
                    permc_spec="MMD_AT_PLUS_A",
                    diag_pivot_thresh=0.0,
                    options=dict(SymmetricMode=True),
                )
            except RuntimeError as exc:  # SuperLU: "Factor is exactly singular"
                raise SingularMatrix(
                    f"the stiffness matrix is singular ({exc}); some motion costs no energy: "
                    "check that the body is fixed (fixed=...) and that no element is degenerate."
                ) from None
            if A.shape[0] <= _CACHE_MAX_DOFS:
                _FACTORS.put(A, lu)
        x = lu.solve(b)
        if not np.all(np.isfinite(x)):
            raise SingularMatrix("the direct solve produced non-finite values: the matrix is singular.")
        return LinearSolve(x, "direct", 0, _relative_residual(A, x, b), time.perf_counter() - t0)


@dataclass(frozen=True)
class AMGSolver:
    """Conjugate gradients preconditioned by smoothed-aggregation AMG (pyamg).

    Needs the optional dependency pyamg (``pip install fem_elastic[fast]``).
    The near-null space (the six rigid-body modes of elasticity) is passed as
    ``near_null``; without it AMG converges several times slower.

    Parameters
    ----------
    rtol : float
        Relative residual at which CG stops. Newton only needs a direction
        that is accurate relative to its own convergence, so 1e-8 is ample.
    maxiter : int
        Most CG iterations.
    """

    rtol: float = 1e-8
    maxiter: int = 500

    def __post_init__(self):
        if not (0 < self.rtol < 1):
            raise InvalidParameter(f"AMGSolver rtol must be in (0, 1), got {self.rtol!r}.")

    def solve(self, A, b, near_null=None, rtol=None) -> LinearSolve:
        """Solve A x = b by AMG-preconditioned CG to ``rtol`` (default: the solver's own)."""
        rtol = self.rtol if rtol is None else max(float(rtol), self.rtol)
        try:
            import pyamg
        except ImportError:  # pragma: no cover - depends on the environment
            raise InvalidParameter(
                "AMGSolver needs pyamg: pip install 'fem_elastic[fast]' (or pip install pyamg), "
                "or pass linear_solver=fe.DirectSolver()."
            ) from None
        t0 = time.perf_counter()
        A = sp.csr_matrix(A, copy=True)  # pyamg may edit A's structure; never the caller's
        B = None if near_null is None else np.ascontiguousarray(near_null, dtype=float)
        # The prolongation smoother's Jacobi weight needs a bound on the spectral
        # radius of D^-1 A. pyamg's default ("diagonal") and "block" weightings
        # estimate it by Lanczos from a random vector: on the benchmark beam the
        # same system then took 30 CG iterations one time and failed to converge
        # in 500 another, and "block" diverged on a thin P2 beam. "local" uses a
        # Gershgorin bound instead: deterministic, never too small, and it
        # converged on every system tried (45 iterations where the others took 30).
        ml = pyamg.smoothed_aggregation_solver(
            A,
            B=B,
            symmetry="hermitian",
            smooth=("jacobi", {"omega": 4.0 / 3.0, "weighting": "local"}),
            coarse_solver="splu",
            max_coarse=500,
        )
        residuals: list[float] = []
        x = ml.solve(b, tol=rtol, accel="cg", maxiter=self.maxiter, residuals=residuals)
        rel = _relative_residual(A, x, b) if np.all(np.isfinite(x)) else np.inf
        its = max(len(residuals) - 1, 0)
        if not rel <= 10 * rtol:  # CG's own test is in the preconditioned norm: allow 10x
            raise LinearSolverFailed(
                f"AMG-CG reached a relative residual of {rel:.2e} after {its} iterations "
                f"(asked {rtol:.1e}): the matrix may be indefinite or badly conditioned. "
                "Use linear_solver=fe.DirectSolver(), or raise maxiter.",
                result=LinearSolve(x, "amg-cg", its, rel, time.perf_counter() - t0),
            )
        return LinearSolve(x, "amg-cg", its, rel, time.perf_counter() - t0)


@dataclass(frozen=True)
class AutoSolver:
    """The direct solver for small systems, AMG-CG for large ones.

    If AMG-CG misses its tolerance (it can stall on badly conditioned
    systems, e.g. very thin P2 beams), the system is solved directly instead,
    with a warning in the log: a wrong direction would cost Newton far more.

    Parameters
    ----------
    max_direct_dofs : int
        Largest system solved directly. Sparse LU's fill grows fast in 3-D; on
        the project's machines AMG-CG overtakes it near 20k DOFs. Without
        pyamg installed, every system is solved directly.
    amg : AMGSolver
        The iterative solver used above the threshold.
    fallback : bool
        Solve directly when AMG-CG fails (default); False re-raises.
    """

    max_direct_dofs: int = 20_000
    amg: AMGSolver = AMGSolver()
    fallback: bool = True

    def solve(self, A, b, near_null=None, rtol=None) -> LinearSolve:
        """Direct below ``max_direct_dofs``, AMG-CG (to ``rtol`` if given) above."""
        if A.shape[0] > self.max_direct_dofs and _have_pyamg():
            try:
                return self.amg.solve(A, b, near_null, rtol=rtol)
            except LinearSolverFailed as exc:
                if not self.fallback:
                    raise
                log.warning("%s Falling back to the direct solver.", exc)
        return DirectSolver().solve(A, b, near_null)

    def strict(self) -> "AutoSolver":
        """The same solver, raising :class:`LinearSolverFailed` instead of falling back.

        Newton uses it on an exact (possibly indefinite) tangent, where the
        better remedy for a stalled CG is the PSD projection, not a large LU.
        """
        return replace(self, fallback=False)


def _have_pyamg() -> bool:
    try:
        import pyamg  # noqa: F401
    except ImportError:
        log.info("pyamg is not installed: solving directly (pip install 'fem_elastic[fast]')")
        return False
    return True
