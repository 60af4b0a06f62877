"""Benchmark: one projective-dynamics iteration against one Newton iteration of implicit Euler.

On one mesh (default: the 1 x 0.1 x 0.1 m beam of 100 x 16 x 16 cells of
``scripts/bench_step.py``, 153,600 P1 tets, 87,567 DOFs), a corotated body (E = 1e7 Pa,
nu = 0.45, the energy both schemes minimise: fe.Corotated is fe.ProjectiveCorotated with its
default band), held on its left face, under gravity, from the bent state of
``bench_step.py`` (tip deflection 0.1 m) at rest, dt = 1/60 s:

1. the one-off setup of ``fe.ProjectiveDynamics`` (the scalar Laplacian, then the sparse LU
   factorisation of ``M/h^2 + (2 mu + 3 lam) L`` on the free nodes, once per model and dt);
2. one projective-dynamics iteration: a step of ``fe.ProjectiveDynamics(iterations=1)`` with
   the factorisation cached (the local step: F, a batched signed SVD, the projections and the
   force of the targets; the global step: one LU solve for x, y and z; plus the step's own
   overhead, so slightly more than one iteration);
3. one Newton iteration of ``fe.ImplicitEuler`` on the same model and state: a step with
   ``max_iter=1`` and no dt cuts (it stops, not converged, after one assembly of the
   gradient and PSD-projected Hessian, one linear solve with the default solver, AMG-CG above
   20k DOFs, and the line search), timed to the Diverged it raises;

and prints their medians over ``--repeats`` (>= 5; the two timed in turn) and the ratio
(goal <= 0.2). With
``--accuracy`` it also runs the converged implicit Euler step and reports how far
projective dynamics is from it after 1, 10 and 100 iterations.

numba and BLAS run single-threaded, as in the other benchmarks.

Usage::

    python scripts/bench_projective.py               # full size, a few minutes
    python scripts/bench_projective.py --quick       # 20 x 4 x 4 cells, seconds
    python scripts/bench_projective.py --cells 50 8 8 --repeats 7 --accuracy
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_step import bent_state, interleaved


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs=3, default=None, metavar=("NX", "NY", "NZ"))
    parser.add_argument("--quick", action="store_true", help="a 20 x 4 x 4 beam (seconds)")
    parser.add_argument("--repeats", type=int, default=5, help="repeats of each timing (>= 5)")
    parser.add_argument("--accuracy", action="store_true",
                        help="also compare projective dynamics with the converged implicit step")
    args = parser.parse_args(argv)
    cells = tuple(args.cells) if args.cells else ((20, 4, 4) if args.quick else (100, 16, 16))
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        run(cells, max(5, args.repeats), args.accuracy)


def run(cells, repeats, accuracy):
    import scipy

    import fem_elastic as fe

    dt = 1.0 / 60.0
    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells)
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.Corotated(E=1.0e7, nu=0.45)),
                     fixed="left", gravity=(0.0, 0.0, -9.81))
    state = fe.State(bent_state(model.X), np.zeros(model.ndofs), 0.0)
    print(f"fem_elastic projective dynamics benchmark: numpy {np.__version__}, scipy "
          f"{scipy.__version__}, python {platform.python_version()}, {platform.machine()}, "
          f"{os.cpu_count()} CPUs, BLAS threads 1")
    print(f"mesh: beam 1.0 x 0.1 x 0.1 m, cells {cells}, {mesh.t.shape[1]:,} P1 tets, "
          f"{model.ndofs:,} DOFs; Corotated E = 1e7 Pa, nu = 0.45; fixed left, gravity; bent "
          f"state at rest; dt = 1/60 s; medians of {repeats}")

    # 1. setup and factorisation (once per model and dt)
    pd = fe.ProjectiveDynamics(iterations=1)
    t0 = time.perf_counter()
    pd.step(model, state, dt)
    t_first = time.perf_counter() - t0
    t_factor = pd.last_stats.seconds["solve"]

    # 2. one projective-dynamics iteration, the factorisation cached
    stats = []

    def pd_iteration():
        pd.step(model, state, dt)
        stats.append(dict(pd.last_stats.seconds))

    # 3. one Newton iteration of implicit Euler
    newton = fe.ImplicitEuler(max_iter=1, max_dt_cuts=0)
    nstats = []

    def newton_iteration():
        try:
            newton.step(model, state, dt)
        except fe.Diverged:
            pass  # not converged after its one iteration: what is timed
        nstats.append(newton.last_stats)

    rows = interleaved({"pd": pd_iteration, "newton": newton_iteration}, repeats)
    (t_pd, t_pd_min, _), (t_newton, t_newton_min, _) = rows["pd"], rows["newton"]
    local = statistics.median(s["linearize"] for s in stats)
    solve = statistics.median(s["solve"] for s in stats)
    assert pd.factorizations == 1
    assembly = statistics.median(s.seconds["linearize"] for s in nstats)
    linear = statistics.median(s.seconds["solve"] for s in nstats)
    search = statistics.median(s.seconds["line_search"] for s in nstats)
    assert all(s.newton_iterations == 1 for s in nstats)

    ms = 1e3
    print()
    print(f"{'timing':<58} {'median ms':>10} {'min ms':>9}")
    print("-" * 79)
    print(f"{'projective dynamics: first step (setup + LU factorisation)':<58} {t_first * ms:10.1f}")
    print(f"{'  of which the LU factorisation (once per model and dt)':<58} {t_factor * ms:10.1f}")
    print(f"{'projective dynamics: one iteration (a 1-iteration step)':<58} {t_pd * ms:10.1f} "
          f"{t_pd_min * ms:9.1f}")
    print(f"{'  local step (F, signed SVD, projections, forces)':<58} {local * ms:10.1f}")
    print(f"{'  global step (one LU solve for x, y, z)':<58} {solve * ms:10.1f}")
    print(f"{'implicit Euler: one Newton iteration':<58} {t_newton * ms:10.1f} {t_newton_min * ms:9.1f}")
    print(f"{'  assembly (gradient + projected Hessian)':<58} {assembly * ms:10.1f}")
    print(f"{'  linear solve':<58} {linear * ms:10.1f}")
    print(f"{'  line search':<58} {search * ms:10.1f}")
    print()
    print(f"ratio: one projective-dynamics iteration / one Newton iteration = {t_pd / t_newton:.3f}"
          f"   (goal <= 0.2)")
    print(f"       {t_newton / t_pd:.0f} projective-dynamics iterations cost one Newton iteration; "
          f"the factorisation costs {t_factor / t_pd:.1f} iterations, once")

    if accuracy:
        ie = fe.ImplicitEuler(rtol=1e-10, max_iter=100)
        t0 = time.perf_counter()
        reference = ie.step(model, state, dt)
        t_ie = time.perf_counter() - t0
        print()
        print(f"accuracy against the converged implicit Euler step ({ie.last_stats.newton_iterations} "
              f"Newton iterations, {t_ie:.1f} s): ||x_PD - x_IE|| / ||x_IE - x_n||")
        for k in (1, 10, 100):
            p = fe.ProjectiveDynamics(iterations=k)
            t0 = time.perf_counter()
            out = p.step(model, state, dt)
            t_k = time.perf_counter() - t0
            gap = np.linalg.norm(out.x - reference.x) / np.linalg.norm(reference.x - state.x)
            print(f"  {k:4d} iterations: {gap:.2e}   ({t_k:.1f} s with its factorisation)")


if __name__ == "__main__":
    main()
