"""State: immutable positions, velocities and time."""

import numpy as np
import pytest

import fem_elastic as fe


@pytest.fixture(scope="module", params=[1, 2])
def model(request):
    return fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1000.0,
                    body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3), order=request.param))


def test_state_is_an_immutable_copy(model):
    x = model.X.copy()
    s = fe.State(x, np.zeros_like(x), 0.5)
    x[0] = 99.0
    assert s.x[0] != 99.0
    with pytest.raises(ValueError):
        s.x[0] = 1.0
    with pytest.raises(AttributeError):
        s.t = 1.0


def test_rest_accepts_vectors_arrays_and_functions(model):
    nv = model.mesh.p.shape[1]
    s = fe.State.rest(model, velocity=(1.0, 2.0, 3.0))
    np.testing.assert_allclose(s.v.reshape(-1, 3), np.broadcast_to([1, 2, 3], (model.ndofs // 3, 3)))
    u = np.random.default_rng(0).random((nv, 3))
    s = fe.State.rest(model, displacement=u)
    np.testing.assert_allclose(s.displacement(model), u)  # vertices exactly
    # a linear field given as a function is reproduced at every node (edge nodes too)
    s = fe.State.rest(model, velocity=lambda X: 2.0 * X)
    np.testing.assert_allclose(s.v, 2.0 * model.X)
    if model.space.order == 2:  # vertex values: edge nodes take the mean, exact for linear fields
        s2 = fe.State.rest(model, velocity=2.0 * model.mesh.p.T)
        np.testing.assert_allclose(s2.v, 2.0 * model.X, atol=1e-14)


def test_rest_rejects_bad_shapes(model):
    with pytest.raises(fe.InvalidParameter, match="shape"):
        fe.State.rest(model, velocity=np.zeros((5, 2)))
    with pytest.raises(fe.InvalidParameter, match="shape"):
        fe.State(np.zeros(3), np.zeros(4))


def test_rest_names_the_shapes_it_accepts(model):
    nn, nv = model.ndofs // 3, model.mesh.p.shape[1]
    with pytest.raises(fe.InvalidParameter) as info:
        fe.State.rest(model, velocity=np.zeros((5, 2)))
    # P1: nodes are vertices, one shape; P2: every node or the vertices
    shapes = f"({nn}, 3)," if nn == nv else f"({nn}, 3) (every node) or ({nv}, 3) (the vertices),"
    assert f"an array of shape {shapes} or a function" in str(info.value)


@pytest.mark.parametrize("name", ["displacement", "velocity"])
def test_rest_rejects_non_finite_fields_in_every_form(model, name):
    nv = model.mesh.p.shape[1]
    field = np.zeros((nv, 3))
    field[3, 1] = np.inf
    for value, what in [((0.0, np.nan, 0.0), name), (field, name),
                        (lambda X: np.where(X > 0.5, np.nan, 0.0), f"the {name} function")]:
        with pytest.raises(fe.InvalidParameter, match=rf"^{what} has \d+ NaN or infinite value"):
            fe.State.rest(model, **{name: value})
