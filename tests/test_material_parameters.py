"""Every material from exactly one pair of elastic constants: (E, nu), (mu, lam) or (mu, K)."""

import dataclasses
import math
import pickle

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.dynamics.checkpoint import _describe
from fem_elastic.materials import elastic_constants

CLASSES = [fe.LinearElastic, fe.StVK, fe.NeoHookean, fe.StableNeoHookean, fe.Corotated]
E, NU = 1.0e6, 0.4
MU, LAM = E / (2 * (1 + NU)), E * NU / ((1 + NU) * (1 - 2 * NU))
K = LAM + 2 * MU / 3


def sample_F():
    rng = np.random.default_rng(0)
    F = np.eye(3)[:, :, None] + 0.2 * rng.standard_normal((3, 3, 20))
    return F[..., np.linalg.det(np.moveaxis(F, -1, 0)) > 0.3]


@pytest.mark.parametrize("cls", CLASSES)
def test_the_three_pairs_give_the_same_material(cls):
    a, b, c = cls(E=E, nu=NU), cls(mu=MU, lam=LAM), cls(mu=MU, K=K)
    F = sample_F()
    # each conversion is a few flops without cancellation at nu = 0.4 (measured: <= 2.3e-16);
    # 1e-14 and 1e-13 are margins over round-off, a wrong formula is an O(1) error.
    for m in (b, c):
        assert m.mu == pytest.approx(a.mu, rel=1e-14) and m.lam == pytest.approx(a.lam, rel=1e-13)
        assert m.E == pytest.approx(E, rel=1e-14) and m.nu == pytest.approx(NU, rel=1e-14)
        assert m.K == pytest.approx(a.K, rel=1e-14)
        for method in ("psi", "dpsi_dF", "d2psi_dF2", "d2psi_dF2_psd"):
            x, y = getattr(m, method)(F), getattr(a, method)(F)
            np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-12 * E)


@pytest.mark.parametrize("cls", CLASSES)
def test_given_values_are_kept_exactly_and_shown_in_the_repr(cls):
    m = cls(mu=3.0e5, lam=1.1e6)
    assert (m.mu, m.lam) == (3.0e5, 1.1e6)
    assert repr(m) == f"{cls.__name__}(mu=300000.0, lam=1100000.0)"
    k = cls(mu=3.0e5, K=2.0e9)
    assert (k.mu, k.K) == (3.0e5, 2.0e9) and k.lam == 2.0e9 - 2.0e5
    assert repr(k) == f"{cls.__name__}(mu=300000.0, K=2000000000.0)"
    assert 0.4999 < k.nu < 0.5


@pytest.mark.parametrize("cls", CLASSES)
def test_e_nu_materials_are_unchanged(cls):
    """The E/nu call, its repr, its Lame parameters (bit for bit) and its checkpoint description."""
    m = cls(E=E, nu=NU)
    assert repr(m) == f"{cls.__name__}(E=1000000.0, nu=0.4)"
    assert (m.mu, m.lam) == fe.lame_parameters(E, NU)
    assert cls(E, NU) == m and hash(cls(E, NU)) == hash(m)  # positional, as before
    assert _describe(m) == {"class": cls.__name__, "E": E.hex(), "nu": NU.hex()}
    assert [f.name for f in dataclasses.fields(m)] == ["E", "nu"]
    assert dataclasses.replace(m, nu=0.3) == cls(E=E, nu=0.3)
    with pytest.raises(AttributeError):
        m.E = 2.0


@pytest.mark.parametrize("cls", CLASSES)
@pytest.mark.parametrize("kwargs", [dict(E=E, nu=NU), dict(mu=MU, lam=LAM), dict(mu=MU, K=K)])
def test_pickle_keeps_the_pair(cls, kwargs):
    m = cls(**kwargs)
    back = pickle.loads(pickle.dumps(m))
    assert back == m and repr(back) == repr(m) and (back.mu, back.lam) == (m.mu, m.lam)


PAIRS = "exactly one pair of \\(E, nu\\), \\(mu, lam\\) or \\(mu, K\\)"


