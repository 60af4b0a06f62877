"""Benchmark: an implicit step with one AMG hierarchy per step against one per solve (issue 19).

Times ``fe.ImplicitEuler`` steps (dt = 1/60 s) of a Neo-Hookean cantilever released from rest
under gravity (default: a 1 x 0.1 x 0.1 m beam of 70 x 11 x 11 cells, 50,820 P1 tets,
30,672 DOFs, so the default ``fe.AutoSolver`` takes AMG-CG), in one process, two ways:

* ``after``: the library as it is (:mod:`fem_elastic.solvers.newton`): one smoothed-aggregation
  hierarchy per step, reused as the CG preconditioner of every Newton iteration, and the exact
  tangent's CG stopped at its first negative curvature;
* ``before``: the behaviour before issue 19, selected by the private switch
  ``fem_elastic.solvers.newton._REUSE_AMG = False``: a new hierarchy for every solve, and an
  exact-tangent solve that is thrown away (now counted) when it gives no descent direction.

After one untimed warm-up step of each, each repeat takes ``--steps`` steps from rest with each variant in turn (interleaved, so a
change of load on the shared machine falls on both alike). Prints, per variant, the median
over all timed steps of the step time (s), and the per-step means of Newton iterations, linear
solves, AMG setups (hierarchies built) and CG iterations, then the ratio after / before and
the largest difference of the final positions (relative to the largest displacement).

BLAS is pinned to one thread (threadpoolctl, when installed).

Usage::

    python scripts/bench_newton_amg.py                 # ~50k tets, 3 repeats x 3 steps
    python scripts/bench_newton_amg.py --quick         # 12 x 3 x 3 cells, AMG forced, seconds
    python scripts/bench_newton_amg.py --cells 100 16 16 --repeats 5
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import time

import numpy as np


def _blas_one_thread():
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - optional
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def run_variant(fe, newton, model, reuse, steps, dt, solver):
    """Steps from rest with ``_REUSE_AMG = reuse``: (per-step rows, final positions)."""
    old = newton._REUSE_AMG
    newton._REUSE_AMG = reuse
    try:
        ie = fe.ImplicitEuler(linear_solver=solver)
        s = fe.State.rest(model)
        rows = []
        for _ in range(steps):
            t0 = time.perf_counter()
            s = ie.step(model, s, dt)
            st = ie.last_stats
            rows.append((time.perf_counter() - t0, st.newton_iterations, st.linear_solves,
                         st.linear_setups, st.linear_iterations))
        return rows, s.x
    finally:
        newton._REUSE_AMG = old


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cells", type=int, nargs=3, default=(70, 11, 11))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=3, help="implicit steps per repeat")
    ap.add_argument("--max-direct-dofs", type=int, default=None,
                    help="AutoSolver threshold (default the library's 20000; --quick: 0)")
    ap.add_argument("--quick", action="store_true", help="12 x 3 x 3 cells, AMG forced")
    args = ap.parse_args(argv)
    if args.quick:
        args.cells = (12, 3, 3)
        if args.max_direct_dofs is None:
            args.max_direct_dofs = 0

    import fem_elastic as fe
    from fem_elastic.solvers import newton

    mesh = fe.beam_mesh(1.0, 0.1, 0.1, tuple(args.cells))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1.0e7, nu=0.45)),
                     fixed="left", gravity=(0.0, 0.0, -9.81))
    # max_factor_bytes=0: never CHOLMOD, so AutoSolver takes AMG-CG above max_direct_dofs (what
    # this benchmark measures)
    solver = (fe.AutoSolver(max_factor_bytes=0) if args.max_direct_dofs is None
              else fe.AutoSolver(max_direct_dofs=args.max_direct_dofs, max_factor_bytes=0))
    dt = 1.0 / 60.0
    print(f"ImplicitEuler, dt = 1/60 s, Neo-Hookean cantilever from rest under gravity: "
          f"{mesh.nelements} tets, "
          f"{model.ndofs} DOFs; {args.repeats} repeats x {args.steps} steps, "
          f"AutoSolver(max_direct_dofs={solver.max_direct_dofs})")
    variants = {"before": False, "after": True}
    rows = {k: [] for k in variants}
    final = {}
    with _blas_one_thread():
        for reuse in variants.values():  # warm-up, untimed: JIT compiles, first-touch caches
            run_variant(fe, newton, model, reuse, 1, dt, solver)
        for _ in range(args.repeats):
            for label, reuse in variants.items():
                r, x = run_variant(fe, newton, model, reuse, args.steps, dt, solver)
                rows[label].extend(r)
                final[label] = x
    med = {}
    for label in variants:
        a = np.array(rows[label])
        med[label] = statistics.median(a[:, 0])
        print(f"{label:>6}: step {med[label]:.3f} s (median of {len(a)}), per step: "
              f"Newton iterations {a[:, 1].mean():.2f}, linear solves {a[:, 2].mean():.2f}, "
              f"AMG setups {a[:, 3].mean():.2f}, CG iterations {a[:, 4].mean():.1f}")
    u = float(np.abs(final["before"] - model.X).max())
    diff = float(np.abs(final["after"] - final["before"]).max())
    print(f"ratio after / before: step time {med['after'] / med['before']:.3f}")
    print(f"final positions: max |after - before| = {diff:.3e} m, {diff / u if u > 0 else 0.0:.2e} "
          f"of the largest displacement {u:.3e} m")


if __name__ == "__main__":
    main()
