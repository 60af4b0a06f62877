"""Tetrahedral meshes: construction, validation and repair.

Every mesh in fem_elastic is a linear scikit-fem :class:`skfem.MeshTet` whose
tetrahedra are positively oriented (signed volume ``V > 0``, see
:func:`signed_volumes`) and whose vertices are all used by some element.
Named boundaries are skfem facet-index arrays (``mesh.boundaries[name]``).

Two skfem facts shape this module:

- ``MeshTet.init_tensor`` and ``MeshTet.init_ball`` return meshes in which about
  half of the tetrahedra are negatively oriented, so :func:`beam_mesh` calls
  :func:`reorient`.
- ``MeshTet(p, t)`` checks nothing unless skfem's logger is at DEBUG level (and
  then only logs): out-of-range indices, NaN coordinates or 2-D points are
  accepted and fail later, far from the cause. :func:`mesh_from_arrays`
  therefore checks the raw arrays before constructing the mesh.

Boundaries are re-mapped through their vertex triples whenever ``t`` or the
vertex numbering changes, because skfem facet indices are derived from ``t``.
"""

from __future__ import annotations

import logging
import numbers
from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike
from skfem import MeshTet, MeshTet2

from ..errors import InvalidMesh, InvalidParameter

__all__ = [
    "DEGENERATE_TOL",
    "RESOLUTION",
    "SIZE_RANGE",
    "beam_mesh",
    "mesh_from_arrays",
    "validate_mesh",
    "signed_volumes",
    "reorient",
    "remove_unused_vertices",
    "mesh_quality",
    "boundary_facets",
]

logger = logging.getLogger(__name__)

#: A tetrahedron is degenerate when ``|V| < DEGENERATE_TOL * mean(|V|)``.
#: Relative, so it is independent of units and mesh size; 1e-10 is far below
#: any usable element (whose stiffness would be ~1e10 times the mean) and far
#: above round-off of a truly flat element (~1e-16 relative).
DEGENERATE_TOL = 1e-10

#: Sizes (m) a mesh may span: from a nanostructure to far beyond a galaxy. Outside
#: this range the quantities assembly computes (volumes ~ L^3, facet normals squared
#: ~ L^4, forces ~ rho g L^3 and their squared norms ~ L^6, with material constants up
#: to ~1e12) leave the float64 range (1e-308 to 1e308), and a mesh that size is
#: almost surely in the wrong units.
SIZE_RANGE = (1e-30, 1e30)

#: Coarsest relative resolution of an edge by its coordinates that is accepted: a
#: vertex at distance d from the origin is known to ~eps d, so an edge of length h
#: is resolved to ~eps d / h of itself, and F = I + grad u and every strain carry
#: that error at rest. 1e-6 (a mm element 4500 km from the origin) leaves strains
#: of 1e-4 accurate to 1 %.
RESOLUTION = 1e-6

_MAX_LISTED = 10
#: skfem numbers vertices in int32 arrays (``mesh.t``)
_MAX_VERTICES = np.iinfo(np.int32).max


def _listed(indices) -> str:
    """Format up to ``_MAX_LISTED`` indices for an error message."""
    indices = np.asarray(indices).ravel()
    shown = ", ".join(str(int(i)) for i in indices[:_MAX_LISTED])
    more = f", ... ({indices.size} in all)" if indices.size > _MAX_LISTED else ""
    return f"[{shown}{more}]"


