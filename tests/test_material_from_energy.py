"""fe.material_from_energy: generated derivatives against finite differences and the hand-written
materials, the PSD projection, the energy's domain, use in a model, and bad energies."""

import copy
import pickle
import sys
import warnings

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.materials import isotropic
from fem_elastic.materials.isotropic import isotropic_hessian
from fem_elastic.materials.svd import signed_svd

pytest.importorskip("sympy")

MU, LAM = 3.4e5, 1.2e6  # Pa; a compressible rubber-like solid (nu ~ 0.39)
STIFF = 2.0 * MU + LAM  # the stress and tangent scale (Pa)
I3 = np.eye(3)
log, exp, sqrt = fe.math.log, fe.math.exp, fe.math.sqrt


def rotation(rng):
    Q, R = np.linalg.qr(rng.standard_normal((3, 3)))
    Q = Q * np.sign(np.diag(R))
    return Q * np.sign(np.linalg.det(Q))


def sample_F(seed=0, n=12):
    """(3, 3, n) deformation gradients with det F > 0.2: near I, far from I, compressed, stretched."""
    rng = np.random.default_rng(seed)
    Fs = [rotation(rng) @ np.diag([0.5, 0.6, 0.7]) @ rotation(rng),
          rotation(rng) @ np.diag([1.7, 1.1, 0.8]) @ rotation(rng),
          np.diag([0.4, 1.0, 1.0]), 1.1 * I3]
    while len(Fs) < n:
        F = I3 + 0.3 * rng.standard_normal((3, 3))
        if np.linalg.det(F) > 0.2:
            Fs.append(F)
    return np.stack(Fs, axis=-1)


def fd_gradient(f, F, h=1e-6):
    """Central differences of f (batch-valued) with respect to each F_kl: (3, 3) + f(F).shape."""
    out = None
    for k in range(3):
        for l in range(3):
            Fp, Fm = F.copy(), F.copy()
            Fp[k, l] += h
            Fm[k, l] -= h
            d = (f(Fp) - f(Fm)) / (2.0 * h)
            if out is None:
                out = np.empty((3, 3) + d.shape)
            out[k, l] = d
    return out


# -- the energies ----------------------------------------------------------------------------
def mooney_rivlin(I1, I2, J, c1, c2, lam):
    """Compressible Mooney-Rivlin: stress-free at rest through the -2 (c1 + 2 c2) ln J term."""
    return c1 * (I1 - 3) + c2 * (I2 - 3) - 2 * (c1 + 2 * c2) * log(J) + lam / 2 * log(J) ** 2


def demiray(I1, I2, J, mu, b, kappa):
    """Exponential (Demiray) isochoric energy with a log-free volumetric term."""
    return mu / (2 * b) * (exp(b * (J ** (-2 / 3) * I1 - 3)) - 1) + kappa / 2 * (J - 1) ** 2


def neo_hookean_of_F(F, mu, lam):
    J = fe.math.det(F)
    return mu / 2 * (fe.math.trace(F.T @ F) - 3) - mu * log(J) + lam / 2 * log(J) ** 2


def stvk_of_F(F, mu, lam):
    E = (F.T @ F - np.eye(3)) / 2
    return mu * fe.math.trace(E @ E) + lam / 2 * fe.math.trace(E) ** 2


def fibre_of_F(F, mu, lam, k):
    """Neo-Hookean with a stiff fibre along x: anisotropic, only expressible in F."""
    J = fe.math.det(F)
    stretch2 = F[0, 0] ** 2 + F[1, 0] ** 2 + F[2, 0] ** 2
    return (mu / 2 * (fe.math.trace(F.T @ F) - 3) - mu * log(J) + lam / 2 * log(J) ** 2
            + k / 4 * (stretch2 - 1) ** 2)


def ogden_like_of_F(F, mu, kappa):
    """Energy with a square root of I1 (and a log): exercises sqrt's derivative."""
    J = fe.math.det(F)
    return mu * (sqrt(fe.math.trace(F.T @ F) + 1) - 2) - mu / 2 * log(J) + kappa / 2 * (J - 1) ** 2


