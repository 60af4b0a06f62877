"""Static equilibrium: minimise the total potential energy, along a load path.

``solve_static`` runs Newton's method (:mod:`fem_elastic.solvers.newton`) on
Pi(x) = E_body(x) - s f_ext . (x - X), with the prescribed displacements at
``X + s u_p`` and the fixed DOFs at ``X``, for load factors s rising to 1.
When the full load cannot be reached from the rest state in one go (Newton
stalls, or the line search finds only inverted states), the load is applied
in increments, each started from the previous equilibrium: the increment is
halved after a failure and doubled after an easy success (never beyond
``1 / steps`` when ``steps`` is given). A step that moves prescribed
displacements starts from a predictor, the linearised response of the free
DOFs to the increment (one solve with the tangent of the previous
equilibrium), so a boundary layer of elements is never stretched by the
whole increment.

Every converged step is kept in :attr:`StaticResult.path` with its load
factor, displacements and reactions: a force-displacement curve is one line.
The reactions are the forces the supports exert, ``R = dPi/dx`` on the held
DOFs (zero on free ones): ``sum R + sum f_ext = 0`` at equilibrium.

After convergence the lowest eigenvalue of the exact free-DOF tangent tells
whether the equilibrium is a minimum (:mod:`fem_elastic.solvers.stability`);
an unstable one warns (:class:`~fem_elastic.solvers.stability.UnstableEquilibrium`)
and, with ``stabilize=True``, is perturbed along its eigenvector until Newton
settles in a stable state.

Convergence is relative to the problem's own scale: the force scale is the
norm of the external load plus that of the forces the prescribed
displacements exert on the rest state (``||K_0 u_p||`` on the free DOFs),
and a step that changes the load always takes at least one Newton step, so a
load below the round-off floor of the gradient (a nanometre beam, a nearly
incompressible material) is never answered with the unchanged start.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, TypedDict, cast

import numpy as np

from ..errors import InvalidParameter, NotConverged
from ..physics.impulse_contact import reject_impulse_contact
from .linear_solvers import LinearSolverFailed, SingularMatrix, as_linear_solver
from .newton import constrain, newton_minimize, saddle_extension_safe
from .petsc_solver import PETScSolver  # cheap: petsc4py is imported on its first solve
from .stability import UnstableEquilibrium, lowest_eigenpair
from .static_view import StaticResultView

if TYPE_CHECKING:  # for annotations only
    from typing import Unpack  # Python >= 3.11

    from ..physics.multibody import AnyModel, BodyBoundary
    from ..physics.supports import Where
    from .solver_types import LinearSolver

__all__ = ["EquilibriumPoint", "LoadPath", "RoundoffWarning", "StaticResult", "UnstableEquilibrium",
           "load_path", "solve_static"]

log = logging.getLogger(__name__)

#: lambda / mu * eps above which the displacement formulation's answer carries a visible
#: round-off error (measured: the relative error of a locked slab is ~ 1-30 lambda / mu * eps)
_ROUNDOFF_RATIO = 1e-6


class RoundoffWarning(UserWarning):
    """A static problem whose answer double precision cannot resolve.

    A material with nu so close to 0.5 that ``lambda / mu`` approaches ``1 / eps``
    (e.g. the plane-strain conversion nu* = nu / (1 - nu) of nu = 1/3, which is
    0.49999999999999994) has a stiffness matrix whose shear part lies below the
    round-off of its volumetric part: the displacement formulation then returns
    an answer with a relative error of about ``lambda / mu * eps`` (up to O(1)).
    """


def _check_conditioning(model) -> None:
    """Warn when the body's lambda / mu is beyond what double precision resolves."""
    material = getattr(model.body_potential, "material", None)
    mu, lam = getattr(material, "mu", None), getattr(material, "lam", None)
    if getattr(model.body, "formulation", "displacement") != "displacement":
        return
    if mu is None or lam is None or not mu > 0:
        return
    ratio = float(lam) / float(mu)
    if ratio * np.finfo(float).eps > _ROUNDOFF_RATIO:
        nu = getattr(material, "nu", None)
        warnings.warn(
            f"the material's lambda / mu = {ratio:.3g}"
            + (f" (nu = {nu!r})" if nu is not None else "")
            + f", so lambda / mu * eps = {ratio * np.finfo(float).eps:.2g}: the stiffness's "
            "shear part is lost below the round-off of its volumetric part, and the displacements "
            f"carry a relative error of up to ~{min(1.0, 30 * ratio * np.finfo(float).eps):.1g}. "
            "Use nu <= 0.4999999 (lambda / mu <= 5e6), or a mixed formulation "
            "(fe.ElasticBody(..., order=2, formulation='mixed')).",
            RoundoffWarning, stacklevel=3,
        )


