"""Projective dynamics (fe.ProjectiveDynamics) and its energy (fe.ProjectiveCorotated).

The energy is a real material, checked by finite differences; projective dynamics
converges, as its iterations grow, to fe.ImplicitEuler on a body of that material
(a fitted linear rate, and < 1e-6 relative after enough iterations); its global matrix
is factorised once; a free body keeps its linear momentum; a damped cantilever settles
on fe.solve_static's answer; scene files and checkpoints reach it.
"""

from __future__ import annotations

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.app.scene import parse_scene
from fem_elastic.dynamics.checkpoint import run_fingerprint
from small_scene import small_scene

E, NU, RHO, DT = 1e5, 0.3, 1000.0, 0.01


def _cantilever(material=None, order=1, cells=(8, 2, 2), **terms):
    material = material or fe.ProjectiveCorotated(E=E, nu=NU)
    terms.setdefault("gravity", (0.0, 0.0, -9.81))
    return fe.Model(fe.beam_mesh(1.0, 0.1, 0.1, cells), density=RHO,
                    body=fe.ElasticBody(material, order=order), fixed="left", **terms)


def _moving_state(model, steps=3):
    """The cantilever a few implicit steps after its release: bending, moving."""
    s = fe.State.rest(model)
    for _ in range(steps):
        s = fe.ImplicitEuler().step(model, s, DT)
    return s


def _gap(model, state, iterations, reference):
    out = fe.ProjectiveDynamics(iterations=iterations).step(model, state, DT)
    return np.linalg.norm(out.x - reference.x) / np.linalg.norm(reference.x - state.x)


# ---------------------------------------------------------------------------------------
# the energy as a material


def _random_F(rng, n, spread=0.25):
    """Deformation gradients near rotations, stretched and sheared by up to ``spread``."""
    out = np.empty((3, 3, n))
    for k in range(n):
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        Q *= np.sign(np.linalg.det(Q))
        out[..., k] = Q @ (np.eye(3) + spread * rng.uniform(-1, 1, (3, 3)))
    return out


@pytest.mark.parametrize("band", [(1.0, 1.0), (0.9, 1.1)])
def test_energy_passes_finite_difference_checks_of_stress_and_tangent(band):
    m = fe.ProjectiveCorotated(E=2e6, nu=0.35, sigma_min=band[0], sigma_max=band[1])
    rng = np.random.default_rng(1)
    F = _random_F(rng, 40)
    # keep clear of the band's edges, where psi is C^1 only
    mean = np.linalg.svd(np.moveaxis(F, -1, 0), compute_uv=False).mean(axis=1)
    F = F[..., (np.abs(mean - band[0]) > 1e-3) & (np.abs(mean - band[1]) > 1e-3)]
    n = F.shape[-1]
    P, C = m.dpsi_dF(F), m.d2psi_dF2(F)
    h = 1e-6
    for i in range(3):
        for j in range(3):
            dF = np.zeros((3, 3, n))
            dF[i, j] = h
            dpsi = (m.psi(F + dF) - m.psi(F - dF)) / (2 * h)
            np.testing.assert_allclose(dpsi, P[i, j], rtol=1e-6, atol=1e-6 * np.abs(P).max())
            dP = (m.dpsi_dF(F + dF) - m.dpsi_dF(F - dF)) / (2 * h)
            np.testing.assert_allclose(dP, C[:, :, i, j], rtol=1e-5, atol=1e-6 * np.abs(C).max())
    Cp = m.d2psi_dF2_psd(F)
    w = np.linalg.eigvalsh(np.moveaxis(Cp.reshape(9, 9, n), -1, 0))
    assert w.min() >= -1e-10 * np.abs(w).max()
    # at rest it is linear elasticity with the Lame parameters of (E, nu)
    # (inside a band of some width, without the volume term)
    lam = m.lam if band == (1.0, 1.0) else 0.0
    C0 = m.d2psi_dF2(np.eye(3))
    assert C0[0, 0, 0, 0] == pytest.approx(2 * m.mu + lam) and C0[0, 0, 1, 1] == pytest.approx(lam, abs=1e-6)


