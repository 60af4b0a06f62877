"""Benchmark: one XPBD iteration against one symplectic Euler step, on the same beam.

Times, in one run and on one mesh (default: the 1 x 0.1 x 0.1 m beam of 100 x 16 x 16 cells of
``scripts/bench_step.py``, 153,600 P1 tets, 87,567 DOFs), from the same bent state:

1. one ``fe.SymplecticEuler().step`` (one fused elastic force, the vector updates, contacts
   and held DOFs) on a stable Neo-Hookean body (E = 1e7 Pa, nu = 0.45), the reference;
2. one Gauss-Seidel sweep of ``fe.XPBD``'s Neo-Hookean constraints over every tet (the
   colour order, numba), and one Jacobi sweep;
3. one ``fe.XPBD(iterations=n).step`` for two n, whose difference over the difference of n
   is the cost of one iteration inside a step (the prediction, velocity update and held
   DOFs are the per-step overhead, given as well), at ``h omega_max = 2`` (the largest step
   the Neo-Hookean constraints take accurately, see ``fem_elastic.dynamics.position_based.xpbd``);
4. the same for ``fe.XPBD(constraints="edge_volume")`` (edges and tets) and ``fe.PBD``.

Prints the medians over ``--repeats`` (>= 5) repeats, called round-robin, and the ratio
"one XPBD iteration / one symplectic Euler step" (goal <= 2). numba and BLAS run on one
thread, as in ``scripts/bench_step.py``. The first call (the JIT compile or the load of the
cached kernels, the colouring of the constraints) is timed separately.

Usage::

    python scripts/bench_position_based.py               # full size, about a minute
    python scripts/bench_position_based.py --quick       # 20 x 4 x 4 cells, seconds
    python scripts/bench_position_based.py --cells 50 8 8 --repeats 7
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_step import bent_state, interleaved  # the same bent beam, the same round-robin timing


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs=3, default=None, metavar=("NX", "NY", "NZ"))
    parser.add_argument("--quick", action="store_true", help="a 20 x 4 x 4 beam (seconds)")
    parser.add_argument("--repeats", type=int, default=7, help="repeats of each timing (>= 5)")
    parser.add_argument("--threads", type=int, default=1, help="NUMBA_NUM_THREADS (default 1)")
    args = parser.parse_args(argv)
    cells = tuple(args.cells) if args.cells else ((20, 4, 4) if args.quick else (100, 16, 16))
    os.environ["NUMBA_NUM_THREADS"] = str(args.threads)  # read when numba is first imported

    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        run(cells, max(5, args.repeats))


def run(cells, repeats):
    import fem_elastic as fe
    from fem_elastic.dynamics.position_based import constraints
    from fem_elastic.dynamics.position_based.xpbd import max_frequency_estimate

    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells)
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.StableNeoHookean(E=1.0e7, nu=0.45)),
                     fixed="left", gravity=(0.0, 0.0, -9.81))
    ne = mesh.t.shape[1]
    x0 = bent_state(model.X)
    state = fe.State(x0, np.zeros(model.ndofs), 0.0)
    numba = constraints.numba_kernels() is not None
    print(f"fem_elastic position-based benchmark: numpy {np.__version__}, python "
          f"{platform.python_version()}, {platform.machine()}, BLAS threads 1, "
          f"{'numba sweeps' if numba else 'numpy sweeps (numba not importable or FEM_ELASTIC_NUMBA=0)'}")
    print(f"mesh: beam 1.0 x 0.1 x 0.1 m, cells {cells}, {ne:,} P1 tets, {mesh.edges.shape[1]:,} edges, "
          f"{model.ndofs:,} DOFs; StableNeoHookean E = 1e7 Pa, nu = 0.45; bent state")

    dt_se = 1.0e-6  # below the critical step: the step's cost does not depend on dt
    se = fe.SymplecticEuler()
    n1, n2 = 2, 6
    integrators = {
        "XPBD neohookean": (fe.XPBD(iterations=n1), fe.XPBD(iterations=n2)),
        "XPBD edge_volume": (fe.XPBD(iterations=n1, constraints="edge_volume"),
                             fe.XPBD(iterations=n2, constraints="edge_volume")),
        "PBD (edges + volumes)": (fe.PBD(iterations=n1, stiffness=0.5), fe.PBD(iterations=n2, stiffness=0.5)),
    }
    first = {}
    t0 = time.perf_counter()
    se.step(model, state, dt_se)
    first["SymplecticEuler"] = time.perf_counter() - t0
    xpbd = integrators["XPBD neohookean"][0]
    t0 = time.perf_counter()
    sets = xpbd.prepared(model).sets
    first["XPBD neohookean"] = time.perf_counter() - t0
    # the Neo-Hookean constraints need h omega_max <= 2 (fem_elastic.dynamics.position_based.xpbd):
    # time their steps at that step size, where they are accurate; the others at 1 ms
    omega = max_frequency_estimate(sets[0], model.lumped_mass[0::3])
    dts = {name: (2.0 / omega if name.startswith("XPBD neo") else 1.0e-3) for name in integrators}
    for name, (a, b) in integrators.items():
        t0 = time.perf_counter()
        a.step(model, state, dts[name])
        first[name] = first.get(name, 0.0) + time.perf_counter() - t0
        b.prepared(model)  # share nothing: b colours its own sets (not timed)
    w = 1.0 / model.lumped_mass
    w[~model.free] = 0.0
    coeff = xpbd._coefficients(sets, dts["XPBD neohookean"])

    def sweep(method):
        x = x0.copy()
        lams = [np.zeros((len(s), s.m)) for s in sets]

        def call():
            for s, lam, (at, scale) in zip(sets, lams, coeff):
                s.sweep(x, w, lam, at, scale, method)
        return call

    fns = {"fe.SymplecticEuler().step": lambda: se.step(model, state, dt_se),
           "XPBD neohookean: one Gauss-Seidel sweep": sweep("gauss_seidel"),
           "XPBD neohookean: one Jacobi sweep": sweep("jacobi")}
    for name, (a, b) in integrators.items():
        fns[f"{name}: step, {n1} iterations"] = (lambda a=a, h=dts[name]: a.step(model, state, h))
        fns[f"{name}: step, {n2} iterations"] = (lambda b=b, h=dts[name]: b.step(model, state, h))
    rows = {label: median for label, (median, _, _) in interleaved(fns, repeats).items()}
    ms = 1e3
    print("\nstep sizes: " + ", ".join(f"{k} {v:.3g} s" for k, v in dts.items())
          + " (the Neo-Hookean constraints at h omega_max = 2)")
    print("first calls (compile or cache load, colouring): "
          + ", ".join(f"{k} {v:.2f} s" for k, v in first.items()))
    for name, (a, b) in integrators.items():
        s = a.prepared(model).sets
        print(f"  {name}: " + ", ".join(f"{len(c):,} {type(c).__name__} in {c.n_colors} colours" for c in s))
    print(f"\nmedians of {repeats}:")
    for label, t in rows.items():
        print(f"  {label:55s} {t * ms:9.2f} ms")
    t_se = rows["fe.SymplecticEuler().step"]
    print("\nratios to one fe.SymplecticEuler().step "
          f"({t_se * ms:.2f} ms; goal for one XPBD iteration: <= 2):")
    gs, jac = rows["XPBD neohookean: one Gauss-Seidel sweep"], rows["XPBD neohookean: one Jacobi sweep"]
    print(f"  one XPBD iteration (Neo-Hookean constraints, Gauss-Seidel sweep): {gs / t_se:5.2f} x")
    print(f"  one XPBD iteration (Neo-Hookean constraints, Jacobi sweep):       {jac / t_se:5.2f} x")
    for name in integrators:
        t1, t2 = rows[f"{name}: step, {n1} iterations"], rows[f"{name}: step, {n2} iterations"]
        per_it = (t2 - t1) / (n2 - n1)
        overhead = t1 - n1 * per_it
        print(f"  {name}: one iteration inside a step {per_it / t_se:5.2f} x ({per_it * ms:.2f} ms), "
              f"per-step overhead {overhead / t_se:5.2f} x ({overhead * ms:.2f} ms)")


if __name__ == "__main__":
    main()
