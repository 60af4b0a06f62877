"""Sparse Cholesky (CHOLMOD, SuiteSparse) for symmetric positive definite systems.

The stiffness of a supported body, a projected tangent, the projective-dynamics
matrix ``M / h^2 + w L`` and the shift-invert matrix ``K - sigma M`` of a
modal solve are symmetric positive definite: a Cholesky factor ``L L^T`` needs
no pivoting, half the memory of an LU and, with CHOLMOD's supernodal kernels
(dense BLAS on the supernodes), a fraction of SuperLU's time.

:class:`CholmodSolver` splits the factorisation in two and keeps both:

- the **symbolic analysis** (fill-reducing ordering, elimination tree,
  supernodes) depends only on the sparsity pattern; it is done once per
  pattern (``analyses`` counts them);
- the **numeric factorisation** (``Factor.cholesky_inplace``) is redone only
  when the values change (``factorizations`` counts them): a Newton solve or
  a nonlinear load path refactorises on the kept analysis;
- a solve whose matrix equals the last one (compared entry by entry, so a
  reused factor is always the factor of the matrix given: linear statics over
  load steps, a linear body stepped at a fixed dt, several right-hand sides)
  only back-substitutes.

A matrix that is not positive definite (an exact tangent under compression, a
body left free) makes CHOLMOD stop with ``CholmodNotPositiveDefiniteError``:
the system is then solved by SuperLU with a logged warning (``fallbacks``
counts them), never by a wrong factor; :meth:`CholmodSolver.strict` raises
:class:`~fem_elastic.solvers.linear_solvers.LinearSolverFailed` instead, which
Newton answers by projecting the tangent (no LU is spent on an indefinite
matrix it would discard).

scikit-sparse is an optional dependency (``pip install -e ".[cholmod]"``); it
is built from source against SuiteSparse's headers (Debian/Ubuntu:
``apt-get install libsuitesparse-dev`` first). It is imported here only, on
first use.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..errors import MissingDependency
from .linear_solvers import (_CACHE_MAX_DOFS, _FACTORS, LinearSolve, LinearSolverFailed, SingularMatrix,
                             _relative_residual, superlu)

__all__ = ["CholmodSolver", "have_cholmod", "fill_bytes", "shared_solver", "spd_factor",
           "shift_invert_operator", "pivoting_lu", "INSTALL_HINT"]

log = logging.getLogger(__name__)

INSTALL_HINT = (
    'pip install -e ".[cholmod]" (scikit-sparse, built from source against SuiteSparse: on '
    "Debian/Ubuntu run apt-get install libsuitesparse-dev first)"
)

#: Fill of the Cholesky factor, ``nnz(L) ~= FILL_COEFFICIENT * nnz(A) * n^(1/3)`` (the
#: ``n^(4/3)`` growth of a nested-dissection factor in 3-D; A the full symmetric matrix, n its
#: order). Measured with CHOLMOD's supernodal factor by ``scripts/bench_linear_solvers.py
#: --fill``: 0.12-0.14 on P2 Cook slabs (5.6k-22k DOFs), 0.22 and 0.31 on P1 beams (3.3k and
#: 88k DOFs, 577 MiB); the coefficient grows slowly with n on the beam, so 0.4 keeps the
#: estimate above every measured one.
FILL_COEFFICIENT = 0.4


def _sksparse_cholmod():
    """The ``sksparse.cholmod`` module, or :class:`fe.MissingDependency` saying what to install."""
    try:
        from sksparse import cholmod
    except ImportError:
        raise MissingDependency(
            f"the CHOLMOD solver needs scikit-sparse: {INSTALL_HINT}; or use "
            'linear_solver="direct" (SuperLU) or "auto".'
        ) from None
    return cholmod


def have_cholmod() -> bool:
    """Whether scikit-sparse (CHOLMOD) is importable."""
    try:
        _sksparse_cholmod()
    except MissingDependency:
        return False
    return True


def fill_bytes(n: int, nnz: int) -> float:
    """Estimated memory of the Cholesky factor of an ``(n, n)`` matrix with ``nnz`` entries (bytes).

    ``12 * nnz(L)`` (a float64 value and an int32 row index per entry) with
    ``nnz(L) = FILL_COEFFICIENT * nnz * n^(1/3)``, the growth of a
    nested-dissection factor of a 3-D mesh; see :data:`FILL_COEFFICIENT`.
    Cheap (no analysis): :class:`~fem_elastic.solvers.linear_solvers.AutoSolver`
    decides with it before any factorisation.
    """
    return 12.0 * FILL_COEFFICIENT * float(nnz) * max(int(n), 1) ** (1.0 / 3.0)


def pivoting_lu(A):
    """SuperLU with threshold partial pivoting, for a matrix CHOLMOD found not positive definite.

    :func:`~fem_elastic.solvers.linear_solvers.superlu` takes the diagonal pivots
    as they come (right for a positive definite matrix); on an indefinite one that
    is unstable (a relative residual of 2e-2 measured on a shifted beam stiffness),
    so here a pivot is taken off the diagonal when it is below 0.1 of its column's
    largest entry. Raises :class:`fe.SingularMatrix` if ``A`` is singular.
    """
    return superlu(A, diag_pivot_thresh=0.1, what="the matrix")


def _as_csc(A):
    """A symmetric matrix as CSC without copying (a CSR matrix's transpose is itself)."""
    if sp.isspmatrix_csr(A) or isinstance(A, sp.csr_array):
        return sp.csc_matrix((A.data, A.indices, A.indptr), shape=A.shape)
    return sp.csc_matrix(A)


class CholmodSolver:
    """Sparse Cholesky by CHOLMOD (scikit-sparse), analysis and factor kept for reuse.

    ``solve(A, b, near_null=None, rtol=None)`` as the other linear solvers:
    ``A`` symmetric positive definite (only its lower triangle is read), ``b``
    one right-hand side ``(n,)`` or several ``(n, k)``.

    Parameters
    ----------
    fallback : bool
        Solve a matrix that is not positive definite by SuperLU (with a
        warning in the log, default); False raises :class:`fe.LinearSolverFailed`.

    Attributes
    ----------
    analyses : int
        Symbolic analyses done (one per sparsity pattern met in turn).
    factorizations : int
        Numeric factorisations (CHOLMOD's; SuperLU fallbacks are in ``fallbacks``).
    solves : int
        Calls of :meth:`solve`.
    fallbacks : int
        Matrices found not positive definite and solved by SuperLU.

    Raises
    ------
    MissingDependency
        At construction, if scikit-sparse is not installed.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> A = sp.csr_matrix(np.array([[4.0, 1.0], [1.0, 3.0]]))
    >>> s = CholmodSolver()  # doctest: +SKIP
    >>> s.solve(A, np.array([1.0, 2.0])).x  # doctest: +SKIP
    array([0.09090909, 0.63636364])
    """

    def __init__(self, fallback: bool = True) -> None:
        self._cholmod = _sksparse_cholmod()
        self.fallback = bool(fallback)
        self.analyses = 0
        self.factorizations = 0
        self.solves = 0
        self.fallbacks = 0
        self._pattern: tuple | None = None  # (shape, indptr, indices) of the analysed matrix
        self._values: np.ndarray | None = None  # data of the matrix the current factor is of
        # CHOLMOD Factor: the analysis, and the numeric factor when _kind == "cholmod"
        self._factor: Any = None
        self._kind: str | None = None  # "cholmod" or "superlu": what `_solver` is
        self._solver: Any = None  # callable b -> x of the current factor
        self._shared = False  # a thread's solver of fe.AutoSolver (kept whatever its size)
        self._publish = True  # offer the last factor to solve_static's stability check

    def __repr__(self):
        return (f"CholmodSolver(fallback={self.fallback}; analyses={self.analyses}, "
                f"factorizations={self.factorizations}, solves={self.solves}, "
                f"fallbacks={self.fallbacks})")

    # -- the factor ------------------------------------------------------------------------
    def _same_pattern(self, A) -> bool:
        p = self._pattern
        return (p is not None and p[0] == A.shape and np.array_equal(p[1], A.indptr)
                and np.array_equal(p[2], A.indices))

    def _same_values(self, A) -> bool:
        return self._values is not None and np.array_equal(self._values, A.data)

    def factorize(self, A: sp.spmatrix,
                  fallback: bool | None = None) -> tuple[Callable[[np.ndarray], np.ndarray], int]:
        """Factor ``A`` (or keep the factor if ``A`` is the matrix it is of).

        Returns
        -------
        solve : callable
            ``b -> x`` by the factor.
        setups : int
            Analyses plus factorisations this call did (0: the factor was reused).
        """
        fallback = self.fallback if fallback is None else fallback
        C = _as_csc(A)
        setups = 0
        same_pattern = self._same_pattern(C)  # each O(nnz) comparison once per call
        same_values = same_pattern and self._same_values(C)
        if not same_values:
            self._unpublish()  # the factor is about to change (or be replaced): nobody may use it
        if not same_pattern:
            # CHOLMOD's own choice of supernodal (LL') or simplicial (LDL', where the flops per
            # entry of L stay below 40: small or banded matrices; a 1,485-DOF P2 beam analyses and
            # factors in 2.3 against 3.4 ms)
            self._factor = self._cholmod.analyze(C, mode="auto")
            self._pattern = (C.shape, C.indptr.copy(), C.indices.copy())
            self._values = self._kind = self._solver = None
            self.analyses += 1
            setups += 1
        elif same_values and (self._kind == "cholmod" or fallback):
            return self._solver, 0
        try:
            self._factor.cholesky_inplace(C)
            # LL' fails on a matrix that is not positive definite (Newton's test of an exact
            # tangent); simplicial LDL' does not: its D then has a pivot <= 0, which says the same
            # (D() reads the factor's diagonal in place; for LL' it is diag(L)^2 > 0)
            if not np.all(self._factor.D() > 0.0):
                raise self._cholmod.CholmodNotPositiveDefiniteError(
                    "a pivot of the LDL' factorisation is not positive")
        except self._cholmod.CholmodNotPositiveDefiniteError as exc:
            self.factorizations += 1
            self._values = self._kind = self._solver = None
            if not fallback:
                raise LinearSolverFailed(
                    f"CHOLMOD: the matrix is not positive definite ({exc}): an exact tangent "
                    "under compression, or a body whose supports leave a motion free.",
                    result=None,
                ) from None
            log.warning("CHOLMOD: the matrix is not positive definite (%s); solving it by "
                        "SuperLU (sparse LU) instead", exc)
            self.fallbacks += 1
            lu = pivoting_lu(A)
            self._values, self._kind, self._solver = C.data.copy(), "superlu", lu.solve
            return self._solver, setups + 1
        self.factorizations += 1
        self._values, self._kind, self._solver = C.data.copy(), "cholmod", self._factor
        if self._publish and (self._shared or C.shape[0] <= _CACHE_MAX_DOFS):
            # the last factor made: solve_static's stability check preconditions LOBPCG with it
            # (withdrawn by _unpublish before this factor is refactorised in place)
            _FACTORS.put_elsewhere_kept(C.shape, _FactorSolve(self._factor))
        return self._solver, setups + 1

    def _unpublish(self) -> None:
        if self._factor is not None and isinstance(_FACTORS.lu, _FactorSolve) and _FACTORS.lu.factor is self._factor:
            _FACTORS.key = _FACTORS.lu = None

    def release(self) -> None:
        """Drop the kept analysis and factor (their memory); the next solve analyses anew."""
        self._unpublish()
        self._pattern = self._values = self._factor = self._kind = self._solver = None

    # -- the solver interface --------------------------------------------------------------
    def solve(self, A: sp.spmatrix, b: np.ndarray, near_null: np.ndarray | None = None,
              rtol: float | None = None) -> LinearSolve:
        """Solve ``A x = b`` (``near_null`` and ``rtol`` are accepted for a common interface)."""
        return self._solve(A, b, self.fallback)

    def _solve(self, A, b, fallback) -> LinearSolve:
        t0 = time.perf_counter()
        if not sp.issparse(A):
            A = sp.csr_matrix(A)
        self.solves += 1
        solve, setups = self.factorize(A, fallback)
        b = np.asarray(b, dtype=float)
        x = np.asarray(solve(b), dtype=float).reshape(b.shape)
        if not np.all(np.isfinite(x)):
            raise SingularMatrix("the Cholesky solve produced non-finite values: the matrix is singular.")
        method = "cholmod" if self._kind == "cholmod" else "direct"
        # (n, k) right-hand sides: the Frobenius norms, relative
        return LinearSolve(x, method, 0, _relative_residual(A, x, b), time.perf_counter() - t0,
                           setups=setups)

    def strict(self) -> "_StrictCholmod":
        """This solver (same factor and counters), raising :class:`fe.LinearSolverFailed` on a
        matrix that is not positive definite instead of falling back to SuperLU.

        Newton uses it on an exact tangent: Cholesky's failure is its proof of
        indefiniteness, and the answer is the projected tangent.
        """
        return _StrictCholmod(self)

    def reusing(self, ndofs: int | None = None) -> "CholmodSolver":
        """The solver a Newton solve should use for all its solves: this one (its analysis is kept)."""
        return self


class _StrictCholmod:
    """A :class:`CholmodSolver` seen without its SuperLU fallback (shares its factor)."""

    def __init__(self, parent: CholmodSolver):
        self.parent = parent

    def solve(self, A, b, near_null=None, rtol=None) -> LinearSolve:
        return self.parent._solve(A, b, False)


class _FactorSolve:
    """``solve(b)`` by a CHOLMOD factor (SuperLU's factors have the same method)."""

    __slots__ = ("factor",)

    def __init__(self, factor: Callable[[np.ndarray], np.ndarray]) -> None:
        self.factor = factor

    def solve(self, b):
        return self.factor(b)


def spd_factor(A, what: str = "the matrix"):
    """A factor of the symmetric positive definite ``A`` with ``solve(b)``, made once for many solves.

    CHOLMOD's Cholesky factor where scikit-sparse is installed; SuperLU's LU
    otherwise, or (with a logged warning) where CHOLMOD finds ``A`` not
    positive definite. Used where one matrix serves many right-hand sides:
    projective dynamics' global step.

    Parameters
    ----------
    A : sparse matrix
        Symmetric ``(n, n)``.
    what : str
        What ``A`` is, for the warning.
    """
    if have_cholmod():
        solver = CholmodSolver(fallback=False)
        solver._publish = False  # a one-off factor of its own matrix, not a Newton solve's
        try:
            solve, _ = solver.factorize(A)
            return _FactorSolve(solve)
        except LinearSolverFailed as exc:
            log.warning("%s: %s Factorising it by SuperLU instead.", what, exc)
            return pivoting_lu(A)
    return superlu(A)


def shift_invert_operator(A):
    """``x -> A^-1 x`` by CHOLMOD as a ``LinearOperator``, for ARPACK's shift-invert mode.

    ``A = K - sigma M``, factorised once and applied at every Lanczos
    iteration. None where scikit-sparse is missing or ``A`` is not positive
    definite (warned): ARPACK then factorises ``A`` itself (SuperLU), as without
    CHOLMOD.
    """
    if not have_cholmod():
        return None
    import scipy.sparse.linalg as spla

    solver = CholmodSolver(fallback=False)
    solver._publish = False  # K - sigma M is no stiffness for the stability check
    try:
        solve, _ = solver.factorize(sp.csr_matrix(A))
    except LinearSolverFailed as exc:
        log.warning("shift-invert: %s ARPACK factorises it by SuperLU instead.", exc)
        return None

    def apply(b):
        return solve(np.asarray(b, dtype=float))

    return spla.LinearOperator(A.shape, matvec=apply, matmat=apply, dtype=float)


_LOCAL = threading.local()


def shared_solver() -> CholmodSolver:
    """This thread's :class:`CholmodSolver` of ``fe.AutoSolver`` (one analysis and factor kept).

    Kept across Newton solves, load steps and time steps, so a linear body's
    matrix is factorised once and a nonlinear one's pattern analysed once;
    ``shared_solver().release()`` frees the factor's memory. One per thread: a
    factor is refactorised in place, so threads sharing one would solve
    through each other's matrices (a thread pool running studies).
    """
    solver = getattr(_LOCAL, "solver", None)
    if solver is None:
        solver = _LOCAL.solver = CholmodSolver()
        solver._shared = True
    return solver
