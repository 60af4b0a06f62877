"""Static equilibrium: minimise the total potential energy.

``solve_static`` runs Newton's method (:mod:`fem_elastic.solvers.newton`) on
Pi(x) = E_body(x) - f_ext . (x - X). When the full load cannot be reached
from the rest state in one go (Newton stalls, or the line search finds only
inverted states), the load is applied in increments, each started from the
previous equilibrium: the increment is halved after a failure and doubled
after an easy success.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InvalidParameter, NotConverged
from .newton import newton_minimize

__all__ = ["StaticResult", "solve_static"]

log = logging.getLogger(__name__)


@dataclass
class StaticResult:
    """A static equilibrium.

    Attributes
    ----------
    x : numpy.ndarray
        Deformed DOF positions, ``(ndofs,)`` (m).
    displacement : numpy.ndarray
        Vertex displacements, ``(n_vertices, 3)`` (m), whatever the element order.
    converged : bool
        Whether the full load was reached to tolerance.
    load_factor : float
        The largest load fraction reached in equilibrium (1.0 when converged).
    iterations : int
        Newton iterations over all load steps.
    residual_history : list of float
        ||g|| on the free DOFs (N) at every Newton iterate, all steps in order.
    load_steps : list of float
        The load factors at which equilibrium was reached.
    line_search_cuts, linear_iterations : int
        Solver statistics summed over all steps.
    seconds : dict
        Wall time (s) in linearization (assembly), linear solves and line search.
    wall_time : float
        Total wall time (s).
    message : str
        Why it stopped.
    """

    x: np.ndarray
    displacement: np.ndarray
    converged: bool
    load_factor: float
    iterations: int
    residual_history: list = field(default_factory=list)
    load_steps: list = field(default_factory=list)
    line_search_cuts: int = 0
    linear_iterations: int = 0
    seconds: dict = field(default_factory=dict)
    wall_time: float = 0.0
    message: str = ""


def solve_static(
    model,
    *,
    rtol: float = 1e-8,
    max_iter: int = 30,
    linear_solver=None,
    project: bool = True,
    initial_load_step: float = 1.0,
    min_load_step: float = 1.0 / 1024,
    check: bool = True,
) -> StaticResult:
    """Static equilibrium of a model under its loads.

    Parameters
    ----------
    model : Model
        Must fix enough DOFs to remove rigid-body motion.
    rtol : float
        Newton stops when the out-of-balance force on the free DOFs is below
        ``rtol`` times the norm of the external load (N), or when it is
        within ten times its round-off floor (``ElasticPotential.gradient_roundoff``)
        and the next Newton step would change the energy by less than its
        round-off: a stiff body under a small load cannot be resolved further.
    max_iter : int
        Most Newton iterations per load step.
    linear_solver : object, optional
        ``fe.DirectSolver()``, ``fe.AMGSolver()`` or the default
        ``fe.AutoSolver()`` (direct below 20k DOFs, AMG-CG above).
    project : bool
        Project the tangent to positive semi-definite per quadrature point
        while far from equilibrium (guarantees a descent direction under
        compression), and use the exact tangent near it (quadratic
        convergence). False uses the exact tangent throughout.
    initial_load_step : float
        First load increment, in (0, 1]; 1 tries the full load at once.
    min_load_step : float
        Smallest increment before giving up.
    check : bool
        Raise :class:`fe.NotConverged` (carrying the result) if the full load
        is not reached; with False, return the result with ``converged=False``.

    Returns
    -------
    StaticResult

    Raises
    ------
    UnderConstrained
        If the fixed DOFs leave a rigid-body mode free.
    NotConverged
        If ``check`` and the full load was not reached.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(10, 2, 2)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.LinearElastic(E=1e7, nu=0.3)),
    ...                  fixed="left", traction={"right": (0.0, 0.0, -1e3)})
    >>> res = fe.solve_static(model)
    >>> res.converged, res.displacement.shape
    (True, (99, 3))
    """
    if not (0 < initial_load_step <= 1) or not (0 < min_load_step <= initial_load_step):
        raise InvalidParameter(
            "need 0 < min_load_step <= initial_load_step <= 1, got "
            f"initial_load_step={initial_load_step!r}, min_load_step={min_load_step!r}."
        )
    model.check_supported()
    t_start = time.perf_counter()
    f_full = model.external_force(1.0)
    free = model.free
    g_scale_full = float(np.linalg.norm(f_full[free]))
    near_null = model.space.rigid_body_modes()
    g_floor = model.gradient_roundoff()
    e_noise = model.energy_roundoff()
    pattern = model.space.pattern
    x = model.X.copy()
    total = StaticResult(
        x=x, displacement=model.to_vertices(x - model.X), converged=False, load_factor=0.0,
        iterations=0, seconds={"linearize": 0.0, "solve": 0.0, "line_search": 0.0},
    )
    if g_scale_full == 0.0:
        total.converged, total.load_factor, total.message = True, 1.0, "no load: the rest state"
        total.wall_time = time.perf_counter() - t_start
        return total
    s, ds = 0.0, float(initial_load_step)
    while s < 1.0:
        target = min(1.0, s + ds)
        res = newton_minimize(
            lambda y: model.energy(y, target),
            lambda y, proj: model.linearize(y, target, project=proj),
            x,
            free,
            rtol=rtol,
            g_scale=target * g_scale_full,
            max_iter=max_iter,
            linear_solver=linear_solver,
            near_null=near_null,
            pattern=pattern,
            energy_roundoff=e_noise,
            project=project,
            g_floor=g_floor,
            gradient=lambda y: model.gradient(y, target),
        )
        total.iterations += res.iterations
        total.residual_history.extend(res.residual_history)
        total.line_search_cuts += res.line_search_cuts
        total.linear_iterations += res.linear_iterations
        for k, v in res.seconds.items():
            total.seconds[k] += v
        if res.converged:
            x, s = res.x, target
            total.load_steps.append(s)
            if res.iterations <= 5:
                ds = min(2 * ds, 1.0)
            log.info("load factor %.4g reached in %d Newton iterations", s, res.iterations)
        else:
            ds /= 2
            log.info("load factor %.4g failed (%s); halving the increment to %.3g", target, res.message, ds)
            if ds < min_load_step:
                total.message = (
                    f"stalled at load factor {s:.4g}: the increment fell below {min_load_step:.3g} "
                    f"(last failure: {res.message})"
                )
                break
    total.x = x
    total.displacement = model.to_vertices(x - model.X)
    total.load_factor = s
    total.converged = s >= 1.0
    if total.converged:
        total.message = f"converged in {len(total.load_steps)} load step(s), {total.iterations} Newton iterations"
    total.wall_time = time.perf_counter() - t_start
    if check and not total.converged:
        raise NotConverged(
            f"solve_static did not reach the full load: {total.message}. Try more Newton "
            "iterations (max_iter=...), a smaller first load step (initial_load_step=0.1), "
            "or check that the load is physically attainable for this material.",
            result=total,
        )
    return total
