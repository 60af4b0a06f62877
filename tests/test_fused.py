"""Tests of fem_elastic.discretization.fused: the fused numba P1 kernels against the numpy path.

Both paths of ``ElasticPotential.energy`` / ``.gradient`` run on a small distorted P1 mesh
at random deformations, and must agree to round-off for every registered material; the
fused energy and gradient are checked against each other by central differences; the
fallbacks (``FEM_ELASTIC_NUMBA=0``, numba missing, P2, unregistered materials) take the
numpy path. Tests that need numba are skipped without it.
"""

import subprocess
import sys
from functools import lru_cache

import numpy as np
import pytest
import skfem

import fem_elastic as fe
from fem_elastic.discretization import fused
from fem_elastic.discretization import Discretization
from fem_elastic.physics.elastic_body import ElasticPotential

E, NU = 1.0e6, 0.4
REGISTERED = [fe.LinearElastic, fe.StVK, fe.NeoHookean, fe.StableNeoHookean]
RTOL = 1e-12

needs_numba = pytest.mark.skipif(
    not fused.available(), reason="numba not installed (or FEM_ELASTIC_NUMBA=0)"
)


def ids(cls):
    return cls.__name__


@lru_cache(maxsize=None)
def space(order: int = 1, cells: tuple[int, int, int] = (3, 2, 2)) -> Discretization:
    """A 0.3 x 0.1 x 0.1 m box of ``cells`` (default 3 x 2 x 2: 72 tets), vertices moved by <= 10 %."""
    mesh = fe.beam_mesh(0.3, 0.1, 0.1, cells=cells)
    rng = np.random.default_rng(7)
    mesh = skfem.MeshTet(mesh.p + rng.uniform(-0.005, 0.005, mesh.p.shape), mesh.t)
    fe.validate_mesh(mesh)
    return Discretization(mesh, order)


def det3(F):
    return np.linalg.det(np.moveaxis(F, (0, 1), (-2, -1)))


def random_states(n=3, noise=0.004):
    """Affine deformations far from I (stretch, shear, rotation) plus nodal noise; all J > 0."""
    s = space()
    rng = np.random.default_rng(11)
    Xp = s.X.reshape(-1, 3)
    states = []
    while len(states) < n:
        A = np.eye(3) + 0.3 * rng.standard_normal((3, 3))
        x = (Xp @ A.T).ravel() + noise * rng.standard_normal(s.ndofs)
        if det3(s.deformation_gradient(x - s.X)).min() > 0.2:
            states.append(x)
    return states


def numpy_path(monkeypatch, fn):
    with monkeypatch.context() as m:
        m.setenv(fused.ENV, "0")
        return fn()


# the switch ------------------------------------------------------------------------------
def test_environment_variable_switches_the_fused_path_off(monkeypatch):
    monkeypatch.setenv(fused.ENV, "0")
    assert not fused.available()
    assert fused.kernels_for(fe.NeoHookean(E, NU), space()) is None


def test_numpy_path_without_numba(monkeypatch):
    """As if numba were not installed: available() is False and the potential still works."""
    monkeypatch.delenv(fused.ENV, raising=False)
    monkeypatch.setattr(fused, "_module", None)
    monkeypatch.setattr(fused, "_import_error", ImportError("No module named 'numba'"))
    assert not fused.available()
    assert fused.registry() == {}
    pot = ElasticPotential(fe.NeoHookean(E, NU), space())
    x = random_states(1)[0]
    assert pot._fused() is None
    np.testing.assert_array_equal(pot.gradient(x), pot._force(pot.material.dpsi_dF(pot.F(x))))


def test_import_does_not_load_numba():
    code = "import sys, fem_elastic; sys.exit('numba' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


@needs_numba
def test_registry_covers_the_closed_form_materials():
    reg = fused.registry()
    assert set(reg) == set(REGISTERED)
    assert len({k.kind for k in reg.values()}) == len(reg)
    assert fe.Corotated not in reg  # per-element SVD: numpy path


@needs_numba
@pytest.mark.parametrize("material", [fe.Corotated(E, NU)], ids=["Corotated"])
def test_unregistered_material_takes_the_numpy_path(material):
    assert fused.kernels_for(material, space()) is None
    assert fused.kernels_for(material, space(2)) is None
    # P2 has its own fused kernels (tests/test_fused_p2.py)
    from fem_elastic.discretization._fused_p2_kernels import FusedP2

    assert isinstance(fused.kernels_for(fe.NeoHookean(E, NU), space(2)), FusedP2)

    class Custom(fe.NeoHookean):  # a subclass may change psi: exact classes only
        pass

    assert fused.kernels_for(Custom(E, NU), space()) is None
    assert isinstance(fused.kernels_for(fe.NeoHookean(E, NU), space()), fused.FusedP1)


