"""How fast XPBD approaches implicit Euler on the same energy: the tables behind tests/test_xpbd.py.

1. The cantilever of the issue: 1 x 0.1 x 0.1 m, 10 x 2 x 2 cells, 1000 kg/m^3, gravity, E = 10 MPa
   (small strain), ten steps of 0.01 s from rest. The relative distance of XPBD's displacement
   to implicit Euler's (``fe.ImplicitEuler(rtol=1e-12)``) on the same energy, against the
   iterations per step, for
   - ``constraints="edge_volume"`` at nu = 1/4: springs only, the energy of ``fe.MassSpring(E)``,
     which implicit Euler integrates on the same mesh (fitted log-log slope over 50-400);
   - ``constraints="neohookean"`` (Macklin and Mueller 2021) at nu = 0.3, against implicit
     Euler on ``fe.ConstraintNeoHookean``, its energy.
2. The Neo-Hookean constraints against the step size: a 0.5 m cantilever (5 x 1 x 1 cells,
   E = 0.1 MPa) released under gravity for 0.1 s, XPBD converged (50 iterations) against
   implicit Euler at the same dt, with ``h omega_max`` (fitted slope in dt), and XPBD with
   ``substeps`` at dt = 0.01 s against implicit Euler at the substep.
3. Static sag: XPBD run to rest (mass-proportional damping) against ``fe.solve_static`` of the
   same energy: the springs against the iterations, the Neo-Hookean constraints against dt.

Why the two forms behave so differently is in ``fem_elastic/dynamics/position_based/xpbd.py``:
the Neo-Hookean constraints' shear stiffness is the geometric stiffness of their rest
multipliers, which XPBD's update leaves out.

Usage::

    python scripts/xpbd_convergence.py            # about a minute
    python scripts/xpbd_convergence.py --quick    # fewer rows, seconds
"""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np

G = (0.0, 0.0, -9.81)


def _run(model, integrator, dt, steps):
    import fem_elastic as fe

    s = fe.State.rest(model)
    t0 = time.perf_counter()
    for _ in range(steps):
        s = integrator.step(model, s, dt)
    return s, (time.perf_counter() - t0) / steps


def _distance(model, s, ref, ref_model):
    u, u_ref = s.x - model.X, ref.x - ref_model.X
    if not np.all(np.isfinite(u)):
        return np.inf
    return float(np.linalg.norm(u - u_ref) / np.linalg.norm(u_ref))


def _slope(x, y):
    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = np.isfinite(y) & (y > 0)
    return float(np.polyfit(np.log(x[ok]), np.log(y[ok]), 1)[0]) if ok.sum() >= 2 else float("nan")


def table_iterations(quick):
    import fem_elastic as fe

    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells=(10, 2, 2))
    kw = dict(density=1000.0, fixed="left", gravity=G)
    E, dt, steps = 1e7, 0.01, 10
    springs = fe.Model(mesh, body=fe.MassSpring(E=E), **kw)
    ev_model = fe.Model(mesh, body=fe.ElasticBody(fe.LinearElastic(E=E, nu=0.25)), **kw)
    nh_model = fe.Model(mesh, body=fe.ElasticBody(fe.ConstraintNeoHookean(E=E, nu=0.3)), **kw)
    ref_s, t_ie_s = _run(springs, fe.ImplicitEuler(rtol=1e-12), dt, steps)
    ref_n, t_ie_n = _run(nh_model, fe.ImplicitEuler(rtol=1e-12), dt, steps)
    hw = dt * 2.0 / fe.critical_time_step(nh_model, fe.SymplecticEuler())
    print(f"1. cantilever 1 x 0.1 x 0.1 m, 10 x 2 x 2 cells, E = 10 MPa, ten steps of 0.01 s "
          f"(h omega_max = {hw:.0f}); tip sag by implicit Euler: springs "
          f"{(ref_s.x - springs.X)[2::3].min() * 1e3:.1f} mm, Neo-Hookean "
          f"{(ref_n.x - nh_model.X)[2::3].min() * 1e3:.1f} mm")
    print(f"   implicit Euler: {t_ie_s * 1e3:.1f} ms/step (springs), {t_ie_n * 1e3:.1f} ms/step (Neo-Hookean)")
    print("   iterations | edge_volume (nu = 1/4) vs IE on fe.MassSpring | ms/step | "
          "neohookean vs IE on fe.ConstraintNeoHookean | ms/step")
    its = [10, 50, 200, 800] if quick else [10, 20, 50, 100, 200, 400, 800, 1600, 3200]
    ev, nh = [], []
    for n in its:
        s, t_ev = _run(ev_model, fe.XPBD(iterations=n, constraints="edge_volume"), dt, steps)
        ev.append(_distance(ev_model, s, ref_s, springs))
        s, t_nh = _run(nh_model, fe.XPBD(iterations=n), dt, steps)
        nh.append(_distance(nh_model, s, ref_n, nh_model))
        print(f"   {n:10d} | {ev[-1]:46.2e} | {t_ev * 1e3:7.2f} | {nh[-1]:43.2e} | {t_nh * 1e3:7.2f}")
    sel = [i for i, n in enumerate(its) if 50 <= n <= 400]
    print(f"   fitted slope of the edge_volume distance over 50-400 iterations: "
          f"{_slope([its[i] for i in sel], [ev[i] for i in sel]):.2f}")


