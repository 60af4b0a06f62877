"""Newton with line search across MPI ranks: static solves and implicit steps on PETSc.

The same minimisation as :func:`fem_elastic.solvers.newton.newton_minimize`, on
the distributed vectors and matrix of a
:class:`~fem_elastic.solvers.distributed.DistributedProblem`: each iteration
assembles the gradient and the tangent rank by rank (PSD-projected per
quadrature point until a full Newton step is accepted, then the exact one,
projected again if CG meets negative curvature), solves with the
:class:`~fem_elastic.solvers.petsc_solver.PETScSolver`'s KSP (inexact Newton:
the CG tolerance follows the gradient's decrease), and backtracks along the step
until the energy, summed over the ranks, decreases by Armijo's rule.

:func:`solve_static_distributed` ramps the loads and prescribed displacements
(with cut-back, as ``fe.solve_static``) and returns an ordinary
:class:`~fem_elastic.solvers.static.StaticResult` on every rank;
:func:`implicit_euler_step` minimises the incremental potential of one implicit
Euler step. Both are called by the serial entry points when their linear
solver is a ``fe.PETScSolver``.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from ..errors import InvalidParameter, NotConverged
from .linear_solvers import LinearSolverFailed
from .distributed import check_distributable, distributed_problem
from .petsc_solver import PETScSolver, comm_world

__all__ = ["DistributedNewton", "solve_static_distributed", "implicit_euler_step", "destroy_ksp"]

log = logging.getLogger(__name__)

_EPS = np.finfo(float).eps
_KSP_DIVERGED_INDEFINITE = (-8, -13)  # KSP_DIVERGED_INDEFINITE_PC, KSP_DIVERGED_INDEFINITE_MAT


@dataclass
class DistributedNewton:
    """The outcome of one distributed Newton minimisation (same fields as ``NewtonResult``)."""

    converged: bool = False
    iterations: int = 0
    residual_history: list = field(default_factory=list)
    line_search_cuts: int = 0
    linear_iterations: int = 0
    linear_solves: int = 0
    linear_setups: int = 0  # preconditioner set-ups (GAMG hierarchies, LU factors): one per tangent
    message: str = ""
    seconds: dict = field(default_factory=lambda: {"linearize": 0.0, "solve": 0.0, "line_search": 0.0})
    extensions: int = 0  # steps lengthened at a saddle: never here (no contact across ranks)


def minimize(problem, ksp, x, *, s: float = 1.0, y=None, k: float = 0.0, rtol: float = 1e-8,
             g_scale: float | None = None, max_iter: int = 30, min_iter: int = 0,
             armijo: float = 1e-4, max_cuts: int = 30, project: bool = True,
             energy_roundoff: float | None = None, g_floor: float | None = None) -> DistributedNewton:
    """Minimise G over the free DOFs from the distributed vector ``x`` (updated in place).

    ``x`` must hold the held DOFs' values already. Converged when ||g_free|| <=
    ``rtol * g_scale`` (N), ``g_scale`` being the largest of the one given, the first
    ||g_free|| and the held DOFs' reaction then; or when the Newton step predicts an
    energy change below the energy's round-off (``eps |G|`` plus the body's own) and
    ||g|| is within ten times its round-off floor. The floors default to the model's
    (statics); an implicit step passes the incremental potential's, which add the inertia
    term's (they grow as 1/h^2).
    """
    result = DistributedNewton()
    free = problem.free_owned
    g = problem.vec()
    dx = problem.vec()
    x_try = problem.vec()
    e_noise = problem.model.energy_roundoff() if energy_roundoff is None else energy_roundoff
    g_floor = problem.model.gradient_roundoff() if g_floor is None else g_floor
    try:
        e = problem.energy(x, s, y, k)
        if not math.isfinite(e):
            result.message = "the starting point is inadmissible (energy is not finite)"
            return result
        exact = not project
        for it in range(max_iter + 1):
            t0 = time.perf_counter()
            problem.gradient(x, s, y, k, out=g)
            ga = g.getArray()
            if it == 0:  # as the serial Newton: a non-finite reaction does not set the scale
                reaction = math.sqrt(problem.allsum(float(ga[~free] @ ga[~free])))
                reaction = reaction if math.isfinite(reaction) else 0.0
            ga[~free] = 0.0
            gnorm = g.norm()
            result.seconds["linearize"] += time.perf_counter() - t0
            result.residual_history.append(gnorm)
            if not math.isfinite(gnorm):
                result.message = "the gradient is not finite"
                return result
            if it == 0:
                g_scale = max(gnorm, reaction, g_scale or 0.0)
            assert g_scale is not None
            if gnorm == 0.0 or (gnorm <= rtol * g_scale and it >= min_iter):
                result.converged = True
                result.message = f"||g|| = {gnorm:.3e} N <= {rtol:.1e} * {g_scale:.3e} N"
                return result
            if it == max_iter:
                result.message = f"no convergence in {max_iter} iterations (||g|| = {gnorm:.3e} N)"
                return result
            eta = min(1e-2, 0.1 * gnorm / result.residual_history[0])
            slope, its = _direction(problem, ksp, x, g, dx, k, exact, eta, result)
            if not slope < 0.0 and exact and project:  # no descent from the exact tangent: project
                # (project=False keeps the exact tangent throughout, as the serial Newton does)
                exact = False
                slope, its = _direction(problem, ksp, x, g, dx, k, False, eta, result)
            if not slope < 0.0:  # steepest descent, scaled like the Newton step
                # without one, a step of g / max diag(H) (m), as the serial Newton
                length = dx.norm() or gnorm / max(problem.A.getDiagonal().norm(problem.PETSc.NormType.INFINITY),
                                                  _EPS)
                g.copy(dx)
                dx.scale(-length / gnorm)
                slope = float(g.dot(dx))
            t0 = time.perf_counter()
            roundoff = 0.5 * abs(slope) <= 10.0 * (e_noise + _EPS * abs(e))
            if roundoff and gnorm <= 10.0 * g_floor and it >= min_iter:
                result.converged = True
                result.message = (f"||g|| = {gnorm:.3e} N is at its round-off level and the Newton "
                                  "step predicts no decrease above the energy's round-off")
                return result
            alpha = 1.0
            for _ in range(max_cuts + 1):
                x.copy(x_try)
                x_try.axpy(alpha, dx)
                e_try = problem.energy(x_try, s, y, k)
                if math.isfinite(e_try) and (e_try <= e + armijo * alpha * slope
                                             or (roundoff and alpha == 1.0)):
                    break
                alpha *= 0.5
                result.line_search_cuts += 1
            else:
                result.seconds["line_search"] += time.perf_counter() - t0
                result.message = f"line search failed after {max_cuts} halvings (||g|| = {gnorm:.3e} N)"
                return result
            result.seconds["line_search"] += time.perf_counter() - t0
            x_try.copy(x)
            e = e_try
            result.iterations = it + 1
            if project:  # near the solution (a full step): the exact tangent converges quadratically
                exact = alpha == 1.0
        return result
    finally:
        for v in (g, dx, x_try):
            v.destroy()


def _direction(problem, ksp, x, g, dx, k, exact, eta, result):
    """Solve H dx = -g; the slope g . dx (nan when CG met negative curvature) and CG iterations."""
    t0 = time.perf_counter()
    A = problem.hessian(x, project=not exact, k=k)
    result.seconds["linearize"] += time.perf_counter() - t0
    t0 = time.perf_counter()
    ksp.setOperators(A)
    rtol0 = ksp.getTolerances()[0]
    rtol = max(rtol0, eta) if eta else rtol0  # the forcing term loosens, never tightens
    rhs = g.duplicate()
    g.copy(rhs)
    rhs.scale(-1.0)

    def solve_with(krylov):
        krylov.setTolerances(rtol=rtol)
        dx.set(0.0)
        krylov.solve(rhs, dx)
        result.linear_iterations += krylov.getIterationNumber()
        result.linear_solves += 1
        return int(krylov.getIterationNumber()), int(krylov.getConvergedReason())

    its, reason = solve_with(ksp)
    result.linear_setups += 1  # the new tangent's values: PETSc sets the preconditioner up again
    if reason == _KSP_DIVERGED_INDEFINITE[0] and not exact:
        # the projected tangent is positive semi-definite: the preconditioner is what failed
        # (Chebyshev smoothing on a poor eigenvalue estimate); GMRES, which does not need a
        # positive definite preconditioner, solves with the same set-up hierarchy
        log.info("CG met an indefinite preconditioner on the projected tangent; GMRES instead")
        its, reason = solve_with(_gmres(ksp))
    ksp.setTolerances(rtol=rtol0)
    rhs.destroy()
    result.seconds["solve"] += time.perf_counter() - t0
    if reason in _KSP_DIVERGED_INDEFINITE:
        return math.nan, its
    if reason < 0 and reason != -3:  # -3: the iteration limit; its iterate may still descend
        # the same reason on every rank (KSP reasons are collective): raised everywhere
        raise LinearSolverFailed(
            f"the PETSc linear solve failed (KSP converged reason {reason}, after {its} iterations): "
            "try fe.PETScSolver(preconditioner='lu'), or other GAMG options (options={...})."
        )
    return float(g.dot(dx)), its


def _gmres(ksp):
    """A GMRES KSP on ``ksp``'s operators and preconditioner, kept on ``ksp`` (made once)."""
    gmres = ksp.getAttr("fe_gmres")
    if gmres is None:
        from .petsc_solver import petsc

        PETSc = petsc()
        gmres = PETSc.KSP().create(comm=ksp.getComm())
        gmres.setType(PETSc.KSP.Type.GMRES)
        gmres.setGMRESRestart(100)
        gmres.setPC(ksp.getPC())
        gmres.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        gmres.setPCSide(PETSc.PC.Side.RIGHT)
        ksp.setAttr("fe_gmres", gmres)
    gmres.setOperators(*ksp.getOperators())
    gmres.setTolerances(max_it=ksp.getTolerances()[3])
    return gmres


