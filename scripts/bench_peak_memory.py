"""Peak memory of a process that builds the ~150k-tet beam model and assembles one projected tangent.

Issue 19's row: "peak memory of a process that builds the 150k-tet model and assembles
one projected tangent: 2.0 GB, goal <= 0.6 GB", against what the data needs (the CSR
tangent and the per-element gradients). Each measurement runs in a fresh Python
subprocess (``ru_maxrss`` only grows, so a process measures one thing): it imports
fem_elastic (and numba's kernels, loaded from their cache by a tiny warm-up model),
builds a 1 x 0.1 x 0.1 m beam of 100 x 16 x 16 cells (153,600 P1 tets, 87,567 DOFs),
a Neo-Hookean model held at its left end, and calls ``model.linearize(x, project=True)``
once at a bent state (the fused P1 tangent with per-point PSD projection, as a Newton
iteration of an implicit step does), printing the peak resident set size
(``resource.getrusage(RUSAGE_SELF).ru_maxrss``) after each stage, and beside it

- the data's own size: the CSR tangent (values, column indices, row pointers), the
  per-element shape-function gradients, volumes and vertex indices of the fused kernels,
  and their int32 map of the element blocks into the CSR data;
- with ``--trace``: tracemalloc's peak within each stage and the top allocation sites
  still alive at its end (slower; numpy's buffers included, also those numba and scipy
  allocate through numpy).

Usage::

    .venv/bin/python scripts/bench_peak_memory.py            # full size
    .venv/bin/python scripts/bench_peak_memory.py --trace    # where the peak comes from
    .venv/bin/python scripts/bench_peak_memory.py --cells 40 6 6
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

GOAL_BYTES = 0.6e9  # the goal for the whole process
BEFORE_BYTES = 2.0e9  # the measurement


def child(cells, trace: bool) -> dict:
    """Runs in the fresh subprocess: the stages, their peak RSS (bytes) and the data's size."""
    import resource
    import tracemalloc

    def peak() -> int:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # kB on Linux

    out = {"stages": [], "top": {}}

    def stage(name):
        out["stages"].append((name, peak()))
        if trace and tracemalloc.is_tracing():
            snap = tracemalloc.take_snapshot()
            stats = snap.statistics("lineno")[:6]
            out["top"][name] = [(str(s.traceback), s.size) for s in stats]
            out["stages"][-1] += (tracemalloc.get_traced_memory()[1],)
            tracemalloc.reset_peak()

    import numpy as np

    import fem_elastic as fe
    from fem_elastic.discretization import fused

    # load numba's cached kernels (compiled on an earlier run) outside the measured build
    small = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e7, nu=0.45)), fixed="left")
    small.linearize(small.X, project=True)
    del small
    stage("imports (numpy, scipy, scikit-fem, numba kernels)")
    if trace:
        tracemalloc.start()
    mesh = fe.beam_mesh(1.0, 0.1, 0.1, tuple(cells))
    stage("mesh")
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1.0e7, nu=0.45)),
                     fixed="left")
    stage("model")
    X = model.X.reshape(-1, 3)
    x = (X + np.column_stack([0 * X[:, 0], 0 * X[:, 0], 0.02 * X[:, 0] ** 2])).ravel()
    g, H = model.linearize(x, project=True)
    stage("one projected tangent (model.linearize(x, project=True))")
    kern = fused.kernels_for(model.body_potential.material, model.space)
    ne = model.space.dx.shape[0]
    data = {"csr": H.data.nbytes + H.indices.nbytes + H.indptr.nbytes}
    if kern is not None:
        geo = kern.geo
        data["gradients"] = geo.Dm_inv.nbytes + geo.V.nbytes + geo.nodes.nbytes
        from fem_elastic.discretization import _fused_tangent_kernels as T

        data["block-offset map"] = T.element_offsets(model.space.pattern, geo.nodes).nbytes
    out.update(ne=ne, ndofs=model.ndofs, nnz=int(H.nnz), data=data, fused=kern is not None)
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs=3, default=(100, 16, 16), metavar=("NX", "NY", "NZ"))
    parser.add_argument("--trace", action="store_true", help="tracemalloc's top sites per stage")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.cells, args.trace)))
        return
    cmd = [sys.executable, os.path.abspath(__file__), "--child", "--cells", *map(str, args.cells)]
    if args.trace:
        cmd.append("--trace")
    res = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if res.returncode:
        raise SystemExit(res.stderr)
    r = json.loads(res.stdout.strip().splitlines()[-1])
    mib = 2.0 ** 20
    print(f"peak memory: {r['ne']:,} P1 tets, {r['ndofs']:,} DOFs, tangent nnz {r['nnz']:,}, "
          f"Neo-Hookean, fused kernels: {r['fused']} (a fresh process)")
    print(f"{'stage':<60}{'peak RSS MiB':>14}" + (f"{'traced peak MiB':>17}" if args.trace else ""))
    for s in r["stages"]:
        line = f"{s[0]:<60}{s[1] / mib:14.1f}"
        if len(s) > 2:
            line += f"{s[2] / mib:17.1f}"
        print(line)
    total = r["stages"][-1][1]
    base = r["stages"][0][1]
    need = sum(r["data"].values())
    print("the data's own size: " + ", ".join(f"{k} {v / mib:.1f} MiB" for k, v in r["data"].items())
          + f"; total {need / mib:.1f} MiB")
    print(f"peak RSS {total / 1e9:.3f} GB (goal <= {GOAL_BYTES / 1e9:.1f} GB: "
          f"{'met' if total <= GOAL_BYTES else 'NOT met'}; the issue measured {BEFORE_BYTES / 1e9:.1f} GB); "
          f"above the imports {(total - base) / mib:.0f} MiB = {(total - base) / max(need, 1):.1f} x the data")
    for name, top in r["top"].items():
        print(f"\ntop allocation sites in '{name}':")
        for where, size in top:
            print(f"  {size / mib:8.1f} MiB  {where}")


if __name__ == "__main__":
    main()