# agreement with the numpy path -----------------------------------------------------------
@needs_numba
@pytest.mark.parametrize("material_cls", REGISTERED, ids=ids)
def test_pointwise_kernels_match_the_materials(material_cls):
    """psi and P at single points, near I and far from it (including inverted F)."""
    m = material_cls(E, NU)
    k = fused.registry()[material_cls]
    rng = np.random.default_rng(3)
    F = np.concatenate([
        np.eye(3)[:, :, None] + 1e-3 * rng.standard_normal((3, 3, 50)),
        np.eye(3)[:, :, None] + 0.5 * rng.standard_normal((3, 3, 50)),
    ], axis=-1)
    if material_cls is fe.NeoHookean:
        F = F[:, :, det3(F) > 0]
    prm = k.params(m)
    psi = np.empty(F.shape[-1])
    P = np.empty((9, F.shape[-1]))
    kern = fused._kernels()
    kern.psi_points(k.kind, np.ascontiguousarray(F.reshape(9, -1)), prm, psi)
    kern.P_points(k.kind, np.ascontiguousarray(F.reshape(9, -1)), prm, P)
    psi_ref, P_ref = m.psi(F), m.dpsi_dF(F).reshape(9, -1)
    np.testing.assert_allclose(psi, psi_ref, rtol=RTOL, atol=RTOL * np.abs(psi_ref).max())
    scale = np.abs(P_ref).max(axis=0)  # per point
    assert np.all(np.abs(P - P_ref).max(axis=0) <= RTOL * scale)


@needs_numba
@pytest.mark.parametrize("material_cls", REGISTERED, ids=ids)
def test_energy_and_gradient_match_the_numpy_path(material_cls, monkeypatch):
    pot = ElasticPotential(material_cls(E, NU), space())
    assert pot._fused() is not None
    for x in random_states():
        e_f, g_f = pot.energy(x), pot.gradient(x)
        e_np = numpy_path(monkeypatch, lambda: pot.energy(x))
        g_np = numpy_path(monkeypatch, lambda: pot.gradient(x))
        assert abs(e_f - e_np) <= RTOL * abs(e_np)
        assert np.linalg.norm(g_f - g_np) <= RTOL * np.linalg.norm(g_np)
        assert np.abs(g_f - g_np).max() <= RTOL * np.abs(g_np).max()


@needs_numba
@pytest.mark.parametrize("material_cls", REGISTERED, ids=ids)
def test_rest_state_is_free_of_energy_and_force(material_cls):
    pot = ElasticPotential(material_cls(E, NU), space())
    X = space().X
    assert pot.energy(X) == 0.0
    assert np.abs(pot.gradient(X)).max() <= 1e-12 * E * 0.1**2


@needs_numba
def test_inverted_neohookean_element(monkeypatch):
    """+inf energy on both paths; the gradient is NaN on the same DOFs (P is NaN at J <= 0)."""
    pot = ElasticPotential(fe.NeoHookean(E, NU), space())
    x = random_states(1)[0].copy()
    s = space()
    nodes = s.element_dofs[0::3, 0] // 3  # the first tet's vertices
    x[3 * nodes[0]: 3 * nodes[0] + 3] = x.reshape(-1, 3)[nodes[1:]].mean(axis=0) * 2.0 - x.reshape(
        -1, 3)[nodes[0]]  # reflect vertex 0 through the opposite face's centroid: J < 0
    assert det3(s.deformation_gradient(x - s.X))[0, 0] < 0
    assert pot.energy(x) == np.inf
    assert numpy_path(monkeypatch, lambda: pot.energy(x)) == np.inf
    g_f = pot.gradient(x)
    g_np = numpy_path(monkeypatch, lambda: pot.gradient(x))
    np.testing.assert_array_equal(np.isnan(g_f), np.isnan(g_np))
    assert np.isnan(g_f).any()
    ok = ~np.isnan(g_np)
    assert np.linalg.norm(g_f[ok] - g_np[ok]) <= RTOL * np.linalg.norm(g_np[ok])


