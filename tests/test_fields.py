"""Tests of fem_elastic.physics.fields: per-tet von Mises stress and strain-energy density.

Closed forms (homogeneous stretches), invariants (energy sums, the spring
network's virial against the force through a section, frame indifference)
and the inverted-element convention.
"""

from types import SimpleNamespace

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.errors import InvalidParameter
from fem_elastic.physics.fields import CellFields, cell_fields, von_mises

E, NU = 1.0e6, 0.3


def _cube(cells=(2, 2, 2)):
    return fe.beam_mesh(length=1.0, width=1.0, height=1.0, cells=cells)


def _model(body, mesh=None):
    return fe.Model(_cube() if mesh is None else mesh, density=1000.0, body=body)


def _affine(model, F, c=(0.0, 0.0, 0.0)):
    """Positions of every DOF (P2 mid-edge nodes included) under x = F X + c."""
    return (model.X.reshape(-1, 3) @ np.asarray(F).T + c).ravel()


def _rotation(axis, angle):
    """Rodrigues' formula."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _principal_von_mises(sigma):
    s1, s2, s3 = np.linalg.eigvalsh(sigma)
    return np.sqrt(0.5 * ((s1 - s2) ** 2 + (s2 - s3) ** 2 + (s3 - s1) ** 2))


# --- the von Mises helper ---------------------------------------------------------------


def test_von_mises_of_elementary_stresses():
    tau = 3.0e5
    shear = np.array([[0, tau, 0], [tau, 0, 0], [0, 0, 0]])
    stack = np.stack([np.diag([-7.0, 0, 0]), shear, 4.0 * np.eye(3)], axis=-1)  # (3, 3, 3)
    # uniaxial |s|, pure shear sqrt(3) tau, hydrostatic 0; exact up to one rounding of sqrt
    np.testing.assert_allclose(von_mises(stack), [7.0, np.sqrt(3.0) * tau, 0.0], rtol=1e-15, atol=0)
    Q = _rotation((1, 2, 3), 0.9)
    general = np.array([[1.0, 0.3, -0.2], [0.3, -2.0, 0.5], [-0.2, 0.5, 0.7]]) * 1e5
    # invariant under rotation; the principal-stress form is an independent formula.
    # 1e-12: eigvalsh and the rotation each round at ~1e-16 of the largest stress.
    np.testing.assert_allclose(von_mises(Q @ general @ Q.T), _principal_von_mises(general),
                               rtol=1e-12)
    with pytest.raises(InvalidParameter, match="3, 3"):
        von_mises(np.zeros((5, 3, 3)))


# --- FEM bodies: closed forms -------------------------------------------------------------


@pytest.mark.parametrize("order", [1, 2])
def test_linear_elastic_uniaxial_stress(order):
    """F = diag(1 + eps, 1 - nu eps, 1 - nu eps): P = diag(E eps, 0, 0) exactly.

    The Cauchy stress P F^T / J is uniaxial, E eps (1 + eps) / J = E eps / (1 - nu eps)^2,
    so von Mises is that value, and psi = 1/2 E eps^2, in every tet.
    """
    eps = 1e-2
    model = _model(fe.ElasticBody(fe.LinearElastic(E=E, nu=NU), order=order))
    x = _affine(model, np.diag([1 + eps, 1 - NU * eps, 1 - NU * eps]))
    out = cell_fields(model, x)
    n_tets = model.mesh.t.shape[1]
    assert out["von_mises"].shape == out["energy_density"].shape == (n_tets,)
    # 1e-12: F carries ~1e-16 absolute round-off, which P turns into ~(lam + 2 mu) 1e-16,
    # 1e-13 of E eps here; the energy carries the same relative error.
    np.testing.assert_allclose(out["von_mises"], E * eps / (1 - NU * eps) ** 2, rtol=1e-12)
    np.testing.assert_allclose(out["energy_density"], 0.5 * E * eps**2, rtol=1e-12)


@pytest.mark.parametrize("order", [1, 2])
def test_neohookean_homogeneous_deformation_against_closed_form(order):
    """psi = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2 is a function of I1 = tr b and J, so

    sigma = (2 / J) dpsi/dI1 b + dpsi/dJ I = (mu (b - I) + lam ln J I) / J,   b = F F^T.
    """
    material = fe.NeoHookean(E=E, nu=NU)
    mu, lam = material.mu, material.lam
    F = np.array([[1.10, 0.20, 0.00], [0.05, 0.95, 0.10], [0.00, -0.03, 1.02]])  # stretch + shear
    J = np.linalg.det(F)
    b = F @ F.T
    sigma = (mu * (b - np.eye(3)) + lam * np.log(J) * np.eye(3)) / J
    psi = mu / 2 * (np.trace(b) - 3) - mu * np.log(J) + lam / 2 * np.log(J) ** 2

    model = _model(fe.ElasticBody(material, order=order))
    x = _affine(model, F, c=(0.3, -0.1, 2.0))
    fields = CellFields(model)
    out = fields(x)
    # 1e-11: F is interpolated from positions of size ~2 m, ~1e-15 absolute round-off in
    # F, turned by mu, lam ~1e6 Pa into ~1e-9 Pa on stresses of ~1e5 Pa.
    np.testing.assert_allclose(out["von_mises"], _principal_von_mises(sigma), rtol=1e-11)
    np.testing.assert_allclose(out["energy_density"], psi, rtol=1e-11)
    S = fields.stress(x)
    np.testing.assert_allclose(S, np.broadcast_to(sigma[:, :, None], S.shape), rtol=0,
                               atol=1e-11 * np.abs(sigma).max())


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("material", [fe.NeoHookean, fe.StVK, fe.Corotated, fe.StableNeoHookean])
def test_energy_density_times_volume_is_the_body_energy(order, material):
    model = _model(fe.ElasticBody(material(E=E, nu=NU), order=order))
    rng = np.random.default_rng(3)
    x = model.X + 0.02 * rng.standard_normal(model.X.shape)  # non-affine, 2 % of a 0.5 m cell
    fields = CellFields(model)
    total = np.sum(fields(x)["energy_density"] * fields.volume)
    # the same quadrature sum in a different order: round-off only
    np.testing.assert_allclose(total, model.body_potential.energy(x), rtol=1e-12)
    np.testing.assert_allclose(fields.volume.sum(), 1.0, rtol=1e-14)  # the unit cube


# --- frame indifference and inversion -----------------------------------------------------


@pytest.mark.parametrize(
    "body",
    [fe.ElasticBody(fe.NeoHookean(E=E, nu=NU)), fe.ElasticBody(fe.StVK(E=E, nu=NU), order=2),
     fe.ElasticBody(fe.Corotated(E=E, nu=NU)), fe.ElasticBody(fe.StableNeoHookean(E=E, nu=NU)),
     fe.MassSpring(E=E)],
    ids=["NeoHookean", "StVK-P2", "Corotated", "StableNeoHookean", "MassSpring"],
)
def test_rigid_motion_is_stress_free(body):
    model = _model(body)
    x = _affine(model, _rotation((1, 2, 3), 1.3), c=(5.0, -2.0, 1.0))
    out = cell_fields(model, x)
    # round-off of F = R (positions of size ~6 m): ~1e-15, times the moduli ~1e6 Pa
    assert np.all(out["von_mises"] < 1e-8)
    assert np.all(np.abs(out["energy_density"]) < 1e-8)


def test_linear_elastic_is_not_frame_indifferent():
    """Its spurious stress under a rotation theta is of order E theta^2 (second order)."""
    model = _model(fe.ElasticBody(fe.LinearElastic(E=E, nu=NU)))
    theta = 1e-3
    vm1, vm2 = (cell_fields(model, _affine(model, _rotation((0, 0, 1), a)))["von_mises"]
                for a in (theta, 2 * theta))
    assert np.all(vm1 > 0.05 * E * theta**2) and np.all(vm1 < E * theta**2)
    # the next term is O(theta^4), 1e-6 relative here
    np.testing.assert_allclose(vm2 / vm1, 4.0, rtol=1e-4)


def _push_vertex_through(model):
    """Move the cube's centre vertex far out along x: tets on the -x side turn inside out."""
    X = model.X.reshape(-1, 3)
    centre = np.flatnonzero(np.all(np.isclose(X, 0.5), axis=1))
    assert centre.size == 1
    x = X.copy()
    x[centre] = [2.0, 0.5, 0.5]
    p = x[model.mesh.t]  # (4, ne, 3) corners
    v = np.einsum("ei,ei->e", p[1] - p[0], np.cross(p[2] - p[0], p[3] - p[0]))
    inverted = v < 0
    assert 0 < inverted.sum() < inverted.size
    return x.ravel(), inverted


