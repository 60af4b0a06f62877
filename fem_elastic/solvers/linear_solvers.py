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
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import FemElasticError, InvalidParameter, NotConverged

if TYPE_CHECKING:  # for annotations only (pyamg is optional)
    from pyamg.multilevel import MultilevelSolver

__all__ = [
    "LinearSolve", "DirectSolver", "AMGSolver", "AutoSolver", "SingularMatrix", "LinearSolverFailed",
    "ReusedAMG", "preconditioned_cg", "superlu", "as_linear_solver", "LINEAR_SOLVER_NAMES",
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
    setups : int
        Preconditioner or factor builds this solve made: AMG hierarchies and
        LU factorizations (0 when a kept one was reused).
    negative_curvature : bool
        CG met a direction p with ``p . A p <= 0`` (the matrix is not positive
        definite) and stopped there; ``x`` is then its last iterate, a descent
        direction of the quadratic model but not a solution.
    """

    x: np.ndarray
    method: str
    iterations: int
    residual: float
    seconds: float
    setups: int = 0
    negative_curvature: bool = False


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

    def put_elsewhere_kept(self, shape, factor):
        """Record a factor kept by another solver (CHOLMOD's) as the last one made, so the
        stability check can precondition with it; :meth:`get` never returns it."""
        self.key = (shape, None, None, None)
        self.lu = factor


_FACTORS = _FactorCache()
_CACHE_MAX_DOFS = 50_000  # larger factors hold too much memory to keep around


def superlu(A: sp.spmatrix, diag_pivot_thresh: float = 0.0,
            what: str = "the stiffness matrix") -> spla.SuperLU:
    """SuperLU factor of a symmetric matrix ``A`` (symmetric ordering, diagonal pivots preferred).

    ``diag_pivot_thresh`` is SuperLU's: 0 takes the diagonal pivots as they
    come (right for a positive definite matrix), 0.1 pivots off the diagonal
    where it is below 0.1 of its column's largest entry
    (:func:`~fem_elastic.solvers.cholmod.pivoting_lu`). ``what`` names ``A``
    in the error. Raises :class:`SingularMatrix` if ``A`` is singular.
    """
    try:
        return spla.splu(
            sp.csc_matrix(A),
            permc_spec="MMD_AT_PLUS_A",
            diag_pivot_thresh=diag_pivot_thresh,
            options=dict(SymmetricMode=True),
        )
    except RuntimeError as exc:  # SuperLU: "Factor is exactly singular"
        raise SingularMatrix(
            f"{what} is singular ({exc}); some motion costs no energy: "
            "check that the body is fixed (fixed=...) and that no element is degenerate."
        ) from None


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

    def solve(self, A: sp.spmatrix, b: np.ndarray, near_null: np.ndarray | None = None,
              rtol: float | None = None) -> LinearSolve:
        """Solve A x = b exactly (``rtol`` is accepted for a common interface and ignored)."""
        t0 = time.perf_counter()
        A = sp.csr_matrix(A)
        lu = _FACTORS.get(A)
        if lu is None:
            lu = superlu(A)
            if A.shape[0] <= _CACHE_MAX_DOFS:
                _FACTORS.put(A, lu)
            setups = 1
        else:
            setups = 0
        x = lu.solve(b)
        if not np.all(np.isfinite(x)):
            raise SingularMatrix("the direct solve produced non-finite values: the matrix is singular.")
        return LinearSolve(x, "direct", 0, _relative_residual(A, x, b), time.perf_counter() - t0,
                           setups=setups)


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

    def hierarchy(self, A: sp.spmatrix, near_null: np.ndarray | None = None) -> MultilevelSolver:
        """The smoothed-aggregation hierarchy of ``A`` (a pyamg ``MultilevelSolver``).

        ``A`` is copied first: pyamg may edit the structure of the matrix it is given.
        """
        try:
            import pyamg
        except ImportError:  # pragma: no cover - depends on the environment
            raise InvalidParameter(
                "AMGSolver needs pyamg: pip install 'fem_elastic[fast]' (or pip install pyamg), "
                "or pass linear_solver=fe.DirectSolver()."
            ) from None
        A = sp.csr_matrix(A, copy=True)
        B = None if near_null is None else np.ascontiguousarray(near_null, dtype=float)
        # The prolongation smoother's Jacobi weight needs a bound on the spectral
        # radius of D^-1 A. pyamg's default ("diagonal") and "block" weightings
        # estimate it by Lanczos from a random vector: on the benchmark beam the
        # same system then took 30 CG iterations one time and failed to converge
        # in 500 another, and "block" diverged on a thin P2 beam. "local" uses a
        # Gershgorin bound instead: deterministic, never too small, and it
        # converged on every system tried (45 iterations where the others took 30).
        return pyamg.smoothed_aggregation_solver(
            A,
            B=B,
            symmetry="hermitian",
            smooth=("jacobi", {"omega": 4.0 / 3.0, "weighting": "local"}),
            coarse_solver="splu",
            max_coarse=500,
        )

    def solve(self, A: sp.spmatrix, b: np.ndarray, near_null: np.ndarray | None = None,
              rtol: float | None = None) -> LinearSolve:
        """Solve A x = b by AMG-preconditioned CG to ``rtol`` (default: the solver's own)."""
        rtol = self.rtol if rtol is None else max(float(rtol), self.rtol)
        t0 = time.perf_counter()
        A = sp.csr_matrix(A)
        M = self.hierarchy(A, near_null).aspreconditioner(cycle="V")
        x, its, ok, _ = preconditioned_cg(A, b, M, rtol, self.maxiter)
        rel = _relative_residual(A, x, b) if np.all(np.isfinite(x)) else np.inf
        if not ok:
            raise LinearSolverFailed(
                f"AMG-CG reached a relative residual of {rel:.2e} after {its} iterations "
                f"(asked {rtol:.1e}): the matrix may be indefinite or badly conditioned. "
                "Use linear_solver=fe.DirectSolver(), or raise maxiter.",
                result=LinearSolve(x, "amg-cg", its, rel, time.perf_counter() - t0, setups=1),
            )
        return LinearSolve(x, "amg-cg", its, rel, time.perf_counter() - t0, setups=1)

    def reusing(self, fallback: bool = False) -> "ReusedAMG":
        """A :class:`ReusedAMG` that keeps one hierarchy across the solves of a Newton solve."""
        return ReusedAMG(self, fallback=fallback)


def preconditioned_cg(A, b, M, rtol, maxiter, x0=None):
    """Preconditioned conjugate gradients for ``A x = b``, watching the curvature.

    Stops when the residual satisfies ``||r|| <= rtol ||b||`` (the 2-norm, not
    the preconditioned one; ``r`` is CG's updated residual, ``b - A x`` up to
    round-off), after ``maxiter`` iterations, or at
    the first search direction with ``p . A p <= 0`` (reported as not
    converged, with ``negative_curvature``): ``A`` is then not positive
    definite (an exact tangent under compression), and the iterate so far,
    which every earlier step moved down the quadratic model ``x . A x / 2 -
    b . x`` (from ``x0 = 0`` it satisfies ``b . x > 0``), is returned as it is
    (Steihaug 1983; Nocedal and Wright, Algorithm 7.1). The caller decides
    what that means: :class:`ReusedAMG` hands the iterate to Newton on an
    exact tangent, and treats it as a failure on a positive definite one.

    Parameters
    ----------
    A : sparse matrix or LinearOperator
    b : numpy.ndarray
    M : LinearOperator
        Symmetric positive definite preconditioner (an AMG V-cycle).
    rtol : float
        Relative residual to reach.
    maxiter : int
        Most iterations.
    x0 : numpy.ndarray, optional
        Start (a warm start from an earlier, interrupted solve); default 0.

    Returns
    -------
    x : numpy.ndarray
    iterations : int
    converged : bool
    negative_curvature : bool
    """
    b = np.asarray(b, dtype=float)
    nb = float(np.linalg.norm(b))
    x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=float)
    if nb == 0.0:
        return np.zeros_like(b), 0, True, False
    r = b - A @ x if x0 is not None else b.copy()
    target = rtol * nb
    if float(np.linalg.norm(r)) <= target:
        return x, 0, True, False
    z = M @ r
    p = z.copy()
    rz = float(r @ z)
    for k in range(maxiter):
        Ap = A @ p
        pAp = float(p @ Ap)
        if not pAp > 0.0:
            return x, k, False, True
        a = rz / pAp
        x += a * p
        r -= a * Ap
        if float(np.linalg.norm(r)) <= target:
            return x, k + 1, True, False
        z = M @ r
        rz_new = float(r @ z)
        p *= rz_new / rz
        p += z
        rz = rz_new
    return x, maxiter, False, False


class ReusedAMG:
    """AMG-preconditioned CG that keeps one hierarchy across the solves of a Newton solve.

    The tangent of an implicit step changes little between its Newton
    iterations, so the smoothed-aggregation hierarchy (rigid-body near-null
    space) of the first solve stays a good preconditioner for the later
    ones: only its setup, not its quality, is saved. It is rebuilt, from the
    matrix of the solve at hand, when CG on the kept hierarchy needs more
    than ``rebuild_factor`` times the iterations the solve right after the
    last setup would have taken for the same tolerance (its residual
    reduction per iteration, measured then, extrapolated to the tolerance of
    this solve: Newton's forcing term tightens from 1e-2 to 1e-8 over a
    step, so a bare count would call every tight solve slow; at least
    ``min_rebuild_iterations``; 1.5 and 10: a looser rule let a large-deflection
    solve from rest keep the hierarchy of the undeformed beam and lose the
    saving of the inexact forcing term), or fails: CG then
    goes on from its last iterate with the new hierarchy (a warm start, so
    no iteration is thrown away). A hierarchy is only ever built from a
    positive (semi-)definite matrix (``psd=True``): on an exact, possibly
    indefinite tangent CG stops at the first negative curvature or at that
    limit and says so, and Newton answers by projecting.

    Parameters
    ----------
    amg : AMGSolver
        Tolerance, iteration limit and hierarchy settings.
    fallback : bool
        Solve a positive definite system directly (SuperLU) when CG fails even
        on a fresh hierarchy (as :class:`AutoSolver` does); False raises
        :class:`LinearSolverFailed`.
    rebuild_factor, min_rebuild_iterations : float, int
        The rebuild rule above.

    Attributes
    ----------
    setups : int
        Hierarchies built so far.
    """

    def __init__(self, amg: AMGSolver | None = None, fallback: bool = False,
                 rebuild_factor: float = 1.5, min_rebuild_iterations: int = 10):
        self.amg = amg if amg is not None else AMGSolver()
        self.fallback = bool(fallback)
        self.rebuild_factor = float(rebuild_factor)
        self.min_rebuild_iterations = int(min_rebuild_iterations)
        self.preconditioner = None
        self.rate = None  # log10 of the residual reduction per CG iteration on a fresh hierarchy
        self.setups = 0

    def _measure(self, A, b, x, its, x0_used=False):
        """Record the residual reduction per iteration of a solve on a fresh hierarchy."""
        if its > 0 and not x0_used:
            rel = max(_relative_residual(A, x, b), 1e-16)
            self.rate = min(np.log10(rel) / its, -1e-3)  # < 0: keeps the extrapolation finite

    def _setup(self, A, near_null):
        self.preconditioner = self.amg.hierarchy(A, near_null).aspreconditioner(cycle="V")
        self.setups += 1

    def solve(self, A, b, near_null=None, rtol=None, psd=True, x0=None) -> LinearSolve:
        """Solve ``A x = b`` by CG on the kept hierarchy (built here if there is none).

        Parameters
        ----------
        psd : bool
            ``A`` is positive semi-definite (a projected tangent). False (an
            exact tangent): CG stops at the first negative curvature, or when
            it would need a rebuild, and returns its iterate with
            ``negative_curvature`` set instead of raising.
        x0 : numpy.ndarray, optional
            Warm start.
        """
        rtol = self.amg.rtol if rtol is None else max(float(rtol), self.amg.rtol)
        t0 = time.perf_counter()
        A = sp.csr_matrix(A)
        setups0 = self.setups
        if self.preconditioner is None:
            self._setup(A, near_null)
        fresh = self.setups > setups0
        if fresh or self.rate is None or not psd:
            # an exact tangent near a bifurcation is nearly singular: CG on it needs many more
            # iterations than on the projection, and cutting it short would give up the
            # exact Newton step (linear convergence; a thin P2 beam in compression then
            # stalled its load steps); it stops at negative curvature instead
            limit = self.amg.maxiter
        else:
            expected = np.log10(rtol) / self.rate  # iterations a fresh hierarchy would take
            limit = min(self.amg.maxiter, max(self.min_rebuild_iterations,
                                              int(np.ceil(self.rebuild_factor * expected))))
        x, its, ok, _ = preconditioned_cg(A, b, self.preconditioner, rtol, limit, x0=x0)
        total = its
        if fresh and ok:
            self._measure(A, b, x, its)
        if not ok and not psd:  # an indefinite (or hard) exact tangent: Newton projects
            rel = _relative_residual(A, x, b)
            return LinearSolve(x, "amg-cg", total, rel, time.perf_counter() - t0,
                               setups=self.setups - setups0, negative_curvature=True)
        if not ok and not fresh:  # the kept hierarchy no longer fits: rebuild, go on from x
            log.debug("AMG-CG needed more than %d iterations on the kept hierarchy; rebuilding", limit)
            self._setup(A, near_null)
            x, its, ok, _ = preconditioned_cg(A, b, self.preconditioner, rtol, self.amg.maxiter,
                                              x0=x if np.all(np.isfinite(x)) else None)
            total += its
            if ok:
                self._measure(A, b, x, its, x0_used=True)
        rel = _relative_residual(A, x, b) if np.all(np.isfinite(x)) else np.inf
        setups = self.setups - setups0
        if not ok:
            self.preconditioner = None  # it failed on this matrix: build anew next time
            msg = (f"AMG-CG reached a relative residual of {rel:.2e} after {total} iterations "
                   f"(asked {rtol:.1e}): the matrix may be indefinite or badly conditioned.")
            if self.fallback:
                log.warning("%s Falling back to the direct solver.", msg)
                d = DirectSolver().solve(A, b, near_null)
                return replace(d, iterations=total, seconds=time.perf_counter() - t0,
                               setups=setups + d.setups)
            raise LinearSolverFailed(
                msg + " Use linear_solver=fe.DirectSolver(), or raise maxiter.",
                result=LinearSolve(x, "amg-cg", total, rel, time.perf_counter() - t0, setups=setups),
            )
        return LinearSolve(x, "amg-cg", total, rel, time.perf_counter() - t0, setups=setups)


@dataclass(frozen=True)
class AutoSolver:
    """The fastest solver that fits: CHOLMOD where its factor fits in memory, else SuperLU
    for small systems and AMG-CG for large ones.

    The rule, measured (``scripts/bench_linear_solvers.py``, linear static solves on this
    project's 2-core machine, medians of 5, each solver from nothing):

    1. **CHOLMOD** (scikit-sparse, the ``cholmod`` extra) whenever it is installed and
       the estimated factor, ``12 * 0.4 * nnz(A) * n^(1/3)`` bytes
       (:func:`~fem_elastic.solvers.cholmod.fill_bytes`: the ``n^(4/3)`` fill of nested
       dissection in 3-D, the coefficient above the 0.12-0.31 measured; a value and a row
       index per entry of L), fits in ``max_factor_bytes`` (default: half the free
       memory, :func:`fem_elastic.resources.available_memory`). Measured, each solver
       from nothing, time against SuperLU's in the same process:

       ========================================  =======  =========  =====================
       linear static solve                       SuperLU  CHOLMOD    AMG-CG (rtol 1e-8)
       ========================================  =======  =========  =====================
       Cook slab, P2, nu = 0.4999, 21,609 DOFs   1        0.44-0.53  fails (500 its: 42x)
       beam, P1, 22,143 DOFs                     1        0.29-0.52  0.67-0.70
       beam, P1, 87,567 DOFs (153,600 tets)      1        0.11       0.16
       ========================================  =======  =========  =====================

       (medians of 5 in each of two runs, of 3 in one run for the 87,567-DOF beam, on a
       2-core machine under load; CHOLMOD with Debian's OpenBLAS). CHOLMOD was the
       fastest on every system, 1.4-2.3x AMG-CG on the beams, and its factor of the
       87,567-DOF beam took 577 MiB; so it is taken wherever its factor fits, and AMG-CG
       (whose memory is about three copies of the matrix) only where it does not.
       A matrix that is not positive definite (an exact tangent under compression) is
       solved by SuperLU (with a warning; from :meth:`strict`, Newton on an exact
       tangent, without one, and above ``max_direct_dofs`` it raises
       :class:`LinearSolverFailed` instead, so Newton projects the tangent, as after a
       failed AMG-CG).
       The analysis and factor are kept between calls (one process-wide
       :class:`~fem_elastic.solvers.cholmod.CholmodSolver`): a new matrix of the same
       pattern is only refactorised, the same matrix only back-substituted.
    2. Otherwise (no scikit-sparse, or a factor too large): SuperLU up to
       ``max_direct_dofs``, AMG-CG above (with pyamg). If AMG-CG misses its tolerance (it
       can stall on badly conditioned systems, e.g. thin or nearly incompressible plates),
       the system is solved directly instead, with a warning in the log: a wrong direction
       would cost Newton far more.

    Parameters
    ----------
    max_direct_dofs : int
        Largest system SuperLU solves when CHOLMOD is not used. Sparse LU's fill grows
        fast in 3-D; on the project's machines AMG-CG overtakes it near 20k DOFs. Without
        pyamg installed, every system is solved directly.
    amg : AMGSolver
        The iterative solver used above the threshold.
    fallback : bool
        Solve directly when AMG-CG fails, or by SuperLU when CHOLMOD finds the matrix not
        positive definite (default); False raises :class:`LinearSolverFailed`.
    max_factor_bytes : float, optional
        Largest estimated CHOLMOD factor (bytes); 0 never uses CHOLMOD. Default: half the
        free memory (2 GiB where it cannot be read).
    max_exact_lu_dofs : int, optional
        Without ``fallback`` (:meth:`strict`, Newton on an exact tangent): the largest
        system that CHOLMOD proves not positive definite which SuperLU still solves
        (default ``max_direct_dofs``); above it :class:`LinearSolverFailed` is raised and
        Newton projects the tangent. Newton under IPC contact lowers it
        (:data:`fem_elastic.solvers.newton.CONTACT_EXACT_LU_DOFS`).
    """

    max_direct_dofs: int = 20_000
    amg: AMGSolver = AMGSolver()
    fallback: bool = True
    max_factor_bytes: float | None = None
    max_exact_lu_dofs: int | None = None

    def uses_cholmod(self, ndofs: int, nnz: int) -> bool:
        """Whether the rule picks CHOLMOD for a matrix of ``ndofs`` rows and ``nnz`` entries."""
        from . import cholmod

        budget = self.max_factor_bytes
        if budget is None:
            from ..resources import available_memory

            free = available_memory()
            budget = 2.0 * 2**30 if free is None else 0.5 * free
        if budget <= 0 or not cholmod.have_cholmod():
            return False
        return cholmod.fill_bytes(ndofs, nnz) <= budget

    def solve(self, A: sp.spmatrix, b: np.ndarray, near_null: np.ndarray | None = None,
              rtol: float | None = None) -> LinearSolve:
        """CHOLMOD if it fits, else direct below ``max_direct_dofs`` and AMG-CG (to ``rtol``) above."""
        if self.uses_cholmod(A.shape[0], A.nnz):
            from .cholmod import shared_solver

            try:
                return shared_solver().strict().solve(A, b)
            except LinearSolverFailed as exc:  # not positive definite
                lu_limit = self.max_direct_dofs if self.max_exact_lu_dofs is None \
                    else min(self.max_direct_dofs, self.max_exact_lu_dofs)
                if not self.fallback and A.shape[0] > lu_limit:
                    raise  # Newton on an exact tangent too large for LU: it projects (as after AMG-CG)
                # what the rule without CHOLMOD does at this size: SuperLU, whose direction
                # Newton then tests for descent (an exact tangent near a saddle still gives one)
                (log.warning if self.fallback else log.debug)("%s Solving it by SuperLU instead.", exc)
                return DirectSolver().solve(A, b, near_null)
        if A.shape[0] > self.max_direct_dofs and _have_pyamg():
            try:
                return self.amg.solve(A, b, near_null, rtol=rtol)
            except LinearSolverFailed as exc:
                if not self.fallback:
                    raise
                log.warning("%s Falling back to the direct solver.", exc)
        return DirectSolver().solve(A, b, near_null)

    def strict(self, max_lu_dofs: int | None = None) -> "AutoSolver":
        """The same solver, raising :class:`LinearSolverFailed` instead of falling back.

        Newton uses it on an exact (possibly indefinite) tangent, where the
        better remedy for a stalled CG, or a Cholesky that finds the tangent
        indefinite, is the PSD projection, not a large LU. ``max_lu_dofs``:
        the largest such tangent still solved by SuperLU (``max_exact_lu_dofs``,
        if this solver's own is not lower).
        """
        if max_lu_dofs is None:
            return replace(self, fallback=False)
        if self.max_exact_lu_dofs is not None:  # a user's own limit stays when it is lower
            max_lu_dofs = min(self.max_exact_lu_dofs, max_lu_dofs)
        return replace(self, fallback=False, max_exact_lu_dofs=max_lu_dofs)

    def reusing(self, ndofs: int, nnz: int | None = None) -> ReusedAMG | AutoSolver:
        """The solver a Newton solve of ``ndofs`` unknowns should use for all its solves.

        This solver itself where the rule picks CHOLMOD (``nnz``: the matrix's
        entries; default 81 per row, P2's most) or SuperLU (both keep their
        factor); above ``max_direct_dofs`` (with pyamg) a :class:`ReusedAMG` that
        keeps one hierarchy across the solves and falls back to the direct
        solver as :meth:`solve` does.
        """
        if self.uses_cholmod(ndofs, 81 * ndofs if nnz is None else nnz):
            return self
        if ndofs > self.max_direct_dofs and _have_pyamg():
            return self.amg.reusing(fallback=self.fallback)
        return self


def _have_pyamg() -> bool:
    try:
        import pyamg  # noqa: F401
    except ImportError:
        log.info("pyamg is not installed: solving directly (pip install 'fem_elastic[fast]')")
        return False
    return True


#: the linear solvers by name (``linear_solver="..."`` in Python and in scene files)
LINEAR_SOLVER_NAMES = ("auto", "direct", "amg", "cholmod", "petsc")


def as_linear_solver(spec=None):
    """The solver object ``spec`` stands for: None is ``AutoSolver()``, a name from
    :data:`LINEAR_SOLVER_NAMES` its solver, an object with ``solve`` itself.

    Raises
    ------
    InvalidParameter
        An unknown name or an object without ``solve``.
    MissingDependency
        ``"cholmod"`` without scikit-sparse installed.
    """
    if spec is None:
        return AutoSolver()
    if isinstance(spec, str):
        if spec == "cholmod":
            from .cholmod import CholmodSolver

            return CholmodSolver()
        if spec == "petsc":
            from .petsc_solver import PETScSolver

            return PETScSolver()
        named = {"auto": AutoSolver, "direct": DirectSolver, "amg": AMGSolver}.get(spec)
        if named is None:
            raise InvalidParameter(
                f"unknown linear solver {spec!r}: use one of {', '.join(LINEAR_SOLVER_NAMES)}, "
                "or a solver object such as fe.DirectSolver()."
            )
        return named()
    if not callable(getattr(spec, "solve", None)):
        raise InvalidParameter(
            f"linear_solver must be a name ({', '.join(LINEAR_SOLVER_NAMES)}) or a solver object "
            f"with solve(A, b, near_null), got {spec!r}."
        )
    return spec
