"""The memory estimate of fem_elastic.resources against what building a model takes.

For beam meshes of P1 and P2 tets: tracemalloc's peak while building a Model and
linearizing it once, the nonzeros of its tangent, and SuperLU's fill (nnz of L + U)
on the free DOFs; beside them what ``model_memory`` estimates for the path that ran: the
per-tet constants ``FUSED_BYTES_PER_TET`` (numba's fused kernels) or, with
``FEM_ELASTIC_NUMBA=0``, ``BYTES_PER_TET`` (the numpy path), and ``NNZ_PER_TET`` come
from these figures.

    .venv/bin/python scripts/bench_memory_estimate.py
    FEM_ELASTIC_NUMBA=0 .venv/bin/python scripts/bench_memory_estimate.py   # the numpy path
"""

from __future__ import annotations

import tracemalloc

import scipy.sparse.linalg as sla

import fem_elastic as fe
from fem_elastic.discretization import fused
from fem_elastic.resources import format_bytes, model_memory


def main() -> None:
    print(f"tangent assembled by the {'fused kernels' if fused.available() else 'numpy path'}")
    for order in (1, 2):  # once per process, not per tet: loading numba's compiled kernels
        warm = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1000.0,
                        body=fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3), order=order), fixed="left")
        warm.linearize(warm.X)
    print(f"{'mesh':<14}{'order':>6}{'tets':>8}{'ndof':>8}{'peak':>12}{'peak/tet':>10}{'estimate':>12}"
          f"{'nnz/tet':>9}{'LU fill/nnz':>13}{'LU est./fill':>14}")
    for cells, order in [((20, 4, 4), 1), ((40, 6, 6), 1), ((10, 3, 3), 2), ((20, 4, 4), 2)]:
        mesh = fe.beam_mesh(cells=cells)
        nt, nv = mesh.t.shape[1], mesh.p.shape[1]
        tracemalloc.start()
        model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3), order=order),
                         fixed="left")
        _, H = model.linearize(model.X)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        A = H[model.free][:, model.free].tocsc()
        lu = sla.splu(A)
        fill = lu.L.nnz + lu.U.nnz
        est = model_memory(nt, nv, order, "direct", fused=fused.available())
        lu_bytes = 12 * fill  # a value and an index per entry
        print(f"{str(cells):<14}{order:>6}{nt:>8}{H.shape[0]:>8}{format_bytes(peak):>12}{peak / nt:>10.0f}"
              f"{format_bytes(est['model']):>12}{H.nnz / nt:>9.1f}{fill / H.nnz:>13.2f}"
              f"{est['solver'] / lu_bytes:>14.2f}")


if __name__ == "__main__":
    main()
