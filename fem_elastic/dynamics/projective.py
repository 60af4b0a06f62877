"""Projective dynamics: implicit Euler by a local/global solver with one factorised matrix.

Bouaziz, Martin, Liu, Kavan and Pauly (2014) write the elastic energy as a
sum of squared distances of linear functions of the positions to
constraint sets, ``E(x) = sum_i w_i / 2 ||A_i x - p_i||^2`` with ``p_i``
the projection of ``A_i x`` onto set ``i``. Here ``A_i x`` is the
deformation gradient F at a quadrature point (one per P1 tet) and the sets
are the corotated strain (``F -> R``, weight ``2 mu dV``) and the volume
constraint (mean stretch in a band, weight ``3 lam dV``) of
:class:`fe.ProjectiveCorotated`, whose module derives the weights from
(E, nu). One implicit Euler step minimises

    G(x) = 1/(2 h^2) ||x - y||_M^2 + E(x) - f_ext . x,      y = x_n + h v_n,

by alternating

- the **local step**: ``p_i = P_i(A_i x)`` for every point at once (a
  batched signed SVD, :func:`fem_elastic.materials.svd.signed_svd`), and
- the **global step**: the quadratic ``G`` with the ``p_i`` frozen,
  ``B x = M y / h^2 + sum_i w_i A_i^T p_i + f_ext`` with

      B = M / h^2 + sum_i w_i A_i^T A_i = (M_s / h^2 + (2 mu + 3 lam) L) (x) I_3,

  ``L`` the scalar stiffness ("Laplacian") ``int grad N_a . grad N_b dV`` and
  ``M_s`` the scalar (lumped or consistent) mass: B does not depend on x, so
  it is factorised once per model and dt (CHOLMOD's sparse Cholesky where
  scikit-sparse is installed, else SuperLU's LU; on the free DOFs, the held
  ones eliminated), and its three coordinate blocks are the same matrix, so one
  factorisation of a nodes-by-nodes matrix serves x, y and z.

The global step is computed in its residual form ``x <- x - B^-1 dG/dx(x)``,
which is algebraically the same (``dG/dx = B x - rhs(p(x))``) and lets the
terms that are not projective enter ``dG/dx`` with their exact gradient:
Rayleigh damping ``C (x - x_n) / h`` (``C = alpha M + beta K(x_n)``, frozen at the
step's start as implicit Euler does; ``alpha M / h`` and ``beta (2 mu + 3
lam) L / h``, an upper bound of ``beta K / h`` for ``lam >= 0``, are added
to B, so B stays constant) and penalty or barrier contact (lagged: their
stiffness is not in B; the impulse method, applied after the step, suits
the scheme better). Dead loads (gravity, tractions) are exact.

The iteration is block-coordinate descent on ``G(x, p)``: it never raises
G while the projections are nearest points (R is always the nearest
rotation), and a fixed point is a stationary point of G, because the
gradient of ``1/2 ||F - P(F)||^2`` is ``F - P(F)``. As the iterations grow, a
step therefore converges to the implicit Euler step of the same energy,
``fe.ImplicitEuler`` on a body of :class:`fe.ProjectiveCorotated` (or
:class:`fe.Corotated`, the same energy with the default band):
``tests/test_projective_dynamics.py`` fits the linear rate and reaches 1e-6
relative. The rate is slow where B is a poor model of the tangent: stiff,
bending-dominated or nearly incompressible steps (B carries the volume
weight ``3 lam`` in every direction, the true tangent only in the
volumetric one). A few iterations give the method's characteristic look:
stable at any dt, softer than the converged step.

On a body of another material (Neo-Hookean, ...) the scheme minimises the
projective corotated energy with that material's (E, nu) instead (logged
once per model): the model's own energy is then only what the diagnostics record.
"""

from __future__ import annotations

import logging
import math
import numbers
import time
import weakref
from typing import TYPE_CHECKING, Literal

import numpy as np
import scipy.sparse as sp

from ..errors import Diverged, InvalidParameter
from ..materials import Corotated, Material, ProjectiveCorotated
from ..physics.elastic_body import ElasticPotential
from ..solvers.cholmod import spd_factor
from .integrators.base import Integrator, StepStats, check_dt, check_state
from .position_based.base import check_one_body
from .state import State

if TYPE_CHECKING:  # for annotations only
    from ..physics.multibody import AnyModel

__all__ = ["ProjectiveDynamics"]

log = logging.getLogger(__name__)

#: Factorisations kept per integrator (one per dt and set of held DOFs in use).
_CACHE_SIZE = 4


