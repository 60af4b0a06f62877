"""Ready-made energies for :func:`fe.material_from_energy`, written as a user would.

Each is a plain function of the invariants ``I1 = tr C``, ``I2`` and
``J = det F`` of ``C = F^T F`` and of named parameters (Pa), written with
:mod:`fe.math <fem_elastic.materials.energy_math>`; pass it with its
parameters: ``fe.material_from_energy(fe.energies.stable_neo_hookean,
mu=1e6, lam=2e6)``. Each is stress-free at rest and linearizes to linear
elasticity with the shear modulus ``mu``; the first Lame parameter is ``lam``
(Neo-Hookean), ``lam - mu`` (the log-free stable Neo-Hookean, whose energy at
rest is the constant ``mu^2 / (2 lam)``) or ``kappa - 2/3 mu`` (Cook's membrane,
``kappa`` the bulk modulus).

Examples
--------
>>> import numpy as np
>>> import fem_elastic as fe
>>> [float(f(3.0, 3.0, 1.0, 1e6, 2e6)) for f in (neo_hookean, stable_neo_hookean, cook_membrane)]
[0.0, 250000.0, 0.0]
"""

from __future__ import annotations

from . import energy_math as m

__all__ = ["neo_hookean", "stable_neo_hookean", "cook_membrane"]


def neo_hookean(I1, I2, J, mu, lam):
    """Compressible Neo-Hookean (Bonet and Wood), the energy of :class:`fe.NeoHookean`.

    ``psi = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2``; ``+inf`` at ``J <= 0``.

    Parameters
    ----------
    I1, I2, J : float or array or sympy expression
        Invariants of ``C = F^T F`` (``I2`` unused) and ``J = det F``.
    mu, lam : float
        Lame parameters (Pa).

    Returns
    -------
    Energy density (J/m^3).

    Examples
    --------
    >>> float(neo_hookean(3.0, 3.0, 1.0, mu=1.0, lam=1.0))
    0.0
    """
    return mu / 2 * (I1 - 3) - mu * m.log(J) + lam / 2 * m.log(J) ** 2


def stable_neo_hookean(I1, I2, J, mu, lam):
    """Log-free stable Neo-Hookean: ``psi = mu/2 (I1 - 3) + lam/2 (J - 1 - mu/lam)^2``.

    The energy of Smith, de Goes and Kim (2018, "Stable Neo-Hookean Flesh
    Simulation", eq. 14, without its ``ln(I_C + 1)`` term): no logarithm of
    ``J``, so it is finite and smooth through inversion. Its rest shape is
    stress-free (``alpha = 1 + mu/lam`` balances the ``I1`` term), with the
    constant energy ``psi(I) = mu^2 / (2 lam)`` there (it moves nothing), and
    it linearizes to linear elasticity with the shear modulus ``mu`` and the
    first Lame parameter ``lam - mu``: pass ``lam = lam_Lame + mu`` to match a
    given (mu, lam_Lame), as the paper does. (:class:`fe.StableNeoHookean`
    rescales ``mu`` and ``lam`` and keeps the ``ln(I_C + 1)`` term to match
    linear elasticity with (mu, lam) exactly.)

    Parameters
    ----------
    I1, I2, J : float or array or sympy expression
        Invariants of ``C = F^T F`` (``I2`` unused) and ``J = det F``.
    mu, lam : float
        Lame-like parameters (Pa), ``lam > 0``.

    Returns
    -------
    Energy density (J/m^3).

    Examples
    --------
    >>> float(stable_neo_hookean(3.0, 3.0, 1.0, mu=1.0, lam=2.0))   # mu^2 / (2 lam) at rest
    0.25
    """
    return mu / 2 * (I1 - 3) + lam / 2 * (J - 1 - mu / lam) ** 2


def cook_membrane(I1, I2, J, mu, kappa):
    """The compressible Neo-Hookean of deal.II's step-44 and its Cook's-membrane code-gallery program.

    ``psi = mu/2 (J^(-2/3) I1 - 3) + kappa/4 (J^2 - 1 - 2 ln J)``: an
    isochoric Neo-Hookean term of the modified invariant ``I1_bar =
    J^(-2/3) I1`` and the volumetric function ``U(J) = 1/4 (J^2 - 1 - 2 ln J)``
    of deal.II's step-44 tutorial (J.-P. Pelteret and A. McBride, "The
    deal.II tutorial step-44: three-field formulation for non-linear solid
    mechanics", doi:10.5281/zenodo.439772) and of the code-gallery program
    "Quasi-static finite-strain compressible elasticity" (J.-P. Pelteret),
    whose benchmark is Cook's membrane with ``mu = 80.194e6`` Pa and
    ``nu = 0.4999`` (``kappa = 2 mu (1 + nu) / (3 (1 - 2 nu))``).
    Defined for ``J > 0`` (``+inf`` elsewhere).

    Parameters
    ----------
    I1, I2, J : float or array or sympy expression
        Invariants of ``C = F^T F`` (``I2`` unused) and ``J = det F``.
    mu : float
        Shear modulus (Pa).
    kappa : float
        Bulk modulus (Pa).

    Returns
    -------
    Energy density (J/m^3).

    Examples
    --------
    >>> float(cook_membrane(3.0, 3.0, 1.0, mu=80.194e6, kappa=4e11))
    0.0
    """
    return mu / 2 * (J ** (-2 / 3) * I1 - 3) + kappa / 4 * (J ** 2 - 1 - 2 * m.log(J))
