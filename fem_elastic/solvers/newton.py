"""Newton's method with backtracking line search, for energy minimisation.

One solver serves statics (minimise the total potential energy) and, in the
dynamics layer, implicit Euler (minimise the incremental potential). It sees
only an objective with ``energy(x)`` and ``linearize(x) -> (g, H)``, the set
of free DOFs, and a linear solver.

Each iteration solves ``H dx = -g`` on the free DOFs, with H the (projected,
so positive semi-definite) Hessian, then backtracks ``alpha = 1, 1/2, ...``
until the Armijo condition ``Pi(x + alpha dx) <= Pi(x) + c alpha g . dx``
holds. An energy of +inf (an inverted element of a barrier material) counts
as "too far" and is backtracked from like any other failure, so no NaN ever
enters the iterate.

The projected Hessian is only an approximation of the true one: under
compression the clamped eigenvalues (the rotational "twist" modes of every
element) are exactly the soft modes of a bending structure, and Newton with
the projected Hessian converges only linearly, sometimes slowly. So once a
projected step is accepted in full (the iterate is in the basin where the
quadratic model is good), the next iteration tries the exact Hessian; if
that direction is not a descent direction or needs backtracking, it goes
back to the projection. Near convergence the predicted decrease ``|g . dx|``
falls to the round-off of Pi itself, where energy comparisons carry no
information; the full Newton step is then taken (it is tiny, and Newton is
in its quadratic regime there).

Under IPC contact (``max_step`` and ``saddle_extension`` given) a full projected step taken
where the exact tangent proved indefinite is doubled, up to 64 times, while
the energy keeps falling and the CCD allows it: Newton stands near a saddle
there, and the projection leaves the descent direction only the inertia's
stiffness, so unextended steps leave the saddle by a small factor each
(13 iterations of a resting step of the 21,870-tet drop in
``scripts/bench_ipc.py``, 2 with the doubling).

Linear solves (issue 19). Above the direct solver's size (``AutoSolver``,
or an ``AMGSolver``) one smoothed-aggregation hierarchy, built at the first
solve of the call (one implicit step, or one load step), preconditions CG
for every later tangent of the call (:class:`ReusedAMG`; it is rebuilt when
CG on it needs more than 1.5 times the iterations a fresh hierarchy would take,
extrapolated from the solve right after the setup, or fails). Exact or projected is decided inside that CG, without a
solve of its own: the exact tangent's CG stops at its first search direction
``p`` with ``p . H p <= 0``. That curvature is the exact cheap indicator of
indefiniteness along the Krylov space the solve explores (a Lanczos-type
test; the sign of ``dx . H dx`` of a finished solve would cost the solve
first), and every CG iterate before it is a descent direction. Newton then
assembles the projected tangent and continues CG from that iterate (a warm
start; the iterations are kept, and counted). "Start projected when the
previous step needed it" was not chosen: it would give up Newton's quadratic
convergence on every step after one indefinite tangent, where the curvature
test costs nothing when the exact tangent is positive definite. A solver
that cannot stop at negative curvature (a direct one, a user's) keeps the
solve-then-test of the exact tangent; that solve is counted in
``linear_solves``.

The tolerance is relative to the problem's force scale: the larger of the
caller's ``g_scale`` (a load, an inertial force), the out-of-balance force of
the start and the force the held DOFs carry there (the reaction of the
supports and drives, ``||g(x0)||`` on the fixed DOFs). A body held crushed or
stretched carries forces of the size of its stresses even where its free
DOFs are in balance, and its round-off is of that size too: an absolute
floor there (a residual of 2e-10 N on a crushed Neo-Hookean cube that its
elements' forces of 1e4 N cannot resolve) would call a converged state a
failure.
"""

from __future__ import annotations

import inspect
import logging
import math
import time
import weakref
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp

from .linear_solvers import (AMGSolver, AutoSolver, LinearSolverFailed, ReusedAMG,
                             SingularMatrix, as_linear_solver)