@pytest.mark.parametrize("cls", CLASSES)
@pytest.mark.parametrize("kwargs, match", [
    (dict(), "got no elastic constant: give " + PAIRS),
    (dict(mu=MU), "got mu: give " + PAIRS),
    (dict(lam=LAM), "got lam: give " + PAIRS),
    (dict(K=K), "got K: give " + PAIRS),
    (dict(E=E), "got E: give " + PAIRS),
    (dict(E=E, nu=NU, mu=MU, lam=LAM), "got E and nu and mu and lam: give " + PAIRS),
    (dict(E=E, lam=LAM), "got E and lam"),
    (dict(nu=NU, mu=MU), "got nu and mu"),
    (dict(mu=MU, lam=LAM, K=K), "got mu and lam and K"),
    (dict(mu=0.0, lam=LAM), "shear modulus mu must be > 0 Pa"),
    (dict(mu=-MU, K=K), "shear modulus mu must be > 0 Pa"),
    (dict(mu=MU, lam=-MU), "lam must be > -2/3 mu"),
    (dict(mu=MU, K=0.0), "bulk modulus K must be > 0 Pa"),
    (dict(mu=MU, K=-1.0), "bulk modulus K must be > 0 Pa"),
    (dict(mu=float("inf"), lam=LAM), "mu must be finite"),
    (dict(mu=MU, lam=float("nan")), "lam must be finite"),
    (dict(mu="3e5", lam=LAM), "mu must be a real number"),
    (dict(mu=MU, K=True), "K must be a real number"),
])
def test_anything_but_one_valid_pair_is_invalid(cls, kwargs, match):
    with pytest.raises(fe.InvalidParameter, match=match):
        cls(**kwargs)


def test_projective_corotated_takes_the_pairs_too():
    """Its own __init__ (the volume band) passes the pair on to Material's."""
    band = dict(sigma_min=0.9, sigma_max=1.1)
    a = fe.ProjectiveCorotated(E=E, nu=NU, **band)
    F = sample_F()
    for m in (fe.ProjectiveCorotated(mu=MU, lam=LAM, **band), fe.ProjectiveCorotated(mu=MU, K=K, **band)):
        assert (m.sigma_min, m.sigma_max) == (0.9, 1.1)
        for method in ("psi", "dpsi_dF", "d2psi_dF2_psd"):  # tolerances as in the test above
            np.testing.assert_allclose(getattr(m, method)(F), getattr(a, method)(F), rtol=1e-12,
                                       atol=1e-12 * E)
    m = fe.ProjectiveCorotated(mu=3.0e5, lam=1.1e6, sigma_min=0.9)
    assert (m.mu, m.lam) == (3.0e5, 1.1e6)
    assert repr(m) == "ProjectiveCorotated(mu=300000.0, lam=1100000.0, sigma_min=0.9, sigma_max=1.0)"
    with pytest.raises(fe.InvalidParameter, match="got E and lam: give " + PAIRS):
        fe.ProjectiveCorotated(E=E, lam=LAM)


def test_elastic_constants_round_trip():
    # round trips through a few flops, without severe cancellation at these nu (lam + mu >= mu/2,
    # 3K + mu >= mu): measured <= 2.3e-16, so 1e-12 everywhere is a margin over round-off.
    for E_, nu in [(1e6, 0.3), (2e11, -0.5), (5e3, 0.4999)]:
        c = elastic_constants(E_, nu)
        assert c.given == ("E", "nu") and (c.E, c.nu) == (E_, nu)
        for back in (elastic_constants(mu=c.mu, lam=c.lam), elastic_constants(mu=c.mu, K=c.K)):
            assert math.isclose(back.E, E_, rel_tol=1e-12) and math.isclose(back.nu, nu, rel_tol=1e-12)
            assert math.isclose(back.lam, c.lam, rel_tol=1e-12) and math.isclose(back.K, c.K, rel_tol=1e-12)
    # an auxetic solid: negative lam is allowed while K > 0
    aux = elastic_constants(mu=1.0, lam=-0.5)
    assert aux.nu < 0 and aux.K > 0


def test_a_model_built_from_mu_and_lam():
    mesh = fe.beam_mesh(cells=(4, 1, 1))
    results = []
    for material in (fe.NeoHookean(E=E, nu=NU), fe.NeoHookean(mu=MU, lam=LAM)):
        model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(material), fixed="left",
                         gravity=(0.0, 0.0, -9.81))
        results.append(fe.solve_static(model).displacement)
    # MU, LAM are lame_parameters(E, NU) to the last bit (test_e_nu_materials_are_unchanged): the
    # two models are the same, 1e-10 leaves room for the solver's round-off alone
    np.testing.assert_allclose(results[1], results[0], rtol=0, atol=1e-10 * np.abs(results[0]).max())
