"""Adaptive sub-stepping of the explicit integrators from the critical time step.

An explicit step of any dt is taken as n = ceil(dt / (safety dt_crit)) stable
sub-steps, dt_crit re-estimated at the current configuration every
``recheck_every`` steps and on a failed attempt; a step whose end state is
not finite, inverted, or has gained energy is retried with more sub-steps.
"""

import math
import warnings

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.app.scene_schema import Boolean, Integer, Number, integrator_options, make_integrator, schema_help

SE = fe.SymplecticEuler


def _beam(material=None, **kw):
    """A 1 m cantilever of 6 P1 hexahedra (84 DOFs): a soft body with fast top modes."""
    material = material or fe.NeoHookean(E=1e5, nu=0.3)
    return fe.Model(fe.beam_mesh(cells=(6, 1, 1)), density=1000.0, body=fe.ElasticBody(material),
                    fixed="left", **kw)


@pytest.fixture(scope="module")
def sagging():
    """The cantilever under gravity, its critical step at rest, and a step 10 times it."""
    model = _beam(gravity=(0.0, 0.0, -9.81))
    dt_crit = fe.critical_time_step(model, SE())
    return model, dt_crit, 10.0 * dt_crit


def _total(model, s):
    return model.kinetic_energy(s.v) + model.energy(s.x)