ENERGIES = {
    "neo_hookean": (fe.energies.neo_hookean, dict(mu=MU, lam=LAM)),
    "stable_neo_hookean": (fe.energies.stable_neo_hookean, dict(mu=MU, lam=LAM)),
    "cook_membrane": (fe.energies.cook_membrane, dict(mu=MU, kappa=LAM)),
    "mooney_rivlin": (mooney_rivlin, dict(c1=0.3 * MU, c2=0.2 * MU, lam=LAM)),
    "demiray": (demiray, dict(mu=MU, b=2.0, kappa=LAM)),
    "neo_hookean_of_F": (neo_hookean_of_F, dict(mu=MU, lam=LAM)),
    "stvk_of_F": (stvk_of_F, dict(mu=MU, lam=LAM)),
    "fibre_of_F": (fibre_of_F, dict(mu=MU, lam=LAM, k=5 * MU)),
    "ogden_like_of_F": (ogden_like_of_F, dict(mu=MU, kappa=LAM)),
}
INVARIANT_FORM = ["neo_hookean", "stable_neo_hookean", "cook_membrane", "mooney_rivlin", "demiray"]


def make(name):
    psi, params = ENERGIES[name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # ogden_like is not stress-free (checked below)
        return fe.material_from_energy(psi, **params)


# -- derivatives against finite differences ----------------------------------------------------
# F is O(1): h = 1e-6 has truncation ~ h^2 S / ell^3 and round-off ~ eps S / h, i.e. ~1e-10 S
# relative to the scale S of the differentiated quantity at the most compressed point (ell ~ 0.4);
# measured: <= 6e-10 STIFF for the stress. 1e-6 S is a >1e3 margin; a wrong term is an error of
# the size of the derivative itself.
@pytest.mark.parametrize("name", list(ENERGIES))
def test_stress_is_the_gradient_of_the_energy(name):
    m = make(name)
    F = sample_F(1)
    np.testing.assert_allclose(m.dpsi_dF(F), fd_gradient(m.psi, F), rtol=0, atol=1e-6 * STIFF)


@pytest.mark.parametrize("name", list(ENERGIES))
def test_tangent_is_the_gradient_of_the_stress(name):
    m = make(name)
    F = sample_F(2)
    C = m.d2psi_dF2(F)
    C_fd = np.moveaxis(fd_gradient(m.dpsi_dF, F), (0, 1), (2, 3))
    # the stress differentiated here is S ~ 10 STIFF (|C| reaches 20-30 STIFF at the most compressed
    # point): 1e-6 S as above. The exponential energy reaches ~1e5 STIFF at the most stretched
    # point: relative there
    np.testing.assert_allclose(C, C_fd, rtol=1e-8, atol=1e-6 * STIFF * 10)
    np.testing.assert_allclose(C, np.moveaxis(C, (0, 1), (2, 3)), rtol=1e-14, atol=1e-9 * STIFF)
    P, C2 = m.stress_and_tangent(F)
    np.testing.assert_allclose(P, m.dpsi_dF(F), rtol=1e-14, atol=1e-9 * STIFF)
    np.testing.assert_allclose(C2, C, rtol=1e-14, atol=1e-9 * STIFF)


@pytest.mark.parametrize("name", [n for n in ENERGIES if n != "ogden_like_of_F"])
def test_stress_free_and_linear_elastic_at_rest(name):
    m = make(name)
    I = I3[:, :, None]
    np.testing.assert_allclose(m.dpsi_dF(I), 0.0, atol=1e-9 * STIFF)
    lin = fe.LinearElastic(mu=m.mu, lam=m.lam)
    if name != "fibre_of_F":  # isotropic: the linearization is linear elasticity of (mu, lam)
        np.testing.assert_allclose(m.d2psi_dF2(I), lin.d2psi_dF2(I), rtol=0, atol=1e-9 * STIFF)


def test_linearized_moduli():
    assert make("neo_hookean").mu == pytest.approx(MU, rel=1e-14)
    assert make("neo_hookean").lam == pytest.approx(LAM, rel=1e-14)
    assert make("cook_membrane").K == pytest.approx(LAM, rel=1e-14)  # kappa
    snh = make("stable_neo_hookean")  # its lam is the Lame parameter only up to mu: lam - mu
    assert snh.mu == pytest.approx(MU, rel=1e-14) and snh.lam == pytest.approx(LAM - MU, rel=1e-14)
    assert float(snh.psi(I3)) == pytest.approx(MU ** 2 / (2 * LAM), rel=1e-12)
    m = make("neo_hookean")
    assert m.E == pytest.approx(MU * (3 * LAM + 2 * MU) / (LAM + MU)) and 0 < m.nu < 0.5


# -- equal to the hand-written materials -----------------------------------------------------------
def hand_stable_neo_hookean(I1, I2, J, mu, lam):
    """fe.StableNeoHookean's energy in full (Smith, de Goes and Kim 2018, with ln(I_C + 1))."""
    mu_, lam_ = 4 / 3 * mu, lam + 5 / 6 * mu
    alpha = 1 + 3 * mu_ / (4 * lam_)
    rest = lam_ / 2 * (1 - alpha) ** 2 - mu_ / 2 * np.log(4.0)
    return mu_ / 2 * (I1 - 3) + lam_ / 2 * (J - alpha) ** 2 - mu_ / 2 * log(I1 + 1) - rest


@pytest.mark.parametrize("psi, cls", [
    (fe.energies.neo_hookean, fe.NeoHookean),
    (neo_hookean_of_F, fe.NeoHookean),
    (hand_stable_neo_hookean, fe.StableNeoHookean),
    (stvk_of_F, fe.StVK),
])
def test_equal_to_the_hand_written_material(psi, cls):
    m, ref = fe.material_from_energy(psi, mu=MU, lam=LAM), cls(mu=MU, lam=LAM)
    rng = np.random.default_rng(4)
    F = np.concatenate([sample_F(3), I3[:, :, None] + 0.4 * rng.standard_normal((3, 3, 200))], axis=-1)
    if cls is fe.NeoHookean:
        F = F[..., np.linalg.det(np.moveaxis(F, -1, 0)) > 0.05]
    F = F.reshape(3, 3, -1, 2)  # a (nelems, nqp) batch
    for method in ("psi", "dpsi_dF", "d2psi_dF2", "d2psi_dF2_psd"):
        a, b = getattr(m, method)(F), getattr(ref, method)(F)
        assert a.shape == b.shape
        # round-off: ~1e-16 relative to the largest entry; 1e-12 of the local scale
        scale = np.abs(b).reshape(-1, *F.shape[2:]).max(axis=0) + STIFF
        assert np.all(np.abs(a - b) <= 1e-12 * scale), method


# -- the PSD projection --------------------------------------------------------------------------
def eig9(C):
    return np.linalg.eigvalsh(np.moveaxis(C.reshape(9, 9, -1), -1, 0))


@pytest.mark.parametrize("name", list(ENERGIES))
def test_projection_is_symmetric_psd_and_keeps_psd_tangents(name):
    m = make(name)
    F = sample_F(5, n=30)
    C, Cp = m.d2psi_dF2(F), m.d2psi_dF2_psd(F)
    np.testing.assert_allclose(Cp, np.moveaxis(Cp, (0, 1), (2, 3)), rtol=0, atol=1e-9 * STIFF)
    scale = np.abs(C).reshape(81, -1).max(axis=0)
    assert np.all(eig9(Cp).min(axis=1) >= -1e-11 * scale)
    w = eig9(C).min(axis=1)
    psd = w >= 1e-9 * scale
    assert psd.any() and (~psd).any()  # the batch has both
    np.testing.assert_allclose(Cp[..., psd], C[..., psd], rtol=0, atol=1e-9 * STIFF)
    # clamping removes only the negative part: C - Cp is negative semi-definite
    assert np.all(eig9(C - Cp).max(axis=1) <= 1e-9 * scale)


@pytest.mark.parametrize("name", INVARIANT_FORM)
def test_singular_value_eigensystem_reconstructs_the_tangent(name):
    """The closed-form eigensystem (twist/flip of psi_1, psi_2, psi_J) rebuilds d2psi_dF2,
    repeated singular values included: this checks the I2 and J terms of the formulas."""
    m = make(name)
    F = np.concatenate([sample_F(6), I3[:, :, None], 1.2 * I3[:, :, None],
                        np.diag([0.7, 0.7, 1.3])[:, :, None]], axis=-1)
    U, s, V = signed_svd(F)
    H, lt, lf = m.singular_value_hessian(s)
    C = isotropic_hessian(U, s, V, H, lt, lf, clamp=False)
    np.testing.assert_allclose(C, m.d2psi_dF2(F), rtol=0, atol=1e-8 * STIFF)


def test_energy_of_F_has_no_closed_form_eigensystem():
    with pytest.raises(fe.InvalidParameter, match="needs an energy of the invariants"):
        make("stvk_of_F").singular_value_hessian(np.ones((3, 1)))


# -- the energy's domain ---------------------------------------------------------------------
INVERTED = np.stack([np.diag([1.0, 1.0, -1.0]), np.zeros((3, 3)), np.diag([0.5, 0.5, -0.2]), I3], axis=-1)


@pytest.mark.parametrize("name", ["neo_hookean", "cook_membrane", "mooney_rivlin", "neo_hookean_of_F",
                                  "demiray"])
def test_log_or_fractional_power_energies_are_inf_at_inverted_points(name):
    m = make(name)
    with np.errstate(all="raise"):  # no floating-point warning leaks
        psi = m.psi(INVERTED)
        P = m.dpsi_dF(INVERTED)
        C = m.d2psi_dF2(INVERTED)
        Cp = m.d2psi_dF2_psd(INVERTED)
    assert list(psi[:3]) == [np.inf] * 3 and psi[3] == pytest.approx(0.0, abs=1e-9 * STIFF)
    for A in (P, C, Cp):
        assert np.isnan(A[..., :3]).all() and np.isfinite(A[..., 3]).all()


def test_log_free_energy_is_finite_through_inversion():
    m = make("stable_neo_hookean")
    with np.errstate(all="raise"):
        for f in (m.psi, m.dpsi_dF, m.d2psi_dF2, m.d2psi_dF2_psd):
            assert np.isfinite(f(INVERTED)).all()
    np.testing.assert_allclose(m.dpsi_dF(INVERTED), fd_gradient(m.psi, INVERTED), atol=1e-6 * STIFF)


def test_energy_beyond_the_float_range_is_inf_not_nan():
    m = make("neo_hookean")
    psi = m.psi(np.stack([1e110 * I3, 1e160 * I3], axis=-1))
    assert np.all(psi == np.inf)


# -- in a model ---------------------------------------------------------------------------------
def beam_model(material, order=1):
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(6, 1, 1))
    return fe.Model(mesh, density=1000.0, body=fe.ElasticBody(material, order=order), fixed="left",
                    traction={"right": (0.0, 0.0, -2e3)})


