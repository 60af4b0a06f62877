"""Cost of IPC contact: an implicit step with IPC over the same step without contact, and the
broad phase's time against the number of surface primitives (fitted exponent).

The scene (default): the two-body drop of ``scenes/two_bodies.toml`` (a soft block, the
"ball", thrown down onto a stiff block that rests on the barrier ground), refined to ``--cells``
n: the ball n x n x n cells, the block 2n x 2n x n (30 n^3 tets; 9 gives 21,870). Every step of
the drop with IPC is timed, and from the same state the same implicit Euler step of the same
scene without its ``[contact]`` table (no IPC; the ground, a fixed obstacle with its own barrier,
stays in both). The two alternate in one process, one pair per step, so the machine's load
weighs on both alike; each keeps its own CHOLMOD analysis and factor, as a run of it alone would. The table gives each step's Newton iterations and times; the summary
splits the steps into those where no IPC pair is within dhat (the contact's fixed cost: broad
phase, CCD, an empty barrier) and those with IPC pairs, and gives the median, the worst step and
the whole drop. Both solves use ``max_iter=200``: the impact of a 21,870-tet drop takes 18
Newton iterations with the scene's barrier stiffness (kappa = 1e7 N/m^3), and 67 with IPC's
adaptive one (``--kappa auto``), more than ImplicitEuler's default 30.

``--cubes``: two aligned cubes, the upper one starting half of dhat above the lower one, timed
on their first step (the barrier closes the gap by three decades) and on a step in resting
contact, each ``--repeats`` times (medians). Their grids match face to face, so every edge-edge
pair is parallel: the hardest case for the barrier's Newton.

    .venv/bin/python scripts/bench_ipc.py                     # the drop, 21,870 tets, 0.6 s
    .venv/bin/python scripts/bench_ipc.py --quick             # 240 tets, 0.2 s (the suite's smoke test)
    .venv/bin/python scripts/bench_ipc.py --cubes --repeats 3 # the aligned cubes, 20,736 tets
    .venv/bin/python scripts/bench_ipc.py --cubes --trace     # their Newton iterations, logged
    .venv/bin/python scripts/bench_ipc.py --no-saddle-extension  # Newton as before the doubling
    .venv/bin/python scripts/bench_ipc.py --cubes --projection abs   # IPC's other pair projection
    .venv/bin/python scripts/bench_ipc.py --velocity-tol 1e-3  # both sides with IPC's step rule
    .venv/bin/python scripts/bench_ipc.py --kappa auto        # the drop with IPC's adaptive kappa

``--kappa K`` (N/m^3, or ``auto``) replaces the scene's barrier stiffness: it sets the gap the
ball rests at (0.7 mm at the scene's 1e7, 0.011 mm with ``auto``) and with it the Newton
iterations of every contact step (docs/guide/contact.md, "Choosing kappa").

``--velocity-tol v`` (m/s) gives both sides ``fe.ImplicitEuler(velocity_tol=v)``: Newton also
stops after a whole step on the exact tangent that moves no DOF by more than v * dt (IPC's
convergence rule, besides the force tolerance).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

import fem_elastic as fe

SCENE = Path(__file__).resolve().parent.parent / "scenes" / "two_bodies.toml"


def two_cubes(n, size=0.2, gap=5e-4):
    """Two n x n x n cubes (6 n^3 tets each), the second above the first with a gap (m)."""
    m = fe.beam_mesh(length=size, width=size, height=size, cells=(n, n, n))
    p, t = m.p.T, m.t.T
    p2 = p + np.array([0.0, 0.0, size + gap])
    return fe.mesh_from_arrays(np.vstack([p, p2]), np.vstack([t, t + len(p)])), len(p)


def model_of(mesh, n_lower, contact):
    """Neo-Hookean cubes (E = 1 MPa, rho = 1000 kg/m^3) under gravity, the lower one's bottom fixed."""
    fixed = np.zeros(mesh.p.shape[1], dtype=bool)
    fixed[:n_lower] = mesh.p[2, :n_lower] < 1e-12  # the lower cube's bottom face
    return fe.Model(mesh, 1000.0, fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3)), fixed=fixed,
                    gravity=(0.0, 0.0, -9.81), contact=contact)


