"""Benchmark: one explicit symplectic Euler step on the 153,600-tet beam, before and after issue 19.5.

Times, interleaved and as medians over ``--repeats`` (>= 5 for the figures), on a
1 x 0.1 x 0.1 m Neo-Hookean beam of 100 x 16 x 16 cells (153,600 P1 tets, 87,567 DOFs)
held at its left end, in a bent state (as ``scripts/bench_step.py``), for each numba
thread count of ``--threads`` (default 1 and 2):

- ``before``: the step as the integrator took it before the fast path (reproduced here:
  a new force vector as ``model.gradient`` made it, from the serial fused loop as it was,
  Dm^-1 read through a 3x3 view per element; divided by the lumped mass; the held DOFs
  from ``model.free_at`` and ``model.constraints`` every step);
- ``after``: ``fe.SymplecticEuler().step``: cached inverse mass and held DOFs, force and
  next state in preallocated buffers, the fused gradient on numba's threads;
- ``numpy update``: ``fe.SymplecticEuler().step`` with the update of the first pass of
  19.5 (numpy: negate, scale, ``v + h a``, ``x + h v1``, the State's two copies, the next
  step's finiteness scan), against ``after``, the one numba pass of
  ``integrators/_symplectic_kernel.py`` (same bits); both step on from their own last State;
- ``step without force``: the same two steps with the force handed over (as the gradient a
  step remembers of its last State), so that only the update, the checks and the State are
  timed;
- the gradients alone: before, today's serial kernel (``FEM_ELASTIC_NUMBA_THREADS=0``:
  the blocked loop of ``discretization/_fused_gradient_kernels.py``, 64 elements at a
  time with F, P and the nodal forces vectorised; the same bits as before), the
  threaded kernel (the same loop on each part of the mesh).

The reference is the 7.7 ms per step of the issue's table (Newton-physics/warp CPU);
the goal is <= 0.8 x that. BLAS is pinned to one thread. The machine's load matters:
on a shared 2-core machine a second thread competes with other processes, and after a
threaded call OpenMP's threads spin for a while, which slows a serial call timed right
after it (the serial rows of the 2-thread table).

Usage::

    python scripts/bench_explicit.py                # full size, 1 and 2 threads
    python scripts/bench_explicit.py --quick        # 20 x 4 x 4 cells, seconds
    python scripts/bench_explicit.py --threads 1 2 4 --repeats 11
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

#: ms per explicit symplectic step on the 152,880-tet beam (issue 19's table: Newton-physics /
#: warp 1.19 CPU), and the goal as a fraction of it.
REFERENCE_MS = 7.7
GOAL = 0.8


_OLD_KERNEL = []


def old_gradient(model, x):
    """``model.gradient(x)`` as before issue 19.5 (a body without loads or contacts): a zero
    vector plus a new one from the serial loop as it was, Dm^-1 indexed as a 3x3 view per
    element (the same bits as today's serial kernel, slower)."""
    import numba

    from fem_elastic.discretization import _fused_kernels as K
    from fem_elastic.discretization import fused

    if not _OLD_KERNEL:
        @numba.njit(error_model="numpy", nogil=True)
        def gradient_p1_before(x, X, nodes, Dm_inv, V, kind, prm, out):
            out[:] = 0.0
            for e in range(nodes.shape[0]):
                F = K._deformation_gradient(x, X, nodes, Dm_inv, e)
                p = K.P(kind, F, prm)
                v = V[e]
                d = Dm_inv[e]
                k0, k1, k2, k3 = 3 * nodes[e, 0], 3 * nodes[e, 1], 3 * nodes[e, 2], 3 * nodes[e, 3]
                for i in range(3):
                    q0, q1, q2 = p[3 * i] * v, p[3 * i + 1] * v, p[3 * i + 2] * v
                    f1 = q0 * d[0, 0] + q1 * d[0, 1] + q2 * d[0, 2]
                    f2 = q0 * d[1, 0] + q1 * d[1, 1] + q2 * d[1, 2]
                    f3 = q0 * d[2, 0] + q1 * d[2, 1] + q2 * d[2, 2]
                    out[k1 + i] += f1
                    out[k2 + i] += f2
                    out[k3 + i] += f3
                    out[k0 + i] -= f1 + f2 + f3

        _OLD_KERNEL.append(gradient_p1_before)
    kern = fused.kernels_for(model.body_potential.material, model.space)
    g = kern.geo
    xr = x.view()
    xr.setflags(write=False)
    body = np.empty(g.ndofs)
    _OLD_KERNEL[0](xr, g.X, g.nodes, g.Dm_inv, g.V, kern.kind, kern.prm, body)
    total = np.zeros(model.ndofs)
    total += body
    return total


def old_step(model, state, h):
    """One symplectic Euler step as ``fe.SymplecticEuler`` took it before issue 19.5."""
    import fem_elastic as fe

    free = model.free_at(state.t)
    f = old_gradient(model, state.x)
    np.negative(f, out=f)
    fd = model.damping_force(state.x, state.v, "lumped")
    if fd is not None:
        f += fd
    f /= model.lumped_mass
    f[~free] = 0.0
    f *= h
    f += state.v
    x1 = state.x + h * f
    x1, v1 = model.respond_contacts(x1, f)
    dofs, xc, vc = model.constraints(state.t + h)
    x1[dofs], v1[dofs] = xc, vc
    return fe.State(x1, v1, state.t + h)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs=3, default=None, metavar=("NX", "NY", "NZ"))
    parser.add_argument("--quick", action="store_true", help="a 20 x 4 x 4 beam (seconds)")
    parser.add_argument("--repeats", type=int, default=7, help="repeats of each timing (>= 5)")
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="numba thread counts")
    args = parser.parse_args(argv)
    cells = tuple(args.cells) if args.cells else ((20, 4, 4) if args.quick else (100, 16, 16))
    os.environ["NUMBA_NUM_THREADS"] = str(max(args.threads))  # read when numba is first imported

    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        run(cells, max(1, args.repeats), args.threads)


