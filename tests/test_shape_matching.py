"""Shape matching (fe.ShapeMatching on a model, fe.ShapeMatcher on a bare point cloud).

Rigid mode reproduces a rigid motion exactly (to round-off); free bodies keep their
linear and angular momentum, with clusters too; linear and quadratic modes return to
the rest shape after a deformation; clusters survive a large deformation and return;
held vertices stay put; scene files and checkpoints reach it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.app.scene import SceneError, parse_scene
from fem_elastic.dynamics.shape_matching import grid_clusters
from small_scene import small_scene

DT = 0.01


def _beam(cells=(10, 2, 2), **terms):
    return fe.Model(fe.beam_mesh(1.0, 0.1, 0.1, cells), density=1000.0,
                    body=fe.ElasticBody(fe.Corotated(E=1e5, nu=0.3)), **terms)


def _rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _sheared(P):
    """A homogeneous stretch and shear about the centre (a displacement field)."""
    c = P.mean(axis=0)
    A = np.array([[1.3, 0.2, 0.0], [0.0, 0.8, 0.1], [0.1, 0.0, 1.1]])
    return (P - c) @ A.T + c - P


def _bent(P):
    """The 1 m beam bent into a half circle and twisted by 90 degrees (a displacement field)."""
    s = P[:, 0]
    radius = 1.0 / np.pi
    phi = s / radius
    twist = 0.5 * np.pi * s
    y, z = P[:, 1] - 0.05, P[:, 2] - 0.05
    yt = y * np.cos(twist) - z * np.sin(twist)
    zt = y * np.sin(twist) + z * np.cos(twist)
    r = radius - zt
    out = np.column_stack([r * np.sin(phi), yt + 0.05, radius - r * np.cos(phi) + 0.05])
    return out - P


def shape_error(X, x):
    """Largest distance (m) of x from the best rigid motion of the rest shape X."""
    c0, c1 = X.mean(axis=0), x.mean(axis=0)
    U, _, Vt = np.linalg.svd((X - c0).T @ (x - c1))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return np.abs((X - c0) @ R.T + c1 - x).max()


# ---------------------------------------------------------------------------------------
# rigid motions


@pytest.mark.parametrize("mode", ["rigid", "linear", "quadratic"])
@pytest.mark.parametrize("clusters", [1, 4])
def test_a_rigidly_moved_body_is_its_own_goal(mode, clusters):
    model = _beam()
    X = model.X.reshape(-1, 3)
    Q = _rotation([1.0, 2.0, -0.5], 2.0)
    x = X @ Q.T + np.array([0.3, -1.0, 2.0])
    sm = fe.ShapeMatching(mode=mode, beta=0.7, clusters=clusters).matcher(model)
    assert np.abs(sm.goals(x) - x).max() < 1e-14 * 4
    state = fe.State(x.ravel(), np.zeros(model.ndofs))
    out = fe.ShapeMatching(mode=mode, beta=0.7, alpha=1.0, clusters=clusters).step(model, state, DT)
    assert np.abs(out.x - state.x).max() < 1e-14 * 4 and np.abs(out.v).max() < 1e-12


def test_rigid_mode_snaps_a_deformed_body_to_a_rigid_motion_in_one_step():
    model = _beam()
    X = model.X.reshape(-1, 3)
    rng = np.random.default_rng(0)
    Q = _rotation([0.0, 1.0, 1.0], 0.8)
    deformed = (X + _sheared(X) + 0.01 * rng.normal(size=X.shape)) @ Q.T
    state = fe.State(deformed.ravel(), np.zeros(model.ndofs))
    out = fe.ShapeMatching(mode="rigid", alpha=1.0).step(model, state, DT)
    x = out.x.reshape(-1, 3)
    # x = R X + c exactly: the affine fit has an orthogonal, proper linear part, no residual
    A, *_ = np.linalg.lstsq(np.c_[X, np.ones(len(X))], x, rcond=None)
    R = A[:3].T
    assert np.abs(R.T @ R - np.eye(3)).max() < 1e-13 and np.linalg.det(R) == pytest.approx(1.0, abs=1e-13)
    assert np.abs(np.c_[X, np.ones(len(X))] @ A - x).max() < 1e-13
    # ... about the centre of mass, which stays where it was
    m = model.lumped_mass[0::3]
    assert np.allclose(m @ x / m.sum(), m @ deformed / m.sum(), rtol=0, atol=1e-14)


@pytest.mark.parametrize("mode", ["rigid", "linear", "quadratic"])
@pytest.mark.parametrize("clusters, damping", [(1, 0.0), (1, 0.3), (5, 0.0), (5, 0.5)])
def test_a_free_body_keeps_its_linear_and_angular_momentum(mode, clusters, damping):
    model = _beam()
    rng = np.random.default_rng(1)
    state = fe.State.rest(model, displacement=lambda P: _sheared(P) + 0.002 * rng.normal(size=P.shape),
                          velocity=lambda P: np.cross([0.0, 1.0, 3.0], P - P.mean(axis=0)) + [1.0, 0.0, -2.0])
    p0, L0 = model.linear_momentum(state.v), model.angular_momentum(state.x, state.v)
    sm = fe.ShapeMatching(mode=mode, alpha=0.5, damping=damping, clusters=clusters)
    run = fe.simulate(model, sm, DT, steps=40, state=state, energy_growth=math.inf)
    scale = model.total_mass * 3.0  # kg m/s: the body's speeds are ~1-3 m/s
    assert np.abs(run.linear_momentum - p0).max() < 1e-12 * scale
    assert np.abs(run.angular_momentum - L0).max() < 1e-12 * scale


# ---------------------------------------------------------------------------------------
# back to the rest shape


@pytest.mark.parametrize("mode", ["linear", "quadratic"])
def test_deformable_modes_return_to_the_rest_shape(mode):
    model = _beam()
    X = model.X.reshape(-1, 3)
    state = fe.State.rest(model, displacement=_sheared)
    assert shape_error(X, state.x.reshape(-1, 3)) > 0.05
    sm = fe.ShapeMatching(mode=mode, beta=0.5, alpha=0.5, damping=0.3)
    run = fe.simulate(model, sm, DT, steps=150, state=state, energy_growth=math.inf)
    errors = [shape_error(X, X + u) for u in run.displacement[[10, 50, 150]]]
    assert errors[0] > errors[1] > errors[2] and errors[2] < 1e-8


def test_without_damping_the_deformation_oscillates_without_growing():
    """The paper's integration is symplectic Euler on the goal pull: bounded, not damped."""
    model = _beam()
    X = model.X.reshape(-1, 3)
    state = fe.State.rest(model, displacement=_sheared)
    run = fe.simulate(model, fe.ShapeMatching(mode="linear", alpha=0.5), DT, steps=120, state=state,
                      energy_growth=math.inf)
    errors = np.array([shape_error(X, X + u) for u in run.displacement])
    assert errors.max() < 1.5 * errors[0] and errors[60:].max() > 0.3 * errors[0]