@pytest.mark.parametrize(
    "body", [fe.ElasticBody(fe.NeoHookean(E=E, nu=NU)),
             fe.ElasticBody(fe.StableNeoHookean(E=E, nu=NU)), fe.MassSpring(E=E)],
    ids=["NeoHookean", "StableNeoHookean", "MassSpring"],
)
def test_inverted_tets_have_nan_von_mises(body):
    model = _model(body)
    x, inverted = _push_vertex_through(model)
    fields = CellFields(model)
    out = fields(x)
    np.testing.assert_array_equal(np.isnan(out["von_mises"]), inverted)
    assert np.all(np.isnan(fields.stress(x)[:, :, inverted]))
    ed = out["energy_density"]
    if isinstance(body, fe.ElasticBody) and isinstance(body.material, fe.NeoHookean):
        assert np.all(ed[inverted] == np.inf)  # the material's own convention, passed through
    else:
        assert np.all(np.isfinite(ed))


# --- spring bodies --------------------------------------------------------------------------


@pytest.mark.parametrize("calibration", [fe.van_gelder_stiffness, fe.lloyd_stiffness])
def test_spring_energy_density_sums_to_the_spring_energy(calibration):
    model = _model(fe.MassSpring(E=E, calibration=calibration), mesh=_cube((3, 2, 2)))
    x = model.X + 0.03 * np.random.default_rng(7).standard_normal(model.X.shape)
    fields = CellFields(model)
    out = fields(x)
    # each spring's energy is split in shares that sum to 1: exact up to round-off
    np.testing.assert_allclose(np.sum(out["energy_density"] * fields.volume),
                               model.body_potential.energy(x), rtol=1e-12)
    assert np.all(out["energy_density"] >= 0)