def _vertex_forces(space, f: np.ndarray) -> np.ndarray:
    """Nodal forces ``(ndofs,)`` lumped onto the vertices, ``(n_vertices, 3)``.

    A P2 edge node's force goes half to each vertex of its edge: the total
    (and so every boundary's resultant) is kept. Several bodies (a
    ``fe.MultiBody``'s stacked space): each body's, stacked.
    """
    parts = getattr(space, "parts", None)
    if parts is not None:
        o = space.dof_offsets
        return np.concatenate([_vertex_forces(s, f[o[b]:o[b + 1]]) for b, s in enumerate(parts)])
    fv = f[space.vertex_dofs].copy()
    if space.order == 2:
        mesh = space.mesh
        edge_nodes = np.asarray(space.dofs.edge_dofs)[0]
        fe_ = f.reshape(-1, 3)[edge_nodes]  # (n_edges, 3)
        for end in (0, 1):
            np.add.at(fv, mesh.edges[end], 0.5 * fe_)
    return fv


@dataclass
class EquilibriumPoint:
    """One converged point of a load path.

    Attributes
    ----------
    load_factor : float
        The load factor s (loads at s times their value, prescribed
        displacements at s times theirs).
    x : numpy.ndarray
        DOF positions ``(ndofs,)`` (m).
    displacement : numpy.ndarray
        Vertex displacements ``(n_vertices, 3)`` (m).
    reactions : numpy.ndarray
        Support reactions lumped on the vertices, ``(n_vertices, 3)`` (N), zero
        on free DOFs (P2 edge nodes' reactions go half to each vertex of the edge).
    reaction_dofs : numpy.ndarray
        The reactions on every DOF, ``(ndofs,)`` (N).
    iterations : int
        Newton iterations of the step that reached it (0 for the start).
    min_eigenvalue : float or None
        Lowest eigenvalue of the free-DOF tangent (N/m), when checked.
    stable : bool or None
        Whether the tangent is positive definite there (None when not checked).
    """

    load_factor: float
    x: np.ndarray
    displacement: np.ndarray
    reactions: np.ndarray
    reaction_dofs: np.ndarray = field(repr=False)
    iterations: int = 0
    min_eigenvalue: float | None = None
    stable: bool | None = None
    _model: Any = field(default=None, repr=False, compare=False)  # the Model solved

    def reaction_force(self, where: Where | BodyBoundary) -> np.ndarray:
        """Total reaction (N), ``(3,)``, on a boundary name, names, vertex indices or mask.

        Sums the reactions of every node of the boundary; a node shared by two
        supported boundaries (an edge of both) counts in each.
        """
        nodes = self._model.boundary_nodes(where)
        return self.reaction_dofs.reshape(-1, 3)[nodes].sum(axis=0)


