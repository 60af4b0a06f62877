#!/usr/bin/env bash
# The distributed backend's route (fem_elastic[mpi]: fe.PETScSolver under mpiexec), for Debian 12 /
# Ubuntu; see docs/scaling.md for why this route. Usage: bash scripts/install_mpi.sh [VENV]  (default .venv)
#
#   1. Debian's PETSc 3.18 (petsc-dev, with Open MPI, MUMPS and hypre): ~30 s of apt instead of
#      ~25 min of compiling PETSc; needs root (prefix sudo as your machine requires).
#   2. petsc4py 3.18 compiled against it (~5 min on 2 cores; PyPI has no wheel), without build
#      isolation because its setup needs the venv's numpy headers and PETSC_DIR. Run this after
#      the project's own install: petsc4py is then built against the numpy the venv keeps.
#   3. mpi4py compiled against the same Open MPI (~6 min), so both speak to one MPI.
#   4. pymetis, from its wheel.
set -euo pipefail
VENV=${1:-.venv}
# your own PETSc: set PETSC_DIR (and PETSC_ARCH) before running this, and apt-get is skipped
if [ -z "${PETSC_DIR:-}" ] && ! dpkg -s petsc-dev >/dev/null 2>&1; then
    { apt-get update && apt-get install -y --no-install-recommends petsc-dev; } || {
        echo "error: could not install petsc-dev with apt-get (run as root?); the [mpi] extra needs" \
             "PETSc (Debian's petsc-dev, or your own PETSc build with PETSC_DIR/PETSC_ARCH set)" >&2
        exit 1
    }
fi
# Debian's PETSc: /usr/lib/petsc is its alternatives link to /usr/lib/petscdir/petsc3.18/<arch>-real
export PETSC_DIR=${PETSC_DIR:-$(readlink -f /usr/lib/petsc)}
"$VENV/bin/python" -c "import numpy" 2>/dev/null || "$VENV/bin/pip" install "numpy>=1.24"
"$VENV/bin/pip" install "setuptools>=65" wheel  # bdist_wheel for petsc4py's setup.py
"$VENV/bin/pip" install --no-build-isolation "petsc4py>=3.18,<3.19"
"$VENV/bin/pip" install --no-binary=mpi4py "mpi4py>=3.1" "pymetis>=2023.1"
