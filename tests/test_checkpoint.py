"""Checkpoints: a run stopped anywhere and resumed records the uninterrupted trajectory, bit for bit."""

from __future__ import annotations

import os

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.dynamics.checkpoint import CHECKPOINT_NAME, FRAMES_NAME, STEPS_NAME
from fem_elastic.dynamics.trajectory import STEP_FIELDS

ARRAYS = ("times", "displacement", "velocity", "kinetic", "potential", "total", "linear_momentum",
          "angular_momentum")
COUNTS = ("gradient_evaluations", "newton_iterations", "line_search_cuts", "linear_iterations",
          "dt_cuts", "substeps")


def _beam(material=fe.NeoHookean, E=2e5, order=1, **terms):
    return fe.Model(fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(4, 1, 1)), density=1000.0,
                    body=fe.ElasticBody(material(E=E, nu=0.3), order=order), fixed="left", **terms)


def _kicked(model):
    return fe.State.rest(model, velocity=lambda X: np.column_stack(
        [0 * X[:, 0], 0.3 * X[:, 0], -0.5 * X[:, 0]]))


def assert_same_run(a, b):
    """Every recorded array and every per-step count equal, bit for bit; the same cuts."""
    for name in ARRAYS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape, name
        assert np.array_equal(x, y), f"{name} differs: max |diff| {np.max(np.abs(x - y)):.3g}"
    for name in COUNTS:
        assert np.array_equal(a.step_stats[name], b.step_stats[name]), name
    assert a.cuts == b.cuts
    assert a.steps == b.steps and a.dt == b.dt
    assert np.array_equal(a.final_state.x, b.final_state.x)
    assert np.array_equal(a.final_state.v, b.final_state.v)
    assert a.final_state.t == b.final_state.t


class _StopAt:
    """A callback that raises ``exc`` after step ``k``."""

    def __init__(self, k, exc=KeyboardInterrupt):
        self.k, self.exc = k, exc

    def __call__(self, step, state):
        if step == self.k:
            raise self.exc("stopped by the test")


CASES = {
    "implicit Euler, Neo-Hookean P1, gravity": (
        lambda: _beam(gravity=(0, 0, -9.81)), fe.ImplicitEuler, 0.02, None),
    "Newmark, StVK P2, kicked": (lambda: _beam(fe.StVK, order=2), fe.Newmark, 0.02, _kicked),
    "symplectic Euler, corotated, damped": (
        lambda: _beam(fe.Corotated, E=2e4, damping=fe.Rayleigh(0.5, 1e-4), gravity=(0, 0, -9.81)),
        fe.SymplecticEuler, 1e-3, None),
    "RK4, linear, kicked": (lambda: _beam(fe.LinearElastic, E=2e4), fe.RK4, 2e-3, _kicked),
    "stiffness warping, ground contact": (
        lambda: _beam(fe.Corotated, gravity=(0, 0, -9.81), ground=fe.Ground(z=-0.08)),
        fe.LinearizedImplicitEuler, 0.02, None),
    "Newmark, twisted end (driven)": (
        lambda: fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
                         body=fe.ElasticBody(fe.NeoHookean(E=2e5, nu=0.3)), fixed="left",
                         driven={"right": fe.Twist(np.pi / 4, duration=0.1, release=0.2)}),
        fe.Newmark, 0.02, None),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("how", ["ctrl-c", "crash after a periodic checkpoint"])