@pytest.mark.parametrize("name, order", [("neo_hookean", 1), ("neo_hookean", 2), ("neo_hookean_of_F", 1)])
def test_solve_static_matches_the_hand_written_neo_hookean(name, order):
    generated = fe.solve_static(beam_model(make(name), order))
    hand = fe.solve_static(beam_model(fe.NeoHookean(mu=MU, lam=LAM), order))
    assert generated.converged and hand.converged
    tip = np.abs(hand.displacement).max()
    assert tip > 1e-3  # a real deflection
    np.testing.assert_allclose(generated.displacement, hand.displacement, rtol=0, atol=1e-8 * tip)


def test_generated_material_takes_the_numpy_path_and_runs_an_integrator():
    from fem_elastic.discretization import Discretization, fused

    m = make("neo_hookean")
    space = Discretization(fe.beam_mesh(cells=(2, 1, 1)), order=1)
    assert fused.kernels_for(m, space) is None  # not registered: numpy path
    model = beam_model(m)
    for integrator in (fe.ImplicitEuler(), fe.Newmark()):
        run = fe.simulate(model, integrator, dt=1e-3, steps=2)
        assert run.steps == 2 and np.isfinite(run.displacement).all() and np.abs(run.displacement).max() > 0


def test_pickle_copy_equality_and_checkpoint_description():
    from fem_elastic.dynamics.checkpoint import _describe

    m = fe.material_from_energy(fe.energies.cook_membrane, mu=MU, kappa=LAM)
    back = pickle.loads(pickle.dumps(m))
    assert back == m and hash(back) == hash(m) and repr(back) == repr(m)
    assert copy.deepcopy(m) == m
    assert m != fe.material_from_energy(fe.energies.cook_membrane, mu=MU, kappa=2 * LAM)
    assert m != fe.material_from_energy(fe.energies.neo_hookean, mu=MU, lam=LAM - 2 * MU / 3)
    d = _describe(m)
    assert d["class"] == "EnergyMaterial" and d["form"] == "invariants"
    assert d["energy"]["function"] == "fem_elastic.materials.energies.cook_membrane"
    assert d["params"] == {"kappa": float(LAM).hex(), "mu": float(MU).hex()}