def test_energy_with_the_default_band_is_the_corotated_energy():
    F = _random_F(np.random.default_rng(2), 30, spread=0.6)
    pd, co = fe.ProjectiveCorotated(E=1e6, nu=0.4), fe.Corotated(E=1e6, nu=0.4)
    np.testing.assert_allclose(pd.psi(F), co.psi(F), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(pd.dpsi_dF(F), co.dpsi_dF(F), rtol=1e-12, atol=1e-7)
    np.testing.assert_allclose(pd.d2psi_dF2(F), co.d2psi_dF2(F), rtol=1e-10, atol=1e-6)


def test_the_energy_is_the_sum_of_weighted_squared_distances_to_the_projections():
    m = fe.ProjectiveCorotated(E=1e6, nu=0.3, sigma_min=0.95, sigma_max=1.02)
    F = _random_F(np.random.default_rng(3), 20, spread=0.4)
    R, delta = m.projections(F)
    strain = ((F - R) ** 2).sum(axis=(0, 1))
    volume = ((delta * R) ** 2).sum(axis=(0, 1))  # ||F - P_v(F)||^2, P_v(F) = F - delta R
    np.testing.assert_allclose(m.psi(F), m.mu * strain + 1.5 * m.lam * volume, rtol=1e-12)


# ---------------------------------------------------------------------------------------
# convergence to implicit Euler on the same energy


@pytest.fixture(scope="module")
def converging():
    model = _cantilever()
    state = _moving_state(model)
    reference = fe.ImplicitEuler(rtol=1e-12, max_iter=100).step(model, state, DT)
    return model, state, reference


def test_a_step_converges_to_the_implicit_euler_step_of_the_same_energy(converging):
    model, state, reference = converging
    iterations = np.array([10, 20, 40, 80, 120, 160])
    gaps = np.array([_gap(model, state, k, reference) for k in iterations])
    assert np.all(np.diff(gaps) < 0), gaps
    # linear convergence: log(gap) falls on a line in the iteration count
    slope, intercept = np.polyfit(iterations, np.log(gaps), 1)
    fit = np.exp(intercept + slope * iterations)
    assert slope < -0.05 and np.all(np.abs(np.log(gaps / fit)) < 1.5), (slope, gaps)
    assert gaps[-1] < 1e-6
    assert _gap(model, state, 400, reference) < 1e-10  # and on to round-off


def test_a_corotated_body_is_the_same_problem(converging):
    model, state, _ = converging
    co = _cantilever(fe.Corotated(E=E, nu=NU))
    a = fe.ProjectiveDynamics(iterations=30).step(co, fe.State(state.x, state.v, state.t), DT)
    b = fe.ProjectiveDynamics(iterations=30).step(model, state, DT)
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-13)


@pytest.mark.parametrize("what", ["P2 tets", "consistent mass", "Rayleigh damping", "volume band"])
def test_convergence_holds_for_the_other_settings(what):
    material = fe.ProjectiveCorotated(E=E, nu=NU, sigma_min=0.99, sigma_max=1.01) \
        if what == "volume band" else None
    model = _cantilever(material, order=2 if what == "P2 tets" else 1, cells=(6, 1, 1),
                        damping=fe.Rayleigh(2.0, 2e-3) if what == "Rayleigh damping" else None)
    mass = "consistent" if what == "consistent mass" else "lumped"
    state = _moving_state(model)
    ref = fe.ImplicitEuler(rtol=1e-12, max_iter=100, mass=mass).step(model, state, DT)
    out = fe.ProjectiveDynamics(iterations=600, mass=mass).step(model, state, DT)
    assert np.linalg.norm(out.x - ref.x) / np.linalg.norm(ref.x - state.x) < 1e-6


def test_tol_stops_early_and_counts_iterations(converging):
    model, state, reference = converging
    pd = fe.ProjectiveDynamics(iterations=1000, tol=1e-9)
    out = pd.step(model, state, DT)
    n = pd.last_stats.newton_iterations
    assert 20 < n < 1000 and pd.last_stats.gradient_evaluations == n
    assert np.linalg.norm(out.x - reference.x) / np.linalg.norm(reference.x - state.x) < 1e-6


# ---------------------------------------------------------------------------------------
# the factorisation, momentum, statics


def test_the_global_matrix_is_factorised_once_per_model_and_dt():
    model = _cantilever(cells=(4, 1, 1))
    pd = fe.ProjectiveDynamics(iterations=5)
    run = fe.simulate(model, pd, DT, steps=10)
    assert pd.factorizations == 1 and run.steps == 10
    fe.simulate(model, pd, DT, steps=3, state=run.final_state)
    assert pd.factorizations == 1
    fe.simulate(model, pd, DT / 2, steps=3)
    assert pd.factorizations == 2  # a new dt
    fe.simulate(_cantilever(cells=(4, 1, 1)), pd, DT, steps=2)
    assert pd.factorizations == 3  # a new model
    # caches are not settings: a checkpoint's fingerprint and state leave them out
    assert pd.checkpoint_state(run.final_state) == {}
    fp = run_fingerprint(model, pd, DT, 10, 1, fe.State.rest(model), 1.0)
    assert set(fp["integrator_settings"]) == {"iterations", "tol", "mass"}