#: each model's own CHOLMOD of fe.AutoSolver: id(model) -> (model, solver)
_OWN_FACTORS: dict = {}


def _own_factors(model):
    """Make ``model``'s next solves use its own kept analysis and factor, as in a run of it alone.

    fe.AutoSolver keeps one CHOLMOD analysis and factor per thread (and SuperLU one factor per
    process). The two models alternate here in one thread, so shared they would mislead: in
    flight the IPC step would find the factor of the free step's identical first matrix, and in
    contact the free step would analyse its pattern again after every IPC step. Each model gets
    its own (the private hooks of a benchmark).
    """
    from fem_elastic.solvers import cholmod, linear_solvers

    if cholmod.have_cholmod():
        own = _OWN_FACTORS.get(id(model))
        if own is None:
            solver = fe.CholmodSolver()
            solver._shared = True  # kept whatever its size, as fe.AutoSolver's own
            own = _OWN_FACTORS[id(model)] = (model, solver)  # the model kept: its id stays unique
        cholmod._LOCAL.solver = own[1]
    linear_solvers._FACTORS.key = linear_solvers._FACTORS.lu = None


def time_step(model, state, dt, solver=None):
    """Wall time (s) of one implicit Euler step from ``state``, its stats and its end state."""
    _own_factors(model)
    ie = implicit_euler(solver)
    t0 = time.perf_counter()
    out = ie.step(model, state, dt)
    return time.perf_counter() - t0, ie.last_stats, out


#: Newton iterations allowed per step (both models): an impact takes more than the default 30
MAX_ITER = 200
#: Velocity tolerance (m/s) of both models' Newton (``--velocity-tol``; 0: the force rule alone)
VELOCITY_TOL = 0.0
#: The drop's IPC barrier stiffness (``--kappa``): None keeps the scene's, else N/m^3 or "auto"
KAPPA = None


def implicit_euler(solver=None):
    """The integrator both sides use: ``max_iter=MAX_ITER``, ``velocity_tol=VELOCITY_TOL``."""
    return fe.ImplicitEuler(max_iter=MAX_ITER, linear_solver=solver, velocity_tol=VELOCITY_TOL)


def drop_runs(n):
    """The drop of ``scenes/two_bodies.toml`` at ``n`` cells per ball edge, with and without IPC.

    Returns the two :class:`~fem_elastic.app.scene.BuiltRun` s: the scene as written but for its
    meshes (ball n^3 cells, block 2n x 2n x n: the scene's own element size at n = 2), and the
    same without its ``[contact]`` table.
    """
    from fem_elastic.app.scene import load_scene

    runs = []
    for ipc in (True, False):
        scene = load_scene(SCENE)
        ball, block = scene.spec["bodies"]
        ball["mesh"]["cells"], block["mesh"]["cells"] = [n, n, n], [2 * n, 2 * n, n]
        if not ipc:
            scene.spec["contact"] = None
        elif KAPPA is not None:
            scene.spec["contact"]["kappa"] = KAPPA
        runs.append(scene.build()[0])
    return runs