def table_step_size(quick):
    import fem_elastic as fe

    mesh = fe.beam_mesh(0.5, 0.1, 0.1, cells=(5, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.ConstraintNeoHookean(E=1e5, nu=0.3)),
                     fixed="left", gravity=G)
    omega = 2.0 / fe.critical_time_step(model, fe.SymplecticEuler())
    print(f"\n2. Neo-Hookean constraints against the step: cantilever 0.5 x 0.1 x 0.1 m, 5 x 1 x 1 cells, "
          f"E = 0.1 MPa, 0.1 s from rest; omega_max = {omega:.0f} rad/s")
    print("   dt (s)    | h omega_max | XPBD (50 iterations) vs IE at dt")
    dts = [0.01, 0.005, 0.0025] if quick else [0.02, 0.01, 0.005, 0.0025, 0.00125, 0.000625]
    dist = []
    for dt in dts:
        steps = int(round(0.1 / dt))
        ref, _ = _run(model, fe.ImplicitEuler(rtol=1e-12), dt, steps)
        s, _ = _run(model, fe.XPBD(iterations=50), dt, steps)
        dist.append(_distance(model, s, ref, model))
        print(f"   {dt:9.6f} | {dt * omega:11.2f} | {dist[-1]:.2e}")
    small = [i for i, dt in enumerate(dts) if dt * omega <= 2.0]
    print(f"   fitted slope in dt where h omega_max <= 2: "
          f"{_slope([dts[i] for i in small], [dist[i] for i in small]):.2f}")
    print("   substeps n at dt = 0.01 s (10 steps, 20 iterations each) vs IE at dt / n (10 n steps):")
    for n in ([1, 4] if quick else [1, 2, 4, 8, 16]):
        ref, _ = _run(model, fe.ImplicitEuler(rtol=1e-12), 0.01 / n, 10 * n)
        s, _ = _run(model, fe.XPBD(iterations=20, substeps=n), 0.01, 10)
        print(f"   substeps {n:3d} (h omega_max {0.01 / n * omega:5.2f}): {_distance(model, s, ref, model):.2e}")


def table_static(quick):
    import fem_elastic as fe

    mesh = fe.beam_mesh(0.5, 0.1, 0.1, cells=(5, 1, 1))
    kw = dict(density=1000.0, fixed="left", gravity=G, damping=fe.Rayleigh(30.0, 0.0))
    springs = fe.Model(mesh, body=fe.MassSpring(E=1e6), **kw)
    ev_model = fe.Model(mesh, body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.25)), **kw)
    nh_model = fe.Model(mesh, body=fe.ElasticBody(fe.ConstraintNeoHookean(E=1e6, nu=0.3)), **kw)
    sag_s = -fe.solve_static(springs).displacement[:, 2].min()
    sag_n = -fe.solve_static(nh_model).displacement[:, 2].min()
    print(f"\n3. static sag, cantilever 0.5 x 0.1 x 0.1 m, 5 x 1 x 1 cells, E = 1 MPa, run to rest with "
          f"fe.Rayleigh(30, 0): fe.solve_static gives {sag_s * 1e3:.2f} mm (springs), "
          f"{sag_n * 1e3:.2f} mm (Neo-Hookean)")

    def steady(model, integ, dt, T):
        s, _ = _run(model, integ, dt, int(round(T / dt)))
        return -(s.x - model.X)[2::3].min(), float(np.abs(s.v).max())

    for n in ([10, 50] if quick else [10, 20, 50, 200]):
        for dt in (0.01, 0.02):
            sag, vmax = steady(ev_model, fe.XPBD(iterations=n, constraints="edge_volume"), dt, 2.0)
            print(f"   edge_volume, {n:4d} iterations, dt = {dt:5.3f} s: sag {sag * 1e3:8.3f} mm, "
                  f"{sag / sag_s - 1.0:+.2e} (|v| max {vmax:.0e} m/s)")
    omega = 2.0 / fe.critical_time_step(nh_model, fe.SymplecticEuler())
    for dt in ([0.002, 0.001] if quick else [0.004, 0.002, 0.001, 0.0005]):
        sag, vmax = steady(nh_model, fe.XPBD(iterations=10), dt, 1.2)
        print(f"   neohookean, 10 iterations, dt = {dt:6.4f} s (h omega_max {dt * omega:4.2f}): sag "
              f"{sag * 1e3:8.3f} mm, {sag / sag_n - 1.0:+.2e} (|v| max {vmax:.0e} m/s)")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer rows (seconds)")
    args = parser.parse_args(argv)
    logging.getLogger("fem_elastic").setLevel(logging.ERROR)  # the step-size warnings are the point
    table_iterations(args.quick)
    table_step_size(args.quick)
    table_static(args.quick)


if __name__ == "__main__":
    main()