def destroy_ksp(ksp) -> None:
    """Destroy a KSP of this module and the GMRES fallback kept on it."""
    gmres = ksp.getAttr("fe_gmres")
    if gmres is not None:
        ksp.setAttr("fe_gmres", None)
        gmres.destroy()
    ksp.destroy()


def _set_held(problem, x, x_full):
    """Put the held DOFs' values of the replicated model vector ``x_full`` into the distributed ``x``."""
    mask = problem.held_mask[problem.owned_old]
    x.getArray()[mask] = x_full[problem.owned_old[mask]]


def solve_static_distributed(model, solver: PETScSolver, *, rtol: float = 1e-8, max_iter: int = 30,
                             project: bool = True, initial_load_step: float = 1.0,
                             min_load_step: float = 1.0 / 1024, check: bool = True,
                             steps: int | None = None, stabilize: bool = False):
    """``fe.solve_static`` across the MPI ranks; the same :class:`StaticResult` on every rank.

    Parameters are those of :func:`fem_elastic.solve_static`. The stability check
    (lowest eigenvalue) is not made on this path: ``min_eigenvalue`` is None.
    """

    check_distributable(model, "fe.solve_static")
    if stabilize:
        raise InvalidParameter(
            "solve_static(stabilize=True) perturbs along the lowest eigenmode, and the distributed "
            "path (fe.PETScSolver) makes no stability check: leave out stabilize, or solve serially."
        )
    model.check_supported()
    t_start = time.perf_counter()
    comm = comm_world()
    problem = distributed_problem(model, comm, model.held_dofs, mass=None)
    ksp = solver.ksp(comm)
    try:
        return _load_path(model, problem, ksp, t_start, rtol=rtol, max_iter=max_iter, project=project,
                          initial_load_step=initial_load_step, min_load_step=min_load_step,
                          check=check, steps=steps)
    finally:
        destroy_ksp(ksp)


