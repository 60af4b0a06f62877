"""SfePy reference for ``bench_time_to_accuracy.py``: the steel cantilever on Q2 hexahedra.

Run by an interpreter with SfePy installed (a separate venv, never fem_elastic's)::

    /tmp/sfepyvenv/bin/python scripts/sfepy_cantilever.py --cells 10 1 1 --order 2 \\
        --repeats 5 --clock process

The beam, material, clamp and load are those of ``scripts/bench_time_to_accuracy.py``:
steel (E = 210 GPa, nu = 0.3), L = 1 m, b = h = 0.05 m, every displacement component
clamped on the face x = 0, a uniform traction (0, 0, -P/A) Pa on the face x = L with
P = 3 E I (L / 1000) / L^3 N (a 1 mm Euler-Bernoulli tip deflection), linear elasticity.

The problem is written with SfePy's own imperative API, as in its example
``sfepy/examples/linear_elasticity/linear_elastic_interactive.py``:

- mesh: ``sfepy.mesh.mesh_generators.gen_block_mesh`` (``cells`` hexahedra, x in [0, L]);
- set-up: ``FEDomain``, the facet regions x = 0 and x = L, a vector ``Field`` of
  ``approx_order=order`` (``'lagrange'`` basis, SfePy's default), ``Material`` with
  ``stiffness_from_youngpoisson``, the terms ``dw_lin_elastic`` and ``dw_surface_ltr``,
  ``Equation(s)``, ``Problem``, the clamp ``EssentialBC(u.all = 0)``, the solvers
  ``ScipyDirect({})`` (its default ``method='auto'``: UMFPACK if scikit-umfpack is
  importable, else SciPy's SuperLU through ``spsolve``) and ``Newton({'i_max': 1})``
  (SfePy's linear examples use one Newton iteration);
- solve: ``Problem.solve(save_results=False)``, split by Newton's own timers into
  ``residual`` (two residual assemblies: the one that starts Newton and its
  convergence check after the step), ``matrix`` (the tangent assembly), ``solve``
  (the sparse direct solve) and ``other`` (the rest of ``Problem.solve``: state
  vector, EBC application, time stepper set-up).

SfePy's hexahedral Lagrange element of order 2 (``LagrangeTensorProductPolySpace``) is
the full tensor-product element: 27 nodes per cell (vertices, edge mid-points, face
centres and the cell centre), (2 nx + 1)(2 ny + 1)(2 nz + 1) nodes on an nx x ny x nz
grid; the script checks that DOF count (3 per node) and stops if it differs (the
20-node serendipity element would have fewer). The integral is Gauss-Legendre of order
``2 * order`` (3 x 3 x 3 points for Q2): exact for the stiffness of the box cells here.

The tip deflection is the area mean of u_z over the end face (the work-conjugate of the
uniform traction): ``ev_integrate`` of u over the facet region x = L divided by its
``ev_volume`` (the area). It is checked against a second way, the Q2 face-quadrature
weights of the end-face nodes of a uniform grid (tensor Simpson 1/6, 4/6, 1/6 per
cell and direction), and the script stops if the two disagree beyond round-off.

One warm-up pipeline on a 2 x 1 x 1 mesh runs first (imports, term look-up, the
C extensions' first calls), then ``--repeats`` timed pipelines; the tip deflection
is computed after the timer stops (as the fem_elastic benchmark does). One JSON line
goes to stdout: cells, order, DOFs, tip deflection (m), medians per phase and total
(s), SfePy's version and the linear solver ScipyDirect used.
"""

from __future__ import annotations

import argparse
import json
import logging
import statistics
import sys
import time

import numpy as np

L, B, H = 1.0, 0.05, 0.05  # m
E, NU = 2.1e11, 0.3  # Pa, -
AREA = B * H  # m^2
SECOND_MOMENT = B * H**3 / 12.0  # m^4
P = 3.0 * E * SECOND_MOMENT * (L / 1000.0) / L**3  # N: 1 mm Euler-Bernoulli tip deflection
PHASES = ("mesh", "setup", "residual", "matrix", "solve", "other")


def linear_solver_used(ls) -> str:
    """The factorization SfePy's ``ScipyDirect`` hands to SciPy: 'umfpack' or 'superlu'.

    ``ScipyDirect.__init__`` calls ``scipy.sparse.linalg.use_solver(useUmfpack=...)``,
    which sets the module flag that ``spsolve`` reads; that flag is read back here.
    """
    from scipy.sparse.linalg._dsolve import linsolve

    flag = linsolve.useUmfpack
    flag = getattr(flag, "u", flag)  # SciPy >= 1.15 keeps it in a threading.local
    return "umfpack" if flag else "superlu"


