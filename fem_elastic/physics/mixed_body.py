"""Locking-free near-incompressibility: the mixed (u, theta, p) body, condensed to an energy of x.

Why P2 tets lock
----------------
As nu -> 0.5 the energy's volumetric term ``lam u(J)`` grows without bound
(``lam / mu = 2 nu / (1 - 2 nu)``, 5000 at nu = 0.4999) and the minimiser must keep
``J = 1`` at every quadrature point: 4 constraints per P2 tet, too many for the
displacements to satisfy and still bend. The computed displacement comes out
several times too small (see ``scripts/cook_membrane.py``).

The three-field formulation
---------------------------
Every material supported here is affine in its first Lame parameter,

    psi(F) = psi_0(F) + lam u(J),

with ``psi_0`` the same material at ``lam = 0`` (same mu: its resistance to volume
change is of order mu, it does not lock) and ``u`` a fixed function of the volume
ratio J (:func:`volumetric_split`; a test checks the identity for each material).
Following the Hu-Washizu principle of Simo, Taylor and Pister (1985), the volume
term is given its own dilatation theta and pressure p, element-wise constants
(P0), and the body's energy becomes

    Pi(x, theta, p) = sum_e [ int_e psi_0(F) dV + V_e lam u(theta_e) + p_e int_e (J - theta_e) dV ].

Stationarity in p_e gives ``theta_e = (1/V_e) int_e J dV`` (the element's mean
dilatation); in theta_e, ``p_e = lam u'(theta_e)``. Both are per element, so they
are eliminated exactly (static condensation), leaving an energy of the
positions alone,

    Pi(x) = sum_e [ int_e psi_0(F(x)) dV + V_e lam u(theta_e(x)) ],

one volume constraint per tet instead of four. This is a Potential like any
other: Newton, ``solve_static`` and every implicit integrator use it unchanged.
On P1 tets the element mean of J is J itself (F is constant per tet), so nothing
would change: ``formulation="mixed"`` asks for order 2.

Why P2/P0 and not Taylor-Hood P2/P1
-----------------------------------
A continuous P1 pressure couples neighbouring elements, so it cannot be
condensed element by element: the solvers would need a saddle-point system with
pressure unknowns and an indefinite block, and every integrator would change.
The element-wise constant pressure condenses exactly and keeps the
"energy of the positions" architecture. Its price is stability: P2/P0 is inf-sup
stable on triangles (Boffi, Brezzi and Fortin, *Mixed Finite Element Methods and
Applications*, 2013, ch. 8), but on tets the discrete inf-sup constant measured
by ``scripts/cook_membrane.py --infsup`` decays like h on the structured
6-tets-per-hex meshes (0.19, 0.15, 0.092, 0.062, 0.046 on the Cook slab at 2, 4,
8, 12, 16 cells; Taylor-Hood stays at 0.22 on the same cube meshes), while on
randomly perturbed meshes it stayed near 0.05. The displacement error bound
``(1 + 1/beta_h) inf ||u - v||_1`` is then still O(h) for P2, the order the P0
pressure allows anyway, and independent of lam: no locking, but element
pressures may oscillate. Cook's membrane at nu = 0.4999 converges to the
reference value (``tests/test_mixed.py``, ``scripts/cook_membrane.py``).

Derivatives
-----------
With ``D = dJ/dF`` (the cofactor ``J F^-T``; ``I`` for linear elasticity, whose
"J" is the linearized ``1 + tr(eps) = tr F - 2``) and ``p_e = lam u'(theta_e)``:

    gradient:  g_ai = sum_q (P_0 + p_e D)_ij dN_a,j dx,
    Hessian:   K = sum_q dN . (C_0 + p_e d2J/dF2) . dN dx  +  lam u''(theta_e) / V_e  b_e b_e^T,
               b_e,ai = sum_q D_ij dN_a,j dx   (= V_e dtheta_e/dx).

The first term is the displacement element's contraction with the pointwise
tangent ``C_0 + p_e d2J/dF2``; the second is a rank-one matrix per element.
``project=True`` (what Newton uses far from equilibrium) projects the pointwise
tangent to positive semi-definite by eigen-decomposition of its 9x9 matrix
(``materials.isotropic.project_psd_9x9``) and
clamps ``u''`` at 0, so the Hessian is PSD. Under a homogeneous deformation
``theta_e = J``, so the energy and the gradient are those of the displacement
element exactly (the patch test); the Hessians differ (one rank-one volumetric
term per element instead of one per quadrature point), which is the point.

Stress and pressure
-------------------
``p_e`` is the element's volumetric stress: the lam-term contributes ``p_e D`` to
P, i.e. ``p_e I`` to the Cauchy stress (positive in tension), and
:meth:`MixedPotential.pressure` returns ``-p_e``. The deviatoric stress is that
of the material at F (the lam-term is purely hydrostatic), so ``fe.cell_fields``,
which evaluates the material at F, gives a mixed body's von Mises stress
exactly; its mean stress and energy density there are the pointwise ones, not
the element's (:meth:`MixedPotential.pressure`, :meth:`MixedPotential.energy_density`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..discretization.space import Discretization
from ..errors import InvalidParameter
from ..materials import LinearElastic, NeoHookean, StableNeoHookean
from ..materials.base import Material, _add_cofactor_derivative, _cofactor, _det
from ..materials.isotropic import project_psd_9x9
from .elastic_body import ElasticPotential

__all__ = ["MixedPotential", "VolumetricSplit", "volumetric_split", "check_mixed"]

#: Material class -> (measure of the volume ratio, its volumetric function u):
#: "det" is J = det F, "trace" the linearized J = tr F - 2; "log" is u = ln(J)^2 / 2,
#: "quadratic" u = (J - 1)^2 / 2. Exact classes only: a subclass may change psi.
_SPLITS = {
    LinearElastic: ("trace", "quadratic"),   # lam/2 tr(eps)^2
    NeoHookean: ("det", "log"),              # lam/2 ln(J)^2
    StableNeoHookean: ("det", "quadratic"),  # lam'/2 (J - alpha)^2 - (its lam = 0 part) = lam/2 (J - 1)^2
}


def _supported() -> str:
    return ", ".join(f"fe.{cls.__name__}" for cls in _SPLITS)


@dataclass(frozen=True)
class VolumetricSplit:
    """``psi(F) = rest.psi(F) + lam u(J)``: a material's volumetric term, apart from the rest.

    Attributes
    ----------
    rest : Material
        The same material with the same shear modulus and ``lam = 0``.
    lam : float
        First Lame parameter (Pa), the modulus of the volumetric term.
    measure : {"det", "trace"}
        J = det F, or the linearized ``tr F - 2`` (linear elasticity).
    kind : {"log", "quadratic"}
        ``u(J) = ln(J)^2 / 2`` or ``(J - 1)^2 / 2``.

    Examples
    --------
    >>> import numpy as np
    >>> import fem_elastic as fe
    >>> m = fe.NeoHookean(E=1e6, nu=0.45)
    >>> s = volumetric_split(m)
    >>> s.measure, s.kind, float(s.rest.lam), bool(np.isclose(s.rest.mu, m.mu))
    ('det', 'log', 0.0, True)
    >>> F = np.diag([1.1, 0.9, 1.05])
    >>> bool(np.isclose(m.psi(F), s.rest.psi(F) + s.lam * s.u(np.linalg.det(F))))
    True
    """

    rest: Material
    lam: float
    measure: str
    kind: str

    def u(self, J):
        """The volumetric function (dimensionless); NaN where ``kind == "log"`` and J <= 0."""
        J = np.asarray(J, dtype=float)
        if self.kind == "log":
            with np.errstate(divide="ignore", invalid="ignore"):
                return 0.5 * np.log(J) ** 2
        return 0.5 * (J - 1.0) ** 2

    def du(self, J):
        """u'(J)."""
        J = np.asarray(J, dtype=float)
        if self.kind == "log":
            with np.errstate(divide="ignore", invalid="ignore"):
                return np.log(J) / J
        return J - 1.0

    def d2u(self, J):
        """u''(J)."""
        J = np.asarray(J, dtype=float)
        if self.kind == "log":
            with np.errstate(divide="ignore", invalid="ignore"):
                return (1.0 - np.log(J)) / (J * J)
        return np.ones_like(J)


