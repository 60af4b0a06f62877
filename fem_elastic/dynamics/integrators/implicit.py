"""Implicit Euler as energy minimisation, and its one-Newton-step linearization.

Implicit (backward) Euler, ``v1 = v + h M^-1 f(x1, v1)``, ``x1 = x + h v1``,
is the minimiser of the incremental potential (see
:mod:`fem_elastic.dynamics.integrators.incremental`)

    G(x) = 1/(2 h^2) ||x - (x_n + h v_n)||_M^2 + Pi(x) + 1/(2h) ||x - x_n||_C^2,

found by the Newton solver of the static problem, with backtracking line
search, to a tolerance (the lecture notes' Algorithm 2). It is
unconditionally stable and dissipates energy (first order).

Many engines take a single Newton step per time step instead (Baraff and
Witkin 1998): :class:`LinearizedImplicitEuler`. It costs one assembly and
one linear solve, and is exact for linear forces; for a corotated body it
is the stiffness-warping scheme (element stiffness precomputed once,
rotations from the polar decomposition each step).
"""

from __future__ import annotations

import logging
import math
import time
from typing import TYPE_CHECKING, Literal

import numpy as np

from ...errors import Diverged, InvalidParameter
from ...solvers.linear_solvers import AutoSolver, as_linear_solver
from ...materials import Corotated
from ...physics.impulse_contact import reject_impulse_contact
from ...solvers.newton import NewtonResult, _direction, newton_minimize, saddle_extension_safe
from ...solvers.petsc_solver import PETScSolver
from ...solvers.static import _contact_max_step
from ..state import State
from .base import Integrator, StepStats, check_dt, check_state
from .incremental import IncrementalPotential

if TYPE_CHECKING:  # for annotations only
    from ...physics.multibody import AnyModel
    from ...solvers.solver_types import LinearSolver

__all__ = ["ImplicitEuler", "LinearizedImplicitEuler"]

_DRIVEN_THROUGH_CONTACT = (
    "the driven boundary's motion over the step carries a surface through a contact (IPC's "
    "continuous collision detection); a shorter step moves it less"
)
_INVERTED_AT_START = (
    "an element is inverted at the start of the step (in the state given, or by the prescribed "
    "boundary motion over one step), where the body's energy is not defined"
)
log = logging.getLogger(__name__)


def _check_mass(mass):
    if mass not in ("lumped", "consistent"):
        raise InvalidParameter(f"mass must be 'lumped' or 'consistent', got {mass!r}.")
    return mass


#: Most halvings of a step (2^20 ~ 1e6 sub-steps at worst): beyond, lower dt.
MAX_DT_CUTS = 20

