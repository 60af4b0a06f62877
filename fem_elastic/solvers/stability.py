"""Stability of a static equilibrium: the lowest eigenvalue of the free-DOF tangent.

An equilibrium x* of the total potential energy Pi is stable when Pi has a
minimum there, i.e. when the exact tangent K = d^2 Pi / dx^2 restricted to
the free DOFs is positive definite. Newton's method finds any stationary
point: a column under an end load beyond its buckling load converges to the
straight state, a saddle. :func:`lowest_eigenpair` computes the lowest
eigenvalue of ``K_ff`` (N/m) and its eigenvector:

* up to :data:`DENSE_MAX` free DOFs, by a dense symmetric eigensolver;
* above, by LOBPCG (scipy) preconditioned by the inverse of a positive
  definite matrix near K_ff: the factorization the last Newton solve left
  in the direct solver's cache when there is one (no new factorization at
  all), else a sparse LU of the PSD-projected tangent (up to the direct
  solver's size), else smoothed-aggregation AMG on it (pyamg, with the
  rigid-body modes). A good preconditioner makes LOBPCG converge in a few
  tens of iterations, so the check costs a fraction of the solve.

The eigenvalue is of the standard problem ``K_ff phi = lambda phi`` (units
N/m; its sign is what tells stability). An equilibrium is called stable when
``lambda_min >= -tol * max |K_ii|`` (``tol`` 1e-10 by default: the
eigenvalue's round-off).

:class:`UnstableEquilibrium` is the warning ``fe.solve_static`` gives for a
converged but unstable equilibrium.
"""

from __future__ import annotations

import logging
import time
import warnings

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["UnstableEquilibrium", "EigenCheck", "lowest_eigenpair", "DENSE_MAX"]

log = logging.getLogger(__name__)

#: Largest free-DOF count solved by the dense eigensolver.
DENSE_MAX = 300
#: Relative tolerance (of max |K_ii|) below zero at which an equilibrium counts as unstable.
STABILITY_TOL = 1e-10


class UnstableEquilibrium(UserWarning):
    """``solve_static`` converged to an equilibrium whose tangent is not positive definite.

    The state is stationary but not a minimum of the energy (a saddle, e.g. a
    straight column beyond its buckling load): a perturbation lowers the
    energy. ``fe.solve_static(model, stabilize=True)`` perturbs it along the
    eigenvector of the lowest eigenvalue and converges to a stable state.
    """


class EigenCheck:
    """The result of a stability check: ``value`` (N/m), ``vector`` (``(ndofs,)``, unit norm,
    zero on held DOFs), ``stable``, ``method`` and ``seconds``."""

    __slots__ = ("value", "vector", "stable", "method", "seconds", "iterations")

    def __init__(self, value, vector, stable, method, seconds, iterations=0):
        self.value, self.vector, self.stable = float(value), vector, None if stable is None else bool(stable)
        self.method, self.seconds, self.iterations = method, float(seconds), int(iterations)

    def __repr__(self):
        return (f"EigenCheck(value={self.value:.6g}, stable={self.stable}, method={self.method!r}, "
                f"seconds={self.seconds:.3g})")


def _start_block(n: int, k: int) -> np.ndarray:
    """A fixed (seeded) random start block, so repeated checks give identical answers."""
    return np.random.default_rng(20261203).standard_normal((n, k))


def _cached_factor(ndofs: int, free: np.ndarray):
    """The direct solver's last LU if it is of a constrained ``(ndofs, ndofs)`` system."""
    from . import linear_solvers as ls

    cache = ls._FACTORS
    if cache.lu is None or cache.key is None or cache.key[0] != (ndofs, ndofs):
        return None
    return cache.lu


def _preconditioner(how, A, K_psd, idx, ndofs, near_null, factor, scale):
    """An approximate inverse of A for LOBPCG, and its name.

    ``"factor"``: the given LU of a constrained full-size system near K; ``"lu"``:
    a sparse LU of A itself; ``"amg"``: smoothed-aggregation AMG on A (at a stable
    equilibrium A is positive definite; at an unstable one a negative Rayleigh
    quotient is a certificate however well the preconditioner does);
    ``"amg-psd"``: AMG on the projected tangent.
    """
    n = A.shape[0]
    if how == "factor":
        def apply(R):
            R = np.asarray(R, dtype=float)
            R2 = R.reshape(n, -1)
            full = np.zeros((ndofs, R2.shape[1]))
            full[idx] = R2
            return factor.solve(full)[idx].reshape(R.shape)
        name = "lobpcg+lu(newton)"
    elif how == "lu":
        lu = spla.splu(sp.csc_matrix(A + 1e-12 * scale * sp.identity(n)), permc_spec="MMD_AT_PLUS_A",
                       diag_pivot_thresh=0.0, options={"SymmetricMode": True})

        def apply(R):
            return lu.solve(np.asarray(R, dtype=float))
        name = "lobpcg+lu"
    else:
        import pyamg  # noqa: F401  (without it: ImportError, not the solver's InvalidParameter)

        from .linear_solvers import AMGSolver

        P = A
        if how == "amg-psd":
            P = sp.csr_matrix(K_psd() if callable(K_psd) else K_psd)[idx][:, idx]
        # the Newton solves' hierarchy settings (rigid-body modes, Gershgorin-weighted smoother)
        ml = AMGSolver().hierarchy(P, None if near_null is None else near_null[idx])
        Mop = ml.aspreconditioner(cycle="V")

        def apply(R):
            R = np.asarray(R, dtype=float)
            if R.ndim == 1:
                return Mop @ R
            return np.column_stack([Mop @ R[:, j] for j in range(R.shape[1])])
        name = "lobpcg+amg" + ("(psd)" if how == "amg-psd" else "")
    return spla.LinearOperator((n, n), matvec=apply, matmat=apply, dtype=float), name