class LoadPath(list):
    """The converged points of a static solve, in order of load factor (a list of
    :class:`EquilibriumPoint`), the reference state first (load factor 0).

    ``path.load_factors``, ``path.displacements`` (``(n_points, n_vertices, 3)``)
    and ``path.reaction_forces(name)`` (``(n_points, 3)``) give the curves:

    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), 1000.0,
    ...                  fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)),
    ...                  fixed={"left": "x", "front": "y", "bottom": "z"},  # rollers
    ...                  displacement={"right": (0.01, None, None)})
    >>> path = fe.load_path(model, steps=2)
    >>> path.load_factors.tolist(), (path.reaction_forces("right")[:, 0].round(6) + 0.0).tolist()
    ([0.0, 0.5, 1.0], [0.0, 50.0, 100.0])
    """

    @property
    def load_factors(self) -> np.ndarray:
        return np.array([p.load_factor for p in self])

    @property
    def displacements(self) -> np.ndarray:
        return np.stack([p.displacement for p in self])

    @property
    def min_eigenvalues(self) -> np.ndarray:
        return np.array([np.nan if p.min_eigenvalue is None else p.min_eigenvalue for p in self])

    def reaction_forces(self, where: Where | BodyBoundary) -> np.ndarray:
        return np.stack([p.reaction_force(where) for p in self]) if self else np.zeros((0, 3))


@dataclass(repr=False)
class StaticResult(StaticResultView):
    """A static equilibrium.

    ``repr(result)`` is a few lines (size, material, convergence, timings, the
    largest displacement, the total reaction); ``to_pyvista``, ``plot``,
    ``plot_history`` and ``save`` show it (:mod:`fem_elastic.solvers.static_view`).

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
        Wall time (s) in linearization (assembly), linear solves, line search
        and the stability check (``"stability"``).
    wall_time : float
        Total wall time (s).
    message : str
        Why it stopped.
    reactions : numpy.ndarray
        Support reactions at the last equilibrium, ``(n_vertices, 3)`` (N),
        zero on free DOFs (P2 edge nodes' reactions lumped onto their vertices).
    reaction_dofs : numpy.ndarray
        The same on every DOF, ``(ndofs,)`` (N).
    path : LoadPath
        Every converged point, the reference state first.
    min_eigenvalue : float or None
        Lowest eigenvalue of the free-DOF exact tangent at the last
        equilibrium (N/m); None when not checked (``stability=False``).
    stable : bool or None
        Whether that equilibrium is a minimum of the energy (None when not checked, or
        when no eigensolver converged).
    buckling_mode : numpy.ndarray or None
        The eigenvector of ``min_eigenvalue`` at the vertices, ``(n_vertices, 3)``
        (unit norm over the DOFs).
    perturbations : int
        How many times ``stabilize=True`` perturbed an unstable equilibrium.
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
    reactions: np.ndarray | None = None
    reaction_dofs: np.ndarray | None = field(default=None, repr=False)
    path: LoadPath = field(default_factory=LoadPath, repr=False)
    min_eigenvalue: float | None = None
    stable: bool | None = None
    buckling_mode: np.ndarray | None = field(default=None, repr=False)
    perturbations: int = 0
    _model: Any = field(default=None, repr=False, compare=False)  # the Model solved

    def reaction_force(self, where: Where | BodyBoundary) -> np.ndarray:
        """Total reaction (N), ``(3,)``, on a boundary name, names, vertex indices or mask.

        Examples
        --------
        >>> import fem_elastic as fe
        >>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), 1000.0,
        ...                  fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)),
        ...                  fixed="left", traction={"right": (0.0, 0.0, -100.0)})
        >>> (fe.solve_static(model).reaction_force("left").round(6) + 0.0).tolist()  # 100 Pa x 0.01 m^2
        [0.0, 0.0, 1.0]
        """
        nodes = self._model.boundary_nodes(where)
        # cast: a result without reactions fails here with AttributeError, as it always did
        return cast(np.ndarray, self.reaction_dofs).reshape(-1, 3)[nodes].sum(axis=0)


def _check_steps(steps):
    if steps is None:
        return None
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise InvalidParameter(
            f"steps must be a whole number >= 1 of equal load increments, e.g. steps=10; got {steps!r}."
        )
    return int(steps)


def _check_stability(stability):
    if stability in (True, False, "final", "path", None):
        return "final" if stability is True else (False if stability is None else stability)
    raise InvalidParameter(
        f"stability must be True (check the final equilibrium), 'path' (every step), or False; "
        f"got {stability!r}."
    )


def held_at(model, x: np.ndarray, s: float) -> np.ndarray:
    """A copy of ``x`` with the model's prescribed DOFs at ``X + s u_p`` (load factor ``s``)."""
    x = x.copy()
    presc = model.prescribed_dofs
    if presc.size:
        x[presc] = model.X[presc] + s * model.prescribed_values
    return x