# -- the point of it: a step far above the limit ------------------------------------------------
def test_plain_scheme_diverges_where_the_substepped_one_follows_a_fine_run(sagging):
    model, dt_crit, dt = sagging
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", fe.StabilityWarning)  # expected: dt is 10x the limit
        with pytest.raises(fe.Diverged):
            fe.simulate(model, SE(), dt, steps=20)

    se = SE(substep=True)
    s = fe.State.rest(model)
    energies, states = [], []
    for _ in range(40):
        s = se.step(model, s, dt)
        assert se.last_stats.dt_cuts == 0 and se.last_stats.cuts == []
        energies.append(_total(model, s))
        states.append(s)
    n = se.last_stats.substeps
    assert n == math.ceil(10.0 / 0.8)  # = 13: dt / (safety dt_crit), the body barely strained
    # bounded energy: symplectic Euler conserves a modified energy, so the measured total swings
    # by O(h omega) of the energy in motion and does not drift; measured: 0.4 % of m g L here
    # (98 J, the energy scale of the sag); 1 % leaves room for nothing else
    mgL = model.lumped_mass.sum() / 3.0 * 9.81 * 1.0
    assert np.max(np.abs(energies)) < 0.01 * mgL
    # the same run at the sub-step size: every sub-step is the plain scheme's step of dt / n,
    # from the same positions and velocities, so x and v agree bit for bit; only the clock
    # differs, t0 + k dt / n in the sub-steps against a running sum in the fine run (round-off)
    ref = fe.State.rest(model)
    plain = SE()
    for k in range(40 * n):
        ref = plain.step(model, ref, dt / n)
        if (k + 1) % n == 0:
            sub = states[k // n]
            assert np.array_equal(ref.x, sub.x) and np.array_equal(ref.v, sub.v)
            # 480 additions of dt / n, each rounding to half an ulp of t (<= 3.5 s here)
            assert sub.t == pytest.approx(ref.t, rel=480 * np.finfo(float).eps, abs=0)
    assert states[-1].t == pytest.approx(40 * dt, rel=40 * np.finfo(float).eps)


@pytest.mark.parametrize("scheme, factor, stages, damping", [
    (SE, 5.0, 1, None), (SE, 12.3, 1, None), (SE, 20.0, 1, None),
    (fe.RK4, 7.5, 4, None),
    # explicit Euler and midpoint need damping to have a stable step at all: 30 % of critical at
    # the top mode (beta omega_max / 2 = 0.3)
    (fe.ExplicitEuler, 6.0, 1, 0.3), (fe.Midpoint, 6.0, 2, 0.3),
])
def test_substep_count_is_the_critical_step_ratio(scheme, factor, stages, damping):
    model = _beam()
    if damping is not None:
        model = _beam(damping=fe.Rayleigh(beta=2.0 * damping / fe.max_frequency(model)))
    rng = np.random.default_rng(3)
    # a strained start (5 mm random displacements): the estimate is of the configuration given
    s0 = fe.State.rest(model, displacement=0.005 * rng.standard_normal((model.mesh.p.shape[1], 3)))
    dt_crit = fe.critical_time_step(model, scheme(), x=s0.x)
    assert 0 < dt_crit < math.inf
    dt = factor * dt_crit
    integ = scheme(substep=True)
    s1 = integ.step(model, s0, dt)
    st = integ.last_stats
    assert st.substeps == math.ceil(dt / (0.8 * dt_crit))
    # the estimate adds no force evaluation; symplectic Euler's judge (its modified energy) takes
    # the force at the step's end, which the next step's first sub-step reuses
    judge = 1 if scheme is SE else 0
    assert st.gradient_evaluations == stages * st.substeps + judge
    assert st.dt_cuts == 0 and st.cuts == []
    assert s1.t == s0.t + dt and np.isfinite(_total(model, s1))
    integ.step(model, s1, dt)
    assert integ.last_stats.gradient_evaluations == stages * integ.last_stats.substeps


def test_stiffening_under_compression_raises_the_substep_count():
    """A Neo-Hookean bar pushed to 35 % of its length: omega_max doubles, and so does n."""
    L, T = 0.5, 0.3
    model = fe.Model(fe.beam_mesh(length=L, width=0.1, height=0.1, cells=(5, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.45)), fixed="left",
                     driven={"right": fe.Translate((-0.65 * L, 0.0, 0.0), duration=T)})
    dt = 8.0 * fe.critical_time_step(model, SE())
    se = SE(substep=True, recheck_every=1)
    s, ns = fe.State.rest(model), []
    while s.t < T:
        start = s
        s = se.step(model, s, dt)
        assert se.last_stats.cuts == []  # tracked by the estimates alone
        ns.append(se.last_stats.substeps)
    # the last step's count is the ratio to the critical step at that step's start
    assert ns[-1] == math.ceil(dt / (0.8 * fe.critical_time_step(model, SE(), x=start.x)))
    assert ns[0] == math.ceil(8.0 / 0.8)
    assert all(b >= a for a, b in zip(ns, ns[1:]))  # compression only stiffens
    assert ns[-1] >= 2 * ns[0]  # measured 9 -> 19: omega_max x2.1 at 35 % length
    # the driven end is where the motion puts it at the step's end time, t0 + dt exactly
    dofs, xc, _ = model.constraints(s.t)
    assert np.array_equal(s.x[dofs], xc)


# -- failed attempts: retried with more sub-steps, recorded -------------------------------------
def test_a_kick_that_inverts_an_element_is_retried_with_more_substeps(sagging):
    model, dt_crit, _ = sagging
    X = model.X.reshape(-1, 3)
    v = np.zeros_like(X)
    v[np.argmax(X.sum(axis=1)), 2] = -20.0  # one tip corner thrown down at 20 m/s
    s0 = fe.State.rest(model, velocity=v)
    dt = 3.0 * dt_crit
    se = SE(substep=True)
    s1 = se.step(model, s0, dt)
    st = se.last_stats
    n0 = math.ceil(3.0 / 0.8)
    assert st.dt_cuts == len(st.cuts) >= 1
    t, h, reason = st.cuts[0]
    assert (t, h) == (0.0, dt / n0)
    assert "non-finite" in reason or "not finite" in reason  # the corner passes through its element
    assert [c[1] for c in st.cuts] == [dt / n0 / 2**k for k in range(len(st.cuts))]
    assert st.substeps == n0 * 2 ** len(st.cuts)
    assert np.isfinite(model.energy(s1.x)) and np.isfinite(s1.v).all()


def test_a_stale_estimate_is_caught_by_the_energy_and_re_estimated():
    """A critical step 3x too large (as after an unseen stiffening) makes the sub-steps unstable.

    Linear elasticity cannot invert, so the blow-up shows as energy growth; the retry
    re-estimates at the step's start, where doubling alone would still be unstable.
    """
    model = _beam(fe.LinearElastic(E=1e5, nu=0.3))
    rng = np.random.default_rng(1)
    s0 = fe.State.rest(model, velocity=0.01 * rng.standard_normal((model.mesh.p.shape[1], 3)))
    d = fe.critical_time_step(model, SE())
    dt = 5.0 * d
    se = SE(substep=True)
    se.restore_state(s0, {"dt_crit": np.array(3.0 * d), "h_max": np.array(0.8 * 3.0 * d),
                          "since_estimate": np.array(0), "energy_anchor": np.full(3, np.nan)})
    s1 = se.step(model, s0, dt)
    st = se.last_stats
    assert len(st.cuts) == st.dt_cuts == 1
    assert st.cuts[0][:2] == (0.0, dt / 3)  # ceil(5 / 2.4) = 3 sub-steps tried
    # its modified energy is exactly conserved on a linear body even where unstable (it is then
    # indefinite): the blow-up shows in KE + Pi, beyond the largest swing of a stable mode
    assert "total energy grew" in st.cuts[0][2] and "swing" in st.cuts[0][2]
    assert st.substeps == math.ceil(5.0 / 0.8) == 7  # from the re-estimate, not 2 x 3
    # stable now: each mode's measured energy stays within (1 + h w / 2) / (1 - h w / 2) of its
    # start for symplectic Euler (its modified energy is conserved), h w <= 2 x 5 / 7 here
    hw2 = 5.0 / 7.0
    assert _total(model, s1) <= _total(model, s0) * (1 + hw2) / (1 - hw2)


def test_too_many_substeps_raise_diverged(sagging):
    model, dt_crit, dt = sagging
    se = SE(substep=True, max_substeps=8)
    s0 = fe.State.rest(model)
    with pytest.raises(fe.Diverged, match="max_substeps = 8") as err:
        se.step(model, s0, dt)  # needs 12
    assert err.value.last_good_state is s0 and err.value.time == 0.0
    assert "max_substeps" in err.value.reason


@pytest.mark.parametrize("scheme", [fe.ExplicitEuler, fe.Midpoint])
def test_a_scheme_without_a_stable_step_cannot_substep(scheme):
    model = _beam()
    with pytest.raises(fe.InvalidParameter, match="no stable time step") as err:
        scheme(substep=True).step(model, fe.State.rest(model), 1e-3)
    for fix in ("fe.Rayleigh", "fe.SymplecticEuler", "fe.ImplicitEuler"):
        assert fix in str(err.value)


# -- what the integrator remembers ---------------------------------------------------------------
def test_checkpoint_round_trip_repeats_the_next_step_bit_for_bit(sagging):
    model, dt_crit, _ = sagging
    X = model.X.reshape(-1, 3)
    v = np.zeros_like(X)
    v[np.argmax(X.sum(axis=1)), 2] = -20.0
    dt = 3.0 * dt_crit
    a = SE(substep=True, recheck_every=3)
    s = a.step(model, fe.State.rest(model, velocity=v), dt)
    n0 = math.ceil(3.0 / 0.8)
    assert a.last_stats.substeps == 2 * n0  # the kick made it cut once: ...
    s = a.step(model, s, dt)
    assert a.last_stats.substeps == 2 * n0 and a.last_stats.cuts == []  # ... and it keeps the cut
    saved = a.checkpoint_state(s)
    assert sorted(saved) == ["dt_crit", "energy_anchor", "gradient", "h_max", "since_estimate"]
    saved = {k: np.array(val) for k, val in saved.items()}  # as read back from a file

    b = SE(substep=True, recheck_every=3)
    b.restore_state(s, saved)
    fresh = SE(substep=True, recheck_every=3)
    fresh.step(model, s, dt)
    # without the checkpoint: a new estimate here, and fewer sub-steps tried first
    n_fresh = math.ceil(dt / (0.8 * fe.critical_time_step(model, SE(), x=s.x)))
    st = fresh.last_stats
    assert n_fresh < 2 * n0
    assert (st.substeps == n_fresh and st.cuts == []) or st.cuts[0][1] == dt / n_fresh
    for k in range(3):  # the remembered sub-step, then the next re-estimate, then one more
        s_a, s_b = a.step(model, s, dt), b.step(model, s, dt)
        assert np.array_equal(s_a.x, s_b.x) and np.array_equal(s_a.v, s_b.v) and s_a.t == s_b.t
        assert a.last_stats.substeps == b.last_stats.substeps
        assert a.last_stats.cuts == b.last_stats.cuts
        if k == 0:
            assert b.last_stats.substeps == 2 * n0 and b.last_stats.cuts == []
        s = s_a


def test_restore_state_refuses_what_it_cannot_use(sagging):
    model, _, dt = sagging
    s = fe.State.rest(model)
    se = SE(substep=True)
    assert se.checkpoint_state(s) == {}  # nothing estimated yet
    se.restore_state(s, {})  # a checkpoint taken before the first step
    with pytest.raises(fe.InvalidParameter, match="another integrator"):
        se.restore_state(s, {"acceleration": np.zeros(model.ndofs)})  # Newmark's
    with pytest.raises(fe.InvalidParameter, match="damaged"):
        se.restore_state(s, {"dt_crit": np.array(-1.0), "h_max": np.array(1e-3),
                             "since_estimate": np.array(0), "energy_anchor": np.full(3, np.nan)})
    se.step(model, s, dt)
    with pytest.raises(fe.InvalidParameter, match="another integrator"):
        SE().restore_state(s, se.checkpoint_state(s))  # a plain scheme keeps nothing
    assert SE().checkpoint_state(s) == {}


# -- the settings --------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, match", [
    ({"safety": 0.0}, "safety"), ({"safety": 1.5}, "safety"), ({"safety": float("nan")}, "safety"),
    ({"safety": True}, "safety"), ({"safety": "0.9"}, "safety"),
    ({"recheck_every": 0}, "recheck_every"), ({"recheck_every": 2.0}, "recheck_every"),
    ({"recheck_every": True}, "recheck_every"), ({"max_substeps": 0}, "max_substeps"),
    ({"max_substeps": None}, "max_substeps"), ({"substep": "yes"}, "substep"), ({"substep": 1}, "substep"),
])
def test_constructor_rejects_bad_settings(kwargs, match):
    for scheme in (fe.ExplicitEuler, SE, fe.Midpoint, fe.RK4):
        with pytest.raises(fe.InvalidParameter, match=match):
            scheme(**kwargs)


