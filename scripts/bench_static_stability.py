"""Benchmark: the cost of the stability check of ``fe.solve_static`` against the solve itself.

After Newton converges, ``solve_static`` computes the lowest eigenvalue of the exact tangent on
the free DOFs (:mod:`fem_elastic.solvers.stability`): dense below 300 free DOFs, else LOBPCG
preconditioned by the factorization the last Newton solve left (direct solver) or by
smoothed-aggregation AMG on the projected tangent (AMG-CG above 20k DOFs). This prints its
time as a ratio to the rest of the solve (goal: <= 0.3), medians over repeats.

The problem is the cantilever of ``scripts/bench_assembly.py``: a 1 x 0.1 x 0.1 m Neo-Hookean
beam (E = 1e7 Pa, nu = 0.45, P1) clamped at x = 0, with a tip traction that bends it ~10 % of
its length (a nonlinear solve of several Newton iterations). ``--tets`` sets the size (cells
scaled from 100 x 16 x 16, i.e. 153,600 tets and 87,567 DOFs by default).

BLAS/OpenMP threads are pinned to 1 with threadpoolctl, as in the other benchmarks.

Usage::

    python scripts/bench_static_stability.py                 # the 150k-tet beam, 3 repeats
    python scripts/bench_static_stability.py --tets 20000    # smaller, seconds
    python scripts/bench_static_stability.py --order 2 --tets 6000
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time


def cells_for(tets: int) -> tuple[int, int, int]:
    """Cells (nx, ny, nz) of a 100:16:16 beam with about ``tets`` tets (6 per cell)."""
    s = (tets / (6 * 100 * 16 * 16)) ** (1 / 3)
    return max(2, round(100 * s)), max(1, round(16 * s)), max(1, round(16 * s))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tets", type=int, default=153_600, help="about this many tets (default 153600)")
    parser.add_argument("--order", type=int, default=1, choices=(1, 2))
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--deflection", type=float, default=0.1, help="tip deflection / length (beam theory)")
    args = parser.parse_args(argv)

    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        run(cells_for(args.tets), args.order, args.repeats, args.deflection)


def run(cells, order, repeats, deflection):
    import numpy as np
    import scipy

    import fem_elastic as fe

    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells)
    E = 1.0e7
    inertia = 0.1**4 / 12
    p = deflection * 3 * E * inertia / 1.0**3 / 0.01  # tip traction (Pa) for the deflection
    model = fe.Model(mesh, 1000.0, fe.ElasticBody(fe.NeoHookean(E=E, nu=0.45), order=order),
                     fixed="left", traction={"right": (0.0, 0.0, -p)})
    print(f"beam {cells[0]} x {cells[1]} x {cells[2]} cells, P{order}: {mesh.t.shape[1]:,} tets, "
          f"{model.ndofs:,} DOFs ({int(model.free.sum()):,} free); tip traction {p:.4g} Pa")
    print(f"python {platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}, "
          f"{platform.processor() or platform.machine()}; 1 thread")
    fe.solve_static(model, stability=False)  # warm-up: numba kernels, caches
    solve, check, ratio = [], [], []
    for k in range(repeats):
        t0 = time.perf_counter()
        res = fe.solve_static(model)
        wall = time.perf_counter() - t0
        s = res.seconds["stability"]
        solve.append(wall - s)
        check.append(s)
        ratio.append(s / (wall - s))
        print(f"  run {k + 1}: solve {wall - s:.3f} s ({res.iterations} Newton iterations, "
              f"{len(res.load_steps)} load step(s)), stability check {s:.3f} s, ratio {s / (wall - s):.3f}; "
              f"lowest eigenvalue {res.min_eigenvalue:.6g} N/m, stable={res.stable}")
    t0 = time.perf_counter()
    fe.solve_static(model, stability=False)
    plain = time.perf_counter() - t0
    print(f"median: solve {statistics.median(solve):.3f} s, stability check {statistics.median(check):.3f} s, "
          f"ratio {statistics.median(ratio):.3f} (goal <= 0.3); a solve without the check: {plain:.3f} s")


if __name__ == "__main__":
    main()
