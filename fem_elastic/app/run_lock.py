"""Output directories that are safe to write: one run at a time, and never over a user's files.

A scene run (``fem-elastic run``, ``fem-elastic demo``, :func:`fe.run_scene`) writes into
an output directory ``OUT`` that it owns for the time it runs:

- :class:`RunLock` takes an exclusive ``fcntl.flock`` on ``OUT/.fem-elastic.lock``
  (the file holds the holder's pid). A second run on the same directory fails
  at once with :class:`fe.OutputInUse`, which names that pid. The kernel drops
  the lock when the holder exits, however it exits (Ctrl-C, ``kill -9``), so a
  lock file left by a dead process is simply taken over.
- :func:`check_output_dir` refuses ``--out ""`` and a directory that holds
  files a run did not write (a user's scene, a folder of other work) unless
  ``overwrite`` is given, and :func:`remove_stale_variants` clears the run
  directories of variants the scene no longer has, so a reused output
  directory never mixes two runs.
- :func:`check_render_target` keeps ``fem-elastic render -o`` from writing
  over its inputs (any file of the runs it draws) and checks that the
  target's extension matches the format.
"""

from __future__ import annotations

import errno
import logging
import os
import shutil
from pathlib import Path

from ..errors import InvalidParameter, OutputInUse

log = logging.getLogger(__name__)

__all__ = ["LOCK_NAME", "RunLock", "check_output_dir", "remove_stale_variants", "check_render_target",
           "RUN_FILES"]

#: The lock file of an output directory.
LOCK_NAME = ".fem-elastic.lock"
#: What a run writes at the top of its output directory (besides one directory per variant).
RUN_FILES = frozenset({"scene.toml", "run.json", "summary.json", "movie.mp4", "movie.gif", "png", LOCK_NAME})
#: What a run writes in a variant's run directory.
RUN_DIR_FILES = frozenset({"series.pvd", "summary.json", "frames", "checkpoint"})


def _pid_alive(pid: int) -> bool:
    """True when a process ``pid`` exists (signal 0 probes without sending anything)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    except OSError:
        return False
    return True


def _read_pid(path: Path) -> int | None:
    try:
        text = path.read_text(encoding="ascii", errors="replace").strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


class RunLock:
    """An exclusive lock on an output directory, held while a run writes into it.

    Parameters
    ----------
    directory : path-like
        The output directory (it must exist).

    Examples
    --------
    >>> import tempfile
    >>> from fem_elastic.app.run_lock import RunLock
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     with RunLock(tmp) as lock:
    ...         held = lock.held
    >>> held
    True
    """

    def __init__(self, directory):
        self.directory = Path(directory)
        self.path = self.directory / LOCK_NAME
        self._fd = None

    @property
    def held(self) -> bool:
        """Whether this object holds the lock now."""
        return self._fd is not None

    def acquire(self) -> "RunLock":
        """Take the lock, or raise :class:`fe.OutputInUse` at once if another process holds it.

        Raises
        ------
        OutputInUse
            Another run writes into the directory; ``error.pid`` is its process id.
        """
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not POSIX: no advisory locks to take
            log.warning("no fcntl on this platform: %s is not locked against a second run", self.directory)
            return self
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                # a file system without flock (some network mounts): run unlocked, say so
                log.warning("cannot lock %s (%s): a second run on it is not prevented", self.path, exc)
                return self
            pid = _read_pid(self.path)
            holder = f"process {pid}" if pid is not None else "another process"
            raise OutputInUse(
                f"the output directory {self.directory} is in use by {holder} (it holds {self.path}); "
                "wait for that run to finish (or stop it), or give another --out directory.",
                pid=pid,
            ) from None
        previous = _read_pid(self.path)
        if previous is not None and previous != os.getpid() and not _pid_alive(previous):
            log.info("taking over the lock of %s left by process %d, which no longer runs",
                     self.directory, previous)
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode("ascii"))
        self._fd = fd
        return self

    def release(self) -> None:
        """Drop the lock (the file stays, empty: removing it would race with a new holder)."""
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        try:
            os.ftruncate(fd, 0)
        except OSError:
            pass
        os.close(fd)  # closing the descriptor drops the flock

    def __enter__(self) -> "RunLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


def _is_temporary(name: str) -> bool:
    """A temporary file of :mod:`fem_elastic.files` (``.NAME.XXXX.tmp``) that a kill left."""
    return name.startswith(".") and name.endswith(".tmp")


def _is_run_dir(path: Path) -> bool:
    """A directory that holds only what a variant's run writes (and at least one of those)."""
    try:
        names = {p.name for p in path.iterdir()}
    except OSError:
        return False
    names = {n for n in names if not _is_temporary(n) and n != LOCK_NAME}  # a saved result's lock
    # only a run's names, and a file that only a run writes (a bare "frames" folder may be anyone's)
    return names <= RUN_DIR_FILES and bool(names & {"series.pvd", "summary.json", "checkpoint"})


