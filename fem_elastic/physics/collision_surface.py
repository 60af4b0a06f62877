"""The collision surface of a model: boundary triangles of its tet mesh, on its DOFs.

Contact between bodies (IPC, impulses) acts on the boundary of the tet
mesh only. A :class:`CollisionSurface` lists the surface vertices by the
flat DOF indices of their x, y, z (so a contact term reads and scatters
straight into the model's DOF vector), the outward-oriented boundary
triangles and their edges over those vertices, and the body each vertex
belongs to.

Quadratic (P2) meshes collide by their vertices only: the surface is the
flat triangle through the three corner nodes of each curved boundary face,
and the edge nodes take no part in contact (their motion still enters
through the elasticity). With the small curvature of a P2 face in a
simulation the gap this leaves is second order in the element size; give
``dhat`` above it if it matters.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, overload

import numpy as np

from ..errors import InvalidMesh

if TYPE_CHECKING:  # for annotations only (the model imports this module)
    from .model import Model

__all__ = ["CollisionSurface", "collision_surface", "surface_triangles"]


@overload
def surface_triangles(tets: np.ndarray, points: np.ndarray,
                      return_tets: Literal[False] = False) -> np.ndarray: ...


@overload
def surface_triangles(tets: np.ndarray, points: np.ndarray,
                      return_tets: Literal[True]) -> tuple[np.ndarray, np.ndarray]: ...


def surface_triangles(tets: np.ndarray, points: np.ndarray,
                      return_tets: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Boundary triangles of a tet mesh, counter-clockwise seen from outside.

    A face lies on the boundary when exactly one tet has it; its normal
    ``(b - a) x (c - a)`` points away from the tet's fourth vertex.

    Parameters
    ----------
    tets : numpy.ndarray
        ``(m, 4)`` vertex indices.
    points : numpy.ndarray
        ``(n, 3)`` reference vertex positions (m), for the orientation.
    return_tets : bool
        Also return the tet each triangle belongs to (the renderer colours a
        face by its tet's cell data).

    Returns
    -------
    faces : numpy.ndarray
        ``(f, 3)`` int64 vertex indices.
    face_tet : numpy.ndarray
        ``(f,)`` int64 tet indices, only with ``return_tets``.
    """
    tets = np.asarray(tets, dtype=np.int64).reshape(-1, 4)
    if tets.shape[0] == 0:
        empty = np.zeros((0, 3), dtype=np.int64)
        return (empty, np.zeros(0, dtype=np.int64)) if return_tets else empty
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])  # face k leaves out vertex k
    faces = tets[:, local].reshape(-1, 3)
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    on_surface = counts[inverse.ravel()] == 1
    faces = faces[on_surface]
    face_tet = np.repeat(np.arange(len(tets)), 4)[on_surface]
    opposite = tets[face_tet, np.tile(np.arange(4), len(tets))[on_surface]]
    a, b, c = (points[faces[:, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    inward = np.einsum("ij,ij->i", normal, points[opposite] - a) > 0
    faces[inward] = faces[inward][:, [0, 2, 1]]
    return (faces, face_tet) if return_tets else faces


def _edges_of(faces: np.ndarray) -> np.ndarray:
    """Unique undirected edges ``(k, 2)`` (smaller index first) of triangles ``(f, 3)``."""
    if faces.shape[0] == 0:
        return np.zeros((0, 2), dtype=np.int64)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0).astype(np.int64)


@dataclass(frozen=True)
class CollisionSurface:
    """The boundary of one or several bodies, as contact sees it.

    Attributes
    ----------
    vertex_dofs : numpy.ndarray
        ``(n_s, 3)`` int64: indices into the flat DOF vector ``x`` of each
        surface vertex's x, y, z.
    faces : numpy.ndarray
        ``(m, 3)`` int64 triangles over the ``n_s`` surface vertices,
        counter-clockwise seen from outside (outward normal).
    edges : numpy.ndarray
        ``(k, 2)`` int64 unique edges of the faces.
    body : numpy.ndarray
        ``(n_s,)`` int64 body id of each surface vertex (0 for a single body).
    rest : numpy.ndarray
        ``(n_s, 3)`` float64 reference positions (m).
    """

    vertex_dofs: np.ndarray
    faces: np.ndarray
    edges: np.ndarray
    body: np.ndarray
    rest: np.ndarray

    def __post_init__(self):
        for name in ("vertex_dofs", "faces", "edges", "body", "rest"):
            getattr(self, name).setflags(write=False)

    @property
    def n_vertices(self) -> int:
        """Number of surface vertices ``n_s``."""
        return int(self.vertex_dofs.shape[0])

    def positions(self, x: np.ndarray) -> np.ndarray:
        """Surface vertex positions ``(n_s, 3)`` (m) of a flat DOF vector ``x``."""
        return np.asarray(x)[self.vertex_dofs]

    def displacements(self, dx: np.ndarray) -> np.ndarray:
        """Surface vertex values ``(n_s, 3)`` of a flat DOF increment (same gather as positions)."""
        return np.asarray(dx)[self.vertex_dofs]

    @classmethod
    def stack(cls, surfaces: Sequence[CollisionSurface],
              dof_offsets: Sequence[int] | np.ndarray) -> "CollisionSurface":
        """The surfaces of several bodies as one, DOF indices offset and body ids set.

        Parameters
        ----------
        surfaces : sequence of CollisionSurface
            One per body, each on its own body's DOF vector.
        dof_offsets : sequence of int
            Where each body's DOFs start in the stacked DOF vector.

        Returns
        -------
        CollisionSurface
            Vertex ``i`` of body ``b`` gets body id ``b`` (its position in the
            list), faces and edges are renumbered past the earlier bodies'
            vertices.
        """
        surfaces = list(surfaces)
        offsets = [int(o) for o in dof_offsets]
        if len(surfaces) != len(offsets) or not surfaces:
            raise ValueError(
                f"stack needs one DOF offset per surface and at least one surface; got "
                f"{len(surfaces)} surface(s) and {len(offsets)} offset(s)."
            )
        vd, faces, edges, body, rest = [], [], [], [], []
        base = 0
        for b, (s, off) in enumerate(zip(surfaces, offsets)):
            vd.append(s.vertex_dofs + off)
            faces.append(s.faces + base)
            edges.append(s.edges + base)
            body.append(np.full(s.n_vertices, b, dtype=np.int64))
            rest.append(s.rest)
            base += s.n_vertices
        return cls(
            vertex_dofs=np.concatenate(vd).astype(np.int64),
            faces=np.concatenate(faces).astype(np.int64),
            edges=np.concatenate(edges).astype(np.int64),
            body=np.concatenate(body),
            rest=np.concatenate(rest).astype(np.float64),
        )


def collision_surface(model: Model) -> CollisionSurface:
    """The collision surface of a single-body :class:`fe.Model`.

    The boundary triangles of the tet mesh (faces of exactly one tet),
    oriented outwards, over the vertices they touch; P2 meshes by their
    corner vertices only (see the module docstring).

    Parameters
    ----------
    model : Model
        A model with ``mesh`` (skfem.MeshTet) and ``space`` (its Discretization).

    Returns
    -------
    CollisionSurface

    Raises
    ------
    InvalidMesh
        When the mesh has no boundary triangle (no tets).
    """
    mesh = model.mesh
    points = np.asarray(mesh.p, dtype=np.float64).T
    faces = surface_triangles(np.asarray(mesh.t).T, points)
    if faces.shape[0] == 0:
        raise InvalidMesh(
            "the mesh has no surface (no boundary triangle), so it cannot collide: give a tet "
            "mesh with at least one tet, or leave this body out of the contact."
        )
    verts, local = np.unique(faces, return_inverse=True)
    faces = local.reshape(-1, 3).astype(np.int64)
    return CollisionSurface(
        vertex_dofs=np.ascontiguousarray(model.space.vertex_dofs[verts], dtype=np.int64),
        faces=faces,
        edges=_edges_of(faces),
        body=np.zeros(verts.size, dtype=np.int64),
        rest=np.ascontiguousarray(points[verts]),
    )
