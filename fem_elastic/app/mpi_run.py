"""``fem-elastic run`` across MPI ranks: which process writes, and ``--ranks N``.

``mpiexec -n N fem-elastic run SCENE.toml --out DIR`` starts N copies of the
command. Each builds the scene and runs it: the solves are collective (every rank
assembles its share of the tets, :mod:`fem_elastic.solvers.distributed`) and end
with the same result on every rank. Rank 0 alone writes to ``DIR`` and prints;
the other ranks write their (identical) output to a scratch directory that is
removed at the end, so the run lock, the series writer and the summary work as
in a serial run. A scene whose solves are not distributed (a serial linear
solver: each rank would repeat the whole run) is refused with the fix.

``fem-elastic run SCENE.toml --out DIR --ranks N`` starts ``mpiexec -n N`` on
the same command itself; without an MPI launcher on the PATH it is a
:class:`fem_elastic.MissingDependency` that names the fix.
"""

from __future__ import annotations

import shutil
import subprocess
import sys

from ..errors import InvalidParameter, MissingDependency
from ..solvers.partition import MPI_INSTALL_HINT
from ..solvers.petsc_solver import launcher_world

__all__ = ["launcher_world", "check_distributed_scene", "relaunch_command", "relaunch"]


def check_distributed_scene(scene, size: int) -> None:
    """Refuse a scene whose runs would not share the work among ``size`` > 1 ranks."""
    spec = scene.spec
    solve = spec.get("solve") or {}
    if solve.get("kind") == "static":
        if solve.get("linear_solver") != "petsc":
            raise InvalidParameter(
                f"this command runs on {size} MPI ranks, but the static scene {scene.name!r} solves "
                'serially: set linear_solver = "petsc" in its [solve] table (or run it without mpiexec).'
            )
        return
    integ = spec.get("integrator") or {}
    if integ.get("type") != "implicit_euler" or integ.get("linear_solver") != "petsc":
        raise InvalidParameter(
            f"this command runs on {size} MPI ranks, but the scene {scene.name!r} steps serially: the "
            'distributed path is [integrator] type = "implicit_euler" with linear_solver = "petsc" '
            "(or run it without mpiexec)."
        )


def _strip_ranks(argv: list[str]) -> list[str]:
    """``argv`` without ``--ranks N`` (or ``--ranks=N``, or argparse's abbreviations ``--ran N`` ...)."""
    out, skip = [], False
    for a in argv:
        if skip:
            skip = False
            continue
        name = a.split("=", 1)[0]
        if len(name) >= 4 and "--ranks".startswith(name):  # "--r" alone is ambiguous with --resume
            skip = "=" not in a
            continue
        out.append(a)
    return out


def relaunch_command(argv: list[str], ranks: int) -> list[str]:
    """The ``mpiexec -n ranks python -m fem_elastic ...`` command for the CLI arguments ``argv``.

    Raises
    ------
    MissingDependency
        No ``mpiexec`` on the PATH.
    """
    mpiexec = shutil.which("mpiexec")
    if mpiexec is None:
        raise MissingDependency(
            f"--ranks {ranks} needs an MPI launcher, and there is no mpiexec on the PATH: "
            f"{MPI_INSTALL_HINT}; or run with one process (leave out --ranks)."
        )
    version = subprocess.run([mpiexec, "--version"], capture_output=True, text=True, check=False)
    extra = ["--oversubscribe"] if "Open MPI" in version.stdout or "OpenRTE" in version.stdout else []
    return [mpiexec, "-n", str(ranks), *extra, sys.executable, "-m", "fem_elastic", *_strip_ranks(argv)]


def relaunch(argv: list[str], ranks: int) -> int:
    """Run the command again under ``mpiexec -n ranks``; its exit status."""
    if launcher_world()[1] > 1:
        raise InvalidParameter("--ranks is for a command started without mpiexec; under mpiexec "
                               "the number of ranks is mpiexec's -n.")
    return subprocess.run(relaunch_command(argv, ranks), check=False).returncode  # this environment
