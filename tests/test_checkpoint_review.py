"""Second reader's checks of checkpoints and resume (issue 7, part 1).

Each test states a case where the claim "a resumed run repeats the uninterrupted
one bit for bit, and a different run is refused" should hold. Most began as
strict xfails showing a bug found in review, and pass since it was fixed.
"""

from __future__ import annotations

import builtins
import json
import logging
import shlex
import sys
from pathlib import Path

import numpy as np
import pytest

import fem_elastic as fe
import fem_elastic.dynamics.checkpoint as ckmod
from fem_elastic.app import cli
from fem_elastic.app.vtu import read_series
from fem_elastic.app.output import SeriesWriter
from fem_elastic.app.runner import resume_scene, run_scene

sys.path.insert(0, str(Path(__file__).parent))
from test_checkpoint import _beam, _StopAt, assert_same_run  # noqa: E402
from test_cli import TINY  # noqa: E402


class _PowerCut(BaseException):
    """A crash that no handler in the library catches (as kill -9: no cleanup of our own)."""


def _kicked_down(model):
    return fe.State.rest(model, velocity=lambda X: np.column_stack(
        [0 * X[:, 0], 0 * X[:, 0], -20.0 * X[:, 0]]))


def test_a_crash_while_rewriting_cuts_keeps_the_previous_checkpoint(tmp_path, monkeypatch):
    model = _beam(gravity=(0, 0, -9.81))
    kick = _kicked_down(model)
    make = lambda: fe.ImplicitEuler(max_iter=4)  # noqa: E731 - few iterations: every step is cut
    full = fe.simulate(model, make(), 0.05, steps=6, state=kick)
    assert len({c["step"] for c in full.cuts}) >= 2, "the scene must cut steps before two checkpoints"
    d = tmp_path / "ck"
    opened = {"n": 0}
    real_open = builtins.open

    def open_then_die(path, mode="r", *args, **kwargs):
        fh = real_open(path, mode, *args, **kwargs)
        if isinstance(path, (str, Path)) and ckmod.CUTS_NAME in Path(path).name \
                and any(c in mode for c in "wax+"):
            opened["n"] += 1
            if opened["n"] == 2:  # the second checkpoint's write of the cuts: the power goes
                fh.close()
                raise _PowerCut
        return fh

    monkeypatch.setattr(builtins, "open", open_then_die)
    try:  # however the cuts are written (in place, appended, or to a file renamed over it)
        fe.simulate(model, make(), 0.05, steps=6, state=kick, checkpoint_dir=d, checkpoint_every=1)
    except _PowerCut:
        pass
    finally:
        monkeypatch.undo()
    assert opened["n"] >= 2, "the run must write the cuts at two checkpoints"
    resumed = fe.simulate(model, make(), 0.05, steps=6, state=kick, checkpoint_dir=d,
                          checkpoint_every=1, resume=True)
    assert_same_run(full, resumed)


def test_a_lost_cuts_file_is_a_typed_error(tmp_path):
    model = _beam(gravity=(0, 0, -9.81))
    d = tmp_path / "ck"
    with pytest.raises(KeyboardInterrupt):
        fe.simulate(model, fe.ImplicitEuler(max_iter=4), 0.05, steps=6, state=_kicked_down(model),
                    checkpoint_dir=d, callback=_StopAt(3))
    assert fe.load_checkpoint(d).cuts, "the run must have cut steps"
    (d / ckmod.CUTS_NAME).write_text("")  # emptied, as by a crash mid-rewrite
    with pytest.raises(fe.InvalidParameter, match="cuts.jsonl"):
        fe.load_checkpoint(d)