def pipeline(cells, order: int) -> tuple[dict, float, int, str, dict]:
    """Build and solve the cantilever once.

    Parameters
    ----------
    cells : tuple of 3 int
        Hexahedra along x, y and z.
    order : int
        Lagrange order of the displacement field.

    Returns
    -------
    seconds : dict
        Seconds per phase (``PHASES``) and ``total``.
    tip : float
        Area mean of u_z over the end face x = L (m; negative: downwards).
    ndofs : int
        Displacement DOFs, clamped ones included (3 per node).
    solver : str
        'umfpack' or 'superlu'.
    checks : dict
        Newton's status and the second tip evaluation, for the caller's checks.
    """
    from sfepy.base.base import IndexedStruct
    from sfepy.discrete import Equation, Equations, FieldVariable, Integral, Material, Problem
    from sfepy.discrete.conditions import Conditions, EssentialBC
    from sfepy.discrete.fem import FEDomain, Field
    from sfepy.mechanics.matcoefs import stiffness_from_youngpoisson
    from sfepy.mesh.mesh_generators import gen_block_mesh
    from sfepy.solvers.ls import ScipyDirect
    from sfepy.solvers.nls import Newton
    from sfepy.terms import Term

    nx, ny, nz = cells
    t = {}
    t0 = time.perf_counter()
    mesh = gen_block_mesh((L, B, H), (nx + 1, ny + 1, nz + 1), (0.5 * L, 0.5 * B, 0.5 * H),
                          name="cantilever", verbose=False)
    t1 = time.perf_counter()
    domain = FEDomain("domain", mesh)
    eps = 1e-8 * L
    omega = domain.create_region("Omega", "all")
    left = domain.create_region("Left", f"vertices in x < {eps:.10g}", "facet")
    right = domain.create_region("Right", f"vertices in x > {L - eps:.10g}", "facet")
    field = Field.from_args("displacement", np.float64, "vector", omega, approx_order=order)
    u = FieldVariable("u", "unknown", field)
    v = FieldVariable("v", "test", field, primary_var_name="u")
    solid = Material("solid", D=stiffness_from_youngpoisson(3, E, NU))
    load = Material("load", val=np.array([[0.0], [0.0], [-P / AREA]]))
    integral = Integral("i", order=2 * order)
    elastic = Term.new("dw_lin_elastic(solid.D, v, u)", integral, omega, solid=solid, v=v, u=u)
    traction = Term.new("dw_surface_ltr(load.val, v)", integral, right, load=load, v=v)
    equations = Equations([Equation("balance", elastic - traction)])
    problem = Problem("cantilever", equations=equations)
    problem.set_bcs(ebcs=Conditions([EssentialBC("clamp", left, {"u.all": 0.0})]))
    ls = ScipyDirect({})
    nls_status = IndexedStruct()
    nls = Newton({"i_max": 1, "eps_a": 1e-10}, lin_solver=ls, status=nls_status)
    problem.set_solver(nls)
    t2 = time.perf_counter()
    state = problem.solve(save_results=False, verbose=False)
    t3 = time.perf_counter()
    t["mesh"], t["setup"] = t1 - t0, t2 - t1
    for k in ("residual", "matrix", "solve"):
        t[k] = nls_status.time_stats[k]
    t["other"] = (t3 - t2) - t["residual"] - t["matrix"] - t["solve"]
    t["total"] = t3 - t0

    u = state["u"]  # the solved unknown (the Variables that Problem.solve returns)
    uz_integral = problem.evaluate(f"ev_integrate.{2 * order}.Right(u)", u=u, mode="eval")
    area = problem.evaluate(f"ev_volume.{2 * order}.Right(u)", u=u, mode="eval")
    tip = float(np.ravel(uz_integral)[2] / area)
    ndofs = field.n_nod * 3
    checks = {"n_iter": nls_status.n_iter, "err0": nls_status.err0, "err": nls_status.err,
              "area": float(area), "tip_nodal": tip_by_face_weights(field, u, cells, order),
              "element": f"{type(field.poly_space).__name__}, {field.poly_space.n_nod} nodes"}
    return t, tip, ndofs, linear_solver_used(ls), checks


