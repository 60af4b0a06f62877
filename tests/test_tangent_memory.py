"""The fused P1 tangent's memory (issue 19, the peak-memory row): a (ne, 4, 4) block-offset map
into the CSR data instead of (ne, 12, 12) entry maps, and no int64 ``scatter`` unless the numpy
assembly asks for it."""

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.discretization import fused
from fem_elastic.discretization.space import SparsityPattern

pytestmark = pytest.mark.skipif(not fused.available(), reason="numba is not importable")


def _model():
    return fe.Model(fe.beam_mesh(cells=(4, 2, 2)), density=1000.0,
                    body=fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.4)), fixed="left")


def _bent(model):
    X = model.X.reshape(-1, 3)
    u = np.zeros_like(X)
    u[:, 2] = 0.05 * X[:, 0] ** 2
    u[:, 0] = -0.1 * (X[:, 2] - 0.05) * X[:, 0]  # some compression: projected points
    return model.X + u.ravel()


def test_fused_tangent_builds_no_scatter_and_matches_the_numpy_assembly(monkeypatch):
    model = _model()
    x = _bent(model)
    pattern = model.space.pattern
    H = model.body_potential.hessian(x, project=True)
    assert "scatter" not in pattern.__dict__  # the cached property was never built
    from fem_elastic.discretization import _fused_tangent_kernels as tk

    off = tk.element_offsets(pattern, fused._geometry(model.space).nodes)
    assert off.shape == (model.space.dx.shape[0], 4, 4) and off.dtype == np.int32
    monkeypatch.setenv(fused.ENV, "0")  # the numpy path: builds scatter on first use
    H_np = model.body_potential.hessian(x, project=True)
    assert "scatter" in pattern.__dict__
    # the same entries; the two paths round differently (a few ulps of the largest entry)
    assert np.abs(H.data - H_np.data).max() <= 1e-12 * np.abs(H_np.data).max()


def test_block_offsets_place_every_entry_where_scatter_does():
    model = _model()
    pattern = model.space.pattern
    from fem_elastic.discretization import _fused_tangent_kernels as tk

    nodes = fused._geometry(model.space).nodes
    off = tk.element_offsets(pattern, nodes)
    ne = nodes.shape[0]
    scatter = pattern.scatter.reshape(4, 3, 4, 3, ne)  # (a, i, b, k, e)
    a, i, b, k, e = np.meshgrid(*(np.arange(n) for n in (4, 3, 4, 3, ne)), indexing="ij")
    pos = pattern.indptr[3 * nodes[e, a] + i] + off[e, a, b] + k
    assert np.array_equal(pos, scatter)


def test_block_offsets_refuse_a_pattern_of_other_elements():
    model = _model()
    from fem_elastic.discretization import _fused_tangent_kernels as tk

    nodes = fused._geometry(model.space).nodes
    other = SparsityPattern(model.space.element_dofs[:, :1], model.ndofs)  # one element only
    with pytest.raises(ValueError, match="another discretization"):
        tk.element_offsets(other, nodes)
