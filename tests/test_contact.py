"""Contact with obstacles: derivatives, projection, barrier admissibility, impulses, resting."""

import math

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.discretization import Discretization
from fem_elastic.errors import InvalidParameter
from fem_elastic.physics.contact import BarrierContact, PenaltyContact
from fem_elastic.physics.obstacles import Box, Ground, Sphere
from fem_elastic.solvers.newton import newton_minimize

G = 9.81  # m/s^2, the default design gravity of the contact stiffness
DHAT = 0.1  # m, barrier activation distance in the derivative tests (geometry is O(1) m)


# ------------------------------------------------------------------------------------------
# sample states: half the nodes in contact, half not, all away from the kinks of the energy
def _unit(v):
    return v / np.linalg.norm(v)


def _plane_points(ground, d, rng):
    n = ground.unit_normal
    t1 = _unit(np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0]))
    t2 = np.cross(n, t1)
    ab = rng.uniform(-1.0, 1.0, (d.size, 2))
    return ground.point + ab[:, :1] * t1 + ab[:, 1:] * t2 + d[:, None] * n


def _sphere_points(sphere, d, rng):
    u = rng.normal(size=(d.size, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    return sphere.center + (sphere.radius + d)[:, None] * u


def _box_points_inside(box, depth, rng):
    """Points at ``depth`` below a random face, >= 0.4 m from every other face."""
    lo, hi = box.lower, box.upper
    p = rng.uniform(lo + 0.4, hi - 0.4, (depth.size, 3))
    for i, dep in enumerate(depth):
        k, upper = rng.integers(3), rng.integers(2)
        p[i, k] = hi[k] - dep if upper else lo[k] + dep
    return p


def _box_points_outside(box, d, rng):
    """Points at distance d outside a face, an edge or a corner (cycling), off the region borders."""
    lo, hi = box.lower, box.upper
    p = rng.uniform(lo + 0.2, hi - 0.2, (d.size, 3))
    for i, di in enumerate(d):
        axes = rng.permutation(3)[: i % 3 + 1]
        u = _unit(rng.uniform(0.4, 1.0, axes.size))  # every outside offset well above the FD step
        for k, uk in zip(axes, u):
            p[i, k] = hi[k] + di * uk if rng.integers(2) else lo[k] - di * uk
    return p


GEOMETRIES = {
    "ground": lambda: Ground(z=0.3),
    "tilted ground": lambda: Ground(point=(0.1, -0.2, 0.3), normal=(1.0, 2.0, 3.0)),
    "sphere": lambda: Sphere((0.1, 0.2, -0.3), 1.0),
    "box": lambda: Box((0.0, -1.0, 0.5), (1.0, 1.0, 2.0)),
}


def _state(name, obstacle, method, rng, nodes=6):
    """Flat positions of 2 * nodes nodes: the first half active, the second half not."""
    if method == "penalty":
        active = -rng.uniform(0.05, 0.3, nodes)  # penetrating, away from d = 0
        idle = rng.uniform(0.05, 0.5, nodes)
    else:
        active = rng.uniform(0.2, 0.8, nodes) * DHAT  # inside (0, dhat), away from both ends
        idle = rng.uniform(1.2, 3.0, nodes) * DHAT
    d = np.concatenate([active, idle])
    if name == "sphere":
        p = _sphere_points(obstacle, d, rng)
    elif name == "box":
        p = np.vstack([
            _box_points_inside(obstacle, -active, rng) if method == "penalty"
            else _box_points_outside(obstacle, active, rng),
            _box_points_outside(obstacle, idle, rng),
        ])
    else:
        p = _plane_points(obstacle, d, rng)
    # the samples are where they were meant to be (an error here is in the test, not the code)
    np.testing.assert_allclose(obstacle.signed_distance(p), d, atol=1e-12)
    return p.ravel()


def _potential(obstacle, method, x, rng):
    weights = rng.uniform(0.5, 2.0, x.size // 3)  # N/m, different per node
    if method == "penalty":
        return PenaltyContact(obstacle, x, weights)
    return BarrierContact(obstacle, x, weights, dhat=DHAT)


CASES = [(name, method) for name in GEOMETRIES for method in ("penalty", "barrier")]


@pytest.mark.parametrize("name, method", CASES)
def test_gradient_and_hessian_match_central_differences(name, method):
    rng = np.random.default_rng(CASES.index((name, method)))
    obstacle = GEOMETRIES[name]()
    x = _state(name, obstacle, method, rng)
    pot = _potential(obstacle, method, x, rng)
    h = 1e-6  # m; O(1) m geometry and d >= 0.02 m from any kink: truncation ~ (h/d)^2 < 1e-8
    g = pot.gradient(x)
    H = pot.hessian(x).toarray()
    fd_g = np.empty_like(x)
    fd_H = np.empty((x.size, x.size))
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = h
        fd_g[j] = (pot.energy(x + e) - pot.energy(x - e)) / (2 * h)
        fd_H[:, j] = (pot.gradient(x + e) - pot.gradient(x - e)) / (2 * h)
    # relative 1e-6: the truncation above plus round-off eps * E / h ~ 1e-10 relative
    assert np.linalg.norm(fd_g - g) <= 1e-6 * np.linalg.norm(g)
    assert np.linalg.norm(fd_H - H) <= 1e-6 * np.linalg.norm(H)
    # the idle nodes (second half) feel nothing; the active ones all do
    half = x.size // 2
    assert np.all(g[half:] == 0.0) and np.all(np.linalg.norm(g[:half].reshape(-1, 3), axis=1) > 0)
    # the Hessian is symmetric and block diagonal (3x3 per node)
    np.testing.assert_allclose(H, H.T, atol=1e-12 * np.abs(H).max())  # round-off of n n^T products
    node = np.arange(x.size) // 3
    assert np.all(H[node[:, None] != node[None, :]] == 0.0)
    # linearize is gradient and hessian at once
    gl, Hl = pot.linearize(x)
    np.testing.assert_array_equal(gl, g)
    np.testing.assert_array_equal(Hl.toarray(), H)


@pytest.mark.parametrize("name, method", CASES)
def test_projected_hessian_is_the_psd_clamp_of_each_block(name, method):
    rng = np.random.default_rng(7)
    obstacle = GEOMETRIES[name]()
    x = _state(name, obstacle, method, rng)
    pot = _potential(obstacle, method, x, rng)
    H = pot.hessian(x).toarray()
    P = pot.hessian(x, project=True).toarray()
    scale = np.abs(H).max()
    assert np.linalg.eigvalsh(P).min() >= -1e-12 * scale  # PSD up to eigensolver round-off
    # it equals the eigenvalue clamp of every exact 3x3 block
    for a in range(x.size // 3):
        s = slice(3 * a, 3 * a + 3)
        lam, Q = np.linalg.eigh(H[s, s])
        clamp = (Q * np.maximum(lam, 0.0)) @ Q.T
        np.testing.assert_allclose(P[s, s], clamp, atol=1e-12 * scale)  # eigh round-off
    curved = name == "sphere" or (name == "box" and method == "barrier")
    if curved:  # there the exact Hessian is indefinite, so the projection matters
        assert np.linalg.eigvalsh(H).min() < -1e-3 * scale
    else:  # planes (and box faces from inside) have no curvature: already PSD, unchanged
        np.testing.assert_array_equal(P, H)


# ------------------------------------------------------------------------------------------
def test_barrier_is_infinite_at_penetration_and_finite_outside():
    pot = BarrierContact(Ground(), np.zeros(6), kappa=10.0, dhat=1e-3)
    above = np.array([0.0, 0.0, 2e-3, 0.0, 0.0, 5e-4])
    assert math.isfinite(pot.energy(above)) and pot.energy(above) > 0
    for z in (-1e-6, 0.0):
        x = above.copy()
        x[5] = z
        assert pot.energy(x) == math.inf
        assert np.isnan(pot.gradient(x)[5])  # no force is defined through the barrier
    tiny = above.copy()
    tiny[5] = 1e-12  # a hair above the plane: huge but finite
    assert math.isfinite(pot.energy(tiny)) and pot.energy(tiny) > pot.energy(above)


def test_barrier_vanishes_smoothly_at_dhat():
    """b, b' and b'' all go to 0 at d = dhat, so the energy is C2 there."""
    dhat = 1e-3
    pot = BarrierContact(Ground(), np.zeros(3), kappa=1.0, dhat=dhat)
    z = dhat * (1.0 - 1e-4)
    x = np.array([0.0, 0.0, z])
    b0 = pot.energy(np.array([0.0, 0.0, 0.5 * dhat]))
    g0 = abs(pot.gradient(np.array([0.0, 0.0, 0.5 * dhat]))[2])
    h0 = pot.hessian(np.array([0.0, 0.0, 0.5 * dhat]))[2, 2]
    # at 1e-4 dhat from the edge: b ~ s^3, b' ~ s^2, b'' ~ s with s = 1e-4 relative
    assert pot.energy(x) <= 1e-10 * b0
    assert abs(pot.gradient(x)[2]) <= 1e-7 * g0
    assert pot.hessian(x)[2, 2] <= 1e-3 * h0


@pytest.mark.parametrize("method", ["penalty", "barrier"])
@pytest.mark.parametrize("name", list(GEOMETRIES))
def test_no_contact_is_cheap_and_zero(name, method):
    rng = np.random.default_rng(3)
    obstacle = GEOMETRIES[name]()
    x = _state(name, obstacle, method, rng)[18:]  # the 6 idle nodes only
    pot = _potential(obstacle, method, x, rng)
    assert pot.energy(x) == 0.0
    assert np.all(pot.gradient(x) == 0.0) and pot.gradient(x).shape == x.shape
    H = pot.hessian(x, project=True)
    assert H.shape == (x.size, x.size) and H.nnz == 0
    g, H = pot.linearize(x)
    assert np.all(g == 0.0) and H.nnz == 0
    assert pot.energy_roundoff() == 0.0 and pot.gradient_roundoff() == 0.0


# ------------------------------------------------------------------------------------------
# impulses
@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_impulse_bounces_with_restitution(e):
    ground = Ground(method="impulse", restitution=e)
    x = np.array([0.3, -0.2, -0.01])
    v = np.array([0.0, 0.0, -3.0])
    x1, v1 = ground.respond(x, v, nodal_mass=[0.1])
    np.testing.assert_array_equal(x1, [0.3, -0.2, 0.0])  # projected onto the plane
    np.testing.assert_allclose(v1, [0.0, 0.0, 3.0 * e], atol=1e-15)  # one multiplication


def test_impulse_friction_stops_or_slows_the_tangential_motion():
    x = np.array([0.0, 0.0, -0.01])
    v = np.array([2.0, 1.0, -3.0])
    vt = v[:2]
    # large mu: the friction bound mu (1 + e) |v_n| = 15 exceeds |v_t|: sticks, never reverses
    _, v1 = Ground(method="impulse", restitution=0.5, friction=10.0).respond(x, v)
    np.testing.assert_allclose(v1, [0.0, 0.0, 1.5], atol=1e-15)
    # small mu: |v_t| drops by exactly mu (1 + e) |v_n| = 0.1 * 1.5 * 3, direction kept
    _, v2 = Ground(method="impulse", restitution=0.5, friction=0.1).respond(x, v)
    speed = np.linalg.norm(vt) - 0.1 * 1.5 * 3.0
    np.testing.assert_allclose(v2[:2], speed * vt / np.linalg.norm(vt), rtol=1e-14)  # round-off
    assert v2[2] == pytest.approx(1.5, rel=1e-15)


def test_impulse_leaves_free_and_separating_nodes_alone_and_inputs_untouched():
    ground = Ground(method="impulse", restitution=0.8, friction=0.3)
    x = np.array([0.0, 0.0, 0.5,  # above the plane, falling: not in contact
                  1.0, 0.0, -0.02,  # below, already moving out: position fixed, velocity kept
                  2.0, 0.0, -0.01])  # below, moving in: bounces
    v = np.array([1.0, 0.0, -5.0, 1.0, 0.0, 2.0, 0.0, 0.0, -1.0])
    x0, v0 = x.copy(), v.copy()
    x1, v1 = ground.respond(x, v)
    np.testing.assert_array_equal(x, x0)
    np.testing.assert_array_equal(v, v0)
    assert x1 is not x and v1 is not v
    np.testing.assert_array_equal(x1, [0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0])
    np.testing.assert_array_equal(v1[:6], v[:6])
    np.testing.assert_allclose(v1[6:], [0.0, 0.0, 0.8], atol=1e-15)


def test_impulse_on_a_sphere_and_a_box_reflects_along_the_normal():
    s = Sphere((0.0, 0.0, 0.0), 1.0, method="impulse", restitution=1.0)
    u = _unit(np.array([1.0, 2.0, 2.0]))
    x1, v1 = s.respond(0.9 * u, -2.0 * u)
    np.testing.assert_allclose(x1, u, rtol=1e-15)  # back on the sphere
    np.testing.assert_allclose(v1, 2.0 * u, rtol=1e-15)  # elastic: the normal velocity reverses
    b = Box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), method="impulse")
    x1, v1 = b.respond(np.array([0.5, 0.4, 0.95]), np.array([1.0, 0.0, -1.0]))
    np.testing.assert_allclose(x1, [0.5, 0.4, 1.0], rtol=1e-15)  # out through the nearest face
    np.testing.assert_allclose(v1, [1.0, 0.0, 0.0], atol=1e-15)  # plastic, frictionless


def test_other_methods_respond_with_copies_and_impulse_builds_nothing():
    x, v = np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, -1.0])
    x1, v1 = Ground().respond(x, v)
    np.testing.assert_array_equal(x1, x)
    np.testing.assert_array_equal(v1, v)
    assert x1 is not x and v1 is not v
    space = Discretization(fe.beam_mesh(1.0, 1.0, 1.0, cells=(1, 1, 1)), order=1)
    assert Ground(method="impulse").build(space, np.ones(8)) is None
    assert Ground(method="impulse").critical_omega(np.ones(8)) == 0.0