def _load_path(model, problem, ksp, t_start, *, rtol, max_iter, project, initial_load_step,
               min_load_step, check, steps):
    """The load steps of :func:`solve_static_distributed` (its KSP made and destroyed there)."""
    from .static import EquilibriumPoint, StaticResult, _vertex_forces, held_at, next_load_factor

    x = problem.to_vec(model.X)
    # the problem's force scale: the load, plus what the prescribed displacements exert at rest
    f_free = problem.f_owned[problem.free_owned]
    f_scale = math.sqrt(problem.allsum(float(f_free @ f_free)))
    u_scale = 0.0
    if model.prescribed_dofs.size and np.any(model.prescribed_values != 0.0):
        d = np.zeros(model.ndofs)
        d[model.prescribed_dofs] = model.prescribed_values
        dv = problem.to_vec(d)
        Kd = problem.body_tangent_times(x, dv)  # K_0 d on every row, held too
        kd = Kd.getArray(readonly=True)[problem.free_owned]
        u_scale = math.sqrt(problem.allsum(float(kd @ kd)))
        if u_scale == 0.0:  # no free DOF feels it: the forces on all (as the serial solve)
            ka = Kd.getArray(readonly=True)
            u_scale = math.sqrt(problem.allsum(float(ka @ ka))) or 1.0
        for v in (dv, Kd):
            v.destroy()
    g_scale_full = f_scale + u_scale
    seconds = {"linearize": 0.0, "solve": 0.0, "line_search": 0.0, "stability": 0.0}
    total = StaticResult(x=model.X.copy(), displacement=model.to_vertices(np.zeros(model.ndofs)),
                         converged=False, load_factor=0.0, iterations=0, seconds=seconds, _model=model)

    def point(xv, s, its):
        xs = problem.gather(xv)
        gv = problem.gradient(xv, s)
        r = np.where(model.free, 0.0, problem.gather(gv))
        gv.destroy()
        return EquilibriumPoint(load_factor=float(s), x=xs, displacement=model.to_vertices(xs - model.X),
                                reactions=_vertex_forces(model.space, r), reaction_dofs=r,
                                iterations=its, _model=model)

    total.path.append(point(x, 0.0, 0))
    max_ds = 1.0 if steps is None else 1.0 / steps  # (solve_static set initial_load_step for steps)
    s, ds = 0.0, float(min(initial_load_step, max_ds))
    if g_scale_full == 0.0:
        s = 1.0
        total.load_steps.append(1.0)
        total.path.append(point(x, 1.0, 0))
        total.message = "no load: the rest state"
    while s < 1.0:
        target = next_load_factor(s, ds, steps)  # the serial load path's rule, grid snap included
        x_try = x.duplicate()
        x.copy(x_try)
        _set_held(problem, x_try, held_at(model, model.X, target))
        res = minimize(problem, ksp, x_try, s=target, rtol=rtol, g_scale=target * g_scale_full,
                       max_iter=max_iter, min_iter=1, project=project)
        total.iterations += res.iterations
        total.residual_history.extend(res.residual_history)
        total.line_search_cuts += res.line_search_cuts
        total.linear_iterations += res.linear_iterations
        for key, v in res.seconds.items():
            seconds[key] += v
        if res.converged:
            x.destroy()
            x, s = x_try, target
            total.load_steps.append(s)
            total.path.append(point(x, s, res.iterations))
            if res.iterations <= 5:
                ds = min(2 * ds, max_ds)
        else:
            x_try.destroy()
            ds /= 2
            log.info("load factor %.4g failed (%s); halving the increment to %.3g", target, res.message, ds)
            if ds < min_load_step:
                total.message = (f"stalled at load factor {s:.4g}: the increment fell below "
                                 f"{min_load_step:.3g} (last failure: {res.message})")
                break
    x.destroy()
    total.load_factor = s
    total.converged = s >= 1.0
    if total.converged and not total.message:
        total.message = (f"converged in {len(total.load_steps)} load step(s), {total.iterations} "
                         f"Newton iterations on {problem.size} MPI rank(s)")
    last = total.path[-1]
    total.x, total.displacement = last.x, last.displacement
    total.reactions, total.reaction_dofs = last.reactions, last.reaction_dofs
    total.wall_time = time.perf_counter() - t_start
    if check and not total.converged:
        raise NotConverged(f"solve_static (PETSc, {problem.size} ranks) did not reach the full load: "
                           f"{total.message}. Try more Newton iterations (max_iter=...) or a smaller "
                           "first load step (initial_load_step=0.1).", result=total)
    return total


