"""One rank's share of a model in a distributed (PETSc over MPI) solve.

Every rank holds the whole :class:`~fem_elastic.Model` (the script or scene built
it on every rank) and the replicated state between solves; inside a solve the
work is split:

- the tets are partitioned by METIS (:mod:`~fem_elastic.solvers.partition`);
  rank r builds the body's energy on **its own tets only** (a sub-mesh and its
  own :class:`~fem_elastic.discretization.space.Discretization`, so the
  package's fused kernels assemble it);
- the DOFs are renumbered so that rank r owns one contiguous block: the rows of
  a PETSc MPIAIJ matrix (block size 3) and of PETSc vectors;
- the rank's tets need the positions of their nodes, owned or not: a PETSc
  scatter brings them (ghost exchange) and, in reverse with addition, sends the
  element forces back to the owners;
- the Hessian goes in row by row from the rank's own CSR (``setValuesIJV``,
  with the DOFs' distributed indices, negative for held DOFs, so PETSc drops
  them, plus one diagonal entry per owned DOF); rows another rank owns are
  sent to it by PETSc at assembly. The matrix is preallocated exactly once:
  the entries of rows owned elsewhere are sent to their owner, which counts
  the distinct columns of every row (petsc4py 3.18 has no COO interface);
- the dead loads and the lumped mass are replicated vectors: each rank adds
  its owned entries; energies and norms are reduced over the ranks.

See :mod:`fem_elastic.solvers.distributed_newton` for the Newton solver, the
static solve and the implicit step that run on it.
"""

from __future__ import annotations

import logging
import weakref
from typing import Any

import numpy as np
from skfem import MeshTet

from ..discretization.mass import consistent_mass
from ..discretization.space import Discretization
from ..errors import InvalidParameter
from .partition import Partition, partition_elements, partition_space
from .petsc_solver import petsc

__all__ = ["DistributedProblem", "distributed_problem", "check_distributable"]

log = logging.getLogger(__name__)


def check_distributable(model, what: str) -> None:
    """Raise :class:`InvalidParameter` for what the distributed path does not handle (yet)."""
    from ..physics.elastic_body import ElasticPotential

    if not isinstance(getattr(model, "body_potential", None), ElasticPotential):
        raise InvalidParameter(
            f"{what} with fe.PETScSolver distributes an fe.ElasticBody on one tet mesh; this "
            f"model's body is {type(getattr(model, 'body', model)).__name__}. "
            "Use a serial linear solver (linear_solver='auto') for it."
        )
    if model.contacts or model.contact is not None:
        raise InvalidParameter(
            f"{what} with fe.PETScSolver does not handle contact (obstacles or contact=) yet; "
            "use a serial linear solver (linear_solver='auto') for scenes with contact."
        )
    if model.damping is not None:
        raise InvalidParameter(
            f"{what} with fe.PETScSolver does not apply damping yet; remove damping= or use a "
            "serial linear solver."
        )