class _Setup:
    """What projective dynamics needs of a model, built once per model: not a setting."""

    def __init__(self, model):
        check_one_body(model, "projective dynamics")
        body = model.body_potential
        material = getattr(body, "material", None)
        if not isinstance(body, ElasticPotential) or not isinstance(material, Material):
            raise InvalidParameter(
                "projective dynamics needs a finite element body, fe.ElasticBody(material), e.g. "
                f"fe.ElasticBody(fe.Corotated(E=1e6, nu=0.3)); got {type(body).__name__}."
            )
        if isinstance(material, ProjectiveCorotated) or type(material) is Corotated:
            pd = material  # a corotated body's energy is the projective one with the band [1, 1]
        else:
            pd = ProjectiveCorotated(mu=material.mu, lam=material.lam)  # exact, no (E, nu) round trip
            log.info("projective dynamics on a %s body minimises the projective corotated "
                     "energy with its Lame parameters, not the body's own energy", type(material).__name__)
        if pd.lam < 0.0:
            raise InvalidParameter(
                f"projective dynamics needs a non-negative volume weight 3 lam, i.e. nu >= 0; the "
                f"body has nu = {material.nu!r} (lam = {pd.lam:.4g} Pa). Use nu >= 0 or fe.ImplicitEuler."
            )
        self.material = pd
        self.potential = ElasticPotential(pd, model.space)
        space = model.space
        nodes = space.element_dofs[0::3] // 3  # (nloc, ne) scalar nodes of each element
        n = space.ndofs // 3
        # L_ab = int grad N_a . grad N_b dV, one scalar block for the three coordinates
        Ke = np.einsum("ajeq,bjeq,eq->abe", space.dN, space.dN, space.dx, optimize=True)
        nl = nodes.shape[0]
        rows = np.broadcast_to(nodes[:, None, :], (nl, nl, nodes.shape[1])).ravel()
        cols = np.broadcast_to(nodes[None, :, :], (nl, nl, nodes.shape[1])).ravel()
        self.laplacian = sp.csr_matrix((Ke.ravel(), (rows, cols)), shape=(n, n))
        self.weight = 2.0 * pd.mu + 3.0 * pd.lam  # Pa: sum of the constraint weights per volume
        self.lumped = model.lumped_mass[0::3].copy()
        self._consistent = None
        self._model = model

    def scalar_mass(self, mass: str):
        """The scalar mass matrix (kg): lumped as a vector, consistent as CSR."""
        if mass == "lumped":
            return self.lumped
        if self._consistent is None:
            self._consistent = sp.csr_matrix(self._model.mass_matrix[0::3, 0::3])
        return self._consistent


def _check_int(name, value, low):
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < low:
        raise InvalidParameter(f"{name} must be an integer >= {low}, got {value!r}.")
    return int(value)