def run(cells, repeats, thread_counts):
    import numba

    import fem_elastic as fe
    from fem_elastic.discretization import fused
    from fem_elastic.dynamics.integrators import explicit

    from bench_step import bent_state

    if not fused.available():
        raise SystemExit("numba is not importable (or FEM_ELASTIC_NUMBA=0): nothing to compare")
    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells)
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1.0e7, nu=0.45)),
                     fixed="left")
    ne = model.space.dx.shape[0]
    kern = fused.kernels_for(model.body_potential.material, model.space)
    state = fe.State(bent_state(model.X), np.zeros(model.ndofs), 0.0)
    dt = 1.0e-6  # below the critical time step (~3e-5 s at this mesh size)
    print(f"explicit step benchmark: {ne:,} P1 tets, {model.ndofs:,} DOFs, NeoHookean; numba "
          f"{numba.__version__}, "
          f"{os.cpu_count()} CPUs; load average {os.getloadavg()[0]:.2f}; BLAS threads 1")
    print("main-thread CPU ms: the CPU time of the calling thread (time.thread_time); it leaves "
          "out the time the thread waited for a core, so where it is well below the wall time "
          "the machine was busy with other work")
    out = np.empty(model.ndofs)
    env = fused.THREADS_ENV

    def with_env(value, fn):
        def call():
            os.environ[env] = value
            return fn()
        return call

    integrator = fe.SymplecticEuler()
    numpy_update = fe.SymplecticEuler()
    # each integrator steps on from its own last State, as in a run (the fused update vouches for
    # the finiteness of the States it returns, so the next step skips check_state's scan)
    chain = {"fused": state, "numpy": state}

    def step_fused():
        chain["fused"] = integrator.step(model, chain["fused"], dt)

    def step_numpy_update():
        saved = explicit._update_kernel
        explicit._update_kernel = lambda: None
        try:
            chain["numpy"] = numpy_update.step(model, chain["numpy"], dt)
        finally:
            explicit._update_kernel = saved

    # the step without its force: the gradient handed over as the one a step remembers (that of
    # the state it returned last), so what is timed is the update, the checks and the State
    g_given = kern.gradient(state.x)
    given = {"fused": fe.SymplecticEuler(), "numpy": fe.SymplecticEuler()}
    given_chain = {"fused": state, "numpy": state}

    def overhead(which):
        def call():
            integ = given[which]
            integ._gradient = (given_chain[which].x, g_given)
            saved = explicit._update_kernel
            if which == "numpy":
                explicit._update_kernel = lambda: None
            try:
                given_chain[which] = integ.step(model, given_chain[which], dt)
            finally:
                explicit._update_kernel = saved
        return call

    before_rows, after_rows, before_cpu, after_cpu, mid_rows, mid_cpu = {}, {}, {}, {}, {}, {}
    over_rows = {}
    for n in thread_counts:
        numba.set_num_threads(n)
        for value, fn in (("0", lambda: old_gradient(model, state.x)),
                          ("0", lambda: kern.gradient(state.x, out=out)),
                          ("1", lambda: kern.gradient(state.x, out=out)),
                          ("0", lambda: old_step(model, state, dt)),
                          ("1", step_numpy_update),
                          ("1", step_fused), ("1", overhead("numpy")), ("1", overhead("fused"))):
            with_env(value, fn)()  # warm up: compile or load, build the caches
        fns = {
            "gradient before (old serial kernel)": with_env("0", lambda: old_gradient(model, state.x)),
            "gradient, serial kernel": with_env("0", lambda: kern.gradient(state.x, out=out)),
            "gradient, threaded kernel": with_env("1", lambda: kern.gradient(state.x, out=out)),
            "step before (old path, old kernel)": with_env("0", lambda: old_step(model, state, dt)),
            "step, numpy update (19.5 first pass)": with_env("1", step_numpy_update),
            "step after (fe.SymplecticEuler)": with_env("1", step_fused),
            "step without force, numpy update": overhead("numpy"),
            "step without force, fused update": overhead("fused"),
        }
        times = {k: [] for k in fns}
        cpu = {k: [] for k in fns}
        for _ in range(repeats):
            for k, fn in fns.items():
                c0, t0 = time.thread_time(), time.perf_counter()
                fn()
                times[k].append(time.perf_counter() - t0)
                cpu[k].append(time.thread_time() - c0)
        layer = numba.threading_layer() if n > 1 else "none"
        print(f"\nnumba threads {numba.get_num_threads()}, threading layer {layer} "
              f"({repeats} runs, interleaved; load average now {os.getloadavg()[0]:.2f})")
        print(f"{'timing':<40} {'median ms':>10} {'min ms':>9} {'main-thread CPU ms':>19}")
        for k, v in times.items():
            print(f"{k:<40} {statistics.median(v) * 1e3:10.2f} {min(v) * 1e3:9.2f} "
                  f"{statistics.median(cpu[k]) * 1e3:19.2f}")
        before_rows[n] = statistics.median(times["step before (old path, old kernel)"])
        after_rows[n] = statistics.median(times["step after (fe.SymplecticEuler)"])
        before_cpu[n] = statistics.median(cpu["step before (old path, old kernel)"])
        over_rows[n] = tuple(statistics.median(v[f"step without force, {k} update"])
                             for v in (times, cpu) for k in ("numpy", "fused"))
        mid_rows[n] = statistics.median(times["step, numpy update (19.5 first pass)"])
        mid_cpu[n] = statistics.median(cpu["step, numpy update (19.5 first pass)"])
        after_cpu[n] = statistics.median(cpu["step after (fe.SymplecticEuler)"])
    os.environ.pop(env, None)
    # the two paths agree to round-off (one step, serial vs threaded gradient, f / m vs f (1/m))
    a = old_step(model, state, dt)
    b = integrator.step(model, state, dt)
    g_old = old_gradient(model, state.x)
    os.environ[env] = "0"
    same = np.array_equal(g_old, kern.gradient(state.x))
    os.environ.pop(env, None)
    dv = np.max(np.abs(a.v - b.v)) / np.max(np.abs(a.v))
    print("\nexplicit symplectic step, median ms (ratio to the 7.7 ms reference; goal <= "
          f"{GOAL:g} x):")
    for n in thread_counts:
        print(f"  {n} thread(s): before {before_rows[n] * 1e3:6.2f} ms ({before_rows[n] * 1e3 / REFERENCE_MS:.2f} x)"
              f"   after {after_rows[n] * 1e3:6.2f} ms ({after_rows[n] * 1e3 / REFERENCE_MS:.2f} x)"
              f"   speed-up {before_rows[n] / after_rows[n]:.2f} x;   main-thread CPU: before "
              f"{before_cpu[n] * 1e3:6.2f} ms, after {after_cpu[n] * 1e3:6.2f} ms "
              f"({after_cpu[n] * 1e3 / REFERENCE_MS:.2f} x)")
    print("the fused update alone (same kernel; the numpy update of the first pass of 19.5 against "
          "the one numba pass that also vouches for finiteness and drops the State copies):")
    for n in thread_counts:
        print(f"  {n} thread(s): numpy update {mid_rows[n] * 1e3:6.2f} ms ({mid_rows[n] * 1e3 / REFERENCE_MS:.2f} x)"
              f"   fused update {after_rows[n] * 1e3:6.2f} ms; main-thread CPU {mid_cpu[n] * 1e3:6.2f} -> "
              f"{after_cpu[n] * 1e3:6.2f} ms")
    for n in thread_counts:
        t_np, t_fu, c_np, c_fu = over_rows[n]
        print(f"  {n} thread(s), the step without its force: numpy update {t_np * 1e3:.3f} ms, fused "
              f"{t_fu * 1e3:.3f} ms (main-thread CPU {c_np * 1e3:.3f} -> {c_fu * 1e3:.3f} ms)")
    a_n, b_n = chain["fused"], chain["numpy"]  # both chains took the same number of steps
    print(f"  check: the two chains after the same steps are bit-identical: "
          f"{np.array_equal(a_n.x, b_n.x) and np.array_equal(a_n.v, b_n.v)}")
    if ne != 153_600:
        print("  (the reference is for the ~150k-tet beam: run without --quick/--cells)")
    print(f"  check: before vs after, max relative difference of v1: {dv:.1e}; old and new serial "
          f"kernels give the same bits: {same}")


if __name__ == "__main__":
    import sys

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # for bench_step.bent_state
    main()