def test_critical_time_step_and_step_matrix_are_those_of_one_substep(sagging):
    """The plain scheme's figures are unchanged; a sub-stepping scheme reports its sub-step limit."""
    model, dt_crit, _ = sagging
    # the closed form of symplectic Euler, 2 / omega_max (to the 1e-12 bisection of the search)
    assert dt_crit == pytest.approx(2.0 / fe.max_frequency(model), rel=1e-10)
    for scheme in (SE, fe.RK4):
        # equal to the Lanczos tolerance, 1e-10 relative (ARPACK starts from a random vector)
        assert fe.critical_time_step(model, scheme(substep=True)) == pytest.approx(
            fe.critical_time_step(model, scheme()), rel=1e-9)
        np.testing.assert_array_equal(scheme(substep=True).step_matrix(0.1, 3.0, 0.01),
                                      scheme().step_matrix(0.1, 3.0, 0.01))
    assert "substep=True" in repr(SE(substep=True)) and repr(SE()) == "fe.SymplecticEuler()"


def test_scene_files_reach_the_options_with_their_types():
    for name in ("explicit_euler", "symplectic_euler", "midpoint", "rk4"):
        opts = integrator_options(name)
        assert {k: type(t) for k, (t, _) in opts.items()} == {
            "substep": Boolean, "safety": Number, "recheck_every": Integer, "max_substeps": Integer}
        assert opts["substep"][1] is False and opts["safety"][1] == 0.8
    integ = make_integrator({"type": "rk4", "substep": True, "safety": 0.5, "recheck_every": 3})
    assert (integ.substep, integ.safety, integ.recheck_every) == (True, 0.5, 3)
    assert "symplectic_euler: substep = false, safety = 0.8" in " ".join(schema_help().split())


