"""Hyperelastic material models: energy density psi(F), stress P = dpsi/dF and tangent dP/dF.

Every material is a frozen dataclass built from Young's modulus E (Pa) and
Poisson's ratio nu, with four vectorized methods on deformation gradients of
shape ``(3, 3, ...)`` (scikit-fem's layout):

- ``psi(F)`` -> ``(...)``, J/m^3;
- ``dpsi_dF(F)`` -> ``(3, 3, ...)``, P in Pa;
- ``d2psi_dF2(F)`` -> ``(3, 3, 3, 3, ...)``, ``C[i, j, k, l] = dP_ij/dF_kl`` in Pa;
- ``d2psi_dF2_psd(F)`` -> the same, projected to positive semi-definite as a
  9x9 matrix at each point (what Newton's method needs).

All nonlinear materials linearize at ``F = I`` to :class:`LinearElastic` with
the same (mu, lam).

At any finite F, ``psi`` is finite or ``+inf``, never NaN or ``-inf``: ``+inf``
where the state is inadmissible (:class:`NeoHookean` at ``det F <= 0``) or where
the energy's terms overflow the float range (each energy grows at least like
``|F|^2``, so it is then beyond ~1e308 J/m^3 itself; NaN, from ``inf - inf`` with
a negative Lame parameter, would poison sums and comparisons). ``tests/
test_fuzz_materials.py`` checks this, and the derivatives against finite
differences, at random F from near-singular to inverted to 100x stretched.

Examples
--------
>>> import numpy as np
>>> import fem_elastic.materials as M
>>> F = np.eye(3)[:, :, None] * np.ones((1, 1, 4))
>>> [float(m.psi(F).max()) for m in (M.LinearElastic(1e6, 0.3), M.NeoHookean(1e6, 0.3))]
[0.0, 0.0]
"""

from .base import Material, lame_parameters
from .corotated import Corotated
from .linear import LinearElastic
from .neohookean import NeoHookean
from .stable_neohookean import StableNeoHookean
from .stvk import StVK

__all__ = [
    "Material",
    "lame_parameters",
    "LinearElastic",
    "StVK",
    "NeoHookean",
    "StableNeoHookean",
    "Corotated",
]
