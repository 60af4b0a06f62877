"""Cook's membrane at nu = 0.4999 in plane strain: the P2 displacement element locks, the mixed one does not.

The tapered panel (0, 0), (48, 44), (48, 60), (0, 44) (Cook 1974), clamped at x = 0,
a uniform vertical shear traction of total force 100 (per unit thickness) on the
16-long right edge, linear elastic E = 250, nu = 0.4999 (lam / mu = 5000), plane
strain as a slab one element thick held in z on both faces::

    fe.Model(fe.cook_membrane_mesh(cells=(n, n)), density=1.0,
             body=fe.ElasticBody(fe.LinearElastic(E=250.0, nu=0.4999), order=2,
                                 formulation="mixed"),
             fixed={"left": "xyz", "front": "z", "back": "z"},
             traction={"right": (0.0, 100.0 / 16, 0.0)})

It prints the vertical displacement of the upper right corner (48, 60) on each mesh
for ``formulation="displacement"`` and ``"mixed"``, and its error against the
reference 7.771.

``--reference`` recomputes that reference independently: 2-D plane-strain
Taylor-Hood elements (P2/P1 and P3/P2, inf-sup stable) with scikit-fem on 8 to 64
and 8 to 32 cells per side, extrapolated by Richardson (the error ratio of the
last three meshes gives the rate): 7.769 from both, a few seconds. ``--fine``
(P2/P1 to 128, P3/P2 to 64 cells, a few minutes) gives 7.7711 and 7.7710, where
the rates have settled (1.08, 1.07; the clamped corners' singularity): hence
7.771, within about 0.002.

``--infsup`` prints the discrete inf-sup constant of P2/P0 on the Cook slab and on
a clamped cube (the stability of the mixed element's pressure, see
:mod:`fem_elastic.physics.mixed_body`), with Taylor-Hood P2/P1 for comparison.

Run ``python scripts/cook_membrane.py`` (meshes 2 to 32, about a minute) or
``--cells 4 8 16``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import fem_elastic as fe
from fem_elastic.geometry.generators import cook_membrane_mesh

E, LOAD = 250.0, 100.0
EDGE = 16.0  # length of the loaded edge
REFERENCE = 7.771  # --reference --fine: 2-D Taylor-Hood P3/P2 and P2/P1, Richardson-extrapolated


def tip_displacement(n: int, formulation: str, nu: float, material: str = "linear"):
    """(vertical tip displacement, DOFs, Newton iterations, seconds) on an n x n mesh."""
    mesh = cook_membrane_mesh(cells=(n, n))
    cls = {"linear": fe.LinearElastic, "neohookean": fe.NeoHookean}[material]
    model = fe.Model(mesh, density=1.0,
                     body=fe.ElasticBody(cls(E=E, nu=nu), order=2, formulation=formulation),
                     fixed={"left": "xyz", "front": "z", "back": "z"},
                     traction={"right": (0.0, LOAD / EDGE, 0.0)})
    t0 = time.perf_counter()
    res = fe.solve_static(model, linear_solver=fe.DirectSolver())
    tip = (mesh.p[0] == 48.0) & (mesh.p[1] == 60.0)
    return (float(res.displacement[tip, 1].mean()), model.ndofs, res.iterations,
            time.perf_counter() - t0)


def table(cells, nu: float, material: str) -> None:
    ref = REFERENCE if (material == "linear" and nu == 0.4999) else None  # the reference's case only
    print(f"Cook's membrane, {material} E = {E:g}, nu = {nu:g}, plane strain, F = {LOAD:g}: "
          "vertical displacement of the corner (48, 60)"
          + (f"; reference {ref}" if ref else "; no reference for this case: errors not shown") + "\n")
    print(f"{'cells':>8}{'DOFs':>8} | {'P2 displacement':>15} {'error':>8} | "
          f"{'mixed P2/P0':>11} {'error':>8} {'rate':>5} | {'disp/mixed':>10} {'s':>6}")
    last = None
    for n in cells:
        ud, ndofs, _, td = tip_displacement(n, "displacement", nu, material)
        um, _, _, tm = tip_displacement(n, "mixed", nu, material)
        ed = em = None
        errors = ["-", "-"]
        if ref:
            ed, em = (ref - ud) / ref, (ref - um) / ref
            errors = [f"{100 * ed:.2f}%", f"{100 * em:.2f}%"]
        rate = ""
        if last is not None and em is not None and em > 0 and last[1] > 0:
            rate = f"{np.log(last[1] / em) / np.log(n / last[0]):5.2f}"
        print(f"{n:>3} x {n:<3}{ndofs:>7} | {ud:15.4f} {errors[0]:>8} | {um:11.4f} {errors[1]:>8} "
              f"{rate:>5} | {ud / um:10.3f} {td + tm:6.1f}", flush=True)
        last = (n, em)
    if ref:
        print("\nerror = (reference - tip) / reference; rate = order of the mixed element's error "
              "in the cell size\n(the re-entrant clamped corners limit it to about 1 on uniform meshes).")


# --- the independent reference: 2-D plane-strain Taylor-Hood ---------------------------------

def taylor_hood_2d(n: int, degree: int, nu: float = 0.4999) -> float:
    """Tip displacement of Cook's membrane with P{degree}/P{degree-1} triangles, plane strain."""
    import scipy.sparse as sp
    from skfem import (Basis, BilinearForm, ElementTriP1, ElementTriP2, ElementTriP3, ElementVector,
                       FacetBasis, LinearForm, MeshTri, condense, solve)
    from skfem.helpers import ddot, div, sym_grad

    mu = E / (2 * (1 + nu))
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    unit = MeshTri.init_tensor(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1))
    xi, eta = unit.p
    mesh = MeshTri(np.vstack([48 * xi, 44 * xi + (44 - 28 * xi) * eta]), unit.t).with_boundaries(
        {"left": lambda x: x[0] < 1e-9, "right": lambda x: x[0] > 48 - 1e-9})
    eu = ElementVector({2: ElementTriP2, 3: ElementTriP3}[degree]())
    ep = {2: ElementTriP1, 3: ElementTriP2}[degree]()
    ub = Basis(mesh, eu, intorder=2 * degree)
    pb = Basis(mesh, ep, quadrature=ub.quadrature)

    @BilinearForm
    def a(u, v, w):
        return 2 * mu * ddot(sym_grad(u), sym_grad(v))

    @BilinearForm
    def b(u, q, w):
        return div(u) * q

    @BilinearForm
    def c(p, q, w):
        return p * q / lam

    @LinearForm
    def f(v, w):
        return LOAD / EDGE * v[1]

    K = sp.bmat([[a.assemble(ub), b.assemble(ub, pb).T], [b.assemble(ub, pb), -c.assemble(pb)]]).tocsc()
    rhs = np.concatenate([f.assemble(FacetBasis(mesh, eu, facets=mesh.boundaries["right"],
                                                intorder=2 * degree)), np.zeros(pb.N)])
    u = solve(*condense(K, rhs, D=ub.get_dofs(mesh.boundaries["left"]).all()))
    tip = np.flatnonzero((np.abs(mesh.p[0] - 48) < 1e-9) & (np.abs(mesh.p[1] - 60) < 1e-9))[0]
    return float(u[ub.nodal_dofs[1, tip]])