class _Implicit(Integrator):
    """Shared: constraints at the end of the step and step cutting on failure."""

    explicit = False

    def __init__(self, mass: Literal["lumped", "consistent"] = "lumped", max_dt_cuts: int = 4,
                 linear_solver: LinearSolver | str | None = None) -> None:
        super().__init__()
        self.mass = _check_mass(mass)
        if linear_solver is not None:  # a name ("auto", "direct", "amg", "cholmod") or an object
            linear_solver = as_linear_solver(linear_solver)  # with solve(); InvalidParameter else
        if (isinstance(max_dt_cuts, bool) or not isinstance(max_dt_cuts, int)
                or not 0 <= max_dt_cuts <= MAX_DT_CUTS):
            # bounded: k halvings can cost 2^k sub-steps for one step
            raise InvalidParameter(
                f"max_dt_cuts must be an integer from 0 to {MAX_DT_CUTS}, got {max_dt_cuts!r} (each cut halves "
                f"dt, so {MAX_DT_CUTS} cuts already allow steps 2^{MAX_DT_CUTS} = {2 ** MAX_DT_CUTS:.2g} times "
                "smaller); lower dt instead.")
        self.max_dt_cuts = max_dt_cuts
        self.linear_solver = linear_solver

    def step(self, model: AnyModel, state: State, dt: float) -> State:
        h = check_dt(dt)
        check_state(model, state)
        reject_impulse_contact(model, f"fe.{self.name}")
        stats = self.last_stats = StepStats()
        out, why = self._cut_step(model, state, h, 0, stats)
        if out is None:
            hint = "Try a smaller dt, more Newton iterations, or a softer/less extreme scene."
            if why.startswith("Newton did not converge (no convergence") \
                    and _contact_max_step(model) is not None:
                # halving dt does not shorten an IPC impact: every Newton step is bounded by the
                # CCD, and the gap still closes, over decades with kappa = "auto" (67 iterations
                # for the 21,870-tet drop of scripts/bench_ipc.py; 18 with the scene's 1e7)
                spec = getattr(model.contact, "spec", None)
                auto = " ('auto' keeps them far closer)" if getattr(spec, "kappa", None) == "auto" else ""
                hint = (f"An impact under IPC contact takes many CCD-bounded Newton iterations, "
                        f"whatever the step: raise max_iter (e.g. fe.{self.name}(max_iter=200); "
                        "[integrator] max_iter = 200 in a scene), or stiffen the barrier "
                        "(fe.IPCContact(kappa=...): Newton needs fewer iterations where resting "
                        f"bodies stay a tenth of dhat apart or more{auto}). Else "
                        + hint[0].lower() + hint[1:])
            raise Diverged(
                f"{self.name} failed at t = {state.t:.6g} s even after halving dt {self.max_dt_cuts} "
                f"times (to {h / 2 ** self.max_dt_cuts:.3g} s): {why}. {hint}",
                time=state.t, reason=why, last_good_state=state,
            )
        return out

    def _cut_step(self, model, state, h, depth, stats):
        """Try one step of h; on failure two of h/2, recursively to max_dt_cuts levels."""
        out, why = self._try(model, state, h, stats)
        if out is not None:
            return out, why
        stats.cuts.append((float(state.t), float(h), why))  # every failed attempt, the last one too
        if depth >= self.max_dt_cuts:
            return None, why
        stats.dt_cuts += 1
        log.info("%s: step at t=%.6g s with dt=%.3g s failed (%s); halving", self.name, state.t, h, why)
        mid, why = self._cut_step(model, state, h / 2, depth + 1, stats)
        if mid is None:
            return None, why
        stats.substeps += 1
        return self._cut_step(model, mid, h / 2, depth + 1, stats)

    @staticmethod
    def _start(model, state, h):
        """The held DOFs at t + h, the free mask, and the prescribed values."""
        dofs, xc, vc = model.constraints(state.t + h)
        free = np.ones(model.ndofs, dtype=bool)
        free[dofs] = False
        return free, dofs, xc, vc

    def _solver_settings(self, model):
        return dict(
            linear_solver=self.linear_solver,
            near_null=model.rigid_body_modes,
            pattern=model.space.pattern,
            max_step=_contact_max_step(model),
            saddle_extension=saddle_extension_safe(model),
        )


def _count_newton(stats, res) -> None:
    """Add a Newton solve's statistics (serial or distributed) to the step's."""
    stats.newton_iterations += res.iterations
    stats.line_search_cuts += res.line_search_cuts
    stats.linear_iterations += res.linear_iterations
    stats.linear_solves += res.linear_solves
    stats.linear_setups += res.linear_setups
    stats.extensions += res.extensions
    for k, v in res.seconds.items():
        stats.seconds[k] = stats.seconds.get(k, 0.0) + v


_PETSC_VELOCITY_TOL = (
    "velocity_tol is a rule of the serial Newton; the distributed one (fe.PETScSolver) converges "
    "on the force alone: leave velocity_tol at 0 or solve serially.")