__all__ = ["NewtonResult", "newton_minimize", "saddle_extension_safe"]


def _takes_rtol(solver) -> bool:
    """Whether ``solver.solve`` accepts an ``rtol`` keyword (ours do; a user's may not)."""
    method = solver.solve
    func = getattr(method, "__func__", None)  # a method: the signature is its function's
    if func is None:
        return _has_rtol(method)
    try:
        known = _RTOL_OF.get(func)
        if known is None:
            known = _RTOL_OF[func] = _has_rtol(func)
        return known
    except TypeError:  # not weakly referenceable
        return _has_rtol(func)


def _has_rtol(func) -> bool:
    try:
        return "rtol" in inspect.signature(func).parameters
    except (TypeError, ValueError):
        return False


# inspect.signature took 0.14 ms a call, twice per static solve: each function's answer is kept,
# weakly (a user's solve function, and what it holds, may go)
_RTOL_OF: "weakref.WeakKeyDictionary[Callable, bool]" = weakref.WeakKeyDictionary()

log = logging.getLogger(__name__)

_EPS = np.finfo(float).eps


@dataclass
class NewtonResult:
    """The outcome of a Newton minimisation.

    Attributes
    ----------
    x : numpy.ndarray
        Last iterate (the minimiser when ``converged``), ``(ndofs,)``.
    converged : bool
    iterations : int
        Newton iterations taken.
    residual_history : list of float
        ||g|| on the free DOFs (N) before each iteration and at the end.
    line_search_cuts : int
        Total step halvings.
    linear_iterations : int
        Total Krylov iterations of the linear solves (0 for a direct solver).
    message : str
        Why it stopped.
    seconds : dict
        Wall time (s) spent in ``"linearize"``, ``"solve"`` and ``"line_search"``.
    linear_solves : int
        Linear solves, every one (an exact-tangent CG stopped at negative
        curvature included: its iterate seeds the projected solve).
    linear_setups : int
        Preconditioner hierarchies (AMG) and LU factorizations built.
    extensions : int
        Full projected steps lengthened at a saddle under IPC contact (see
        ``_extend``: where the exact tangent proved indefinite and the CCD
        passed the longer step).
    """

    x: np.ndarray
    converged: bool
    iterations: int
    residual_history: list = field(default_factory=list)
    line_search_cuts: int = 0
    linear_iterations: int = 0
    message: str = ""
    seconds: dict = field(default_factory=lambda: {"linearize": 0.0, "solve": 0.0, "line_search": 0.0})
    linear_solves: int = 0
    linear_setups: int = 0
    extensions: int = 0


#: Private switch for benchmarks (scripts/bench_newton_amg.py): False restores the behaviour
#: before issue 19 (a new AMG hierarchy for every solve, and an exact-tangent solve that is
#: thrown away when its direction is no descent direction).
_REUSE_AMG = True


def constrain(H: sp.csr_matrix, free: np.ndarray, pattern=None) -> sp.csr_matrix:
    """Replace the rows and columns of fixed DOFs by the identity.

    Keeps the matrix symmetric and its size, so the solution has dx = 0 on
    fixed DOFs for a right-hand side that is 0 there. With the model's
    ``pattern`` (the Hessian came from it) this edits the data array in place
    of a sparse product.
    """
    fixed = ~free
    if pattern is not None and pattern.owns(H):
        mask = pattern.entries_touching(fixed)
        H.data[mask] = 0.0
        H.data[pattern.diagonal_positions[fixed]] = 1.0
        return H
    D = sp.diags(free.astype(float))
    return (D @ H @ D + sp.diags(fixed.astype(float))).tocsr()


