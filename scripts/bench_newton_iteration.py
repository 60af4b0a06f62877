"""Issue 19's row "one Newton iteration of an implicit step" against a hand-written reference.

On a 1 x 0.1 x 0.1 m Neo-Hookean beam (E = 10 MPa, nu = 0.45, 1000 kg/m^3) of 100 x 16 x 16
cells (153,600 P1 tets, 87,567 DOFs) held at its left end and released from rest under
gravity, ``fe.ImplicitEuler(linear_solver=fe.AMGSolver())`` takes ``--steps`` real steps of
dt = 1/60 s; each step's time per Newton iteration is its wall time over
``StepStats.newton_iterations`` (the step's start-up and final convergence test included).

The reference, in the same process, repeats each step's Newton solve by hand, from the same
first guess and for the same number of iterations, at the same tolerances (the inexact
forcing term ``eta = min(1e-2, 0.1 ||g|| / ||g_0||)`` of ``newton_minimize`` for CG, the same
Armijo backtracking), each iteration:

1. the fused P1 gradient and projected tangent kernels called directly
   (``FusedP1.gradient``, ``FusedP1.hessian(x, pattern, project=True)``), plus gravity and
   the lumped inertia ``m (x - y) / dt^2`` (``y = x_n + dt v_n``), ``m / dt^2`` on the diagonal;
2. the Dirichlet rows and columns removed (``H[free][:, free]``);
3. ``pyamg.smoothed_aggregation_solver`` with the six rigid-body modes as B (the settings of
   ``fe.AMGSolver``: Jacobi prolongation smoothing with the Gershgorin weight, SuperLU on the
   coarsest level), and scipy's CG preconditioned by it to ``eta``;
4. the line search's energy evaluations (fused energy kernel).

Two references: ``fresh`` builds a hierarchy at every iteration (the issue's reference,
"hand kernel + pyamg SA-RBM solve"), ``reused`` one per step, kept as CG's preconditioner
for the step's iterations (what the library does since issue 19.1, without its rebuild rule).
The row is ours / reference per step, median over the steps (goal <= 1.0).

Usage::

    .venv/bin/python scripts/bench_newton_iteration.py              # full size, 5 steps
    .venv/bin/python scripts/bench_newton_iteration.py --quick      # 30 x 5 x 5 cells, seconds
    .venv/bin/python scripts/bench_newton_iteration.py --profile    # + cProfile of our steps
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

DT = 1.0 / 60.0
ARMIJO = 1e-4  # newton_minimize's default sufficient-decrease constant


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs=3, default=None, metavar=("NX", "NY", "NZ"))
    parser.add_argument("--quick", action="store_true", help="30 x 5 x 5 cells")
    parser.add_argument("--steps", type=int, default=5, help="real steps (>= 5 for the figures)")
    parser.add_argument("--profile", action="store_true", help="cProfile our steps (top 25)")
    args = parser.parse_args(argv)
    cells = tuple(args.cells) if args.cells else ((30, 5, 5) if args.quick else (100, 16, 16))
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        run(cells, max(1, args.steps), args.profile)


class HandNewton:
    """The reference: one implicit Euler step's Newton iterations written out (module notes)."""

    def __init__(self, model, kern):
        self.model, self.kern = model, kern
        self.free = model.free
        self.f_ext = model.external_force()
        self.B = np.ascontiguousarray(model.rigid_body_modes[self.free])
        self.diag = model.space.pattern.diagonal_positions

    def energy(self, x, y, m_h2):
        d = x - y
        return self.kern.energy(x) - float(self.f_ext @ x) + 0.5 * float(d @ (m_h2 * d))

    def solve(self, state, x0, iterations, reuse):
        """``iterations`` Newton iterations from x0 plus the final gradient; (x, seconds by stage)."""
        import pyamg
        import scipy.sparse.linalg as sla

        model, kern, free = self.model, self.kern, self.free
        m_h2 = model.lumped_mass / (DT * DT)
        y = state.x + DT * state.v
        x = x0.copy()
        t = {"gradient + tangent": 0.0, "constrain": 0.0, "AMG setup": 0.0, "CG": 0.0,
             "line search": 0.0}
        cg_iters = 0
        e = self.energy(x, y, m_h2)
        g0 = None
        ml = None
        for it in range(iterations + 1):
            t0 = time.perf_counter()
            g = kern.gradient(x)
            g -= self.f_ext
            g += m_h2 * (x - y)
            g[~free] = 0.0
            gnorm = float(np.linalg.norm(g))
            if it == iterations:  # the converged iterate: its gradient only, as newton_minimize
                t["gradient + tangent"] += time.perf_counter() - t0
                break
            H = kern.hessian(x, model.space.pattern, project=True)
            H.data[self.diag] += m_h2
            t1 = time.perf_counter()
            A = H[free][:, free]
            b = -g[free]
            t2 = time.perf_counter()
            if ml is None or not reuse:
                ml = pyamg.smoothed_aggregation_solver(
                    A, B=self.B, symmetry="hermitian",
                    smooth=("jacobi", {"omega": 4.0 / 3.0, "weighting": "local"}),
                    coarse_solver="splu", max_coarse=500)
            t3 = time.perf_counter()
            g0 = gnorm if g0 is None else g0
            eta = max(min(1e-2, 0.1 * gnorm / g0), 1e-8)  # newton_minimize's, AMGSolver's floor
            n_cg = [0]

            def count(_):
                n_cg[0] += 1

            sol, info = sla.cg(A, b, rtol=eta, atol=0.0, M=ml.aspreconditioner(), maxiter=500,
                               callback=count)
            cg_iters += n_cg[0]
            t4 = time.perf_counter()
            dx = np.zeros_like(x)
            dx[free] = sol
            slope = float(g @ dx)
            alpha = 1.0
            for _ in range(30):
                x_try = x + alpha * dx
                e_try = self.energy(x_try, y, m_h2)
                if np.isfinite(e_try) and e_try <= e + ARMIJO * alpha * slope:
                    break
                alpha *= 0.5
            x, e = x_try, e_try
            t5 = time.perf_counter()
            for k, dt_ in zip(t, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4)):
                t[k] += dt_
        return x, t, cg_iters, gnorm


