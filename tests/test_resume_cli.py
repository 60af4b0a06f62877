"""`fem-elastic run --resume DIR`: a stopped scene run finishes as if it had never stopped."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fem_elastic.app import cli
from fem_elastic.app.vtu import read_series
from fem_elastic.app.output import SeriesWriter

from test_cli import TINY, clean_error, run

# Figures that measure the machine, not the run: they differ between any two runs.
TIMINGS = ("wall_time", "seconds_output", "seconds_total", "seconds_simulate")


def _scene(tmp_path, **replace):
    text = TINY.replace('render = ["gif", "png"]', "render = []").replace("duration = 0.1", "duration = 0.2")
    for old, new in replace.items():
        text = text.replace(old, new)
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return path


def _strip(summary: dict) -> dict:
    """A summary without its timings and the resume's own note."""
    out = {}
    for k, v in summary.items():
        if k in TIMINGS or k.startswith("seconds_") or k in ("resumed_from_step",):
            continue
        if k == "message":
            v = v.split(" (resumed")[0]
        out[k] = _strip(v) if isinstance(v, dict) else v
    return out


def assert_same_output(a: Path, b: Path, variants=("fem", "springs")):
    """Series (every frame's arrays and times) and summaries equal, bit for bit."""
    for name in variants:
        sa, sb = read_series(a / name), read_series(b / name)
        assert np.array_equal(sa.times, sb.times), name
        assert np.array_equal(sa.displacement, sb.displacement), name
        assert np.array_equal(sa.velocity, sb.velocity), name
        for field in sa.cell_data:
            assert np.array_equal(sa.cell_data[field], sb.cell_data[field], equal_nan=True), field
        assert [p.name for p in sa.files] == [p.name for p in sb.files]
        assert _strip(sa.summary) == _strip(sb.summary)
        assert sb.summary["status"] == "completed"


@pytest.mark.parametrize("where", ["fem", "springs"])
def test_ctrl_c_then_resume_matches_an_uninterrupted_run(tmp_path, monkeypatch, capsys, where):
    scene = _scene(tmp_path)
    assert cli.main(["run", str(scene), "--out", str(tmp_path / "a"), "-q"]) == 0
    real = SeriesWriter.callback

    def stop_at_step_12(self, k, state):
        if k == 12 and self.run_dir.name == where:
            raise KeyboardInterrupt
        real(self, k, state)

    monkeypatch.setattr(SeriesWriter, "callback", stop_at_step_12)
    b = tmp_path / "b"
    assert cli.main(["run", str(scene), "--out", str(b), "-q"]) == 130
    err = capsys.readouterr().err
    assert "interrupted" in err and f"fem-elastic run --resume {b}" in err
    assert json.loads((b / where / "summary.json").read_text())["status"] == "interrupted"
    monkeypatch.setattr(SeriesWriter, "callback", real)
    assert cli.main(["run", "--resume", str(b)]) == 0
    stdout = capsys.readouterr().out
    assert f"{where}: resumed from its checkpoint at step 12" in stdout
    assert_same_output(tmp_path / "a", b)
    assert json.loads((b / "summary.json").read_text())["status"] == "completed"


def test_a_crash_resumes_from_the_last_periodic_checkpoint(tmp_path, monkeypatch, capsys):
    """Frames written after the last checkpoint are dropped and written again, identically."""
    scene = _scene(tmp_path, **{"every = 2": "every = 1\ncheckpoint_every = 5"})
    assert cli.main(["run", str(scene), "--out", str(tmp_path / "a"), "-q", "--variant", "fem"]) == 0
    real = SeriesWriter.callback

    def power_cut(self, k, state):
        real(self, k, state)
        if k == 13:
            raise SystemExit("power cut")  # nothing is cleaned up: no summary, no new checkpoint

    monkeypatch.setattr(SeriesWriter, "callback", power_cut)
    b = tmp_path / "b"
    with pytest.raises(SystemExit):
        cli.main(["run", str(scene), "--out", str(b), "-q", "--variant", "fem"])
    assert len(list((b / "fem" / "frames").glob("*.vtu"))) == 15  # frames 0..14 on disk
    monkeypatch.setattr(SeriesWriter, "callback", real)
    assert cli.main(["run", "--resume", str(b), "-q"]) == 0
    assert json.loads((b / "fem" / "summary.json").read_text())["resumed_from_step"] == 10
    assert_same_output(tmp_path / "a", b, variants=("fem",))
    assert not (b / "springs").exists()  # the variants the run was started with, no more