class _Problem:
    """The static problem of a model at load factor s: held values, energy, reactions."""

    def __init__(self, model):
        self.model = model
        self.free = model.free
        self.presc = model.prescribed_dofs
        self.u_p = model.prescribed_values
        self.moving = bool(self.presc.size and np.any(self.u_p != 0.0))
        f_full = model.external_force(1.0)
        self.f_scale = float(np.linalg.norm(f_full[self.free]))
        if self.moving:
            d = np.zeros(model.ndofs)
            d[self.presc] = self.u_p
            Kd = model.rest_stiffness @ d
            # the forces the prescription exerts on the free DOFs (on all, if none is free)
            self.u_scale = float(np.linalg.norm(Kd[self.free])) or float(np.linalg.norm(Kd)) or 1.0
        else:
            self.u_scale = 0.0

    def held(self, x: np.ndarray, s: float) -> np.ndarray:
        """x with the prescribed DOFs at ``X + s u_p``."""
        return held_at(self.model, x, s)

    def point(self, x, s, iterations=0) -> EquilibriumPoint:
        model = self.model
        g = model.gradient(x, s)
        r = np.where(self.free, 0.0, g)
        return EquilibriumPoint(
            load_factor=float(s), x=x, displacement=model.to_vertices(x - model.X),
            reactions=_vertex_forces(model.space, r), reaction_dofs=r, iterations=iterations,
            _model=model,
        )


def _contact_max_step(model):
    """``model.max_step`` (CCD of an IPC contact) when the model has one, else None."""
    contact = getattr(model, "contact", None)
    if contact is None or getattr(contact, "kind", None) != "potential":
        return None
    return model.max_step


def next_load_factor(s: float, ds: float, steps: int | None) -> float:
    """``s + ds``, not past 1 nor the next point ``k / steps``, snapped onto that grid (10 x 0.1 = 1)."""
    target = min(1.0, s + ds)
    if steps is not None:
        target = min(target, (math.floor(s * steps * (1 + 1e-12)) + 1) / steps)
        snap = round(target * steps) / steps
        target = snap if abs(target - snap) < 1e-12 else target
    return target


def _predictor(model, problem, x, s, target, solver, near_null, pattern, seconds):
    """The start of a step that moves prescribed DOFs: the linear response of the free DOFs.

    Solves ``K_ff dx_f = -(g_f + K_fp du_p)`` with the tangent at the previous
    equilibrium (exact; projected if that is singular or indefinite for the
    solver), and returns the lower-energy admissible state of the predicted one
    and the plain one (prescribed DOFs moved, free ones left), or the plain one.
    """
    plain = problem.held(x, target)
    if not problem.moving:
        return plain, 0
    t0 = time.perf_counter()
    free = problem.free
    d = plain - x  # the prescribed increment, zero elsewhere
    candidates = [plain]
    for project in (False, True):
        try:
            g, K = model.linearize(x, target, project=project)
            rhs = -(g + K @ d)
            rhs[~free] = 0.0
            A = constrain(K, free, pattern)
            dx = solver.solve(A, rhs, None if near_null is None else near_null * free[:, None]).x
        except (SingularMatrix, LinearSolverFailed, np.linalg.LinAlgError):
            continue
        if np.all(np.isfinite(dx)):
            candidates.insert(0, plain + np.where(free, dx, 0.0))
            break
    seconds["solve"] += time.perf_counter() - t0
    best, e_best = plain, math.inf
    for c in candidates:
        e = model.energy(c, target)
        if math.isfinite(e) and e < e_best:
            best, e_best = c, e
    return best, 1 if best is not plain else 0


