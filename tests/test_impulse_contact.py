"""Impulse collisions (the lecture notes' response) and the bounding-sphere broad phase."""

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.physics.broad_phase import BoundingSpheres, sphere_pairs, triangle_spheres
from fem_elastic.physics.collision_surface import CollisionSurface, _edges_of
from fem_elastic.physics.impulse_contact import (
    BoundImpulseContact,
    RestContactWarning,
    ImpulseContact,
    closest_point_triangle,
    collide_particles,
)

#: momentum is conserved by construction (equal and opposite impulses): what is left is the
#: round-off of a few additions of terms of size m |v|, a few ulps of that size
ROUNDOFF = 1e-14


def _pair(e=0.5, mu=0.0, v1=(1.0, 0.0, 0.0), v2=(-2.0, 0.0, 0.0), m=(1.0, 3.0)):
    """Two overlapping particles of radius 0.1 m along a tilted line of centres."""
    n = np.array([1.0, 2.0, 2.0]) / 3.0
    x = np.array([[0.1, -0.2, 0.3], [0.1, -0.2, 0.3]]) + np.outer([0.0, 0.19], n)
    v = np.array([v1, v2], dtype=float)
    x1, v1n = collide_particles(x, v, np.array(m), 0.1, restitution=e, friction=mu)
    return n, x, v, x1, v1n, np.array(m)


@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_head_on_particles_keep_momentum_and_scale_normal_velocity_by_e(e):
    n, x, v, x1, v1, m = _pair(e=e, v1=(1.0, 2.0, 2.0), v2=(-0.5, -1.0, -1.0))  # along n
    p0, p1 = m @ v, m @ v1
    assert np.abs(p1 - p0).max() <= ROUNDOFF * (m @ np.abs(v)).max()
    un0 = (v[1] - v[0]) @ n
    un1 = (v1[1] - v1[0]) @ n
    assert un0 < 0.0  # they approach
    assert un1 == pytest.approx(-e * un0, rel=1e-12, abs=1e-14)  # round-off of one division
    if e == 1.0:  # elastic: kinetic energy kept as well (the notes' second invariant)
        assert 0.5 * m @ (v1 ** 2).sum(1) == pytest.approx(0.5 * m @ (v ** 2).sum(1), rel=1e-12)
    # overlap removed, centre of mass kept
    assert np.linalg.norm(x1[1] - x1[0]) == pytest.approx(0.2, rel=1e-12)
    np.testing.assert_allclose(m @ x1, m @ x, rtol=0, atol=1e-15)


def test_separating_particles_are_left_alone():
    n, x, v, x1, v1, m = _pair(v1=(-1.0, 0, 0), v2=(1.0, 0, 0))
    np.testing.assert_array_equal(v1, v)


@pytest.mark.parametrize("mu, sticks", [(0.1, False), (2.0, True)])
def test_oblique_collision_coulomb_friction(mu, sticks):
    t = np.array([2.0, -1.0, 0.0]) / np.sqrt(5.0)  # a tangent of n = (1, 2, 2)/3
    n = np.array([1.0, 2.0, 2.0]) / 3.0
    va = 1.0 * t + 2.0 * n
    vb = -0.5 * t - 1.0 * n
    _, x, v, x1, v1, m = _pair(e=0.5, mu=mu, v1=va, v2=vb)
    u0, u1 = v[1] - v[0], v1[1] - v1[0]
    dvn = (u1 - u0) @ n
    assert dvn == pytest.approx(1.5 * 3.0)  # (1 + e) |u_n|, u_n = -3 m/s
    ut0, ut1 = u0 - (u0 @ n) * n, u1 - (u1 @ n) * n
    assert np.abs(m @ v1 - m @ v).max() <= ROUNDOFF * (m @ np.abs(v)).max()
    if sticks:  # mu dv_n exceeds |u_t| = 1.5 m/s: stops, does not reverse
        assert np.linalg.norm(ut1) <= 1e-14
    else:  # slides: |u_t| drops by exactly mu dv_n, same direction
        assert np.linalg.norm(ut0) - np.linalg.norm(ut1) == pytest.approx(mu * dvn, rel=1e-12)
        assert ut1 @ ut0 > 0.0


