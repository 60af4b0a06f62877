"""Component-wise supports and prescribed displacements (issue 15, items 1-2).

Analytic checks: the uniaxial bar on rollers (sigma = E eps exactly, lateral
contraction -nu eps), a symmetric quarter model equal to the full model on a
mirrored mesh, and patch tests with prescribed displacements through
solve_static (a linear field reproduced exactly by P1 and P2).
"""

import numpy as np
import pytest
from skfem import MeshTet

import fem_elastic as fe

E, NU = 1.0e6, 0.3


def linear(order=1, E=E, nu=NU):
    return fe.ElasticBody(fe.LinearElastic(E=E, nu=nu), order=order)


def model(mesh=None, body=None, **kw):
    return fe.Model(mesh if mesh is not None else fe.beam_mesh(cells=(4, 1, 1)), 1000.0,
                    body if body is not None else linear(), **kw)


# -- the forms of fixed ----------------------------------------------------------------------------
@pytest.mark.parametrize("order", [1, 2])
def test_components_select_the_dofs_of_each_node(order):
    m = model(body=linear(order), fixed={"left": "xz", "bottom": (False, True, False)})
    X = m.X.reshape(-1, 3)
    comp = np.arange(m.ndofs) % 3
    node = np.arange(m.ndofs) // 3
    left = np.isclose(X[node, 0], 0.0)
    bottom = np.isclose(X[node, 2], 0.0)
    expected = np.flatnonzero((left & (comp != 1)) | (bottom & (comp == 1)))
    np.testing.assert_array_equal(m.fixed_dofs, expected)
    assert (~m.free).sum() == expected.size


def test_all_forms_of_fixed_agree():
    mesh = fe.beam_mesh(cells=(4, 2, 2))
    left = np.flatnonzero(np.isclose(mesh.p[0], 0.0))
    mask = np.isclose(mesh.p[0], 0.0)
    ref = model(mesh, fixed="left").fixed_dofs
    for fixed in ({"left": "xyz"}, {"left": (True, True, True)}, [(left, "xyz")], [(mask, "zyx")],
                  {tuple(left.tolist()): "xyz"}, {("left",): "xyz"}):
        np.testing.assert_array_equal(model(mesh, fixed=fixed).fixed_dofs, ref)


@pytest.mark.parametrize("fixed, match", [
    ({"left": "w"}, r'"x", "yz"|"xyz"'),
    ({"left": True}, "bool triple"),
    ({"left": (1, 0, 0)}, "bool triple"),
    ({"left": ""}, "components held"),
    ({"left": (False, False, False)}, "holds no component"),
    ({"left": "xx"}, "components held"),
    ({"lefft": "x"}, r"'lefft'.*boundaries"),
    ({3.5: "x"}, "mapping from any of these"),
    ({"left"}, "mapping from any of these"),
])
def test_bad_fixed_is_a_typed_error_naming_the_forms(fixed, match):
    with pytest.raises(fe.InvalidParameter, match=match):
        model(fixed=fixed)


def test_a_dict_of_components_is_no_longer_read_as_its_keys():
    # the old silent bug: {"left": (True, False, False)} clamped all three components
    m = model(fixed={"left": (True, False, False)})
    assert np.all(m.fixed_dofs % 3 == 0)


def test_rollers_alone_are_under_constrained_and_the_free_modes_are_named():
    with pytest.raises(fe.UnderConstrained, match=r"3 rigid-body mode\(s\) free: translation along y; "
                       r"translation along z; rotation about x\."):
        model(fixed={"left": "x"}).check_supported()
    with pytest.raises(fe.UnderConstrained, match="1 rigid-body mode.*translation along z"):
        fe.solve_static(model(fixed={"left": "x", "front": "y"}, gravity=(0, 0, -9.81)))
    with pytest.raises(fe.UnderConstrained, match="rotation about every axis through"):
        model(fixed=[0]).check_supported()
    model(fixed={"left": "x", "front": "y", "bottom": "z"}).check_supported()  # enough