# ------------------------------------------------------------------------------------------
# stiffness rules
def test_single_node_rests_at_the_design_penetration_and_gap():
    """One node carrying the whole weight: the rules are exact there."""
    m = 0.3  # kg
    weight = m * G
    k = Ground(penetration=2e-3).node_stiffness([m])
    x = np.array([0.0, 0.0, -2e-3])
    p1 = PenaltyContact(Ground(), x, stiffness=k)
    assert p1.contact_force(x)[2] == pytest.approx(weight, rel=1e-14)  # k * penetration = M g
    kappa = Ground(method="barrier", dhat=1e-3).node_stiffness([m])
    b1 = BarrierContact(Ground(), x, kappa, dhat=1e-3)
    assert b1.contact_force(np.array([0.0, 0.0, 5e-4]))[2] == pytest.approx(weight, rel=1e-13)


def test_critical_omega_is_the_fastest_node_on_its_spring():
    m = np.array([0.1, 0.2, 0.7])  # kg, 1 kg in all
    g = Ground(penetration=1e-3)
    assert g.critical_omega(m) == pytest.approx(math.sqrt(G / 1e-3 / 0.1), rel=1e-14)
    space_X = np.zeros(9)
    assert PenaltyContact(g, space_X, g.node_stiffness(m), nodal_mass=m).critical_omega() == \
        pytest.approx(g.critical_omega(m), rel=1e-14)
    # barrier: the curvature of one node's energy at the design gap dhat / 2
    b = Ground(method="barrier", dhat=1e-3)
    pot = BarrierContact(b, space_X, b.node_stiffness(m), dhat=1e-3, nodal_mass=m)
    x = np.array([0.0, 0.0, 5e-4, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0])
    k_half = pot.hessian(x)[2, 2]
    assert b.critical_omega(m) == pytest.approx(math.sqrt(k_half / 0.1), rel=1e-12)
    assert pot.critical_omega() == pytest.approx(b.critical_omega(m), rel=1e-14)