class ImplicitEuler(_Implicit):
    """Backward Euler by minimising the incremental potential with Newton.

    Parameters
    ----------
    rtol : float
        Newton stops when the out-of-balance force of G on the free DOFs is
        below ``rtol`` times the step's force scale (the larger of the
        momentum flux ``||M v_n|| / h``, the external load and the
        out-of-balance force at the first guess), or at the round-off floor of G (the
        body's, plus the inertia term's ``eps ||m |x| || / h^2``).
    max_iter : int
        Most Newton iterations per (sub-)step. An impact under IPC contact
        (``fe.IPCContact``) needs more than the default: every Newton step is
        bounded by the CCD while the gap closes from dhat to the barrier's
        equilibrium (the 21,870-tet drop of ``scripts/bench_ipc.py`` takes 67
        on its impact step); give 200 there.
    mass : {"lumped", "consistent"}
        Mass matrix in the inertia term.
    max_dt_cuts : int
        When Newton fails, the step is retried as two halves, recursively
        up to this many times; then :class:`fe.Diverged` is raised.
    project : bool
        PSD-projected Hessian away from the solution (see :mod:`fem_elastic.solvers.newton`).
    linear_solver : object or str, optional
        ``fe.DirectSolver()``, ``fe.AMGSolver()``, or a name (``"direct"``, ``"amg"``,
        ``"auto"``, ``"cholmod"``); default ``fe.AutoSolver()``. ``fe.PETScSolver()``
        (``"petsc"``) solves each step across MPI ranks (``mpiexec -n N``;
        :mod:`fem_elastic.solvers.distributed_newton`; no contact or damping there).
    velocity_tol : float
        Velocity tolerance (m/s), off at 0 (the default: the force rule of
        ``rtol`` alone). Newton also stops after a whole Newton step (not cut
        by the line search or the CCD) that moves no DOF by more than
        ``velocity_tol * h`` (``velocity_tol * h / 2`` for fe.Newmark and
        fe.Trapezoid, whose end velocity is ``2 (x1 - x0) / h - v0``), taken on
        the exact tangent: the rule of IPC (Li et al. 2020) and libuipc.
        Newton is then in its quadratic regime, and the end velocity lies
        within about ``velocity_tol`` of the force-converged one. It spares
        the last iterations of a step (``scripts/bench_ipc.py
        --velocity-tol``: a sixth of the IPC drop's time). Serial solves only
        (not with ``fe.PETScSolver``).

    Examples
    --------
    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
    ...                  fixed="left", gravity=(0, 0, -9.81))
    >>> ie = fe.ImplicitEuler()
    >>> s = ie.step(model, fe.State.rest(model), 0.01)
    >>> s.t, ie.last_stats.newton_iterations > 0
    (0.01, True)
    """

    order = 1
    #: position change (m) per unit of velocity change (m/s) at the step's end, over h: the
    #: scale of ``velocity_tol`` (x1 = x0 + h v1 here; Newmark and the trapezoid, whose
    #: v1 = 2 (x1 - x0) / h - v0, halve it)
    _step_per_velocity = 1.0

    def __init__(self, rtol: float = 1e-8, max_iter: int = 30,
                 mass: Literal["lumped", "consistent"] = "lumped", max_dt_cuts: int = 4,
                 project: bool = True, linear_solver: LinearSolver | str | None = None,
                 velocity_tol: float = 0.0) -> None:
        super().__init__(mass, max_dt_cuts, linear_solver)
        if not (isinstance(rtol, (int, float)) and 0 < rtol < 1):
            raise InvalidParameter(f"rtol must be in (0, 1), got {rtol!r}.")
        if (isinstance(velocity_tol, bool) or not isinstance(velocity_tol, (int, float))
                or not 0.0 <= velocity_tol < math.inf):
            raise InvalidParameter(
                f"velocity_tol must be a finite number >= 0 (m/s; 0 turns it off), got "
                f"{velocity_tol!r}.")
        self.velocity_tol = float(velocity_tol)
        if self.velocity_tol > 0.0 and self._distributed:
            raise InvalidParameter(_PETSC_VELOCITY_TOL)
        if isinstance(max_iter, bool) or not isinstance(max_iter, int) or max_iter < 1:
            raise InvalidParameter(f"max_iter must be an integer >= 1, got {max_iter!r}.")
        self.rtol, self.max_iter, self.project = float(rtol), max_iter, bool(project)

    def _objective(self, model, state, h):
        return IncrementalPotential(model, state.x + h * state.v, h, self.mass, state.x)

    def _velocity(self, state, x1, h):
        return (x1 - state.x) / h

    def _prediction(self, G, state, h):
        """The first guess of Newton (a new array), tried against the old positions: G's target y."""
        return G.y.copy()

    @property
    def _distributed(self) -> bool:
        """Whether the step runs across MPI ranks: fe.PETScSolver, for implicit Euler alone
        (Newmark and the trapezoid share this step but not its objective: they stay serial)."""
        return isinstance(self.linear_solver, PETScSolver) and type(self) is ImplicitEuler

    def _try(self, model, state, h, stats):
        if self._distributed:
            return self._try_distributed(model, state, h, stats)
        free, dofs, xc, vc = self._start(model, state, h)
        G = self._objective(model, state, h)
        # First guess: the inertial prediction y or the old positions, whichever has the lower
        # incremental potential. Starting no higher than x_n means the minimiser Newton reaches
        # has G(x_{n+1}) <= G(x_n), the discrete energy bound of implicit Euler; from y alone a
        # stiff body at a large dt can land in an inverted basin and gain energy.
        x0 = self._prediction(G, state, h)
        x0[dofs] = xc
        x_old = state.x.copy()
        x_old[dofs] = xc
        max_step = _contact_max_step(model)
        if (max_step is not None and np.any(x_old[dofs] != state.x[dofs])
                and max_step(state.x, x_old - state.x) < 1.0):
            # the driven DOFs' own motion over the step would carry a surface through a contact:
            # the solve would start intersecting; a shorter step (cut back) moves them less
            return None, _DRIVEN_THROUGH_CONTACT
        if max_step is not None and max_step(x_old, x0 - x_old) < 1.0:
            x0 = x_old  # the prediction would pass through a contact: start from the old positions
        g0, g_old = G.energy(x0), G.energy(x_old)
        if not math.isfinite(g0) or g_old < g0:
            x0, g0 = x_old, g_old
        if not math.isfinite(g0):
            return None, _INVERTED_AT_START
        scale = G.scale(state, free)
        # lagged friction (IPC): solve with the friction of the start of the step, re-lag at the
        # solution and solve again, friction_iterations times in all
        contact = model.contact if max_step is not None else None
        lag = getattr(contact, "lag_friction", None) if getattr(contact, "mu", 0.0) > 0 else None
        rounds = contact.spec.friction_iterations if lag is not None else 1
        if contact is not None and hasattr(contact, "begin_solve"):
            # IPC's kappa balances against the whole G; it is updated here, between steps,
            # from the minimum distance at the step's start
            contact.begin_solve(G.gradient, x=state.x)
        try:
            for r in range(rounds):
                if lag is not None:  # the first round lags at the start of the step
                    lag(state.x, x_old if r == 0 else x0, h)
                counted = _Counted(G)
                res = newton_minimize(
                    G.energy, counted.linearize, x0, free, rtol=self.rtol,
                    g_scale=scale if scale > 0 else None, max_iter=self.max_iter,
                    energy_roundoff=G.energy_roundoff(x0), project=self.project,
                    gradient=counted.gradient, g_floor=G.gradient_roundoff(x0),
                    step_tol=self.velocity_tol * h * self._step_per_velocity,
                    **self._solver_settings(model),
                )
                stats.gradient_evaluations += counted.calls
                _count_newton(stats, res)
                if not res.converged:
                    return None, f"Newton did not converge ({res.message})"
                x0 = res.x
        finally:
            if lag is not None:
                contact.clear_friction()
        x1 = res.x
        v1 = self._velocity(state, x1, h)
        return self._finish(model, x1, v1, state.t + h), ""

    def _try_distributed(self, model, state, h, stats):
        """One step across the MPI ranks (fe.PETScSolver): solvers.distributed_newton."""
        from ...solvers.distributed_newton import implicit_euler_step

        if self.velocity_tol > 0.0:  # (set after construction)
            raise InvalidParameter(_PETSC_VELOCITY_TOL)
        free, dofs, xc, vc = self._start(model, state, h)
        G = self._objective(model, state, h)
        x0 = self._prediction(G, state, h)  # the two first guesses, as serially
        x0[dofs] = xc
        x_old = state.x.copy()
        x_old[dofs] = xc
        scale = G.scale(state, free)
        x1, res = implicit_euler_step(
            model, self.linear_solver, G.y, h, self.mass, dofs, [x0, x_old], rtol=self.rtol,
            max_iter=self.max_iter, project=self.project, g_scale=scale if scale > 0 else None,
            energy_roundoff=G.energy_roundoff(G.y), g_floor=G.gradient_roundoff(G.y))
        _count_newton(stats, res)
        if not res.converged:
            return None, f"Newton did not converge ({res.message})"
        return self._finish(model, x1, self._velocity(state, x1, h), state.t + h), ""

    def step_matrix(self, h: float, omega: float, zeta: float = 0.0) -> np.ndarray:
        return np.linalg.inv(np.eye(2) - h * self._oscillator(omega, zeta))