def test_a_free_body_keeps_its_linear_momentum():
    model = fe.Model(fe.beam_mesh(1.0, 0.2, 0.1, (6, 2, 1)), density=RHO,
                     body=fe.ElasticBody(fe.Corotated(E=E, nu=NU)))
    rng = np.random.default_rng(4)
    state = fe.State.rest(model, displacement=0.02 * rng.normal(size=(model.ndofs // 3, 3)),
                          velocity=lambda X: np.column_stack([1.0 + 0 * X[:, 0], 3 * X[:, 2], -2 * X[:, 1]]))
    p0 = model.linear_momentum(state.v)
    run = fe.simulate(model, fe.ProjectiveDynamics(iterations=3), DT, steps=30, state=state)
    drift = np.abs(run.linear_momentum - p0).max()
    assert drift < 1e-12 * np.abs(p0).max()


def test_a_damped_cantilever_settles_on_the_static_answer():
    """The static solution is a fixed point of every step (any iteration count): damped, the
    run approaches it (a sag of 23 % of the length: geometrically nonlinear)."""
    model = _cantilever(fe.ProjectiveCorotated(E=1e6, nu=NU), cells=(6, 1, 1),
                        damping=fe.Rayleigh(20.0, 0.0))
    static = fe.solve_static(model).displacement[:, 2].min()
    run = fe.simulate(model, fe.ProjectiveDynamics(iterations=10), 0.02, steps=200)
    error = np.abs(run.displacement[:, :, 2].min(axis=1) / static - 1.0)
    assert error[-1] < 1e-4 and error[-1] < error[100] < error[50]


# ---------------------------------------------------------------------------------------
# scene files, checkpoints, bad input


def test_a_scene_file_builds_and_runs_it():
    text = small_scene("pd", material="corotated", cells=(4, 1, 1), duration=0.05,
                       integrator="projective_dynamics", integrator_options='iterations = 7\nmass = "consistent"')
    run = parse_scene(text).build()[0]
    pd = run.integrator
    assert isinstance(pd, fe.ProjectiveDynamics) and (pd.iterations, pd.mass, pd.tol) == (7, "consistent", 0.0)
    traj = fe.simulate(run.model, pd, run.dt, steps=run.steps, state=run.state)
    assert np.all(traj.step_stats["newton_iterations"] == 7) and traj.displacement[-1, :, 2].min() < 0


def test_a_resumed_run_is_the_uninterrupted_one(tmp_path):
    model = _cantilever(cells=(4, 1, 1))
    full = fe.simulate(model, fe.ProjectiveDynamics(iterations=4), DT, steps=9)

    def stop(step, state):
        if step == 5:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        fe.simulate(model, fe.ProjectiveDynamics(iterations=4), DT, steps=9, checkpoint_dir=tmp_path,
                    callback=stop)
    resumed = fe.simulate(_cantilever(cells=(4, 1, 1)), fe.ProjectiveDynamics(iterations=4), DT, steps=9,
                          checkpoint_dir=tmp_path, resume=True)
    assert resumed.resumed_from_step == 5
    assert np.array_equal(resumed.displacement, full.displacement)
    assert np.array_equal(resumed.final_state.v, full.final_state.v)


@pytest.mark.parametrize("kwargs, words", [
    ({"iterations": 0}, "iterations must be an integer >= 1"),
    ({"iterations": 2.5}, "iterations must be an integer"),
    ({"tol": -1.0}, "tol must be a finite number >= 0"),
    ({"mass": "diagonal"}, "mass must be 'lumped' or 'consistent'"),
])
def test_bad_settings_are_refused(kwargs, words):
    with pytest.raises(fe.InvalidParameter, match=words):
        fe.ProjectiveDynamics(**kwargs)


def test_bodies_it_cannot_run_are_refused():
    auxetic = _cantilever(fe.Corotated(E=E, nu=-0.2))
    with pytest.raises(fe.InvalidParameter, match="nu >= 0"):
        fe.ProjectiveDynamics().step(auxetic, fe.State.rest(auxetic), DT)
    springs = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=RHO, body=fe.MassSpring(E=E))
    with pytest.raises(fe.InvalidParameter, match="finite element body"):
        fe.ProjectiveDynamics().step(springs, fe.State.rest(springs), DT)
    with pytest.raises(fe.InvalidParameter, match="sigma_min <= 1 <= sigma_max"):
        fe.ProjectiveCorotated(E=E, nu=NU, sigma_min=1.05)


def test_another_material_runs_the_projective_energy_of_its_constants():
    nh = _cantilever(fe.NeoHookean(E=E, nu=NU), cells=(4, 1, 1))
    co = _cantilever(fe.Corotated(E=E, nu=NU), cells=(4, 1, 1))
    a = fe.ProjectiveDynamics(iterations=8).step(nh, fe.State.rest(nh), DT)
    b = fe.ProjectiveDynamics(iterations=8).step(co, fe.State.rest(co), DT)
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-12)


def test_the_benchmark_script_prints_its_ratio():
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parent.parent / "scripts" / "bench_projective.py"
    r = subprocess.run([sys.executable, str(script), "--quick"], capture_output=True, text=True, timeout=600,
                       check=False)
    assert r.returncode == 0, r.stderr
    ratio = float(r.stdout.split("one Newton iteration = ")[1].split()[0])
    assert 0.0 < ratio < 1.0 and "the factorisation costs" in r.stdout
