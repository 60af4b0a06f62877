"""External loads as Potentials: gravity and surface traction.

Both are dead loads (their direction and magnitude do not follow the
deformation), so each is a linear potential ``E(x) = -f . (x - X)`` with a
constant nodal force vector ``f`` (N) integrated once through scikit-fem.
"""

from __future__ import annotations

import math

import numpy as np
from skfem import FacetBasis, LinearForm

from .discretization import Discretization
from .errors import InvalidParameter
from .potential import LinearPotential

__all__ = ["gravity_load", "traction_load", "as_vector3"]


def as_vector3(value, name: str, unit: str) -> np.ndarray:
    """A finite 3-vector from user input, or a clear :class:`InvalidParameter`."""
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidParameter(
            f"{name} must be three numbers ({unit}), e.g. (0.0, 0.0, -9.81); got {value!r}."
        ) from None
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise InvalidParameter(
            f"{name} must be three finite numbers ({unit}), e.g. (0.0, 0.0, -9.81); got {value!r}."
        )
    return v


@LinearForm
def _vector_density(v, w):
    # w.g: the load per unit volume (N/m^3) or area (N/m^2), shape (3, 1, 1) so that
    # scikit-fem broadcasts it instead of reading it as a DOF vector
    return v[0] * w.g[0] + v[1] * w.g[1] + v[2] * w.g[2]


def gravity_load(space: Discretization, density: float, g) -> LinearPotential:
    """The weight of the body, ``f_a = int rho g N_a dV`` (N).

    Parameters
    ----------
    space : Discretization
    density : float
        Mass density (kg/m^3).
    g : array_like
        Gravitational acceleration (m/s^2), e.g. ``(0, 0, -9.81)``.

    Returns
    -------
    LinearPotential
        ``E(x) = -f . (x - X)``; its ``force`` sums to ``rho g V``.
    """
    g = as_vector3(g, "gravity", "m/s^2")
    f = _vector_density.assemble(space.mass_basis, g=(density * g)[:, None, None])
    return LinearPotential(f, space.X)


def traction_load(space: Discretization, boundary: str, t) -> LinearPotential:
    """A uniform traction ``t`` (Pa) on a named boundary of the reference configuration.

    ``f_a = int_Gamma t N_a dA`` (N); the total force is ``t`` times the
    boundary's reference area.

    Parameters
    ----------
    space : Discretization
    boundary : str
        Name of a boundary of the mesh (``mesh.boundaries``).
    t : array_like
        Traction vector (Pa = N/m^2).
    """
    t = as_vector3(t, f"traction on {boundary!r}", "Pa")
    boundaries = space.mesh.boundaries or {}
    if boundary not in boundaries:
        raise InvalidParameter(
            f"traction names boundary {boundary!r}, which the mesh does not have; "
            f"its boundaries are {sorted(boundaries)}."
        )
    fb = FacetBasis(
        space.mesh,
        space.basis.elem,
        facets=boundaries[boundary],
        intorder=max(2 * space.order, 2),
    )
    f = _vector_density.assemble(fb, g=t[:, None, None])
    if not math.isfinite(float(np.sum(f))):  # pragma: no cover - guarded by as_vector3
        raise InvalidParameter(f"traction on {boundary!r} produced non-finite forces.")
    return LinearPotential(f, space.X)