def _rest_on_ground(ground, order, lift):
    """Newton on body + gravity + contact for a 0.1 m rubber cube (1 kg) starting ``lift`` above z = 0."""
    mesh = fe.beam_mesh(0.1, 0.1, 0.1, cells=(2, 2, 2))
    mesh = mesh.translated((0.0, 0.0, lift - mesh.p[2].min()))
    model = fe.Model(mesh, density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3), order=order),
                     gravity=(0.0, 0.0, -G))
    contact = ground.build(model.space, model.lumped_mass[0::3])
    X = model.X
    # a frictionless plane leaves x, y and the rotation about z free: hold x, y of one bottom
    # corner and y of the next one along x. Three constraints for three modes carry no load.
    p = X.reshape(-1, 3)
    a = np.flatnonzero(np.all(np.isclose(p, [0.0, 0.0, lift]), axis=1))[0]
    b = np.flatnonzero(np.all(np.isclose(p, [0.1, 0.0, lift]), axis=1))[0]
    free = np.ones(X.size, dtype=bool)
    free[[3 * a, 3 * a + 1, 3 * b + 1]] = False

    def energy(x):
        return model.energy(x) + contact.energy(x)

    def linearize(x, project):
        g, H = model.linearize(x, project=project)
        gc, Hc = contact.linearize(x, project=project)
        return g + gc, H + Hc

    weight = 1.0 * G  # N: 1000 kg/m^3 * (0.1 m)^3 * g
    res = newton_minimize(energy, linearize, X, free, rtol=1e-10, g_scale=weight,
                          linear_solver=fe.DirectSolver(),
                          energy_roundoff=model.energy_roundoff() + contact.energy_roundoff(),
                          g_floor=model.gradient_roundoff() + contact.gradient_roundoff())
    assert res.converged, res.message
    return res.x, contact, weight