def test_a_resumed_substepped_run_is_the_uninterrupted_one(sagging, tmp_path):
    """Through simulate's checkpoints: a kick makes it cut before the stop, re-estimates follow it.

    The re-estimates start Lanczos from ARPACK's random vector, so a resumed run's dt_crit can
    differ from the uninterrupted one's in the last digits; n = ceil(dt / (safety dt_crit)) is an
    integer far from its rounding boundary here (and the estimate enters nothing else).
    """
    model, dt_crit, _ = sagging
    X = model.X.reshape(-1, 3)
    v = np.zeros_like(X)
    v[np.argmax(X.sum(axis=1)), 2] = -20.0
    state = fe.State.rest(model, velocity=v)
    dt = 3.0 * dt_crit

    def run(**kw):
        return fe.simulate(model, SE(substep=True, recheck_every=3), dt, steps=12, state=state, **kw)

    full = run()
    assert full.cuts and full.cuts[0]["step"] == 0

    def stop(k, s):
        if k == 4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run(checkpoint_dir=tmp_path, callback=stop)
    resumed = run(checkpoint_dir=tmp_path, resume=True)
    assert resumed.resumed_from_step == 4  # steps 0-3 done; step 4's callback raised
    for name in ("times", "displacement", "velocity", "total"):
        assert np.array_equal(getattr(full, name), getattr(resumed, name)), name
    for name in ("substeps", "dt_cuts", "gradient_evaluations"):
        assert np.array_equal(full.step_stats[name], resumed.step_stats[name]), name
    assert full.cuts == resumed.cuts


def test_an_integrator_moved_to_another_model_forgets_the_first(sagging):
    """Its estimate, sub-step and remembered energies belong to the model they were taken on."""
    model, dt_crit, dt = sagging
    stiff = _beam(fe.NeoHookean(E=4e5, nu=0.3), gravity=(0.0, 0.0, -9.81))  # omega_max x2
    se = SE(substep=True)
    s = se.step(model, fe.State.rest(model), dt)
    assert se.last_stats.substeps == math.ceil(10.0 / 0.8)
    se.step(stiff, s, dt)  # the same state object, a model twice as fast
    assert se.last_stats.cuts == []  # estimated afresh, not found out by a failed attempt
    assert se.last_stats.substeps == math.ceil(dt / (0.8 * fe.critical_time_step(stiff, SE(), x=s.x)))
    assert se.last_stats.substeps >= 2 * math.ceil(10.0 / 0.8) - 1