def test_resuming_with_another_driven_release_is_refused(tmp_path):
    def model(release):
        return fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
                        body=fe.ElasticBody(fe.NeoHookean(E=2e5, nu=0.3)), fixed="left",
                        driven={"right": fe.Twist(np.pi / 4, duration=0.1, release=release)})

    d = tmp_path / "ck"
    with pytest.raises(KeyboardInterrupt):
        fe.simulate(model(0.2), fe.Newmark(), 0.02, steps=10, checkpoint_dir=d, callback=_StopAt(3))
    with pytest.raises(fe.InvalidParameter, match="different run"):
        fe.simulate(model(0.5), fe.Newmark(), 0.02, steps=10, checkpoint_dir=d, resume=True)


def test_resuming_with_another_linear_solver_tolerance_is_refused(tmp_path):
    model = _beam(gravity=(0, 0, -9.81))
    d = tmp_path / "ck"
    with pytest.raises(KeyboardInterrupt):
        fe.simulate(model, fe.ImplicitEuler(linear_solver=fe.AMGSolver(rtol=1e-8)), 0.02, steps=6,
                    checkpoint_dir=d, callback=_StopAt(3))
    with pytest.raises(fe.InvalidParameter, match="different run"):
        fe.simulate(model, fe.ImplicitEuler(linear_solver=fe.AMGSolver(rtol=1e-3)), 0.02, steps=6,
                    checkpoint_dir=d, resume=True)


def test_substepped_symplectic_resume_has_the_same_statistics(tmp_path):
    """Its remembered gradient is checkpointed: positions and force counts match (7a86192)."""
    model = _beam(fe.LinearElastic, E=2e4, gravity=(0, 0, -9.81))
    state = fe.State.rest(model, velocity=lambda X: np.column_stack(
        [0 * X[:, 0], 0.3 * X[:, 0], -0.5 * X[:, 0]]))
    make = lambda: fe.SymplecticEuler(substep=True, recheck_every=3)  # noqa: E731
    full = fe.simulate(model, make(), 0.02, steps=8, state=state, record_every=2)
    assert full.step_stats["substeps"].max() > 1, "dt must be above the critical step"
    d = tmp_path / "ck"
    with pytest.raises(KeyboardInterrupt):
        fe.simulate(model, make(), 0.02, steps=8, state=state, record_every=2, checkpoint_dir=d,
                    callback=_StopAt(4))
    resumed = fe.simulate(model, make(), 0.02, steps=8, state=state, record_every=2,
                          checkpoint_dir=d, resume=True)
    assert_same_run(full, resumed)


def _tiny(tmp_path, extra=""):
    # 10 steps, a frame every 3: frames after steps 0, 3, 6, 9 and the last (10), which only
    # SeriesWriter.finish writes in run_variant (the writer is not told n_steps)
    text = TINY.replace('render = ["gif", "png"]', "render = []").replace("every = 2", "every = 3" + extra)
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return fe.load_scene(path)


def test_a_stop_between_the_final_checkpoint_and_the_last_frame(tmp_path, monkeypatch, caplog):
    scene = _tiny(tmp_path)
    run_scene(scene, tmp_path / "a", variants=["fem"], render=False)
    real = SeriesWriter.finish

    def stop_before_finishing(self, trajectory=None, status="completed", *args, **kwargs):
        if status == "completed":
            raise KeyboardInterrupt  # Ctrl-C (or kill -9) right after simulate returned
        return real(self, trajectory, status, *args, **kwargs)

    monkeypatch.setattr(SeriesWriter, "finish", stop_before_finishing)
    with pytest.raises(KeyboardInterrupt):
        run_scene(scene, tmp_path / "b", variants=["fem"], render=False)
    monkeypatch.setattr(SeriesWriter, "finish", real)
    with caplog.at_level(logging.WARNING):
        resume_scene(tmp_path / "b", render=False)
    assert not [r for r in caplog.records if "missing" in r.getMessage()]
    sa, sb = read_series(tmp_path / "a" / "fem"), read_series(tmp_path / "b" / "fem")
    assert np.array_equal(sa.times, sb.times) and np.array_equal(sa.displacement, sb.displacement)
    assert [p.name for p in sb.files] == [p.name for p in sa.files]


