"""Output directories are safe: one run at a time, never over a user's files, never over inputs.

The lock is tried with real processes (a holder that runs, one killed with
SIGKILL, one stopped by Ctrl-C); the directory and render-target checks
through the command in process (``cli.main``) and the library function.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import fem_elastic as fe
from fem_elastic.app import cli
from fem_elastic.app.run_lock import (
    LOCK_NAME, RunLock, check_output_dir, check_render_target, foreign_entries, remove_stale_variants,
)
from small_scene import small_scene

ROOT = Path(__file__).resolve().parent.parent

SCENE = small_scene("lock", E="1e6")

#: a process that takes the lock on argv[1] with RunLock, says so, and holds it until killed or
#: interrupted (Ctrl-C: the `with` block releases it on the way out)
HOLDER = textwrap.dedent("""
    import signal, sys, time
    # Ctrl-C raises KeyboardInterrupt as in a terminal, also when the test run itself was started
    # in the background by a non-interactive shell (which leaves SIGINT ignored for children)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    from fem_elastic.app.run_lock import RunLock
    with RunLock(sys.argv[1]):
        try:  # "locked" is said inside the try: a Ctrl-C right after it is still caught here
            print("locked", flush=True)
            time.sleep(60)
        except KeyboardInterrupt:
            sys.exit(130)
""")
#: the same lock taken by the protocol alone (flock on the lock file, pid in it): starts in
#: milliseconds, without importing the package
RAW_HOLDER = textwrap.dedent(f"""
    import fcntl, os, sys, time
    fd = os.open(os.path.join(sys.argv[1], {LOCK_NAME!r}), os.O_RDWR | os.O_CREAT, 0o644)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    os.ftruncate(fd, 0)
    os.write(fd, (str(os.getpid()) + "\\n").encode())
    print("locked", flush=True)
    time.sleep(60)
