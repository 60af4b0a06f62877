"""Rayleigh damping: a dissipation proportional to mass and to stiffness.

Damping is not an energy, so it is not a Potential: the integrators apply
the damping force ``f_d = -C v`` with the Rayleigh matrix

    C = alpha M + beta K(x),

where ``M`` is the mass the integrator uses (the lumped mass by default,
for every integrator; implicit ones accept ``mass="consistent"``) and
``K(x)`` the body's linear-elastic rest stiffness rotated element by
element to the current configuration (``sum_e R_e K_e R_e^T``, stiffness
warping; :meth:`fe.Model.damping_stiffness`). The rotation matters: the
plain rest stiffness ``K_0`` brakes a spinning body, because it only
ignores infinitesimal rotations about the reference shape; the warped one
ignores rigid motion at any orientation and stays positive semi-definite,
so the damping only dissipates. Explicit schemes apply it matrix-free (one
polar decomposition per element per force evaluation); implicit ones
freeze it at the start of each step. For small motions about the
reference ``K(x) = K_0`` and the damping ratio of the linear mode of
angular frequency omega is

    zeta(omega) = alpha / (2 omega) + beta omega / 2,

so ``alpha`` (1/s) damps the slow modes and ``beta`` (s) the fast ones.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

from ..errors import InvalidParameter

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
            if isinstance(val, bool) or not isinstance(val, numbers.Real) or not math.isfinite(val) or val < 0:
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