@needs_numba
def test_inverted_stable_neohookean_element_stays_finite(monkeypatch):
    pot = ElasticPotential(fe.StableNeoHookean(E, NU), space())
    x = space().X.copy().reshape(-1, 3)
    x[:, 2] *= -1.0  # mirror the whole body: every J = -1
    x = x.ravel()
    e_f, e_np = pot.energy(x), numpy_path(monkeypatch, lambda: pot.energy(x))
    assert np.isfinite(e_f) and abs(e_f - e_np) <= RTOL * abs(e_np)
    g_f, g_np = pot.gradient(x), numpy_path(monkeypatch, lambda: pot.gradient(x))
    assert np.linalg.norm(g_f - g_np) <= RTOL * np.linalg.norm(g_np)


@needs_numba
def test_nonfinite_positions_give_infinite_energy():
    pot = ElasticPotential(fe.LinearElastic(E, NU), space())
    x = space().X.copy()
    x[5] = np.nan
    assert pot.energy(x) == np.inf


@needs_numba
def test_wrong_shape_is_rejected():
    kernels = fused.kernels_for(fe.StVK(E, NU), space())
    with pytest.raises(ValueError, match="shape"):
        kernels.gradient(space().X[:-1])


# derivatives -----------------------------------------------------------------------------
@needs_numba
@pytest.mark.parametrize("material_cls", REGISTERED, ids=ids)
def test_fused_gradient_is_the_derivative_of_fused_energy(material_cls):
    pot = ElasticPotential(material_cls(E, NU), space())
    x = random_states(1)[0]
    rng = np.random.default_rng(5)
    d = rng.standard_normal(x.size)
    d /= np.linalg.norm(d)
    h = 1e-6
    fd = (pot.energy(x + h * d) - pot.energy(x - h * d)) / (2 * h)
    exact = pot.gradient(x) @ d
    assert fd == pytest.approx(exact, rel=1e-6)
    # and per DOF, on a few of them
    g = pot.gradient(x)
    for k in rng.choice(x.size, 5, replace=False):
        e = np.zeros(x.size)
        e[k] = h
        assert (pot.energy(x + e) - pot.energy(x - e)) / (2 * h) == pytest.approx(
            g[k], rel=1e-5, abs=1e-6 * np.abs(g).max())


@needs_numba
def test_model_uses_the_fused_path(monkeypatch):
    model = fe.Model(fe.beam_mesh(0.3, 0.1, 0.1, cells=(3, 2, 2)), density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E, NU), order=1), fixed="left")
    assert model.body_potential._fused() is not None
    x = model.X * 1.01
    g = model.gradient(x)
    g_np = numpy_path(monkeypatch, lambda: model.gradient(x))
    assert np.linalg.norm(g - g_np) <= RTOL * np.linalg.norm(g_np)


# stiffness warping: the polar rotation and K(x) v ------------------------------------------
def _rotations(rng, n):
    """n random proper rotations, (3, 3, n), from normalized quaternions."""
    q = rng.standard_normal((4, n))
    w, a, b, c = q / np.linalg.norm(q, axis=0)
    return np.array([
        [1 - 2 * (b * b + c * c), 2 * (a * b - c * w), 2 * (a * c + b * w)],
        [2 * (a * b + c * w), 1 - 2 * (a * a + c * c), 2 * (b * c - a * w)],
        [2 * (a * c - b * w), 2 * (b * c + a * w), 1 - 2 * (a * a + b * b)],
    ])


@needs_numba
@pytest.mark.parametrize("s_lo, s_hi, inverted", [
    (0.999, 1.001, False),  # small strain: two cubic steps
    (0.72, 1.22, False),    # |F^T F - I| < 0.5: more cubic steps
    (0.2, 5.0, False),      # large stretches: scaled Newton
    (1e-7, 1e-4, False),    # crushed to a point (det > 0): Newton copes with cond ~1e3
    (0.3, 2.0, True),       # inverted (det < 0): LAPACK's SVD, signed
], ids=["small", "moderate", "large", "crushed", "inverted"])
def test_polar_rotation_kernel_is_the_signed_svd_rotation(s_lo, s_hi, inverted):
    """F = U diag(s) V^T built with known rotations: the kernel returns U V^T, as the numpy
    polar_rotation does (for det F < 0 the sign goes on the smallest |s|, det R = +1)."""
    from fem_elastic.materials.svd import polar_rotation

    rng = np.random.default_rng(3)
    n = 2000
    U, V = _rotations(rng, n), _rotations(rng, n)
    s = np.sort(rng.uniform(s_lo, s_hi, (3, n)), axis=0)[::-1]
    s[1] = np.maximum(s[1], 2.0 * s[2])  # keep s_2 + s_3 and s_2 - |s_3| away from 0
    if inverted:
        s[2] *= -1.0
    F = np.einsum("iak,ak,jak->ijk", U, s, V)
    R_exact = np.einsum("iak,jak->ijk", U, V)
    R = np.empty((9, n))
    fused._kernels().polar_points(np.ascontiguousarray(F.reshape(9, n)), R)
    R = R.reshape(3, 3, n)
    # R's condition number is ~s_1 / (s_2 +- s_3) <= ~1e3 here
    assert np.abs(R - R_exact).max() < 1e-12
    assert np.abs(R - polar_rotation(F)).max() < 1e-12


