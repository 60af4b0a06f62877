"""Running a sweep of independent cases in parallel, keeping every result as it finishes.

A study is a list of :class:`Case` (an ``id`` and JSON-able ``params``) and one
module-level function ``fn(params) -> row``. :func:`run_sweep` runs ``fn`` on
every case through an executor and appends each row to ``out_dir/results.jsonl``
the moment it comes back (one JSON object per line, flushed and fsync'ed). So:

- an interrupted study (Ctrl-C, a killed job, a crashed node) keeps every case
  that finished, and running it again skips them (resume, by ``id``; a case
  whose params changed since its row was written runs again, and its new row
  supersedes the old one);
- a case whose ``fn`` raises is a row with ``status = "error"`` and the error's
  type and message, not the end of the sweep; a resume runs it again (the
  error may have been a bug since fixed), and its new row supersedes the old;
- every row carries ``id``, the case's params, ``status`` and ``seconds`` (the
  wall time of ``fn``, measured where it ran).

Executors
---------
``executor=None`` or ``"process"``
    a :class:`concurrent.futures.ProcessPoolExecutor` with ``workers`` processes
    (default ``os.cpu_count()``), each limited to one BLAS / OpenMP / numba thread
    so that parallel runs do not oversubscribe the cores (and their wall times
    stay comparable with a serial run's); a worker ends itself when the process
    that started it dies (``kill -9``), so a killed study leaves no idle workers.
``"serial"``
    every case in this process, in order (debugging, tests, profiles).
a :class:`concurrent.futures.Executor`
    used as it is (a thread pool, an MPI pool, ...); the caller owns it.
a ``dask.distributed.Client``
    each case is a task on the cluster; rows come back in completion order
    through ``distributed.as_completed``. Start the workers with one thread each
    (``dask worker tcp://scheduler:8786 --nthreads 1``) for timings comparable
    with a local run; each task also limits BLAS to one thread (threadpoolctl)::

        from dask.distributed import Client
        import fem_elastic.study as study

        client = Client("tcp://scheduler:8786")   # or Client(LocalCluster(...))
        study.run_accuracy_study("results/accuracy", executor=client)

The results file is written only by the process that calls :func:`run_sweep`,
so nothing on the workers needs the output directory.
"""

from __future__ import annotations

import concurrent.futures as cf
import json
import logging
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

from ..errors import FemElasticError, InvalidParameter

__all__ = ["Case", "SweepIncomplete", "SweepRows", "run_sweep", "read_results", "write_csv", "RESULTS_FILE"]

logger = logging.getLogger(__name__)

#: Name of the per-study file of rows, one JSON object per line, in ``out_dir``.
RESULTS_FILE = "results.jsonl"

# Environment variables read by the BLAS/OpenMP/numba thread pools when they start.
_THREAD_ENV = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "BLIS_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "NUMBA_NUM_THREADS",
)


@dataclass(frozen=True)
class Case:
    """One run of a sweep.

    Parameters
    ----------
    id : str
        Unique within the sweep and stable across runs of it: resume skips the
        ids already in ``results.jsonl``. A path-like name reads well, e.g.
        ``"static_tip/NeoHookean/P2/n8"``.
    params : dict
        JSON-able arguments of the sweep's function; they are copied into the row.

    Examples
    --------
    >>> Case("modal/P2/n4", {"order": 2, "nx": 4}).params["nx"]
    4
    """

    id: str
    params: dict


class SweepIncomplete(FemElasticError, RuntimeError):
    """Some cases did not run because the executor failed (not because ``fn`` raised).

    A worker killed by the operating system (out of memory), a lost cluster node
    or an unpicklable function leaves its cases out of ``results.jsonl``, so that
    running the sweep again runs exactly them.

    Attributes
    ----------
    failed : dict
        Case id -> ``"Type: message"`` of the executor's error.
    rows : list of dict
        The rows of the cases that did finish, in case order.
    """

    def __init__(self, message: str, failed: dict, rows: list):
        super().__init__(message)
        self.failed = failed
        self.rows = rows


