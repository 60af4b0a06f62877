"""The PSD projection of IPC's pair Hessians (``fe.IPCContact(projection=...)``)."""

from __future__ import annotations

import numpy as np
import pytest

import fem_elastic as fe

GAP = 5e-4  # m: the apex of the upper tet above the lower tet's top face, inside dhat = 1e-3 m


def _one_pair(projection):
    """Two tets, the upper one's apex GAP above the interior of the lower one's top face.

    Every other pair of surface primitives is at least 0.2 m apart, far outside dhat, so
    exactly one vertex-triangle pair is active and the projected Hessian of the whole barrier
    is that of the one pair.
    """
    p = np.array([
        [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0],  # lower
        [0.25, 0.25, GAP], [0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0],  # upper
    ])
    t = np.array([[0, 2, 1, 3], [4, 5, 6, 7]])  # both positively oriented
    mesh = fe.mesh_from_arrays(p, t)
    model = fe.Model(mesh, 1000.0, fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
                     contact=fe.IPCContact(dhat=1e-3, kappa=1e6, projection=projection))
    return model, model.contact


@pytest.mark.filterwarnings("ignore:IPC contact")
@pytest.mark.parametrize("projection", ["clamp", "abs"])
def test_projected_pair_hessian_filters_the_exact_one_eigenvalue_by_eigenvalue(projection):
    model, c = _one_pair(projection)
    x = model.X.copy()
    assert c.diagnostics(x)["active_contacts"] == 1
    H = c.hessian(x, project=False).toarray()
    lam, V = np.linalg.eigh(H)
    scale = np.abs(lam).max()
    # the point-plane distance is not convex in the triangle's vertices: the exact pair Hessian
    # is indefinite, so the two projections differ from it (and from each other)
    assert lam.min() < -1e-6 * scale
    filtered = np.abs(lam) if projection == "abs" else np.maximum(lam, 0.0)
    expected = (V * filtered) @ V.T
    Hp = c.hessian(x, project=True).toarray()
    # ipctk's own 12 x 12 eigendecomposition against numpy's of the embedded matrix: both
    # backward stable, so they agree to a few eps of the largest eigenvalue (1e-9: margin)
    np.testing.assert_allclose(Hp, expected, atol=1e-9 * scale)
    assert np.linalg.eigvalsh(Hp).min() >= -1e-9 * scale  # PSD to the same round-off


@pytest.mark.filterwarnings("ignore:IPC contact")
def test_projection_changes_only_the_projected_hessian():
    _, clamp = _one_pair("clamp")
    model, absolute = _one_pair("abs")
    x = model.X.copy()
    np.testing.assert_array_equal(clamp.gradient(x), absolute.gradient(x))
    He_c = clamp.hessian(x, project=False).toarray()
    He_a = absolute.hessian(x, project=False).toarray()
    # one pair: ipctk's assembly has no summation order to vary, the exact Hessians are equal
    np.testing.assert_array_equal(He_c, He_a)
    assert np.abs(clamp.hessian(x, project=True) - absolute.hessian(x, project=True)).max() \
        > 1e-6 * np.abs(He_c).max()


@pytest.mark.filterwarnings("ignore:IPC contact")
def test_absolute_projection_steps_a_drop_without_intersection():
    """The Newton path with the absolute-value projection: a cube dropped from dhat / 2 onto a
    cube with a fixed bottom settles into the barrier, never intersecting, as with the clamp."""
    size = 0.2
    m = fe.beam_mesh(length=size, width=size, height=size, cells=(2, 2, 2))
    p, t = m.p.T, m.t.T
    mesh = fe.mesh_from_arrays(np.vstack([p, p + [0.0, 0.0, size + GAP]]),
                               np.vstack([t, t + len(p)]))
    fixed = np.zeros(mesh.p.shape[1], dtype=bool)
    fixed[: len(p)] = mesh.p[2, : len(p)] < 1e-12
    model = fe.Model(mesh, 1000.0, fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3)), fixed=fixed,
                     gravity=(0.0, 0.0, -9.81), contact=fe.IPCContact(dhat=1e-3, projection="abs"))
    ie, state = fe.ImplicitEuler(max_iter=200), fe.State.rest(model)
    for _ in range(4):
        state = ie.step(model, state, 0.01)
        assert not model.contact.has_intersections(state.x)
    d = model.contact.diagnostics(state.x)
    # in contact, inside the barrier: closer than dhat, never at 0
    assert d["active_contacts"] > 0 and 0.0 < d["min_distance"] < 1e-3


def test_bad_projection_is_refused():
    with pytest.raises(fe.InvalidParameter, match="projection"):
        fe.IPCContact(dhat=1e-3, projection="eigen")
