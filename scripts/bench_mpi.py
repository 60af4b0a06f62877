"""Benchmark: the distributed (PETSc over MPI) static solve, time per phase and memory per rank.

Issue 21, item 4. Run it under ``mpiexec -n P`` (or as a plain script: one rank). Every rank
builds the same cantilever, a ``length x 0.1 x 0.1`` m box of ``nx x n x n`` cubic cells
(``fe.beam_mesh``, 6 tets a cell, ``nx ~ 4 n``), linear elastic (E = 1e7 Pa, nu = 0.3, or
``--material neohookean``), held at ``x = 0``, under gravity, P1. Then, phase by phase, each
phase between barriers and timed on every rank (the table gives the slowest rank's time, which
is the phase's wall time):

1. ``model``: ``fe.Model(fe.beam_mesh(...))`` and what every rank computes of the *whole* model
   (space, DOF numbering, held DOFs, dead loads): replicated on every rank;
2. ``partition``: ``partition_elements`` (METIS on the dual graph) alone, on rank 0 (zero
   work on one rank: no METIS);
3. ``setup``: ``DistributedProblem(...)``: it partitions again on rank 0 and broadcasts, then
   each rank builds its sub-mesh and sub-space, the ghost scatter and the exactly
   preallocated MPIAIJ matrix (so ``setup`` includes ``partition``);
4. ``assembly``: ``problem.gradient`` and ``problem.hessian`` (PSD-projected, as Newton's first
   iteration) at the rest state ``X``;
5. ``pc_setup``: ``ksp.setOperators(A); ksp.setUp()`` on a new KSP from ``fe.PETScSolver()``
   (CG + GAMG with the rigid-body near-null space, Chebyshev on Jacobi smoothing);
6. ``solve``: ``ksp.solve`` of ``A du = -g`` to ``--rtol`` (relative, unpreconditioned
   residual), with its CG iterations (``--smoother``: the package's default, ``jacobi``
   for PETSc's own GAMG default, Chebyshev on Jacobi with a 10 % eigenvalue margin, or
   ``sor``, Richardson + SOR, which fails on the 150k-tet beam: docs/scaling.md);
7. ``solve_static``: the whole ``fe.solve_static(model, linear_solver=fe.PETScSolver(),
   stability=False)`` on a fresh model (inexact Newton: several CG solves), its Newton and CG
   iterations.

Each phase is repeated ``--repeats`` times (medians printed; the model is rebuilt every
repeat, the previous one freed first). Numba compiles its kernels on a tiny beam first, outside
the timings. Memory per rank: the resident set size after the imports and that warm-up
(``rss_base``), right after the first model build (``rss_model``; minus ``rss_base``: the
replicated part), after the first PC setup
(``rss_pc``), the peak (``ru_maxrss``) after the first repeat (``rss_peak1``: one model,
one set-up, one solve and one ``solve_static``) and at the end (``rss_peak``; each repeat's
model and PETSc objects are released before the next), in MiB. Only rank 0 prints. BLAS and
numba run ``--threads`` threads per rank (default 1: one core a rank).

Usage::

    python scripts/bench_mpi.py --quick                                # a few thousand tets
    mpiexec -n 2 python scripts/bench_mpi.py --tets 150000 --json out.json
    mpiexec -n 2 python scripts/bench_mpi.py --tets 1200000 --repeats 1
    python scripts/bench_mpi.py --fit run1.json run2.json ...          # the scaling model

(As root, Open MPI also needs ``OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1``;
in a container without CMA, ``OMPI_MCA_btl_vader_single_copy_mechanism=none``.)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import sys
import time

PHASES = ("model", "partition", "setup", "assembly", "pc_setup", "solve", "solve_static")


def cells_for(tets: int) -> tuple[int, int, int]:
    """Cells ``(nx, n, n)`` with ``nx ~ 4 n`` and ``6 nx n^2`` closest to ``tets``."""
    n = max(1, round((tets / 24.0) ** (1.0 / 3.0)))
    nx = max(1, round(tets / (6.0 * n * n)))
    return nx, n, n


def rss_now_mib() -> float:
    """This process's current resident set size (MiB), from /proc (Linux)."""
    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def rss_peak_mib() -> float:
    """This process's peak resident set size (MiB): ``ru_maxrss`` is in KiB on Linux."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


FIT_PHASES = ("setup", "assembly", "pc_setup", "solve")


def fit(paths, budgets_gib=(4.0, 8.0, 16.0), sizes=(5e6, 50e6), ranks=(8, 64)) -> dict:
    """Fit the scaling model to ``--json`` results and predict ranks and times (docs/scaling.md).

    Times (the fastest repeat of each run): per phase, ``t1(n) = c n^q`` by least squares in
    log-log on the 1-rank runs (n tets; q = 1 for ``model``, ``partition`` and ``assembly``,
    whose work is linear in n by construction, so that noise does not bend them), predicted on p ranks as ``t1(n) / p`` for ``setup``, ``assembly``, ``pc_setup`` and
    ``solve``: the work divides ideally among p ranks that each have a core of their own (the
    2-rank runs here shared 2 busy cores, so their ratio to 1 rank, ``speedup_2``, is printed
    but not used); ``model`` (every rank builds the whole model) stays ``t1(n)`` on every
    rank and ``partition`` (METIS on rank 0 alone, fitted on the runs with p > 1) is not
    divided either; CG iterations ``k n^q`` (all runs). Memory per rank (MiB): ``base + r n``
    after the model build (r: the replicated model) and ``base + r n + d n / p`` after the PC
    set-up (d: the distributed part: sub-mesh, matrix, AMG hierarchy), r and d by least
    squares (the transient peak above that is reported, not fitted); the ranks for a budget B per rank are
    the fewest with ``base + r n + d n / p <= B`` (none when ``base + r n > B``), and, for
    comparison, the same with r = 0 (no replicated model).
    """
    import numpy as np

    runs = [json.load(open(path)) for path in paths]
    n = np.array([r["tets"] for r in runs], dtype=float)
    p = np.array([r["ranks"] for r in runs], dtype=float)
    # the fastest repeat: on a machine shared with other jobs their load only adds time
    t = {ph: np.array([min(r["seconds_all"][ph]) for r in runs]) for ph in PHASES}
    its = np.array([statistics.median(r["cg_iterations"]) for r in runs])

    def power(mask, y, linear=False):
        if linear:  # t = c n, least squares in log: c the geometric mean of t / n
            return {"c": float(np.exp(np.mean(np.log(y[mask] / n[mask])))), "q": 1.0}
        if mask.sum() < 2:
            return {"c": float("nan"), "q": float("nan")}
        q, logc = np.polyfit(np.log(n[mask]), np.log(y[mask]), 1)
        return {"c": float(np.exp(logc)), "q": float(q)}

    one, two = p == 1, p == 2
    out: dict = {"runs": len(runs), "model": power(one, t["model"], linear=True),
                 "partition": power(two, t["partition"], linear=True)}
    for ph in FIT_PHASES:
        out[ph] = power(one, t[ph], linear=ph == "assembly")
        out[ph]["speedup_2"] = {int(nn): float(t[ph][one & (n == nn)][0] / t[ph][two & (n == nn)][0])
                                for nn in sorted(set(n[one]) & set(n[two]))}
    out["cg_iterations"] = power(np.ones_like(one), its)
    # memory (MiB) per rank: the largest rank of each run
    base = np.array([max(d["rss_base"] for d in r["per_rank"]) for r in runs])
    model = np.array([max(d["rss_model"] for d in r["per_rank"]) for r in runs]) - base
    pc = np.array([max(d["rss_pc"] for d in r["per_rank"]) for r in runs]) - base
    r_mib = float(n @ model / (n @ n))
    d_mib = float((n / p) @ (pc - r_mib * n) / ((n / p) @ (n / p)))
    base_mib = float(np.median(base))
    out["memory"] = {"base_mib": base_mib, "replicated_mib_per_tet": r_mib,
                     "distributed_mib_per_tet": d_mib}

    def at(ph, nn):
        return out[ph]["c"] * nn ** out[ph]["q"]

    def step(nn, pp):
        sec = {ph: at(ph, nn) / pp for ph in FIT_PHASES}
        sec["model"] = at("model", nn)
        sec["partition"] = at("partition", nn) if pp > 1 else 0.0
        return {"ranks": pp, "cg_iterations": at("cg_iterations", nn), "seconds": sec,
                "newton_step_s": sec["assembly"] + sec["pc_setup"] + sec["solve"],
                "linear_static_s": sum(sec.values()),
                "memory_per_rank_gib": (base_mib + r_mib * nn + d_mib * nn / pp) / 1024.0}

    preds = []
    for nn in sizes:
        for budget in budgets_gib:
            row: dict = {"tets": nn, "budget_gib": budget, "replicated_gib": r_mib * nn / 1024.0}
            for key, r in (("ranks", r_mib), ("ranks_without_replication", 0.0)):
                room = budget * 1024.0 - base_mib - r * nn
                row[key] = max(1, int(np.ceil(d_mib * nn / room))) if room > 0 else None
            if row["ranks"] is not None:
                row["at_ranks"] = step(nn, row["ranks"])
            preds.append(row)
        for pp in ranks:
            preds.append({"tets": nn, "at_ranks": step(nn, pp)})
    out["predictions"] = preds
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fit", nargs="+", metavar="JSON", default=None,
                        help="no benchmark: fit the scaling model to these --json results, "
                             "print it and the predictions for 5M and 50M tets (docs/scaling.md)")
    parser.add_argument("--tets", type=int, default=150_000, help="target number of tets")
    parser.add_argument("--quick", action="store_true", help="about 3,000 tets, 1 repeat (the test)")
    parser.add_argument("--material", choices=("linear", "neohookean"), default="linear")
    parser.add_argument("--repeats", type=int, default=3, help="samples per phase (medians printed)")
    parser.add_argument("--rtol", type=float, default=1e-8,
                        help="CG's relative residual in the 'solve' phase (default 1e-8)")
    parser.add_argument("--smoother", choices=("default", "sor", "jacobi"), default="default",
                        help="GAMG's level smoother: 'default' is fe.PETScSolver()'s (Chebyshev + "
                             "Jacobi, 30 %% eigenvalue margin); 'jacobi' is PETSc's GAMG default "
                             "(Chebyshev + Jacobi, 10 %% margin); 'sor' Richardson + SOR; the last "
                             "two passed as PETScSolver(options=...)")
    parser.add_argument("--threads", type=int, default=1, help="BLAS and numba threads per rank")
    parser.add_argument("--json", default=None, help="also write the results to this JSON file")
    args = parser.parse_args(argv)
    if args.fit:
        result = fit(args.fit)
        print(json.dumps(result, indent=1))
        if args.json:
            with open(args.json, "w") as f:
                json.dump(result, f, indent=1)
        return 0
    if args.quick:
        args.tets, args.repeats = 3000, 1
    if args.tets < 6 or args.repeats < 1:
        parser.error("--tets must be >= 6 and --repeats >= 1")
    for var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(args.threads)  # read when numba / BLAS first load

    import fem_elastic as fe
    from fem_elastic.solvers import distributed
    from fem_elastic.solvers.distributed import DistributedProblem
    from fem_elastic.solvers.partition import partition_elements
    from fem_elastic.solvers.petsc_solver import comm_world
    from mpi4py import MPI

    comm = comm_world()
    mpi = comm.tompi4py()
    rank, size = comm.getRank(), comm.getSize()
    nx, ny, nz = cells_for(args.tets)
    width = 0.1  # m; the length is width * nx / ny: cubic cells
    material = (fe.LinearElastic(E=1e7, nu=0.3) if args.material == "linear"
                else fe.NeoHookean(E=1e7, nu=0.3))

    def build(cells=(nx, ny, nz)):
        mesh = fe.beam_mesh(length=width * cells[0] / cells[1], width=width, height=width,
                            cells=cells)
        model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(material), fixed="left",
                         gravity=(0.0, 0.0, -9.81))
        # what the distributed path reads of the whole model, on every rank
        _ = (model.space.element_dofs, model.X, model.held_dofs, model.external_force(1.0))
        return model

    smoother = {"default": {},
                "jacobi": {"mg_levels_ksp_type": "chebyshev", "mg_levels_pc_type": "jacobi",
                           "mg_levels_ksp_chebyshev_esteig": "0,0.1,0,1.1"},
                "sor": {"mg_levels_ksp_type": "richardson", "mg_levels_pc_type": "sor"}}[args.smoother]

    def static(m):
        return fe.solve_static(m, linear_solver=fe.PETScSolver(options=smoother), stability=False,
                               check=False)

    # warm-up on a tiny beam: numba compiles the kernels (about a second) outside the timings
    tiny = build((4 * size, 1, 1))
    warm = DistributedProblem(tiny, comm, tiny.held_dofs)
    xw = warm.to_vec(tiny.X)
    warm.gradient(xw).destroy()
    warm.hessian(xw, project=True)
    xw.destroy()
    warm.destroy()
    static(tiny)
    tiny = warm = None
    rss_base = rss_now_mib()

    times = {p: [] for p in PHASES}
    cpu = {p: [] for p in PHASES}  # the process's CPU time: leaves out other jobs' share
    info: dict = {}

    def timed(phase, fn):
        """Run fn between barriers; record the slowest rank's seconds."""
        comm.barrier()
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        comm.barrier()
        times[phase].append(mpi.allreduce(dt, op=MPI.MAX))
        cpu[phase].append(mpi.allreduce(dc, op=MPI.MAX))
        return out

    model = None
    for rep in range(args.repeats):
        model = None  # free the previous repeat's model before building the next
        model = timed("model", build)
        if rep == 0:
            info["rss_base"], info["rss_model"] = rss_base, rss_now_mib()
        timed("partition", lambda: partition_elements(model.mesh.t, size) if rank == 0 else None)
        problem = timed("setup", lambda: DistributedProblem(model, comm, model.held_dofs))
        x = problem.to_vec(model.X)

        def assemble():
            g = problem.gradient(x)
            g.getArray()[~problem.free_owned] = 0.0  # held DOFs: no residual (identity rows)
            return g, problem.hessian(x, project=True)

        g, A = timed("assembly", assemble)
        ksp = fe.PETScSolver(rtol=args.rtol, options=smoother).ksp(comm)

        def pc_setup():
            ksp.setOperators(A)
            ksp.setUp()

        timed("pc_setup", pc_setup)
        if rep == 0:
            info["rss_pc"] = rss_now_mib()
        b, du = g.duplicate(), g.duplicate()
        g.copy(b)
        b.scale(-1.0)
        du.set(0.0)
        timed("solve", lambda: ksp.solve(b, du))
        info.setdefault("cg_iterations", []).append(int(ksp.getIterationNumber()))
        info.setdefault("ksp_reason", []).append(int(ksp.getConvergedReason()))
        info["n_local_tets"] = problem.n_elements
        info["n_owned_dofs"] = problem.hi - problem.lo
        for obj in (ksp, b, du, g, x):
            obj.destroy()
        problem.destroy()
        problem = None
        info["tets"] = int(model.mesh.t.shape[1])
        info["dofs"] = int(model.ndofs)
        info["free_dofs"] = int(model.ndofs - model.held_dofs.size)
        # the whole static solve, on a fresh model (no cached distributed problem)
        model = None
        fresh = build()
        res = timed("solve_static", lambda: static(fresh))
        info.setdefault("newton_iterations", []).append(int(res.iterations))
        info.setdefault("static_cg_iterations", []).append(int(res.linear_iterations))
        info.setdefault("static_converged", []).append(bool(res.converged))
        info["tip_deflection_m"] = float(-res.displacement[:, 2].min())
        distributed.release(fresh)  # its matrix and vectors, now
        fresh = res = None
        if rep == 0:
            info["rss_peak1"] = rss_peak_mib()  # the peak of one cycle, before any repeat
    info["rss_peak"] = rss_peak_mib()

    per_rank = mpi.gather({k: info[k] for k in ("rss_base", "rss_model", "rss_pc", "rss_peak1",
                                                  "rss_peak", "n_local_tets",
                                                  "n_owned_dofs")}, root=0)
    if rank != 0:
        return 0
    med = {p: statistics.median(v) for p, v in times.items()}
    out = {
        "ranks": size, "tets": info["tets"], "dofs": info["dofs"], "free_dofs": info["free_dofs"],
        "cells": [nx, ny, nz], "material": args.material, "repeats": args.repeats,
        "rtol": args.rtol, "threads_per_rank": args.threads,
        "seconds_median": med, "seconds_all": times,
        "cpu_seconds_median": {p: statistics.median(v) for p, v in cpu.items()},
        "cpu_seconds_all": cpu, "load_average": list(os.getloadavg()),
        "cg_iterations": info["cg_iterations"], "ksp_reason": info["ksp_reason"],
        "newton_iterations": info["newton_iterations"],
        "static_cg_iterations": info["static_cg_iterations"],
        "static_converged": info["static_converged"], "smoother": args.smoother,
        "tip_deflection_m": info["tip_deflection_m"],
        "per_rank": per_rank, "host": platform.node(), "cpus": os.cpu_count(),
    }
    print(f"bench_mpi: {size} rank(s), {info['tets']} tets ({nx} x {ny} x {nz} cells), "
          f"{info['dofs']} DOFs ({info['free_dofs']} free), {args.material}, P1, "
          f"medians of {args.repeats}, {args.threads} thread(s) a rank, {os.cpu_count()} CPUs, "
          f"GAMG smoother {args.smoother}")
    print(f"{'phase':<14}{'seconds':>10}{'CPU s':>10}   (slowest rank; load average "
          f"{os.getloadavg()[0]:.1f})")
    for p in PHASES:
        extra = ""
        if p == "solve":
            extra = f"   CG iterations {info['cg_iterations']}, rtol {args.rtol:g}"
        elif p == "solve_static":
            extra = (f"   Newton iterations {info['newton_iterations']}, "
                     f"CG iterations {info['static_cg_iterations']}, "
                     f"converged {info['static_converged']}")
        elif p == "setup":
            extra = "   (includes partition)"
        print(f"{p:<14}{med[p]:>10.3f}{out['cpu_seconds_median'][p]:>10.3f}{extra}")
    print(f"{'rank':<6}{'tets':>10}{'owned DOFs':>12}{'RSS base MiB':>14}{'RSS model MiB':>15}"
          f"{'RSS pc MiB':>12}{'peak 1st MiB':>14}{'peak RSS MiB':>14}")
    for r, d in enumerate(per_rank):
        print(f"{r:<6}{d['n_local_tets']:>10}{d['n_owned_dofs']:>12}{d['rss_base']:>14.0f}"
              f"{d['rss_model']:>15.0f}{d['rss_pc']:>12.0f}{d['rss_peak1']:>14.0f}"
              f"{d['rss_peak']:>14.0f}")
    ok = all(reason > 0 for reason in info["ksp_reason"]) and all(info["static_converged"])
    print(f"CG converged: {ok} (KSP reasons {info['ksp_reason']}, solve_static converged "
          f"{info['static_converged']}); tip deflection {info['tip_deflection_m']:.6e} m")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