def test_clusters_survive_a_large_deformation_and_return():
    model = _beam(cells=(20, 2, 2))
    X = model.X.reshape(-1, 3)
    state = fe.State.rest(model, displacement=_bent)
    assert shape_error(X, state.x.reshape(-1, 3)) > 0.2
    sm = fe.ShapeMatching(mode="quadratic", beta=0.5, alpha=0.5, damping=0.5, clusters=5)
    run = fe.simulate(model, sm, DT, steps=300, state=state, energy_growth=math.inf)
    assert sm.matcher(model).n_clusters == 5 and np.all(np.isfinite(run.displacement))
    errors = [shape_error(X, X + u) for u in run.displacement[[0, 100, 200, 300]]]
    assert errors[3] < 1e-3 * errors[0] and errors[3] < errors[2] < errors[1] < errors[0]
    # what clusters are for: their goals follow a large deformation far more closely than one
    # cluster's can (the pull that tears the shape is that far off), the more so the more clusters
    x = state.x.reshape(-1, 3)
    off = [np.abs(fe.ShapeMatching(mode="quadratic", clusters=n).matcher(model).goals(x) - x).max()
           for n in (1, 5, 10)]
    assert off[2] < 0.5 * off[1] < 0.25 * off[0]


def test_grid_clusters_overlap_and_cover_every_point():
    model = _beam(cells=(20, 2, 2))
    X = model.X.reshape(-1, 3)
    node, cluster = grid_clusters(X, 5, 0.25)  # cells 0.2 m long, each reaching 0.05 m beyond
    assert cluster.max() + 1 == 5 and set(node) == set(range(len(X)))
    per_node = np.bincount(node)
    assert per_node.min() == 1 and per_node.max() == 2  # neighbours share the overlap
    inside = np.abs(X[:, 0] - 0.2 * np.round(X[:, 0] / 0.2)) <= 0.05 + 1e-12  # near an inner wall
    inside &= (X[:, 0] > 0.1) & (X[:, 0] < 0.9)
    assert np.array_equal(per_node == 2, inside)
    node, cluster = grid_clusters(X, 5, 1.0)  # a cell and its neighbours (both, on a wall)
    assert np.median(np.bincount(node)) == 3 and np.bincount(node).max() == 4
    node, cluster = grid_clusters(X, 1, 0.5)
    assert np.array_equal(node, np.arange(len(X))) and np.all(cluster == 0)


# ---------------------------------------------------------------------------------------
# held vertices, loads, obstacles


def test_fixed_vertices_are_held_and_the_cantilever_sags():
    model = _beam(fixed="left", gravity=(0.0, 0.0, -9.81))
    sm = fe.ShapeMatching(mode="linear", beta=0.3, alpha=0.5, damping=0.2, clusters=4)
    run = fe.simulate(model, sm, DT, steps=100)
    held = model.fixed_dofs
    assert np.array_equal(run.final_state.x[held], model.X[held])
    assert np.all(run.final_state.v[held] == 0.0)
    tip = run.displacement[:, :, 2].min(axis=1)
    assert -0.5 < tip[-1] < -1e-3 and np.all(np.isfinite(run.total))


