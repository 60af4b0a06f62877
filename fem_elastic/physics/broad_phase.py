"""Broad phase of collision detection: a hierarchy of bounding spheres.

The lecture notes' collision detection in big scenes
(``seeds/003_fa0e65673940b383.txt``, "Collision Detection in Big Scenes",
"Hierarchical Collision Test"; ``seeds/004_c7ec6aa2b510111b.txt``, "Broad
phase: AABBs, bounding spheres"): testing all n^2 pairs of primitives is
quadratic; instead each primitive gets a conservative proxy, a bounding
sphere (centre ``c``, radius ``r``; two spheres overlap only if
``|c1 - c2| < r1 + r2``), and the spheres are organised in a tree searched
recursively with early pruning, so only the parts of the scene that are close
are visited.

The tree here is scipy's :class:`scipy.spatial.cKDTree` over the sphere
centres: a k-d tree is a hierarchy of nested axis-aligned boxes, each node
bounding the centres below it. A query for the spheres that may overlap a
sphere of radius ``r`` walks it with the radius ``r + r_max`` (``r_max`` the
largest radius in the tree), pruning every box farther than that, and the
candidates are then filtered by the exact sphere-sphere test. Building the
tree costs O(n log n) and a query O(log n + k) for k candidates, so the
broad phase of n primitives of similar size costs O(n log n)
(``scripts/bench_broad_phase.py`` fits the exponent).

The narrow phase (exact distances between the candidates) is the caller's:
:mod:`fem_elastic.physics.impulse_contact`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from ..errors import InvalidParameter

__all__ = ["BoundingSpheres", "triangle_spheres", "sphere_pairs"]


def _as_spheres(centers, radii):
    c = np.asarray(centers, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != 3:
        raise InvalidParameter(f"sphere centres must be an (n, 3) array (m), got shape {c.shape}.")
    r = np.broadcast_to(np.asarray(radii, dtype=np.float64), (c.shape[0],)).copy()
    if not (np.isfinite(c).all() and np.isfinite(r).all()) or (r < 0.0).any():
        raise InvalidParameter(
            "bounding spheres need finite centres (m) and finite radii >= 0 (m); got NaN, "
            "infinite or negative values (a state that blew up?)."
        )
    return c, r


def triangle_spheres(points: np.ndarray, faces: np.ndarray):
    """Bounding spheres of triangles: the centroid and the largest distance to a corner.

    Parameters
    ----------
    points : numpy.ndarray
        ``(n, 3)`` vertex positions (m).
    faces : numpy.ndarray
        ``(m, 3)`` vertex indices of the triangles.

    Returns
    -------
    centers : numpy.ndarray
        ``(m, 3)`` (m).
    radii : numpy.ndarray
        ``(m,)`` (m); every corner, hence the whole triangle, is inside.
    """
    corners = points[faces]  # (m, 3, 3)
    centers = corners.mean(axis=1)
    radii = np.linalg.norm(corners - centers[:, None, :], axis=2).max(axis=1)
    return centers, radii


class BoundingSpheres:
    """A tree of bounding spheres (scipy's k-d tree over their centres).

    Parameters
    ----------
    centers : array_like
        ``(n, 3)`` sphere centres (m).
    radii : float or array_like
        ``(n,)`` radii (m), >= 0, or one radius for all.

    Examples
    --------
    >>> import numpy as np
    >>> tree = BoundingSpheres(np.array([[0.0, 0, 0], [1.0, 0, 0]]), 0.1)
    >>> i, j = tree.query(np.array([[0.95, 0.0, 0.0]]), 0.0)
    >>> i.tolist(), j.tolist()   # the point lies in the second sphere only
    ([0], [1])
    """

    def __init__(self, centers: ArrayLike, radii: float | ArrayLike) -> None:
        self.centers, self.radii = _as_spheres(centers, radii)
        self.r_max = float(self.radii.max()) if self.radii.size else 0.0
        self.tree = cKDTree(self.centers)

    def __len__(self) -> int:
        return int(self.centers.shape[0])

    def query(self, centers: ArrayLike, radii: float | ArrayLike,
              margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Pairs of overlapping spheres between ``(centers, radii)`` and the tree.

        Sphere ``i`` of the query and ``j`` of the tree are a pair when
        ``|c_i - c_j| < r_i + r_j + margin`` (the notes' sphere-sphere test,
        spheres inflated by ``margin`` (m), e.g. a contact thickness).

        Returns
        -------
        i, j : numpy.ndarray
            int64 indices into the query's spheres and the tree's, sorted by i then j.
        """
        c, r = _as_spheres(centers, radii)
        empty = np.zeros(0, dtype=np.int64)
        if c.shape[0] == 0 or len(self) == 0:
            return empty, empty.copy()
        reach = float(r.max()) + self.r_max + float(margin)
        other = cKDTree(c)
        pairs = other.sparse_distance_matrix(self.tree, reach, output_type="ndarray")
        i = pairs["i"].astype(np.int64)
        j = pairs["j"].astype(np.int64)
        keep = pairs["v"] < r[i] + self.radii[j] + margin
        i, j = i[keep], j[keep]
        order = np.lexsort((j, i))
        return i[order], j[order]

    def self_pairs(self, margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Pairs ``i < j`` of overlapping spheres within the tree (inflated by ``margin``, m).

        Returns
        -------
        i, j : numpy.ndarray
            int64 indices, ``i < j``, sorted by i then j.
        """
        empty = np.zeros(0, dtype=np.int64)
        if len(self) < 2:
            return empty, empty.copy()
        pairs = self.tree.query_pairs(2.0 * self.r_max + float(margin), output_type="ndarray")
        if pairs.size == 0:
            return empty, empty.copy()
        i, j = pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)
        d = np.linalg.norm(self.centers[i] - self.centers[j], axis=1)
        keep = d < self.radii[i] + self.radii[j] + margin
        i, j = i[keep], j[keep]
        order = np.lexsort((j, i))
        return i[order], j[order]


def sphere_pairs(centers_a, radii_a, centers_b=None, radii_b=None, margin: float = 0.0):
    """Overlapping bounding spheres, through the tree: the broad phase in one call.

    With one set, its pairs ``i < j`` (:meth:`BoundingSpheres.self_pairs`);
    with two, the pairs between them (:meth:`BoundingSpheres.query`, ``i``
    in the first set, ``j`` in the second).

    Parameters
    ----------
    centers_a, centers_b : array_like
        ``(n, 3)`` sphere centres (m).
    radii_a, radii_b : float or array_like
        Radii (m), >= 0.
    margin : float
        Added to every sum of radii (m), >= 0.

    Returns
    -------
    i, j : numpy.ndarray
        int64 index arrays of the candidate pairs.
    """
    margin = float(margin)
    if not np.isfinite(margin) or margin < 0.0:
        raise InvalidParameter(f"margin must be a finite distance >= 0 (m), got {margin!r}.")
    if centers_b is None:
        return BoundingSpheres(centers_a, radii_a).self_pairs(margin)
    return BoundingSpheres(centers_b, radii_b).query(centers_a, radii_a, margin)