def newton_minimize(
    energy: Callable[[np.ndarray], float],
    linearize: Callable[[np.ndarray, bool], tuple],
    x0: np.ndarray,
    free: np.ndarray,
    *,
    rtol: float = 1e-8,
    g_scale: float | None = None,
    max_iter: int = 50,
    linear_solver=None,
    near_null: np.ndarray | None = None,
    pattern=None,
    energy_roundoff: float = 0.0,
    armijo: float = 1e-4,
    max_cuts: int = 30,
    project: bool = True,
    g_floor: float = 0.0,
    gradient: Callable[[np.ndarray], np.ndarray] | None = None,
    inexact: bool = True,
    min_iter: int = 0,
    max_step: Callable[[np.ndarray, np.ndarray], float] | None = None,
    hessian_constant: bool = False,
    saddle_extension: bool = False,
    step_tol: float = 0.0,
) -> NewtonResult:
    """Minimise ``energy`` from ``x0`` over the free DOFs.

    Parameters
    ----------
    energy : callable
        x -> Pi(x) (J), +inf where inadmissible.
    linearize : callable
        (x, project) -> (gradient (N), Hessian (N/m, sparse, symmetric)); with
        ``project=True`` the Hessian must be positive semi-definite.
    x0 : numpy.ndarray
        Start, ``(ndofs,)``; fixed DOFs keep their values from it.
    free : numpy.ndarray of bool
        ``(ndofs,)``, True for unknowns.
    rtol : float
        Converged when ||g_free|| <= rtol * g_scale.
    g_scale : float, optional
        Force scale (N) of the problem, e.g. the norm of the external load;
        the largest of it, ||g_free(x0)|| and ||g_fixed(x0)|| (the reaction
        the held DOFs carry) is used (default: the larger of the last two).
    max_iter : int
        Most Newton iterations.
    linear_solver : object with ``solve(A, b, near_null)``
        Default :class:`fem_elastic.AutoSolver`.
    near_null : numpy.ndarray, optional
        ``(ndofs, k)`` near-null space for AMG (rigid-body modes).
    pattern : SparsityPattern, optional
        The Hessian's CSR pattern, for cheap constraint application.
    energy_roundoff : float
        Absolute round-off of Pi (J) beyond ``eps |Pi|``; when the predicted
        decrease is below ten times the total, energy comparisons are
        meaningless and the full step is taken.
    armijo : float
        Sufficient-decrease constant c of the Armijo condition.
    max_cuts : int
        Most step halvings per iteration before giving up.
    project : bool
        Use the PSD-projected Hessian away from the solution (and the exact
        one near it, see the module notes). False always uses the exact one.
    g_floor : float
        Round-off level of ||g|| (N), an upper bound (it adds the round-off
        of every element coherently). Also converged when ||g|| <= 10
        g_floor and the Newton step predicts an energy decrease below the
        energy's round-off: no iterate can then be told apart from the
        solution.
    gradient : callable, optional
        x -> gradient alone. When given, each iterate after the first is
        first tested for convergence with the gradient only, so the
        converged iterate costs no Hessian assembly (a linear problem then
        takes one assembly instead of two).
    min_iter : int
        Fewest Newton steps before any convergence test may stop it (unless
        the gradient is exactly zero). ``solve_static`` passes 1 for a load
        step that changes the load: the start is then never "converged"
        however small the load is against the round-off floors, since a
        Newton step from it solves the linearised problem to the accuracy of
        the linear solver, whatever the problem's scale.
    inexact : bool
        Inexact Newton: an iterative linear solver stops at a relative
        residual ``eta = min(1e-2, 0.1 ||g|| / ||g_0||)`` instead of its own
        tight tolerance (the forcing term of Eisenstat and Walker 1996, in
        its simplest form). Far from the solution a rough direction is as
        good as an exact one; as ``||g||`` falls eta falls with it, which
        keeps Newton's fast local convergence. Direct solvers ignore it.
    max_step : callable, optional
        ``(x, dx) -> fraction in [0, 1]``: the largest collision-free
        fraction of the step (continuous collision detection of a contact
        barrier, ``model.max_step``). The line search starts at that fraction
        instead of 1, so no trial point ever crosses into intersection (the
        barrier's energy is finite for intersecting states, it cannot tell).
        With it the energy at ``x`` is re-evaluated after each linearization,
        since a contact term may adapt its stiffness there (IPC's adaptive
        barrier stiffness).
    hessian_constant : bool
        The energy is quadratic (a linear elastic body under dead loads,
        ``Model.quadratic``): its Hessian, exact or projected, is the same
        matrix at every x. With ``gradient`` given, the iterations after the
        first then reuse the first one's Hessian instead of assembling it
        again (the same bits: the direct solvers see an identical matrix and
        keep their factor). A linear static solve needs the second iteration
        only for its round-off test; this makes that iteration a gradient and
        a back-substitution.

    saddle_extension : bool
        With ``max_step``: a full projected step taken where the exact
        tangent proved indefinite (a saddle) is doubled while the energy keeps
        falling and ``max_step`` passes the longer step (``_extend``). Only
        where ``max_step`` bounds every contact of the problem (see
        :func:`saddle_extension_safe`): a longer step is otherwise checked at
        its end alone, and could pass through an obstacle.
    step_tol : float
        Step tolerance (m), off at 0. Also converged after a full step
        (``alpha >= 1``: the line search, and the CCD under contact, took the
        whole Newton step) on the exact tangent whose largest DOF change
        ``max |dx|`` is at most ``step_tol``: IPC's rule (Li et al. 2020,
        ``||p||_inf / h < eps_d``; libuipc's ``velocity_tol * dt``), which an
        implicit step passes as a velocity tolerance times h. Only such a step
        counts: Newton is then in its quadratic regime and the error left is
        of the order of the step squared over the problem's length scale. A
        step the CCD cut short is small because a contact blocks it; a
        projected one may be small because the projection hides a saddle (and
        with ``project`` the first step is always projected); a steepest
        descent step is no Newton step.

    Returns
    -------
    NewtonResult
    """
    solver = as_linear_solver(linear_solver)  # None: AutoSolver(); a name: its solver
    if _REUSE_AMG and isinstance(solver, AutoSolver):  # one AMG hierarchy for the whole solve
        indptr = getattr(pattern, "indptr", None)  # a stacked (multi-body) pattern has no CSR of its own
        solver = solver.reusing(len(free), None if indptr is None else int(indptr[-1]))
    elif _REUSE_AMG and isinstance(solver, AMGSolver):
        solver = solver.reusing()
    x = np.array(x0, dtype=float)
    free = np.asarray(free, dtype=bool)
    if near_null is not None:
        near_null = near_null * free[:, None]
    result = NewtonResult(x=x, converged=False, iterations=0)
    e = energy(x)
    if not math.isfinite(e):
        result.message = "the starting point is inadmissible (energy is not finite)"
        return result
    exact = not project  # use the exact Hessian this iteration
    constrained_H = None  # the Hessian constrain() already edited in place (kept when constant)
    for it in range(max_iter + 1):
        t0 = time.perf_counter()
        need_hessian = True
        if gradient is not None and it > 0:  # test convergence before assembling a Hessian
            g = gradient(x)
            gnorm = float(np.linalg.norm(g[free]))
            assert g_scale is not None  # set at it == 0
            need_hessian = math.isfinite(gnorm) and (gnorm > rtol * g_scale or it < min_iter) \
                and it < max_iter
        if need_hessian and not (hessian_constant and it > 0 and gradient is not None):
            g, H = linearize(x, not exact)  # (else g is gradient(x) above, H the first one's)
        result.seconds["linearize"] += time.perf_counter() - t0
        if it == 0:  # the reaction the held DOFs carry: part of the problem's force scale
            reaction = float(np.linalg.norm(g[~free])) if not free.all() else 0.0
        g = np.where(free, g, 0.0)
        gnorm = float(np.linalg.norm(g))
        result.residual_history.append(gnorm)
        if not math.isfinite(gnorm):
            result.message = "the gradient is not finite"
            return result
        if it == 0:
            reaction = reaction if math.isfinite(reaction) else 0.0
            g_scale = max(gnorm, reaction) if g_scale is None else max(g_scale, gnorm, reaction)
        assert g_scale is not None  # set at it == 0
        if gnorm == 0.0 or (gnorm <= rtol * g_scale and it >= min_iter):
            result.converged = True
            result.message = f"||g|| = {gnorm:.3e} N <= {rtol:.1e} * {g_scale:.3e} N"
            break
        if it == max_iter:
            result.message = f"no convergence in {max_iter} iterations (||g|| = {gnorm:.3e} N)"
            break
        eta = min(1e-2, 0.1 * gnorm / result.residual_history[0]) if inexact else None
        tried_exact = exact and project  # an exact tangent that proves indefinite is projected
        if isinstance(solver, ReusedAMG):
            # CG on the exact tangent stops at its first negative curvature (the tangent is
            # indefinite); its iterate so far is the warm start of the projected tangent's CG
            dx, slope, indefinite = _direction(solver, H, g, free, pattern, near_null, result, eta,
                                               psd=not (exact and project))
            if indefinite:
                log.debug("negative curvature in CG on the exact Hessian; projecting")
                exact = False
                t0 = time.perf_counter()
                _, H = linearize(x, True)
                result.seconds["linearize"] += time.perf_counter() - t0
                dx, slope, _ = _direction(solver, H, g, free, pattern, near_null, result, eta,
                                          psd=True, x0=dx)
        else:
            dx, slope, H, exact = _direction_trial(
                solver, linearize, x, H, g, free, pattern, near_null, result, eta, exact, project,
                constrained=H is constrained_H,
                lu_dofs=CONTACT_EXACT_LU_DOFS if max_step is not None else None)
            # constrain() edits a matrix of the pattern in place: a kept Hessian needs it once
            constrained_H = H if pattern is not None and pattern.owns(H) else None
        # a step that can end the solve by step_tol: Newton's own on the exact tangent (no
        # projection that may hide a saddle, no steepest descent), in its quadratic regime
        exact_newton_step = bool(exact and slope < 0)
        if not slope < 0:  # still no descent direction: steepest descent
            log.debug("Newton direction is not a descent direction; using -g")
            # keep the Newton step's length; without one, a step of -g / max diag(H)
            length = np.linalg.norm(dx) or gnorm / max(float(np.abs(H.diagonal()).max()), _EPS)
            dx = -g * (length / gnorm)
            slope = float(g @ dx)
        t0 = time.perf_counter()
        roundoff = 0.5 * abs(slope) <= 10.0 * (energy_roundoff + _EPS * abs(e))
        if roundoff and gnorm <= 10.0 * g_floor and it >= min_iter:
            result.converged = True
            result.message = (
                f"||g|| = {gnorm:.3e} N is at its round-off level ({g_floor:.3e} N) and the "
                "Newton step predicts no decrease above the energy's round-off"
            )
            break
        alpha = 1.0
        if max_step is not None:
            e = energy(x)  # the contact stiffness may have changed in linearize
            alpha = min(1.0, float(max_step(x, dx)))
            if not alpha > 0.0:
                result.message = (
                    "the collision-free fraction of the Newton step is 0: the start of the step "
                    "is in contact at distance 0 (check for intersecting bodies)"
                )
                result.iterations = it
                break
        for cut in range(max_cuts + 1):
            x_try = x + alpha * dx
            e_try = energy(x_try)
            if math.isfinite(e_try) and (
                e_try <= e + armijo * alpha * slope or (roundoff and alpha == 1.0)
            ):
                break
            alpha *= 0.5
            result.line_search_cuts += 1
        else:
            result.seconds["line_search"] += time.perf_counter() - t0
            result.message = (
                f"line search failed: no decrease after {max_cuts} halvings "
                f"(||g|| = {gnorm:.3e} N)"
            )
            result.iterations = it
            break
        if saddle_extension and max_step is not None and alpha == 1.0 and tried_exact and not exact:
            # a full projected step where the exact tangent was indefinite: near a saddle of a
            # barrier, the projection leaves its descent direction only the inertia's stiffness
            x_try, e_try, alpha = _extend(energy, max_step, x, dx, x_try, e_try)
            result.extensions += alpha > 1.0
        result.seconds["line_search"] += time.perf_counter() - t0
        if project:
            exact = alpha >= 1.0  # full step: in the quadratic basin; else project again
        x, e = x_try, e_try
        result.x = x
        result.iterations = it + 1
        # the step's largest DOF change (m): alpha > 0 scales the max, with no array the size of
        # dx made for it (0.03 against 1.1 ms at 87,567 DOFs)
        moved = alpha * float(np.abs(dx).max())
        log.debug("Newton %d: ||g|| = %.3e N, alpha = %g, Pi = %.9e J, max |step| = %.3e m", it,
                  gnorm, alpha, e, moved)
        if step_tol > 0.0 and alpha >= 1.0 and exact_newton_step and it + 1 >= min_iter \
                and moved <= step_tol:  # the whole exact Newton step, within the tolerance
            result.converged = True
            result.message = (f"a full Newton step of max |dx| = {moved:.3e} m <= step_tol "
                              f"= {step_tol:.3e} m (||g|| = {gnorm:.3e} N before it)")
            break
    result.x = x
    return result


