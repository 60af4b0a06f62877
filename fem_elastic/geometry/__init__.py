"""Geometry: tetrahedral meshes, their generators, validation, quality and files.

Holds what a body's shape is before any physics: :mod:`~fem_elastic.geometry.mesh`
(building a validated scikit-fem ``MeshTet`` from arrays, named boundaries,
reorientation, ``beam_mesh``, quality measures),
:mod:`~fem_elastic.geometry.generators` (benchmark geometries: Cook's membrane) and
:mod:`~fem_elastic.geometry.mesh_io` (reading and writing mesh files through
meshio). A bottom layer beside :mod:`fem_elastic.materials`: it may import only
:mod:`fem_elastic.errors` and :mod:`fem_elastic.files` (and numpy, scipy,
scikit-fem, meshio), never the layers above it.
"""

from .mesh import (
    DEGENERATE_TOL,
    beam_mesh,
    boundary_facets,
    mesh_from_arrays,
    mesh_quality,
    remove_unused_vertices,
    reorient,
    signed_volumes,
    validate_mesh,
)
from .generators import cook_membrane_mesh
from .mesh_io import load_mesh, save_mesh

__all__ = [
    "DEGENERATE_TOL", "beam_mesh", "boundary_facets", "cook_membrane_mesh", "load_mesh", "mesh_from_arrays",
    "mesh_quality", "remove_unused_vertices", "reorient", "save_mesh", "signed_volumes",
    "validate_mesh",
]
