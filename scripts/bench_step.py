"""Benchmark: one time step, explicit and implicit, on a 153,600-tet Neo-Hookean beam.

Times, in one run and on one mesh (default: a 1 x 0.1 x 0.1 m beam of 100 x 16 x 16 cells,
153,600 P1 tets, 87,567 DOFs), in a bent state (an Euler-Bernoulli cantilever shape, as in
``scripts/bench_assembly.py``):

1. ``ElasticPotential.gradient`` (the elastic force with its sign flipped) on the numpy path
   (``FEM_ELASTIC_NUMBA=0``: F, P and the force contraction as whole-mesh arrays) and on the
   fused path (:mod:`fem_elastic.discretization.fused`: one pass over the elements);
2. ``ElasticPotential.energy`` on both paths (a line search calls it many times);
3. one symplectic Euler step written out by hand on the fused path,
   ``v += dt (-g) / m`` on the free DOFs, then ``x += dt v``, and its cost in gradients;
   and the library's ``fe.SymplecticEuler().step`` on the same model, for comparison;

against a reference measured on this machine by the issue author: NVIDIA Warp 1.9.1's CPU
backend, 17.7 ms per step on the same Neo-Hookean tet forces, and 44.7 ms for a
straightforward numpy kernel;

4. ``fe.ImplicitEuler`` steps of the cantilever released under gravity (dt = 1/60 s), with
   the share of each step spent in assembly (residual and tangent, including the PSD
   projection), in the projection alone (timed as the difference between a projected and an
   exact linearization at the same state, times the number of projected ones), in the
   linear solves (AMG-CG above 20k DOFs) and in the line search, and the Newton iterations
   per step.

numba and BLAS run single-threaded (the headline): ``NUMBA_NUM_THREADS`` is set to 1 before
numba loads, unless ``--threads`` says otherwise, and BLAS is pinned to 1 thread with
threadpoolctl. The first call of the fused kernels (the JIT compile, or the load of the
cached object code) is timed separately. Prints medians over repeats.

Usage::

    python scripts/bench_step.py               # full size, ~10-20 s
    python scripts/bench_step.py --quick       # 20 x 4 x 4 cells, seconds
    python scripts/bench_step.py --repeats 21 --cells 50 8 8
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import numpy as np


def interleaved(fns, repeats):
    """{label: (median s, min s, last result)}, the functions called in turn ``repeats`` times.

    Round-robin rather than one function after the other, so that a change of
    load on a shared machine during the run falls on every timing alike.
    """
    times = {label: [] for label in fns}
    out = {}
    for _ in range(repeats):
        for label, fn in fns.items():
            t0 = time.perf_counter()
            out[label] = fn()
            times[label].append(time.perf_counter() - t0)
    return {k: (statistics.median(v), min(v), out[k]) for k, v in times.items()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs=3, default=None, metavar=("NX", "NY", "NZ"))
    parser.add_argument("--quick", action="store_true", help="a 20 x 4 x 4 beam (seconds)")
    parser.add_argument("--repeats", type=int, default=11, help="repeats of each timing")
    parser.add_argument("--threads", type=int, default=1, help="NUMBA_NUM_THREADS (default 1)")
    parser.add_argument("--implicit-steps", type=int, default=3,
                        help="ImplicitEuler steps to time (0 skips the implicit part)")
    args = parser.parse_args(argv)
    cells = tuple(args.cells) if args.cells else ((20, 4, 4) if args.quick else (100, 16, 16))
    os.environ["NUMBA_NUM_THREADS"] = str(args.threads)  # read when numba is first imported

    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        run(cells, max(1, args.repeats))
        if args.implicit_steps > 0:
            run_implicit(cells, args.implicit_steps)


def run_implicit(cells, steps):
    """ImplicitEuler on the cantilever released under gravity: per-step time and its shares."""
    import fem_elastic as fe

    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells)
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1.0e7, nu=0.45)),
                     fixed="left", gravity=(0.0, 0.0, -9.81))
    # count and time the projected and exact linearizations Newton asks for
    calls = {True: 0, False: 0}
    linearize = model.linearize

    def counting(x, load_factor=1.0, project=True):
        calls[bool(project)] += 1
        return linearize(x, load_factor, project=project)

    model.linearize = counting
    dt = 1.0 / 60.0
    integrator = fe.ImplicitEuler()
    run = fe.simulate(model, integrator, dt, steps=steps)
    st = run.step_stats
    step_s = st["seconds_step"]
    # the projection alone: a projected minus an exact linearization, at the last state
    x = run.final_state.x
    t_proj, t_exact = [], []
    for _ in range(5):
        t0 = time.perf_counter()
        linearize(x, project=True)
        t_proj.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        linearize(x, project=False)
        t_exact.append(time.perf_counter() - t0)
    # the fastest of each: a difference of two timings is the first casualty of a loaded machine
    proj_each = max(min(t_proj) - min(t_exact), 0.0)
    total = float(step_s.sum())
    assembly = float(st["seconds_linearize"].sum())
    solve = float(st["seconds_solve"].sum())
    search = float(st["seconds_line_search"].sum())
    projection = proj_each * calls[True]
    print()
    print(f"ImplicitEuler, dt = 1/60 s, {steps} steps of the cantilever released under gravity "
          f"({model.ndofs:,} DOFs, linear solver {'AMG-CG' if model.ndofs > 20000 else 'sparse LU'}):")
    print(f"  per step: median {statistics.median(step_s):.2f} s; Newton iterations per step "
          f"{st['newton_iterations'].tolist()} (median {statistics.median(st['newton_iterations'])}); "
          f"linear-solver iterations {st['linear_iterations'].tolist()}")
    print(f"  linearizations: {calls[True]} projected, {calls[False]} exact; "
          f"projection {proj_each * 1e3:.0f} ms each")
    print(f"  shares of the step time: assembly (incl. projection) {assembly / total:5.1%}, "
          f"of which projection {projection / total:5.1%}; linear solve {solve / total:5.1%}; "
          f"line search {search / total:5.1%}; other {(total - assembly - solve - search) / total:5.1%}")


def bent_state(X: np.ndarray) -> np.ndarray:
    """A cantilever bending shape of the 1 m beam (tip deflection 0.1 m):
    :func:`fem_elastic.study.scaling.bent_state`, the state the scaling study times at."""
    from fem_elastic.study.scaling import bent_state as cantilever_bend  # fem_elastic imported late

    return cantilever_bend(X)


def run(cells, repeats):
    import scipy

    import fem_elastic as fe
    from fem_elastic.discretization import fused

    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells)
    material = fe.NeoHookean(E=1.0e7, nu=0.45)
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(material, order=1), fixed="left")
    space, pot, free = model.space, model.body_potential, model.free
    ne = space.dx.shape[0]
    x = bent_state(model.X)

    print(f"fem_elastic force benchmark: numpy {np.__version__}, scipy {scipy.__version__}, "
          f"python {platform.python_version()}, {platform.machine()}, BLAS threads 1")
    print(f"mesh: beam 1.0 x 0.1 x 0.1 m, cells {cells}, {ne:,} P1 tets, {model.ndofs:,} DOFs; "
          f"NeoHookean E = 1e7 Pa, nu = 0.45; bent state (tip deflection 0.1 m)")

    def numpy_path(fn):
        def call():
            before = os.environ.get(fused.ENV)
            os.environ[fused.ENV] = "0"
            try:
                return fn()
            finally:
                if before is None:
                    del os.environ[fused.ENV]
                else:
                    os.environ[fused.ENV] = before
        return call

    fns = {
        "numpy gradient": numpy_path(lambda: pot.gradient(x)),
        "numpy energy": numpy_path(lambda: pot.energy(x)),
    }
    if not fused.available():
        print("\nnumba is not importable (or FEM_ELASTIC_NUMBA=0): only the numpy path ran.")
        print_rows(interleaved(fns, repeats), repeats)
        return

    import numba

    t0 = time.perf_counter()
    pot.gradient(x)
    pot.energy(x)
    t_first = time.perf_counter() - t0
    kernels = fused._kernels()
    from fem_elastic.discretization import _fused_gradient_kernels

    hits = sum(sum(f.stats.cache_hits.values())
               for f in (_fused_gradient_kernels.gradient_p1, kernels.energy_p1))
    how = "loaded from the cache" if hits else "compiled (and cached)"
    fns["fused gradient"] = lambda: pot.gradient(x)
    fns["fused energy"] = lambda: pot.energy(x)

    # one symplectic Euler step by hand, on the fused path: v += dt (-g)/m on free DOFs; x += dt v
    dt = 1.0e-6  # below the critical time step (~3e-5 s at this mesh size)
    dt_over_m = np.where(free, dt / model.lumped_mass, 0.0)  # 0 on the held DOFs
    xs, vs = x.copy(), np.zeros(model.ndofs)

    def step():  # in place: no temporaries beyond the gradient
        a = pot.gradient(xs)
        a *= dt_over_m
        np.subtract(vs, a, out=vs)  # v1 = v - dt g / m
        np.multiply(vs, dt, out=a)
        np.add(xs, a, out=xs)  # x1 = x + dt v1

    fns["symplectic Euler step, by hand (fused)"] = step
    integrator = fe.SymplecticEuler()
    state = fe.State(x, np.zeros(model.ndofs), 0.0)
    fns["fe.SymplecticEuler().step (fused)"] = lambda: integrator.step(model, state, dt)

    rows = interleaved(fns, repeats)
    t_np_g, _, g_np = rows["numpy gradient"]
    t_np_e, _, e_np = rows["numpy energy"]
    t_f_g, _, g_f = rows["fused gradient"]
    t_f_e, _, e_f = rows["fused energy"]
    t_step = rows["symplectic Euler step, by hand (fused)"][0]
    t_lib = rows["fe.SymplecticEuler().step (fused)"][0]

    print(f"numba {numba.__version__}, NUMBA_NUM_THREADS={numba.config.NUMBA_NUM_THREADS}; "
          f"first fused gradient + energy call: {t_first:.2f} s ({how})")
    print_rows(rows, repeats)
    err_g = np.linalg.norm(g_f - g_np) / np.linalg.norm(g_np)
    err_e = abs(e_f - e_np) / abs(e_np)
    ms = 1e3
    print()
    print("ratios:")
    print(f"  gradient numpy / fused: {t_np_g / t_f_g:6.1f} x   ({t_np_g * ms:.1f} ms -> "
          f"{t_f_g * ms:.2f} ms)")
    print(f"  energy   numpy / fused: {t_np_e / t_f_e:6.1f} x   ({t_np_e * ms:.1f} ms -> "
          f"{t_f_e * ms:.2f} ms)")
    print(f"  symplectic Euler step / fused gradient: by hand {t_step / t_f_g:.2f}, "
          f"fe.SymplecticEuler {t_lib / t_f_g:.2f}   (target <= 1.3)")
    print("  Warp 1.9.1 CPU reference (measured on this machine by the issue author): "
          "17.7 ms/step; straightforward numpy: 44.7 ms")
    vs_warp = (f"Warp / ours (by hand): {17.7e-3 / t_step:.2f} x" if ne == 153_600
               else "(the reference is for the 153,600-tet beam: run without --quick/--cells)")
    print(f"  this step: {t_step * ms:.2f} ms by hand, {t_lib * ms:.2f} ms through "
          f"fe.SymplecticEuler; {vs_warp}")
    print(f"  check: fused vs numpy, relative difference: gradient {err_g:.1e}, energy {err_e:.1e}")


def print_rows(rows, repeats):
    print()
    print(f"{'timing':<44} {'median ms':>10} {'min ms':>9}   ({repeats} runs, interleaved)")
    print("-" * 76)
    for label, (med, best, _) in rows.items():
        print(f"{label:<44} {med * 1e3:10.2f} {best * 1e3:9.2f}")


if __name__ == "__main__":
    main()