#: Most doublings of a projected step at a saddle (:func:`_extend`): up to 64 times its length
MAX_EXTENSIONS = 6

#: Under IPC contact (``max_step`` given), the largest exact tangent that CHOLMOD proves
#: indefinite which ``fe.AutoSolver`` still solves by SuperLU; above it Newton projects the
#: tangent at once. On the drop's incremental potential (``scripts/bench_ipc.py``) SuperLU
#: costs 1.1x CHOLMOD's analysis and factor at 1,590 DOFs, 1.9x at 4,578 and 7.4x at 13,830;
#: an LU that gave no descent direction (often, at the barrier's saddles) costs a projected
#: solve on top. Above this size the 21,870-tet drop took 206-217 s instead of 252-294 s. Without
#: contact the LU is kept up to ``max_direct_dofs``: there an indefinite exact tangent is a
#: body under compression, whose projected Newton converges only linearly.
CONTACT_EXACT_LU_DOFS = 5_000


def saddle_extension_safe(model) -> bool:
    """Whether ``model.max_step`` bounds every contact a longer Newton step could cross.

    True with IPC contact (its CCD checks the whole segment of a step) when
    the fixed obstacles, if any, are half-spaces (``fe.Ground``): a step
    cannot pass through a plane without ending beyond it, where its barrier is
    infinite and its penalty large. A sphere or a box is checked only at a
    step's end, so a step doubled at a saddle could jump through it.
    """
    from ..physics.obstacles import Ground

    contact = getattr(model, "contact", None)
    return (getattr(contact, "kind", None) == "potential"
            and all(isinstance(o, Ground) for o in getattr(model, "obstacles", ())))