def test_the_derivation_is_cached_per_energy():
    a = fe.material_from_energy(fe.energies.neo_hookean, mu=1.0, lam=1.0)
    b = fe.material_from_energy(fe.energies.neo_hookean, mu=2.0, lam=3.0)
    assert a._code is b._code
    assert float(b.d2psi_dF2(I3)[0, 1, 1, 0]) == pytest.approx(2.0)


# -- fe.math -------------------------------------------------------------------------------------------
def test_fe_math_works_on_numbers_and_arrays_and_does_not_shadow_the_stdlib():
    x = np.array([1.0, 4.0])
    np.testing.assert_allclose(fe.math.sqrt(x), [1.0, 2.0])
    assert fe.energies.neo_hookean(3.0, 3.0, 1.0, 1.0, 1.0) == 0.0
    F = np.stack([np.diag([1.0, 2.0, 3.0])] * 2, axis=-1)
    np.testing.assert_allclose(fe.math.det(F), [6.0, 6.0])
    np.testing.assert_allclose(fe.math.trace(F), [6.0, 6.0])
    assert "math" not in fe.__all__
    namespace = {}
    exec("import math\nfrom fem_elastic import *", namespace)
    assert namespace["math"] is sys.modules["math"]


# -- bad energies -------------------------------------------------------------------------------------
IP = fe.InvalidParameter