class StaticOptions(TypedDict, total=False):
    """The keywords of :func:`solve_static` besides the model (for ``load_path(model, **kw)``)."""

    rtol: float
    max_iter: int
    linear_solver: LinearSolver | str | None
    project: bool
    initial_load_step: float
    min_load_step: float
    check: bool
    stability: bool | Literal["final", "path"] | None
    stabilize: bool


class SolveOptions(StaticOptions, total=False):
    """Every keyword of :func:`solve_static` (for ``BuiltRun.solve(**options)``)."""

    steps: int | None


def solve_static(
    model: AnyModel,
    *,
    rtol: float = 1e-8,
    max_iter: int = 30,
    linear_solver: LinearSolver | str | None = None,
    project: bool = True,
    initial_load_step: float = 1.0,
    min_load_step: float = 1.0 / 1024,
    check: bool = True,
    steps: int | None = None,
    stability: bool | Literal["final", "path"] | None = "final",
    stabilize: bool = False,
) -> StaticResult:
    """Static equilibrium of a model under its loads and prescribed displacements.

    Parameters
    ----------
    model : Model
        Must hold enough DOFs to remove rigid-body motion.
    rtol : float
        Newton stops when the out-of-balance force on the free DOFs is below
        ``rtol`` times the problem's force scale (N): the norm of the external
        load plus that of ``K_0 u_p``, the forces the prescribed displacements
        exert on the rest state; or when it is within ten times its round-off
        floor (``ElasticPotential.gradient_roundoff``) and the next Newton step
        would change the energy by less than its round-off, after at least one
        Newton step: a stiff body under a small load cannot be resolved further.
    max_iter : int
        Most Newton iterations per load step.
    linear_solver : object, optional
        ``fe.DirectSolver()``, ``fe.AMGSolver()``, ``fe.CholmodSolver()`` or the
        default ``fe.AutoSolver()`` (its docstring has the rule), or one of their
        names ``"direct"``, ``"amg"``, ``"cholmod"``, ``"auto"``.
        ``fe.PETScSolver()`` solves across MPI ranks (run the script with
        ``mpiexec -n N``; :mod:`fem_elastic.solvers.distributed_newton`): same
        result on every rank, no stability check (``min_eigenvalue`` is None).
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
    steps : int, optional
        Equal load increments ``1 / steps``: every one is a point of
        :attr:`StaticResult.path`. A failed increment is halved as without
        ``steps`` (the points in between join the path too).
    stability : True, "final", "path" or False
        Check the lowest eigenvalue of the free-DOF tangent at the final
        equilibrium (True, "final", the default), at every point of the path
        ("path"), or not at all (False: for huge models where even the check
        costs too much).
    stabilize : bool
        If the final equilibrium is unstable, perturb it along the eigenvector
        of the lowest eigenvalue and solve again, until it is stable (at most
        a few times). Without it an unstable equilibrium only warns
        (:class:`fe.UnstableEquilibrium`).

    Returns
    -------
    StaticResult

    Raises
    ------
    UnderConstrained
        If the held DOFs leave a rigid-body mode free.
    NotConverged
        If ``check`` and the full load was not reached.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(10, 2, 2)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.LinearElastic(E=1e7, nu=0.3)),
    ...                  fixed="left", traction={"right": (0.0, 0.0, -1e3)})
    >>> res = fe.solve_static(model)
    >>> res.converged, res.displacement.shape, res.stable
    (True, (99, 3), True)
    """
    steps = _check_steps(steps)
    stability = _check_stability(stability)
    if steps is not None and initial_load_step == 1.0:
        initial_load_step = 1.0 / steps
    if not (0 < initial_load_step <= 1) or not (0 < min_load_step <= initial_load_step):
        raise InvalidParameter(
            "need 0 < min_load_step <= initial_load_step <= 1, got "
            f"initial_load_step={initial_load_step!r}, min_load_step={min_load_step!r}."
        )
    reject_impulse_contact(model, "fe.solve_static")
    if isinstance(linear_solver, str):
        linear_solver = as_linear_solver(linear_solver)  # a name: its solver ("petsc" included)
    if isinstance(linear_solver, PETScSolver):
        from .distributed_newton import solve_static_distributed  # across MPI ranks: its own module

        if stability:
            log.info("solve_static with fe.PETScSolver: no stability check on the distributed path")
        _check_conditioning(model)  # the RoundoffWarning of a nearly incompressible body, as serially
        return solve_static_distributed(model, linear_solver, rtol=rtol, max_iter=max_iter, project=project,
                                        initial_load_step=initial_load_step, min_load_step=min_load_step,
                                        check=check, steps=steps, stabilize=stabilize)
    model.check_supported()
    memory_check = getattr(model, "check_tangent_memory", None)  # before any assembly (ResourceLimit)
    if memory_check is not None:
        memory_check("auto")
    _check_conditioning(model)
    t_start = time.perf_counter()
    solver = as_linear_solver(linear_solver)  # None: AutoSolver(); a name: its solver
    problem = _Problem(model)
    free = problem.free
    g_scale_full = problem.f_scale + problem.u_scale
    near_null = model.space.rigid_body_modes()
    g_floor = model.gradient_roundoff()
    e_noise = model.energy_roundoff()
    pattern = model.space.pattern
    x = model.X.copy()
    total = StaticResult(
        x=x, displacement=model.to_vertices(x - model.X), converged=False, load_factor=0.0,
        iterations=0, seconds={"linearize": 0.0, "solve": 0.0, "line_search": 0.0, "stability": 0.0},
        _model=model,
    )
    total.path.append(problem.point(x, 0.0))
    from . import linear_solvers as _ls

    lu_before = _ls._FACTORS.lu
    last_check = {}

    def checked(point):
        if stability == "path":
            lu = _ls._FACTORS.lu
            ec = _eigen(model, point.x, point.load_factor, free, near_null, total,
                        lu if lu is not lu_before else None)
            point.min_eigenvalue, point.stable = ec.value, ec.stable
            last_check["ec"] = ec

    checked(total.path[0])
    max_ds = 1.0 if steps is None else 1.0 / steps
    s, ds = 0.0, float(min(initial_load_step, max_ds))
    if g_scale_full == 0.0:
        s = 1.0
        total.load_steps.append(1.0)
        total.path.append(problem.point(x, 1.0))
        checked(total.path[-1])
        total.message = "no load: the rest state"
    failed = None  # (x, load factor) of the last failed attempt: what the diagnosis looks at
    while s < 1.0:
        target = next_load_factor(s, ds, steps)
        x0, pred = _predictor(model, problem, x, s, target, solver, near_null, pattern, total.seconds)
        max_step = _contact_max_step(model)
        fraction = 1.0 if max_step is None else max_step(x, x0 - x)  # CCD of the start, once
        if pred and fraction < 1.0:
            # the predictor would pass through a contact (IPC): start from the last equilibrium
            # with only the prescribed DOFs moved to the target (Newton moves only free DOFs,
            # so they must be at the target from the start)
            x0, pred = problem.held(x, target), 0
            fraction = max_step(x, x0 - x)
        if fraction < 1.0:
            # the prescribed DOFs alone would cross a contact: a smaller load increment
            ds /= 2
            log.info("load factor %.4g: the prescribed motion crosses a contact; halving the "
                     "increment to %.3g", target, ds)
            if ds < min_load_step:
                total.message = (f"stalled at load factor {s:.4g}: the prescribed displacement "
                                 "drives a body through a contact")
                break
            continue
        res = newton_minimize(
            lambda y: model.energy(y, target),
            lambda y, proj: model.linearize(y, target, project=proj),
            x0,
            free,
            rtol=rtol,
            g_scale=target * g_scale_full,
            max_iter=max_iter,
            linear_solver=solver,
            near_null=near_null,
            pattern=pattern,
            energy_roundoff=e_noise,
            project=project,
            g_floor=g_floor,
            gradient=lambda y: model.gradient(y, target),
            min_iter=0 if pred else 1,
            max_step=max_step, saddle_extension=saddle_extension_safe(model),
            hessian_constant=bool(getattr(model, "quadratic", False)),
        )
        total.iterations += res.iterations + pred
        total.residual_history.extend(res.residual_history)
        total.line_search_cuts += res.line_search_cuts
        total.linear_iterations += res.linear_iterations
        for k, v in res.seconds.items():
            total.seconds[k] += v
        if res.converged:
            x, s = res.x, target
            total.load_steps.append(s)
            point = problem.point(x, s, res.iterations + pred)
            total.path.append(point)
            checked(point)
            if res.iterations <= 5:
                ds = min(2 * ds, max_ds)
            log.info("load factor %.4g reached in %d Newton iterations", s, res.iterations)
        else:
            failed = (res.x, target)
            ds /= 2
            log.info("load factor %.4g failed (%s); halving the increment to %.3g", target, res.message, ds)
            if ds < min_load_step:
                total.message = (
                    f"stalled at load factor {s:.4g}: the increment fell below {min_load_step:.3g} "
                    f"(last failure: {res.message})"
                )
                break
    total.load_factor = s
    total.converged = s >= 1.0
    if total.converged and not total.message:
        total.message = (f"converged in {len(total.load_steps)} load step(s), "
                         f"{total.iterations} Newton iterations")
    if total.converged and stability:
        lu = _ls._FACTORS.lu
        x = _check_final(model, problem, total, x, free, near_null, stabilize, solver, pattern,
                         last_check.get("ec"), lu if lu is not lu_before else None,
                         dict(rtol=rtol, max_iter=max_iter, g_scale=g_scale_full, energy_roundoff=e_noise,
                              g_floor=g_floor, project=project))
    last = total.path[-1]
    total.x = x
    total.displacement = model.to_vertices(x - model.X)
    total.reactions, total.reaction_dofs = last.reactions, last.reaction_dofs
    total.wall_time = time.perf_counter() - t_start
    if check and not total.converged:
        x_failed, s_failed = failed if failed is not None else (x, total.load_factor)
        diagnosis = _diagnose_failure(model, x_failed, total, s_failed)
        raise NotConverged(
            f"solve_static did not reach the full load: {total.message}. "
            + (f"{diagnosis} " if diagnosis else "")
            + "Try more Newton iterations (max_iter=...), a smaller first load step "
            "(initial_load_step=0.1)"
            + (", or check that the load is physically attainable for this material." if not diagnosis
               else "."),
            result=total,
        )
    return total