@pytest.mark.parametrize("calibration", [fe.van_gelder_stiffness, fe.lloyd_stiffness])
def test_spring_virial_stress_carries_the_section_force(calibration):
    """Uniaxial stretch x -> diag(1 + eps, 1, 1) X of a 6 x 4 x 4 beam of springs.

    Every spring with a length along x lies within one layer of cells and crosses
    every section x = c of that layer, with l_x = h (1 + eps). So over the layer's tets
    sum_t v_t sigma_xx = sum_e T_e n_x l_x = h (1 + eps) F_x, with F_x the tension
    through the section, and the layer's current volume is h (1 + eps) A: the
    volume-weighted mean of sigma_xx over a layer is F_x / A exactly.

    Within a cube the six tets differ (by about +-15 %: one tet of a 6-tet split is
    an anisotropic spring cell), but the cube, the mesh's repeating cell, carries the
    same mean stress everywhere in the interior.
    """
    length, side, eps = 0.6, 0.2, 1e-3
    mesh = fe.beam_mesh(length=length, width=side, height=side, cells=(6, 4, 4))
    model = _model(fe.MassSpring(E=E, calibration=calibration), mesh=mesh)
    X = model.X.reshape(-1, 3)
    x = (X * [1 + eps, 1, 1]).ravel()
    S = CellFields(model).stress(x)[0, 0]

    pot = model.body_potential
    xp = x.reshape(-1, 3)
    d = xp[pot.edges[1]] - xp[pot.edges[0]]
    l = np.linalg.norm(d, axis=1)
    tension = pot.stiffness * (l - pot.rest_length)
    p = xp[mesh.t]
    v = np.einsum("ei,ei->e", p[1] - p[0], np.cross(p[2] - p[0], p[3] - p[0])) / 6
    centroid = X[mesh.t].mean(axis=0)
    h = length / 6
    for layer in range(6):
        c = (layer + 0.5) * h * (1 + eps)  # a section through the middle of the layer
        crossing = (np.minimum(xp[pot.edges[0], 0], xp[pot.edges[1], 0]) < c) & (
            np.maximum(xp[pot.edges[0], 0], xp[pot.edges[1], 0]) > c)
        Fx = np.sum(tension[crossing] * np.abs(d[crossing, 0]) / l[crossing])
        tets = np.floor(centroid[:, 0] / h).astype(int) == layer
        mean = np.sum(v[tets] * S[tets]) / np.sum(v[tets])
        np.testing.assert_allclose(mean, Fx / side**2, rtol=1e-12)  # an identity: round-off
    assert Fx > 0

    cube = np.floor(centroid / [h, side / 4, side / 4]).astype(int)
    interior = np.all((cube > 0) & (cube < [5, 3, 3]), axis=1)
    key = cube[:, 0] * 100 + cube[:, 1] * 10 + cube[:, 2]
    means = [np.sum(v[key == k] * S[key == k]) / np.sum(v[key == k])
             for k in np.unique(key[interior])]
    # uniform to round-off: every interior cube holds the same springs' shares
    np.testing.assert_allclose(means, Fx / side**2, rtol=1e-10)
    spread = (S[interior].max() - S[interior].min()) / (Fx / side**2)
    assert 0.05 < spread < 0.5  # the per-tet anisotropy described above (~0.27 measured)


def test_springs_off_the_mesh_edges_are_rejected():
    model = _model(fe.MassSpring(E=E))
    pot = model.body_potential
    X = model.X.reshape(-1, 3)
    far = np.argmax(np.linalg.norm(X - X[0], axis=1))  # the opposite corner: no tet edge
    # a stand-in model: CellFields reads only .space and .body_potential
    off_edge = type(pot)(model.X, [[0], [int(far)]], [1.0])
    bad = SimpleNamespace(space=model.space, body_potential=off_edge)
    with pytest.raises(InvalidParameter, match="no tet edge"):
        CellFields(bad)
    with pytest.raises(InvalidParameter, match="ElasticBody and fe.MassSpring"):
        CellFields(SimpleNamespace(space=model.space, body_potential=object()))


def test_bad_input_is_rejected():
    model = _model(fe.ElasticBody(fe.NeoHookean(E=E, nu=NU)))
    with pytest.raises(InvalidParameter, match="state.x"):
        cell_fields(model, model.X[:-3])
