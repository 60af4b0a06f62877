"""What the MPI tests share: whether the distributed backend is here, and how to start mpiexec.

The backend (petsc4py, mpi4py, pymetis and an ``mpiexec``) is the ``[mpi]`` extra, installed by
``scripts/install_mpi.sh``. Without it these tests skip, except where ``FEM_ELASTIC_REQUIRE_MPI=1``
(``.ci/run`` sets it): there a missing backend fails them, so CI cannot pass by skipping.
"""

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def mpi_missing() -> str:
    """Why the backend cannot run here ("" when it can)."""
    for module in ("petsc4py", "mpi4py", "pymetis"):
        if importlib.util.find_spec(module) is None:
            return f"{module} is not installed (bash scripts/install_mpi.sh)"
    if shutil.which("mpiexec") is None:
        return "no mpiexec on the PATH (bash scripts/install_mpi.sh installs Open MPI with PETSc)"
    return ""


def require_mpi() -> None:
    """Skip the calling test without the backend; fail instead under FEM_ELASTIC_REQUIRE_MPI=1."""
    why = mpi_missing()
    if why:
        if os.environ.get("FEM_ELASTIC_REQUIRE_MPI") == "1":
            pytest.fail(f"FEM_ELASTIC_REQUIRE_MPI=1 but the MPI backend is missing: {why}")
        pytest.skip(why)


def mpi_env() -> dict:
    """The environment for mpiexec: Open MPI refuses root without these (CI runs as root), and
    its shared-memory transport's single-copy mechanism (CMA) is not allowed in containers."""
    # a process that initialised MPI itself (an in-process PETSc test: an Open MPI singleton)
    # carries the launcher variables of that singleton; mpiexec must not inherit them
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "PMI_"))}
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_btl_vader_single_copy_mechanism="none", OMPI_MCA_rmaps_base_oversubscribe="1")
    return env


def run_mpi(n: int, args: list, timeout: float = 240, cwd=None) -> subprocess.CompletedProcess:
    """``mpiexec -n n <args>`` (args[0] "python" means this interpreter); the finished process."""
    args = [sys.executable if a == "python" else str(a) for a in args]
    return subprocess.run(["mpiexec", "-n", str(n), *args], capture_output=True, text=True,
                          timeout=timeout, env=mpi_env(), cwd=cwd or ROOT, check=False)