def test_resumed_run_is_bit_for_bit_the_uninterrupted_one(tmp_path, case, how):
    make_model, make_integrator, dt, initial = CASES[case]
    model = make_model()
    state = initial(model) if initial else fe.State.rest(model)
    steps, every = 17, 3
    full = fe.simulate(model, make_integrator(), dt, steps=steps, state=state, record_every=2,
                       check_stability=False)
    d = tmp_path / "ck"
    if how == "ctrl-c":  # the checkpoint is written on the interrupt, of the last step completed
        with pytest.raises(KeyboardInterrupt):
            fe.simulate(model, make_integrator(), dt, steps=steps, state=state, record_every=2,
                        check_stability=False, checkpoint_dir=d, callback=_StopAt(10))
        assert fe.load_checkpoint(d).step == 10  # steps 0..9 done; step 10's callback raised
    else:  # a crash leaves only the periodic checkpoints (every 3 steps): resume from step 9
        with pytest.raises(RuntimeError):
            fe.simulate(model, make_integrator(), dt, steps=steps, state=state, record_every=2,
                        check_stability=False, checkpoint_dir=d, checkpoint_every=every,
                        callback=_StopAt(10, RuntimeError))
        assert fe.load_checkpoint(d).step == 9
    # a fresh integrator and a rebuilt model, as in a new process
    resumed = fe.simulate(make_model(), make_integrator(), dt, steps=steps, state=state, record_every=2,
                          check_stability=False, checkpoint_dir=d, checkpoint_every=every, resume=True)
    assert resumed.resumed_from_step in (9, 10)
    assert_same_run(full, resumed)
    # the history files hold exactly the run, written once (appended, never rewritten)
    ck = fe.load_checkpoint(d)
    assert ck.complete and ck.step == steps
    frame_bytes = full.times.size * (9 + 6 * model.mesh.p.shape[1]) * 8
    assert (d / FRAMES_NAME).stat().st_size == frame_bytes
    assert (d / STEPS_NAME).stat().st_size == steps * len(STEP_FIELDS) * 8


def _two_cubes_ipc():
    """A 0.1 m cube 2 mm above another, whose bottom is held, IPC contact between them (96 tets)."""
    m = fe.beam_mesh(length=0.1, width=0.1, height=0.1, cells=(2, 2, 2))
    p, t = m.p.T, m.t.T
    mesh = fe.mesh_from_arrays(np.vstack([p, p + [0.0, 0.0, 0.102]]), np.vstack([t, t + len(p)]))
    fixed = np.zeros(mesh.p.shape[1], dtype=bool)
    fixed[:len(p)] = mesh.p[2, :len(p)] < 1e-12
    return fe.Model(mesh, 1000.0, fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3)), fixed=fixed,
                    gravity=(0.0, 0.0, -9.81), contact=fe.IPCContact(dhat=1e-3))


def test_ipc_resume_keeps_the_adaptive_barrier_stiffness(tmp_path):
    """IPC's adaptive kappa is state of the model: the checkpoint keeps it, so the resumed run is
    the uninterrupted one bit for bit (without it the resumed run restarts from the bound kappa
    and drifts by ~1e-8 m here). ipctk sums the pair Hessians on several threads in a varying
    order (two uninterrupted runs then differ by ~3e-17 m), so the test runs it on one thread."""
    ipctk = pytest.importorskip("ipctk")
    threads = ipctk.get_num_threads()
    ipctk.set_num_threads(1)
    try:
        steps, dt = 17, 0.01
        state = fe.State.rest(_two_cubes_ipc())
        model = _two_cubes_ipc()
        full = fe.simulate(model, fe.ImplicitEuler(), dt, steps=steps, state=state, record_every=2,
                           check_stability=False)
        d = tmp_path / "ck"
        with pytest.raises(KeyboardInterrupt):
            fe.simulate(_two_cubes_ipc(), fe.ImplicitEuler(), dt, steps=steps, state=state,
                        record_every=2, check_stability=False, checkpoint_dir=d,
                        callback=_StopAt(10))
        ck = fe.load_checkpoint(d)
        kappa = ck.model_state["contact.kappa"][0]
        fresh = _two_cubes_ipc()
        assert kappa != fresh.contact.kappa  # the contact set it during the first 10 steps
        resumed = fe.simulate(fresh, fe.ImplicitEuler(), dt, steps=steps, state=state,
                              record_every=2, check_stability=False, checkpoint_dir=d, resume=True)
        assert resumed.resumed_from_step == 10
        assert_same_run(full, resumed)
        assert fresh.contact.kappa == model.contact.kappa
    finally:
        ipctk.set_num_threads(threads)