def _signed_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes of tets given as (n, 3) points and (m, 4) indices."""
    x0 = points[tets[:, 0]]
    a = points[tets[:, 1]] - x0
    b = points[tets[:, 2]] - x0
    c = points[tets[:, 3]] - x0
    return np.einsum("ij,ij->i", np.cross(a, b), c) / 6.0


def _check_arrays(points, tets) -> tuple[np.ndarray, np.ndarray]:
    """Check shapes, finiteness and index range of raw arrays; return copies."""
    try:
        points = np.asarray(points)
        tets = np.asarray(tets)
    except ValueError:  # ragged nested lists
        raise InvalidMesh(
            "points and tets must be rectangular arrays, (n_vertices, 3) coordinates in m "
            "and (n_elements, 4) vertex indices; some rows have a different length. Check "
            "how they were read."
        ) from None
    if points.dtype.kind not in "iuf":
        raise InvalidMesh(
            f"points must be real coordinates in m, got dtype {points.dtype}. Convert them, "
            "e.g. np.asarray(points, dtype=float), if they were read as text."
        )
    if points.ndim != 2 or points.shape[1] != 3:
        raise InvalidMesh(
            f"points must have shape (n_vertices, 3) (3-D coordinates in m), got "
            f"{points.shape}. fem_elastic simulates solids; embed 2-D points in 3-D "
            "by adding a z column."
        )
    if tets.ndim != 2 or tets.shape[1] != 4:
        raise InvalidMesh(
            f"tets must have shape (n_elements, 4) (linear tetrahedra), got {tets.shape}. "
            "For quadratic tets (10 nodes) keep the first 4 columns (the corners)."
        )
    if tets.shape[0] == 0:
        raise InvalidMesh(
            "The mesh has no tetrahedra (tets has 0 rows); a volume tet mesh is needed: "
            "mesh the solid's volume (e.g. gmsh -3 or TetGen), not only its surface."
        )
    if not np.issubdtype(tets.dtype, np.integer):
        raise InvalidMesh(
            f"tets must hold integer vertex indices, got dtype {tets.dtype}. Convert them, "
            "e.g. np.asarray(tets).astype(np.int64), after checking they are whole numbers."
        )
    points = np.array(points, dtype=np.float64)
    bad_vertices = np.nonzero(~np.all(np.isfinite(points), axis=1))[0]
    if bad_vertices.size:
        raise InvalidMesh(
            f"{bad_vertices.size} vertices have NaN or infinite coordinates: vertices "
            f"{_listed(bad_vertices)}. Fix the mesh generator's output or drop those "
            "vertices and the tets that use them.",
            elements=bad_vertices,
        )
    bad_elements = np.nonzero(np.any((tets < 0) | (tets >= points.shape[0]), axis=1))[0]
    if bad_elements.size:
        raise InvalidMesh(
            f"{bad_elements.size} tets refer to vertex indices outside [0, "
            f"{points.shape[0] - 1}]: elements {_listed(bad_elements)}. The connectivity "
            "does not match the point array: 0-based indices are expected (subtract 1 from "
            "1-based ones), and every index needs a row of points.",
            elements=bad_elements,
        )
    return points, np.array(tets, dtype=np.int64)


def _check_scale(points: np.ndarray, tets: np.ndarray) -> None:
    """Raise InvalidMesh when float64 cannot represent the mesh's computations.

    Two ways: the mesh spans less than ``SIZE_RANGE[0]`` or more than
    ``SIZE_RANGE[1]`` m (wrong units; volumes, forces and their squares over- or
    underflow), or it lies so far from the origin that its coordinates resolve an
    edge only to worse than ``RESOLUTION`` of its length (spurious strains at rest;
    beyond ~1e15 times the edge every tet comes out flat).
    """
    lo, hi = SIZE_RANGE
    with np.errstate(over="ignore", invalid="ignore"):
        extent = float(np.max(points.max(axis=0) - points.min(axis=0)))
    far = float(np.abs(points).max())
    if extent == 0.0:
        raise InvalidMesh(
            "All vertices of the mesh coincide (it spans 0 m), so every tet is flat. The "
            "point array is probably wrong (a column of zeros, or points written in the "
            "wrong place): check it against the mesh file."
        )
    if not lo <= extent <= hi or far > hi:
        size = f"spans {extent:.3g} m" if not lo <= extent <= hi else f"reaches {far:.3g} m from the origin"
        raise InvalidMesh(
            f"The mesh {size}, outside the [{lo:g}, {hi:g}] m fem_elastic computes with: "
            "volumes, forces and their squares would leave the float64 range. The units are "
            "probably wrong (fem_elastic uses m): scale the mesh, e.g. mesh.scaled(1e-3) "
            "for coordinates in mm."
        )
    a = tets[:, [1, 2, 3, 2, 3, 3]]
    b = tets[:, [0, 0, 0, 1, 1, 2]]
    edges = points[a] - points[b]
    h = float(np.median(np.sqrt(np.einsum("eki,eki->ek", edges, edges))))
    eps = np.finfo(float).eps
    if h > 0.0 and eps * far > RESOLUTION * h:
        raise InvalidMesh(
            f"The mesh lies {far:.3g} m from the origin, {far / h:.2g} times its typical edge "
            f"({h:.3g} m): float64 coordinates there resolve an edge only to "
            f"{eps * far / h:.0e} of its length (at most {RESOLUTION:g} is accepted), and the "
            "strains computed from them carry that error. Translate the mesh near the origin, "
            "e.g. mesh.translated(-mesh.p.mean(axis=1))."
        )


def _check_connectivity(tets: np.ndarray) -> None:
    """Raise InvalidMesh for a tet that repeats a vertex, then for duplicate tets."""
    key = np.sort(tets, axis=1)
    repeated = np.nonzero((key[:, 1:] == key[:, :-1]).any(axis=1))[0]
    if repeated.size:
        e = int(repeated[0])
        raise InvalidMesh(
            f"{repeated.size} tets use a vertex twice (e.g. element {e} = "
            f"{tets[e].tolist()}): elements {_listed(repeated)}. A tet needs four distinct "
            "vertices; the connectivity is corrupt there (check how it was written or "
            "converted), or drop those elements.",
            elements=repeated,
        )
    # sort the rows by (v0 n + v1, v2 n + v3): equal neighbours are the same tet
    n = int(key.max()) + 1
    k1, k2 = key[:, 0] * n + key[:, 1], key[:, 2] * n + key[:, 3]
    order = np.lexsort((k2, k1))
    same = (k1[order][1:] == k1[order][:-1]) & (k2[order][1:] == k2[order][:-1])
    if same.any():
        dup = np.sort(order[1:][same])
        first = int(order[:-1][same][0])
        raise InvalidMesh(
            f"{dup.size} tets repeat another tet's four vertices (e.g. element {int(order[1:][same][0])} "
            f"and element {first}): elements {_listed(dup)}. Overlapping copies double the "
            "mass and stiffness there; drop them, e.g. keep the rows "
            "np.unique(np.sort(tets, axis=1), axis=0, return_index=True)[1].",
            elements=dup,
        )


def _check_volumes(volumes: np.ndarray, tol: float) -> None:
    """Raise InvalidMesh for degenerate, then inverted, tets."""
    scale = np.mean(np.abs(volumes))
    degenerate = np.nonzero(np.abs(volumes) <= tol * scale)[0]
    if degenerate.size:
        raise InvalidMesh(
            f"{degenerate.size} tets have (nearly) zero volume (|V| <= {tol:g} * mean |V|): "
            f"elements {_listed(degenerate)}. Such elements make the stiffness matrix "
            "singular; remesh (e.g. TetGen or gmsh with a quality constraint) or "
            "remove the slivers.",
            elements=degenerate,
        )
    inverted = np.nonzero(volumes < 0)[0]
    if inverted.size:
        raise InvalidMesh(
            f"{inverted.size} tets are inverted (negative signed volume): elements "
            f"{_listed(inverted)}. If only the vertex order is wrong, fix it with "
            "fem_elastic.reorient(mesh), or load with "
            "fem_elastic.load_mesh(path, reorient=True).",
            elements=inverted,
        )


def _check_unused(n_vertices: int, tets: np.ndarray) -> None:
    unused = np.flatnonzero(np.bincount(tets.ravel(), minlength=n_vertices) == 0)
    if unused.size:
        raise InvalidMesh(
            f"{unused.size} vertices are not used by any tet: vertices {_listed(unused)}. "
            "They would carry degrees of freedom with no stiffness or mass; drop them "
            "with fem_elastic.remove_unused_vertices(mesh).",
            elements=unused,
        )


#: Vertices closer than this fraction of the mesh's diameter count as one point duplicated.
COINCIDENT_TOL = 1e-9


def _check_coincident(points: np.ndarray, tets: np.ndarray) -> None:
    """Coincident vertices: tets on either side of them are not connected (a hidden crack).

    Two close vertices that are the ends of an edge of some tet are connected
    through it: a (very) short edge, not a crack.
    """
    from scipy.spatial import cKDTree

    diameter = float(np.linalg.norm(np.ptp(points, axis=0)))
    pairs = cKDTree(points).query_pairs(COINCIDENT_TOL * diameter, output_type="ndarray")
    if pairs.size:
        n = np.int64(points.shape[0])
        a, b = np.triu_indices(4, 1)  # the six edges of a tet
        ends = np.sort(np.stack((tets[:, a], tets[:, b]), axis=-1).reshape(-1, 2).astype(np.int64), axis=1)
        close = np.sort(pairs.astype(np.int64), axis=1)
        pairs = pairs[~np.isin(close[:, 0] * n + close[:, 1], ends[:, 0] * n + ends[:, 1])]
    if pairs.size:
        dup = np.unique(pairs)
        raise InvalidMesh(
            f"{len(pairs)} pair(s) of vertices coincide (closer than {COINCIDENT_TOL:g} of the mesh's "
            f"size, {COINCIDENT_TOL * diameter:.3g} m): vertices {_listed(dup)}. The tets on either "
            "side share no vertex there, so the body has a hidden crack. Merge them with a tolerance "
            "(gmsh: Coherence Mesh; numpy: np.unique of the rounded coordinates, then remap the tets), "
            "or, if the crack is meant, mesh the pieces as separate bodies.",
            elements=dup,
        )


def _facet_indices(mesh: MeshTet, triples: np.ndarray) -> np.ndarray:
    """skfem facet index of each vertex triple, -1 where it is not a facet."""
    triples = np.sort(np.asarray(triples, dtype=np.int64).reshape(-1, 3), axis=1)
    facets = np.sort(mesh.facets.T.astype(np.int64), axis=1)
    both = np.vstack((facets, triples))
    _, inverse = np.unique(both, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    lookup = np.full(inverse.max() + 1, -1, dtype=np.int64)
    lookup[inverse[: len(facets)]] = np.arange(len(facets))
    return lookup[inverse[len(facets):]]


def _boundary_triples(mesh: MeshTet) -> dict[str, np.ndarray]:
    """Named boundaries as (nf, 3) vertex triples, independent of facet numbering."""
    return {
        name: mesh.facets[:, np.asarray(facets)].T.copy()
        for name, facets in (mesh.boundaries or {}).items()
    }


def _attach_boundaries(mesh: MeshTet, triples: Mapping, missing: str = "raise") -> MeshTet:
    """Return ``mesh`` with boundaries given as vertex triples turned into facets."""
    if not triples:
        return mesh
    boundaries = {}
    for name, tri in triples.items():
        try:
            tri = np.asarray(tri)
        except ValueError:  # ragged nested lists
            raise InvalidMesh(
                f"Boundary {name!r} must be an (n_facets, 3) array of vertex indices; its "
                "rows have different lengths. Give three vertex indices per triangle."
            ) from None
        if tri.size and (tri.ndim != 2 or tri.shape[1] != 3):
            raise InvalidMesh(
                f"Boundary {name!r} must be an (n_facets, 3) array of vertex indices, "
                f"got shape {tri.shape}. Give three vertex indices per triangle."
            )
        if tri.size and not np.issubdtype(tri.dtype, np.integer):
            raise InvalidMesh(
                f"Boundary {name!r} must hold integer vertex indices, got dtype {tri.dtype}. "
                "Convert it, e.g. np.asarray(triangles).astype(np.int64), after checking "
                "the values are whole vertex numbers."
            )
        idx = _facet_indices(mesh, tri)
        bad = np.nonzero(idx < 0)[0]
        if bad.size:
            msg = (
                f"{bad.size} triangles of boundary {name!r} are not faces of any tet: rows "
                f"{_listed(bad)}."
            )
            if missing == "raise":
                raise InvalidMesh(
                    msg + " Boundary triangles must be faces of the tets: check that they use "
                    "the same 0-based vertex numbers as tets.", elements=bad)
            logger.warning("%s They are dropped.", msg)
        boundaries[str(name)] = np.unique(idx[idx >= 0]).astype(np.int32)
    return mesh.with_boundaries(boundaries)


def boundary_facets(mesh: MeshTet, name: str, *, what: str) -> np.ndarray:
    """Facet indices of the named boundary ``name`` of ``mesh``.

    Parameters
    ----------
    mesh : skfem.MeshTet
        Mesh with named boundaries (``mesh.boundaries``).
    name : str
        Boundary name.
    what : str
        What refers to the boundary (e.g. ``"Load 'traction'"``), to start the
        error message with.

    Returns
    -------
    numpy.ndarray
        ``mesh.boundaries[name]``, a non-empty array of facet indices.

    Raises
    ------
    InvalidParameter
        The mesh has no boundary ``name``, or it has no facets.

    Examples
    --------
    >>> import fem_elastic.geometry.mesh as fm
    >>> fm.boundary_facets(fm.beam_mesh(), "left", what="Support").size
    8
    """
    boundaries = mesh.boundaries or {}
    if name not in boundaries:
        raise InvalidParameter(
            f"{what} names boundary {name!r}, which the mesh does not have; its "
            f"boundaries are {sorted(boundaries)}."
        )
    facets = np.asarray(boundaries[name])
    if facets.dtype == bool:  # a mask over the facets (scikit-fem accepts one): its indices
        facets = np.flatnonzero(facets)
    if facets.size == 0:
        raise InvalidParameter(
            f"{what} names boundary {name!r}, which is empty (no facets), so it can "
            "carry no load and fix nothing. Check how the boundary was selected."
        )
    return facets


def signed_volumes(mesh: MeshTet) -> np.ndarray:
    """Signed volume of every tetrahedron.

    Parameters
    ----------
    mesh : skfem.MeshTet
        Linear tet mesh, points in m.

    Returns
    -------
    numpy.ndarray
        Shape ``(n_elements,)``, in m^3. Positive when vertices 1, 2, 3 seen from
        vertex 0 are ordered counter-clockwise, i.e.
        ``V = det[x1 - x0, x2 - x0, x3 - x0] / 6 > 0``.

    Examples
    --------
    >>> import fem_elastic.geometry.mesh as fm
    >>> v = fm.signed_volumes(fm.beam_mesh(1.0, 0.1, 0.1, cells=(4, 1, 1)))
    >>> bool(v.min() > 0), round(float(v.sum()), 12)
    (True, 0.01)
    """
    return _signed_volumes(np.asarray(mesh.p, dtype=np.float64).T, np.asarray(mesh.t).T)


def validate_mesh(mesh: MeshTet, *, degenerate_tol: float = DEGENERATE_TOL) -> MeshTet:
    """Check that ``mesh`` is a usable linear tet mesh; return it unchanged.

    Checks, in order: it is a linear :class:`skfem.MeshTet`; points are finite
    and 3-D; element indices are in range; no tet uses a vertex twice and no two
    tets have the same four vertices; the mesh spans ``SIZE_RANGE`` (1e-30 to 1e30
    m) and lies near enough the origin that its coordinates resolve its edges to
    ``RESOLUTION`` (1e-6); no tet is degenerate (``|V| <= degenerate_tol * mean
    |V|``); none is inverted (``V < 0``); every vertex is used by some tet; no two
    vertices coincide (closer than ``COINCIDENT_TOL`` of the mesh's diameter).

    Parameters
    ----------
    mesh : skfem.MeshTet
        The mesh to check (points in m).
    degenerate_tol : float, optional
        Relative volume below which a tet counts as degenerate; see
        :data:`DEGENERATE_TOL`.

    Returns
    -------
    skfem.MeshTet
        ``mesh`` itself.

    Raises
    ------
    InvalidMesh
        On the first problem found; the message names it, lists up to 10
        offending element (or vertex) indices, which are also in
        ``error.elements``, and says how to fix it.

    Examples
    --------
    >>> import numpy as np
    >>> import fem_elastic.geometry.mesh as fm
    >>> from fem_elastic.errors import InvalidMesh
    >>> mesh = fm.beam_mesh()
    >>> fm.validate_mesh(mesh) is mesh
    True
    >>> flipped = fm.MeshTet(mesh.p, mesh.t[[1, 0, 2, 3]])
    >>> try:
    ...     fm.validate_mesh(flipped)
    ... except InvalidMesh as err:
    ...     print(len(err.elements))
    480
    """
    if isinstance(mesh, MeshTet2):
        raise InvalidMesh(
            "A quadratic MeshTet2 was given, but fem_elastic meshes have linear "
            "geometry. Use skfem.MeshTet(mesh.p, mesh.t) for the linear mesh, or build "
            "one with fem_elastic.load_mesh / fem_elastic.beam_mesh (quadratic fields "
            "come from the element order, not the mesh)."
        )
    if not isinstance(mesh, MeshTet):
        raise InvalidMesh(
            f"A tetrahedral mesh (skfem.MeshTet) is needed, got {type(mesh).__name__}. "
            "Build one with fem_elastic.beam_mesh, load one with fem_elastic.load_mesh, "
            "or tetrahedralize: a MeshHex can be split with skfem.MeshTet.init_tensor on "
            "the same grid, a surface can be meshed with gmsh -3 or TetGen."
        )
    points, tets = _check_arrays(np.asarray(mesh.p).T, np.asarray(mesh.t).T)
    _check_connectivity(tets)
    _check_scale(points, tets)
    _check_volumes(_signed_volumes(points, tets), degenerate_tol)
    _check_unused(points.shape[0], tets)
    _check_coincident(points, tets)
    return mesh


def mesh_from_arrays(
    points: ArrayLike,
    tets: ArrayLike,
    boundaries: Mapping[str, ArrayLike] | None = None,
    *,
    reorient: bool = False,
    validate: bool = True,
) -> MeshTet:
    """Build a checked :class:`skfem.MeshTet` from point and element arrays.

    The raw arrays are checked (shape, finite coordinates, index range) before
    skfem sees them, because ``MeshTet(p, t)`` accepts such input silently.

    Parameters
    ----------
    points : array_like
        Vertex coordinates, shape ``(n_vertices, 3)``, in m.
    tets : array_like of int
        Vertex indices of each tet, shape ``(n_elements, 4)``, 0-based.
    boundaries : mapping of str to array_like, optional
        Named boundaries, each an ``(n_facets, 3)`` array of vertex indices of
        tet faces (in any vertex order).
    reorient : bool, optional
        Swap two vertices of every negatively oriented tet first.
    validate : bool, optional
        Run :func:`validate_mesh` on the result.

    Returns
    -------
    skfem.MeshTet
        The mesh, with ``boundaries`` as skfem facet-index arrays.

    Raises
    ------
    InvalidMesh
        When the arrays are malformed, or (``validate=True``) the mesh fails
        :func:`validate_mesh`, or a boundary triangle is not a tet face.

    Examples
    --------
    >>> import fem_elastic.geometry.mesh as fm
    >>> points = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    >>> mesh = fm.mesh_from_arrays(points, [[0, 1, 2, 3]], {"base": [[0, 2, 1]]})
    >>> mesh.t.shape, mesh.boundaries["base"].size
    ((4, 1), 1)
    """
    return _from_arrays(points, tets, boundaries, reorient=reorient, validate=validate)


def _from_arrays(points, tets, boundaries, *, reorient, validate, missing="raise") -> MeshTet:
    """:func:`mesh_from_arrays`, choosing what to do with stray boundary triangles."""
    if boundaries is not None and not isinstance(boundaries, Mapping):
        raise InvalidMesh(
            "boundaries must be a dict {name: (n_facets, 3) vertex indices}, e.g. "
            f"{{'left': [[0, 2, 1]]}}; got a {type(boundaries).__name__}."
        )
    p, t = _check_arrays(points, tets)
    if reorient:
        t = _reoriented(p, t)
    mesh = MeshTet(np.ascontiguousarray(p.T), np.ascontiguousarray(t.T.astype(np.int32)))
    if validate:
        validate_mesh(mesh)
    return _attach_boundaries(mesh, boundaries or {}, missing=missing)


def _reoriented(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    negative = _signed_volumes(points, tets) < 0
    tets = tets.copy()
    tets[negative, 0], tets[negative, 1] = tets[negative, 1], tets[negative, 0].copy()
    if negative.any():
        logger.debug("Reoriented %d of %d tets.", int(negative.sum()), len(tets))
    return tets


def reorient(mesh: MeshTet) -> MeshTet:
    """Make every tet positively oriented by swapping two of its vertices.

    Named boundaries and subdomains are kept (boundaries are re-mapped through
    their vertex triples).

    Parameters
    ----------
    mesh : skfem.MeshTet
        Linear tet mesh.

    Returns
    -------
    skfem.MeshTet
        A new mesh with the same points and elements, ``signed_volumes > 0``
        except for degenerate tets, which stay degenerate.

    Examples
    --------
    >>> import numpy as np
    >>> import fem_elastic.geometry.mesh as fm
    >>> cube = fm.MeshTet.init_tensor(*(np.linspace(0, 1, 3),) * 3)
    >>> bool((fm.signed_volumes(cube) < 0).any())
    True
    >>> bool((fm.signed_volumes(fm.reorient(cube)) > 0).all())
    True
    """
    points, tets = _check_arrays(np.asarray(mesh.p).T, np.asarray(mesh.t).T)
    new = MeshTet(mesh.p.copy(), np.ascontiguousarray(_reoriented(points, tets).T.astype(np.int32)))
    new = _attach_boundaries(new, _boundary_triples(mesh))
    if mesh.subdomains:
        new = new.with_subdomains({k: np.asarray(v) for k, v in mesh.subdomains.items()})
    return new


def remove_unused_vertices(mesh: MeshTet) -> MeshTet:
    """Drop vertices that no tet uses, renumbering the rest in order.

    Parameters
    ----------
    mesh : skfem.MeshTet
        Linear tet mesh.

    Returns
    -------
    skfem.MeshTet
        A new mesh; named boundaries and subdomains are kept.

    Examples
    --------
    >>> import numpy as np
    >>> import fem_elastic.geometry.mesh as fm
    >>> p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [5, 5, 5.0]]).T
    >>> fm.remove_unused_vertices(fm.MeshTet(p, np.array([[0, 1, 2, 3]]).T)).p.shape
    (3, 4)
    """
    used, t_new = np.unique(np.asarray(mesh.t), return_inverse=True)
    t_new = t_new.reshape(mesh.t.shape).astype(np.int32)
    new = MeshTet(np.ascontiguousarray(mesh.p[:, used]), t_new)
    old_to_new = np.full(mesh.p.shape[1], -1, dtype=np.int64)
    old_to_new[used] = np.arange(used.size)
    triples = {k: old_to_new[v] for k, v in _boundary_triples(mesh).items()}
    new = _attach_boundaries(new, triples)
    if mesh.subdomains:
        new = new.with_subdomains({k: np.asarray(v) for k, v in mesh.subdomains.items()})
    if used.size < mesh.p.shape[1]:
        logger.info("Removed %d unused vertices.", mesh.p.shape[1] - used.size)
    return new


def _mean_ratio(points: np.ndarray, tets: np.ndarray, volumes: np.ndarray) -> np.ndarray:
    """Mean-ratio shape quality ``12 (3|V|)^(2/3) / sum(l_ij^2)``, signed by V.

    1 for a regular tet, -> 0 for flat ones, negative for inverted ones.
    """
    edges = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    sum_l2 = sum(np.sum((points[tets[:, i]] - points[tets[:, j]]) ** 2, axis=1) for i, j in edges)
    return np.sign(volumes) * 12.0 * np.cbrt(3.0 * np.abs(volumes)) ** 2 / sum_l2


def mesh_quality(mesh: MeshTet) -> dict:
    """Summary statistics of a tet mesh, for reports and ``fem-elastic info``.

    The shape measure is the mean ratio ``q = 12 (3|V|)^(2/3) / sum(l_ij^2)``
    (Liu & Joe 1994): 1 for a regular tet, near 0 for slivers, signed by the
    orientation, so inverted tets show up as negative.

    Parameters
    ----------
    mesh : skfem.MeshTet
        Linear tet mesh (points in m).

    Returns
    -------
    dict
        ``n_vertices``, ``n_elements``, ``volume`` (total, m^3), ``min_volume``,
        ``max_volume``, ``mean_volume`` (signed, m^3), ``min_quality``,
        ``mean_quality``, ``n_inverted``, ``bounding_box`` (``(min xyz, max
        xyz)``, m) and ``boundaries`` (name -> number of facets).

    Examples
    --------
    >>> import fem_elastic.geometry.mesh as fm
    >>> q = fm.mesh_quality(fm.beam_mesh(cells=(10, 1, 1)))
    >>> q["n_elements"], q["boundaries"]["left"], round(q["volume"], 12)
    (60, 2, 0.01)
    """
    points, tets = _check_arrays(np.asarray(mesh.p).T, np.asarray(mesh.t).T)
    volumes = _signed_volumes(points, tets)
    quality = _mean_ratio(points, tets, volumes)
    return {
        "n_vertices": int(points.shape[0]),
        "n_elements": int(tets.shape[0]),
        "volume": float(volumes.sum()),
        "min_volume": float(volumes.min()),
        "max_volume": float(volumes.max()),
        "mean_volume": float(volumes.mean()),
        "min_quality": float(quality.min()),
        "mean_quality": float(quality.mean()),
        "n_inverted": int(np.count_nonzero(volumes < 0)),
        "bounding_box": (points.min(axis=0).tolist(), points.max(axis=0).tolist()),
        "boundaries": {k: int(np.size(v)) for k, v in (mesh.boundaries or {}).items()},
    }


def _positive_length(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InvalidParameter(f"{name} must be a positive length in m, got {value!r}.")
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise InvalidParameter(f"{name} must be a positive, finite length in m, got {value!r}.")
    return value


def _positive_ints(value, n: int, name: str, hint: str = "") -> tuple[int, ...]:
    """``value`` as ``n`` positive integers (cell counts), or :class:`InvalidParameter` naming ``name``."""
    try:
        items = tuple(value)
    except TypeError:
        raise InvalidParameter(f"{name} must be {n} positive integers{hint}, got {value!r}.") from None
    if len(items) != n or not all(
        isinstance(c, numbers.Integral) and not isinstance(c, bool) and c > 0  # type: ignore[operator]
        for c in items
    ):
        raise InvalidParameter(f"{name} must be {n} positive integers{hint}, got {items!r}.")
    return tuple(int(c) for c in items)


def beam_mesh(
    length: float = 1.0,
    width: float = 0.1,
    height: float = 0.1,
    cells: tuple[int, int, int] = (20, 2, 2),
) -> MeshTet:
    """Tet mesh of the box ``[0, length] x [0, width] x [0, height]``.

    A structured grid of ``cells`` hexahedra, each split into 6 tets (by
    ``skfem.MeshTet.init_tensor``), reoriented so every tet has positive volume.

    Parameters
    ----------
    length : float, optional
        Extent along x (the beam axis), m.
    width : float, optional
        Extent along y, m.
    height : float, optional
        Extent along z, m.
    cells : tuple of 3 int, optional
        Number of hexahedral cells along x, y and z.

    Returns
    -------
    skfem.MeshTet
        ``(cells[0]+1)(cells[1]+1)(cells[2]+1)`` vertices and
        ``6 cells[0] cells[1] cells[2]`` tets, with named boundaries "left"
        (x = 0), "right" (x = length), "front" (y = 0), "back" (y = width),
        "bottom" (z = 0) and "top" (z = height).

    Raises
    ------
    InvalidParameter
        A dimension is not positive and finite, ``cells`` is not three
        positive integers, or the mesh would not fit in int32 indices or in memory.

    Examples
    --------
    >>> import fem_elastic.geometry.mesh as fm
    >>> mesh = fm.beam_mesh(length=2.0, width=0.2, height=0.1, cells=(10, 2, 1))
    >>> mesh.p.shape, mesh.t.shape
    ((3, 66), (4, 120))
    >>> sorted(mesh.boundaries)
    ['back', 'bottom', 'front', 'left', 'right', 'top']
    """
    dims = (
        _positive_length("length", length),
        _positive_length("width", width),
        _positive_length("height", height),
    )
    cells = _positive_ints(cells, 3, "cells", " (nx, ny, nz)")  # type: ignore[assignment]
    n_vertices = (cells[0] + 1) * (cells[1] + 1) * (cells[2] + 1)
    if n_vertices > _MAX_VERTICES:
        raise InvalidParameter(
            f"cells = {tuple(int(n) for n in cells)} gives {n_vertices:.3g} vertices and "
            f"{6 * cells[0] * cells[1] * cells[2]:.3g} tets, more than the {_MAX_VERTICES} "
            "vertices skfem's 32-bit element indices can number. Use fewer cells."
        )
    axes = [np.linspace(0.0, d, int(n) + 1) for d, n in zip(dims, cells)]
    try:
        mesh = reorient(MeshTet.init_tensor(*axes))
    except MemoryError:
        raise InvalidParameter(
            f"cells = {tuple(int(n) for n in cells)} gives {n_vertices:.3g} vertices and "
            f"{6 * cells[0] * cells[1] * cells[2]:.3g} tets, which do not fit in memory "
            "here. Use fewer cells."
        ) from None
    # init_tensor puts the end coordinates exactly (linspace endpoints), but
    # compare with a tolerance relative to the cell size to be robust. The box is
    # convex, so a facet whose midpoint lies on one of its planes lies in it: every
    # such facet is a boundary facet, and the midpoints are tested once for all six
    # (skfem's with_boundaries of six tests took 1.1 ms of a 1.3 ms 27x1x1 beam).
    tol = [1e-9 * d / n for d, n in zip(dims, cells)]
    midpoints = mesh.p[:, mesh.facets].mean(axis=1)
    planes = {"left": (0, 0.0), "right": (0, dims[0]), "front": (1, 0.0), "back": (1, dims[1]),
              "bottom": (2, 0.0), "top": (2, dims[2])}
    named = mesh.with_boundaries({
        name: np.flatnonzero(np.abs(midpoints[axis] - at) < tol[axis]).astype(np.int32)
        for name, (axis, at) in planes.items()
    })
    # the copy shares t, of which the facets are a function: hand it scikit-fem's lazily built
    # facets rather than have them built again on first use (0.5 ms of a 27x1x1 P2 model); where
    # a scikit-fem release names them otherwise nothing is copied, and they are built as before
    if np.array_equal(named.t, mesh.t):
        for cached in ("_facets", "_t2f"):
            if cached in vars(mesh):
                setattr(named, cached, vars(mesh)[cached])
    return named