def _vertex_over_triangle(w_in=(0.2, 0.3, 0.5), depth=2e-4):
    """One free vertex just above a triangle (not incident to it), as a CollisionSurface."""
    tri = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    p = np.asarray(w_in) @ tri + np.array([0.0, 0.0, depth])
    rest = np.vstack([tri, p + np.array([0.0, 0.0, 0.1])])  # at rest the vertex is far above
    faces = np.array([[0, 1, 2]])
    surface = CollisionSurface(vertex_dofs=np.arange(12).reshape(4, 3), faces=faces,
                               edges=_edges_of(faces), body=np.zeros(4, dtype=np.int64), rest=rest)
    return surface, np.vstack([tri, p]).ravel()


@pytest.mark.parametrize("e, mu", [(0.0, 0.3), (0.5, 0.3), (0.5, 0.05)])  # sticks, sticks, slides
def test_vertex_triangle_keeps_momentum_and_removes_approach(e, mu):
    surface, x = _vertex_over_triangle()
    contact = BoundImpulseContact(ImpulseContact(restitution=e, friction=mu, thickness=1e-3), surface)
    m = np.array([1.0, 2.0, 0.5, 0.7])
    v = np.array([[0.1, 0.0, 0.5], [0.0, 0.2, 0.4], [0.0, 0.0, 0.6], [0.3, -0.1, -2.0]])
    x1, v1 = contact.respond(x, v.ravel(), m)
    v1 = v1.reshape(-1, 3)
    assert np.abs(m @ v1 - m @ v).max() <= ROUNDOFF * (m @ np.abs(v)).max()
    w = np.array([0.2, 0.3, 0.5])
    un0 = (v[3] - w @ v[:3])[2]
    un1 = (v1[3] - w @ v1[:3])[2]
    assert un0 < 0 and un1 == pytest.approx(-e * un0, rel=1e-12, abs=1e-14)
    # Coulomb: the tangential relative speed drops by mu times the normal change, or stops
    ut0 = np.linalg.norm((v[3] - w @ v[:3])[:2])
    ut1 = np.linalg.norm((v1[3] - w @ v1[:3])[:2])
    assert ut1 == pytest.approx(max(ut0 - mu * (un1 - un0), 0.0), rel=1e-12, abs=1e-14)
    P1 = x1.reshape(-1, 3)
    gap = P1[3, 2] - (w @ P1[:3])[2]
    # pushed out to the thickness: for a single contact the linearised gap is the gap (the push
    # is a translation along the face normal), so one round lands on it to round-off (measured:
    # exact); 1e-9 leaves room for the round-off of the weighted sums only
    assert gap == pytest.approx(1e-3, rel=1e-9)
    np.testing.assert_allclose(m @ P1, m @ x.reshape(-1, 3), rtol=0, atol=1e-15)
    d = contact.diagnostics(x)
    assert d["active_contacts"] == 1 and d["min_distance"] == pytest.approx(2e-4)


def test_held_vertices_do_not_move():
    surface, x = _vertex_over_triangle()
    contact = BoundImpulseContact(ImpulseContact(thickness=1e-3), surface)
    contact.held = np.array([True, True, True, False])  # a fixed triangle
    v = np.zeros((4, 3))
    v[3, 2] = -1.0
    x1, v1 = contact.respond(x, v.ravel(), np.ones(4))
    np.testing.assert_array_equal(v1[:9], 0.0)
    np.testing.assert_array_equal(x1[:9], x[:9])
    assert v1[11] == pytest.approx(0.0, abs=1e-15)


