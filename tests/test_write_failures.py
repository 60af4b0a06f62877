"""Writers check what they wrote: a failed write is a typed error, and nothing truncated is left.

A full disk is a file size limit (``RLIMIT_FSIZE``, with SIGXFSZ ignored so
that a write past it fails with EFBIG as on a full disk) set in a real
subprocess running the command; ffmpeg failing (while writing, or at its
trailer) is a stand-in writer that raises where imageio-ffmpeg raises.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.files import _atomic_write, write_text_atomic
from small_scene import small_scene

ROOT = Path(__file__).resolve().parent.parent

resource = pytest.importorskip("resource", reason="RLIMIT_FSIZE needs the POSIX resource module")

SCENE = small_scene("full", integrator="symplectic_euler", dt=0.001, duration=0.004, cells=(6, 2, 2))

#: the command, in a process whose files may not grow past argv[1] bytes
LIMITED = textwrap.dedent("""
    import resource, signal, sys
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of a kill, as a full disk gives ENOSPC
    limit = int(sys.argv[1])
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
    from fem_elastic.app.cli import main
    sys.exit(main(sys.argv[2:]))
""")


def _limited(limit, *args):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-c", LIMITED, str(limit), *map(str, args)], capture_output=True,
                          text=True, env=env, timeout=300)


@pytest.mark.parametrize("limit", [5_000])  # frames 0-2 (3.5-4.6 kB) fit, the fourth (6.2 kB) does not
def test_a_full_disk_ends_the_run_with_a_typed_error_and_no_truncated_file(tmp_path, limit):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE, encoding="utf-8")
    out = tmp_path / "out"
    r = _limited(limit, "run", scene, "--out", out, "--quiet", "--no-render")
    assert r.returncode == 1, r.stderr
    assert "Traceback" not in r.stderr
    assert "cannot write" in r.stderr and "File too large" in r.stderr and "ulimit -f" in r.stderr
    # every file under a final name is whole: the VTU frames parse, the JSON files load
    import json

    import meshio

    for p in out.rglob("*"):
        if p.is_file():
            assert not p.name.endswith(".tmp"), p  # temporary files are removed
            if p.suffix == ".vtu":
                meshio.read(p)
            elif p.suffix == ".json":
                json.loads(p.read_text())
            assert p.stat().st_size < limit or p.suffix == ".f64", p


def test_atomic_write_turns_an_os_error_into_write_failed_and_keeps_the_old_file(tmp_path):
    path = tmp_path / "a.txt"
    write_text_atomic(path, "old")

    def fails(tmp):
        with open(tmp, "w") as fh:
            fh.write("half")
        raise OSError(28, "No space left on device")

    with pytest.raises(fe.WriteFailed, match="cannot write .*a.txt: No space left on device; nothing was "
                                             "left under that name .free some space") as err:
        _atomic_write(path, fails)
    assert isinstance(err.value, OSError) and err.value.path == str(path)
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]


class _FakeWriter:
    """imageio-ffmpeg's write_frames generator, failing where it fails: at ``send`` or ``close``."""

    def __init__(self, path, fail_at):
        self.path, self.fail_at = path, fail_at

    def send(self, frame):
        with open(self.path, "ab") as fh:
            fh.write(b"x" * 10)
        if frame is not None and self.fail_at == "send":
            raise OSError(32, "[Errno 32] Broken pipe\n\nFFMPEG STDERR OUTPUT: No space left on device")

    def close(self):
        if self.fail_at == "close":
            raise RuntimeError("ffmpeg returned with code 1: error writing trailer")


class _FakeScene:
    n_frames = 3

    class plotter:  # noqa: N801 - the attribute the renderer reads
        window_size = (16, 16)

    def draw(self, k):
        return np.zeros((16, 16, 3), dtype=np.uint8)


@pytest.mark.parametrize("fail_at", ["send", "close", "empty"])
def test_an_ffmpeg_failure_is_a_typed_error_and_leaves_no_movie(tmp_path, monkeypatch, fail_at):
    from fem_elastic.app import render

    class FakeFFmpeg:
        @staticmethod
        def write_frames(path, size, **kw):
            if fail_at == "empty":
                class Nothing:
                    def send(self, frame):
                        pass

                    def close(self):
                        pass

                return Nothing()
            return _FakeWriter(path, fail_at)

    monkeypatch.setattr(render, "_require", lambda name: FakeFFmpeg)
    out = tmp_path / "movie.mp4"
    with pytest.raises(fe.WriteFailed, match="cannot write .*movie.mp4"):
        render._render_mp4(_FakeScene(), out, 30, None)
    assert list(tmp_path.iterdir()) == []  # neither the movie nor its temporary file


def test_a_checkpoint_append_that_fails_is_a_typed_error(tmp_path, monkeypatch):
    from fem_elastic.dynamics.checkpoint import Checkpointer

    d = tmp_path / "ck"
    d.mkdir()
    (d / "frames.f64").mkdir()  # a directory where the file goes: open() fails with IsADirectoryError
    with pytest.raises(fe.WriteFailed, match="frames.f64"):
        Checkpointer._append_bytes(d / "frames.f64", 0, b"12345678")