def drop(n, steps, solver=None):
    """Time every step of the drop with IPC against the same step without; print the table and
    the summary; return the rows ``(step, t_ipc, its_ipc, t_free, its_free, pairs_start,
    pairs_end, min_distance_end)``."""
    with_ipc, without = drop_runs(n)
    m, mf, dt, state = with_ipc.model, without.model, with_ipc.dt, with_ipc.state
    steps = steps or with_ipc.steps
    print(f"two-body drop ({SCENE.name}): {m.mesh.t.shape[1]} tets, {m.ndofs} DOFs, "
          f"{m.collision_surface().n_vertices} surface vertices, dt = {dt} s, {steps} steps; "
          f"ImplicitEuler(max_iter={MAX_ITER}, velocity_tol={VELOCITY_TOL:g}), solver "
          f"{'auto' if solver is None else solver!r}; IPC dhat = {m.contact.spec.dhat:g} m, kappa = "
          f"{m.contact.spec.kappa if m.contact.spec.kappa == 'auto' else format(m.contact.spec.kappa, 'g')}")
    # warm-up (numba, ipctk, patterns): the free model, and a throwaway copy of the IPC one (the
    # timed model's contact state, kappa, stays as the scene starts it)
    time_step(mf, state, dt, solver)
    time_step(drop_runs(n)[0].model, state, dt, solver)
    rows = []
    pairs = m.contact.diagnostics(state.x)["active_contacts"]
    print(" step    t (s)  pairs  min dist (m) | IPC ms  its | no IPC ms  its |  ratio  per it")
    for k in range(steps):
        tf, sf, _ = time_step(mf, state, dt, solver)
        ti, si, new = time_step(m, state, dt, solver)
        d = m.contact.diagnostics(new.x)
        row = (k, ti, si.newton_iterations, tf, sf.newton_iterations, pairs, d["active_contacts"],
               d["min_distance"])
        rows.append(row)
        print(f"{k:5d} {new.t:8.3f} {d['active_contacts']:6d} {d['min_distance']:13.3e} | "
              f"{ti * 1e3:7.0f} {si.newton_iterations:4d} | {tf * 1e3:9.0f} {sf.newton_iterations:4d} | "
              f"{ti / tf:6.2f}x {_per_iteration(row):5.2f}x", flush=True)
        state, pairs = new, d["active_contacts"]
    summarize_drop(rows)
    return rows


def _per_iteration(row):
    """A drop row's ratio of the time per Newton iteration, with IPC over without."""
    _, t_ipc, its_ipc, t_free, its_free = row[:5]
    return (t_ipc / max(its_ipc, 1)) / (t_free / max(its_free, 1))


def summarize_drop(rows):
    """Print the ratios of the drop's steps by kind, the worst step and the whole drop."""
    r = np.array([row[1] / row[3] for row in rows])
    per_it = np.array([_per_iteration(row) for row in rows])
    touching = np.array([row[5] > 0 or row[6] > 0 for row in rows])
    for label, sel in (("steps with no IPC pair within dhat", ~touching),
                       ("steps with IPC pairs", touching)):
        if sel.any():
            q1, med, q3 = np.percentile(r[sel], [25, 50, 75])
            print(f"{label} ({int(sel.sum())}): ratio median {med:.2f}x (quartiles {q1:.2f}-{q3:.2f}x, "
                  f"range {r[sel].min():.2f}-{r[sel].max():.2f}x); per Newton iteration median "
                  f"{np.median(per_it[sel]):.2f}x")
    w = int(np.argmax(r))
    print(f"worst step: {rows[w][0]}, {r[w]:.2f}x: {rows[w][2]} Newton iterations "
          f"against {rows[w][4]}")
    t_ipc, t_free = sum(row[1] for row in rows), sum(row[3] for row in rows)
    print(f"whole drop: {t_ipc:.1f} s with IPC, {t_free:.1f} s without: ratio (IPC / no contact) "
          f"{t_ipc / t_free:.2f}x; all steps' ratio median {np.median(r):.2f}x  (goal <= 1.5x)")


def _breakdown(stats):
    s = stats.seconds
    return (f"{stats.newton_iterations} Newton iterations, {stats.linear_solves} linear solves, "
            f"{stats.linear_setups} factorisations/AMG set-ups; linearize "
            f"{s.get('linearize', 0.0):.2f} s, solve {s.get('solve', 0.0):.2f} s, line search "
            f"{s.get('line_search', 0.0):.2f} s")