@pytest.mark.parametrize("psi, params, match", [
    (lambda C, mu: mu * C, dict(mu=1.0), "must be psi\\(F, <params>\\)"),
    (lambda I1, J, mu: mu * I1, dict(mu=1.0), "first arguments are named \\('I1', 'J', 'mu'\\)"),
    (lambda I1, I2, J, *args: I1, {}, "takes \\*args or \\*\\*kwargs"),
    (lambda I1, I2, J, mu, lam: mu * (I1 - 3), dict(mu=1.0), "needs a value for lam: pass lam=..."),
    (lambda I1, I2, J, mu: mu * (I1 - 3), dict(mu=1.0, kappa=2.0),
     "has no parameter kappa: its parameters are \\['mu'\\]"),
    (lambda I1, I2, J, mu: mu * (I1 - 3), dict(mu="soft"), "mu must be a real number"),
    (lambda I1, I2, J, mu: mu * (I1 - 3), dict(mu=float("nan")), "mu must be finite"),
    (lambda I1, I2, J, mu, lam: mu * np.log(J), dict(mu=1.0, lam=1.0), "write psi with fe.math"),
    (lambda F, mu: mu * __import__("math").log(F[0, 0]), dict(mu=1.0), "not math.\\* or numpy.\\*"),
    (lambda F, mu: mu * (F.T @ F), dict(mu=1.0), "must return one scalar energy density"),
    (lambda I1, I2, J, mu: (mu * I1, J), dict(mu=1.0), "must return one scalar energy density"),
    (lambda I1, I2, J, mu: None, dict(mu=1.0), "did it forget a return"),
    (lambda I1, I2, J, mu, lam: mu / 2 * (I1 - 3) - mu * log(J - 1), dict(mu=1.0, lam=1.0),
     "not defined at rest"),
    (fe.energies.neo_hookean, dict(mu=-1e6, lam=2e6), "not a stable solid at rest"),
    (fe.energies.neo_hookean, dict(mu=1e6, lam=-1e6), "bulk modulus K = -333333 Pa"),
    ("neo_hookean", dict(mu=1.0, lam=1.0), "needs the energy as a function"),
])
def test_bad_energies_are_typed_errors_naming_the_fix(psi, params, match):
    with pytest.raises(IP, match=match):
        fe.material_from_energy(psi, **params)


