"""Extended position-based dynamics (Macklin, Mueller and Chentanez 2016) with physical compliance.

XPBD gives each constraint a compliance ``alpha`` (the inverse stiffness of
its energy ``U = C^2 / (2 alpha)``) and a multiplier ``lam``, reset to zero at
every step; each projection (module notes of
:mod:`~fem_elastic.dynamics.position_based.constraints`) solves, with
``at = alpha / h^2``,

    dlam = (-C - at lam) / (G W G^T + at),     dx = W G^T dlam,     lam += dlam.

A fixed point of the sweeps satisfies ``C(x) + at lam = 0`` and
``M (x - x*) = sum_j G_j(x_j)^T dlam_j``, ``x* = x_n + h v_n + h^2 M^-1 f_ext``,
with each gradient taken where its correction was made. Were they all taken
at x, that would be ``M (x - x*) / h^2 + grad U(x) = 0``: the implicit-Euler
step of the energy ``U = sum_j C_j^2 / (2 alpha_j)``, the minimiser of
``1/(2 h^2) |x - x_n - h v_n|_M^2 + U(x) - f_ext . x`` that
:class:`fe.ImplicitEuler` finds by Newton. What is left at convergence,
``sum_j (G_j(x_j) - G_j(x))^T dlam_j``, is the price of Macklin et al.'s
approximation (the residual g of the momentum equation dropped from each
update), and it decides how close XPBD gets:

- for the springs and volumes of ``"edge_volume"`` (rest value 0) the
  multipliers are as small as the stresses, the gradients turn little within a
  step, and the steps approach implicit Euler's as the iterations grow, at any
  step size: ten steps of 0.01 s of a 10 MPa cantilever (``h omega_max = 68``)
  are within 1.8 % of implicit Euler at 200 iterations per step, 0.05 % at 800
  (a fitted slope of -1.8 in the iteration count), down to a floor of 0.03 %;
  damped to rest the sag is ``fe.solve_static``'s within 0.2 %, at dt = 0.01
  and 0.02 s alike: the stiffness is in alpha, not in dt or the iterations;
- for ``"neohookean"`` ``C_D = sqrt(I_C)`` is ``sqrt(3)`` at rest: every tet
  carries rest multipliers ``lam_D = -sqrt(3) mu_c V0 h^2``, ``lam_H = mu_c V0
  h^2`` whose forces cancel only at ``F = I``, and the body's whole shear
  stiffness is the geometric stiffness of those multipliers
  (``lam d2C/dx2``), which the XPBD update leaves out. The first sweep of a
  step builds them at the predicted positions, and the fixed point keeps the
  mark: it differs from implicit Euler's step by an amount that grows with
  ``h omega_max`` (``omega_max`` the body's highest frequency). Measured on a
  cantilever released under gravity for 0.1 s: 0.04 % at
  ``h omega_max = 0.23``, 0.6 % at 0.9, 1.7 % at 1.8, 11 % at 3.6, 92 % at
  7.3 (a slope of 1.8 in dt below 2); ten steps of 0.01 s of the 10 MPa
  cantilever (``h omega_max = 68``) are 20 times their own motion away. The
  sweeps converge in a few iterations at such steps, so more iterations do
  not help; ``substeps`` do (a step of dt in n substeps is n implicit-Euler
  steps of dt / n, to the accuracy of the table at ``h omega_max / n``), as
  Macklin et al. (2019) recommend. A step past ``h omega_max =``
  :data:`HW_LIMIT` logs a warning with the substeps it needs. The 2x2 block
  solve of a tet's two constraints (see :class:`~.constraints.TetNeoHookean`)
  matters here: projecting all the C_D of a sweep before all the C_H put the
  run 78 % away from implicit Euler where the block solve is 0.2 % away
  (``h omega_max = 1.4``, a 1 m cantilever).

The energies (``constraints``):

``"neohookean"`` (default)
    Macklin and Mueller's (2021) constraint form of stable Neo-Hookean, two
    constraints per tet (:class:`~.constraints.TetNeoHookean`):
    ``C_D = sqrt(I_C)`` with ``alpha_D = 1 / (mu_c V0)`` and
    ``C_H = J - (1 + mu_c / lam_c)`` with ``alpha_H = 1 / (lam_c V0)``. Its
    energy is :class:`~.energy.ConstraintNeoHookean` (not
    :class:`fe.StableNeoHookean`, which has a logarithmic term more; the two
    agree at small strain). The Lame parameters come from the body's material
    (E, nu): ``mu_c = mu`` and ``lam_c = lam + mu`` (``consistent_lame=True``:
    small strains then give linear elasticity with the material's E and nu),
    or ``lam_c = lam`` (the paper's formulas read literally; a small-strain
    first Lame parameter ``lam - mu``). A body whose material is a
    ``ConstraintNeoHookean`` uses its own ``mu_c`` and ``lam_c``.
``"edge_volume"``
    Springs on the edges and a volume constraint on the tets, compliances from
    (E, nu). Edge e: ``C = l - l0``, ``alpha_e = 1 / k_e`` with van Gelder's
    (1998) ``k_e = E sum_{tets at e} V_t / l0^2``. Under a homogeneous strain
    eps each edge stretches by ``l0 n.eps n``, so a hydrostatic strain
    ``eps = e I`` stores ``sum_e k_e l0^2 e^2 / 2 = 6 E V e^2 / 2`` (every tet
    has six edges): the springs' bulk modulus is ``K_s = 2 E / 3`` on any mesh,
    the bulk modulus of the only Poisson ratio an isotropic spring network can
    have, 1/4 (:mod:`fem_elastic.physics.springs`). The tet constraint
    ``C = J - 1`` with ``alpha = 1 / (K_v V0)`` adds the bulk modulus that is
    missing for nu, ``K_v = K(E, nu) - 2E/3 = E (4 nu - 1) / (3 (1 - 2 nu))``,
    so the body has the material's bulk modulus exactly; for nu <= 1/4 there is
    nothing to add (the springs are already that stiff in volume) and the
    volume constraints are left out. The shear response is the spring
    network's, which depends on the mesh (see :mod:`fem_elastic.physics.springs`).
    At nu = 1/4 the energy is that of ``fe.MassSpring(E)`` on the same mesh.

Examples
--------
>>> import fem_elastic as fe
>>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
...                  body=fe.ElasticBody(fe.StableNeoHookean(E=1e5, nu=0.3)),
...                  fixed="left", gravity=(0, 0, -9.81))
>>> xpbd = fe.XPBD(iterations=20)
>>> s = xpbd.step(model, fe.State.rest(model), 0.01)
>>> s.t, bool(s.x[2::3].min() < model.X[2::3].min())
(0.01, True)
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Literal

import numpy as np

from ...errors import InvalidParameter
from ...geometry.mesh import signed_volumes
from ...physics.springs import van_gelder_stiffness
from .base import PositionBased, check_p1_body
from .constraints import EdgeDistance, TetNeoHookean, TetVolume
from .energy import ConstraintNeoHookean

if TYPE_CHECKING:  # for annotations only
    from ...physics.multibody import AnyModel

__all__ = ["XPBD", "CONSTRAINTS", "HW_LIMIT", "max_frequency_estimate"]

log = logging.getLogger(__name__)

#: The energies XPBD can give a body (see the module notes).
CONSTRAINTS = ("neohookean", "edge_volume")

#: ``h omega_max`` above which a step with the Neo-Hookean constraints is logged as inaccurate.
#: Measured (scripts/xpbd_convergence.py, a cantilever released under gravity for 0.1 s): the
#: converged XPBD run differs from implicit Euler's by 0.6 % at h omega_max = 0.9, 1.7 % at 1.8,
#: 11 % at 3.6 and 92 % at 7.3; at 68 (ten steps of 0.01 s of a 10 MPa beam) by 20 times the
#: motion itself. The static sag it settles to is 2.6 % off at 1.2 and 7 % at 2.3.
HW_LIMIT = 2.0


def max_frequency_estimate(tets, nodal_mass) -> float:
    """An estimate of the body's highest angular frequency (rad/s) from its Neo-Hookean tets.

    The largest over the tets of ``sqrt((lam_c + 2 mu_c) V sum_a |grad N_a|^2 / m_a)``,
    the frequency of one tet's volumetric mode on the lumped masses: within 15 %
    of the highest eigenfrequency (``2 / fe.critical_time_step(model, fe.SymplecticEuler())``)
    of the P1 beams measured, no Lanczos iteration needed.

    Parameters
    ----------
    tets : TetNeoHookean
    nodal_mass : numpy.ndarray, shape (n_vertices,)
        Lumped mass per vertex (kg).

    Returns
    -------
    float
    """
    dN = np.concatenate([-tets.Dm_inv.sum(axis=1, keepdims=True), tets.Dm_inv], axis=1)  # (ne, 4, 3)
    s = (np.einsum("nai,nai->na", dN, dN) / nodal_mass[tets.nodes]).sum(axis=1)
    return float(np.sqrt(((tets.lam + 2.0 * tets.mu) * tets.volume * s).max()))


class XPBD(PositionBased):
    """Extended position-based dynamics: constraints with compliance from the body's material.

    Parameters
    ----------
    iterations : int
        Constraint sweeps per step, >= 1.
    constraints : {"neohookean", "edge_volume"}
        The energy (see :mod:`fem_elastic.dynamics.position_based.xpbd`).
    method : {"gauss_seidel", "jacobi"}
        Gauss-Seidel sweeps (graph-coloured) or Jacobi sweeps.
    damping : float
        Velocity damping per step in [0, 1] towards the rigid motion
        (Mueller et al. 2007, section 3.5).
    relaxation : float
        Jacobi only: over-relaxation of the averaged corrections, in (0, 2).
    consistent_lame : bool
        ``"neohookean"``: ``lam_c = lam + mu`` (True, the default) or ``lam``.
    substeps : int
        Steps of ``dt / substeps`` per step, each with ``iterations`` sweeps
        (see the module notes: the Neo-Hookean constraints need small steps).

    Examples
    --------
    >>> XPBD(iterations=50)
    fe.XPBD(iterations=50, constraints='neohookean', method='gauss_seidel', damping=0, relaxation=1, consistent_lame=True, substeps=1)
    """

    _who = "fe.XPBD"

    def __init__(self, iterations: int = 20,
                 constraints: Literal["neohookean", "edge_volume"] = "neohookean",
                 method: Literal["gauss_seidel", "jacobi"] = "gauss_seidel", damping: float = 0.0,
                 relaxation: float = 1.0, consistent_lame: bool = True,
                 substeps: int = 1) -> None:
        super().__init__(iterations, method, damping, relaxation, substeps)
        if not isinstance(constraints, str) or constraints not in CONSTRAINTS:
            raise InvalidParameter(f"constraints must be one of {CONSTRAINTS}, got {constraints!r}.")
        if not isinstance(consistent_lame, (bool, np.bool_)):
            raise InvalidParameter(f"consistent_lame must be True or False, got {consistent_lame!r}.")
        self.constraints = constraints
        self.consistent_lame = bool(consistent_lame)
        self._warned: set[tuple[int, float]] = set()

    def __repr__(self) -> str:
        return (f"fe.XPBD(iterations={self.iterations}, constraints={self.constraints!r}, "
                f"method={self.method!r}, damping={self.damping:g}, relaxation={self.relaxation:g}, "
                f"consistent_lame={self.consistent_lame}, substeps={self.substeps})")

    def energy_material(self, model: AnyModel) -> ConstraintNeoHookean:
        """The material whose FEM energy equals the ``"neohookean"`` constraint energy on ``model``.

        ``fe.ElasticBody(xpbd.energy_material(model))`` is the body to give
        :class:`fe.ImplicitEuler` or :func:`fe.solve_static` for a comparison
        with this integrator on ``model``.

        Examples
        --------
        >>> import fem_elastic as fe
        >>> model = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1000.0,
        ...                  body=fe.ElasticBody(fe.StableNeoHookean(E=1e6, nu=0.3)))
        >>> XPBD().energy_material(model)
        ConstraintNeoHookean(E=1000000.0, nu=0.3)
        """
        material = check_p1_body(model, self._who).material
        if isinstance(material, ConstraintNeoHookean):
            return material
        return ConstraintNeoHookean(E=material.E, nu=material.nu, consistent_lame=self.consistent_lame)

    def _constraint_sets(self, model):
        mesh = model.mesh
        if self.constraints == "neohookean":
            m = self.energy_material(model)
            return [TetNeoHookean(mesh, m.mu_c, m.lam_c)]
        material = check_p1_body(model, self._who).material
        E, nu = float(material.E), float(material.nu)
        k_edge = van_gelder_stiffness(mesh, E)  # N/m, the springs of fe.MassSpring(E) exactly
        V = np.abs(signed_volumes(mesh))
        sets = [EdgeDistance.of_mesh(mesh, compliance=1.0 / k_edge)]
        K_v = E * (4.0 * nu - 1.0) / (3.0 * (1.0 - 2.0 * nu))
        if K_v > 0.0:
            sets.append(TetVolume(mesh, compliance=1.0 / (K_v * V)))
        else:
            log.info("XPBD edge_volume: nu = %g <= 1/4, the springs alone have at least the bulk "
                     "modulus asked; no volume constraints", nu)
        return sets

    def _coefficients(self, sets, h):
        h2 = h * h
        if self.constraints == "neohookean":
            self._check_step(sets[0], h)
        return [(s.compliance / h2, np.ones(len(s))) for s in sets]

    def _check_step(self, tets, h) -> None:
        """Log a warning (once per model and step) when ``h omega_max`` is past what the form takes."""
        key = (id(tets), h)
        if key in self._warned:
            return
        self._warned.add(key)
        mass = self._setup[1].mass.reshape(-1, 3)[:, 0]
        hw = h * max_frequency_estimate(tets, mass)
        if hw > HW_LIMIT:
            log.warning(
                "XPBD with Neo-Hookean constraints at a (sub)step of %.3g s: h omega_max ~ %.3g, past "
                "%g. The shear stiffness of these constraints is the geometric stiffness of their "
                "rest multipliers, which the XPBD update leaves out: the iterations converge to a "
                "point away from the implicit-Euler step (measured: 2 %% at h omega_max = 2, 11 %% at "
                "3.6, 92 %% at 7), and further out they do not converge. Use substeps >= %d (each "
                "substep is implicit Euler's at dt / substeps), or constraints='edge_volume'.",
                h, hw, HW_LIMIT, int(np.ceil(hw / HW_LIMIT)))