def compare(label, with_ipc, without, state, dt, repeats, solver=None):
    """Time the same step from ``state`` with and without contact; print and return the ratio.

    The two steps alternate ``repeats`` times (after one warm-up each: numba compilation);
    the medians are compared, and the ratio of each pair is printed too."""
    time_step(with_ipc, state, dt, solver)
    time_step(without, state, dt, solver)
    t_ipc, t_free, pairs, its = [], [], [], []
    for _ in range(repeats):
        a, s_ipc, _ = time_step(with_ipc, state, dt, solver)
        b, s_free, _ = time_step(without, state, dt, solver)
        t_ipc.append(a)
        t_free.append(b)
        pairs.append(a / b)
        # ipctk sums the pair Hessians in parallel, in a varying order: near a saddle the
        # Newton path, and so its iteration count, can differ between repeats of one step
        its.append(s_ipc.newton_iterations)
    m_ipc, m_free = float(np.median(t_ipc)), float(np.median(t_free))
    print(f"{label}: implicit Euler step, dt = {dt} s, median of {repeats}: with IPC "
          f"{m_ipc * 1e3:.1f} ms (Newton iterations of the repeats {its}; the last: "
          f"{_breakdown(s_ipc)}); without contact {m_free * 1e3:.1f} ms "
          f"({_breakdown(s_free)})")
    per_it = (m_ipc / float(np.median(its))) / (m_free / s_free.newton_iterations)
    print(f"{label}: ratio (IPC / no contact): {m_ipc / m_free:.2f}x  (goal <= 1.5x; pairs "
          f"{min(pairs):.2f}-{max(pairs):.2f}x); per Newton iteration {per_it:.2f}x")
    return m_ipc / m_free


def trace_step(label, model, state, dt, solver=None):
    """One step with Newton's debug log and the CCD bound of every Newton step.

    Each CCD line gives the collision-free fraction of the step, and at the step's start the
    minimum distance, the active pairs and kappa; each Newton line ||g|| on the free DOFs (N)
    before the step, the step fraction taken and the incremental potential after it."""
    import logging

    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    newton_log = logging.getLogger("fem_elastic.solvers.newton")
    newton_log.setLevel(logging.DEBUG)
    contact = model.contact
    bound = contact.max_step

    def max_step(x, dx):
        a = bound(x, dx)
        d = contact.diagnostics(x)
        print(f"  CCD: collision-free fraction {a:.3f} from minimum distance "
              f"{d['min_distance']:.3e} m ({d['active_contacts']} pairs, kappa {d['kappa']:.4g})")
        return a

    contact.max_step = max_step
    try:
        t, stats, out = time_step(model, state, dt, solver)
    finally:
        del contact.max_step  # the bound method again
        newton_log.setLevel(logging.NOTSET)
    d = contact.diagnostics(out.x)
    print(f"{label} with IPC: {t:.2f} s, {_breakdown(stats)}; at its end minimum distance "
          f"{d['min_distance']:.3e} m, {d['active_contacts']} pairs")
    return out


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