""")


def _holder(directory, script=RAW_HOLDER):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen([sys.executable, "-c", script, str(directory)], stdout=subprocess.PIPE,
                         text=True, env=env)
    assert p.stdout.readline().strip() == "locked"
    return p


def _scene(tmp_path) -> Path:
    path = tmp_path / "scene.toml"
    path.write_text(SCENE, encoding="utf-8")
    return path


def test_a_second_run_on_a_locked_directory_fails_at_once_naming_the_holder(tmp_path):
    holder = _holder(tmp_path)
    try:
        t0 = time.perf_counter()
        with pytest.raises(fe.OutputInUse, match=f"process {holder.pid}") as err:
            RunLock(tmp_path).acquire()
        assert time.perf_counter() - t0 < 1.0  # at once: LOCK_NB, no waiting on the holder
        assert err.value.pid == holder.pid
        assert "another --out" in str(err.value)
        # the command says the same in one line, exit 2
        out = tmp_path / "out"
        out.mkdir()
        holder2 = _holder(out)
        try:
            assert cli.main(["run", str(_scene(tmp_path)), "--out", str(out), "--quiet"]) == 2
        finally:
            holder2.kill()
            holder2.wait()
    finally:
        holder.kill()
        holder.wait()


def test_the_lock_of_a_killed_process_is_taken_over(tmp_path):
    holder = _holder(tmp_path)
    holder.send_signal(signal.SIGKILL)  # no clean-up at all: the kernel drops the flock
    holder.wait()
    assert (tmp_path / LOCK_NAME).read_text().strip() == str(holder.pid)  # its pid is still there
    with RunLock(tmp_path) as lock:
        assert lock.held
        assert (tmp_path / LOCK_NAME).read_text().strip() == str(os.getpid())
    assert (tmp_path / LOCK_NAME).read_text() == ""  # released: emptied


def test_ctrl_c_releases_the_lock(tmp_path):
    holder = _holder(tmp_path, HOLDER)
    holder.send_signal(signal.SIGINT)
    assert holder.wait(timeout=10) == 130
    with RunLock(tmp_path) as lock:
        assert lock.held


def test_a_run_releases_its_lock_and_the_next_run_reuses_the_directory(tmp_path):
    scene, out = _scene(tmp_path), tmp_path / "out"
    assert cli.main(["run", str(scene), "--out", str(out), "--quiet", "--no-render"]) == 0
    assert (out / LOCK_NAME).read_text() == ""
    assert cli.main(["run", str(scene), "--out", str(out), "--quiet", "--no-render"]) == 0  # its own files


@pytest.mark.parametrize("out", ["", "   "])
def test_an_empty_out_is_refused(out, tmp_path, capsys):
    assert cli.main(["run", str(_scene(tmp_path)), "--out", out, "--quiet"]) == 2
    assert "--out \"\"" in capsys.readouterr().err
    with pytest.raises(fe.InvalidParameter, match="is empty"):
        check_output_dir(out)


def test_a_directory_with_files_the_run_did_not_write_is_refused_unless_overwrite(tmp_path, capsys):
    scene = _scene(tmp_path)  # the user's scene lives in tmp_path: a run must not write there
    (tmp_path / "notes").mkdir()
    assert cli.main(["run", str(scene), "--out", str(tmp_path), "--quiet", "--no-render"]) == 2
    err = capsys.readouterr().err
    assert "did not write" in err and "notes" in err and "scene.toml" in err and "--overwrite" in err
    assert not (tmp_path / "fem").exists()  # nothing written
    before = scene.read_text()
    assert cli.main(["run", str(scene), "--out", str(tmp_path), "--quiet", "--no-render", "--overwrite"]) == 0
    assert (tmp_path / "fem" / "series.pvd").is_file()
    assert (tmp_path / "notes").is_dir()  # left alone
    # the run's scene copy is scene.toml: with --overwrite it replaces a file of that name; the
    # user's scene had that name and the same text, so nothing is lost here, but it shows why
    # the check exists
    assert (tmp_path / "scene.toml").read_text() == before


def test_stale_variant_folders_are_removed_and_foreign_folders_kept(tmp_path):
    scene, out = _scene(tmp_path), tmp_path / "out"
    assert cli.main(["run", str(scene), "--out", str(out), "--quiet", "--no-render"]) == 0
    # an earlier run of another scene left variant "old"
    (out / "old" / "frames").mkdir(parents=True)
    (out / "old" / "series.pvd").write_text("<VTKFile/>")
    assert foreign_entries(out) == []  # it looks like a run's
    assert remove_stale_variants(out, ["fem"]) == ["old"]
    assert not (out / "old").exists()
    (out / "mine").mkdir()
    (out / "mine" / "data.csv").write_text("1,2\n")
    assert remove_stale_variants(out, ["fem"]) == []  # not a run directory: never removed
    assert foreign_entries(out) == ["mine"]
    # and the command removes a stale one by itself
    (out / "old").mkdir()
    (out / "old" / "summary.json").write_text("{}")
    assert cli.main(["run", str(scene), "--out", str(out), "--quiet", "--no-render", "--overwrite"]) == 0
    assert not (out / "old").exists() and (out / "mine" / "data.csv").is_file()


def test_render_never_writes_over_its_inputs_and_checks_the_extension(tmp_path, capsys):
    scene, out = _scene(tmp_path), tmp_path / "out"
    assert cli.main(["run", str(scene), "--out", str(out), "--quiet", "--no-render"]) == 0
    run_dirs = [out / "fem"]
    pvd = out / "fem" / "series.pvd"
    text = pvd.read_text()
    for target, fmt, phrase in [
        (pvd, "mp4", "does not end in .mp4"),
        (out / "fem" / "frames" / "frame_0000.vtu", "gif", "does not end in .gif"),
        (out / "scene.toml", "png", "looks like a file"),
        (out / "fem", "png", "files of the runs"),
        (out / "fem" / "frames", "png", "files of the runs"),
        (out / "movie.gif", "mp4", "name the file movie.mp4"),
        (out / "fem" / "summary.json.mp4", "mp4", None),  # a new name beside the inputs: fine
    ]:
        if phrase is None:
            assert check_render_target(target, fmt, run_dirs) == target
            continue
        with pytest.raises(fe.InvalidParameter, match=phrase.replace(".", r"\.").replace("files of", "file of")):
            check_render_target(target, fmt, run_dirs)
    # a run file renamed to look like a movie is still an input
    fake = out / "fem" / "frames" / "x.mp4"
    fake.write_text("not a movie")
    with pytest.raises(fe.InvalidParameter, match="never writes over its inputs"):
        check_render_target(fake, "mp4", run_dirs)
    # the command: exit 2, one line, the input untouched
    assert cli.main(["render", str(out), "--format", "mp4", "-o", str(pvd), "--quiet"]) == 2
    assert "does not end in .mp4" in capsys.readouterr().err
    assert pvd.read_text() == text


def test_rendering_a_run_directory_again_replaces_its_own_render(tmp_path):
    run = tmp_path / "fem"
    (run / "frames").mkdir(parents=True)
    (run / "series.pvd").write_text("<VTKFile/>")
    (run / "movie.mp4").write_bytes(b"an earlier render")
    (run / "png").mkdir()
    (run / "checkpoint").mkdir()
    assert check_render_target(run / "movie.mp4", "mp4", [run]) == run / "movie.mp4"
    assert check_render_target(run / "png", "png", [run]) == run / "png"
    with pytest.raises(fe.InvalidParameter, match="never writes over its inputs"):
        check_render_target(run / "checkpoint" / "pictures", "png", [run / ".." / "fem"])


@pytest.mark.parametrize("stop", [False, True])
def test_the_scene_summary_is_written_while_the_lock_is_held(stop, tmp_path, monkeypatch):
    import json

    from fem_elastic.app import output, runner

    out = tmp_path / "out"
    written = {}
    write = output.write_summary

    def spy(path, summary):  # is the directory still locked? another RunLock on it must fail
        try:
            with RunLock(out):
                held = False
        except fe.OutputInUse:
            held = True
        written[Path(path).relative_to(out).as_posix()] = held
        return write(path, summary)

    monkeypatch.setattr(output, "write_summary", spy)
    if stop:  # Ctrl-C while setting up the variant's series
        monkeypatch.setattr(runner, "run_variant", lambda *a, **k: (_ for _ in ()).throw(KeyboardInterrupt))
        with pytest.raises(runner.SceneInterrupted):
            runner.run_scene(fe.load_scene(_scene(tmp_path)), out)
    else:
        runner.run_scene(fe.load_scene(_scene(tmp_path)), out)
    assert written["summary.json"] is True, written
    assert all(written.values()), written
    status = json.loads((out / "summary.json").read_text())["status"]
    assert status == ("interrupted" if stop else "completed")
