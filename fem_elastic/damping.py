"""Rayleigh damping: a dissipation proportional to mass and to stiffness.

Damping is not an energy, so it is not a Potential: the integrators apply
the damping force ``f_d = -C v`` with the constant Rayleigh matrix

    C = alpha M + beta K_0,

where ``M`` is the mass the integrator uses (lumped for explicit schemes,
consistent for implicit ones unless told otherwise) and ``K_0`` the body's
stiffness at the reference configuration (assembled once, on first use).
Keeping ``C`` constant is the classical choice: the damping ratio of the
linear mode of angular frequency omega is

    zeta(omega) = alpha / (2 omega) + beta omega / 2,

so ``alpha`` (1/s) damps the slow modes and ``beta`` (s) the fast ones.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import InvalidParameter

__all__ = ["Rayleigh"]


@dataclass(frozen=True)
class Rayleigh:
    """Mass- and stiffness-proportional damping ``C = alpha M + beta K_0``.

    Parameters
    ----------
    alpha : float
        Mass-proportional coefficient (1/s), >= 0.
    beta : float
        Stiffness-proportional coefficient (s), >= 0.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> d = fe.Rayleigh.from_damping_ratios(0.05, 2.0, 0.05, 20.0)  # 5 % at 2 Hz and 20 Hz
    >>> round(d.damping_ratio(2 * 3.141592653589793 * 2.0), 6)
    0.05
    """

    alpha: float = 0.0
    beta: float = 0.0

    def __post_init__(self):
        for name in ("alpha", "beta"):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val) or val < 0:
                unit = "1/s" if name == "alpha" else "s"
                raise InvalidParameter(
                    f"Rayleigh damping {name} must be a finite number >= 0 ({unit}), got {val!r}."
                )
            object.__setattr__(self, name, float(val))

    def damping_ratio(self, omega: float) -> float:
        """Damping ratio of a linear mode of angular frequency ``omega`` (rad/s)."""
        return self.alpha / (2.0 * omega) + self.beta * omega / 2.0

    @classmethod
    def from_damping_ratios(cls, zeta1: float, f1: float, zeta2: float, f2: float) -> "Rayleigh":
        """The coefficients giving ratio ``zeta1`` at ``f1`` Hz and ``zeta2`` at ``f2`` Hz."""
        w1, w2 = 2 * math.pi * f1, 2 * math.pi * f2
        if not (0 < w1 < w2):
            raise InvalidParameter(f"need 0 < f1 < f2 (Hz), got f1={f1!r}, f2={f2!r}.")
        det = w2 / w1 - w1 / w2
        alpha = 2.0 * (zeta1 * w2 - zeta2 * w1) / det
        beta = 2.0 * (zeta2 / w1 - zeta1 / w2) / det
        if alpha < 0 or beta < 0:
            raise InvalidParameter(
                f"ratios {zeta1} at {f1} Hz and {zeta2} at {f2} Hz need a negative coefficient "
                f"(alpha={alpha:.3g}, beta={beta:.3g}); choose ratios closer to each other."
            )
        return cls(alpha, beta)