def _extend(energy, max_step, x, dx, x_full, e_full):
    """Double a full projected Newton step while the energy keeps falling (and CCD allows it).

    Where the exact tangent is indefinite, Newton stands near a saddle: the
    PSD projection gives the directions of negative curvature only what the
    rest of the objective adds (the inertia's ``m / h^2`` when a barrier
    pair's Hessian is clamped), so each full step moves away from the saddle
    by only a factor ``1 + |lambda| / lambda_projected``. Resting under IPC
    the 21,870-tet drop of ``scripts/bench_ipc.py`` spent 13 Newton
    iterations so (||g|| growing 3e-4 to 1.6e-2 N while the energy fell). Each
    doubling costs an energy and a CCD bound, no factorisation; the first that
    does not lower the energy, or that CCD cuts, ends it. Returns the
    iterate, its energy and the step fraction taken.
    """
    alpha, x_best, e_best = 1.0, x_full, e_full
    for _ in range(MAX_EXTENSIONS):
        a = 2.0 * alpha
        x_try = x + a * dx
        # x -> x_best is collision-free already: the CCD checks only the doubling's new half
        if max_step(x_best, x_try - x_best) < 1.0:  # it would meet a contact
            break
        e_try = energy(x_try)
        if not e_try < e_best:
            break
        alpha, x_best, e_best = a, x_try, e_try
    if alpha > 1.0:
        log.debug("projected step at a saddle extended to %g times its length", alpha)
    return x_best, e_best, alpha