def test_a_models_fixed_vertices_are_the_held_ones():
    # the binding reads the model's held DOFs: the surface vertices of the fixed face, no other
    mesh = fe.beam_mesh(length=0.1, width=0.1, height=0.1, cells=(2, 2, 2))
    model = fe.Model(mesh, 1000.0, fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left",
                     contact=fe.ImpulseContact(thickness=1e-3))
    contact = model.contact
    on_left = contact.surface.rest[:, 0] == 0.0  # the left face is x = 0
    assert on_left.sum() == 9  # its 3 x 3 vertices
    np.testing.assert_array_equal(contact.held, on_left)


def test_closest_point_triangle_against_sampling():
    rng = np.random.default_rng(1)
    k = 200
    p, a, b, c = (rng.normal(size=(k, 3)) for _ in range(4))
    q, w = closest_point_triangle(p, a, b, c)
    assert (w >= 0).all() and np.allclose(w.sum(1), 1.0, atol=1e-15)
    np.testing.assert_allclose(q, w[:, :1] * a + w[:, 1:2] * b + w[:, 2:] * c, atol=1e-14)
    g = np.linspace(0.0, 1.0, 61)
    U, V = np.meshgrid(g, g)
    keep = U + V <= 1.0
    U, V = U[keep], V[keep]
    d = np.linalg.norm(p - q, axis=1)
    for i in range(k):
        samples = a[i] + U[:, None] * (b[i] - a[i]) + V[:, None] * (c[i] - a[i])
        # no sample of the triangle is nearer than the closest point (beyond round-off)
        assert d[i] <= np.linalg.norm(samples - p[i], axis=1).min() + 1e-12


def _brute_pairs(c1, r1, c2, r2, margin):
    d = np.linalg.norm(c1[:, None, :] - c2[None, :, :], axis=2)
    return set(zip(*np.nonzero(d < r1[:, None] + r2[None, :] + margin)))


def test_broad_phase_contains_every_brute_force_pair():
    rng = np.random.default_rng(2)
    c1, c2 = rng.random((400, 3)), rng.random((300, 3))
    r1, r2 = 0.05 * rng.random(400), 0.06 * rng.random(300)
    i, j = sphere_pairs(c1, r1, c2, r2, margin=0.01)
    brute = _brute_pairs(c1, r1, c2, r2, 0.01)
    assert set(zip(i.tolist(), j.tolist())) == brute and len(brute) > 50
    # far fewer candidates than pairs: the tree prunes
    assert len(brute) < 0.05 * 400 * 300
    i, j = BoundingSpheres(c1, r1).self_pairs(0.01)
    brute_self = {(a, b) for a, b in _brute_pairs(c1, r1, c1, r1, 0.01) if a < b}
    assert set(zip(i.tolist(), j.tolist())) == brute_self


def test_triangle_spheres_bound_their_triangles():
    rng = np.random.default_rng(3)
    points = rng.random((30, 3))
    faces = rng.integers(0, 30, size=(40, 3))
    c, r = triangle_spheres(points, faces)
    for k in range(3):
        assert (np.linalg.norm(points[faces[:, k]] - c, axis=1) <= r + 1e-15).all()


def test_particle_cloud_collisions_found_through_the_tree():
    rng = np.random.default_rng(4)
    n = 300
    x = rng.random((n, 3))
    v = rng.normal(size=(n, 3))
    m = 0.5 + rng.random(n)
    x1, v1 = collide_particles(x, v, m, 0.03, restitution=0.3, friction=0.2)
    assert np.abs(m @ v1 - m @ v).max() <= 1e-13 * (m @ np.abs(v)).max()  # many contacts
    np.testing.assert_allclose(m @ x1, m @ x, atol=1e-13)
    i, j = np.nonzero(np.triu(np.linalg.norm(x[:, None] - x[None], axis=2) < 0.06, 1))
    touched = np.unique(np.concatenate([i, j]))
    untouched = np.setdiff1d(np.arange(n), touched)
    np.testing.assert_array_equal(v1[untouched], v[untouched])  # only overlapping pairs respond


