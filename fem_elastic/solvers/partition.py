"""Partitioning a tet mesh for distributed solves: METIS on the dual graph, node owners, numbering.

A distributed solve (:mod:`fem_elastic.solvers.distributed`) gives every MPI rank a
set of tetrahedra to assemble. The tets are split with METIS (``pymetis``) on the
mesh's **dual graph**, two tets being neighbours when they share a face
(``ncommon=3``), which keeps the cut between ranks, and with it the ghost nodes
and the off-process matrix entries, small. Every node of the finite element space
(vertices, and for P2 the edge nodes) is **owned** by the lowest rank among the
tets that hold it, and the nodes are renumbered so that each rank owns one
contiguous block: the row layout of a PETSc MPIAIJ matrix with block size 3
(DOF ``3 n + i`` of node ``n``).

The partition depends only on the mesh and the number of parts; it is computed
once, on rank 0, and broadcast, so every rank works from the same one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from ..errors import InvalidParameter, MissingDependency

__all__ = ["Partition", "partition_elements", "partition_space", "MPI_INSTALL_HINT"]

#: how to get the distributed backend (README, docs/scaling.md)
MPI_INSTALL_HINT = (
    "the distributed backend needs mpi4py, petsc4py and pymetis: on Debian/Ubuntu run "
    "'bash scripts/install_mpi.sh' (Debian's PETSc 3.18 with Open MPI, petsc4py and mpi4py "
    "compiled against it, pymetis from its wheel; see docs/scaling.md)"
)


def partition_elements(t: np.ndarray, nparts: int) -> np.ndarray:
    """The part (0 .. nparts-1) of every tet, by METIS on the face-sharing dual graph.

    Parameters
    ----------
    t : numpy.ndarray
        ``(4, n_tets)`` vertex indices (scikit-fem's ``mesh.t``).
    nparts : int
        Number of parts (MPI ranks), 1 <= nparts <= n_tets.

    Returns
    -------
    numpy.ndarray
        ``(n_tets,)`` int64; every part is non-empty.

    Raises
    ------
    InvalidParameter
        More parts than tets.
    MissingDependency
        pymetis is not installed (only asked for with nparts > 1).
    """
    t = np.asarray(t)
    n_tets = t.shape[1]
    if isinstance(nparts, bool) or not isinstance(nparts, (int, np.integer)) or nparts < 1:
        raise InvalidParameter(f"nparts must be a whole number >= 1, got {nparts!r}.")
    if nparts > n_tets:
        raise InvalidParameter(
            f"cannot split {n_tets} tets among {nparts} MPI ranks: every rank needs at least one "
            f"tet. Run with at most {n_tets} rank(s) (mpiexec -n {n_tets} ...) or refine the mesh."
        )
    if nparts == 1:
        return np.zeros(n_tets, dtype=np.int64)
    try:
        import pymetis
    except ImportError as e:
        raise MissingDependency(f"partitioning needs pymetis: {MPI_INSTALL_HINT}.") from e
    part = pymetis.part_mesh(nparts, cast(Any, np.ascontiguousarray(t.T, dtype=np.int64)), gtype=pymetis.GType.DUAL, ncommon=3)
    parts = np.asarray(part.element_part, dtype=np.int64)
    if np.unique(parts).size != nparts:  # METIS may leave a part empty on tiny or odd meshes
        # fall back to contiguous blocks of the METIS order: every part non-empty, cut still local
        order = np.argsort(parts, kind="stable")
        parts = np.empty(n_tets, dtype=np.int64)
        parts[order] = np.arange(n_tets) * nparts // n_tets
    return parts


@dataclass(frozen=True)
class Partition:
    """Tets per rank, node owners and the rank-contiguous node numbering.

    Attributes
    ----------
    nparts : int
    element_part : numpy.ndarray
        ``(n_tets,)`` the rank that assembles each tet.
    node_owner : numpy.ndarray
        ``(n_nodes,)`` the rank that owns each node of the space (the lowest rank
        among its tets).
    new_node : numpy.ndarray
        ``(n_nodes,)`` each node's index in the distributed numbering, where rank r
        owns ``node_ranges[r] .. node_ranges[r+1]-1``.
    node_ranges : numpy.ndarray
        ``(nparts + 1,)`` the owned blocks.
    """

    nparts: int
    element_part: np.ndarray
    node_owner: np.ndarray
    new_node: np.ndarray
    node_ranges: np.ndarray

    def new_dofs(self, dofs: np.ndarray) -> np.ndarray:
        """The distributed index of DOFs in the space's numbering (``3 n + i`` -> ``3 n' + i``)."""
        dofs = np.asarray(dofs, dtype=np.int64)
        return 3 * self.new_node[dofs // 3] + dofs % 3

    def elements(self, rank: int) -> np.ndarray:
        """The tets rank ``rank`` assembles (sorted)."""
        return np.flatnonzero(self.element_part == rank)

    def dof_range(self, rank: int) -> tuple[int, int]:
        """The DOFs rank ``rank`` owns in the distributed numbering, ``[start, end)``."""
        return int(3 * self.node_ranges[rank]), int(3 * self.node_ranges[rank + 1])


def partition_space(element_dofs: np.ndarray, ndofs: int, element_part: np.ndarray,
                    nparts: int) -> Partition:
    """Node owners and numbering of a space from its tets' parts.

    Parameters
    ----------
    element_dofs : numpy.ndarray
        ``(3 nloc, n_tets)`` the DOFs of each tet (``Discretization.element_dofs``).
    ndofs : int
        DOFs of the space.
    element_part : numpy.ndarray
        ``(n_tets,)`` from :func:`partition_elements`.
    nparts : int
    """
    n_nodes = ndofs // 3
    nodes = np.asarray(element_dofs[0::3], dtype=np.int64) // 3  # (nloc, n_tets): the x DOFs, 3 n
    owner = np.full(n_nodes, nparts, dtype=np.int64)
    np.minimum.at(owner, nodes.ravel(), np.broadcast_to(element_part, nodes.shape).ravel())
    if np.any(owner == nparts):
        raise InvalidParameter("the space has nodes that belong to no tet; validate the mesh first.")
    order = np.lexsort((np.arange(n_nodes), owner))  # by owner, then by the old index
    new_node = np.empty(n_nodes, dtype=np.int64)
    new_node[order] = np.arange(n_nodes)
    ranges = np.concatenate([[0], np.cumsum(np.bincount(owner, minlength=nparts))]).astype(np.int64)
    return Partition(nparts=nparts, element_part=np.asarray(element_part, dtype=np.int64),
                     node_owner=owner, new_node=new_node, node_ranges=ranges)