def _diagnose_failure(model, x, total, load_factor=None) -> str:
    """The cause of a failed load path, where one can be named (before the generic advice).

    ``x`` is the last failed attempt's iterate (at ``load_factor``, default the
    result's), where an inversion shows, not the last converged state.
    """
    load_factor = total.load_factor if load_factor is None else load_factor
    from ..physics.inversion import DetF

    try:
        det_f = DetF(model)
        J = det_f(x)
    except (ValueError, FloatingPointError):  # pragma: no cover - a state too broken to measure
        return ""
    if not np.all(np.isfinite(x)):
        return "The last iterate is not finite."
    bad = int(np.sum(J <= 0))
    if bad:
        return (f"At load factor {load_factor:.4g}, {bad} {det_f.where} have det F <= 0 "
                f"(min {float(J.min()):.3g}): the load inverts elements, which this material "
                "cannot follow; a finer mesh, order=2, or a material that allows inversion "
                "(fe.StableNeoHookean) may carry it.")
    if "inadmissible" in total.message or "not finite" in total.message:
        return ("The energy is not finite at the start of the step: an element is inverted or "
                "flattened in the reference or prescribed state (check the mesh and the prescribed "
                "displacements).")
    if "collision-free" in total.message:
        return "Bodies intersect at the start of the step (check the obstacles' positions)."
    return ""