def volumetric_split(material: Material) -> VolumetricSplit:
    """The split ``psi = psi_0 + lam u(J)`` of a material, or a typed error naming those that have one.

    Parameters
    ----------
    material : Material
        ``fe.LinearElastic``, ``fe.NeoHookean`` or ``fe.StableNeoHookean``.

    Returns
    -------
    VolumetricSplit

    Raises
    ------
    InvalidParameter
        For any other material (St. Venant-Kirchhoff's and corotated elasticity's
        lam-terms are functions of tr E and of the singular values, not of J).
    """
    spec = _SPLITS.get(type(material))
    if spec is None:
        raise InvalidParameter(
            f"formulation='mixed' needs a material whose energy splits into a shear part and "
            f"lam u(J), a function of the volume ratio J alone; {type(material).__name__} does "
            f"not. Materials with that split: {_supported()}; or use "
            "formulation='displacement'."
        )
    mu = float(material.mu)
    rest = type(material)(E=2.0 * mu, nu=0.0)  # nu = 0: lam = 0, mu = E / 2 unchanged
    return VolumetricSplit(rest=rest, lam=float(material.lam), measure=spec[0], kind=spec[1])


def check_mixed(material: Material, order: int) -> None:
    """Raise :class:`InvalidParameter` unless ``(material, order)`` can use ``formulation="mixed"``."""
    if order != 2:
        raise InvalidParameter(
            f"formulation='mixed' needs order=2 (quadratic tets with an element-wise constant "
            f"pressure), got order={order!r}: on linear tets F is constant per element, so the "
            "element's mean dilatation is its dilatation and the mixed element would lock exactly "
            "like the displacement one. Use fe.ElasticBody(material, order=2, formulation='mixed')."
        )
    volumetric_split(material)