class SweepRows(list):
    """The rows :func:`run_sweep` returns: a list, plus how many of them this call computed.

    Attributes
    ----------
    n_run : int
        Cases whose function ran in this call (new cases, cases whose params
        changed and cases that had ended in an error); the other rows were read
        back from ``results.jsonl``.
    """

    def __init__(self, rows=(), n_run: int = 0):
        super().__init__(rows)
        self.n_run = n_run


# --- the wrapped call (runs on the worker) -------------------------------------------------


def _limit_threads() -> None:
    """Pin BLAS, OpenMP and numba to one thread in this (worker) process.

    The environment variables reach thread pools that start later (and child
    processes); threadpoolctl and ``numba.set_num_threads`` reach those already
    loaded (a forked worker inherits the parent's BLAS).
    """
    for name in _THREAD_ENV:
        os.environ[name] = "1"
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # the [fast] extra is optional; the variables above still apply
        pass
    else:
        threadpool_limits(limits=1)
    import sys

    numba = sys.modules.get("numba")
    if numba is not None:  # only if already imported: importing it costs ~0.4 s
        try:
            numba.set_num_threads(1)
        except (ValueError, RuntimeError):  # already a single-threaded layer
            pass


#: How often (s) a pool worker checks that the process that started it is still alive.
_PARENT_POLL = 0.5


def _exit_with_parent() -> None:
    """End this (worker) process when its parent dies, e.g. a study killed with ``kill -9``.

    A process-pool worker blocks on its task queue, which it holds open itself (inherited
    by fork), so it never sees the parent go: without this, each worker of a killed study
    would live on, idle, forever. A daemon thread polls the parent's pid (re-parenting
    changes it) and exits the worker at once; the case it was running is lost, as the
    parent that would have written its row is.
    """
    import threading

    parent = os.getppid()

    def watch():
        while True:
            time.sleep(_PARENT_POLL)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="fem-elastic-parent-watch", daemon=True).start()


def _init_worker() -> None:
    """Initializer of the default process pool: one BLAS thread, and exit with the parent."""
    _limit_threads()
    _exit_with_parent()