class DistributedProblem:
    """This rank's tets, its owned DOFs, the scatter of ghosts and the COO pattern.

    Parameters
    ----------
    model : Model
        The same model on every rank.
    comm : petsc4py.PETSc.Comm
        The ranks that share the work (``PETSc.COMM_WORLD``).
    held : numpy.ndarray
        Sorted DOFs (the model's numbering) whose rows and columns are held:
        identity rows in the matrix, zero in the gradient.
    mass : {"lumped", "consistent"} or None
        The mass the matrix carries (implicit steps); None for statics.
    """

    @property
    def model(self):
        """The model this problem distributes (alive as long as its caller holds it)."""
        return self._model()

    def __init__(self, model, comm: Any, held: np.ndarray, mass: str | None = None):
        PETSc = petsc()
        self.PETSc = PETSc
        # the model through a weak reference: _PROBLEMS keeps this problem for as long as the
        # model lives, so a strong one would keep the model (and this problem) alive for ever
        self._model = weakref.ref(model)
        self.comm = comm
        self.mpi = comm.tompi4py()
        self.rank, self.size = comm.getRank(), comm.getSize()
        space = model.space
        self.ndofs = space.ndofs
        parts: Any = None
        if self.rank == 0:  # one partition, computed once, on rank 0; its error reaches every rank
            try:
                parts = partition_elements(model.mesh.t, self.size)
            except Exception as e:  # noqa: BLE001 - re-raised on every rank below
                parts = e
        parts = self.mpi.bcast(parts, root=0)
        if isinstance(parts, Exception):
            raise parts
        self.partition: Partition = partition_space(space.element_dofs, space.ndofs, parts, self.size)
        elems = self.partition.elements(self.rank)
        self.n_elements = int(elems.size)
        # the sub-mesh of this rank's tets; np.unique keeps the vertex order, so the sorted
        # tet columns stay sorted and each tet's local DOFs match the global tet's
        t = model.mesh.t[:, elems]
        verts = np.unique(t)
        submesh = MeshTet(np.ascontiguousarray(model.mesh.p[:, verts]),
                          np.ascontiguousarray(np.searchsorted(verts, t)))
        self.subspace = Discretization(submesh, space.order)
        self.body = model.body.build(self.subspace)
        local_to_global = np.empty(self.subspace.ndofs, dtype=np.int64)
        local_to_global[self.subspace.element_dofs] = space.element_dofs[:, elems]
        matched = bool(self.mpi.allreduce(np.array_equal(self.subspace.X, space.X[local_to_global]),
                                          op=_mpi_land()))
        if not matched:  # raised on every rank, so none waits in a collective for the others
            raise RuntimeError("internal error: a rank's sub-mesh DOFs do not match the model's")
        self.local_to_global = local_to_global
        new_of_old = self.partition.new_dofs(np.arange(self.ndofs))
        self.old_of_new = np.empty(self.ndofs, dtype=np.int64)
        self.old_of_new[new_of_old] = np.arange(self.ndofs)
        self.local_new = new_of_old[local_to_global]  # PETSc index of every local DOF
        self.lo, self.hi = self.partition.dof_range(self.rank)
        self.owned_old = self.old_of_new[self.lo:self.hi]  # model DOFs this rank owns, in order
        # held DOFs and the owned replicated data
        self.held = np.asarray(held, dtype=np.int64)
        held_mask = np.zeros(self.ndofs, dtype=bool)
        held_mask[self.held] = True
        self.held_mask = held_mask
        self.free_owned = ~held_mask[self.owned_old]
        self.X_owned = model.X[self.owned_old]
        self.f_owned = model.external_force(1.0)[self.owned_old]
        self.mass = mass
        self.m_owned: Any = model.lumped_mass[self.owned_old] if mass == "lumped" else None
        # PETSc objects: vectors, the ghost scatter, the matrix with its COO pattern
        self.x_local = PETSc.Vec().createSeq(self.subspace.ndofs, comm=PETSc.COMM_SELF)
        iset = PETSc.IS().createGeneral(self.local_new.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
        self.scatter = PETSc.Scatter().create(self.vec(), iset, self.x_local, None)
        self._setup_matrix()
        self.M: Any = self._consistent_mass() if mass == "consistent" else None
        log.info("rank %d of %d: %d tets, %d owned DOFs, %d local DOFs", self.rank, self.size,
                 self.n_elements, self.hi - self.lo, self.subspace.ndofs)

    # --- layout -------------------------------------------------------------------------
    def vec(self) -> Any:
        """A new distributed vector (owned block of this rank, block size 3), zero."""
        v = self.PETSc.Vec().createMPI((self.hi - self.lo, self.ndofs), bsize=3, comm=self.comm)
        v.set(0.0)
        return v

    def to_vec(self, x: np.ndarray, out: Any = None) -> Any:
        """A replicated model vector ``(ndofs,)`` as a distributed vector (owned entries)."""
        v = self.vec() if out is None else out
        v.getArray()[:] = np.asarray(x)[self.owned_old]
        return v

    def gather(self, v: Any) -> np.ndarray:
        """A distributed vector as a replicated model vector ``(ndofs,)`` on every rank."""
        owned = self.mpi.allgather(v.getArray(readonly=True).copy())
        x = np.empty(self.ndofs)
        x[self.old_of_new] = np.concatenate(owned)
        return x

    def local(self, v: Any) -> np.ndarray:
        """This rank's tets' DOF values (owned and ghost) of a distributed vector."""
        self.scatter.scatter(v, self.x_local, addv=self.PETSc.InsertMode.INSERT_VALUES,
                             mode=self.PETSc.ScatterMode.FORWARD)
        return self.x_local.getArray(readonly=True)

    def allsum(self, value: float) -> float:
        """The sum of a number over the ranks."""
        return float(self.mpi.allreduce(float(value)))

    # --- the matrix -----------------------------------------------------------------------
    def _setup_matrix(self):
        PETSc = self.PETSc
        pattern = self.subspace.pattern
        held_local = self.held_mask[self.local_to_global]
        # rows and columns of held DOFs are dropped (PETSc ignores a negative index); the
        # owned diagonal is set on its own (identity on held rows, the lumped mass on free ones)
        self._indptr = np.asarray(pattern.indptr).astype(PETSc.IntType)
        cols_local = np.asarray(pattern.indices, dtype=np.int64)
        self._rowmap = np.where(held_local, -1, self.local_new).astype(PETSc.IntType)
        self._cols = np.where(held_local[cols_local], -1, self.local_new[cols_local]).astype(PETSc.IntType)
        rows_local = np.repeat(np.arange(self.subspace.ndofs), np.diff(pattern.indptr))
        keep = ~(held_local[rows_local] | held_local[cols_local])
        self.A = self._preallocated(self.local_new[rows_local[keep]], self.local_new[cols_local[keep]])
        self.A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        coords = self.to_vec(self.model.X)
        self.A.setNearNullSpace(PETSc.NullSpace().createRigidBody(coords))
        coords.destroy()
        n_owned = self.hi - self.lo
        self._diag_indptr = np.arange(n_owned + 1).astype(PETSc.IntType)
        self._diag_rows = np.arange(self.lo, self.hi).astype(PETSc.IntType)
        self._diag = np.empty(n_owned)

    def _preallocated(self, rows: np.ndarray, cols: np.ndarray) -> Any:
        """A distributed AIJ matrix preallocated exactly for these entries (+ the owned diagonal).

        Entries whose row another rank owns are sent to it first (once): each rank then
        counts, per owned row, the distinct columns inside and outside its diagonal block.
        """
        PETSc = self.PETSc
        starts = 3 * self.partition.node_ranges
        owner = np.searchsorted(starts, rows, side="right") - 1
        order = np.argsort(owner, kind="stable")
        bounds = np.searchsorted(owner[order], np.arange(self.size + 1))
        sent = [(rows[order[bounds[p]:bounds[p + 1]]], cols[order[bounds[p]:bounds[p + 1]]])
                for p in range(self.size)]
        got = self.mpi.alltoall(sent)
        diag = np.arange(self.lo, self.hi, dtype=np.int64)
        R = np.concatenate([r for r, _ in got] + [diag])
        C = np.concatenate([c for _, c in got] + [diag])
        keys = np.sort(R * self.ndofs + C)  # distinct entries: sort and mask (np.unique is ~80x
        keys = keys[np.concatenate([[True], keys[1:] != keys[:-1]])]  # slower here, numpy 2.4)
        R, C = keys // self.ndofs - self.lo, keys % self.ndofs
        inside = (C >= self.lo) & (C < self.hi)
        n_owned = self.hi - self.lo
        d_nnz = np.bincount(R[inside], minlength=n_owned).astype(PETSc.IntType)
        o_nnz = np.bincount(R[~inside], minlength=n_owned).astype(PETSc.IntType)
        A = PETSc.Mat().create(comm=self.comm)
        A.setSizes(((n_owned, self.ndofs), (n_owned, self.ndofs)), bsize=3)
        A.setType(PETSc.Mat.Type.AIJ)
        A.setPreallocationNNZ((d_nnz, o_nnz))
        return A

    def _consistent_mass(self, drop_held: bool = False) -> Any:
        """The consistent mass (kg) as a distributed matrix (assembled once).

        With ``drop_held`` the rows and columns of held DOFs are left out, as in the
        tangent, whose pattern then holds this one's.
        """
        PETSc = self.PETSc
        M = consistent_mass(self.subspace, self.model.density).tocsr()
        M.sort_indices()
        rows_local = np.repeat(np.arange(M.shape[0]), np.diff(M.indptr))
        held = self.held_mask[self.local_to_global] if drop_held else np.zeros(M.shape[0], dtype=bool)
        keep = ~(held[rows_local] | held[M.indices])
        Mp = self._preallocated(self.local_new[rows_local[keep]], self.local_new[M.indices[keep]])
        cols = np.where(held[M.indices], -1, self.local_new[M.indices]).astype(PETSc.IntType)
        rowmap = np.where(held, -1, self.local_new).astype(PETSc.IntType)
        Mp.setValuesIJV(M.indptr.astype(PETSc.IntType), cols, M.data, addv=PETSc.InsertMode.ADD_VALUES,
                        rowmap=rowmap)
        Mp.assemble()
        return Mp

    # --- energy, gradient, Hessian of G(x) = Pi(x; s) + |x - y|_M^2 / (2 k^2) -------------
    def energy(self, x: Any, s: float = 1.0, y: Any = None, k: float = 0.0) -> float:
        """G at the distributed vector ``x`` (J), summed over the ranks; +inf if inadmissible.

        ``s`` scales the dead loads; with an inertial target ``y`` (a distributed vector) and
        step factor ``k`` (s) the mass term is added (implicit steps).
        """
        e = self.body.energy(self.local(x))
        xo = x.getArray(readonly=True)
        e -= s * float(self.f_owned @ (xo - self.X_owned))
        e += self._inertia_energy(x, y, k, xo)
        return self.allsum(e) if np.isfinite(e) else self.allsum(np.inf)

    def _inertia_energy(self, x, y, k, xo) -> float:
        if y is None or self.mass is None:
            return 0.0
        d = xo - y.getArray(readonly=True)
        if self.mass == "lumped":
            return 0.5 * float(self.m_owned @ (d * d)) / (k * k)
        Md = self._mass_times_difference(x, y)
        e = 0.5 * float(d @ Md.getArray(readonly=True)) / (k * k)  # owned part; summed by the caller
        Md.destroy()
        return e

    def _mass_times_difference(self, x: Any, y: Any) -> Any:
        """``M (x - y)`` (kg m) with the consistent mass, a new distributed vector."""
        d = x.duplicate()
        x.copy(d)
        d.axpy(-1.0, y)
        Md = d.duplicate()
        self.M.mult(d, Md)
        d.destroy()
        return Md

    def _sum_local(self, values: np.ndarray, out: Any = None) -> Any:
        """A distributed vector summing every rank's local DOF values (ghosts to their owners)."""
        v = self.vec() if out is None else out
        v.set(0.0)
        self.x_local.getArray()[:] = values
        self.scatter.scatter(self.x_local, v, addv=self.PETSc.InsertMode.ADD_VALUES,
                             mode=self.PETSc.ScatterMode.REVERSE)
        return v

    def body_tangent_times(self, x: Any, d: Any) -> Any:
        """``K(x) d`` (N) of the body's exact tangent, on every row (held ones too)."""
        H = self.body.hessian(self.local(x).copy(), project=False)
        return self._sum_local(H @ self.local(d))

    def gradient(self, x: Any, s: float = 1.0, y: Any = None, k: float = 0.0, out: Any = None) -> Any:
        """dG/dx (N) as a distributed vector (held DOFs included: their reactions)."""
        g = self._sum_local(self.body.gradient(self.local(x)), out)
        ga = g.getArray()
        ga -= s * self.f_owned
        if y is not None and self.mass == "lumped":
            ga += self.m_owned * (x.getArray(readonly=True) - y.getArray(readonly=True)) / (k * k)
        elif y is not None and self.mass == "consistent":
            Md = self._mass_times_difference(x, y)
            g.axpy(1.0 / (k * k), Md)
            Md.destroy()
        return g

    def hessian(self, x: Any, project: bool, k: float = 0.0) -> Any:
        """The free-DOF tangent (N/m) with identity rows and columns on held DOFs, assembled."""
        PETSc = self.PETSc
        H = self.body.hessian(self.local(x), project=project)
        diag = self._diag
        if self.mass == "lumped" and k > 0:
            diag[:] = self.m_owned / (k * k)
        else:
            diag[:] = 0.0
        diag[~self.free_owned] = 1.0  # the held rows' identity (their other entries are dropped)
        A = self.A
        A.zeroEntries()
        add = PETSc.InsertMode.ADD_VALUES
        A.setValuesIJV(self._indptr, self._cols, H.data, addv=add, rowmap=self._rowmap)
        A.setValuesIJV(self._diag_indptr, self._diag_rows, diag, addv=add, rowmap=self._diag_rows)
        A.assemble()
        if self.mass == "consistent" and k > 0:
            Mf = self._free_mass()
            self.A.axpy(1.0 / (k * k), Mf, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        return self.A

    def _free_mass(self):
        """The consistent mass without the held rows and columns (built once)."""
        Mf = getattr(self, "_Mf", None)
        if Mf is None:
            Mf = self._Mf = self._consistent_mass(drop_held=True)
        return Mf

    def destroy(self) -> None:
        """Free the PETSc objects."""
        from .distributed_newton import destroy_ksp

        for obj in (self.A, self.M, getattr(self, "_Mf", None), self.scatter, self.x_local):
            if obj is not None:
                obj.destroy()
        if self.__dict__.get("_ksp") is not None:
            destroy_ksp(self.__dict__.pop("_ksp"))


def _mpi_land():
    from mpi4py import MPI

    return MPI.LAND


_PROBLEMS: "weakref.WeakKeyDictionary[Any, dict]" = weakref.WeakKeyDictionary()


def release(model) -> None:
    """Destroy the PETSc objects of the model's distributed problems now (not at garbage collection)."""
    for problem in _PROBLEMS.pop(model, {}).values():
        problem.destroy()


def distributed_problem(model, comm: Any, held: np.ndarray, mass: str | None = None) -> DistributedProblem:
    """The model's :class:`DistributedProblem` for these held DOFs and mass (kept on the model)."""
    held = np.asarray(held, dtype=np.int64)
    key = (comm.getSize(), mass, held.size, hash(held.tobytes()))
    cache = _PROBLEMS.setdefault(model, {})  # beside the model, not in it: a Model stays picklable
    problem = cache.get(key)
    if problem is None:
        for old in cache.values():
            old.destroy()
        cache.clear()
        problem = cache[key] = DistributedProblem(model, comm, held, mass)
    return problem