class MixedPotential(ElasticPotential):
    """Elastic energy (J) of a P2 body with an element-wise mean dilatation: no volumetric locking.

    The condensed three-field energy ``sum_e int_e psi_0(F) dV + V_e lam u(theta_e)``
    of the module notes. Built by ``fe.ElasticBody(material, order=2,
    formulation="mixed").build(space)``; a Potential of the positions like
    :class:`ElasticPotential`, whose kinematics (``F``), force assembly and element
    stiffness kernel it shares.

    Parameters
    ----------
    material : Material
        ``fe.LinearElastic``, ``fe.NeoHookean`` or ``fe.StableNeoHookean``.
    space : Discretization
        Of order 2.

    Examples
    --------
    >>> import numpy as np
    >>> import fem_elastic as fe
    >>> from fem_elastic.discretization import Discretization
    >>> space = Discretization(fe.beam_mesh(cells=(2, 1, 1)), order=2)
    >>> m = fe.NeoHookean(E=1e6, nu=0.4999)
    >>> mixed, disp = MixedPotential(m, space), fe.ElasticPotential(m, space)
    >>> x = space.X * np.repeat([[1.01, 0.995, 1.0]], space.ndofs // 3, axis=0).ravel()  # homogeneous
    >>> bool(np.isclose(mixed.energy(x), disp.energy(x), rtol=1e-12))
    True
    """

    @property
    def quadratic(self) -> bool:  # type: ignore[override]
        """False: the condensed dilatation term is not quadratic in x."""
        return False

    def __init__(self, material: Material, space: Discretization) -> None:
        check_mixed(material, space.order)
        super().__init__(material, space)
        self.split = volumetric_split(material)
        #: ``(nelems,)`` reference volume of each element (m^3).
        self.volume = np.asarray(space.dx, dtype=float).sum(axis=1)

    # kinematics ------------------------------------------------------------------
    def _volume_ratio(self, F: np.ndarray):
        """J at the points ``(ne, nq)``, dJ/dF ``(3, 3, ne, nq)`` (None for the linearized J) and theta ``(ne,)``."""
        if self.split.measure == "trace":
            J = F[0, 0] + F[1, 1] + F[2, 2] - 2.0
            D = None  # the identity
        else:
            shape = F.shape
            Ff = F.reshape(3, 3, -1)
            with np.errstate(over="ignore", invalid="ignore"):
                K = _cofactor(Ff)
                J = _det(Ff, K).reshape(shape[2:])
            D = K.reshape(shape)
        theta = np.einsum("eq,eq->e", J, self.space.dx) / self.volume
        return J, D, theta

    def theta(self, x: np.ndarray) -> np.ndarray:
        """The mean dilatation of each element, ``(1/V_e) int_e J dV`` ``(nelems,)``."""
        return self._volume_ratio(self.F(x))[2]

    def pressure(self, x: np.ndarray) -> np.ndarray:
        """Element pressure ``-lam u'(theta_e)`` (Pa, positive in compression), ``(nelems,)``.

        The part of the hydrostatic Cauchy stress carried by the volumetric
        term (the whole of it for a nearly incompressible body, up to O(mu)).
        """
        return -self.split.lam * self.split.du(self.theta(x))

    def energy_density(self, x: np.ndarray) -> np.ndarray:
        """``psi_0(F) + lam u(theta_e)`` at the quadrature points (J/m^3): sums with dx to :meth:`energy`."""
        F = self.F(x)
        theta = self._volume_ratio(F)[2]
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            return self.split.rest.psi(F) + (self.split.lam * self.split.u(theta))[:, None]

    # the Potential ---------------------------------------------------------------------
    def energy(self, x: np.ndarray) -> float:
        F = self.F(x)
        theta = self._volume_ratio(F)[2]
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            shear = self.split.rest.psi(F)
            vol = self.split.lam * self.split.u(theta)
            total = float(np.sum(shear * self.space.dx)) + float(np.sum(vol * self.volume))
        if not np.isfinite(total) or not np.all(np.isfinite(theta)) or (
            self.split.kind == "log" and np.any(theta <= 0.0)
        ):
            return np.inf  # inadmissible (inverted elements, or an element's mean J <= 0)
        return total

    def _stress(self, P0: np.ndarray, D, p: np.ndarray) -> np.ndarray:
        """P_0 + p_e dJ/dF at the points."""
        P = P0.copy()
        if D is None:
            for i in range(3):
                P[i, i] += p[:, None]
        else:
            P += p[:, None] * D
        return P

    def gradient(self, x: np.ndarray) -> np.ndarray:
        F = self.F(x)
        _, D, theta = self._volume_ratio(F)
        p = self.split.lam * self.split.du(theta)
        return self._force(self._stress(self.split.rest.dpsi_dF(F), D, p))

    def hessian(self, x: np.ndarray, project: bool = False) -> sp.csr_matrix:
        return self.linearize(x, project=project)[1]

    def linearize(self, x: np.ndarray,
                  project: bool = False) -> tuple[np.ndarray, sp.spmatrix | None]:
        F = self.F(x)
        _, D, theta = self._volume_ratio(F)
        split = self.split
        p = split.lam * split.du(theta)  # (ne,)
        P0, C = split.rest.stress_and_tangent(F, project=project and D is None)
        if D is not None:  # + p_e d2J/dF2 (the cofactor's derivative), then project the sum
            shape = C.shape
            Cf = C.reshape(3, 3, 3, 3, -1)
            _add_cofactor_derivative(Cf, F.reshape(3, 3, -1),
                                     np.broadcast_to(p[:, None], shape[4:]).ravel())
            C = project_psd_9x9(Cf).reshape(shape) if project else Cf.reshape(shape)
        g = self._force(self._stress(P0, D, p))
        Ke = self.element_stiffness(C)  # (3 nl, 3 nl, ne)
        b = self._dtheta(D)  # (3 nl, ne) = V_e dtheta_e/dx
        c = split.lam * split.d2u(theta) / self.volume
        if project:
            c = np.maximum(c, 0.0)
        Ke += c * b[:, None, :] * b[None, :, :]
        return g, self.space.pattern.assemble(Ke)

    def _dtheta(self, D) -> np.ndarray:
        """``b_e,ai = int_e (dJ/dF)_ij dN_a,j dV`` = V_e dtheta_e/dx_ai, as ``(3 nloc, nelems)``."""
        s = self.space
        if D is None:  # dJ/dF = I: b_ai = int dN_a,i dV
            b = np.einsum("aieq,eq->aie", s.dN, s.dx)
        else:
            b = np.einsum("ijeq,ajeq,eq->aie", D, s.dN, s.dx, optimize=True)
        return b.reshape(3 * s.nloc, -1)
