"""Meshes of the classic benchmark geometries (beside :func:`~fem_elastic.geometry.mesh.beam_mesh`).

:func:`cook_membrane_mesh` is Cook's tapered panel (Cook 1974), the standard test of
shear and volumetric locking: the quadrilateral with corners (0, 0), (48, 44),
(48, 60), (0, 44) in the x-y plane, extruded along z into a slab. A structured
grid of the unit square is mapped onto the panel (x = 48 xi, y between the lower
and the upper edge at that x), each hexahedral cell split into 6 tets.
"""

from __future__ import annotations

import numbers

import numpy as np
from skfem import MeshTet

from ..errors import InvalidParameter
from .mesh import _positive_ints, reorient, validate_mesh

__all__ = ["cook_membrane_mesh", "COOK_CORNERS"]

#: The panel's corners in the x-y plane, in the benchmark's units (mm in Cook 1974):
#: lower left, lower right, upper right (where the tip displacement is read), upper left.
COOK_CORNERS = ((0.0, 0.0), (48.0, 44.0), (48.0, 60.0), (0.0, 44.0))


def cook_membrane_mesh(cells: tuple[int, int] = (8, 8), thickness: float = 1.0, layers: int = 1,
                       scale: float = 1.0) -> MeshTet:
    """Tet mesh of Cook's membrane: the tapered panel (0, 0), (48, 44), (48, 60), (0, 44), as a slab.

    Parameters
    ----------
    cells : (int, int)
        Cells along x (from the clamped edge to the loaded one) and across the
        panel (from its lower edge to its upper one). Each cell is split into 6 tets.
    thickness : float
        Extent of the slab along z, in the same units as the panel (48 long).
    layers : int
        Cells through the thickness (1 for a plane-strain slab held in z on both faces).
    scale : float
        Factor on every coordinate: 1 keeps the benchmark's numbers (read as m by
        fem_elastic), 1e-3 turns the millimetres of the literature into metres.

    Returns
    -------
    skfem.MeshTet
        With named boundaries ``"left"`` (x = 0, the clamped edge), ``"right"``
        (x = 48, the loaded edge, 16 long), ``"bottom"`` (the lower slanted edge,
        from (0, 0) to (48, 44)), ``"top"`` (the upper edge, from (0, 44) to (48, 60)),
        ``"front"`` (z = 0) and ``"back"`` (z = thickness).

    Examples
    --------
    >>> mesh = cook_membrane_mesh(cells=(4, 2))
    >>> mesh.t.shape[1], sorted(mesh.boundaries)
    (48, ['back', 'bottom', 'front', 'left', 'right', 'top'])
    >>> tip = (mesh.p[0] == 48.0) & (mesh.p[1] == 60.0)
    >>> int(tip.sum())                       # the upper right corner, on both faces
    2
    """
    nx, ny = _positive_ints(cells, 2, "cells")
    if isinstance(layers, bool) or not isinstance(layers, numbers.Integral) or layers <= 0:
        raise InvalidParameter(f"layers must be a positive integer, got {layers!r}.")
    nz = int(layers)
    for name, value in (("thickness", thickness), ("scale", scale)):
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not (
            np.isfinite(value) and value > 0
        ):
            raise InvalidParameter(f"{name} must be a positive, finite number, got {value!r}.")
    unit = MeshTet.init_tensor(np.linspace(0.0, 1.0, nx + 1), np.linspace(0.0, 1.0, ny + 1),
                               np.linspace(0.0, 1.0, nz + 1))
    xi, eta, zeta = unit.p
    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = COOK_CORNERS
    lower = y0 + (y1 - y0) * xi  # the lower edge's y at x = 48 xi
    upper = y3 + (y2 - y3) * xi
    p = np.vstack([x0 + (x1 - x0) * xi, lower + (upper - lower) * eta, thickness * zeta])
    # the grid's own coordinates decide the faces exactly (no tolerance on mapped values)
    on = {
        "left": xi == 0.0, "right": xi == 1.0, "bottom": eta == 0.0, "top": eta == 1.0,
        "front": zeta == 0.0, "back": zeta == 1.0,
    }
    mesh = reorient(MeshTet(scale * p, unit.t))
    facets = mesh.facets
    boundary = mesh.boundary_facets()
    mesh = mesh.with_boundaries({
        name: boundary[mask[facets[:, boundary]].all(axis=0)] for name, mask in on.items()
    })
    validate_mesh(mesh)
    return mesh