@pytest.mark.parametrize("order", [1, 2])
def test_penalty_resting_penetration_is_within_the_design_tolerance(order):
    penetration = 1e-3  # m
    # start 0.1 mm deep: from a mere touch (d = 0, no contact stiffness yet) the static
    # Hessian is singular in the vertical translation and the first Newton step is meaningless
    x, contact, weight = _rest_on_ground(Ground(penetration=penetration), order, lift=-1e-4)
    depth = np.maximum(0.0, -x[2::3])
    n_contact = int((depth > 0).sum())
    # 9 bottom vertices (P1), 25 bottom nodes with the edge nodes (P2)
    assert n_contact == (9 if order == 1 else 25)
    # the documented bound: no node deeper than `penetration`, and since every contact node has
    # the same k = M g / penetration, the depths add up to exactly `penetration` (sum k d = M g)
    assert depth.max() <= penetration
    # Newton stops at ||g|| <= 1e-10 M g: the force balance holds to ~sqrt(ndofs) times that
    assert depth.sum() == pytest.approx(penetration, rel=1e-8)
    assert contact.contact_force(x)[2::3].sum() == pytest.approx(weight, rel=1e-8)


def test_barrier_resting_gap_is_between_half_dhat_and_dhat():
    dhat = 1e-3  # m
    ground = Ground(method="barrier", dhat=dhat)
    x, contact, weight = _rest_on_ground(ground, 1, lift=0.5 * dhat)
    z = x[2::3]
    touching = z < dhat
    assert touching.sum() == 9  # the bottom vertices
    # the documented range: a node carrying at most the whole weight rests at dhat/2 <= d < dhat
    assert z.min() >= 0.5 * dhat and z[touching].max() < dhat
    assert contact.contact_force(x)[2::3].sum() == pytest.approx(weight, rel=1e-8)  # as above


