"""Benchmark: Neo-Hookean tangent assembly and one Newton iteration, against scikit-fem's forms.

Times, in one run and on one mesh (default: a 1 x 0.1 x 0.1 m beam of 100 x 16 x 16 cells,
153,600 P1 tets, 87,567 DOFs):

1. residual + tangent with this project's kernel (``ElasticPotential.linearize``), exact and
   PSD-projected, with a per-stage breakdown (F, P, material C, projection, element
   matrices, scatter into the fixed CSR pattern);
2. the same residual + tangent with scikit-fem's generic form assembly, written as in its
   hyperelastic example (``docs/examples/ex43.py``, see
   :func:`fem_elastic.discretization.skfem_forms.neohookean_forms_ex43`);
3. one Newton iteration's linear solve on the projected matrix with the supports applied:
   sparse LU (``fe.DirectSolver``, once: 10-25 s and ~3 GB at full size) and AMG-CG
   (``fe.AMGSolver`` with the rigid-body modes), and the share of assembly in a full
   Newton iteration (linearize + solve + one line-search energy).

The state is a cantilever bending shape (Euler-Bernoulli kinematics, tip deflection 10 % of
the length, axial strains up to ~1.5 %, all det F > 0): half of the beam is in compression,
where Neo-Hookean's tangent is indefinite, so the projection has real work.

BLAS/OpenMP threads are pinned to 1 with threadpoolctl (imported here, not a dependency of
the library) so the ratios compare single-threaded code. Prints medians over repeats.

Usage::

    python scripts/bench_assembly.py             # full size, ~1-2 min (30 s: the LU solve)
    python scripts/bench_assembly.py --quick     # 20 x 4 x 4 cells, seconds
    python scripts/bench_assembly.py --cells 50 8 8 --repeats 3
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import numpy as np


def timed(fn, repeats):
    """(median seconds, all times, last result) of ``repeats`` calls."""
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), times, out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs=3, default=None, metavar=("NX", "NY", "NZ"))
    parser.add_argument("--quick", action="store_true", help="a 20 x 4 x 4 beam (seconds)")
    parser.add_argument("--repeats", type=int, default=5, help="repeats of the fast timings")
    parser.add_argument("--skfem-repeats", type=int, default=1,
                        help="repeats of the slow scikit-fem form assembly")
    parser.add_argument("--no-direct", action="store_true", help="skip the sparse LU solve")
    args = parser.parse_args(argv)
    cells = tuple(args.cells) if args.cells else ((20, 4, 4) if args.quick else (100, 16, 16))

    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        run(cells, args.repeats, args.skfem_repeats, not args.no_direct)


def run(cells, repeats, skfem_repeats, direct):
    import scipy

    import skfem
    import fem_elastic as fe
    from fem_elastic.materials.isotropic import is_psd_3x3
    from fem_elastic.materials.svd import signed_svd
    from fem_elastic.solvers.newton import constrain
    from fem_elastic.discretization.skfem_forms import neohookean_forms_ex43

    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells)
    material = fe.NeoHookean(E=1.0e7, nu=0.45)
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(material, order=1),
                     fixed="left", gravity=(0.0, 0.0, -9.81))
    space, pot, free = model.space, model.body_potential, model.free
    ne, nq = space.dx.shape
    print(f"fem_elastic benchmark: numpy {np.__version__}, scipy {scipy.__version__}, "
          f"scikit-fem {skfem.__version__}, python {platform.python_version()}, BLAS threads 1")
    print(f"mesh: beam 1.0 x 0.1 x 0.1 m, cells {cells}, {ne:,} P1 tets x {nq} point(s), "
          f"{model.ndofs:,} DOFs; NeoHookean E = 1e7 Pa, nu = 0.45")

    # the state: an Euler-Bernoulli cantilever shape (tip deflection 10 % of the length),
    # smooth and deterministic, with the beam's upper half stretched and lower half compressed
    L, zc, w_tip = 1.0, 0.05, 0.1
    Xp = model.X.reshape(-1, 3)
    s_ = Xp[:, 0] / L
    w = w_tip * s_**2 * (3.0 - s_) / 2.0  # deflection along -z
    slope = w_tip * 3.0 * s_ * (2.0 - s_) / (2.0 * L)  # dw/dx
    u = np.zeros_like(Xp)
    u[:, 2] = -w
    u[:, 0] = (Xp[:, 2] - zc) * slope  # plane sections stay normal to the axis
    x = model.X + u.ravel()
    near_null = space.rigid_body_modes() * free[:, None]
    F = pot.F(x)
    J = np.linalg.det(np.moveaxis(F, (0, 1), (-2, -1)))
    if not J.min() > 0:
        raise SystemExit(f"the benchmark state has an inverted element (min J = {J.min()})")
    print(f"state: cantilever bending, tip deflection {w_tip:.2f} m, "
          f"det F in [{J.min():.4f}, {J.max():.4f}]")

    rows = []  # (label, median s, repeats)

    def record(label, fn, n):
        med, _, out = timed(fn, n)
        rows.append((label, med, n))
        return med, out

    # 1. ours --------------------------------------------------------------------------------
    pot.linearize(x, project=True)  # warm up: builds the CSR pattern
    t_ours, (g, K) = record("ours: residual + tangent (exact)", lambda: pot.linearize(x, False),
                            repeats)
    t_ours_psd, (_, K_psd) = record("ours: residual + tangent (projected)",
                                    lambda: pot.linearize(x, True), repeats)

    # per-stage breakdown of the projected linearize
    m = material
    stages = []
    t, _, Fx = timed(lambda: pot.F(x), repeats)
    stages.append(("F = I + grad u (gather + einsum)", t))
    t, _, P = timed(lambda: m.dpsi_dF(Fx), repeats)
    stages.append(("P = dpsi_dF(F)", t))
    t, _, _ = timed(lambda: pot._force(P), repeats)
    stages.append(("residual: contraction + bincount", t))
    t_C, _, C = timed(lambda: m.d2psi_dF2(Fx), repeats)
    stages.append(("C = d2psi_dF2(F) (exact)", t_C))
    t_Cp, _, Cp = timed(lambda: m.d2psi_dF2_psd(Fx), repeats)
    stages.append(("C_psd = d2psi_dF2_psd(F)", t_Cp))
    t, _, Ke = timed(lambda: pot.element_stiffness(Cp), repeats)
    stages.append(("element_stiffness(C) (12 x 12 x ne)", t))
    t, _, _ = timed(lambda: space.pattern.assemble(Ke), repeats)
    stages.append(("scatter: pattern.assemble (bincount)", t))
    _, sv, _ = signed_svd(Fx.reshape(3, 3, -1))
    H, lt, lf = material.singular_value_hessian(sv)
    indefinite = float(((lt < 0).any(axis=0) | (lf < 0).any(axis=0) | ~is_psd_3x3(H)).mean())

    # 2. scikit-fem's forms (ex43 style) ---------------------------------------------------------
    residual_ex43, tangent_ex43 = neohookean_forms_ex43(material.mu, material.lam)
    basis = space.basis

    def skfem_linearize():
        w = basis.interpolate(x - model.X)
        return residual_ex43.assemble(basis, displacement=w), tangent_ex43.assemble(
            basis, displacement=w)

    t_sk_res, _ = record("scikit-fem ex43: residual (LinearForm)",
                         lambda: residual_ex43.assemble(basis,
                                                        displacement=basis.interpolate(x - model.X)),
                         skfem_repeats)
    t_sk, (g_sk, K_sk) = record("scikit-fem ex43: residual + tangent", skfem_linearize,
                                skfem_repeats)
    err_g = np.abs(g_sk - g).max() / np.abs(g).max()
    err_K = abs(K_sk - K).max() / abs(K).max()

    # 3. one Newton iteration --------------------------------------------------------------------
    rhs = -np.where(free, g - model.external_force(), 0.0)

    def constrained():
        return constrain(K_psd.copy(), free, space.pattern)

    t_con, A = record("constrain (fixed 'left')", constrained, repeats)
    # fe.AMGSolver's setup is deterministic (Gershgorin-weighted smoothing); the CG
    # iterations of every run are reported to show it
    amg_runs = []

    def amg_solve(solver=fe.AMGSolver()):
        out = solver.solve(A, rhs, near_null)
        amg_runs.append(out)
        return out

    t_amg, sol_amg = record("AMG-CG solve (fe.AMGSolver, rigid-body modes)", amg_solve,
                            max(3, repeats // 2))
    amg_iters = [r.iterations for r in amg_runs]
    amg_worst = max(r.residual for r in amg_runs)
    t_direct = None
    if direct:
        t_direct, sol_direct = record("direct solve (SuperLU, MMD_AT_PLUS_A)",
                                      lambda: fe.DirectSolver().solve(A, rhs), 1)
    t_energy, _ = record("line search: one energy evaluation", lambda: model.energy(x), repeats)

    # report ---------------------------------------------------------------------------------------
    print()
    print(f"{'timing (median)':<48} {'seconds':>9} {'runs':>5}")
    print("-" * 64)
    for label, med, n in rows:
        print(f"{label:<48} {med:9.3f} {n:5d}")
    print()
    print("breakdown of our projected linearize (each stage timed alone):")
    for label, t in stages:
        print(f"  {label:<46} {t:9.3f}")
    print(f"  {'(projection alone: C_psd - C)':<46} {t_Cp - t_C:9.3f}")
    print(f"  quadrature points with an indefinite C: {100 * indefinite:.0f} %")
    print()
    newton_amg = t_ours_psd + t_con + t_amg + t_energy
    newton_direct = t_ours_psd + t_con + t_direct + t_energy if t_direct else None
    print("ratios:")
    print(f"  scikit-fem forms / ours (exact tangent + residual): {t_sk / t_ours:7.1f} x   "
          f"(target >= 10 x)")
    print(f"  projection overhead (projected / exact - 1):         {t_ours_psd / t_ours - 1:+7.0%}"
          f"   (target <= +50 %)")
    print(f"  Newton iteration with AMG: {newton_amg:.2f} s; assembly share "
          f"{t_ours_psd / newton_amg:5.1%}   (target < 30 %)")
    print(f"      AMG: CG iterations per run {amg_iters}, worst relative residual "
          f"{amg_worst:.1e} (asked 1e-8)")
    if newton_direct:
        print(f"  Newton iteration with LU:  {newton_direct:.2f} s; assembly share "
              f"{t_ours_psd / newton_direct:5.1%}")
        print(f"  direct / AMG solve: {t_direct / t_amg:5.1f} x; "
              f"|dx_direct - dx_amg| / |dx| = "
              f"{np.linalg.norm(sol_direct.x - sol_amg.x) / np.linalg.norm(sol_direct.x):.1e}")
    print(f"  check: scikit-fem vs ours, max rel. difference: residual {err_g:.1e}, "
          f"tangent {err_K:.1e}")


if __name__ == "__main__":
    main()
