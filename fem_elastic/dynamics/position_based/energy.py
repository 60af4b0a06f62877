"""The energy XPBD's Neo-Hookean constraints minimise, as a Material: for comparisons with FEM.

:class:`fe.XPBD` projects, per tet, the deviatoric and hydrostatic constraints of
Macklin and Mueller (2021),

    C_D = sqrt(I_C),  alpha_D = 1 / (mu_c V0),      C_H = J - gamma,  alpha_H = 1 / (lam_c V0),

with ``gamma = 1 + mu_c / lam_c``. Their constraint energy
``sum_tets C_D^2 / (2 alpha_D) + C_H^2 / (2 alpha_H)`` is the FEM energy of the
P1 body with the density

    psi(F) = mu_c/2 (I_C - 3) + lam_c/2 [(J - gamma)^2 - (1 - gamma)^2],

up to a constant (``3 mu_c / 2`` per unit volume; here subtracted so that
``psi(I) = 0`` like every material of the package). This is **not**
:class:`fe.StableNeoHookean`: that is Smith, de Goes and Kim's (2018) energy
with the term ``-mu'/2 ln(I_C + 1)`` and the Lame parameters
``mu' = 4/3 mu``, ``lam' = lam + 5/6 mu`` that go with it; Macklin and
Mueller's constraints drop the logarithm. The two agree in the small-strain
limit (both linearise to linear elasticity with the material's (mu, lam),
when ``consistent_lame`` is True) and differ at finite strain: with nu = 0.3
the energy densities differ by 0.04 % at 10 % simple shear, 0.3 % at 10 %
uniaxial stretch, 1 % at 50 % shear and 2 % at 50 % compression. So
:class:`ConstraintNeoHookean` is the exact energy of the constraints, for
``fe.ImplicitEuler`` and ``fe.solve_static`` on the same body as an XPBD run.

Lame parameters
---------------
The linearisation of psi at ``F = I`` is
``C_ijkl = mu_c (d_ik d_jl + d_il d_jk) + (lam_c - mu_c) d_ij d_kl``: the
term ``lam_c (J - gamma) dcof/dF = -mu_c dcof/dF`` at rest shifts the first
Lame parameter by ``-mu_c``. So with the material's Lame parameters
``(mu, lam)`` taken as they are (``consistent_lame=False``: Macklin and
Mueller's formulas read literally) the body is, at small strain, linear
elasticity with ``(mu, lam - mu)``: for nu = 0.3 its Poisson ratio is 1/6 and
its Young modulus 0.90 E. ``consistent_lame=True`` (the default) takes
``mu_c = mu``, ``lam_c = lam + mu``, Smith et al.'s reparameterisation of the
log-free energy (their section 3.4), so that the small-strain limit is
linear elasticity with the material's E and nu.

Examples
--------
>>> import numpy as np
>>> m = ConstraintNeoHookean(E=1.0e6, nu=0.3)
>>> F = np.eye(3) + 1e-7 * np.arange(9.0).reshape(3, 3)
>>> P_lin = __import__("fem_elastic").LinearElastic(E=1.0e6, nu=0.3).dpsi_dF(F)
>>> bool(np.allclose(m.dpsi_dF(F), P_lin, rtol=1e-5, atol=1e-9))   # small strain: linear elasticity
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import InvalidParameter
from ...materials.base import (
    _add_cofactor_derivative,
    _add_identity_term,
    _add_outer,
    _cofactor,
    _det,
    _flat,
    _overflow_to_inf,
)
from ...materials.isotropic import PAIRS, IsotropicMaterial

__all__ = ["ConstraintNeoHookean"]


@dataclass(frozen=True, init=False, repr=False)
class ConstraintNeoHookean(IsotropicMaterial):
    """The energy of the stable Neo-Hookean constraints of XPBD (Macklin and Mueller 2021).

    ``psi = mu_c/2 (I_C - 3) + lam_c/2 [(J - gamma)^2 - (1 - gamma)^2]``,
    ``gamma = 1 + mu_c / lam_c``: finite for any F, stress free at rest.

    Parameters
    ----------
    E : float
        Young's modulus (Pa), > 0 (or another pair of elastic constants, as
        every material of the package takes: ``mu=..., lam=...``).
    nu : float
        Poisson's ratio, -1 < nu < 0.5 (nu > 0 with ``consistent_lame=False``,
        where ``lam_c = lam`` must be > 0).
    consistent_lame : bool
        True: ``mu_c = mu``, ``lam_c = lam + mu`` (small strains give linear
        elasticity with E and nu); False: ``lam_c = lam`` (see the module notes).

    Examples
    --------
    >>> import numpy as np
    >>> m = ConstraintNeoHookean(E=1.0e6, nu=0.45)
    >>> float(m.psi(np.eye(3))), bool(np.isfinite(m.psi(np.diag([1.0, 1.0, -1.0]))))
    (0.0, True)
    """

    consistent_lame: bool = True

    def __init__(self, E: float | None = None, nu: float | None = None, *,
                 consistent_lame: bool = True, **constants: float) -> None:
        super().__init__(E, nu, **constants)
        if not isinstance(consistent_lame, (bool, np.bool_)):
            raise InvalidParameter(f"consistent_lame must be True or False, got {consistent_lame!r}.")
        object.__setattr__(self, "consistent_lame", bool(consistent_lame))
        if not self.lam_c > 0:
            raise InvalidParameter(
                f"the constraint form needs lam_c > 0, got {self.lam_c!r} Pa (nu = {self.nu!r} with "
                "consistent_lame=False); use nu > 0 or consistent_lame=True."
            )

    def __repr__(self) -> str:
        base = super().__repr__()  # the pair of constants given
        return base if self.consistent_lame else base[:-1] + ", consistent_lame=False)"

    @property
    def mu_c(self) -> float:
        """The shear modulus of the constraint energy (Pa): the material's mu."""
        return self.mu

    @property
    def lam_c(self) -> float:
        """The hydrostatic modulus of the constraint energy (Pa): ``lam + mu``, or ``lam``."""
        return self.lam + self.mu if self.consistent_lame else self.lam

    @property
    def gamma(self) -> float:
        """The rest volume ratio of the hydrostatic constraint, ``1 + mu_c / lam_c``."""
        return 1.0 + self.mu_c / self.lam_c

    def psi(self, F: np.ndarray) -> np.ndarray:
        """Strain-energy density (J/m^3), finite for any F; shape ``F.shape[2:]``."""
        F, batch = _flat(F)
        mu_, lam_ = self.mu_c, self.lam_c
        IC = np.einsum("ijn,ijn->n", F, F)
        jm1 = _det(F) - 1.0
        with np.errstate(invalid="ignore", over="ignore"):
            # (J - gamma)^2 - (1 - gamma)^2 = (J - 1)(J - 1 + 2 (1 - gamma)), no cancellation at rest
            out = 0.5 * mu_ * (IC - 3.0) + 0.5 * lam_ * jm1 * (jm1 - 2.0 * mu_ / lam_)
        return _overflow_to_inf(out, F).reshape(batch)

    def dpsi_dF(self, F: np.ndarray) -> np.ndarray:
        """First Piola-Kirchhoff stress ``mu_c F + lam_c (J - gamma) cof F`` (Pa), shape ``F.shape``."""
        F, batch = _flat(F)
        K = _cofactor(F)
        J = _det(F, K)
        P = self.mu_c * F + (self.lam_c * (J - self.gamma)) * K
        return P.reshape((3, 3) + batch)

    def d2psi_dF2(self, F: np.ndarray) -> np.ndarray:
        """Tangent ``mu_c I + lam_c K (x) K + lam_c (J - gamma) dK/dF`` (Pa), ``(3, 3, 3, 3) + batch``.

        Examples
        --------
        >>> import numpy as np
        >>> C = ConstraintNeoHookean(E=1.0e6, nu=0.25).d2psi_dF2(np.eye(3))
        >>> round(float(C[0, 0, 0, 0])), round(float(C[0, 1, 1, 0]))   # 2 mu + lam, mu
        (1200000, 400000)
        """
        F, batch = _flat(F)
        K = _cofactor(F)
        J = _det(F, K)
        C = np.zeros((3, 3, 3, 3, F.shape[-1]))
        _add_outer(C, K, K, self.lam_c)
        _add_cofactor_derivative(C, F, self.lam_c * (J - self.gamma))
        _add_identity_term(C, np.full(F.shape[-1], self.mu_c))
        return C.reshape((3, 3, 3, 3) + batch)

    def singular_value_hessian(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Eigensystem of the Hessian in the signed singular values ``s`` ``(3, N)``.

        With ``h = lam_c (J - gamma)``: ``H_ab = d_ab mu_c + lam_c (J/s_a)(J/s_b)
        + (1 - d_ab) h s_k``, ``lam_twist = mu_c + h s_k``, ``lam_flip = mu_c - h s_k``.

        Examples
        --------
        >>> import numpy as np
        >>> H, lt, lf = ConstraintNeoHookean(E=1.0e6, nu=0.25).singular_value_hessian(np.ones((3, 1)))
        >>> round(float(lt[0, 0])), round(float(lf[0, 0]))    # 0 and 2 mu at rest
        (0, 800000)
        """
        mu_, lam_ = self.mu_c, self.lam_c
        J = s[0] * s[1] * s[2]
        h = lam_ * (J - self.gamma)
        Js = np.array([s[1] * s[2], s[0] * s[2], s[0] * s[1]])  # J / s_a
        H = lam_ * Js[:, None] * Js[None, :]
        lt, lf = np.empty_like(s), np.empty_like(s)
        for a in range(3):
            H[a, a] += mu_
        for row, (i, j, k) in enumerate(PAIRS):
            hs = h * s[k]
            H[i, j] += hs
            H[j, i] += hs
            lt[row] = mu_ + hs
            lf[row] = mu_ - hs
        return H, lt, lf