@needs_numba
def test_polar_rotation_kernel_special_matrices():
    k = fused._kernels()
    F = np.array([np.eye(3).ravel(), np.zeros(9), np.diag([1.0, 1.0, -1.0]).ravel(),
                  np.full(9, np.nan)]).T.copy()
    R = np.empty_like(F)
    k.polar_points(F, R)
    np.testing.assert_array_equal(R[:, 0], np.eye(3).ravel())  # exact at rest
    for j in (1, 2):  # F = 0 and a mirror: some proper rotation, as the numpy path
        Rj = R[:, j].reshape(3, 3)
        assert np.allclose(Rj @ Rj.T, np.eye(3), atol=1e-14) and np.linalg.det(Rj) > 0
    assert np.isnan(R[:, 3]).all()  # non-finite F: NaN, no exception


def _warped(sp):
    from fem_elastic.physics.stiffness_warping import WarpedStiffness

    return WarpedStiffness(sp, fe.Corotated(E, NU))


def _apply_both(monkeypatch, w, x, v):
    fused_result = w.apply(x, v)
    return fused_result, numpy_path(monkeypatch, lambda: w.apply(x, v))


def _rel(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


@needs_numba
@pytest.mark.parametrize("noise", [1e-4, 1e-3, 5e-3], ids=["small", "moderate", "large"])
def test_warped_apply_matches_the_numpy_path(noise, monkeypatch):
    """A large rotation of random deformations: nodal noise of 1e-4 to 5e-3 m on cells of
    ~0.04 m, strains from ~1e-2 (cubic iteration) to ~0.5 (most elements on Newton's path,
    J down to 0.46)."""
    s = space()
    w = _warped(s)
    rng = np.random.default_rng(17)
    Q = _rotations(rng, 1)[..., 0]
    x = ((s.X + noise * rng.standard_normal(s.ndofs)).reshape(-1, 3) @ Q.T + [1.0, -2.0, 0.5])
    x = x.ravel()
    assert det3(s.deformation_gradient(x - s.X)).min() > 0
    v = rng.standard_normal(s.ndofs)
    Kv, Kv_np = _apply_both(monkeypatch, w, x, v)
    assert _rel(Kv, Kv_np) < RTOL


@needs_numba
def test_warped_apply_with_inverted_and_degenerate_elements(monkeypatch):
    s = space()
    w = _warped(s)
    rng = np.random.default_rng(5)
    x = s.X + 2e-3 * rng.standard_normal(s.ndofs)
    p = x.reshape(-1, 3)
    t = s.mesh.t
    # element 0: vertex 0 pushed through the opposite face (inverted)
    a, opp = t[0, 0], t[1:, 0]
    p[a] = p[a] + 1.6 * (p[opp].mean(axis=0) - p[a])
    # an element sharing no vertex with element 0: vertex 0 moved to 1e-8 of its
    # height above the opposite face (nearly degenerate, det F ~ 1e-8)
    e = next(e for e in range(t.shape[1]) if not set(t[:, e]) & set(t[:, 0]))
    b, opp = t[0, e], t[1:, e]
    c = p[opp].mean(axis=0)
    p[b] = c + 1e-8 * (p[b] - c)
    J = det3(s.deformation_gradient(x - s.X))[:, 0]
    assert J[0] < 0 and 0 < J[e] < 1e-7
    v = rng.standard_normal(s.ndofs)
    Kv, Kv_np = _apply_both(monkeypatch, w, x, v)
    assert np.isfinite(Kv).all()
    assert _rel(Kv, Kv_np) < RTOL


@needs_numba
def test_warped_apply_takes_the_fused_path_for_p1_only(monkeypatch):
    calls = []
    original = fused.warped_apply
    monkeypatch.setattr(fused, "warped_apply", lambda *a: calls.append(1) or original(*a))
    for order, expected in ((1, 1), (2, 0)):
        calls.clear()
        w = _warped(space(order))
        w.apply(w.space.X, np.ones(w.space.ndofs))
        assert len(calls) == expected
    calls.clear()
    w = _warped(space())
    numpy_path(monkeypatch, lambda: w.apply(w.space.X, np.ones(w.space.ndofs)))
    assert not calls