def _eigen(model, x, s, free, near_null, total, factor=None):
    """The stability check at (x, s), timed into ``total.seconds['stability']``.

    ``factor``: the LU the last Newton solve left (a preconditioner that costs
    nothing); without one, large models get AMG on the projected tangent.
    """
    t0 = time.perf_counter()
    _, K = model.linearize(x, s, project=False)

    def K_psd():  # only if AMG on the exact tangent fails
        return model.linearize(x, s, project=True)[1]

    if factor is not None and getattr(factor, "shape", (model.ndofs,) * 2) != (model.ndofs,) * 2:
        factor = None
    ec = lowest_eigenpair(K, free, near_null=near_null, factor=factor, K_psd=K_psd)
    total.seconds["stability"] += time.perf_counter() - t0
    log.info("stability: lowest tangent eigenvalue %.6g N/m (%s, %.3g s)", ec.value, ec.method, ec.seconds)
    return ec


def _check_final(model, problem, total, x, free, near_null, stabilize, solver, pattern, ec, factor, kw):
    """Check the final equilibrium's stability; perturb it when asked. Returns the final x."""
    if ec is None:
        ec = _eigen(model, x, 1.0, free, near_null, total, factor)
    tries = 0
    size = float(np.ptp(model.X.reshape(-1, 3), axis=0).max())
    while ec.stable is False and stabilize and tries < 4:
        tries += 1
        # an amplitude of 1e-3 of the body's size at the largest nodal motion, x10 per retry
        amp = 10.0 ** (tries - 4) * size / max(float(np.abs(ec.vector).max()), 1e-300)
        best = None
        for sign in (1.0, -1.0):
            x0 = x + sign * amp * ec.vector
            e0 = model.energy(x0, 1.0)
            if math.isfinite(e0) and (best is None or e0 < best[1]):
                best = (x0, e0)
        if best is None:
            continue
        e_saddle = model.energy(x, 1.0)
        res = newton_minimize(
            lambda y: model.energy(y, 1.0),
            lambda y, proj: model.linearize(y, 1.0, project=proj),
            best[0], free, linear_solver=solver, near_null=near_null, pattern=pattern,
            gradient=lambda y: model.gradient(y, 1.0), min_iter=1,
            max_step=_contact_max_step(model), saddle_extension=saddle_extension_safe(model), **kw,
        )
        total.iterations += res.iterations
        total.residual_history.extend(res.residual_history)
        if not res.converged or not model.energy(res.x, 1.0) < e_saddle:
            continue
        x = res.x
        total.perturbations = tries
        total.path[-1] = problem.point(x, 1.0, res.iterations)
        ec = _eigen(model, x, 1.0, free, near_null, total)
        if ec.stable:
            total.message += ("; the unstable equilibrium was perturbed along its lowest mode "
                              "and settled in a stable one")
    point = total.path[-1]
    point.min_eigenvalue, point.stable = ec.value, ec.stable
    total.min_eigenvalue, total.stable = ec.value, ec.stable
    total.buckling_mode = model.to_vertices(ec.vector)
    if ec.stable is None:
        log.warning("solve_static: the stability check found no eigenvalue (no eigensolver "
                    "converged); result.stable is None")
    elif not ec.stable:
        warnings.warn(
            f"solve_static converged to an unstable equilibrium: the lowest eigenvalue of the "
            f"tangent on the free DOFs is {ec.value:.4g} N/m < 0, so the state is a saddle of the "
            "energy (e.g. a straight column beyond its buckling load), not a minimum. "
            + ("Perturbing it did not reach a stable state. " if stabilize else
               "Pass stabilize=True to perturb it along its lowest mode and reach a stable one. ")
            + "result.buckling_mode holds the mode.",
            UnstableEquilibrium, stacklevel=3,
        )
    return x


def load_path(model: AnyModel, steps: int = 10, **kwargs: Unpack[StaticOptions]) -> LoadPath:
    """The converged points of ``solve_static(model, steps=steps, **kwargs)``: a :class:`LoadPath`.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), 1000.0,
    ...                  fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)),
    ...                  fixed="left", traction={"right": (0.0, 0.0, -100.0)})
    >>> path = fe.load_path(model, steps=4)
    >>> len(path), float(path.load_factors[-1])
    (5, 1.0)
    """
    return solve_static(model, steps=steps, **kwargs).path
