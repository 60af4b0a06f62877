"""Closed-form solutions for slender rectangular cantilevers.

A cantilever of length L (m) along x, clamped at x = 0, with a rectangular
cross-section of width b (along y, m) and height h (along z, m), bending in
the x-z plane. Symbols: E Young's modulus (Pa), nu Poisson's ratio,
G = E / (2 (1 + nu)) the shear modulus, A = b h the area (m^2),
I = b h^3 / 12 the second moment of area about the y axis (m^4), and
kappa = 10 (1 + nu) / (12 + 11 nu) Cowper's (1966) shear coefficient of a
rectangle.

- Euler-Bernoulli beams ignore shear deformation; Timoshenko beams add it,
  which matters more as the beam gets stockier (it scales as (h / L)^2).
- Neither accounts for the 3-D clamp (the fixed face also stops the Poisson
  contraction there), a local effect that vanishes for slender beams.
- :func:`elastica_tip` is the large-deflection answer (the exact elastica of
  an inextensible, shear-free cantilever under a dead tip load): it holds for
  large rotations as long as the strains stay small.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..materials.base import _check_E_nu

__all__ = ["RectangularCantilever", "elastica_tip"]

# First root of 1 + cos(x) cosh(x) = 0: the first bending mode of a clamped-free beam.
_BETA1_L = 1.8751040687119611


@dataclass(frozen=True)
class RectangularCantilever:
    """A clamped-free beam of rectangular section with closed-form answers.

    Parameters
    ----------
    length, width, height : float
        L, b, h (m).
    E : float
        Young's modulus (Pa).
    nu : float
        Poisson's ratio.

    Examples
    --------
    >>> beam = RectangularCantilever(length=1.0, width=0.1, height=0.1, E=1e9, nu=0.3)
    >>> round(beam.tip_load_euler_bernoulli(100.0) * 1e3, 4)  # mm
    4.0
    """

    length: float
    width: float
    height: float
    E: float
    nu: float

    def __post_init__(self):
        _check_E_nu(self.E, self.nu)
        for name in ("length", "width", "height"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                from ..errors import InvalidParameter

                raise InvalidParameter(f"{name} must be finite and > 0 m, got {v!r}.")

    @property
    def area(self) -> float:
        """A = b h (m^2)."""
        return self.width * self.height

    @property
    def second_moment(self) -> float:
        """I = b h^3 / 12 (m^4), for bending in the x-z plane."""
        return self.width * self.height**3 / 12.0

    @property
    def shear_modulus(self) -> float:
        """G (Pa)."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def shear_coefficient(self) -> float:
        """Cowper's kappa for a rectangle."""
        return 10.0 * (1.0 + self.nu) / (12.0 + 11.0 * self.nu)

    def tip_load_euler_bernoulli(self, P: float) -> float:
        """Tip deflection (m) under a transverse end force P (N): P L^3 / (3 E I)."""
        return P * self.length**3 / (3.0 * self.E * self.second_moment)

    def tip_load_timoshenko(self, P: float) -> float:
        """Tip deflection (m) under an end force P (N), with shear: adds P L / (kappa G A)."""
        shear = P * self.length / (self.shear_coefficient * self.shear_modulus * self.area)
        return self.tip_load_euler_bernoulli(P) + shear

    def distributed_load_euler_bernoulli(self, q: float) -> float:
        """Tip deflection (m) under a uniform load q (N/m), e.g. self weight rho g A: q L^4 / (8 E I)."""
        return q * self.length**4 / (8.0 * self.E * self.second_moment)

    def distributed_load_timoshenko(self, q: float) -> float:
        """Tip deflection (m) under a uniform load q (N/m), with shear: adds q L^2 / (2 kappa G A)."""
        shear = q * self.length**2 / (2.0 * self.shear_coefficient * self.shear_modulus * self.area)
        return self.distributed_load_euler_bernoulli(q) + shear

    def first_bending_frequency(self, density: float) -> float:
        """First bending natural frequency (Hz), Euler-Bernoulli: (beta1 L)^2 / (2 pi L^2) sqrt(E I / (rho A))."""
        return (
            _BETA1_L**2
            / (2.0 * math.pi * self.length**2)
            * math.sqrt(self.E * self.second_moment / (density * self.area))
        )


def elastica_tip(alpha: float) -> tuple[float, float]:
    """Tip deflection and shortening of the elastica of a cantilever under a dead transverse tip load.

    An inextensible, shear-free cantilever of length L, clamped at s = 0, with a
    tip force P of fixed direction (perpendicular to the undeformed axis) and
    bending stiffness E I. With theta(s) the rotation of the section and
    ``alpha = P L^2 / (E I)`` the load parameter (dimensionless), the moment
    balance in the arc length s (in units of L) is

        theta'' = -alpha cos(theta),   theta(0) = 0 (clamp),   theta'(1) = 0 (no tip moment),

    solved here by shooting on theta'(0) (``scipy.integrate.solve_ivp`` to
    rtol 1e-11, ``scipy.optimize.brentq`` on theta'(1) = 0). The tip position
    follows from x' = cos(theta), z' = sin(theta).

    For small alpha the deflection is alpha / 3 (Euler-Bernoulli, P L^3 / (3 E I))
    and the shortening (3 / 5) (alpha / 3)^2; for large alpha the beam hangs
    nearly along the load and the deflection tends to 1.

    Parameters
    ----------
    alpha : float
        P L^2 / (E I), >= 0.

    Returns
    -------
    deflection, shortening : float
        Tip displacement along the load and the tip's displacement back toward
        the clamp, both as fractions of L (multiply by L for metres).

    Examples
    --------
    >>> d, s = elastica_tip(1.0)       # Bisshopp & Drucker (1945): 0.3017, 0.0564
    >>> round(d, 4), round(s, 4)
    (0.3017, 0.0564)
    >>> d, s = elastica_tip(1e-4)      # small loads: Euler-Bernoulli, alpha / 3
    >>> round(d / (1e-4 / 3), 6)
    1.0
    """
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq

    if not (math.isfinite(alpha) and alpha >= 0.0):
        from ..errors import InvalidParameter

        raise InvalidParameter(f"alpha = P L^2 / (E I) must be finite and >= 0, got {alpha!r}.")
    if alpha == 0.0:
        return 0.0, 0.0

    def rhs(s, y):  # y = (theta, theta', x, z) in units of L
        return [y[1], -alpha * math.cos(y[0]), math.cos(y[0]), math.sin(y[0])]

    def end(k0):
        return solve_ivp(rhs, (0.0, 1.0), [0.0, k0, 0.0, 0.0], rtol=1e-11, atol=1e-12).y[:, -1]

    # theta'(0) is the root moment P x_tip / (E I) <= alpha: the bracket [0, alpha] holds it
    k0 = brentq(lambda k: end(k)[1], 0.0, alpha * (1.0 + 1e-9), xtol=1e-14)
    y = end(k0)
    return float(y[3]), float(1.0 - y[2])
