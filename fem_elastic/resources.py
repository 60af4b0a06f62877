"""Resources checked before they are spent: memory for a model, disk for its output, input sizes.

A model too large for the machine should say so in a second, with the
estimate and what is free, instead of swapping for minutes and being killed.
The estimates here are made from counts alone (tets, vertices, element order,
solver), before any array is allocated:

- :func:`model_memory` — what building a model takes (bytes per tet,
  measured: see :data:`MODEL_BYTES_PER_TET`), and with ``tangent=True`` what
  assembling its tangent takes too (:data:`BYTES_PER_TET`) plus the linear
  solver's share (a sparse LU's fill, or an AMG hierarchy). ``fe.Model``
  checks the first when it is built, ``Model.check_tangent_memory`` the
  others: the tangent alone at the first ``Model.linearize`` (an explicit
  run's critical time step), with the solver's share before a static solve,
  an implicit run or a modal analysis; so explicit runs are not refused for
  a solver they never use;
- :func:`available_memory`, :func:`free_disk` — what the machine has free
  (``MemAvailable`` of ``/proc/meminfo``, else ``os.sysconf``; ``shutil.disk_usage``),
  overridden by the environment variables ``FEM_ELASTIC_MEMORY_LIMIT`` and
  ``FEM_ELASTIC_DISK_LIMIT`` (bytes, or with a suffix: ``512M``, ``2G``) for
  tests and for sharing a machine;
- :func:`check_memory`, :func:`check_disk` — :class:`fe.ResourceLimit` when
  the estimate exceeds what is free;
- :func:`check_input_file` — a path that must be a regular file of bounded
  size (a scene file), refused by type (a device, a FIFO, a directory) and
  size before it is read.

A foundation module beside :mod:`fem_elastic.errors`: it imports nothing else
of the package.
"""

from __future__ import annotations

import math
import os
import shutil
import stat
from pathlib import Path

from .errors import InvalidParameter, ResourceLimit

__all__ = ["BYTES_PER_TET", "FUSED_BYTES_PER_TET", "MODEL_BYTES_PER_TET", "available_memory", "free_disk", "model_memory", "check_memory",
           "check_disk", "check_input_file", "format_bytes", "MEMORY_ENV", "DISK_ENV"]

MEMORY_ENV = "FEM_ELASTIC_MEMORY_LIMIT"
DISK_ENV = "FEM_ELASTIC_DISK_LIMIT"

#: Peak bytes per tet of building a Model and one ``linearize`` through the numpy path (element
#: matrices, the CSR scatter map, quadrature tensors), by element order: measured with
#: tracemalloc on beam meshes of 4320 and 15360 tets (P1: 4.96-4.98 kB; P2: 26.1 kB per tet;
#: 6.3 and 29.5 kB before issue 19's lazy scatter map), rounded up.
BYTES_PER_TET = {1: 6_000, 2: 30_000}
#: The same through the fused numba kernels (``fem_elastic.discretization.fused``: the element
#: matrices go straight into the CSR data, through an int32 block map): measured on the same
#: meshes, P1 1.27-1.29 kB, P2 9.6-9.8 kB per tet, and 1.59 kB per P1 tet on a 540-tet beam
#: (fixed costs weigh more there), rounded up. The force loop's blocked copy of Dm^-1 and V
#: (``discretization/_fused_gradient_kernels.py``) added 80 B: P1 1.36-1.46 kB per tet on 1920-
#: and 8640-tet beams (``scripts/bench_memory_estimate.py``).
FUSED_BYTES_PER_TET = {1: 1_800, 2: 12_000}
#: Peak bytes per tet of building a Model alone (mesh, space, mass, per-element data, one
#: gradient; no tangent): measured with tracemalloc on beam meshes of 4320 and 15360 tets
#: (P1 0.99-1.00 kB, P2 3.04-3.06 kB per tet; P1 80 B more since the force loop's blocked
#: copy of Dm^-1 and V), rounded up.
MODEL_BYTES_PER_TET = {1: 1_200, 2: 3_500}
#: Nonzeros of the assembled stiffness per tet (measured on the same meshes: P1 26-29, P2 384-400).
NNZ_PER_TET = {1: 30, 2: 400}
#: The automatic solver's largest direct solve (``fem_elastic.solvers.linear_solvers.AutoSolver``).
MAX_DIRECT_DOFS = 20_000