class LinearizedImplicitEuler(_Implicit):
    """Implicit Euler with one Newton step per time step (Baraff and Witkin 1998).

    Solves ``(M / h^2 + K + C / h) dx = -dG/dx`` once from ``x_n`` (held
    DOFs at their new prescription) and takes ``x1 = x_n + dx`` with no
    line search. Exact for linear forces; for nonlinear ones it is first
    order with an error that grows with h (compare with :class:`ImplicitEuler`).

    With a :class:`fe.Corotated` body and ``warping=True`` (the default),
    K and the elastic force come from stiffness warping: the linear element
    stiffness ``K_e`` is computed once and each step uses
    ``f_e = -R_e K_e (R_e^T x_e - X_e)``, ``K = sum R_e K_e R_e^T`` with the
    element rotations ``R_e`` of the polar decomposition of F (the
    real-time physics notes' corotated FEM). Otherwise K is the model's
    Hessian at ``x_n``, PSD-projected if ``project``.

    Parameters
    ----------
    mass : {"lumped", "consistent"}
    project : bool
        Project the tangent to PSD (keeps the system positive definite under compression).
    warping : bool
        Use stiffness warping for a corotated body.
    linear_solver : object, optional

    Examples
    --------
    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.Corotated(E=1e5, nu=0.3)),
    ...                  fixed="left", gravity=(0, 0, -9.81))
    >>> li = fe.LinearizedImplicitEuler()
    >>> s = li.step(model, fe.State.rest(model), 0.01)
    >>> li.last_stats.newton_iterations
    1
    """

    order = 1

    def __init__(self, mass: Literal["lumped", "consistent"] = "lumped", project: bool = True,
                 warping: bool = True, linear_solver: LinearSolver | str | None = None) -> None:
        super().__init__(mass, 0, linear_solver)
        self.project, self.warping = bool(project), bool(warping)

    def _warped(self, model):
        """The model's warped stiffness if the scheme is stiffness warping, else None."""
        material = getattr(model.body_potential, "material", None)
        if self.warping and isinstance(material, Corotated):
            return model.warped_stiffness
        return None

    def _try(self, model, state, h, stats):
        free, dofs, xc, vc = self._start(model, state, h)
        G = IncrementalPotential(model, state.x + h * state.v, h, self.mass, state.x)
        x0 = state.x.copy()
        x0[dofs] = xc
        t0 = time.perf_counter()
        # the model's terms, with the warped stiffness in place of the body's for stiffness warping
        try:
            model_terms = model.linearize(x0, project=self.project, body=self._warped(model))
            g, H = G.linearize(x0, project=self.project, body=model_terms)
        except np.linalg.LinAlgError:  # the PSD projection of a tangent with NaN in it
            return None, _INVERTED_AT_START
        stats.seconds["linearize"] += time.perf_counter() - t0
        if not (np.isfinite(g).all() and np.isfinite(H.data).all()):
            return None, _INVERTED_AT_START  # e.g. log J of an inverted Neo-Hookean element
        stats.gradient_evaluations += 1
        g = np.where(free, g, 0.0)
        solve = NewtonResult(x=x0, converged=False, iterations=1)  # collects the solve's figures
        dx, _ = _direction(self.linear_solver or AutoSolver(), H, g, free, model.space.pattern,
                           model.rigid_body_modes * free[:, None], solve)
        stats.seconds["solve"] += solve.seconds["solve"]
        stats.linear_iterations += solve.linear_iterations
        stats.linear_solves += solve.linear_solves
        stats.linear_setups += solve.linear_setups
        stats.newton_iterations += 1
        x1 = x0 + dx
        if not np.all(np.isfinite(x1)):
            return None, "the linear solve gave a non-finite update"
        return self._finish(model, x1, (x1 - state.x) / h, state.t + h), ""

    def step_matrix(self, h: float, omega: float, zeta: float = 0.0) -> np.ndarray:
        return np.linalg.inv(np.eye(2) - h * self._oscillator(omega, zeta))


class _Counted:
    """The objective's gradient and linearization, counting the residual evaluations."""

    def __init__(self, G):
        self.G, self.calls = G, 0

    def gradient(self, x):
        self.calls += 1
        return self.G.gradient(x)

    def linearize(self, x, project=True):
        self.calls += 1
        return self.G.linearize(x, project)
