"""Fused P1 tangent (numba, scattered into the CSR data) against the numpy assembly.

Times, in one process and on one mesh (default: a 1 x 0.1 x 0.1 m beam of 100 x 16 x 16
cells, 153,600 P1 tets), ``ElasticPotential.hessian(x, project)`` on both paths at a bent
and axially compressed state, and prints per row the medians of ``--repeats`` (>= 5) runs,
the ratio fused / numpy, and the peak memory traced by :mod:`tracemalloc` during one call
of each path (after a warm-up call, so the cached sparsity pattern and the fused path's
``(ne, 4, 4)`` block-offset map, whose size is printed on its own, are not counted).

Usage::

    python scripts/bench_fused_tangent.py              # 153,600 tets
    python scripts/bench_fused_tangent.py --quick      # 20 x 4 x 4 cells, seconds
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
import tracemalloc

import numpy as np

import fem_elastic as fe
from fem_elastic.discretization import Discretization, fused
from fem_elastic.physics.elastic_body import ElasticPotential


def state(space: Discretization, compression: float) -> np.ndarray:
    """Bent (tip deflection 0.1 m), shortened by ``compression`` along the beam, small nodal noise.

    Bending alone compresses one half of the beam, where the Neo-Hookean tangent is
    indefinite (its twist eigenvalues follow the compressive stress); 15 % compression
    makes every element indefinite: the projection's worst case.
    """
    X = space.X.reshape(-1, 3)
    x = X.copy()
    x[:, 0] *= 1.0 - compression
    x[:, 2] -= 0.1 * X[:, 0] ** 2
    rng = np.random.default_rng(0)
    return x.ravel() + 1e-4 * rng.standard_normal(space.ndofs)


def measure(fn, repeats: int, clock=time.perf_counter) -> tuple[float, float]:
    """Median time (s, by ``clock``: wall time by default) of repeats calls, and the tracemalloc
    peak (MiB) of one more call."""
    fn()  # warm-up: compile / load numba, build cached maps
    times = []
    for _ in range(repeats):
        t0 = clock()
        fn()
        times.append(clock() - t0)
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return statistics.median(times), peak / 2**20


def numpy_path(fn):
    def run():
        os.environ[fused.ENV] = "0"
        try:
            return fn()
        finally:
            os.environ.pop(fused.ENV)
    return run


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a 20 x 4 x 4 beam (seconds)")
    parser.add_argument("--cells", type=int, nargs=3, default=None, metavar=("NX", "NY", "NZ"))
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    if not fused.available():
        raise SystemExit("numba is not importable (or FEM_ELASTIC_NUMBA=0): nothing to compare")
    repeats = max(5, args.repeats)
    cells = tuple(args.cells) if args.cells else ((20, 4, 4) if args.quick else (100, 16, 16))
    space = Discretization(fe.beam_mesh(1.0, 0.1, 0.1, cells), order=1)
    ne = space.element_dofs.shape[1]
    print(f"mesh: beam 1.0 x 0.1 x 0.1 m, cells {cells}, {ne:,} P1 tets, {space.ndofs:,} DOFs; "
          f"medians of {repeats} runs; peak = tracemalloc peak of one call")
    print(f"{'state':<16} {'material':<18} {'tangent':<9} {'fused s':>9} {'numpy s':>9} {'ratio':>7} "
          f"{'fused MiB':>10} {'numpy MiB':>10} {'max |dH|/max |H|':>17}")
    rows = [("bent", 0.0, cls) for cls in (fe.NeoHookean, fe.StableNeoHookean, fe.StVK,
                                           fe.LinearElastic)]
    rows.append(("bent+compressed", 0.15, fe.NeoHookean))
    for label, compression, cls in rows:
        x = state(space, compression)
        pot = ElasticPotential(cls(E=1.0e6, nu=0.45), space)
        for project in (False, True):
            if cls is fe.LinearElastic and project:
                continue  # its projected tangent is the exact one
            def f():
                return pot.hessian(x, project=project)
            t_f, m_f = measure(f, repeats)
            t_n, m_n = measure(numpy_path(f), repeats)
            H, H_n = f(), numpy_path(f)()
            err = np.abs(H.data - H_n.data).max() / np.abs(H_n.data).max()
            print(f"{label:<16} {cls.__name__:<18} {'projected' if project else 'exact':<9} {t_f:9.4f} "
                  f"{t_n:9.4f} {t_f / t_n:7.3f} {m_f:10.1f} {m_n:10.1f} {err:17.2e}")
    from fem_elastic.discretization import _fused_tangent_kernels as tk
    off = tk.element_offsets(space.pattern, fused._geometry(space).nodes)
    print(f"fused path, once per pattern: (ne, 4, 4) {off.dtype} block-offset map "
          f"{off.nbytes / 2**20:.1f} MiB (the numpy path's scatter, int64, built on its first use: "
          f"{space.pattern.scatter.nbytes / 2**20:.1f} MiB)")


if __name__ == "__main__":
    main()
