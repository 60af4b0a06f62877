"""External loads as Potentials: gravity and surface traction.

Both are dead loads (their direction and magnitude do not follow the
deformation), so each is a linear potential ``E(x) = -f . (x - X)`` with a
constant nodal force vector ``f`` (N) integrated once through scikit-fem: a
constant load density times the integral of each scalar shape function.
"""

from __future__ import annotations

import numpy as np

from ..discretization.space import Discretization
from ..errors import InvalidParameter
from ..geometry.mesh import boundary_facets
from .potential import LinearPotential

__all__ = ["gravity_load", "traction_load", "facet_shape_integrals", "as_vector3"]


def as_vector3(value, name: str, unit: str, example: str = "(0.0, 0.0, -9.81)") -> np.ndarray:
    """A finite 3-vector from user input, or a clear :class:`InvalidParameter`."""
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidParameter(
            f"{name} must be three numbers ({unit}), e.g. {example}; got {value!r}."
        ) from None
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise InvalidParameter(
            f"{name} must be three finite numbers ({unit}), e.g. {example}; got {value!r}."
        )
    return v


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
    # int rho g N_a dV = rho g sum_b M_ab, by the partition of unity sum_b N_b = 1
    node_volume = np.asarray(space.unit_mass.sum(axis=1)).ravel()  # int N_a dV (m^3)
    return LinearPotential(np.outer(density * node_volume, g).ravel(), space.X)


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
    facets = boundary_facets(space.mesh, boundary, what="traction")
    return LinearPotential(np.outer(facet_shape_integrals(space, facets), t).ravel(), space.X)


def facet_shape_integrals(space: Discretization, facets: np.ndarray) -> np.ndarray:
    """``int_Gamma N_a dA`` (m^2) over the given facets, for every scalar node a of the space.

    The facets of the space's straight-sided tets (it refuses curved ones) are
    flat triangles, where the integrals have a closed form: A/3 at each corner
    for P1; for P2, A/3 at each edge midpoint and 0 at the corners (the
    quadratic Lagrange triangle's corner functions integrate to zero), on the
    nodes as ``space.dofs`` numbers them (checked against scikit-fem's
    ``FacetBasis`` quadrature in the tests). The closed form is exact and skips
    building a facet basis: 2-4 ms of the 20 ms a small P2 static solve took
    (``scripts/bench_time_to_accuracy.py``).
    """
    mesh = space.mesh
    facets = np.asarray(facets, dtype=np.int64)
    tri = mesh.facets[:, facets]  # (3, nf) vertex indices
    p = mesh.p
    area = 0.5 * np.linalg.norm(np.cross(p[:, tri[1]] - p[:, tri[0]], p[:, tri[2]] - p[:, tri[0]],
                                         axis=0), axis=0)
    dofs = space.dofs
    if space.order == 1:
        nodes = dofs.nodal_dofs[0][tri]
    else:
        nodes = dofs.edge_dofs[0][space.facet_edges(facets)]
    return np.bincount(nodes.ravel(), weights=np.tile(area / 3.0, 3), minlength=dofs.N)