def run(cells, steps, profile):
    import numba
    import scipy

    import fem_elastic as fe
    from fem_elastic.discretization import fused

    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells)
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1.0e7, nu=0.45)),
                     fixed="left", gravity=(0.0, 0.0, -9.81))
    kern = fused.kernels_for(model.body_potential.material, model.space)
    if kern is None:
        raise SystemExit("numba is not importable (or FEM_ELASTIC_NUMBA=0): no fused kernels")
    ne = model.space.dx.shape[0]
    print(f"Newton iteration benchmark: {ne:,} P1 tets, {model.ndofs:,} DOFs, Neo-Hookean, "
          f"dt = 1/60 s, gravity; scipy {scipy.__version__}, numba {numba.__version__} "
          f"({numba.get_num_threads()} threads), BLAS 1 thread")
    ref = HandNewton(model, kern)
    ie = fe.ImplicitEuler(linear_solver=fe.AMGSolver())
    s = fe.State.rest(model)
    ie.step(model, s, DT)  # warm up: numba kernels, CSR pattern, block offsets
    ref.solve(s, s.x + DT * s.v, 1, reuse=False)
    rows = []
    prof = None
    if profile:
        import cProfile

        prof = cProfile.Profile()
    for k in range(steps):
        t0 = time.perf_counter()
        if prof is not None:
            prof.enable()
        s1 = ie.step(model, s, DT)
        if prof is not None:
            prof.disable()
        wall = time.perf_counter() - t0
        st = ie.last_stats
        n = st.newton_iterations
        # the reference starts where newton_minimize started: the lower of G(y) and G(x_n)
        y = s.x + DT * s.v
        m_h2 = model.lumped_mass / (DT * DT)
        x0 = y if ref.energy(y, y, m_h2) <= ref.energy(s.x, y, m_h2) else s.x.copy()
        row = {"step": k, "n": n, "ours": wall / n, "ours_cg": st.linear_iterations,
               "ours_setups": st.linear_setups, "ours_sec": dict(st.seconds)}
        for reuse in (False, True):
            t0 = time.perf_counter()
            x_ref, t_ref, cg, gnorm = ref.solve(s, x0, n, reuse)
            tag = "reused" if reuse else "fresh"
            row[tag] = (time.perf_counter() - t0) / n
            row[tag + "_cg"] = cg
            row[tag + "_sec"] = t_ref
        u = np.abs(s1.x - model.X).max()
        row["dx"] = float(np.abs(x_ref - s1.x).max() / max(u, 1e-300))
        rows.append(row)
        print(f"step {k}: {n} Newton iterations; s per iteration: ours {row['ours']:.3f} "
              f"(CG {st.linear_iterations}, setups {st.linear_setups}), reference fresh "
              f"{row['fresh']:.3f} (CG {row['fresh_cg']}), reused {row['reused']:.3f} "
              f"(CG {row['reused_cg']}); ours / fresh {row['ours'] / row['fresh']:.2f}, "
              f"ours / reused {row['ours'] / row['reused']:.2f}; |x_ref - x| / max|u| "
              f"{row['dx']:.1e}")
        s = s1
    r_fresh = [r["ours"] / r["fresh"] for r in rows]
    r_reused = [r["ours"] / r["reused"] for r in rows]
    print(f"\none Newton iteration of an implicit step, median over {steps} real steps:")
    print(f"  ours {statistics.median(r['ours'] for r in rows):.3f} s, reference with a fresh "
          f"hierarchy per iteration {statistics.median(r['fresh'] for r in rows):.3f} s, with one "
          f"per step {statistics.median(r['reused'] for r in rows):.3f} s")
    print(f"  ours / reference (fresh hierarchy, the issue's): {statistics.median(r_fresh):.2f} x "
          f"(first step {r_fresh[0]:.2f} x, range {min(r_fresh):.2f}-{max(r_fresh):.2f}); goal <= 1.0")
    print(f"  ours / reference (one hierarchy per step):       {statistics.median(r_reused):.2f} x "
          f"(first step {r_reused[0]:.2f} x, range {min(r_reused):.2f}-{max(r_reused):.2f})")
    print("  seconds per iteration by stage (median over the steps):")
    for key in ("linearize", "solve", "line_search"):
        print(f"    ours {key:<28} {statistics.median(r['ours_sec'].get(key, 0.0) / r['n'] for r in rows):.3f}")
    for key in rows[0]["fresh_sec"]:
        print(f"    reference fresh {key:<17} {statistics.median(r['fresh_sec'][key] / r['n'] for r in rows):.3f}"
              f"   reused {statistics.median(r['reused_sec'][key] / r['n'] for r in rows):.3f}")
    print(f"  check: the reference's end point against ours, max |dx| / max |u|: "
          f"{max(r['dx'] for r in rows):.1e} (both solve to Newton's tolerance, on different "
          "tangents where ours switches to the exact one)")
    if prof is not None:
        import pstats

        print()
        pstats.Stats(prof).sort_stats("cumulative").print_stats(25)


if __name__ == "__main__":
    main()
