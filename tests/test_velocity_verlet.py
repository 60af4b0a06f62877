"""Velocity Verlet (fe.VelocityVerlet): order, bounded energy, its critical step and step map,
one force evaluation per step, sub-stepping, a resumed run bit for bit, the scene files and
the command."""

import math
import subprocess
import sys
import warnings

import numpy as np
import pytest
import scipy.linalg as sl
from test_checkpoint import _beam, _kicked, _StopAt, assert_same_run

import fem_elastic as fe
from fem_elastic.app.scene_schema import (
    Boolean,
    Integer,
    Number,
    integrator_options,
    make_integrator,
)
from fem_elastic.app.vtu import read_series
from one_mode import in_mode as _in_mode
from one_mode import modal as _modal
from one_mode import one_mode as _one_mode

VV = fe.VelocityVerlet


def _sagging(cells=(4, 1, 1)):
    return fe.Model(fe.beam_mesh(cells=cells), density=1000.0,
                    body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left", gravity=(0, 0, -9.81))


# -- order of accuracy ---------------------------------------------------------------------------
@pytest.mark.parametrize("alpha", [0.0, 2.0])
def test_second_order_on_one_mode_against_the_closed_form(alpha):
    """With damping too: the second kick takes the damping force at v~ = v0 + h a0 = v1 + O(h^2)."""
    model, w, phi = _one_mode(alpha)
    T = 2 * math.pi / w  # one period of the first mode (0.66 s); zeta = 0.105 with alpha = 2
    zeta = alpha / (2 * w)
    q0 = 0.01 / np.abs(phi).max()  # 1 cm at the tip
    exact = sl.expm(np.array([[0, 1], [-w * w, -2 * zeta * w]]) * T / 4) @ [q0, 0.0]
    dts = [T / 400, T / 800, T / 1600]  # 0.78, 0.39, 0.20 times the critical step
    assert dts[0] < fe.critical_time_step(model, VV())
    errors = []
    for dt in dts:  # a quarter period
        vv, s = VV(), _in_mode(model, phi, q0, 0.0)
        for _ in range(round(T / 4 / dt)):
            s = vv.step(model, s, dt)
        q, v = _modal(model, phi, s)
        errors.append(math.hypot(q - exact[0], (v - exact[1]) / w) / q0)
    slope = np.polyfit(np.log(dts), np.log(errors), 1)[0]
    # measured 2.000 (undamped) and 2.001 (damped); the next term is O(h^4), far below at these
    # steps (errors 4e-5 .. 2e-6 of the amplitude)
    assert abs(slope - 2.0) < 0.05, (errors, slope)


def test_second_order_against_a_fine_run_on_a_sagging_beam():
    """Neo-Hookean, large sag from rest under gravity: every mode excited, the top ones at
    h omega up to 1.4, still second order on the whole state."""
    model = _sagging()
    T, n_ref = 0.1, 800
    ref = fe.simulate(model, VV(), T / n_ref, steps=n_ref, record_every=n_ref).final_state
    ns = (25, 50, 100)  # dt = 0.70, 0.35, 0.17 times the critical step
    errors = []
    for n in ns:
        s = fe.simulate(model, VV(), T / n, steps=n, record_every=n).final_state
        errors.append(np.linalg.norm(s.x - ref.x) / np.linalg.norm(ref.x - model.X))
    slope = -np.polyfit(np.log(ns), np.log(errors), 1)[0]
    # measured 2.017 (errors 1.3e-4 .. 7.7e-6): the reference's own error, (n / 800)^2 of each,
    # tilts the fit by +0.01 (2.009 against n = 1600)
    assert abs(slope - 2.0) < 0.1, (errors, slope)


# -- energy --------------------------------------------------------------------------------------
def test_energy_bounded_over_ten_thousand_steps_below_the_critical_step():
    """A kicked Neo-Hookean cantilever (48 DOFs, no gravity) at 0.8 of the critical step:
    10^4 steps (46 s, 61 periods of the first mode), no drift."""
    model = fe.Model(fe.beam_mesh(length=0.5, width=0.1, height=0.1, cells=(3, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left")
    rng = np.random.default_rng(0)
    s = fe.State.rest(model, velocity=lambda X: np.column_stack([0 * X[:, 0], 0.5 * X[:, 0], -X[:, 0]])
                      + 0.05 * rng.standard_normal(X.shape))
    dt = 0.8 * fe.critical_time_step(model, VV())
    e0 = model.kinetic_energy(s.v)  # from the rest shape: Pi = 0
    vv, energies = VV(), []
    for k in range(10_000):
        s = vv.step(model, s, dt)
        if k % 10 == 9:
            energies.append(model.kinetic_energy(s.v) + model.energy(s.x))
    e = np.array(energies)
    # measured: swings of 1.2 % of E (the O(h^2) oscillation of KE + Pi around the conserved
    # modified energy, up to 1 / (1 - r^2) of a mode's energy, r = h omega / 2), and a mean that
    # moves by 2e-4 of E between the first and the last 1000 steps
    assert np.abs(e - e0).max() < 0.03 * e0
    assert abs(e[-100:].mean() - e[:100].mean()) < 2e-3 * e0
    assert np.isfinite(s.x).all()


def test_the_modified_energy_is_conserved_on_a_linear_body():
    """KE + Pi - h^2/8 g . M^-1 g (g = dPi/dx on the free DOFs) is exact for a linear body."""
    model = _one_mode()[0]
    rng = np.random.default_rng(1)
    s = fe.State.rest(model, velocity=lambda X: 0.01 * rng.standard_normal(X.shape))  # every mode
    h = 0.95 * fe.critical_time_step(model, VV())
    free, m = model.free, model.lumped_mass[model.free]

    def modified(s):
        g = model.gradient(s.x)[free]
        return model.kinetic_energy(s.v) + model.energy(s.x) - h * h / 8 * g @ (g / m)

    vv, h0 = VV(), modified(s)
    totals = []
    for _ in range(500):
        s = vv.step(model, s, h)
        totals.append(model.kinetic_energy(s.v) + model.energy(s.x))
        # round-off of energies of 1 mm motions of nodes at up to 1 m: measured 7e-12 of it
        assert abs(modified(s) - h0) < 1e-10 * h0
    assert max(totals) / min(totals) > 1.05  # while KE + Pi itself swings (measured 1.28)


# -- the critical time step and the step map -----------------------------------------------------
def test_critical_time_step_is_two_over_omega_max_and_above_it_warns_and_diverges():
    model = _sagging()
    dt_crit = fe.critical_time_step(model, VV())
    assert dt_crit == pytest.approx(2.0 / fe.max_frequency(model), rel=1e-9)  # Lanczos tolerance
    with pytest.warns(fe.StabilityWarning, match="critical time step"), pytest.raises(fe.Diverged):
        fe.simulate(model, VV(), 1.2 * dt_crit, steps=300)
    with pytest.raises(fe.InvalidParameter, match="safety"):
        VV(safety=-0.5)


@pytest.mark.parametrize("alpha, factor", [(0.0, 0.9), (400.0, 0.9), (400.0, 0.5)])
def test_step_matrix_is_the_observed_amplification_of_the_top_mode(alpha, factor):
    """Steps of the top mode near the limit, undamped and damped (zeta = 0.2), against the map."""
    model, w, phi = _one_mode(alpha, mode=-1)
    h = factor * 2.0 / w
    q0, v0 = 1e-4, -0.05
    vv = VV()
    s1 = vv.step(model, _in_mode(model, phi, q0, v0), h)
    expected = vv.step_matrix(h, w, alpha / (2 * w)) @ [q0, v0]
    # displacements of 0.1 mm on positions of up to 1 m: measured 5e-12 relative
    np.testing.assert_allclose(_modal(model, phi, s1), expected, rtol=1e-10, atol=0)
    # and over 20 steps: the amplitude follows the map (spectral radius 1 undamped; at zeta = 0.2
    # 0.75 at half the undamped limit, and 1.17 at 0.9 of it: damping lowers the limit, and the
    # mode grows as the map says)
    s = _in_mode(model, phi, q0, v0)
    for _ in range(20):
        s = vv.step(model, s, h)
    P = np.linalg.matrix_power(vv.step_matrix(h, w, alpha / (2 * w)), 20) @ [q0, v0]
    np.testing.assert_allclose(_modal(model, phi, s), P, rtol=0, atol=1e-10 * abs(v0))


def test_with_damping_the_critical_step_comes_from_the_step_map():
    """Stiffness-proportional damping, 30 % of critical at the top mode, lowers the limit below
    2 / omega_max; the step found is where the map's spectral radius passes 1."""
    undamped = _beam(fe.LinearElastic, E=2e4)
    w_max = fe.max_frequency(undamped)
    zeta = 0.3
    model = _beam(fe.LinearElastic, E=2e4, damping=fe.Rayleigh(beta=2 * zeta / w_max))
    dt_crit = fe.critical_time_step(model, VV())
    assert dt_crit < 0.99 * 2.0 / w_max
    rho = [max(abs(np.linalg.eigvals(VV().step_matrix(f * dt_crit, w_max, zeta)))) for f in (0.999, 1.01)]
    assert rho[0] <= 1.0 + 1e-9 < rho[1]
    # a viscous mode alone (v' = -c v) is stable for h c <= 2: v1 = (1 - hc + (hc)^2 / 2) v0
    c = 1.0
    assert VV().step_matrix(1.5, 1e-8, c / 2e-8)[1, 1] == pytest.approx(1 - 1.5 + 1.5**2 / 2, rel=1e-6)


# -- one force evaluation per step, and what it remembers -----------------------------------------
def test_one_force_evaluation_per_step_and_the_same_bits_from_a_rebuilt_state():
    model = _sagging()
    dt = 0.5 * fe.critical_time_step(model, VV())
    vv, s = VV(), fe.State.rest(model)
    counts = []
    for _ in range(5):
        prev = s
        s = vv.step(model, s, dt)
        counts.append(vv.last_stats.gradient_evaluations)
        # a fresh integrator from a copy of the state evaluates the force itself: the same bits
        again = VV().step(model, fe.State(prev.x.copy(), prev.v.copy(), prev.t), dt)
        assert np.array_equal(again.x, s.x) and np.array_equal(again.v, s.v)
    assert counts == [2, 1, 1, 1, 1]
    saved = vv.checkpoint_state(s)
    assert sorted(saved) == ["gradient"] and np.array_equal(saved["gradient"], model.gradient(s.x))
    other = VV()
    other.restore_state(s, {k: np.array(a) for k, a in saved.items()})
    a, b = vv.step(model, s, dt), other.step(model, s, dt)
    assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)
    assert other.last_stats.gradient_evaluations == 1
    with pytest.raises(fe.InvalidParameter, match="another integrator"):
        VV().restore_state(s, {"acceleration": np.zeros(model.ndofs)})
    with pytest.raises(fe.InvalidParameter, match="damaged"):
        VV().restore_state(s, {"gradient": np.zeros(5)})
    # moved to another model, it forgets the first one's force
    heavier = fe.Model(model.mesh, density=2000.0, body=model.body, fixed="left", gravity=(0, 0, -9.81))
    vv.step(heavier, a, dt)
    assert vv.last_stats.gradient_evaluations == 2


def test_impulse_contacts_and_penalty_contacts_like_the_other_explicit_schemes():
    """An impulse response moves the end positions: the force is then evaluated afresh (the same
    bits as a fresh integrator); a penalty ground is part of the force."""
    for method in ("impulse", "penalty"):
        model = _beam(E=2e4, gravity=(0, 0, -9.81), ground=fe.Ground(z=-0.001, method=method),
                      damping=fe.Rayleigh(1.0, 1e-4))
        dt = 0.5 * fe.critical_time_step(model, VV())
        vv, s = VV(), fe.State.rest(model)
        twice = []
        for k in range(60):
            prev = s
            s = vv.step(model, s, dt)
            if vv.last_stats.gradient_evaluations == 2:
                twice.append(k)
            again = VV().step(model, fe.State(prev.x.copy(), prev.v.copy(), prev.t), dt)
            assert np.array_equal(again.x, s.x) and np.array_equal(again.v, s.v), (method, k)
        # held up by the ground: projected onto it, or a penalty spring's 0.3 mm into it
        assert s.x[2::3].min() >= -0.0015
        if method == "impulse":
            # the first step, and every step after one that projected a node onto the ground
            # (from the fourth on: the tip then rests on it)
            assert twice[0] == 0 and len(twice) > 30
        else:
            assert twice == [0]


def test_linear_and_angular_momentum_of_a_free_body():
    mesh = fe.beam_mesh(length=0.3, width=0.1, height=0.1, cells=(3, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)))
    rng = np.random.default_rng(0)
    s0 = fe.State.rest(model, velocity=lambda X: np.cross([0.3, -0.2, 1.0], X - X.mean(axis=0))
                       + 0.05 * rng.standard_normal(X.shape))
    run = fe.simulate(model, VV(), 1e-3, steps=50, state=s0)
    P0, L0 = run.linear_momentum[0], run.angular_momentum[0]
    # exact in exact arithmetic (each kick adds no net force or torque, the drift moves along the
    # momentum): 50 steps of round-off on sums over 32 nodes
    np.testing.assert_allclose(run.linear_momentum, np.broadcast_to(P0, run.linear_momentum.shape),
                               rtol=0, atol=1e-12 * np.abs(s0.v).max() * model.lumped_mass.sum())
    np.testing.assert_allclose(run.angular_momentum, np.broadcast_to(L0, run.angular_momentum.shape),
                               rtol=0, atol=1e-12 * np.abs(L0).max())


# -- sub-stepping --------------------------------------------------------------------------------
def test_substep_count_is_the_critical_step_ratio_with_one_force_per_substep():
    model = _sagging((6, 1, 1))
    dt_crit = fe.critical_time_step(model, VV())
    dt = 12.3 * dt_crit
    vv = VV(substep=True)
    s = vv.step(model, fe.State.rest(model), dt)
    n = math.ceil(12.3 / 0.8)
    st = vv.last_stats
    # the judge's modified energy takes the force at the start (once) and at the end, which is
    # the scheme's own last force: n + 1 evaluations, then n a step
    assert (st.substeps, st.dt_cuts, st.gradient_evaluations) == (n, 0, n + 1)
    s = vv.step(model, s, dt)
    assert (vv.last_stats.substeps, vv.last_stats.gradient_evaluations) == (n, n)
    assert fe.critical_time_step(model, VV(substep=True)) == pytest.approx(dt_crit, rel=1e-9)
    np.testing.assert_array_equal(VV(substep=True).step_matrix(0.1, 3.0, 0.01), VV().step_matrix(0.1, 3.0, 0.01))
    with warnings.catch_warnings():
        warnings.simplefilter("error", fe.StabilityWarning)  # no warning: it sub-steps
        run = fe.simulate(model, VV(substep=True), dt, steps=20)
    mgL = model.lumped_mass.sum() / 3.0 * 9.81 * 1.0
    # measured 8e-5 mgL (symplectic Euler sub-stepped alike: 4e-3, first order)
    assert np.abs(run.total).max() < 0.01 * mgL


def test_a_kick_that_inverts_an_element_is_retried_with_more_substeps_and_resumes_bit_for_bit(tmp_path):
    model = _sagging((6, 1, 1))
    X = model.X.reshape(-1, 3)
    v = np.zeros_like(X)
    v[np.argmax(X.sum(axis=1)), 2] = -20.0
    state = fe.State.rest(model, velocity=v)
    dt = 3.0 * fe.critical_time_step(model, VV())

    def run(**kw):
        return fe.simulate(model, VV(substep=True, recheck_every=3), dt, steps=12, state=state, **kw)

    full = run()
    assert full.cuts and full.cuts[0]["step"] == 0
    assert full.step_stats["substeps"][0] >= 2 * math.ceil(3.0 / 0.8)
    with pytest.raises(KeyboardInterrupt):
        run(checkpoint_dir=tmp_path, callback=_StopAt(5))
    assert {"gradient", "dt_crit", "h_max"} <= set(fe.load_checkpoint(tmp_path).integrator_state)
    resumed = run(checkpoint_dir=tmp_path, resume=True)
    assert resumed.resumed_from_step == 5
    for name in ("times", "displacement", "velocity", "total"):
        assert np.array_equal(getattr(full, name), getattr(resumed, name)), name
    for name in ("substeps", "dt_cuts", "gradient_evaluations"):
        assert np.array_equal(full.step_stats[name], resumed.step_stats[name]), name
    assert full.cuts == resumed.cuts


# -- resume bit for bit --------------------------------------------------------------------------
CASES = {
    "corotated, damped, gravity": (
        lambda: _beam(fe.Corotated, E=2e4, damping=fe.Rayleigh(0.5, 1e-4), gravity=(0, 0, -9.81)), 1e-3, None),
    "linear P2, kicked": (lambda: _beam(fe.LinearElastic, E=2e4, order=2), 5e-4, _kicked),
    "impulse ground contact": (
        lambda: _beam(fe.Corotated, E=2e4, gravity=(0, 0, -9.81), ground=fe.Ground(z=-0.001, method="impulse")),
        1e-3, None),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("how", ["ctrl-c", "crash after a periodic checkpoint"])
def test_resumed_run_is_bit_for_bit_the_uninterrupted_one(tmp_path, case, how):
    make_model, dt, initial = CASES[case]
    model = make_model()
    state = initial(model) if initial else fe.State.rest(model)
    steps = 40

    def run(**kw):
        return fe.simulate(model if "resume" not in kw else make_model(), VV(), dt, steps=steps, state=state,
                           record_every=3, check_stability=False, **kw)

    full = run()
    d = tmp_path / "ck"
    if how == "ctrl-c":
        with pytest.raises(KeyboardInterrupt):
            run(checkpoint_dir=d, callback=_StopAt(23))
        assert fe.load_checkpoint(d).step == 23
    else:
        with pytest.raises(RuntimeError):
            run(checkpoint_dir=d, checkpoint_every=7, callback=_StopAt(23, RuntimeError))
        assert fe.load_checkpoint(d).step == 21
    resumed = run(checkpoint_dir=d, checkpoint_every=7, resume=True)
    assert_same_run(full, resumed)


# -- scene files and the command -----------------------------------------------------------------
def test_scene_files_reach_the_options_with_their_types():
    opts = integrator_options("velocity_verlet")
    assert {k: type(t) for k, (t, _) in opts.items()} == {
        "substep": Boolean, "safety": Number, "recheck_every": Integer, "max_substeps": Integer}
    vv = make_integrator({"type": "velocity_verlet", "substep": True, "safety": 0.5})
    assert isinstance(vv, VV) and (vv.substep, vv.safety) == (True, 0.5)


SCENE = """\
[scene]
name = "verlet-and-trapezoid"
[mesh]
kind = "beam"
length = 0.4
width = 0.1
height = 0.1
cells = [4, 1, 1]
[body]
material = "neo_hookean"
E = 1e5
nu = 0.3
density = 1000.0
[boundary]
fixed = ["left"]
[loads]
gravity = [0.0, 0.0, -9.81]
[integrator]
type = "trapezoid"
[time]
dt = 0.01
duration = 0.05

[[compare]]
name = "verlet"
integrator = { type = "velocity_verlet", substep = true }
"""


def test_the_command_runs_both_and_matches_the_python_api(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE)
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "fem_elastic.app.cli", "run", str(path), "--out", str(out),
                        "--quiet", "--no-render"], check=False, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    mesh = fe.beam_mesh(length=0.4, width=0.1, height=0.1, cells=(4, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
                     fixed="left", gravity=(0.0, 0.0, -9.81))
    for variant, integ in (("fem", fe.Trapezoid()), ("verlet", VV(substep=True))):
        series = read_series(out / variant)
        traj = fe.simulate(model, integ, dt=0.01, steps=5)
        # the same arithmetic in both processes (the sub-step count from a Lanczos estimate far
        # from its rounding boundary); the VTU stores float64
        np.testing.assert_allclose(series.displacement, traj.displacement, rtol=0, atol=1e-12)