def foreign_entries(directory: Path) -> list[str]:
    """The entries of ``directory`` that no scene run writes (sorted names).

    Without a run record (``run.json``) the directory is not a run's at all:
    everything in it but the lock file is someone else's (a ``scene.toml``
    there is the user's scene, not a run's copy).
    """
    directory = Path(directory)
    ours = RUN_FILES if (directory / "run.json").is_file() else {LOCK_NAME}
    foreign = []
    for p in sorted(directory.iterdir()):
        name = p.name
        if name in ours or _is_temporary(name):
            continue
        if p.is_dir() and not p.is_symlink() and _is_run_dir(p):
            continue
        foreign.append(name)
    return foreign


def check_output_dir(out_dir, *, overwrite: bool = False, option: str = "--overwrite") -> Path:
    """Refuse an output directory a run must not write into, before anything is written.

    Parameters
    ----------
    out_dir : str or path-like
        The ``--out`` directory. It may not exist yet.
    overwrite : bool
        Write into a directory that holds other files all the same (they are
        left as they are; files with a run's names are replaced).
    option : str
        How the caller spells ``overwrite``, for the message (``"--overwrite"`` on the
        command line, ``"overwrite=True"`` for ``result.save``).

    Returns
    -------
    pathlib.Path

    Raises
    ------
    InvalidParameter
        ``out_dir`` is empty, is a file, or (without ``overwrite``) holds files
        a run did not write; the message lists a few of them.
    """
    if out_dir is None or not str(out_dir).strip():
        raise InvalidParameter(
            "the output directory is empty (--out \"\"): give a directory for the run's output, "
            "e.g. --out results/run1 (use --out . --overwrite to write into the current directory)."
        )
    path = Path(out_dir)
    if path.exists() and not path.is_dir():
        raise InvalidParameter(f"--out {path} is a file; give a directory for the run's output.")
    if overwrite or not path.is_dir():
        return path
    foreign = foreign_entries(path)
    if foreign:
        shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise InvalidParameter(
            f"the output directory {path} holds files that a run did not write ({shown}); a run "
            f"would mix its output with them. Give a new or empty directory, or {option} to write "
            "there all the same (those files are left alone; files with a run's names are replaced)."
        )
    return path


def remove_stale_variants(out_dir, keep) -> list[str]:
    """Remove the run directories of variants not in ``keep`` (from an earlier run of another scene).

    Only in an output directory of an earlier run (it has ``run.json``), and
    only directories that hold nothing but what a run writes, are removed.

    Parameters
    ----------
    out_dir : path-like
    keep : iterable of str
        The variant names of the scene now run.

    Returns
    -------
    list of str
        The names removed.
    """
    keep = set(keep)
    removed: list[str] = []
    if not (Path(out_dir) / "run.json").is_file():  # not a run's directory: nothing there is stale
        return removed
    for p in sorted(Path(out_dir).iterdir()):
        if p.name in keep or p.name in RUN_FILES or p.is_symlink() or not p.is_dir():
            continue
        if _is_run_dir(p):
            shutil.rmtree(p)
            removed.append(p.name)
    if removed:
        log.info("removed the run directories of variants the scene does not have: %s", ", ".join(removed))
    return removed


def _run_inputs(run_dirs) -> set[Path]:
    """Every file and directory of the runs (resolved paths): what a render reads, what a run wrote.

    Renders written before (``movie.mp4``, ``png/``) are not inputs: rendering again replaces them.
    """
    inputs = set()
    for d in run_dirs:
        d = Path(d).resolve()
        inputs.add(d)
        for name in RUN_DIR_FILES:
            p = d / name
            inputs.add(p)
            if p.is_dir():
                inputs.update(q.resolve() for q in p.rglob("*"))
        for name in ("scene.toml", "run.json", "summary.json"):  # the output directory's own
            inputs.add((d.parent / name).resolve())
    return inputs


def check_render_target(target, format: str, run_dirs) -> Path:
    """Check a render's target: an extension that matches ``format``, and none of the runs' files.

    Parameters
    ----------
    target : path-like
        The movie file (mp4, gif) or frame directory (png).
    format : {"mp4", "gif", "png"}
    run_dirs : sequence of path-like
        The run directories drawn.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    InvalidParameter
        The extension does not match, or the target is (or is inside, for
        png) a file or directory of the runs.
    """
    target = Path(target)
    if not str(target).strip() or target.name in ("", ".", ".."):
        raise InvalidParameter(f"the render target {str(target)!r} is not a file name; give e.g. -o movie.{format}.")
    suffix = target.suffix.lower()
    if format in ("mp4", "gif") and suffix != f".{format}":
        raise InvalidParameter(
            f"-o {target} does not end in .{format}, the format asked for (--format {format}); "
            f"name the file {target.with_suffix('.' + format).name}, or give the format that "
            "matches the name."
        )
    if format == "png" and suffix in (".mp4", ".gif", ".png", ".vtu", ".pvd", ".json", ".toml"):
        raise InvalidParameter(
            f"-o {target} looks like a file, but --format png writes a directory of frames; give a "
            "directory, e.g. -o frames_png."
        )
    resolved = target.resolve()
    inputs = _run_inputs(run_dirs)
    inside = [p for p in resolved.parents if p in inputs and p.name in ("frames", "checkpoint")]
    if resolved in inputs or inside:
        example = "frames_png" if format == "png" else f"movie.{format}"
        raise InvalidParameter(
            f"-o {target} is a file of the runs being rendered (or inside their frames); a render never "
            f"writes over its inputs. Give a path outside the run directories, e.g. -o {example}."
        )
    return target