def test_an_energy_that_is_not_stress_free_warns():
    with pytest.warns(UserWarning, match="not stress-free at rest.*- mu log\\(J\\)"):
        fe.material_from_energy(lambda I1, I2, J, mu, lam: mu / 2 * (I1 - 3) + lam / 2 * (J - 1) ** 2,
                                mu=1.0, lam=1.0)


def test_sympy_missing_is_a_typed_error_naming_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "sympy", None)  # import sympy now raises ModuleNotFoundError
    with pytest.raises(fe.MissingDependency, match='pip install "fem_elastic\\[energy\\]"') as err:
        fe.material_from_energy(lambda I1, I2, J, mu: mu / 2 * (I1 - 3 - 2 * log(J)), mu=1.0)
    assert isinstance(err.value, ImportError) and isinstance(err.value, fe.FemElasticError)


def test_an_energy_with_default_parameters():
    m = fe.material_from_energy(
        lambda I1, I2, J, mu, lam=4.0: fe.energies.neo_hookean(I1, I2, J, mu, lam), mu=1.0)
    assert m.params == {"mu": 1.0, "lam": 4.0} and m.lam == pytest.approx(4.0)


def test_generated_source_is_readable():
    m = make("neo_hookean")
    src = m.source["d2psi"]
    assert src.startswith("def d2psi(I1, I2, J, _p0, _p1):") and "numpy.log" in src


def test_project_psd_9x9_clamps_only_negative_eigenvalues():
    rng = np.random.default_rng(8)
    A = rng.standard_normal((9, 9, 5))
    A = A + A.transpose(1, 0, 2)
    out = isotropic.project_psd_9x9(A.reshape(3, 3, 3, 3, 5))
    for k in range(5):
        w, Q = np.linalg.eigh(A[..., k])
        ref = (Q * np.maximum(w, 0)) @ Q.T
        # entries O(1-10): two eigen-decompositions agree to ~1e-15 |A|; a kept negative
        # eigenvalue (or a clamped positive one) is an O(1) error
        np.testing.assert_allclose(out.reshape(9, 9, 5)[..., k], ref, atol=1e-12)


def test_benchmark_script_quick_prints_its_ratios():
    import subprocess
    from pathlib import Path

    script = Path(__file__).resolve().parent.parent / "scripts" / "bench_material_from_energy.py"
    r = subprocess.run([sys.executable, str(script), "--quick", "--repeats", "1"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert "generated / hand-written (medians, invariant form): psi" in r.stdout
    assert "goal <= 2x:" in r.stdout
    assert float(r.stdout.split("max rel. difference to fe.NeoHookean:")[1].split()[0]) < 1e-12


def test_import_fem_elastic_does_not_import_sympy():
    import subprocess

    code = "import sys, fem_elastic as fe; fe.math.log(2.0); print('sympy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