def test_newmark_resume_needs_the_remembered_acceleration(tmp_path):
    """Without the integrator's state the resumed run is not the same: the test can fail."""
    make_model, _, dt, initial = CASES["Newmark, StVK P2, kicked"]
    model = make_model()
    state = initial(model)
    full = fe.simulate(model, fe.Newmark(), dt, steps=12, state=state)
    d = tmp_path / "ck"
    with pytest.raises(KeyboardInterrupt):
        fe.simulate(model, fe.Newmark(), dt, steps=12, state=state, checkpoint_dir=d, callback=_StopAt(6))
    with np.load(d / CHECKPOINT_NAME) as z:
        arrays = {k: z[k] for k in z.files}
    assert "integrator/acceleration" in arrays
    del arrays["integrator/acceleration"]  # Newmark then recomputes a from M a = f
    np.savez(d / CHECKPOINT_NAME, **arrays)
    resumed = fe.simulate(model, fe.Newmark(), dt, steps=12, state=state, checkpoint_dir=d, resume=True)
    diff = np.abs(resumed.displacement - full.displacement).max()
    assert diff > 0.0  # not the same bits: the saved acceleration is what makes a resume exact
    # ... and still the same motion: the scheme's a1 and M^-1 f(x1) differ by Newton's residual
    # (rtol = 1e-8 of the step's force scale), which moves the next steps by about that fraction
    # of the displacement; 100 x rtol leaves room for the few steps it propagates over
    assert diff < 1e-6 * np.abs(full.displacement).max()


def test_finished_checkpoint_returns_the_run_without_stepping(tmp_path):
    model = _beam(gravity=(0, 0, -9.81))
    d = tmp_path / "ck"
    full = fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=5, checkpoint_dir=d)
    calls = []
    again = fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=5, checkpoint_dir=d, resume=True,
                        callback=lambda k, s: calls.append(k))
    assert calls == []
    assert_same_run(full, again)
    assert again.wall_time >= full.wall_time  # the sessions' wall times add up
    traj = fe.load_checkpoint(d).trajectory()
    for name in ARRAYS:
        assert np.array_equal(getattr(traj, name), getattr(full, name))


def test_resume_without_a_checkpoint_starts_afresh(tmp_path):
    model = _beam(gravity=(0, 0, -9.81))
    plain = fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=4)
    fresh = fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=4, checkpoint_dir=tmp_path / "new",
                        resume=True)
    assert fresh.resumed_from_step is None
    assert_same_run(plain, fresh)


def test_a_torn_tail_after_the_checkpoint_is_ignored_and_cut(tmp_path):
    """A crash while appending leaves extra bytes; the checkpoint counts its own records only."""
    model = _beam(gravity=(0, 0, -9.81))
    full = fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=9)
    d = tmp_path / "ck"
    with pytest.raises(KeyboardInterrupt):
        fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=9, checkpoint_dir=d, callback=_StopAt(5))
    for name in (FRAMES_NAME, STEPS_NAME):
        with open(d / name, "ab") as fh:
            fh.write(b"\x7f" * 37)  # half a record of garbage
    resumed = fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=9, checkpoint_dir=d, resume=True)
    assert_same_run(full, resumed)
    assert (d / FRAMES_NAME).stat().st_size == full.times.size * (9 + 6 * 20) * 8


def test_a_failed_checkpoint_write_keeps_the_previous_one(tmp_path, monkeypatch):
    model = _beam(gravity=(0, 0, -9.81))
    d = tmp_path / "ck"
    real_replace = os.replace
    calls = {"n": 0}

    def failing_replace(src, dst):
        if str(dst).endswith(CHECKPOINT_NAME):
            calls["n"] += 1
            if calls["n"] == 2:  # the second checkpoint (after step 4) fails to land
                raise OSError(28, "No space left on device")
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(OSError):
        fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=9, checkpoint_dir=d, checkpoint_every=2)
    monkeypatch.setattr(os, "replace", real_replace)
    assert fe.load_checkpoint(d).step == 2  # the first one, whole
    assert not [p for p in d.iterdir() if p.name.endswith(".tmp")]
    resumed = fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=9, checkpoint_dir=d, checkpoint_every=2,
                          resume=True)
    assert_same_run(fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=9), resumed)


@pytest.mark.parametrize("change, named", [
    (dict(dt=0.01), "dt"),
    (dict(steps=8), "n_steps"),
    (dict(record_every=2), "record_every"),
    (dict(integrator=fe.Newmark()), "integrator"),
    (dict(integrator=fe.ImplicitEuler(rtol=1e-6)), "integrator_settings"),
    (dict(model=_beam(E=3e5, gravity=(0, 0, -9.81))), "body"),
    (dict(model=_beam(gravity=(0, 0, -1.62))), "model_arrays"),
    (dict(state="kicked"), "initial_state"),
])
def test_resuming_a_different_run_is_refused(tmp_path, change, named):
    model = _beam(gravity=(0, 0, -9.81))
    d = tmp_path / "ck"
    with pytest.raises(KeyboardInterrupt):
        fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=6, checkpoint_dir=d, callback=_StopAt(3))
    args = dict(model=model, integrator=fe.ImplicitEuler(), dt=0.02, steps=6, record_every=1, state=None)
    args.update(change)
    if args["state"] == "kicked":
        args["state"] = _kicked(model)
    with pytest.raises(fe.InvalidParameter, match=f"different run.*{named}.*resume=False"):
        fe.simulate(args.pop("model"), args.pop("integrator"), args.pop("dt"), checkpoint_dir=d,
                    resume=True, **args)
    assert fe.load_checkpoint(d).step == 3  # refused before touching anything


