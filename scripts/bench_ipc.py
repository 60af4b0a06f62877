"""Cost of IPC contact: an implicit step with IPC over the same step without contact, and the
broad phase's time against the number of surface primitives (fitted exponent).

The scene: a soft cube resting on a stiff cube (one mesh, two pieces, the lower cube's bottom
fixed), gravity, the upper cube starting half of dhat above the lower one so that the barrier is
active from the first step. The same implicit Euler step is timed from the same state on the
model with ``contact=fe.IPCContact(...)`` and on the model without it, twice: the first step
(the impact: the gap closes from dhat / 2 to the barrier's equilibrium, ~1e-7 m with the
adaptive kappa, through CCD-bounded Newton steps) and a step in resting contact after a few
steps. Each row gives Newton iterations and the time in linearization, linear solves and line
search (CCD included), so the remaining cost can be read off.

    .venv/bin/python scripts/bench_ipc.py            # ~20k tets
    .venv/bin/python scripts/bench_ipc.py --quick    # 96 tets (the test suite's smoke test)
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import fem_elastic as fe


def two_cubes(n, size=0.2, gap=5e-4):
    """Two n x n x n cubes (6 n^3 tets each), the second above the first with a gap (m)."""
    m = fe.beam_mesh(length=size, width=size, height=size, cells=(n, n, n))
    p, t = m.p.T, m.t.T
    p2 = p + np.array([0.0, 0.0, size + gap])
    return fe.mesh_from_arrays(np.vstack([p, p2]), np.vstack([t, t + len(p)])), len(p)


def model_of(mesh, n_lower, contact):
    fixed = np.zeros(mesh.p.shape[1], dtype=bool)
    fixed[:n_lower] = mesh.p[2, :n_lower] < 1e-12  # the lower cube's bottom face
    return fe.Model(mesh, 1000.0, fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3)), fixed=fixed,
                    gravity=(0.0, 0.0, -9.81), contact=contact)


def time_step(model, state, dt, repeats):
    """Best wall time (s) of one implicit Euler step from ``state``, its stats and its end state."""
    ie = fe.ImplicitEuler(max_iter=200)
    best, stats, out = np.inf, None, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = ie.step(model, state, dt)
        elapsed = time.perf_counter() - t0
        if elapsed < best:  # the figures of the timed (fastest) repeat
            best, stats = elapsed, ie.last_stats
    return best, stats, out


def _breakdown(stats):
    s = stats.seconds
    return (f"linearize {s.get('linearize', 0.0):.2f} s, solve {s.get('solve', 0.0):.2f} s, "
            f"line search {s.get('line_search', 0.0):.2f} s")


def compare(label, with_ipc, without, state, dt, repeats):
    """Time the same step from ``state`` with and without contact; print and return the ratio."""
    time_step(with_ipc, state, dt, 1)  # warm-up (numba compilation, factorisation set-up)
    time_step(without, state, dt, 1)
    t_ipc, s_ipc, _ = time_step(with_ipc, state, dt, repeats)
    t_free, s_free, _ = time_step(without, state, dt, repeats)
    print(f"{label}: implicit Euler step, dt = {dt} s: with IPC {t_ipc * 1e3:.1f} ms "
          f"({s_ipc.newton_iterations} Newton iterations; {_breakdown(s_ipc)}), without contact "
          f"{t_free * 1e3:.1f} ms ({s_free.newton_iterations} Newton iterations; {_breakdown(s_free)})")
    print(f"{label}: ratio (IPC / no contact): {t_ipc / t_free:.2f}x  (goal <= 1.5x); per Newton "
          f"iteration {(t_ipc / s_ipc.newton_iterations) / (t_free / s_free.newton_iterations):.2f}x")
    return t_ipc / t_free


def broad_phase_scaling(sizes, repeats):
    import ipctk

    rows = []
    for n in sizes:
        mesh, _ = two_cubes(n)
        model = model_of(mesh, 0, None)
        s = model.collision_surface()
        V = np.asfortranarray(s.rest)
        cm = ipctk.CollisionMesh(V, np.asfortranarray(s.edges, dtype=np.int32),
                                 np.asfortranarray(s.faces, dtype=np.int32))
        best = np.inf
        for _ in range(repeats):
            bvh = ipctk.LBVH()
            t0 = time.perf_counter()
            c = ipctk.NormalCollisions()
            c.build(cm, V, 1e-3, broad_phase=bvh)
            best = min(best, time.perf_counter() - t0)
        rows.append((cm.num_vertices + cm.num_edges + cm.num_faces, best))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="small meshes (seconds)")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    n = 2 if args.quick else 12  # 2 * 6 n^3 tets: 96, or 20,736
    dt = 0.01
    mesh, n_lower = two_cubes(n)
    with_ipc = model_of(mesh, n_lower, fe.IPCContact(dhat=1e-3))
    without = model_of(mesh, n_lower, None)
    state = fe.State.rest(with_ipc)
    d = with_ipc.contact.diagnostics(with_ipc.X)
    print(f"mesh: {mesh.t.shape[1]} tets, {with_ipc.collision_surface().n_vertices} surface vertices, "
          f"{d['active_contacts']} active contact pairs at the start")
    # the first step: the upper cube falls from dhat / 2 into the barrier (the impact, the
    # costliest step: CCD-bounded Newton steps while the gap closes by three decades)
    ratio = compare("first contact", with_ipc, without, state, dt, args.repeats)
    print(f"ratio (IPC / no contact): {ratio:.2f}x  (goal <= 1.5x)")
    # a step in resting contact: after `settle` steps of IPC (the same step timed without contact
    # from the same state, where the elastic problem is the same)
    settle = 2 if args.quick else 5
    ie = fe.ImplicitEuler(max_iter=200)
    for _ in range(settle):
        state = ie.step(with_ipc, state, dt)
    d = with_ipc.contact.diagnostics(state.x)
    print(f"after {settle} steps: minimum distance {d['min_distance']:.3g} m, "
          f"{d['active_contacts']} active pairs, kappa {d['kappa']:.4g} N/m^3")
    compare("resting contact", with_ipc, without, state, dt, args.repeats)
    sizes = (2, 3, 4) if args.quick else (4, 6, 8, 12, 16, 24)
    rows = broad_phase_scaling(sizes, args.repeats)
    for prims, t in rows:
        print(f"broad + narrow phase (ipctk LBVH, collisions within dhat): {prims:8d} primitives "
              f"{t * 1e3:9.3f} ms")
    x, y = np.log([r[0] for r in rows]), np.log([r[1] for r in rows])
    slope = np.polyfit(x, y, 1)[0]
    print(f"fitted exponent of time against primitives: {slope:.2f} (n log n is a little above 1)")


if __name__ == "__main__":
    main()