def _two_cubes(contact, offset=(0.15, 0.02, 0.03)):
    cube = fe.beam_mesh(length=0.1, width=0.1, height=0.1, cells=(2, 2, 2))
    P, T = cube.p.T, cube.t.T
    mesh = fe.mesh_from_arrays(np.vstack([P, P + np.asarray(offset)]), np.vstack([T, T + len(P)]))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
                     contact=contact)
    return model, len(P), T


def _inside(points, P, T, tol=1e-9):
    """Whether each point is strictly inside one of the tets (P, T) (barycentric > tol)."""
    A = P[T[:, 1:]] - P[T[:, :1]]  # (m, 3, 3) edge rows
    Ainv = np.linalg.inv(np.transpose(A, (0, 2, 1)))
    lam = np.einsum("mij,pmj->pmi", Ainv, points[:, None, :] - P[T[:, 0]][None])
    l0 = 1.0 - lam.sum(axis=2)
    return ((lam > tol).all(axis=2) & (l0 > tol)).any(axis=1)


def test_two_cubes_thrown_at_each_other_bounce_without_passing_through():
    # 2 cm apart, 2 m/s closing speed: 2 mm per step at dt = 1e-3 s (below the thickness, so
    # no vertex crosses a face unseen; dt is a third of the critical 2.8e-3 s)
    model, n, T = _two_cubes(fe.ImpulseContact(restitution=0.5, thickness=3e-3), offset=(0.12, 0.02, 0.03))
    v0 = np.zeros((2 * n, 3))
    v0[:n, 0], v0[n:, 0] = 1.0, -1.0
    state = fe.State(model.X.copy(), v0.ravel(), 0.0)
    p0 = model.linear_momentum(state.v)
    scale = float(model.lumped_mass @ np.abs(state.v))
    integrator = fe.SymplecticEuler()
    for _ in range(40):
        state = integrator.step(model, state, 1e-3)
        X = state.x.reshape(-1, 3)
        assert not _inside(X[:n], X[n:], T).any() and not _inside(X[n:], X[:n], T).any()
        assert np.abs(model.linear_momentum(state.v) - p0).max() <= 1e-13 * scale
    V = state.v.reshape(-1, 3)
    assert V[:n, 0].mean() < 0.0 < V[n:, 0].mean()  # they bounced
    assert model.contact.diagnostics(state.x)["min_distance"] > 0.0


@pytest.mark.parametrize("integrator", [fe.PBD(), fe.ShapeMatching()], ids=["PBD", "ShapeMatching"])
def test_position_based_methods_apply_the_impulse_contact(integrator):
    model, n, T = _two_cubes(fe.ImpulseContact(restitution=0.5, thickness=3e-3), offset=(0.12, 0.02, 0.03))
    v0 = np.zeros((2 * n, 3))
    v0[:n, 0], v0[n:, 0] = 1.0, -1.0
    state = fe.State(model.X.copy(), v0.ravel(), 0.0)
    p0 = model.linear_momentum(state.v)
    for _ in range(40):
        state = integrator.step(model, state, 1e-3)
        X = state.x.reshape(-1, 3)
        assert not _inside(X[:n], X[n:], T).any() and not _inside(X[n:], X[:n], T).any()
    V = state.v.reshape(-1, 3)
    assert V[:n, 0].mean() < 0.0 < V[n:, 0].mean()
    # the schemes' own projections keep momentum to the round-off of their sweeps (~1e-12 of
    # the 2 kg m/s here, measured); the contact adds equal and opposite impulses
    assert np.abs(model.linear_momentum(state.v) - p0).max() <= 1e-10


def test_implicit_schemes_and_statics_name_ipc_instead():
    model, _, _ = _two_cubes(fe.ImpulseContact())
    state = fe.State(model.X.copy(), np.zeros(model.ndofs), 0.0)
    for integrator in (fe.ImplicitEuler(), fe.Newmark()):
        with pytest.raises(fe.InvalidParameter, match="IPCContact"):
            integrator.step(model, state, 1e-3)
    with pytest.raises(fe.InvalidParameter, match="IPCContact"):
        fe.solve_static(model)