_SUFFIX = {"": 1, "K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}


def format_bytes(n: float) -> str:
    """``n`` bytes in readable units (GiB, MiB, ...)."""
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if abs(n) >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n:.0f} B"


def _parse_bytes(text: str, name: str) -> int:
    t = text.strip().upper().removesuffix("B").removesuffix("I")
    unit = t[-1] if t and t[-1] in _SUFFIX else ""
    number = t[: len(t) - len(unit)]
    try:
        value = float(number) * _SUFFIX[unit]
    except ValueError:
        value = float("nan")
    if not math.isfinite(value) or value < 0:
        raise InvalidParameter(f"{name}={text!r} is not a size in bytes; give e.g. {name}=2G or {name}=500000000.")
    return int(value)


def available_memory() -> int | None:
    """Memory free for a new model (bytes): ``$FEM_ELASTIC_MEMORY_LIMIT``, else the system's.

    Returns None where the system does not say.
    """
    if os.environ.get(MEMORY_ENV, "").strip():
        return _parse_bytes(os.environ[MEMORY_ENV], MEMORY_ENV)
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024  # kB
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def free_disk(path) -> int | None:
    """Bytes free on the file system of ``path`` (or its nearest existing parent): ``$FEM_ELASTIC_DISK_LIMIT``
    else ``shutil.disk_usage``; None where it cannot be read."""
    if os.environ.get(DISK_ENV, "").strip():
        return _parse_bytes(os.environ[DISK_ENV], DISK_ENV)
    p = Path(path).absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    try:
        return int(shutil.disk_usage(p).free)
    except OSError:
        return None


def model_memory(n_tets: int, n_vertices: int, order: int = 1, solver: str = "auto",
                 tangent: bool = True, fused: bool = False) -> dict:
    """Estimated peak memory of a model and its linear solves (bytes), by part.

    Parameters
    ----------
    n_tets, n_vertices : int
        Counts of the mesh.
    order : {1, 2}
        Element order (2: quadratic tets, about 5x the memory per tet of 1).
    solver : {"auto", "direct", "iterative", "none"}
        ``"direct"``: a sparse LU, whose fill grows as ``nnz * ndof^(1/3)`` in 3-D (fitted to
        SuperLU's fill on beams: 0.34-1.0 x that); ``"iterative"``: AMG-CG, about three copies
        of the matrix; ``"auto"``: direct up to 20 000 DOFs, iterative above (as
        ``AutoSolver``); ``"none"``: explicit schemes, no matrix solve.
    tangent : bool
        True: the model with its assembled tangent (:data:`BYTES_PER_TET`) and the
        ``solver``'s share; False: the model's own share alone (:data:`MODEL_BYTES_PER_TET`:
        mesh, space, mass, per-element data), no matrix and no solver.
    fused : bool
        True: the tangent is assembled by the fused numba kernels (:data:`FUSED_BYTES_PER_TET`,
        about a quarter of the numpy path's :data:`BYTES_PER_TET`).

    Returns
    -------
    dict
        ``"model"``, ``"solver"`` and ``"total"`` (bytes), ``"ndof"``, ``"solver_kind"``,
        ``"order"`` and ``"tangent"``.

    Examples
    --------
    >>> from fem_elastic.resources import model_memory
    >>> m = model_memory(1_000_000, 180_000, order=2)
    >>> m["ndof"] > 3_000_000 and m["total"] > 30e9
    True
    """
    order = 2 if order == 2 else 1
    n_nodes = n_vertices if order == 1 else 2 * n_vertices + n_tets  # edges ~ vertices + tets (Euler)
    ndof = 3 * n_nodes
    nnz = NNZ_PER_TET[order] * n_tets
    model = ((FUSED_BYTES_PER_TET if fused else BYTES_PER_TET) if tangent else MODEL_BYTES_PER_TET)[order] * n_tets
    if not tangent:
        solver = "none"
    if solver == "auto":
        solver = "direct" if ndof <= MAX_DIRECT_DOFS else "iterative"
    if solver == "direct":
        solve = 12 * nnz * max(ndof, 1) ** (1.0 / 3.0)  # value + index per entry of L and U
    elif solver == "iterative":
        solve = 3 * 12 * nnz
    else:
        solve = 0
    return {"model": float(model), "solver": float(solve), "total": float(model + solve), "ndof": ndof,
            "solver_kind": solver, "order": order, "tangent": bool(tangent)}


