"""Model construction: fixed DOFs, loads built only when asked for, bad input."""

import numpy as np
import pytest

import fem_elastic as fe


def make(**kw):
    args = dict(density=1000.0, body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)), fixed="left")
    args.update(kw)
    mesh = args.pop("mesh", fe.beam_mesh(cells=(4, 2, 2)))
    return fe.Model(mesh, **args)


def test_lean_model_builds_no_load_terms():
    model = make()
    assert model.loads == () and len(model.potentials) == 1
    np.testing.assert_array_equal(model.external_force(), 0.0)


def test_loads_are_added_when_asked():
    model = make(gravity=(0, 0, -9.81), traction={"right": (0, 0, -1.0), "top": (0, 0, -2.0)})
    assert len(model.loads) == 3


@pytest.mark.parametrize("order", [1, 2])
def test_fixed_boundary_includes_all_face_nodes(order):
    model = make(body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3), order=order))
    on_left = np.isclose(model.X, 0.0) & (np.arange(model.ndofs) % 3 == 0)
    nodes_left = np.flatnonzero(on_left) // 3
    expected = np.sort(np.concatenate([3 * nodes_left + i for i in range(3)]))
    np.testing.assert_array_equal(model.fixed_dofs, expected)
    assert model.free.sum() == model.ndofs - expected.size


@pytest.mark.parametrize("order", [1, 2])
def test_fixed_by_vertex_indices_and_mask_agree_with_boundary(order):
    mesh = fe.beam_mesh(cells=(4, 2, 2))
    body = fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3), order=order)
    left = np.flatnonzero(np.isclose(mesh.p[0], 0.0))
    by_name = make(mesh=mesh, body=body).fixed_dofs
    by_index = make(mesh=mesh, body=body, fixed=left).fixed_dofs
    mask = np.zeros(mesh.p.shape[1], dtype=bool)
    mask[left] = True
    by_mask = make(mesh=mesh, body=body, fixed=mask).fixed_dofs
    np.testing.assert_array_equal(by_name, by_index)
    np.testing.assert_array_equal(by_name, by_mask)


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(density=0.0), "density"),
        (dict(density=float("nan")), "density"),
        (dict(density="heavy"), "density"),
        (dict(fixed="lefft"), r"'lefft'.*boundaries"),
        (dict(fixed=[10**6]), "vertex indices"),
        (dict(fixed=np.ones(3, dtype=bool)), "one entry per vertex"),
        (dict(fixed=[0.5]), "boundary name"),
        (dict(body=fe.LinearElastic(E=1e6, nu=0.3)), "ElasticBody"),
        (dict(traction={"right": (0, 1)}), "three"),
    ],
)
def test_bad_input_raises_invalid_parameter(kw, match):
    with pytest.raises(fe.InvalidParameter, match=match):
        make(**kw)


def test_bad_mesh_raises_invalid_mesh():
    from skfem import MeshHex

    with pytest.raises(fe.InvalidMesh):
        make(mesh=MeshHex())


def test_under_constrained_messages():
    with pytest.raises(fe.UnderConstrained, match="fixes nothing"):
        make(fixed=None).check_supported()
    mesh = fe.beam_mesh(cells=(4, 2, 2))
    # the vertices on one edge of the beam: a line, so the rotation about it stays free
    line = np.flatnonzero(np.isclose(mesh.p[1], 0) & np.isclose(mesh.p[2], 0))
    with pytest.raises(fe.UnderConstrained, match="1 rigid-body mode"):
        make(mesh=mesh, fixed=line).check_supported()
    make(mesh=mesh).check_supported()  # a whole face: no error


def test_one_fixed_vertex_leaves_three_rotations_free():
    # three fixed DOFs give only three singular values: the rank, not the count of small
    # values, tells how many of the six modes are held
    with pytest.raises(fe.UnderConstrained, match="3 rigid-body mode"):
        make(fixed=[0]).check_supported()
    with pytest.raises(fe.UnderConstrained, match="fixes nothing"):
        make(fixed=[]).check_supported()


def test_model_arrays_are_read_only():
    model = make()
    with pytest.raises(ValueError):
        model.free[0] = False
    with pytest.raises(ValueError):
        model.fixed_dofs[0] = 1


@pytest.mark.parametrize("order", [1, 2])
def test_model_mass_is_the_body_mass(order):
    model = make(body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3), order=order))
    volume = 1.0 * 0.1 * 0.1  # beam_mesh defaults (m^3)
    ones = np.ones(model.ndofs)
    # three components each carry the whole mass rho V (kg), exactly up to round-off
    np.testing.assert_allclose(ones @ model.mass_matrix @ ones, 3 * 1000.0 * volume, rtol=1e-12)
    np.testing.assert_allclose(model.lumped_mass.sum(), 3 * 1000.0 * volume, rtol=1e-12)