def tip_by_face_weights(field, u, cells, order: int) -> float:
    """The area mean of u_z over x = L from the end-face nodes of a uniform Q2 grid (m).

    On a uniform grid of Q2 cells the face integral of the interpolant is the tensor
    Simpson rule on the end-face nodes: weights (1, 4, 1) / 6 per cell and direction,
    summed over the cells that share a node. A second way to the same number, not via
    SfePy's quadrature (for order 1: trapezoid weights (1, 1) / 2). NaN for other orders.
    """
    if order not in (1, 2):
        return float("nan")
    coors = field.get_coor()
    uz = u().reshape(-1, 3)[:, 2]
    on_face = np.abs(coors[:, 0] - L) < 1e-8 * L
    _, ny, nz = cells

    def weights(n: int, width: float, x: np.ndarray) -> np.ndarray:
        per_cell = np.array([1.0, 4.0, 1.0]) / 6.0 if order == 2 else np.array([0.5, 0.5])
        w = np.zeros(order * n + 1)
        for c in range(n):
            w[order * c:order * c + order + 1] += per_cell
        idx = np.rint(x / width * order * n).astype(int)
        return w[idx] / n  # fraction of the width

    wy = weights(ny, B, coors[on_face, 1])
    wz = weights(nz, H, coors[on_face, 2])
    return float(np.sum(wy * wz * uz[on_face]))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs=3, default=[10, 1, 1], metavar=("NX", "NY", "NZ"))
    parser.add_argument("--order", type=int, default=2, help="Lagrange order of the hexahedra")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--serve", action="store_true",
                        help="after the warm-up, read 'nx ny nz' lines from stdin and answer each "
                             "with one pipeline's JSON line (for a caller that interleaves its own "
                             "runs with SfePy's); an empty line or EOF ends it")
    parser.add_argument("--clock", choices=("wall", "process"), default="wall",
                        help="process: CPU time of this process (all its threads), for a loaded "
                             "machine; it replaces time.perf_counter, so SfePy's Newton timers use it too")
    args = parser.parse_args(argv)
    if args.clock == "process":
        time.perf_counter = time.process_time  # before any sfepy Timer captures it
    import sfepy
    from sfepy.base.base import output

    output.set_output(quiet=True)
    logging.getLogger("sfepy").setLevel(logging.WARNING)
    cells, order = tuple(args.cells), args.order

    pipeline((2, 1, 1), order)  # warm-up: imports, term tables, first calls of the C extensions
    if args.serve:
        print(json.dumps({"ready": True}), flush=True)
        for line in sys.stdin:
            if not line.strip():
                break
            c = tuple(int(v) for v in line.split())
            t, tip, ndofs, _, _ = pipeline(c, order)
            print(json.dumps({"cells": list(c), "tip": tip, "ndofs": ndofs, "seconds": t}), flush=True)
        return 0
    runs = [pipeline(cells, order) for _ in range(max(1, args.repeats))]
    t0, tip, ndofs, solver, checks = runs[0]
    nx, ny, nz = cells
    expected = 3 * (order * nx + 1) * (order * ny + 1) * (order * nz + 1)
    if ndofs != expected:
        raise SystemExit(f"{ndofs} DOFs, not the {expected} of the tensor-product Q{order} element")
    if abs(checks["area"] - B * H) > 1e-12 * B * H:
        raise SystemExit(f"end-face area {checks['area']} m^2, not {B * H}")
    # The two tip evaluations integrate the same interpolant exactly: they differ by
    # round-off only (relative 1e-10 leaves room for the sums over ~1e2 nodes).
    if not abs(checks["tip_nodal"] - tip) <= 1e-10 * abs(tip):
        raise SystemExit(f"tip by ev_integrate {tip} m, by face weights {checks['tip_nodal']} m")
    med = {k: statistics.median(r[0][k] for r in runs) for k in PHASES + ("total",)}
    print(json.dumps({
        "cells": list(cells), "order": order, "ndofs": ndofs, "tip": tip,
        "tip_nodal": checks["tip_nodal"], "seconds": med, "repeats": len(runs),
        "clock": args.clock, "newton_iterations": checks["n_iter"],
        "residual0": checks["err0"], "residual": checks["err"],
        "element": checks["element"], "sfepy": sfepy.__version__, "linear_solver": solver,
    }))
    return 0


if __name__ == "__main__":
    sys.exit(main())