def implicit_euler_step(model, solver: PETScSolver, y: np.ndarray, h: float, mass: str,
                        held: np.ndarray, starts: list, *,
                        rtol: float, max_iter: int, project: bool, g_scale: float | None,
                        energy_roundoff: float | None = None, g_floor: float | None = None):
    """Minimise ``|x - y|_M^2 / (2 h^2) + Pi(x)`` across the ranks; (x, result).

    ``starts`` are first guesses (replicated model vectors, e.g. the inertial
    prediction and the old positions): Newton starts from the one with the lowest
    G; each holds the ``held`` DOFs at their values already. Every rank passes the same arrays
    and gets the same minimiser back.
    """
    check_distributable(model, "fe.ImplicitEuler")
    comm = comm_world()
    problem = distributed_problem(model, comm, held, mass=mass)
    ksp = problem.__dict__.get("_ksp")
    if ksp is None or problem.__dict__.get("_ksp_solver") is not solver:
        if ksp is not None:
            destroy_ksp(ksp)
        ksp = problem.__dict__["_ksp"] = solver.ksp(comm)
        problem.__dict__["_ksp_solver"] = solver
    yv = problem.to_vec(y)
    best, x = math.inf, cast(Any, None)
    for start in starts:
        xs = problem.to_vec(start)
        e = problem.energy(xs, 1.0, yv, h)
        if x is None or e < best:
            if x is not None:
                x.destroy()
            best, x = e, xs
        else:
            xs.destroy()
    res = minimize(problem, ksp, x, s=1.0, y=yv, k=h, rtol=rtol, g_scale=g_scale, max_iter=max_iter,
                   project=project, energy_roundoff=energy_roundoff, g_floor=g_floor)
    out = problem.gather(x)
    for v in (x, yv):
        v.destroy()
    return out, res
