"""PETSc's Krylov solvers and preconditioners, serial or across MPI ranks.

:class:`PETScSolver` is a linear solver like :class:`~fem_elastic.DirectSolver`
or :class:`~fem_elastic.AMGSolver`: ``solve(A, b, near_null)`` solves a scipy
system with PETSc (conjugate gradients preconditioned by smoothed-aggregation
GAMG with the rigid-body near-null space, or a direct LU by MUMPS) in the
calling process. Handed to :func:`fem_elastic.solve_static` or to
:class:`fem_elastic.ImplicitEuler`, it does more: the solve becomes distributed
(:mod:`fem_elastic.solvers.distributed`), each MPI rank assembling its own
tets into one PETSc matrix. Run the same script with ``mpiexec -n N``.

petsc4py and mpi4py are optional (``fem_elastic[mpi]``, see
``scripts/install_mpi.sh``); they are imported here only, on first use.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidParameter, MissingDependency
from .linear_solvers import LinearSolve, LinearSolverFailed
from .partition import MPI_INSTALL_HINT

__all__ = ["PETScSolver", "petsc", "comm_world", "launcher_world"]

log = logging.getLogger(__name__)

_PRECONDITIONERS = ("gamg", "lu")
_PREFIXES: dict = {}  # options prefix of each distinct solver configuration


def petsc() -> Any:
    """The ``petsc4py.PETSc`` module (initialised), or :class:`MissingDependency` naming the fix."""
    import os

    if launcher_world()[1] == 1:
        # one process without mpiexec: Open MPI then starts as a "singleton" and, unless told it
        # is isolated, forks a supporting daemon (orted) as a child of this process, which a
        # program that forks or kills its own children (a test runner, a process pool) can take
        # down with it; we never spawn MPI processes, so no daemon is needed
        os.environ.setdefault("OMPI_MCA_ess_singleton_isolated", "1")
    try:
        from petsc4py import PETSc  # initialises PETSc (and MPI) on first import
    except ImportError as e:
        raise MissingDependency(f"fe.PETScSolver needs petsc4py: {MPI_INSTALL_HINT}.") from e

    return PETSc


#: the environment variables in which MPI launchers (Open MPI, MPICH/Hydra, Slurm's srun) give each
#: process its rank and the number of processes
_LAUNCHER_VARS = (("OMPI_COMM_WORLD_RANK", "OMPI_COMM_WORLD_SIZE"), ("PMI_RANK", "PMI_SIZE"),
                  ("SLURM_PROCID", "SLURM_NTASKS"))


def launcher_world() -> tuple[int, int]:
    """(rank, number of processes) as the MPI launcher set them; (0, 1) without ``mpiexec``.

    Read from the environment, so it needs neither MPI nor PETSc (the CLI uses it to
    decide which process writes).
    """
    import os

    for rank, size in _LAUNCHER_VARS:
        if os.environ.get(size, "").isdigit():
            return int(os.environ.get(rank, "0") or 0), int(os.environ[size])
    return 0, 1


def comm_world() -> Any:
    """PETSc's world communicator (``PETSc.COMM_WORLD``); size 1 without ``mpiexec``.

    Raises
    ------
    MissingDependency
        The launcher started N > 1 processes but PETSc sees one: PETSc (or petsc4py) was
        built without MPI, or against another MPI than the launcher's.
    """
    comm = petsc().COMM_WORLD
    _, launched = launcher_world()
    if launched > 1 and comm.getSize() != launched:
        raise MissingDependency(
            f"mpiexec started {launched} processes but PETSc sees {comm.getSize()} rank(s): "
            "PETSc or petsc4py was built without MPI, or against a different MPI than this "
            f"mpiexec. {MPI_INSTALL_HINT}; run with the mpiexec of that MPI (Debian: /usr/bin/mpiexec)."
        )
    return comm


@dataclass
class PETScSolver:
    """Solve with PETSc: CG + GAMG (default) or MUMPS LU; distributed under ``mpiexec``.

    Parameters
    ----------
    preconditioner : {"gamg", "lu"}
        ``"gamg"``: conjugate gradients preconditioned by PETSc's smoothed
        aggregation AMG with the six rigid-body modes as near-null space (block
        size 3), for large SPD systems; ``"lu"``: a direct solve (MUMPS, in
        parallel), for small or ill-conditioned ones.
    rtol : float
        Relative residual at which CG stops (Newton may pass a looser one, its
        forcing term).
    max_it : int
        Most CG iterations.
    options : dict
        Further PETSc options for the solver, without the prefix, e.g.
        ``{"pc_gamg_threshold": 0.02}`` (see PETSc's manual for KSP and PC).

    Notes
    -----
    ``fe.solve_static(model, linear_solver=fe.PETScSolver())`` and
    ``fe.ImplicitEuler(linear_solver=fe.PETScSolver())`` run the distributed
    path: under ``mpiexec -n N`` each rank assembles its share of the tets
    (METIS partition) into one PETSc matrix; every rank returns the same
    result. With one process (no ``mpiexec``) it is the same code on one rank.
    Other integrators (Newmark, the trapezoid, the linearized implicit Euler) call
    :meth:`solve` as a serial linear solver in each process.

    Examples
    --------
    Not run by the doctests (petsc4py is optional); ``tests/test_petsc_solver.py`` runs the same.

    >>> import scipy.sparse as sp, numpy as np
    >>> import fem_elastic as fe
    >>> A = sp.diags([2.0, 3.0, 4.0]).tocsr()
    >>> fe.PETScSolver(preconditioner="lu").solve(A, np.array([2.0, 3.0, 4.0])).x.round(12).tolist()  # doctest: +SKIP
    [1.0, 1.0, 1.0]
    """

    preconditioner: Literal["gamg", "lu"] = "gamg"
    rtol: float = 1e-10
    max_it: int = 2000
    options: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.preconditioner not in _PRECONDITIONERS:
            raise InvalidParameter(
                f"preconditioner must be one of {_PRECONDITIONERS}, got {self.preconditioner!r}."
            )
        if not (0.0 < float(self.rtol) < 1.0):
            raise InvalidParameter(f"rtol must be in (0, 1), got {self.rtol!r}.")
        if isinstance(self.max_it, bool) or not isinstance(self.max_it, int) or self.max_it < 1:
            raise InvalidParameter(f"max_it must be a whole number >= 1, got {self.max_it!r}.")
        if not isinstance(self.options, dict):
            raise InvalidParameter(f"options must be a dict of PETSc options, got {self.options!r}.")

    # --- the KSP, set up from this solver's choices -------------------------------------
    def ksp(self, comm: Any) -> Any:
        """A new PETSc KSP on ``comm`` configured as this solver says.

        The settings go through PETSc's options database under a prefix of their own,
        one per distinct configuration (not per KSP: PETSc 3.18 holds at most 512
        options, and a sweep makes thousands of KSPs).
        """
        PETSc = petsc()
        values = self.settings(comm.getSize())
        key = tuple(sorted((k, str(v)) for k, v in values.items()))
        prefix = _PREFIXES.get(key)
        opts = PETSc.Options()
        if prefix is None:
            prefix = _PREFIXES[key] = f"fe{len(_PREFIXES) + 1}_"
            for k, v in values.items():
                opts[prefix + k] = v
        ksp = PETSc.KSP().create(comm=comm)
        ksp.setOptionsPrefix(prefix)
        ksp.setFromOptions()
        ksp.setTolerances(rtol=float(self.rtol), atol=0.0, max_it=int(self.max_it))
        return ksp

    def settings(self, ranks: int) -> dict:
        """The PETSc options (without prefix) of this solver on ``ranks`` ranks (P1 and P2 alike)."""
        if self.preconditioner == "gamg":
            values: dict = {"ksp_type": "cg", "pc_type": "gamg", "ksp_norm_type": "unpreconditioned"}
            # smoother: Chebyshev on Jacobi, with a 30 % margin on its estimate of the largest
            # eigenvalue. GAMG's default margin (10 %) came out too small on 2 ranks for
            # Neo-Hookean tangents of the test beam (an indefinite preconditioner: CG stops with
            # KSP_DIVERGED_INDEFINITE_PC; Newton then answers with GMRES on the same
            # hierarchy). Symmetric SOR sweeps need no estimate, but fail outright on P2
            # tangents and on the 150k-tet P1 beam (a zero pivot, KSP_DIVERGED_PC_FAILED)
            values.update({"mg_levels_ksp_type": "chebyshev", "mg_levels_pc_type": "jacobi",
                           "mg_levels_ksp_chebyshev_esteig": "0,0.1,0,1.3"})
        else:
            values = {"ksp_type": "preonly", "pc_type": "lu",
                      "pc_factor_mat_solver_type": "mumps" if ranks > 1 else "petsc"}
        values.update(self.options)
        return values

    def solve(self, A: sp.spmatrix, b: np.ndarray, near_null: np.ndarray | None = None,
              rtol: float | None = None) -> LinearSolve:
        """Solve ``A x = b`` (a scipy matrix, in this process) with PETSc.

        Parameters
        ----------
        A : scipy.sparse matrix
            Symmetric positive definite for ``"gamg"`` (N/m).
        b : numpy.ndarray
            Right-hand side (N).
        near_null : numpy.ndarray, optional
            ``(n, k)`` near-null space for GAMG (rigid-body modes); ignored by LU.
        rtol : float, optional
            Looser tolerance for this solve (Newton's forcing term).

        Returns
        -------
        LinearSolve
        """
        PETSc = petsc()
        t0 = time.perf_counter()
        A = sp.csr_matrix(A, dtype=float)
        A.sort_indices()
        n = A.shape[0]
        M = PETSc.Mat().createAIJ(size=A.shape, csr=(A.indptr.astype(PETSc.IntType),
                                                     A.indices.astype(PETSc.IntType), A.data),
                                  comm=PETSc.COMM_SELF)
        if self.preconditioner == "gamg" and n % 3 == 0:
            M.setBlockSize(3)
        if near_null is not None and self.preconditioner == "gamg":
            vecs = []
            Q, _ = np.linalg.qr(np.asarray(near_null, dtype=float))  # PETSc wants orthonormal vectors
            for j in range(Q.shape[1]):
                vecs.append(PETSc.Vec().createWithArray(np.ascontiguousarray(Q[:, j]), comm=PETSc.COMM_SELF))
            M.setNearNullSpace(PETSc.NullSpace().create(vectors=vecs, comm=PETSc.COMM_SELF))
        ksp = self.ksp(PETSc.COMM_SELF)
        ksp.setOperators(M)
        if rtol is not None:  # Newton's forcing term may loosen the solve, never tighten it
            ksp.setTolerances(rtol=max(float(rtol), float(self.rtol)))
        x = np.zeros(n)
        bv = PETSc.Vec().createWithArray(np.ascontiguousarray(b, dtype=float), comm=PETSc.COMM_SELF)
        xv = PETSc.Vec().createWithArray(x, comm=PETSc.COMM_SELF)
        ksp.solve(bv, xv)
        its = int(ksp.getIterationNumber())
        reason = int(ksp.getConvergedReason())  # > 0: converged
        for obj in (ksp, M, bv, xv):
            obj.destroy()
        if reason <= 0:
            raise LinearSolverFailed(
                f"PETSc {self.preconditioner} did not converge (KSP reason {reason}) in {its} "
                "iterations: try preconditioner='lu', a larger max_it, or check that the "
                "system is positive definite (held DOFs remove every rigid-body mode)."
            )
        bnorm = float(np.linalg.norm(b)) or 1.0
        res = float(np.linalg.norm(A @ x - b)) / bnorm
        return LinearSolve(x=x, iterations=its, residual=res, seconds=time.perf_counter() - t0,
                           method=f"petsc-{self.preconditioner}", setups=1)