def reference(fine: bool) -> None:
    print("Independent reference: 2-D plane strain, Taylor-Hood (inf-sup stable), E = 250, "
          "nu = 0.4999\n")
    for degree, cells in ((2, (8, 16, 32, 64, 128) if fine else (8, 16, 32, 64)),
                          (3, (8, 16, 32, 64) if fine else (8, 16, 32))):
        values = []
        for n in cells:
            t0 = time.perf_counter()
            values.append(taylor_hood_2d(n, degree))
            print(f"  P{degree}/P{degree - 1} {n:>4} x {n:<4} tip = {values[-1]:.5f}  "
                  f"({time.perf_counter() - t0:.1f} s)", flush=True)
        u0, u1, u2 = values[-3:]
        r = (u1 - u0) / (u2 - u1)  # error ratio per halving
        print(f"  rate {np.log2(r):.2f}, Richardson extrapolation: {u2 + (u2 - u1) / (r - 1):.4f}\n")


# --- inf-sup constants -------------------------------------------------------------------------

def inf_sup(mesh, held) -> tuple[int, float]:
    """(number of spurious pressure modes, smallest non-zero inf-sup constant) of P2/P0.

    beta^2 is the smallest non-zero eigenvalue of B A^-1 B^T against the P0 mass,
    A the vector Laplacian (the H1 seminorm) on the free DOFs, B the element divergences.
    """
    import scipy.linalg as sla
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla
    from fem_elastic.discretization import Discretization

    s = Discretization(mesh, 2)
    free = ~held(s)
    Ke = np.einsum("ajeq,bjeq,eq->abe", s.dN, s.dN, s.dx)
    nodes = s.element_dofs[0::3] // 3
    rows = np.broadcast_to(nodes[:, None, :], Ke.shape).ravel()
    cols = np.broadcast_to(nodes[None, :, :], Ke.shape).ravel()
    L = sp.csr_matrix((Ke.ravel(), (rows, cols)), shape=(s.ndofs // 3,) * 2)
    A = sp.kron(L, sp.eye(3)).tocsr()  # DOF 3 node + component
    b = np.einsum("aieq,eq->aie", s.dN, s.dx).reshape(3 * s.nloc, -1)  # int_e div N_ai
    ne = b.shape[1]
    B = sp.csr_matrix((b.T.ravel(), (np.repeat(np.arange(ne), 3 * s.nloc), s.element_dofs.T.ravel())),
                      shape=(ne, s.ndofs))[:, free]
    S = B @ spla.splu(A[free][:, free].tocsc()).solve(B.T.toarray())
    w = np.sort(sla.eigh(S, np.diag(s.dx.sum(axis=1)), eigvals_only=True))
    zero = w <= 1e-10 * w[-1]
    return int(zero.sum()), float(np.sqrt(w[~zero][0]))


def infsup_table() -> None:
    def cook_held(s):
        held = np.zeros(s.ndofs, dtype=bool)
        held[s.node_dofs(s.scalar_basis.get_dofs(s.mesh.boundaries["left"]).all())] = True
        for face in ("front", "back"):
            held[3 * np.asarray(s.scalar_basis.get_dofs(s.mesh.boundaries[face]).all()) + 2] = True
        return held

    def clamped(s):
        held = np.zeros(s.ndofs, dtype=bool)
        held[s.node_dofs(s.scalar_basis.get_dofs(s.mesh.boundary_facets()).all())] = True
        return held

    print("Discrete inf-sup constant of P2 displacement / P0 pressure (H1 seminorm):")
    for n in (2, 4, 8, 12):
        modes, beta = inf_sup(cook_membrane_mesh(cells=(n, n)), cook_held)
        print(f"  Cook slab {n:>2} x {n:<2}: beta = {beta:.4f}, beta x cells = {beta * n:.3f}, "
              f"spurious pressure modes {modes}", flush=True)
    for n in (2, 3, 4, 5):
        modes, beta = inf_sup(fe.beam_mesh(1.0, 1.0, 1.0, cells=(n, n, n)), clamped)
        print(f"  clamped unit cube {n}^3: beta = {beta:.4f}, beta x cells = {beta * n:.3f}, "
              f"zero modes {modes} (the constant pressure is one)", flush=True)
    print("beta ~ 1/cells on these structured meshes: P2/P0 is not uniformly stable on tets.\n"
          "(Taylor-Hood P2/P1 on the same cubes: beta = 0.17, 0.21, 0.22, 0.22.)")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cells", type=int, nargs="+", default=None,
                        help="cells along each side of the panel, one mesh per value "
                             "(default 2 4 8 16 32)")
    parser.add_argument("--nu", type=float, default=0.4999)
    parser.add_argument("--material", choices=["linear", "neohookean"], default="linear")
    parser.add_argument("--reference", action="store_true",
                        help="recompute the reference with 2-D Taylor-Hood elements")
    parser.add_argument("--fine", action="store_true", help="with --reference: P2/P1 up to 128 cells")
    parser.add_argument("--infsup", action="store_true", help="print P2/P0 inf-sup constants")
    args = parser.parse_args(argv)
    if args.reference:
        reference(args.fine)
    if args.infsup:
        infsup_table()
    if args.cells is not None or not (args.reference or args.infsup):
        table(args.cells or [2, 4, 8, 16, 32], args.nu, args.material)


if __name__ == "__main__":
    main()
