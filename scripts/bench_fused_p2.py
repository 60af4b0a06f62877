"""Fused P2 kernels (numba: gradient, energy, tangent scattered into the CSR data) against numpy.

Times, in one process and on one mesh (default: a 1 x 0.1 x 0.1 m beam of 60 x 8 x 8
cells, 23,040 P2 tets, 104,907 DOFs), ``ElasticPotential.gradient(x)``, ``energy(x)`` and
``hessian(x, project)`` on both paths at a bent state (and, for Neo-Hookean, a bent and
15 % compressed one, where every point's tangent is indefinite), and prints per row the
medians of ``--repeats`` (>= 5) runs, the ratio fused / numpy, and the peak memory traced
by :mod:`tracemalloc` during one call of each path (after a warm-up call, so the cached
sparsity pattern and the fused path's ``(ne, 10, 10)`` offset map, whose size is printed
on its own, are not counted).

Usage::

    python scripts/bench_fused_p2.py              # 23,040 P2 tets, 104,907 DOFs
    python scripts/bench_fused_p2.py --quick      # 10 x 2 x 2 cells, seconds
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import fem_elastic as fe
from fem_elastic.discretization import Discretization, fused
from fem_elastic.physics.elastic_body import ElasticPotential

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_fused_tangent import measure, numpy_path, state  # noqa: E402  the same states and timing


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a 10 x 2 x 2 beam (seconds)")
    parser.add_argument("--cells", type=int, nargs=3, default=None, metavar=("NX", "NY", "NZ"))
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--clock", choices=("wall", "process"), default="wall",
                        help="process: this process's CPU time (for a loaded machine)")
    args = parser.parse_args()
    # process: this process's CPU time (every kernel here runs on one thread), for a loaded machine
    clock = time.process_time if args.clock == "process" else time.perf_counter
    if not fused.available():
        raise SystemExit("numba is not importable (or FEM_ELASTIC_NUMBA=0): nothing to compare")
    repeats = max(5, args.repeats)
    cells = tuple(args.cells) if args.cells else ((10, 2, 2) if args.quick else (60, 8, 8))
    space = Discretization(fe.beam_mesh(1.0, 0.1, 0.1, cells), order=2)
    ne = space.element_dofs.shape[1]
    print(f"mesh: beam 1.0 x 0.1 x 0.1 m, cells {cells}, {ne:,} P2 tets, {space.ndofs:,} DOFs; "
          f"medians of {repeats} runs ({args.clock} clock); peak = tracemalloc peak of one call")
    print(f"{'state':<16} {'material':<18} {'work':<17} {'fused s':>9} {'numpy s':>9} {'ratio':>7} "
          f"{'fused MiB':>10} {'numpy MiB':>10} {'max rel diff':>13}")
    rows = [("bent", 0.0, cls) for cls in (fe.NeoHookean, fe.StableNeoHookean, fe.StVK,
                                           fe.LinearElastic)]
    rows.append(("bent+compressed", 0.15, fe.NeoHookean))
    for label, compression, cls in rows:
        x = state(space, compression)
        pot = ElasticPotential(cls(E=1.0e6, nu=0.45), space)
        works = {"gradient": lambda: pot.gradient(x), "energy": lambda: pot.energy(x),
                 "tangent exact": lambda: pot.hessian(x, project=False)}
        if cls is not fe.LinearElastic:  # its projected tangent is the exact one
            works["tangent projected"] = lambda: pot.hessian(x, project=True)
        if compression:
            works = {k: works[k] for k in ("gradient", "tangent projected")}
        for work, f in works.items():
            t_f, m_f = measure(f, repeats, clock)
            t_n, m_n = measure(numpy_path(f), repeats, clock)
            a, b = f(), numpy_path(f)()
            a, b = (np.atleast_1d(getattr(v, "data", v)) for v in (a, b))
            err = np.abs(a - b).max() / np.abs(b).max()
            print(f"{label:<16} {cls.__name__:<18} {work:<17} {t_f:9.4f} "
                  f"{t_n:9.4f} {t_f / t_n:7.3f} {m_f:10.1f} {m_n:10.1f} {err:13.2e}", flush=True)
    from fem_elastic.discretization import _fused_p2_kernels as p2
    from fem_elastic.discretization import _fused_tangent_kernels as tk
    off = tk.element_offsets(space.pattern, p2.geometry(space).nodes)
    print(f"fused path, once per pattern: (ne, 10, 10) {off.dtype} offset map "
          f"{off.nbytes / 2**20:.1f} MiB (the numpy path's scatter, int64: "
          f"{space.pattern.scatter.nbytes / 2**20:.1f} MiB, is built for the numpy path)")


if __name__ == "__main__":
    main()