@pytest.mark.parametrize("kwargs, match", [
    ({"restitution": 1.5}, "restitution"), ({"restitution": -0.1}, "restitution"),
    ({"friction": -0.2}, "friction"), ({"thickness": 0.0}, "thickness"),
    ({"thickness": -1e-3}, "thickness"), ({"thickness": float("nan")}, "thickness"),
    ({"restitution": True}, "restitution"),
])
def test_bad_input_is_a_typed_error(kwargs, match):
    with pytest.raises(fe.InvalidParameter, match=match):
        fe.ImpulseContact(**kwargs)


@pytest.mark.parametrize("kwargs, match", [
    ({"restitution": 2.0}, "restitution"), ({"friction": -1.0}, "friction"),
    ({"radius": 0.0}, "radius"),
])
def test_collide_particles_bad_input(kwargs, match):
    args = dict(x=np.zeros((2, 3)), v=np.zeros((2, 3)), m=np.ones(2), radius=0.1)
    args.update(kwargs)
    with pytest.raises(fe.InvalidParameter, match=match):
        collide_particles(**args)


def test_multibody_bodies_collide_without_self_contact():
    cube = fe.beam_mesh(length=0.1, width=0.1, height=0.1, cells=(2, 2, 2))
    material = fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3))
    bodies = [fe.Body(cube, 1000.0, material, name="a", velocity=(1.0, 0.0, 0.0)),
              fe.Body(cube, 1000.0, material, name="b", translate=(0.12, 0.02, 0.03),
                      velocity=(-1.0, 0.0, 0.0))]
    model = fe.MultiBody(bodies, contact=fe.ImpulseContact(restitution=0.5, thickness=3e-3,
                                                           self_contact=False))
    state = fe.State(model.X.copy(), model.initial_velocity(), 0.0)
    p0 = model.linear_momentum(state.v)
    n = model.ndofs // 2
    for _ in range(40):
        state = fe.SymplecticEuler().step(model, state, 1e-3)
    V = state.v.reshape(-1, 3)
    assert V[: n // 3, 0].mean() < 0.0 < V[n // 3:, 0].mean()  # bounced off each other
    assert np.abs(model.linear_momentum(state.v) - p0).max() <= 1e-13 * 2.0  # 2 kg m/s of |p|


def test_bench_broad_phase_quick_prints_its_fit(capsys):
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "scripts" / "bench_broad_phase.py"
    spec = importlib.util.spec_from_file_location("bench_broad_phase", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    bench.main(["--quick", "--repeats", "1"])
    out = capsys.readouterr().out
    assert "fitted exponent p" in out and "fit time = c n log n" in out
    assert "False" not in out and out.count("True") >= 3  # tree = brute force on the small sizes


def test_pairs_within_the_thickness_at_rest_never_collide():
    # a thickness above the cell size (25 mm cells, 30 mm thickness): neighbours across the
    # surface's edges are nearer than it at rest; they are left out, so nothing moves at rest
    mesh = fe.beam_mesh(length=0.1, width=0.05, height=0.05, cells=(4, 2, 2))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
                     contact=fe.ImpulseContact(thickness=0.03))
    contact = model.contact
    assert contact._excluded.size > 0
    v = np.tile([0.0, 0.0, -1.0], model.ndofs // 3)
    x1, v1 = contact.respond(model.X, v, model.lumped_mass)
    np.testing.assert_array_equal(x1, model.X)
    np.testing.assert_array_equal(v1, v)
    assert contact.diagnostics(model.X)["active_contacts"] == 0


def test_diagnostics_min_distance_matches_all_pairs():
    model, n, _ = _two_cubes(fe.ImpulseContact(thickness=2e-3), offset=(0.105, 0.0, 0.0))
    contact = model.contact
    S = contact.surface
    P = S.positions(model.X)
    # every (vertex, triangle) pair of different cubes, by brute force
    cube = np.arange(S.n_vertices) >= np.searchsorted(S.vertex_dofs[:, 0], 3 * n)
    vi, tj = np.nonzero(cube[:, None] != cube[S.faces[:, 0]][None, :])
    tri = P[S.faces[tj]]
    q, _ = closest_point_triangle(P[vi], tri[:, 0], tri[:, 1], tri[:, 2])
    brute = np.linalg.norm(P[vi] - q, axis=1).min()
    assert brute == pytest.approx(0.005, abs=1e-12)  # the 5 mm gap between the cubes
    d = contact.diagnostics(model.X)
    assert d["min_distance"] == pytest.approx(brute, abs=1e-15) and d["active_contacts"] == 0
    assert contact.min_distance(model.X) == pytest.approx(brute, abs=1e-15)


def test_has_intersections_sees_overlapping_cubes_only():
    model, n, _ = _two_cubes(fe.ImpulseContact(thickness=1e-3), offset=(0.12, 0.02, 0.03))
    contact = model.contact
    assert not contact.has_intersections(model.X)
    X = model.X.reshape(-1, 3).copy()
    X[n:] -= [0.04, 0.0, 0.0]  # the second cube 2 cm into the first
    assert contact.has_intersections(X.ravel())
    X[n:] += [0.0, 0.2, 0.0]  # moved aside: apart again
    assert not contact.has_intersections(X.ravel())


def test_run_summary_reports_the_average_contact_force_of_the_impulses():
    """fe.simulate records an impulse contact's force as its impulse over the step (N)."""
    model, n, _ = _two_cubes(fe.ImpulseContact(restitution=0.5, thickness=3e-3), offset=(0.12, 0.02, 0.03))
    v0 = np.zeros((2 * n, 3))
    v0[:n, 0], v0[n:, 0] = 1.0, -1.0
    dt = 1e-3
    traj = fe.simulate(model, fe.SymplecticEuler(), dt, steps=40, state=fe.State(model.X.copy(), v0.ravel(), 0.0))
    force = np.asarray(traj.step_stats["contact_force"])
    assert np.isfinite(force).all() and (force >= 0).all()
    summary = traj.summary()
    assert summary["contact_steps_in_contact"] > 0
    # the cubes (2 x 1 kg) reverse a 1 m/s approach with e = 0.5: total impulse on each side
    # at least m * (1 + e) * 1 m/s spread over the contact steps; the peak average force must
    # therefore reach that impulse over (steps in contact * dt) at least
    mass_each = 1000.0 * 0.1 ** 3
    floor = mass_each * 1.5 * 1.0 / (summary["contact_steps_in_contact"] * dt)
    assert summary["contact_force_max"] >= floor


def _cubes_apart(gap, contact, va=(1.0, 0.0, 0.0), vb=(-1.0, 0.0, 0.0), shift=(0.0, 0.0), mb=1000.0):
    cube = fe.beam_mesh(length=0.1, width=0.1, height=0.1, cells=(2, 2, 2))
    material = fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3))
    bodies = [fe.Body(cube, 1000.0, material, name="a", velocity=va),
              fe.Body(cube, mb, material, name="b", translate=(0.1 + gap, *shift), velocity=vb)]
    return fe.MultiBody(bodies, contact=contact)