def test_bad_checkpoint_arguments_and_files(tmp_path):
    model = _beam()
    with pytest.raises(fe.InvalidParameter, match="need checkpoint_dir"):
        fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=2, checkpoint_every=5)
    with pytest.raises(fe.InvalidParameter, match="need checkpoint_dir"):
        fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=2, resume=True)
    for bad in (-1, 1.5, True, "3"):
        with pytest.raises(fe.InvalidParameter, match="checkpoint_every must be an integer >= 0"):
            fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=2, checkpoint_dir=tmp_path / "a",
                        checkpoint_every=bad)
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(fe.InvalidParameter, match="is a file"):
        fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=2, checkpoint_dir=f)
    with pytest.raises(fe.InvalidParameter, match="no checkpoint in .*missing"):
        fe.load_checkpoint(tmp_path / "nothing")
    d = tmp_path / "ck"
    fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=2, checkpoint_dir=d)
    (d / CHECKPOINT_NAME).write_bytes(b"not a zip file")
    with pytest.raises(fe.InvalidParameter, match="cannot be read.*remove the directory"):
        fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=2, checkpoint_dir=d, resume=True)
    fe.simulate(model, fe.ImplicitEuler(), 0.02, steps=2, checkpoint_dir=d)  # resume=False: replaced
    with open(d / FRAMES_NAME, "r+b") as fh:
        fh.truncate(100)  # the history lost records the checkpoint counts
    with pytest.raises(fe.InvalidParameter, match="damaged"):
        fe.load_checkpoint(d)


def test_diverged_run_checkpoints_its_last_good_step(tmp_path):
    """A blow-up writes no checkpoint of the bad state: the last good step is checkpointed."""
    model = _beam(fe.LinearElastic, E=2e6)
    dt = 1.05 * fe.critical_time_step(model, fe.SymplecticEuler())  # blows up after ~14 steps
    d = tmp_path / "ck"
    with pytest.raises(fe.Diverged) as info:
        fe.simulate(model, fe.SymplecticEuler(), dt, steps=400, state=_kicked(model), check_stability=False,
                    checkpoint_dir=d, checkpoint_every=4)
    ck = fe.load_checkpoint(d)
    assert ck.step == info.value.step  # the step before the bad one, periodic or not
    assert np.array_equal(ck.state.x, info.value.last_good_state.x) and np.isfinite(ck.state.x).all()


def test_cuts_are_recorded_through_a_resume(tmp_path):
    """Newton failing at the full step halves it; where and why survive a checkpoint."""
    model = _beam(gravity=(0, 0, -9.81))
    kick = fe.State.rest(model, velocity=lambda X: np.column_stack(
        [0 * X[:, 0], 0 * X[:, 0], -20.0 * X[:, 0]]))
    make = lambda: fe.ImplicitEuler(max_iter=4)  # noqa: E731 - few iterations: the violent steps cut
    full = fe.simulate(model, make(), 0.05, steps=8, state=kick)
    assert full.cuts, "the scene is meant to make Newton fail at the full step"
    first = full.cuts[0]
    assert set(first) == {"step", "t", "dt", "reason"} and "Newton did not converge" in first["reason"]
    assert first["dt"] == 0.05 and full.dt_cuts == np.count_nonzero(full.step_stats["dt_cuts"])
    assert full.summary()["steps_cut"] == full.dt_cuts
    d = tmp_path / "ck"
    with pytest.raises(KeyboardInterrupt):
        fe.simulate(model, make(), 0.05, steps=8, state=kick, checkpoint_dir=d, callback=_StopAt(4))
    resumed = fe.simulate(model, make(), 0.05, steps=8, state=kick, checkpoint_dir=d, resume=True)
    assert_same_run(full, resumed)
