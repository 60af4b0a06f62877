"""Driven boundaries: prescribed motions and how the model holds them."""

import numpy as np
import pytest

import fem_elastic as fe


def _fd_velocity(motion, X, t, h=1e-6):
    return (motion.displacement(X, t + h) - motion.displacement(X, t - h)) / (2 * h)


def test_twist_is_a_rigid_rotation_with_the_exact_velocity():
    rng = np.random.default_rng(1)
    X = rng.random((20, 3))
    tw = fe.Twist(np.pi, duration=2.0, axis=(1.0, 1.0, 0.0), center=(0.5, 0.5, 0.5))
    for t in (0.3, 1.0, 1.7):
        x = X + tw.displacement(X, t)
        # distances between points are kept (a rotation), points on the axis do not move
        d0 = np.linalg.norm(X[:, None] - X[None], axis=-1)
        d1 = np.linalg.norm(x[:, None] - x[None], axis=-1)
        np.testing.assert_allclose(d1, d0, atol=1e-13)  # round-off of a rotation of unit-size points
        # central difference: O(h^2) ~ 1e-12 m/s with h = 1e-6 s, plus round-off 1e-16/1e-6
        np.testing.assert_allclose(tw.velocity(X, t), _fd_velocity(tw, X, t), atol=1e-8)
    on_axis = np.array([[0.5, 0.5, 0.5], [1.5, 1.5, 0.5]])
    np.testing.assert_allclose(tw.displacement(on_axis, 1.0), 0.0, atol=1e-15)
    # held after the ramp: the full angle, no velocity
    np.testing.assert_allclose(tw.velocity(X, 3.0), 0.0)
    full = fe.Twist(2 * np.pi, duration=1.0)
    np.testing.assert_allclose(full.displacement(X, 1.0), 0.0, atol=1e-14)


def test_translate_and_prescribed():
    tr = fe.Translate((0.0, 0.0, -0.5), duration=2.0)
    X = np.zeros((3, 3))
    np.testing.assert_allclose(tr.displacement(X, 1.0)[:, 2], -0.25)
    np.testing.assert_allclose(tr.velocity(X, 1.0)[:, 2], -0.25)
    np.testing.assert_allclose(tr.displacement(X, 5.0)[:, 2], -0.5)
    pr = fe.Prescribed(lambda X, t: X * t)
    np.testing.assert_allclose(pr.velocity(np.ones((2, 3)), 1.0), 1.0, atol=1e-8)
    bad = fe.Prescribed(lambda X, t: np.zeros(3))
    with pytest.raises(fe.InvalidParameter, match="shape"):
        bad.displacement(np.ones((2, 3)), 0.0)


def test_model_holds_driven_dofs_until_release():
    mesh = fe.beam_mesh(cells=(4, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)),
                     fixed="left", driven={"right": fe.Translate((0.1, 0, 0), duration=1.0, release=2.0)})
    right = np.flatnonzero(np.isclose(mesh.p[0], mesh.p[0].max()))
    dofs, x, v = model.constraints(0.5)
    held = set(dofs.tolist())
    assert all(3 * i + 2 in held for i in right)
    assert not model.free[3 * right].any()  # statics holds them at rest
    assert model.free_at(2.5)[3 * right].all()  # released
    assert model.driving(0.5) and not model.driving(1.5)  # held still after its 1 s: no work done
    pos = dict(zip(dofs.tolist(), x.tolist()))
    np.testing.assert_allclose([pos[3 * i] for i in right], mesh.p[0, right] + 0.05)
    s = fe.simulate(model, fe.ImplicitEuler(), 0.1, t_end=1.0).final_state
    np.testing.assert_allclose(s.x[3 * right], mesh.p[0, right] + 0.1, atol=1e-14)


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: fe.Twist(np.nan, 1.0), "angle"),
        (lambda: fe.Twist(1.0, -1.0), "duration"),
        (lambda: fe.Twist(1.0, 1.0, axis=(0, 0, 0)), "axis"),
        (lambda: fe.Translate((0, 0), 1.0), "offset"),
        (lambda: fe.Translate((0, 0, 1), 1.0, release=-1), "release"),
        (lambda: fe.Prescribed("up"), "function"),
    ],
)
def test_bad_motions(make, match):
    with pytest.raises(fe.InvalidParameter, match=match):
        make()


def test_bad_driven_argument():
    with pytest.raises(fe.InvalidParameter, match="driven"):
        fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1.0,
                 body=fe.ElasticBody(fe.LinearElastic(E=1.0, nu=0.3)), driven={"right": (0, 0, 1)})
    with pytest.raises(fe.InvalidParameter, match="driven names boundary 'nowhere'"):
        fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1.0,
                 body=fe.ElasticBody(fe.LinearElastic(E=1.0, nu=0.3)),
                 driven={"nowhere": fe.Translate((0, 0, 1), 1.0)})