def test_bodies_placed_within_the_thickness_still_collide_and_are_warned_about():
    # 0.5 mm apart with a 2 mm thickness: the pairs between the two bodies are kept (only pairs
    # of one body are left out at rest), with a warning naming the fix
    with pytest.warns(RestContactWarning, match="move the bodies apart by more than the thickness"):
        model = _cubes_apart(5e-4, fe.ImpulseContact(thickness=2e-3))
    assert model.contact._excluded.size == 0
    state = fe.State(model.X.copy(), model.initial_velocity(), 0.0)
    p0 = model.linear_momentum(state.v)
    for _ in range(60):  # 6 ms at 1 m/s each: 12 mm of approach without the contact
        state = fe.SymplecticEuler().step(model, state, 1e-4)
    assert not model.contact.has_intersections(state.x)
    V = state.v.reshape(-1, 3)
    half = V.shape[0] // 2
    assert V[:half, 0].mean() < 0.5 and V[half:, 0].mean() > -0.5  # slowed by the contact
    assert np.abs(model.linear_momentum(state.v) - p0).max() <= 1e-13 * 2.0  # 2 kg m/s of |p|


def test_bodies_farther_than_the_thickness_give_no_warning():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", RestContactWarning)
        model = _cubes_apart(3e-3, fe.ImpulseContact(thickness=2e-3))
    assert model.contact._excluded.size == 0