def _error_text(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


def _run_case(fn, case: Case, limit_threads: bool = False) -> dict:
    """Call ``fn(case.params)`` and build the row: id, params, fn's row, status, seconds.

    An ``Exception`` in ``fn`` becomes ``status = "error"``; ``KeyboardInterrupt``
    and ``SystemExit`` propagate (they are the user's, not the case's).
    """
    context = None
    if limit_threads:
        try:
            from threadpoolctl import threadpool_limits

            context = threadpool_limits(limits=1)
        except ImportError:
            context = None
    t0 = time.perf_counter()
    try:
        out = fn(dict(case.params))
        if not isinstance(out, dict):
            raise TypeError(f"the sweep function returned {type(out).__name__}, expected a dict row")
        status = "ok"
    except Exception as exc:  # noqa: BLE001 - the case's failure is data, not the sweep's
        out = {"error": _error_text(exc)}
        status = "error"
        logger.debug("case %s failed", case.id, exc_info=True)
    finally:
        seconds = time.perf_counter() - t0
        if context is not None:
            context.restore_original_limits()
    row = {"id": case.id, **case.params, "status": status}
    row.update(out)
    row["seconds"] = seconds
    return row


# --- the results file ---------------------------------------------------------------------


def _json_default(value):
    """numpy scalars and arrays to Python numbers and lists."""
    item = getattr(value, "item", None)
    tolist = getattr(value, "tolist", None)
    if tolist is not None and getattr(value, "ndim", 0) > 0:
        return tolist()
    if item is not None:
        return item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON-serializable: return numbers, strings, lists or dicts")


def _dumps(row: dict) -> str:
    # allow_nan: a diverged run's error is legitimately inf or NaN; Python's json reads them back.
    return json.dumps(row, default=_json_default, allow_nan=True)


def _parse_lines(text: str, path: Path) -> tuple[list[dict], bool]:
    """Rows of a JSON-lines text; ``clean`` is False when something had to be dropped."""
    rows = []
    clean = True
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    elif lines:  # no newline at the end: the last write was cut off
        clean = False
    for k, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            clean = False
            logger.warning("%s: line %d is not valid JSON (an interrupted write?); ignored", path, k + 1)
            continue
        if isinstance(row, dict) and "id" in row:
            rows.append(row)
        else:
            clean = False
            logger.warning("%s: line %d is not a row with an id; ignored", path, k + 1)
    return rows, clean


def read_results(out_dir) -> list[dict]:
    """The rows in ``out_dir/results.jsonl``, in the order they finished.

    A last line cut off by an interrupted write (or any line that is not a JSON
    object with an ``id``) is skipped with a warning. When an id appears twice
    (a case re-run by hand), the later row wins.

    Parameters
    ----------
    out_dir : str or os.PathLike
        The sweep's output directory.

    Returns
    -------
    list of dict
        One row per case id; empty when the file does not exist.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     _ = run_sweep([Case("a", {"x": 2})], _square, tmp, executor="serial", progress=False)
    ...     [(r["id"], r["y"]) for r in read_results(tmp)]
    [('a', 4)]
    """
    path = Path(out_dir) / RESULTS_FILE
    if not path.exists():
        return []
    rows, _ = _parse_lines(path.read_text(encoding="utf-8", errors="replace"), path)
    by_id: dict[str, dict] = {}
    for row in rows:
        by_id.pop(row["id"], None)  # keep finishing order, later duplicate wins
        by_id[row["id"]] = row
    return list(by_id.values())


def _square(params: dict) -> dict:
    """A tiny sweep function for the examples: y = x^2."""
    return {"y": params["x"] ** 2}


def _repair(path: Path) -> None:
    """Drop an incomplete last line (and unreadable lines) so that appends start on a new line."""
    if not path.exists():
        return
    text = path.read_text(encoding="utf-8", errors="replace")
    rows, clean = _parse_lines(text, path)
    if clean:
        return
    from ..files import write_text_atomic

    logger.warning("%s: rewriting it with its %d complete rows", path, len(rows))
    write_text_atomic(path, "".join(_dumps(r) + "\n" for r in rows))


class _Appender:
    """Append rows to the results file, each flushed and fsync'ed before the next."""

    def __init__(self, path: Path):
        self.path = path
        self._fh = open(path, "a", encoding="utf-8")

    def write(self, row: dict) -> None:
        self._fh.write(_dumps(row) + "\n")
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        self._fh.close()


# --- CSV ----------------------------------------------------------------------------------


def _csv_cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)  # 'inf', 'nan'
    if isinstance(value, (dict, list, tuple)):
        return json.dumps(value, default=_json_default)
    return str(value)


def write_csv(rows, path) -> Path:
    """Write rows as a CSV table, atomically; the columns are the union of the rows' keys.

    Columns appear in the order their keys are first seen; a row without a key
    has an empty cell there. Floats are written with ``repr`` (round-trip exact),
    lists and dicts as JSON.

    Parameters
    ----------
    rows : iterable of dict
    path : str or os.PathLike
        The CSV file; its directory must exist.

    Returns
    -------
    pathlib.Path
        ``path``.

    Examples
    --------
    >>> import csv, tempfile, pathlib
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     p = write_csv([{"id": "a", "err": 0.5}, {"id": "b", "note": "x"}], pathlib.Path(tmp) / "t.csv")
    ...     print(p.read_text().splitlines())
    ['id,err,note', 'a,0.5,', 'b,,x']
    """
    import csv
    import io

    from ..files import write_text_atomic

    rows = list(rows)
    columns: dict[str, None] = {}
    for row in rows:
        for key in row:
            columns.setdefault(key, None)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(list(columns))
    for row in rows:
        writer.writerow([_csv_cell(row.get(key)) for key in columns])
    return write_text_atomic(Path(path), buf.getvalue())


# --- the sweep ----------------------------------------------------------------------------


