"""Linear static solves above 20k DOFs: AMG-CG and CHOLMOD against SuperLU, in one process.

Two problems, each one linear elastic static solve ``K u = f`` on the free DOFs (the
constrained stiffness of ``fe.solve_static``'s Newton step from rest):

- **Cook slab**: Cook's tapered panel as a plate one element thick, quadratic tets,
  E = 250, nu = 0.4999 (``scripts/cook_membrane.py``'s plane-strain benchmark): a thin,
  nearly incompressible plate, where smoothed-aggregation AMG struggles;
- **beam**: a steel cantilever 1 m x 0.1 m x 0.1 m on linear tets under gravity.

Each solver starts from nothing every repeat (no kept factor or hierarchy): SuperLU
(``fe.DirectSolver``'s factor), CHOLMOD (``fe.CholmodSolver``: analysis, factor, solve),
CHOLMOD's numeric refactorisation alone (analysis kept: what a Newton iteration or a load
step of a nonlinear body pays), and AMG-CG (``fe.AMGSolver``, rigid-body modes, rtol 1e-8).
It prints the median time of each over ``--repeats`` (>= 5) and its ratio to SuperLU's, the
factor fill ``nnz(L) / (nnz(A) n^(1/3))`` with ``--fill``, and the largest difference of each
solution from SuperLU's relative to its largest entry.

Run ``.venv/bin/python scripts/bench_linear_solvers.py`` (about 2 min on 2 cores),
``--quick`` (small sizes, seconds), or choose sizes with ``--cook-cells`` and
``--beam-cells``. An AMG-CG that misses its tolerance (in ``--amg-maxiter``
iterations, 100 by default) is timed once, to its failure, and marked FAILED.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import fem_elastic as fe
from fem_elastic.solvers import linear_solvers as ls
from fem_elastic.solvers.cholmod import CholmodSolver, have_cholmod
from fem_elastic.solvers.newton import constrain

AMG_MAXITER = [100]  # --amg-maxiter; fe.AMGSolver's default is 500


def cook_system(n: int, layers: int = 1):
    mesh = fe.cook_membrane_mesh(cells=(n, n), layers=layers)
    model = fe.Model(mesh, density=1.0,
                     body=fe.ElasticBody(fe.LinearElastic(E=250.0, nu=0.4999), order=2),
                     fixed={"left": "xyz", "front": "z", "back": "z"},
                     traction={"right": (0.0, 100.0 / 16, 0.0)})
    return _system(model)


def beam_system(cells):
    model = fe.Model(fe.beam_mesh(1.0, 0.1, 0.1, cells=tuple(cells)), density=7850.0,
                     body=fe.ElasticBody(fe.LinearElastic(E=2e11, nu=0.3)), fixed="left",
                     gravity=(0.0, 0.0, -9.81))
    return _system(model)


def _system(model):
    g, K = model.linearize(model.X.copy(), 1.0, project=False)
    A = constrain(K, model.free, model.space.pattern).tocsr()
    b = np.where(model.free, -g, 0.0)
    B = model.space.rigid_body_modes() * model.free[:, None]
    return A, b, B


def _superlu(A, b, B):
    ls._FACTORS.key = None  # no kept factor: every repeat factorises
    return ls.DirectSolver().solve(A, b, B).x


def _cholmod(A, b, B):
    return CholmodSolver().solve(A, b).x


def _amg(A, b, B):
    return ls.AMGSolver(rtol=1e-8, maxiter=AMG_MAXITER[0]).solve(A, b, near_null=B).x


def bench(name, A, b, B, repeats, fill):
    solvers = {"SuperLU": _superlu}
    if have_cholmod():
        solvers["CHOLMOD"] = _cholmod
        kept = CholmodSolver()
        kept.solve(A, b)
        A2 = A.copy()
        A2.data *= 2.0  # other values, same pattern: the analysis is kept, the factor redone
        turn = [0]

        def refactor(A, b, B):
            turn[0] ^= 1
            return kept.solve(A2, b).x * 2.0 if turn[0] else kept.solve(A, b).x
        solvers["CHOLMOD refactor"] = refactor
    solvers["AMG-CG"] = _amg
    times = {k: [] for k in solvers}
    xs = {}
    failed = {}
    for _ in range(repeats):  # interleaved, so load on the machine falls on every solver alike
        for k, f in solvers.items():
            if k in failed:  # a failed AMG-CG is not timed again: it fails the same way
                continue
            t0 = time.perf_counter()
            try:
                xs[k] = f(A, b, B)
            except fe.LinearSolverFailed as exc:
                xs[k] = exc.result.x
                failed[k] = exc.result.iterations
            times[k].append(time.perf_counter() - t0)
    ref = statistics.median(times["SuperLU"])
    scale = float(np.abs(xs["SuperLU"]).max())
    print(f"\n{name}: {A.shape[0]} DOFs, nnz(A) = {A.nnz}, medians of {repeats}")
    for k, t in times.items():
        med = statistics.median(t)
        diff = float(np.abs(xs[k] - xs["SuperLU"]).max()) / scale
        note = (f"FAILED: no convergence in {failed[k]} iterations, timed once"
                if k in failed else f"min {min(t):.3f} s")
        print(f"  {k:17s} {med:8.3f} s   {med / ref:6.3f} x SuperLU   ({note}, "
              f"|x - x_SuperLU| / |x|max = {diff:.1e})")
    if fill and have_cholmod():
        from sksparse.cholmod import cholesky

        L = cholesky(A.tocsc(), mode="supernodal").L()
        c = L.nnz / (A.nnz * A.shape[0] ** (1.0 / 3.0))
        print(f"  CHOLMOD fill: nnz(L) = {L.nnz} = {c:.3f} nnz(A) n^(1/3); factor {12 * L.nnz / 2**20:.0f} MiB")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small systems (about 5k DOFs), seconds")
    p.add_argument("--repeats", type=int, default=5, help="timings per solver (median; >= 5)")
    p.add_argument("--cook-cells", type=int, default=None, help="Cook slab cells per side (P2)")
    p.add_argument("--beam-cells", type=int, nargs=3, default=None, help="beam cells (x, y, z), P1")
    p.add_argument("--fill", action="store_true", help="also print CHOLMOD's factor fill")
    p.add_argument("--amg-maxiter", type=int, default=100,
                   help="AMG-CG's iteration limit (default 100; the beam needs 20-50, and AMG-CG on "
                        "the Cook slab, which fails anyway, took 210 s for 500)")
    p.add_argument("--only", choices=("cook", "beam"), help="one problem only")
    a = p.parse_args(argv)
    if a.repeats < 1:
        p.error("--repeats must be >= 1")
    # defaults: both just above 20k DOFs (21,609 and 22,143), the size where the old rule
    # switched from SuperLU to AMG-CG
    cook = a.cook_cells or (12 if a.quick else 24)
    beam = a.beam_cells or ((30, 5, 5) if a.quick else (60, 10, 10))
    if not have_cholmod():
        print("scikit-sparse is not installed: CHOLMOD is left out (pip install -e \".[cholmod]\")")
    AMG_MAXITER[0] = a.amg_maxiter
    if a.only != "beam":
        bench(f"Cook slab, P2, {cook} x {cook} cells, nu = 0.4999", *cook_system(cook), a.repeats, a.fill)
    if a.only != "cook":
        bench(f"beam, P1, {beam[0]} x {beam[1]} x {beam[2]} cells", *beam_system(beam), a.repeats, a.fill)


if __name__ == "__main__":
    main()