def _direction(solver, H, g, free, pattern, near_null, result, rtol=None, psd=None, x0=None,
               constrained=False):
    """Solve H dx = -g on the free DOFs (to ``rtol`` if the solver is iterative).

    Counts the solve, its iterations and its setups in ``result``. With a
    :class:`ReusedAMG` solver (``psd`` given) returns dx, the slope g . dx and
    whether CG met negative curvature (``psd=False``: the exact tangent is
    indefinite, dx is then CG's iterate so far); else dx and the slope.
    ``x0`` is a warm start for CG. ``constrained``: H is already constrained (in place).
    """
    t0 = time.perf_counter()
    A = H if constrained else constrain(H, free, pattern)
    kw = {"rtol": rtol} if rtol is not None and _takes_rtol(solver) else {}
    if isinstance(solver, ReusedAMG):
        kw.update(psd=True if psd is None else psd, x0=x0)
    try:
        lin = solver.solve(A, -g, near_null, **kw)
    except SingularMatrix:
        # A PSD projection can leave a direction with no stiffness at all;
        # a small diagonal shift restores a descent direction.
        shift = 1e-8 * float(np.abs(A.diagonal()).max())
        result.linear_solves += 1  # the failed factorization is a solve too
        lin = solver.solve(A + shift * sp.identity(A.shape[0], format="csr"), -g, near_null, **kw)
    except LinearSolverFailed as exc:
        result.linear_solves += 1
        last = getattr(exc, "result", None)
        if last is not None:
            result.linear_iterations += last.iterations
            result.linear_setups += last.setups
        result.seconds["solve"] += time.perf_counter() - t0
        raise
    result.seconds["solve"] += time.perf_counter() - t0
    result.linear_solves += 1
    result.linear_iterations += lin.iterations
    result.linear_setups += getattr(lin, "setups", 0)
    dx = np.where(free, lin.x, 0.0)
    if psd is not None:
        return dx, float(g @ dx), bool(getattr(lin, "negative_curvature", False))
    return dx, float(g @ dx)