def _kinetic(m, v):
    return 0.5 * float(m @ (v * v))


@pytest.mark.parametrize("mu", [0.0, 0.5])
@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_coupled_contacts_never_create_kinetic_energy(e, mu):
    # an oblique collision of two cubes of unequal density, 0.5 mm into each other's thickness:
    # eight coupled vertex-triangle contacts solved together (Poisson restitution)
    with pytest.warns(RestContactWarning):
        model = _cubes_apart(5e-4, fe.ImpulseContact(restitution=e, friction=mu, thickness=2e-3),
                             va=(2.0, 0.5, 0.0), vb=(-1.0, 0.0, 0.3), shift=(0.03, 0.01), mb=500.0)
    x, v, m = model.X.copy(), model.initial_velocity(), model.lumped_mass
    x1, v1 = model.respond_contacts(x, v)
    assert model.contact.last_contacts == 8
    ke0, ke1 = _kinetic(m, v), _kinetic(m, v1)
    # never more: round-off of the ~160-term sums of the kinetic energy, ~1e-15 relative
    assert ke1 <= ke0 * (1.0 + 1e-14)
    p0, p1 = (m * v).reshape(-1, 3).sum(0), (m * v1).reshape(-1, 3).sum(0)
    assert np.abs(p1 - p0).max() <= ROUNDOFF * float(m @ np.abs(v))
    if e == 1.0 and mu == 0.0:
        # frictionless elastic: the energy is kept up to the Jacobi rounds' residual at their
        # default count (50 rounds: 4e-5 of it measured; the exact inelastic solution keeps all)
        assert ke1 >= ke0 * (1.0 - 2e-4)
    if e == 0.0:  # what the inelastic phase alone takes is the most any e can take
        assert ke1 < ke0


def test_contact_force_is_the_average_over_all_sub_steps_of_a_step():
    # dt = 5 ms above the critical ~2.8 ms: SymplecticEuler(substep=True) takes it in sub-steps,
    # each with its own response; 0.5 m/s each way moves 2.2 mm per sub-step, under the thickness
    model, n, _ = _two_cubes(fe.ImpulseContact(restitution=0.5, thickness=3e-3), offset=(0.105, 0.0, 0.0))
    contact = model.contact
    impulses = []
    respond = contact.respond

    def counting(x, v, mass):
        out = respond(x, v, mass)
        impulses.append(contact.last_impulse)
        return out

    contact.respond = counting
    v0 = np.zeros((2 * n, 3))
    v0[:n, 0], v0[n:, 0] = 0.5, -0.5
    dt, steps = 5e-3, 6
    traj = fe.simulate(model, fe.SymplecticEuler(substep=True), dt, steps=steps,
                       state=fe.State(model.X.copy(), v0.ravel(), 0.0))
    assert len(impulses) > steps  # sub-stepped: several responses per step
    force = np.asarray(traj.step_stats["contact_force"])
    total = sum(impulses)
    assert total > 0.0
    # every response's impulse counted once, in its step: a sum of the same terms, regrouped
    assert float(force.sum()) * dt == pytest.approx(total, rel=1e-12)
