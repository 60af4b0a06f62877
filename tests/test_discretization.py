"""Tests of fem_elastic.discretization: F of affine fields, rigid-body modes, DOF maps."""

import numpy as np
import pytest
import scipy.sparse as sp
import skfem

import fem_elastic as fe
from fem_elastic.discretization import Discretization
from fem_elastic.physics.elastic_body import ElasticPotential

ORDERS = [1, 2]


def distorted_mesh():
    """A 0.3 x 0.2 x 0.1 m box of 36 tets with every vertex moved by up to 0.02 m."""
    mesh = fe.beam_mesh(0.3, 0.2, 0.1, cells=(3, 2, 1))
    rng = np.random.default_rng(0)
    mesh = skfem.MeshTet(mesh.p + rng.uniform(-0.02, 0.02, mesh.p.shape), mesh.t)
    fe.validate_mesh(mesh)
    return mesh


@pytest.fixture(scope="module", params=ORDERS, ids=["P1", "P2"])
def space(request):
    return Discretization(distorted_mesh(), request.param)


def test_shapes_and_quadrature(space):
    ne = space.mesh.t.shape[1]
    nloc = {1: 4, 2: 10}[space.order]
    assert space.nloc == nloc
    assert space.dN.shape[:3] == (nloc, 3, ne) and space.dx.shape == (ne, space.dN.shape[3])
    assert space.element_dofs.shape == (3 * nloc, ne)
    # the weights integrate the volume; the shape-function gradients sum to zero
    assert np.isclose(space.dx.sum(), fe.signed_volumes(space.mesh).sum(), rtol=1e-13)
    assert np.abs(space.dN.sum(axis=0)).max() <= 1e-12 * np.abs(space.dN).max()


def test_deformation_gradient_of_affine_field_is_exact(space):
    # P1 and P2 both reproduce affine fields exactly, on any straight-sided tet
    rng = np.random.default_rng(1)
    A, b = 0.3 * rng.standard_normal((3, 3)), rng.standard_normal(3)
    u = (space.X.reshape(-1, 3) @ A.T + b).ravel()
    F = space.deformation_gradient(u)
    assert F.shape == (3, 3) + space.dx.shape
    expected = (np.eye(3) + A)[:, :, None, None]
    assert np.abs(F - expected).max() <= 1e-12


def test_rigid_body_modes_are_in_the_kernel_of_linear_stiffness(space):
    K = ElasticPotential(fe.LinearElastic(E=1.0e6, nu=0.3), space).hessian(space.X)
    B = space.rigid_body_modes()
    assert B.shape == (space.ndofs, 6)
    assert np.linalg.matrix_rank(B) == 6
    # ||K B|| relative to ||K|| ||B||: round-off level (a non-rigid mode gives O(1e-2..1))
    ratio = np.abs(K @ B).max(axis=0) / (sp.linalg.norm(K, np.inf) * np.abs(B).max(axis=0))
    assert ratio.max() <= 1e-13
    # and a stretch is not in the kernel
    stretch = (space.X.reshape(-1, 3) * np.array([1.0, 0.0, 0.0])).ravel()
    assert np.abs(K @ stretch).max() / (sp.linalg.norm(K, np.inf) * np.abs(stretch).max()) > 1e-3


def test_rigid_body_rotations_are_about_the_center(space):
    c = np.array([0.1, -0.2, 0.3])
    B = space.rigid_body_modes(center=c)
    r = space.X.reshape(-1, 3) - c
    for k in range(3):
        omega = np.eye(3)[k]
        np.testing.assert_allclose(B[:, 3 + k].reshape(-1, 3), np.cross(omega, r), atol=1e-15)


def test_X_matches_vertices_and_edge_midpoints(space):
    mesh = space.mesh
    assert space.vertex_dofs.shape == (mesh.p.shape[1], 3)
    # scikit-fem's doflocs map the reference nodes through each element's affine map, so
    # they match the mesh vertices to a few ulps, not bit for bit
    ulps = 4 * np.finfo(float).eps * np.abs(mesh.p).max()
    np.testing.assert_allclose(space.X[space.vertex_dofs], mesh.p.T, rtol=0, atol=ulps)
    if space.order == 2:
        edge_dofs = np.asarray(space.basis.edge_dofs).T  # (nedges, 3)
        midpoints = 0.5 * (mesh.p[:, mesh.edges[0]] + mesh.p[:, mesh.edges[1]]).T
        np.testing.assert_allclose(space.X[edge_dofs], midpoints, rtol=0, atol=ulps)
    # node-major interleaved order: DOF 3 n + i is component i of node n
    assert np.array_equal(space.vertex_dofs, 3 * (space.vertex_dofs[:, :1] // 3) + np.arange(3))


def test_to_vertices(space):
    ulps = 4 * np.finfo(float).eps * np.abs(space.mesh.p).max()
    np.testing.assert_allclose(space.to_vertices(space.X), space.mesh.p.T, rtol=0, atol=ulps)
    v = np.random.default_rng(2).standard_normal(space.ndofs)
    out = space.to_vertices(v)
    assert out.shape == (space.mesh.p.shape[1], 3)
    np.testing.assert_array_equal(out, v[space.vertex_dofs])


def test_scatter_is_the_transpose_of_gather(space):
    rng = np.random.default_rng(3)
    u = rng.standard_normal(space.ndofs)
    f_e = rng.standard_normal((space.nloc, 3, space.mesh.t.shape[1]))
    assert np.isclose(space.scatter(f_e) @ u, np.sum(f_e * space.gather(u)), rtol=1e-13)


@pytest.mark.parametrize("order", [0, 3, -1, 1.5, "1", None])
def test_invalid_order_raises(order):
    with pytest.raises(fe.InvalidParameter, match="order"):
        Discretization(fe.beam_mesh(cells=(1, 1, 1)), order)


def test_non_tet_mesh_raises():
    with pytest.raises(fe.InvalidMesh, match="tetrahedral"):
        Discretization(skfem.MeshHex(), 1)


@pytest.mark.parametrize("order", [1, 2])
def test_scalar_built_dof_maps_equal_scikit_fems_vector_basis(order):
    # the kernels never build the vector basis; their DOF tables must be its tables
    space = Discretization(fe.beam_mesh(cells=(3, 2, 1)), order)
    vb = space.basis
    np.testing.assert_array_equal(space.element_dofs, vb.element_dofs)
    assert space.ndofs == vb.N
    np.testing.assert_array_equal(space.vertex_dofs, np.asarray(vb.nodal_dofs).T)
    dofs = np.arange(space.ndofs)
    # doflocs agree to a few ulps (scikit-fem maps the reference nodes per element)
    np.testing.assert_allclose(space.X, np.asarray(vb.doflocs)[dofs % 3, dofs], rtol=0, atol=1e-15)


def test_pattern_diagonal_positions_hold_the_diagonal(space):
    # found from each node's rank in its node-graph row: the entries there are (d, d)
    p = space.pattern
    d = p.diagonal_positions
    rows = np.repeat(np.arange(p.shape[0]), np.diff(p.indptr))
    assert d.shape == (p.shape[0],)
    np.testing.assert_array_equal(rows[d], np.arange(p.shape[0]))
    np.testing.assert_array_equal(p.indices[d], np.arange(p.shape[0]))