def test_a_dropped_body_stays_on_an_impulse_ground():
    model = _beam(cells=(4, 1, 1), gravity=(0.0, 0.0, -9.81),
                  ground=fe.Ground(z=-0.2, method="impulse"))
    run = fe.simulate(model, fe.ShapeMatching(mode="rigid", alpha=1.0, damping=0.5), DT, steps=60)
    z = run.displacement[:, :, 2] + model.mesh.p[2][None, :]
    assert z.min() >= -0.2 - 1e-12 and z[-1].min() < -0.19  # it fell to the ground and stays


def test_a_point_cloud_needs_no_mesh():
    rng = np.random.default_rng(5)
    rest = rng.normal(size=(200, 3)) * [1.0, 0.3, 0.2]
    masses = rng.uniform(0.5, 2.0, 200)
    sm = fe.ShapeMatcher(rest, masses, mode="quadratic", beta=0.4, clusters=3)
    x = rest + 0.05 * rng.normal(size=rest.shape)
    v = np.zeros_like(rest)
    for _ in range(300):
        x, v = sm.step(x, v, DT, alpha=0.5, damping=0.3)
    assert shape_error(rest, x) < 1e-6
    # momentum stays 0 to the round-off of 300 goal pulls of O(|x| / dt) each
    assert np.abs((masses[:, None] * v).sum(axis=0)).max() < 1e-12 * masses.sum() * 300 / DT
    # held points stay where they are and anchor the rest
    held = rest[:, 0] < -1.0
    sm = fe.ShapeMatcher(rest, masses, mode="linear", clusters=3, held=held)
    x, v = rest.copy(), np.zeros_like(rest)
    for _ in range(100):
        x, v = sm.step(x, v, DT, alpha=0.5, damping=0.3, force=masses[:, None] * [0.0, 0.0, -9.81])
    assert np.array_equal(x[held], rest[held]) and np.all(v[held] == 0.0)
    assert -0.05 < (x - rest)[:, 2].min() < 0.0  # it hangs from them


# ---------------------------------------------------------------------------------------
# scene files, checkpoints, bad input


def test_a_scene_file_builds_it_and_names_its_modes():
    text = small_scene("sm", material="corotated", cells=(6, 1, 1), duration=0.05, integrator="shape_matching",
                       integrator_options='mode = "quadratic"\nbeta = 0.3\nclusters = 3\ndamping = 0.1')
    run = parse_scene(text).build()[0]
    sm = run.integrator
    assert isinstance(sm, fe.ShapeMatching)
    assert (sm.mode, sm.beta, sm.clusters, sm.damping, sm.alpha) == ("quadratic", 0.3, 3, 0.1, 0.5)
    traj = fe.simulate(run.model, sm, run.dt, steps=run.steps, state=run.state)
    assert traj.displacement[-1, :, 2].min() < 0
    with pytest.raises(SceneError, match="quadratic"):
        parse_scene(text.replace('"quadratic"', '"quadratc"'))


def test_a_resumed_run_is_the_uninterrupted_one(tmp_path):
    def make():
        return _beam(cells=(4, 1, 1), fixed="left", gravity=(0.0, 0.0, -9.81))

    sm = {"mode": "linear", "clusters": 2, "damping": 0.1}
    full = fe.simulate(make(), fe.ShapeMatching(**sm), DT, steps=9)

    def stop(step, state):
        if step == 4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        fe.simulate(make(), fe.ShapeMatching(**sm), DT, steps=9, checkpoint_dir=tmp_path, callback=stop)
    resumed = fe.simulate(make(), fe.ShapeMatching(**sm), DT, steps=9, checkpoint_dir=tmp_path, resume=True)
    assert resumed.resumed_from_step == 4
    assert np.array_equal(resumed.displacement, full.displacement)


@pytest.mark.parametrize("kwargs, words", [
    ({"mode": "affine"}, "mode must be one of"),
    ({"beta": 1.5}, r"beta must be a number in \[0, 1\]"),
    ({"alpha": 0.0}, r"alpha must be a number in \(0, 1\]"),
    ({"damping": -0.1}, r"damping must be a number in \[0, 1\]"),
    ({"clusters": 0}, "clusters must be an integer >= 1"),
    ({"overlap": -1.0}, "overlap must be a number"),
])
def test_bad_settings_are_refused(kwargs, words):
    with pytest.raises(fe.InvalidParameter, match=words):
        fe.ShapeMatching(**kwargs)


def test_flat_point_sets_are_refused():
    flat = np.random.default_rng(6).random((30, 3)) * [1.0, 1.0, 0.0]
    with pytest.raises(fe.InvalidParameter, match="coplanar"):
        fe.ShapeMatcher(flat, np.ones(30))
    with pytest.raises(fe.InvalidParameter, match="masses"):
        fe.ShapeMatcher(np.eye(4, 3), -np.ones(4))