def _lobpcg(A, M, scale, rtol, maxiter):
    """Lowest eigenpair of A by LOBPCG with a block of two (a pair of nearly equal lowest
    eigenvalues, the two bending modes of a square section, is common)."""
    X0 = _start_block(A.shape[0], 2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # LOBPCG warns when it stops at maxiter
        w, v, hist = spla.lobpcg(A, X0, M=M, largest=False, tol=rtol * scale, maxiter=maxiter,
                                 retResidualNormsHistory=True)
    j = int(np.argmin(w))
    lam, phi = float(w[j]), v[:, j]
    # LOBPCG stopped at maxiter returns an upper bound of the lowest eigenvalue, which could
    # call a saddle stable: accept the pair only if its residual met the tolerance (x10 slack
    # for the norm of a block column against LOBPCG's own per-column test)
    residual = float(np.linalg.norm(A @ phi - lam * phi)) / max(float(np.linalg.norm(phi)), 1e-300)
    if not residual <= 10.0 * rtol * scale:
        raise ArithmeticError(f"LOBPCG did not converge in {maxiter} iterations (residual "
                              f"{residual:.3g}, tolerance {rtol * scale:.3g})")
    return lam, phi, len(hist)


def lowest_eigenpair(
    K: sp.spmatrix,
    free: np.ndarray,
    *,
    K_psd: sp.spmatrix | None = None,
    near_null: np.ndarray | None = None,
    factor=None,
    tol: float = STABILITY_TOL,
    max_direct_dofs: int = 20_000,
    maxiter: int = 200,
    lobpcg_tol: float = 1e-7,
) -> EigenCheck:
    """Lowest eigenvalue and eigenvector of the exact tangent on the free DOFs.

    Parameters
    ----------
    K : sparse matrix
        The exact tangent ``(ndofs, ndofs)`` (N/m) at the equilibrium.
    free : numpy.ndarray of bool
        ``(ndofs,)``, True for the unknowns.
    K_psd : sparse matrix or callable, optional
        A positive semi-definite matrix near K (the projected tangent), or a
        function returning it: AMG's fallback when AMG on K itself fails.
    near_null : numpy.ndarray, optional
        ``(ndofs, 6)`` rigid-body modes, for AMG.
    factor : object with ``solve(b)``, optional
        A factorization of a constrained ``(ndofs, ndofs)`` system near K
        (held rows and columns the identity), used as the preconditioner.
        Pass ``"cached"`` to use the direct solver's last factorization.
    tol : float
        Stability tolerance relative to ``max |K_ii|``.
    lobpcg_tol : float
        LOBPCG's residual tolerance relative to ``max |K_ii|`` (the
        eigenvalue's error is about the residual squared over the gap).

    Returns
    -------
    EigenCheck
    """
    t0 = time.perf_counter()
    free = np.asarray(free, dtype=bool)
    idx = np.flatnonzero(free)
    n = idx.size
    ndofs = free.size
    A = sp.csr_matrix(K)[idx][:, idx]
    scale = float(np.abs(A.diagonal()).max()) if n else 0.0
    if n == 0:
        return EigenCheck(np.inf, np.zeros(ndofs), True, "none", time.perf_counter() - t0)
    iterations = 0
    if n <= DENSE_MAX:
        w, v = sla.eigh(A.toarray(), subset_by_index=[0, 0])
        lam, phi, method = float(w[0]), v[:, 0], "dense"
    else:
        if isinstance(factor, str) and factor == "cached":
            factor = _cached_factor(ndofs, free)
        attempts = ["factor"] if factor is not None else []
        attempts += ["lu" if n <= max_direct_dofs else "amg"]
        if K_psd is not None and n > max_direct_dofs:
            attempts.append("amg-psd")
        for how in attempts:
            try:
                M, method = _preconditioner(how, A, K_psd, idx, ndofs, near_null, factor, scale)
                lam, phi, iterations = _lobpcg(A, M, scale, lobpcg_tol, maxiter)
            except (RuntimeError, ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
                log.info("stability check with %s failed (%s)", how, exc)
                continue
            if np.isfinite(lam):
                break
        else:
            w, v = sla.eigh(A.toarray(), subset_by_index=[0, 0]) if n <= 4 * DENSE_MAX else ([np.nan], None)
            lam, phi, method = float(w[0]), (v[:, 0] if v is not None else np.zeros(n)), "dense"
    vec = np.zeros(ndofs)
    vec[idx] = phi / (np.linalg.norm(phi) or 1.0)
    # None when no eigensolver converged: unknown, neither stable nor a saddle
    stable = None if not np.isfinite(lam) else bool(lam >= -tol * scale)
    return EigenCheck(lam, vec, stable, method, time.perf_counter() - t0, iterations)