class ProjectiveDynamics(Integrator):
    """Implicit Euler by projective dynamics' local/global iterations (see the module notes).

    Parameters
    ----------
    iterations : int
        Local/global iterations per step (the most, with ``tol``), >= 1.
    tol : float
        Stop early when an iteration moves the free DOFs by at most ``tol``
        times the step's displacement ``||x - x_n||`` (max norms); 0 (the
        default) always runs ``iterations``, as the paper does.
    mass : {"lumped", "consistent"}
        Mass matrix in the inertia term (and in B).

    Attributes
    ----------
    factorizations : int
        Sparse LU factorisations done so far (one per model, dt and set of
        held DOFs; a cache, never checkpointed).
    last_stats : StepStats
        ``newton_iterations`` and ``gradient_evaluations`` count the
        local/global iterations; ``seconds["linearize"]`` is the local steps'
        time, ``seconds["solve"]`` the global solves' (and any factorisation).

    Examples
    --------
    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.Corotated(E=1e5, nu=0.3)),
    ...                  fixed="left", gravity=(0, 0, -9.81))
    >>> pd = fe.ProjectiveDynamics(iterations=20)
    >>> run = fe.simulate(model, pd, dt=0.01, steps=3)
    >>> pd.factorizations, int(run.step_stats["newton_iterations"][0])
    (1, 20)
    """

    explicit = False
    order = 1

    def __init__(self, iterations: int = 10, tol: float = 0.0,
                 mass: Literal["lumped", "consistent"] = "lumped") -> None:
        super().__init__()
        self.iterations = _check_int("iterations", iterations, 1)
        if isinstance(tol, bool) or not isinstance(tol, numbers.Real) or not math.isfinite(tol) or tol < 0:
            raise InvalidParameter(f"tol must be a finite number >= 0, got {tol!r}; e.g. tol=1e-6.")
        self.tol: float = float(tol)
        if mass not in ("lumped", "consistent"):
            raise InvalidParameter(f"mass must be 'lumped' or 'consistent', got {mass!r}.")
        self.mass: str = mass
        self._model_ref: weakref.ref | None = None  # weak reference to the model the caches below are of
        self._setup: _Setup | None = None
        self._factors: dict[tuple, tuple] = {}  # (dt, mass, held DOFs) -> (free mask per coordinate, solvers)
        self._factorizations: int = 0

    def __repr__(self) -> str:
        return f"fe.ProjectiveDynamics(iterations={self.iterations}, tol={self.tol:g}, mass={self.mass!r})"

    @property
    def factorizations(self) -> int:
        """Sparse LU factorisations of the global matrix done by this integrator so far."""
        return self._factorizations

    # caches ----------------------------------------------------------------------------
    def _setup_for(self, model) -> _Setup:
        if self._model_ref is None or self._model_ref() is not model:
            self._setup = _Setup(model)
            self._factors = {}
            self._model_ref = weakref.ref(model)
        assert self._setup is not None  # set together with self._model_ref
        return self._setup

    def _damping_coefficients(self, model):
        d = model.damping
        return (0.0, 0.0) if d is None else (float(d.alpha or 0.0), float(d.beta or 0.0))

    def _solvers(self, model, setup, h, free):
        """(free mask (n, 3), solve(rhs (n, 3)) -> (n, 3) on the free entries), factorised once."""
        key = (float(h).hex(), self.mass, free.tobytes())
        hit = self._factors.get(key)
        if hit is not None:
            return hit
        alpha, beta = self._damping_coefficients(model)
        M = setup.scalar_mass(self.mass)
        mass_factor = 1.0 / (h * h) + alpha / h
        Mpart = sp.diags(M * mass_factor) if self.mass == "lumped" else M * mass_factor
        B = sp.csr_matrix(Mpart + ((1.0 + beta / h) * setup.weight) * setup.laplacian)
        free3 = free.reshape(-1, 3)
        lus = {}
        for c in range(3):
            cols = free3[:, c]
            k = cols.tobytes()
            if k not in lus:
                idx = np.flatnonzero(cols)
                if idx.size == 0:
                    lus[k] = None
                    continue
                Bff = B[idx][:, idx].tocsr()
                # SPD: CHOLMOD's Cholesky where installed, else SuperLU (solvers.cholmod)
                lus[k] = spd_factor(Bff, "the projective-dynamics matrix")
                self._factorizations += 1
        solvers = [lus[free3[:, c].tobytes()] for c in range(3)]
        if len(self._factors) >= _CACHE_SIZE:
            self._factors.pop(next(iter(self._factors)))
        self._factors[key] = (free3, solvers)
        return self._factors[key]

    # the step --------------------------------------------------------------------------
    def step(self, model: AnyModel, state: State, dt: float) -> State:
        h = check_dt(dt)
        check_state(model, state)
        stats = self.last_stats = StepStats()
        setup = self._setup_for(model)
        t1 = state.t + h
        dofs, xc, _ = model.constraints(t1)
        free = np.ones(model.ndofs, dtype=bool)
        free[dofs] = False
        t0 = time.perf_counter()
        free3, solvers = self._solvers(model, setup, h, free)
        stats.seconds["solve"] += time.perf_counter() - t0

        m = setup.lumped if self.mass == "lumped" else None
        Ms = setup.scalar_mass(self.mass)
        y = state.x + h * state.v
        x = y.copy()
        x[dofs] = xc
        f_ext = model.external_force()
        C = model.damping_matrix(state.x, self.mass)
        inv_h2 = 1.0 / (h * h)
        pot = setup.potential
        contacts = model.contacts
        bound = getattr(model, "contact", None)
        max_step = model.max_step if getattr(bound, "kind", None) == "potential" else None
        if max_step is not None and max_step(state.x, x - state.x) < 1.0:
            x = state.x.copy()  # the inertial prediction passes through a contact: start at x_n
            x[dofs] = xc
        for k in range(self.iterations):
            t0 = time.perf_counter()
            g = pot.gradient(x) - f_ext  # the local step (projections) and the elastic gradient
            for term in contacts:
                g += term.gradient(x)
            d = (x - y).reshape(-1, 3)
            inertia = (m[:, None] * d) if m is not None else Ms @ d
            g += inertia.ravel() * inv_h2
            if C is not None:
                g += (C @ (x - state.x)) / h
            stats.seconds["linearize"] += time.perf_counter() - t0
            stats.gradient_evaluations += 1
            if not np.all(np.isfinite(g)):
                raise Diverged(
                    f"ProjectiveDynamics failed at t = {state.t:.6g} s: the gradient became "
                    f"non-finite at iteration {k + 1}. Try a smaller dt or more damping.",
                    time=state.t, reason="non-finite gradient", last_good_state=state,
                )
            t0 = time.perf_counter()
            dx = self._global_solve(g.reshape(-1, 3), free3, solvers)
            if max_step is not None:  # IPC: never step into intersection (CCD)
                dx = dx * max_step(x, dx.ravel())
            x += dx.ravel()
            stats.seconds["solve"] += time.perf_counter() - t0
            stats.newton_iterations += 1
            if self.tol > 0.0:
                moved = np.abs(dx).max(initial=0.0)
                if moved <= self.tol * np.abs(x - state.x).max(initial=0.0):
                    break
        return self._finish(model, x, (x - state.x) / h, t1)

    @staticmethod
    def _global_solve(g3, free3, solvers):
        """``-B_ff^-1 g`` per coordinate (one LU for all three when they hold the same DOFs)."""
        dx = np.zeros_like(g3)
        if solvers[0] is solvers[1] is solvers[2] and solvers[0] is not None:
            idx = free3[:, 0]
            dx[idx] = -solvers[0].solve(np.ascontiguousarray(g3[idx]))
            return dx
        for c in range(3):
            if solvers[c] is not None:
                idx = free3[:, c]
                dx[idx, c] = -solvers[c].solve(np.ascontiguousarray(g3[idx, c]))
        return dx
