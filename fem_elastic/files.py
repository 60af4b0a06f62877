"""Files written atomically: a crash or Ctrl-C leaves the old file or the new one, never half.

Every file the package writes (meshes, VTU frames, summaries, checkpoints,
study results) goes through :func:`_atomic_write`: a temporary file in the
same directory, flushed and fsync'ed, then ``os.replace`` over the final
name, then the directory fsync'ed so the rename is durable. A write that
fails (a full disk, a size limit) is a :class:`fe.WriteFailed` naming the
file, and leaves nothing under the final name. A foundation module beside
:mod:`fem_elastic.errors`: it imports nothing else of the package.
"""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path
from typing import Any

from .errors import WriteFailed

__all__ = ["write_text_atomic"]


def _new_file_mode(path: Path) -> int:
    """Mode a plain ``open(path, "w")`` would give: the old file's, else 0666 & ~umask."""
    if path.exists():
        return path.stat().st_mode & 0o777
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask



def _fsync_directory(directory: Path) -> None:
    """Make a rename in ``directory`` durable (POSIX; a no-op where unsupported)."""
    try:
        fd = os.open(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _atomic_write(path: Path, write) -> Path:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then move it over ``path``.

    The temporary file is fsync'ed before ``os.replace`` so that the rename
    never exposes a file whose bytes are not on disk yet; on any error
    (KeyboardInterrupt included) it is removed and ``path`` is left as it was.
    An :class:`OSError` while writing (a full disk, a file size limit, an I/O
    error) becomes :class:`fem_elastic.errors.WriteFailed`, which names the file.
    """
    path = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except FileNotFoundError:  # no such directory: the caller's path, as it was
        raise
    except OSError as exc:
        raise write_failed(path, exc) from exc
    try:  # from here on the temporary file is removed whatever stops the write (Ctrl-C too)
        os.close(fd)
        write(tmp)
        with open(tmp, "rb+") as fh:
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, _new_file_mode(path))  # mkstemp makes it owner-only (0600)
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, WriteFailed):
            raise
        raise write_failed(path, exc) from exc
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    _fsync_directory(path.parent)
    return path


def write_failed(path, exc: BaseException) -> WriteFailed:
    """The :class:`WriteFailed` for ``path`` after ``exc``: what happened, and what to do."""
    reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    code: Any = getattr(exc, "errno", None)  # an int, or None for an error without errno
    advice = {errno.ENOSPC: "free some space on that disk or write elsewhere",
              errno.EFBIG: "the file is larger than this process may write (ulimit -f): raise the limit "
                           "or write less (fewer frames)",
              errno.EDQUOT: "your disk quota is used up: free some space or write elsewhere",
              errno.EACCES: "check the directory's permissions", errno.EROFS: "write to another directory",
              }.get(code, "check the disk and the path")
    return WriteFailed(f"cannot write {path}: {reason}; nothing was left under that name ({advice}).",
                       path=path)


def write_text_atomic(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Destination; its directory must exist.
    text : str

    Returns
    -------
    pathlib.Path
        ``path``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from fem_elastic.files import write_text_atomic
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     print(write_text_atomic(pathlib.Path(tmp) / "a.txt", "hi").read_text())
    hi
    """

    def write(tmp):
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)

    return _atomic_write(Path(path), write)