def test_kill_9_then_resume(tmp_path):
    """A process killed outright (no handler runs) resumes from its periodic checkpoint."""
    scene = _scene(tmp_path, **{"duration = 0.2": "duration = 1.5", "every = 2": "every = 3\ncheckpoint_every = 4"})
    a, b = tmp_path / "a", tmp_path / "b"
    proc = subprocess.Popen(
        [sys.executable, "-m", "fem_elastic.app.cli", "run", str(scene), "--out", str(b), "--quiet",
         "--variant", "fem"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    ck = b / "fem" / "checkpoint" / "checkpoint.npz"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not ck.exists() and proc.poll() is None:
        time.sleep(0.05)
    time.sleep(0.3)  # let it run past the first checkpoint
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=60)
    assert ck.exists(), "no checkpoint was written before the kill"
    summary = b / "fem" / "summary.json"
    killed_early = not summary.exists()
    r = run("run", "--resume", b, "--quiet")
    assert r.returncode == 0, r.stderr
    r = run("run", scene, "--out", a, "--quiet", "--variant", "fem")
    assert r.returncode == 0, r.stderr
    assert_same_output(a, b, variants=("fem",))
    if killed_early:  # the usual case: the kill landed mid-run
        assert json.loads(summary.read_text()).get("resumed_from_step", 0) > 0


def test_resume_usage_errors(tmp_path, capsys):
    scene = _scene(tmp_path)
    assert cli.main(["run", "--resume", str(tmp_path)]) == 2
    assert "not the output directory of `fem-elastic run`" in capsys.readouterr().err
    assert cli.main(["run", str(scene), "--resume", str(tmp_path)]) == 2
    assert "give it alone" in capsys.readouterr().err
    assert cli.main(["run", str(scene)]) == 2
    assert "--out DIR" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["run", str(scene), "--out", str(tmp_path / "x"), "--checkpoint-every", "-3"])
    assert exit_info.value.code == 2
    r = run("run", "--resume", tmp_path / "missing")
    clean_error(r, "not the output directory")


def test_checkpoint_every_from_the_command_line(tmp_path):
    scene = _scene(tmp_path)
    out = tmp_path / "o"
    assert cli.main(["run", str(scene), "--out", str(out), "-q", "--checkpoint-every", "7",
                     "--no-render"]) == 0
    record = json.loads((out / "run.json").read_text())
    assert record["checkpoint_every"] == 7 and record["render"] is False
    assert (out / "scene.toml").read_text() == scene.read_text()
    from fem_elastic import load_checkpoint

    ck = load_checkpoint(out / "fem" / "checkpoint")
    assert ck.complete and ck.step == 20


def test_resume_after_frames_were_removed_keeps_the_rest(tmp_path, monkeypatch, caplog):
    """A frame deleted by hand is left out of the series, with one warning, and numbering goes on."""
    scene = _scene(tmp_path)
    out = tmp_path / "o"
    real = SeriesWriter.callback

    def stop_at_step_12(self, k, state):
        if k == 12:
            raise KeyboardInterrupt
        real(self, k, state)

    monkeypatch.setattr(SeriesWriter, "callback", stop_at_step_12)
    assert cli.main(["run", str(scene), "--out", str(out), "-q", "--variant", "fem"]) == 130
    monkeypatch.setattr(SeriesWriter, "callback", real)
    (out / "fem" / "frames" / "frame_000003.vtu").unlink()
    (out / "fem" / "frames" / "frame_000004.vtu").unlink()
    with caplog.at_level("WARNING"):
        assert cli.main(["run", "--resume", str(out), "-q"]) == 0
    warned = [r for r in caplog.records if "frames are missing" in r.getMessage()]
    assert len(warned) == 1 and "2 of the checkpoint's 7 frames" in warned[0].getMessage()
    series = read_series(out / "fem")
    assert series.times.size == 9 and series.files[-1].name == "frame_000010.vtu"


def test_resuming_a_finished_run_leaves_its_files_alone(tmp_path):
    scene = _scene(tmp_path)
    out = tmp_path / "o"
    assert cli.main(["run", str(scene), "--out", str(out), "-q", "--variant", "fem"]) == 0
    files = {p: p.stat().st_mtime_ns for p in (out / "fem").rglob("*") if p.is_file()}
    assert cli.main(["run", "--resume", str(out), "-q"]) == 0
    assert {p: p.stat().st_mtime_ns for p in (out / "fem").rglob("*") if p.is_file()} == files


def test_the_fingerprint_is_the_same_in_another_process():
    """Nothing process-specific (an address in a repr) may enter it: a resume would be refused."""
    code = (
        "import json, fem_elastic as fe\n"
        "from fem_elastic.dynamics.checkpoint import run_fingerprint\n"
        "m = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1000.0, body=fe.MassSpring(E=1e5, nu=0.25),\n"
        "             fixed='left', ground=fe.Ground(z=-1.0), damping=fe.Rayleigh(0.1, 0.0),\n"
        "             driven={'right': fe.Twist(0.5, duration=0.1)})\n"
        "i = fe.ImplicitEuler(linear_solver=fe.AMGSolver(rtol=1e-6))\n"
        "print(json.dumps(run_fingerprint(m, i, 0.01, 5, 1, fe.State.rest(m), 1.0)))\n"
    )
    prints = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
              for _ in range(2)]
    assert prints[0] == prints[1]
    assert "0x7f" not in prints[0] and "van_gelder_stiffness" in prints[0]