def test_barrier_build_refuses_a_penetrating_reference_configuration():
    space = Discretization(fe.beam_mesh(1.0, 1.0, 1.0, cells=(1, 1, 1)), order=1)
    with pytest.raises(InvalidParameter, match="strictly outside"):
        Ground(method="barrier").build(space, np.ones(8))  # the bottom face lies on z = 0
    with pytest.raises(InvalidParameter, match="nodal_mass"):
        Ground().build(space, np.ones(5))


@pytest.mark.parametrize("method", ["penalty", "impulse"])
def test_build_refuses_a_body_that_starts_deep_inside_the_obstacle(method):
    # a 1 m cube of 8 kg (1 kg per vertex, P1), edges of 1 m. The penalty refuses a start deeper
    # than 10 x the resting depth M g / k (= penetration = 1 mm): the limit is 10 mm; the
    # impulse response refuses one deeper than 1 % of the shortest edge: 10 mm too.
    space = Discretization(fe.beam_mesh(1.0, 1.0, 1.0, cells=(1, 1, 1)), order=1)
    limit = 1e-2  # m, both rules on this cube
    for make in (lambda z: Ground(z=z, method=method),
                 # a sphere of radius 1e4 m touching the bottom face's centre from below: the bottom
                 # corners sit 0.25 / 1e4 = 2.5e-5 m higher on it than on the plane, 0.25 % of the limit
                 lambda z: Sphere((0.5, 0.5, z - 1e4), 1e4, method=method)):
        make(0.0).build(space, np.ones(8))  # just touching: accepted
        make(0.9 * limit).build(space, np.ones(8))  # a resting or slightly pressed start: accepted
        with pytest.raises(InvalidParameter, match=r"4 node\(s\) of the reference configuration start "
                                                   r"inside .* Move the mesh"):
            make(1.1 * limit).build(space, np.ones(8))
    # the penalty's limit follows its stiffness: 10 x softer springs rest 10 x deeper
    if method == "penalty":
        Ground(z=0.05, stiffness=8 * G / 1e-2).build(space, np.ones(8))  # rests at 1 cm, limit 10 cm


# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("make, word", [
    (lambda: Ground(method="spring"), "method"),
    (lambda: Ground(stiffness=-1.0), "stiffness"),
    (lambda: Ground(stiffness=0.0), "stiffness"),
    (lambda: Ground(penetration=-1e-3), "penetration"),
    (lambda: Ground(penetration=float("nan")), "penetration"),
    (lambda: Ground(dhat=0.0), "dhat"),
    (lambda: Ground(method="impulse", restitution=1.5), "restitution"),
    (lambda: Ground(method="impulse", restitution=-0.1), "restitution"),
    (lambda: Ground(method="impulse", friction=-0.2), "friction"),
    (lambda: Ground(restitution=0.5), "method='impulse'"),
    (lambda: Ground(method="barrier", friction=0.5), "method='impulse'"),
    (lambda: Ground(normal=(0.0, 0.0, 0.0)), "normal"),
    (lambda: Ground(normal=(0.0, 1.0)), "normal"),
    (lambda: Ground(z=float("inf")), "z"),
    (lambda: Ground(gravity=0.0), "gravity"),
    (lambda: Sphere((0, 0, 0), 0.0), "radius"),
    (lambda: Sphere((0, 0, 0), -1.0), "radius"),
    (lambda: Sphere((0, 0), 1.0), "center"),
    (lambda: Box((0, 0, 0), (1, 0, 1)), "lower < upper"),
    (lambda: Box((1, 1, 1), (0, 0, 0)), "lower < upper"),
    (lambda: PenaltyContact(Ground(), np.zeros(3), stiffness=-1.0), "stiffness"),
    (lambda: BarrierContact(Ground(), np.zeros(3), kappa=1.0, dhat=-1.0), "dhat"),
])
def test_bad_parameters_raise_invalid_parameter(make, word):
    with pytest.raises(InvalidParameter, match=word.replace("(", r"\(")) as info:
        make()
    assert isinstance(info.value, fe.FemElasticError)


def test_contact_stiffness_follows_the_models_gravity_unless_given():
    cube = fe.beam_mesh(length=0.1, width=0.1, height=0.1, cells=(1, 1, 1))
    body = fe.ElasticBody(fe.LinearElastic(E=1e5, nu=0.3))
    k = {}
    for g, own in ((9.81, None), (19.62, None), (19.62, 9.81), (None, None)):
        model = fe.Model(cube, density=1000.0, body=body, gravity=None if g is None else (0, 0, -g),
                         ground=fe.Ground(-1.0, gravity=own))
        k[g, own] = model.contacts[0].weights[0]
    assert k[19.62, None] == pytest.approx(2 * k[9.81, None])  # twice the weight: twice as stiff
    assert k[19.62, 9.81] == pytest.approx(k[9.81, None])  # the obstacle's own |g| wins
    assert k[None, None] == pytest.approx(k[9.81, None])  # no gravity: 9.81 m/s^2


def test_bad_stiffness_arrays_and_calibrations_are_refused():
    with pytest.raises(fe.InvalidParameter, match="stiffness"):
        PenaltyContact(Ground(), np.zeros(6), [1.0, 2.0, 3.0])
    with pytest.raises(fe.InvalidParameter, match="stiffness"):
        PenaltyContact(Ground(), np.zeros(6), "a")
    with pytest.raises(fe.InvalidParameter, match="calibration"):
        fe.Model(fe.beam_mesh(cells=(1, 1, 1)), density=1.0,
                 body=fe.MassSpring(E=1.0, calibration=lambda mesh: mesh))