def cubes(args, solver):
    """The aligned cubes: their first-contact and resting steps, or their trace."""
    n = args.cells or (2 if args.quick else 12)  # 2 * 6 n^3 tets: 96, or 20,736
    dt = 0.01
    mesh, n_lower = two_cubes(n)
    with_ipc = model_of(mesh, n_lower, fe.IPCContact(dhat=1e-3, projection=args.projection))
    without = model_of(mesh, n_lower, None)
    state = fe.State.rest(with_ipc)
    d = with_ipc.contact.diagnostics(with_ipc.X)
    settle = 2 if args.quick else 5  # IPC steps before the resting step
    if args.trace:
        # the resting step's third Newton iteration: a pair's barrier force goes as 1/d, and a
        # Newton step on it squares the relative error of the gap (at 12 cells the minimum
        # distance goes 4.64, 5.08, 5.12, 5.12e-8 m: errors 9 %, 0.9 %, 0.02 %, and ||g|| 0.32,
        # 0.078, 7.3e-4, 6.5e-8 N), so three full steps reach the tolerance (1e-8 * 12.9 N there)
        out = trace_step("first contact", with_ipc, state, dt, solver)
        ie = implicit_euler(solver)
        for _ in range(settle - 1):  # to the state the timed resting step starts from
            out = ie.step(with_ipc, out, dt)
        trace_step("resting contact", with_ipc, out, dt, solver)
        return
    print(f"aligned cubes: {mesh.t.shape[1]} tets, {with_ipc.ndofs} DOFs, "
          f"{with_ipc.collision_surface().n_vertices} surface vertices, {d['active_contacts']} "
          f"active contact pairs at the start; projection {args.projection!r}, solver {args.solver!r}")
    # the first step: the upper cube falls from dhat / 2 into the barrier (the impact, the
    # costliest step: CCD-bounded Newton steps while the gap closes by three decades)
    compare("first contact", with_ipc, without, state, dt, args.repeats, solver)
    # a step in resting contact: after `settle` steps of IPC (the same step timed without contact
    # from the same state, where the elastic problem is the same)
    ie = implicit_euler(solver)
    for _ in range(settle):
        state = ie.step(with_ipc, state, dt)
    d = with_ipc.contact.diagnostics(state.x)
    print(f"after {settle} steps: minimum distance {d['min_distance']:.3g} m, "
          f"{d['active_contacts']} active pairs, kappa {d['kappa']:.4g} N/m^3")
    compare("resting contact", with_ipc, without, state, dt, args.repeats, solver)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="small meshes, few steps (seconds)")
    ap.add_argument("--cubes", action="store_true",
                    help="the two aligned cubes' first-contact and resting steps instead of the drop")
    ap.add_argument("--repeats", type=int, default=5, help="--cubes: pairs of runs per step")
    ap.add_argument("--cells", type=int, default=None,
                    help="the drop: cells along the ball's edge (30 n^3 tets; default 9, --quick 2); "
                         "--cubes: along a cube's edge (2 * 6 n^3 tets; default 12, --quick 2)")
    ap.add_argument("--steps", type=int, default=None,
                    help="the drop's steps (default: the scene's 0.6 s, 60 steps; --quick 20)")
    ap.add_argument("--projection", choices=("clamp", "abs"), default="clamp",
                    help="--cubes: PSD projection of the pair Hessians (fe.IPCContact(projection=...))")
    ap.add_argument("--solver", choices=("auto", "direct", "amg"), default="auto",
                    help="linear solver of both steps (default fe.AutoSolver: direct below 20k DOFs)")
    ap.add_argument("--no-broad-phase", action="store_true", help="skip the broad-phase scaling")
    ap.add_argument("--no-saddle-extension", action="store_true",
                    help="Newton without its doubling of projected steps at saddles (as before "
                         "commit 903847c; newton.MAX_EXTENSIONS = 0), for comparison")
    ap.add_argument("--velocity-tol", type=float, default=0.0, metavar="V",
                    help="m/s: both sides' fe.ImplicitEuler(velocity_tol=V), IPC's rule (a whole exact "
                         "Newton step moving no DOF by more than V * dt ends the solve); default 0, "
                         "the force tolerance alone")
    ap.add_argument("--kappa", default=None, metavar="K",
                    help="the drop's IPC barrier stiffness, N/m^3 or 'auto' (IPC's adaptive rule); "
                         "default the scene's (1e7)")
    ap.add_argument("--trace", action="store_true",
                    help="--cubes: only the first-contact step and the resting step, once each, "
                         "logging each Newton iteration (||g||, step fraction, exact or projected) "
                         "and each CCD bound")
    args = ap.parse_args(argv)
    solver = {"auto": None, "direct": fe.DirectSolver(), "amg": fe.AMGSolver()}[args.solver]
    global VELOCITY_TOL, KAPPA
    VELOCITY_TOL = args.velocity_tol
    if args.kappa is not None:
        if args.kappa == "auto":
            KAPPA = "auto"
        else:
            try:
                KAPPA = float(args.kappa)
            except ValueError:
                KAPPA = math.nan
            if not (math.isfinite(KAPPA) and KAPPA > 0.0):
                ap.error(f"--kappa takes a stiffness in N/m^3 (finite, > 0) or 'auto', got {args.kappa!r}")
        if args.cubes:
            ap.error("--kappa sets the drop's barrier stiffness; the cubes use IPC's adaptive one")
    if args.no_saddle_extension:
        from fem_elastic.solvers import newton

        newton.MAX_EXTENSIONS = 0
    if args.trace and not args.cubes:
        ap.error("--trace traces the cubes' steps: add --cubes")
    if args.cubes:
        cubes(args, solver)
    else:
        drop(args.cells or (2 if args.quick else 9), args.steps or (20 if args.quick else None), solver)
    if args.no_broad_phase or args.trace:
        return
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