def _same_params(row: dict, params: dict) -> bool:
    """Whether a stored row was computed with these params (compared as JSON, so tuples equal lists)."""
    try:
        return all(k in row and _dumps(row[k]) == _dumps(params[k]) for k in params)
    except TypeError:
        return False


def _is_dask_client(executor) -> bool:
    """Duck-typed: a dask.distributed Client has submit and gather (an Executor has no gather)."""
    if isinstance(executor, cf.Executor):
        return False
    return callable(getattr(executor, "submit", None)) and callable(getattr(executor, "gather", None))


def _progress_bar(progress: bool, total: int, initial: int, desc: str):
    if not progress:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:
        logger.info("tqdm is not installed (the [cli] extra): no progress bar")
        return None
    return tqdm(total=total, initial=initial, desc=desc or "cases", unit="case")


def run_sweep(cases, fn, out_dir, *, executor=None, workers=None, progress=True, desc="") -> SweepRows:
    """Run ``fn`` on every case not yet in ``out_dir/results.jsonl`` and append each row as it finishes.

    Parameters
    ----------
    cases : iterable of Case
        Ids must be unique.
    fn : callable
        ``fn(params: dict) -> dict``, a module-level function (it is pickled to
        the workers). Its row is merged after the case's params (it may set
        ``status``, e.g. ``"diverged"``); an exception it raises becomes a row
        with ``status = "error"`` and ``error = "Type: message"``.
    out_dir : str or os.PathLike
        Created if missing; ``results.jsonl`` is appended to.
    executor : None, "process", "serial", concurrent.futures.Executor or dask.distributed.Client
        Where the cases run (see the module docstring). ``None`` is ``"process"``.
    workers : int, optional
        Processes of the default pool (``os.cpu_count()`` if None; never more
        than the cases to run). Ignored for other executors.
    progress : bool
        Draw a tqdm bar over finished cases.
    desc : str
        The bar's label.

    Returns
    -------
    SweepRows
        A list of dict: one row per case, in the order of ``cases`` (rows from
        an earlier, interrupted run included). Every row has ``id``, the params,
        ``status`` and ``seconds`` (s, wall time of ``fn`` where it ran). Its
        ``n_run`` is how many of them this call computed.

    Raises
    ------
    InvalidParameter
        Duplicate case ids or an unknown executor.
    SweepIncomplete
        The executor lost some cases (a worker died); the rest are written, so
        calling again runs only the lost ones.
    KeyboardInterrupt
        Re-raised after cancelling the pending cases; ``results.jsonl`` holds
        every case that finished.

    Examples
    --------
    >>> import tempfile
    >>> cases = [Case(f"x{x}", {"x": x}) for x in range(3)]
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     rows = run_sweep(cases, _square, tmp, executor="serial", progress=False)
    ...     again = run_sweep(cases, _square, tmp, executor="serial", progress=False)  # resumes: runs none
    >>> [(r["id"], r["y"], r["status"]) for r in rows]
    [('x0', 0, 'ok'), ('x1', 1, 'ok'), ('x2', 4, 'ok')]
    >>> [r["seconds"] for r in again] == [r["seconds"] for r in rows], rows.n_run, again.n_run
    (True, 3, 0)
    """
    cases = list(cases)
    ids = [c.id for c in cases]
    if len(set(ids)) != len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        raise InvalidParameter(f"case ids must be unique (resume relies on them); repeated: {dup[:5]}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / RESULTS_FILE
    _repair(path)
    by_id = {c.id: c for c in cases}
    done: dict[str, dict] = {}
    changed = 0
    for row in read_results(out_dir):
        case = by_id.get(row["id"])
        if case is None:
            continue
        if not _same_params(row, case.params):
            changed += 1
        elif row.get("status") == "error":  # a bug or a lost worker: try it again
            done.pop(row["id"], None)
        else:
            done[row["id"]] = row
    pending = [c for c in cases if c.id not in done]
    if done or changed:
        logger.info(
            "%s: resuming, %d of %d cases already done, %d to run (%d of them because their params changed)",
            path, len(done), len(cases), len(pending), changed,
        )
    else:
        logger.info("%s: %d cases to run", path, len(pending))

    rows = dict(done)
    n_run = 0
    failed: dict[str, str] = {}
    bar = _progress_bar(progress, len(cases), len(done), desc) if pending else None
    appender = _Appender(path)

    def finish(row: dict) -> None:
        nonlocal n_run
        appender.write(row)
        n_run += 1
        rows[row["id"]] = row
        if row.get("status") == "error":
            logger.warning("case %s: %s", row["id"], row.get("error"))
        if bar is not None:
            bar.update(1)

    try:
        if not pending:
            pass
        elif executor == "serial":
            for case in pending:
                finish(_run_case(fn, case))
        elif executor is None or executor == "process":
            n = max(1, min(workers or os.cpu_count() or 1, len(pending)))
            with cf.ProcessPoolExecutor(max_workers=n, initializer=_init_worker) as pool:
                _drain_futures(pool, pending, fn, finish, failed)
        elif isinstance(executor, cf.Executor):
            _drain_futures(executor, pending, fn, finish, failed)
        elif _is_dask_client(executor):
            _drain_dask(executor, pending, fn, finish, failed)
        else:
            raise InvalidParameter(
                f"executor must be None, 'process', 'serial', a concurrent.futures.Executor or a "
                f"dask.distributed.Client; got {executor!r}"
            )
    finally:
        appender.close()
        if bar is not None:
            bar.close()

    ordered = [rows[i] for i in ids if i in rows]
    if failed:
        first = next(iter(failed.items()))
        raise SweepIncomplete(
            f"{len(failed)} of {len(cases)} cases did not run because the executor failed "
            f"(first: {first[0]}: {first[1]}); the {len(ordered)} finished rows are in {path}: "
            f"run the sweep again to run only the missing cases.",
            failed=failed,
            rows=ordered,
        )
    return SweepRows(ordered, n_run)


def _drain_futures(pool: cf.Executor, pending, fn, finish, failed) -> None:
    futures = {pool.submit(_run_case, fn, case): case for case in pending}
    try:
        for future in cf.as_completed(futures):
            case = futures[future]
            try:
                row = future.result()
            except Exception as exc:  # noqa: BLE001 - the executor's failure (fn's are rows)
                failed[case.id] = _error_text(exc)
                logger.error("case %s did not run: %s", case.id, failed[case.id])
                continue
            finish(row)
    except BaseException:
        for future in futures:
            future.cancel()
        if isinstance(pool, cf.ProcessPoolExecutor):
            _stop_workers(pool)
        raise


def _stop_workers(pool: cf.ProcessPoolExecutor) -> None:
    """Cancel the queued cases and end the running ones now (their rows are not written, so a resume reruns them).

    Without this, leaving the pool's ``with`` block waits for every running case to finish,
    which can be minutes after a Ctrl-C that reached only this process.
    """
    terminate = getattr(pool, "terminate_workers", None)  # Python >= 3.14
    if terminate is not None:
        terminate()
        return
    # before shutdown, which forgets them (CPython keeps the workers in ``_processes``)
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()


def _drain_dask(client, pending, fn, finish, failed) -> None:
    from distributed import as_completed

    # pure=False: the same case submitted twice (a re-run) is computed, not served from cache.
    futures = [client.submit(_run_case, fn, case, True, pure=False, key=f"fem-elastic-{case.id}-{time.time_ns()}")
               for case in pending]
    by_key = {f.key: case for f, case in zip(futures, pending)}
    try:
        for future in as_completed(futures):
            case = by_key[future.key]
            try:
                row = future.result()
            except Exception as exc:  # noqa: BLE001 - a lost worker, an unpicklable fn
                failed[case.id] = _error_text(exc)
                logger.error("case %s did not run: %s", case.id, failed[case.id])
                continue
            finish(row)
    except BaseException:
        client.cancel(futures)
        raise