def test_ctrl_c_in_every_callback_of_a_scene_resumes_to_the_same_series(tmp_path, monkeypatch):
    """A Ctrl-C at each step in turn (frames written on some, not others) ends the same."""
    scene = _tiny(tmp_path, "\ncheckpoint_every = 4")
    run_scene(scene, tmp_path / "a", variants=["fem"], render=False)
    ref = read_series(tmp_path / "a" / "fem")
    real = SeriesWriter.callback
    for stop in (0, 2, 3, 5, 9):  # before any checkpoint, around a frame, at the last step
        def ctrl_c(self, k, state, stop=stop):
            if k == stop:
                raise KeyboardInterrupt
            real(self, k, state)

        b = tmp_path / f"b{stop}"
        monkeypatch.setattr(SeriesWriter, "callback", ctrl_c)
        with pytest.raises(KeyboardInterrupt):
            run_scene(scene, b, variants=["fem"], render=False)
        monkeypatch.setattr(SeriesWriter, "callback", real)
        resume_scene(b, render=False)
        got = read_series(b / "fem")
        assert np.array_equal(got.times, ref.times), stop
        assert np.array_equal(got.displacement, ref.displacement), stop
        assert np.array_equal(got.velocity, ref.velocity), stop
        assert [p.name for p in got.files] == [p.name for p in ref.files], stop
        assert got.summary["frames"] == ref.summary["frames"] and got.summary["status"] == "completed"


def test_resuming_a_finished_run_without_vtu_keeps_its_summary(tmp_path, caplog):
    scene = _tiny(tmp_path, "\nvtu = false")
    out = tmp_path / "o"
    run_scene(scene, out, variants=["fem"], render=False)
    before = json.loads((out / "fem" / "summary.json").read_text())
    with caplog.at_level(logging.WARNING):
        resume_scene(out, render=False)
    after = json.loads((out / "fem" / "summary.json").read_text())
    assert not [r for r in caplog.records if "missing" in r.getMessage()]
    assert after["frames"] == before["frames"]


def test_the_resume_hint_quotes_a_path_with_spaces(tmp_path, monkeypatch, capsys):
    path = tmp_path / "scene.toml"
    path.write_text(TINY.replace('render = ["gif", "png"]', "render = []"))
    real = SeriesWriter.callback

    def ctrl_c(self, k, state):
        if k == 4:
            raise KeyboardInterrupt
        real(self, k, state)

    monkeypatch.setattr(SeriesWriter, "callback", ctrl_c)
    out = tmp_path / "my runs" / "out"
    assert cli.main(["run", str(path), "--out", str(out), "-q", "--variant", "fem"]) == 130
    assert f"fem-elastic run --resume {shlex.quote(str(out))}" in capsys.readouterr().err


def test_an_interrupted_rerun_leaves_no_stale_completed_summary(tmp_path, monkeypatch, capsys):
    path = tmp_path / "scene.toml"
    path.write_text(TINY.replace('render = ["gif", "png"]', "render = []"))
    out = tmp_path / "o"
    assert cli.main(["run", str(path), "--out", str(out), "-q", "--variant", "fem"]) == 0
    real = SeriesWriter.finish

    def ctrl_c_while_finishing(self, trajectory=None, status="completed", *args, **kwargs):
        if status == "completed":
            raise KeyboardInterrupt
        return real(self, trajectory, status, *args, **kwargs)

    monkeypatch.setattr(SeriesWriter, "finish", ctrl_c_while_finishing)
    assert cli.main(["run", str(path), "--out", str(out), "-q", "--variant", "fem"]) == 130
    assert "--resume" in capsys.readouterr().err
    top = out / "summary.json"
    assert not top.exists() or json.loads(top.read_text())["status"] != "completed"