def _direction_trial(solver, linearize, x, H, g, free, pattern, near_null, result, eta, exact,
                     project, constrained=False, lu_dofs=None):
    """The direction with a solver that cannot stop CG at negative curvature (a direct one,
    a user's, or any with ``_REUSE_AMG`` off): on an exact tangent it is solved first, and
    when its direction is no descent direction the projected tangent is assembled and solved
    too (the first solve is then wasted, but counted). ``lu_dofs``: the largest exact tangent
    that CHOLMOD proves indefinite which ``fe.AutoSolver`` still solves by SuperLU
    (:data:`CONTACT_EXACT_LU_DOFS` under contact). Returns dx, slope, H, exact."""
    # on an exact tangent, a stalled CG is answered by projecting, not by a big LU
    strict = solver
    if exact and project and hasattr(solver, "strict"):
        strict = solver.strict(max_lu_dofs=lu_dofs) if lu_dofs is not None \
            and isinstance(solver, AutoSolver) else solver.strict()
    try:
        dx, slope = _direction(strict, H, g, free, pattern, near_null, result, eta, constrained=constrained)
    except LinearSolverFailed:
        if not (exact and project):
            raise
        dx, slope = np.zeros_like(g), 0.0  # an indefinite exact Hessian stalls CG
    if exact and project and not slope < 0:
        # the exact Hessian is indefinite here: go back to the projection
        log.debug("exact Hessian gave no descent direction; projecting")
        exact = False
        t0 = time.perf_counter()
        _, H = linearize(x, True)
        result.seconds["linearize"] += time.perf_counter() - t0
        dx, slope = _direction(solver, H, g, free, pattern, near_null, result, eta)
    return dx, slope, H, exact
