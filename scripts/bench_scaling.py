"""Benchmark: cost against mesh size, with fitted scaling exponents (issue 19, item 6).

Times, on a family of 1 x 0.1 x 0.1 m Neo-Hookean P1 beams held at their left end
(``fe.study.scaling.measure_scaling``; the beam of ``scripts/bench_step.py`` is the
largest, 100 x 16 x 16 cells, 153,600 tets, 87,567 DOFs):

1. assembly of the residual and the PSD-projected tangent (``model.linearize``, the fused
   numba path when numba is installed) in a bent cantilever state;
2. one ``fe.ImplicitEuler`` step, dt = 1/60 s, from rest under gravity, with AMG-CG at
   every size (``--solver auto`` for the integrators' default, which switches from a
   direct solve to AMG-CG at 20k DOFs);
3. one ``fe.SymplecticEuler`` step (dt = 1e-6 s) from the bent state;

at each size, interleaved, medians of ``--repeats`` (fast operations timed in batches of
about 20 ms), and fits ``log t = a + p log n_tets`` by least squares: p per operation is
printed, and the log-log plot is written to ``--out``. BLAS is pinned to one thread;
numba's threads are ``--threads`` (default: numba's own, one per core). ``--clock process``
times the process's CPU time instead of the wall time: on a machine shared with other
jobs it leaves out their share of the cores.

Usage::

    python scripts/bench_scaling.py                  # 5k-154k tets, a few minutes
    python scripts/bench_scaling.py --quick          # 1k-20k tets, about 20 s
    python scripts/bench_scaling.py --sizes 5000 20000 80000 --implicit-repeats 3 --out s.png
    python scripts/bench_scaling.py --threads 1 --clock process   # on a shared machine
"""

from __future__ import annotations

import argparse
import logging
import os
import platform
import time


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1k-20k tets (seconds)")
    parser.add_argument("--sizes", type=int, nargs="+", default=None,
                        help="target tet counts (default 5k-154k; --quick 1k-20k)")
    parser.add_argument("--repeats", type=int, default=5, help="samples per point (>= 5)")
    parser.add_argument("--implicit-repeats", type=int, default=None,
                        help="samples of the implicit step per point (default: --repeats)")
    parser.add_argument("--solver", choices=("amg", "auto", "direct"), default="amg",
                        help="the implicit step's linear solver (default amg at every size)")
    parser.add_argument("--threads", type=int, default=None,
                        help="NUMBA_NUM_THREADS (default: numba's, one per core)")
    parser.add_argument("--clock", choices=("wall", "process"), default="wall",
                        help="wall time, or this process's CPU time (steadier on a shared "
                             "machine; equal to the wall time of an idle one with --threads 1)")
    parser.add_argument("--out", default="scaling.png", help="the log-log plot (PNG)")
    args = parser.parse_args(argv)
    if args.threads is not None:
        os.environ["NUMBA_NUM_THREADS"] = str(args.threads)  # read when numba is first imported

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    import scipy

    from fem_elastic.solvers.linear_solvers import as_linear_solver
    from fem_elastic.study import scaling

    sizes = args.sizes or (scaling.QUICK_SIZES if args.quick else scaling.FULL_SIZES)
    solver = as_linear_solver(args.solver)
    try:
        import numba

        threads = f"numba {numba.__version__}, {numba.config.NUMBA_NUM_THREADS} threads"
    except ImportError:
        threads = "no numba (numpy path)"
    print(f"fem_elastic scaling benchmark: numpy {np.__version__}, scipy {scipy.__version__}, "
          f"python {platform.python_version()}, {platform.machine()}, {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.1f}; {threads}; BLAS 1 thread")
    print(f"beam 1 x 0.1 x 0.1 m, NeoHookean E = 1e7 Pa, nu = 0.45, P1; target sizes "
          f"{list(sizes)}; implicit step: {type(solver).__name__}, dt = 1/60 s from rest; "
          f"medians of {args.repeats} (implicit {args.implicit_repeats or args.repeats}); "
          f"clock: {args.clock}")
    logging.basicConfig(format="  %(message)s")
    logging.getLogger(scaling.__name__).setLevel(logging.INFO)   # one line per size, as it ends
    t0 = time.perf_counter()
    result = scaling.measure_scaling(sizes, repeats=args.repeats,
                                     implicit_repeats=args.implicit_repeats, linear_solver=solver,
                                     clock=args.clock)
    print(f"fused numba kernels: {'yes' if result.fused else 'no'}; "
          f"measured in {time.perf_counter() - t0:.0f} s\n")
    print(result.summary())
    print()
    exponents = result.exponents
    for op in result.operations:
        p = exponents[op]
        spread = [f"{s.min() * 1e3:.3g}-{s.max() * 1e3:.3g}" for s in result.samples[op]]
        print(f"  {op:14s} p = {p:.2f}   t(153,600 tets) from the fit {result.predict(op, 153600) * 1e3:9.1f} ms"
              f"   samples min-max ms per size: {', '.join(spread)}")
    ax = result.plot()
    ax.figure.tight_layout()
    ax.figure.savefig(args.out, dpi=120)
    plt.close(ax.figure)
    print(f"\nwrote {args.out}")


if __name__ == "__main__":
    main()