def test_a_resume_sweeps_the_temporary_files_a_kill_left(tmp_path):
    scene = _tiny(tmp_path, "\ncheckpoint_every = 4")
    out = tmp_path / "o"
    run_scene(scene, out, variants=["fem"], render=False)
    leftovers = [out / "fem" / "frames" / ".frame_000004.vtu.k9x2ab.tmp",
                 out / "fem" / "checkpoint" / ".checkpoint.npz.q1w2e3.tmp"]
    for p in leftovers:
        p.write_bytes(b"\0" * 64)  # what a kill -9 mid-write leaves
    resume_scene(out, render=False)
    assert not [p for p in leftovers if p.exists()]


# -- second round: the review fixes (d3864db) -------------------------------------------------


def test_a_checkpoint_without_the_cuts_byte_count_is_a_typed_error(tmp_path):
    model = _beam(gravity=(0, 0, -9.81))
    d = tmp_path / "ck"
    with pytest.raises(KeyboardInterrupt):
        fe.simulate(model, fe.ImplicitEuler(max_iter=4), 0.05, steps=6, state=_kicked_down(model),
                    checkpoint_dir=d, callback=_StopAt(3))
    with np.load(d / ckmod.CHECKPOINT_NAME) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["meta"]))
    del meta["cuts_bytes"]  # as the checkpoints of 51993a3..bb34cc9 were written
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez(d / ckmod.CHECKPOINT_NAME, **arrays)
    with pytest.raises(fe.InvalidParameter):
        fe.load_checkpoint(d)


def test_resuming_with_another_prescribed_motion_is_refused(tmp_path):
    def rising(amplitude):  # at rest until 0.03 s, so the initial states are the same
        return lambda X, t: np.outer(np.ones(len(X)), [0.0, 0.0, amplitude * max(t - 0.03, 0.0) ** 2])

    def model(amplitude):
        return fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
                        body=fe.ElasticBody(fe.NeoHookean(E=2e5, nu=0.3)), fixed="left",
                        driven={"right": fe.Prescribed(rising(amplitude))})

    d = tmp_path / "ck"
    with pytest.raises(KeyboardInterrupt):
        fe.simulate(model(1.0), fe.ImplicitEuler(), 0.02, steps=8, checkpoint_dir=d, callback=_StopAt(3))
    with pytest.raises(fe.InvalidParameter, match="different run"):
        fe.simulate(model(-5.0), fe.ImplicitEuler(), 0.02, steps=8, checkpoint_dir=d, resume=True)


def test_a_series_writer_leaves_unrelated_temporary_files_alone(tmp_path):
    mine = tmp_path / ".notes.tmp"
    mine.write_text("not the writer's")
    SeriesWriter(_beam(), tmp_path)
    assert mine.exists()


def test_resuming_with_a_motion_calling_another_function_is_refused(tmp_path):
    def model(fn):  # at rest until 0.03 s, so the initial states are the same
        return fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
                        body=fe.ElasticBody(fe.NeoHookean(E=2e5, nu=0.3)), fixed="left",
                        driven={"right": fe.Prescribed(fn)})

    sin = lambda X, t: np.outer(np.ones(len(X)), [0.0, 0.0, 0.01 * np.sin(max(t - 0.03, 0.0))])  # noqa: E731
    tan = lambda X, t: np.outer(np.ones(len(X)), [0.0, 0.0, 0.01 * np.tan(max(t - 0.03, 0.0))])  # noqa: E731
    d = tmp_path / "ck"
    with pytest.raises(KeyboardInterrupt):
        fe.simulate(model(sin), fe.ImplicitEuler(), 0.02, steps=8, checkpoint_dir=d, callback=_StopAt(3))
    with pytest.raises(fe.InvalidParameter, match="different run"):
        fe.simulate(model(tan), fe.ImplicitEuler(), 0.02, steps=8, checkpoint_dir=d, resume=True)