def check_memory(estimate: dict, what: str = "the model") -> None:
    """:class:`fe.ResourceLimit` when ``estimate["total"]`` exceeds the free memory.

    Parameters
    ----------
    estimate : dict
        From :func:`model_memory`.
    what : str
        What needs it, for the message.
    """
    free = available_memory()
    need = estimate["total"]
    if free is None or need <= free:
        return
    source = f"${MEMORY_ENV}" if os.environ.get(MEMORY_ENV, "").strip() else "MemAvailable"
    tangent = estimate.get("tangent", True)
    if tangent:
        parts = (f"{format_bytes(estimate['model'])} for the model and its tangent, "
                 f"{format_bytes(estimate['solver'])} for the {estimate['solver_kind']} linear solver")
    else:
        parts = f"{format_bytes(estimate['model'])} for the model, no matrix"
    advice = ["a coarser mesh"]  # only what applies: order=1 for quadratic tets, no matrix for one
    if estimate.get("order", 1) == 2:
        advice.append("order=1")
    if tangent:
        advice.append("an explicit integrator such as fe.SymplecticEuler (no matrix) for dynamics")
    raise ResourceLimit(
        f"{what} would need about {format_bytes(need)} of memory ({estimate['ndof']} DOFs: {parts}), "
        f"but only {format_bytes(free)} is free ({source}). Use {', '.join(advice)}, or a machine with "
        f"more memory; set {MEMORY_ENV} to a larger figure to try all the same.",
        needed=need, available=free,
    )


def check_disk(path, needed: float, what: str = "the output") -> None:
    """:class:`fe.ResourceLimit` when ``needed`` bytes exceed the free space at ``path``."""
    free = free_disk(path)
    if free is None or needed <= free:
        return
    source = f"${DISK_ENV}" if os.environ.get(DISK_ENV, "").strip() else "free space"
    raise ResourceLimit(
        f"{what} would need about {format_bytes(needed)} of disk in {path}, but only {format_bytes(free)} is "
        f"free ({source}). Record fewer frames ([output] every = N), shorten the run, write elsewhere "
        f"(--out), or free some space; set {DISK_ENV} to a larger figure to try all the same.",
        needed=needed, available=free,
    )


def check_input_file(path, max_bytes: int, what: str = "input file") -> Path:
    """Refuse ``path`` unless it is a regular file of at most ``max_bytes``: before reading it.

    A FIFO or a device would block or never end (``/dev/zero``), a huge file
    would fill memory: each is refused by its type or size, from ``os.stat``.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist (the caller words it).
    InvalidParameter
        Not a regular file, or larger than ``max_bytes``.
    """
    path = Path(path)
    st = os.stat(path)  # follows links: what would be read
    mode = st.st_mode
    if not stat.S_ISREG(mode):
        kind = ("a directory" if stat.S_ISDIR(mode) else "a FIFO (named pipe)" if stat.S_ISFIFO(mode)
                else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
                else "a socket" if stat.S_ISSOCK(mode) else "not a regular file")
        raise InvalidParameter(f"the {what} {str(path)!r} is {kind}, not a file; give the path of a file.")
    size = st.st_size
    if size > max_bytes:
        raise InvalidParameter(
            f"the {what} {str(path)!r} is {format_bytes(size)}, more than the {format_bytes(max_bytes)} such a "
            "file can reasonably be; check that this is the right file."
        )
    return path