# -- plane strain and held DOFs everywhere ------------------------------------------------------------
def test_plane_strain_slab_holds_uz_on_both_faces():
    mesh = fe.beam_mesh(1.0, 1.0, 0.1, cells=(4, 4, 1))
    m = model(mesh, linear(2), fixed={"left": "xyz", "bottom": "z", "top": "z"},
              traction={"right": (0.0, -100.0, 0.0)})
    res = fe.solve_static(m)
    assert res.converged and res.stable
    np.testing.assert_array_equal(res.displacement[:, 2], 0.0)
    assert res.displacement[:, 1].min() < -1e-4


@pytest.mark.filterwarnings("ignore::fem_elastic.StabilityWarning")  # explicit Euler, undamped: by design
def test_held_components_work_in_modal_analysis_and_every_integrator():
    m = model(fe.beam_mesh(cells=(6, 1, 1)), fixed={"left": "xyz", "front": "y"},
              displacement={"right": (0.002, None, None)}, gravity=(0.0, 0.0, -9.81))
    held = ~m.free
    f = fe.natural_frequencies(m, 3)
    assert np.all(f > 0)
    dt = 0.5 * fe.critical_time_step(m, fe.SymplecticEuler())
    s0 = fe.State.rest(m)
    np.testing.assert_allclose((s0.x - m.X)[m.prescribed_dofs], 0.002)
    for integ in (fe.ExplicitEuler(), fe.SymplecticEuler(), fe.Midpoint(), fe.RK4(), fe.ImplicitEuler(),
                  fe.LinearizedImplicitEuler(), fe.Newmark()):
        traj = fe.simulate(m, integ, dt, steps=5, state=s0)
        x = traj.final_state.x
        np.testing.assert_array_equal(x[m.fixed_dofs], m.X[m.fixed_dofs])
        np.testing.assert_allclose(x[m.prescribed_dofs] - m.X[m.prescribed_dofs], 0.002, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(traj.final_state.v[held], 0.0)


def test_driven_motion_keeps_working_beside_component_wise_supports():
    m = model(fe.beam_mesh(cells=(6, 1, 1)), fixed={"left": "xyz", "front": "y"},
              driven={"right": fe.Translate((0.0, 0.0, -0.01), duration=0.1)})
    dofs, x, v = m.constraints(0.1)
    front_right = np.intersect1d(m.fixed_dofs, m.driven[0][2].ravel())
    assert front_right.size and np.all(front_right % 3 == 1)  # y of the shared edge stays fixed
    z = m.driven[0][2][:, 2]
    np.testing.assert_allclose(x[np.isin(dofs, z)] - m.X[z], -0.01)
    assert not m.free[m.driven[0][2][:, 0]].any()


# -- prescribed displacements --------------------------------------------------------------------
def test_fixed_and_prescribed_in_one_component_is_an_error_naming_both():
    with pytest.raises(fe.InvalidParameter, match=r"'right'.*'x'.*fixed 'front'"):
        model(fixed={"left": "x", "front": "xy"}, displacement={"right": (0.01, None, None)})
    # other components of the shared nodes are fine
    model(fixed={"left": "x", "front": "y", "bottom": "z"}, displacement={"right": (0.01, None, None)})


@pytest.mark.parametrize("displacement, match", [
    ({"right": (0.01, None)}, "three components"),
    ({"right": (None, None, None)}, "prescribes no component"),
    ({"right": ("a", None, None)}, "must be a number"),
    ({"right": (float("nan"), None, None)}, "finite"),
    ([0.01, 0.0, 0.0], "mapping"),
    ({"right": lambda X: X[:, :2]}, "shape"),
])
def test_bad_displacement_is_a_typed_error(displacement, match):
    with pytest.raises(fe.InvalidParameter, match=match):
        model(fixed="left", displacement=displacement)


@pytest.mark.parametrize("order", [1, 2])
def test_uniaxial_bar_on_rollers_is_exact(order):
    """sigma = E eps exactly and the lateral contraction is -nu eps, at every node."""
    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells=(6, 1, 1))
    eps = 0.01
    m = model(mesh, linear(order), fixed={"left": "x", "front": "y", "bottom": "z"},
              displacement={"right": (eps * 1.0, None, None)})
    res = fe.solve_static(m)
    X = mesh.p.T
    u = res.displacement
    np.testing.assert_allclose(u[:, 0], eps * X[:, 0], rtol=0, atol=1e-14)
    np.testing.assert_allclose(u[:, 1], -NU * eps * X[:, 1], rtol=0, atol=1e-14)
    np.testing.assert_allclose(u[:, 2], -NU * eps * X[:, 2], rtol=0, atol=1e-14)
    area = 0.1 * 0.1
    np.testing.assert_allclose(res.reaction_force("right"), [E * eps * area, 0.0, 0.0], rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(res.reaction_force("left"), [-E * eps * area, 0.0, 0.0], rtol=1e-10, atol=1e-9)


def _distorted_box(order_seed=0):
    mesh = fe.beam_mesh(1.0, 1.0, 1.0, cells=(3, 3, 3))
    p = mesh.p.copy()
    inner = np.all((p > 1e-9) & (p < 1 - 1e-9), axis=0)
    p[:, inner] += np.random.default_rng(order_seed).uniform(-0.08, 0.08, (3, int(inner.sum())))
    return MeshTet(p, mesh.t).with_boundaries({
        "left": lambda x: np.isclose(x[0], 0.0), "right": lambda x: np.isclose(x[0], 1.0),
        "front": lambda x: np.isclose(x[1], 0.0), "back": lambda x: np.isclose(x[1], 1.0),
        "bottom": lambda x: np.isclose(x[2], 0.0), "top": lambda x: np.isclose(x[2], 1.0),
    })


@pytest.mark.parametrize("order", [1, 2])
def test_patch_test_with_prescribed_displacements(order):
    """A linear field u = A X + b prescribed on the whole boundary is reproduced exactly inside."""
    A = np.array([[1.0, 0.4, -0.2], [0.3, -0.5, 0.1], [-0.2, 0.2, 0.6]]) * 1e-3
    b = np.array([1e-3, -2e-3, 5e-4])

    def field(X):
        return X @ A.T + b

    mesh = _distorted_box()
    faces = ("left", "right", "front", "back", "bottom", "top")
    m = model(mesh, linear(order), displacement={faces: field})
    res = fe.solve_static(m, steps=2)
    assert res.converged and m.free.any()
    exact = field(m.X.reshape(-1, 3)).ravel()
    np.testing.assert_allclose(res.x - m.X, exact, rtol=0, atol=1e-14)
    np.testing.assert_allclose(res.path[1].x - m.X, 0.5 * exact, rtol=0, atol=1e-14)
    # a homogeneous stress: the boundary reactions balance to zero in total
    np.testing.assert_allclose(res.reactions.sum(axis=0), 0.0, atol=1e-9)


def _mirror(mesh, axis, plane):
    """The mesh and its mirror image in ``x[axis] = plane``, merged on the plane."""
    p = mesh.p
    q = p.copy()
    q[axis] = 2 * plane - q[axis]
    n = p.shape[1]
    P = np.hstack([p, q])
    T = np.hstack([mesh.t, mesh.t[[0, 1, 3, 2]] + n])  # a reflection flips the orientation
    key = np.round(P.T / 1e-9).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return MeshTet(P[:, first], inv.ravel()[T])


@pytest.mark.parametrize("order", [1, 2])
def test_symmetric_quarter_model_equals_the_full_model(order):
    L, w, h = 1.0, 0.2, 0.2
    quarter_mesh = fe.beam_mesh(L, w / 2, h / 2, cells=(6, 1, 1))
    full_mesh = _mirror(_mirror(quarter_mesh, 1, w / 2), 2, h / 2).with_boundaries({
        "left": lambda x: np.isclose(x[0], 0.0), "right": lambda x: np.isclose(x[0], L)})
    body = fe.ElasticBody(fe.NeoHookean(E=E, nu=NU), order=order)
    t = (2e5, 0.0, 0.0)  # a 20 % stretch: nonlinear, and non-uniform near the clamp
    full = fe.solve_static(model(full_mesh, body, fixed="left", traction={"right": t}))
    quarter = fe.solve_static(model(quarter_mesh, body, fixed={"left": "xyz", "back": "y", "top": "z"},
                                    traction={"right": t}))
    # match the quarter's vertices to the full mesh's
    key = lambda P: [tuple(r) for r in np.round(P.T / 1e-9).astype(np.int64)]  # noqa: E731
    index = {k: i for i, k in enumerate(key(full_mesh.p))}
    at = np.array([index[k] for k in key(quarter_mesh.p)])
    scale = np.abs(full.displacement).max()
    np.testing.assert_allclose(quarter.displacement, full.displacement[at], rtol=0, atol=1e-9 * scale)
    # the axial reaction is four times the quarter's (its lateral ones cancel by symmetry)
    np.testing.assert_allclose(4 * quarter.reaction_force("left")[0], full.reaction_force("left")[0],
                               rtol=1e-8)
    np.testing.assert_allclose(full.reaction_force("left")[0], -t[0] * w * h, rtol=1e-8)


@pytest.mark.parametrize("order", [1, 2])
def test_facet_nodes_and_edges_are_scikit_fems(order):
    # The space finds a face's nodes and edges by searching scikit-fem's sorted edge list
    # (instead of its facet-to-edge map): the same sets as scikit-fem's own get_dofs and f2e,
    # on a structured beam and on an unstructured mesh (random vertex numbering)
    from fem_elastic.discretization.space import Discretization

    rng = np.random.default_rng(3)
    beam = fe.beam_mesh(0.5, 0.2, 0.1, cells=(4, 3, 2))
    perm = rng.permutation(beam.p.shape[1])  # renumber the vertices: edges no longer grid-ordered
    inv = np.empty_like(perm)
    inv[perm] = np.arange(perm.size)
    shuffled = MeshTet(beam.p[:, perm], inv[beam.t])
    for mesh in (beam, shuffled):
        space = Discretization(mesh, order)
        assert space._edge_keys is not None  # the sorted-list path, not the fallback
        facets = mesh.boundary_facets()
        for chosen in (facets, facets[:5], facets[rng.permutation(facets.size)[:17]]):
            expected = np.unique(np.asarray(space.scalar_basis.get_dofs(chosen).all()))
            np.testing.assert_array_equal(space.facet_nodes(chosen), expected)
            np.testing.assert_array_equal(np.sort(space.facet_edges(chosen), axis=0),
                                          np.sort(np.asarray(mesh.f2e)[:, chosen], axis=0))


@pytest.mark.parametrize("order", [1, 2])
def test_a_boundary_stored_as_a_facet_mask_is_its_facets(order):
    # scikit-fem accepts a boolean mask over the facets as a named boundary: supports and
    # tractions on it act on the facets it marks (not on facets 0 and 1)
    beam = fe.beam_mesh(0.5, 0.1, 0.1, cells=(4, 2, 2))
    mask = np.zeros(beam.facets.shape[1], dtype=bool)
    mask[beam.boundaries["left"]] = True
    mesh = beam.with_boundaries({"left_mask": mask})
    body = fe.ElasticBody(fe.LinearElastic(1e6, 0.3), order=order)
    by_index = fe.Model(mesh, 1000.0, body, fixed="left", traction={"left": (0.0, 0.0, 1.0)})
    by_mask = fe.Model(mesh, 1000.0, body, fixed="left_mask", traction={"left_mask": (0.0, 0.0, 1.0)})
    np.testing.assert_array_equal(by_mask.free, by_index.free)
    np.testing.assert_array_equal(by_mask.external_force(), by_index.external_force())


def test_a_curved_mesh_is_refused_with_the_fix():
    # the model refuses it when it validates the mesh; the space itself does too (it has no
    # vertex map for a mesh whose points include the edge nodes)
    from skfem import MeshTet2

    from fem_elastic.discretization.space import Discretization

    curved = MeshTet2.init_tensor(*(np.linspace(0.0, 1.0, 3),) * 3)
    with pytest.raises(fe.InvalidMesh, match="MeshTet2.*order=2"):
        Discretization(curved, 2)
    with pytest.raises(fe.InvalidMesh, match="MeshTet2"):
        fe.Model(curved, 1000.0, fe.ElasticBody(fe.LinearElastic(1e6, 0.3), order=2), fixed="left")
