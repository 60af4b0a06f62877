"""The sweep executor: the same rows from every executor, errors as rows, resume, durability."""

import concurrent.futures as cf
import json
import os
import signal
import threading
import time

import pytest

from fem_elastic.errors import InvalidParameter
from fem_elastic.study.executor import Case, RESULTS_FILE, read_results, run_sweep, write_csv

CASES = [Case(f"sq/{x}", {"x": x, "label": f"n{x}"}) for x in range(6)]
CALLS = []


def square(params):
    """Module level, so the process pool and Dask can pickle it."""
    CALLS.append(params["x"])
    if params["x"] == 4:
        raise ValueError("four is not allowed")
    return {"y": params["x"] ** 2, "half": params["x"] / 2}


def interrupt_on_third(params):
    if params["x"] == 2:
        raise KeyboardInterrupt
    return {"y": params["x"]}


def nap(params):
    time.sleep(params["sleep"])
    return {"slept": params["sleep"]}


def _comparable(rows):
    """Rows without the wall time (which differs between runs)."""
    return [{k: v for k, v in r.items() if k != "seconds"} for r in rows]


def _check_rows(rows):
    assert [r["id"] for r in rows] == [c.id for c in CASES]  # case order, whatever finished first
    for r, c in zip(rows, CASES):
        assert r["x"] == c.params["x"] and r["label"] == c.params["label"]
        assert r["seconds"] >= 0.0
        if c.params["x"] == 4:
            assert r["status"] == "error" and r["error"] == "ValueError: four is not allowed"
            assert "y" not in r
        else:
            assert r["status"] == "ok" and r["y"] == c.params["x"] ** 2


@pytest.fixture(scope="module")
def serial_rows(tmp_path_factory):
    rows = run_sweep(CASES, square, tmp_path_factory.mktemp("serial"), executor="serial", progress=False)
    _check_rows(rows)
    return rows


def test_serial_rows_and_file(serial_rows, tmp_path):
    rows = run_sweep(CASES, square, tmp_path, executor="serial", progress=False)
    assert _comparable(rows) == _comparable(serial_rows)
    lines = (tmp_path / RESULTS_FILE).read_text().splitlines()
    assert len(lines) == len(CASES) and all(json.loads(line)["id"] for line in lines)
    assert _comparable(read_results(tmp_path)) == _comparable(rows)


def test_process_pool_gives_the_same_rows(serial_rows, tmp_path):
    rows = run_sweep(CASES, square, tmp_path, workers=2, progress=False)  # default executor: processes
    _check_rows(rows)
    assert _comparable(rows) == _comparable(serial_rows)
    assert len(read_results(tmp_path)) == len(CASES)


def test_thread_pool_gives_the_same_rows(serial_rows, tmp_path):
    with cf.ThreadPoolExecutor(max_workers=3) as pool:
        rows = run_sweep(CASES, square, tmp_path, executor=pool, progress=True, desc="threads")
    assert _comparable(rows) == _comparable(serial_rows)


def test_dask_cluster_gives_the_same_rows(serial_rows, tmp_path):
    distributed = pytest.importorskip("distributed", reason="the Dask test needs the [cluster] extra")
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
    ) as cluster, distributed.Client(cluster) as client:
        rows = run_sweep(CASES, square, tmp_path, executor=client, progress=False)
    assert _comparable(rows) == _comparable(serial_rows)
    assert len(read_results(tmp_path)) == len(CASES)


def test_resume_runs_only_missing_cases(tmp_path):
    run_sweep(CASES[:3], square, tmp_path, executor="serial", progress=False)
    CALLS.clear()
    rows = run_sweep(CASES, square, tmp_path, executor="serial", progress=False)
    assert CALLS == [3, 4, 5]  # the first three came from results.jsonl
    assert rows.n_run == 3
    _check_rows(rows)
    CALLS.clear()
    again = run_sweep(CASES, square, tmp_path, executor="serial", progress=False)
    assert CALLS == [4]  # only the case that errored is tried again (it may have been a bug)
    assert again.n_run == 1  # counted although its id was already in results.jsonl
    assert _comparable(again) == _comparable(rows)  # all but the measured seconds
    assert len((tmp_path / RESULTS_FILE).read_text().splitlines()) == len(CASES) + 1


def _fixed_square(params):
    return {"y": params["x"] ** 2, "half": params["x"] / 2}


def test_resume_retries_an_errored_case_and_its_new_row_wins(tmp_path):
    rows = run_sweep(CASES, square, tmp_path, executor="serial", progress=False)
    assert rows[4]["status"] == "error"
    rows = run_sweep(CASES, _fixed_square, tmp_path, executor="serial", progress=False)  # "the fix"
    assert rows[4]["status"] == "ok" and rows[4]["y"] == 16
    assert [r["status"] for r in rows] == ["ok"] * len(CASES)


def test_resume_reruns_cases_whose_params_changed(tmp_path):
    run_sweep(CASES[:3], square, tmp_path, executor="serial", progress=False)
    changed = [CASES[0], Case(CASES[1].id, {"x": 7, "label": "n1"}), CASES[2]]
    CALLS.clear()
    rows = run_sweep(changed, square, tmp_path, executor="serial", progress=False)
    assert CALLS == [7] and rows[1]["y"] == 49
    assert rows.n_run == 1  # the changed case, whose id was already in results.jsonl
    assert read_results(tmp_path)[-1]["y"] == 49  # the new row supersedes the old one


def test_truncated_last_line_is_tolerated_and_repaired(tmp_path):
    run_sweep(CASES[:3], square, tmp_path, executor="serial", progress=False)
    path = tmp_path / RESULTS_FILE
    text = path.read_text()
    path.write_text(text[: len(text) - 10])  # the third row cut mid-write, no newline
    assert [r["id"] for r in read_results(tmp_path)] == [c.id for c in CASES[:2]]
    CALLS.clear()
    rows = run_sweep(CASES, square, tmp_path, executor="serial", progress=False)
    assert CALLS == [2, 3, 4, 5]  # the cut row is run again
    _check_rows(rows)
    lines = path.read_text().splitlines()
    assert len(lines) == len(CASES) and all(json.loads(line) for line in lines)


def test_rows_are_written_as_they_finish(tmp_path):
    with pytest.raises(KeyboardInterrupt):
        run_sweep(CASES, interrupt_on_third, tmp_path, executor="serial", progress=False)
    assert [r["id"] for r in read_results(tmp_path)] == [c.id for c in CASES[:2]]


def test_ctrl_c_stops_a_process_pool_at_once(tmp_path):
    """KeyboardInterrupt while waiting: the queued and running cases are dropped at once (not
    after the running ones finish, 60 s here), and the finished rows are kept."""
    cases = [Case("fast/0", {"sleep": 0.0}), Case("fast/1", {"sleep": 0.0}),
             Case("slow/0", {"sleep": 60.0}), Case("slow/1", {"sleep": 60.0}), Case("slow/2", {"sleep": 60.0})]
    # a real SIGINT (Ctrl-C) to this process only, as a terminal's would reach it; the fast cases
    # finish well within the 2 s
    timer = threading.Timer(2.0, os.kill, (os.getpid(), signal.SIGINT))
    # Python's own Ctrl-C handler, as in a terminal: a test run started in the background by a
    # non-interactive shell inherits SIGINT ignored, and then no KeyboardInterrupt comes at all
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    t0 = time.perf_counter()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            run_sweep(cases, nap, tmp_path, workers=2, progress=False)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    assert time.perf_counter() - t0 < 15.0
    assert sorted(r["id"] for r in read_results(tmp_path)) == ["fast/0", "fast/1"]


def test_duplicate_ids_and_unknown_executor_are_rejected(tmp_path):
    with pytest.raises(InvalidParameter, match="unique"):
        run_sweep([CASES[0], CASES[0]], square, tmp_path, executor="serial", progress=False)
    with pytest.raises(InvalidParameter, match="executor"):
        run_sweep(CASES[:1], square, tmp_path, executor="mpi", progress=False)


def test_write_csv_union_of_columns(tmp_path):
    import csv

    rows = [{"id": "a", "err": 0.1, "status": "ok"}, {"id": "b", "status": "error", "error": "X: y"},
            {"id": "c", "err": float("inf"), "list": [1, 2]}]
    path = write_csv(rows, tmp_path / "t.csv")
    with open(path, newline="") as fh:
        table = list(csv.DictReader(fh))
    assert list(table[0]) == ["id", "err", "status", "error", "list"]
    assert table[0]["err"] == "0.1" and table[1]["err"] == "" and table[2]["err"] == "inf"
    assert table[1]["error"] == "X: y" and json.loads(table[2]["list"]) == [1, 2]
    assert not list(tmp_path.glob(".*.tmp"))  # the temporary file was moved into place


_KILLED_STUDY = """
import os, sys, time
from pathlib import Path
from fem_elastic.study.executor import Case, run_sweep

def nap_and_tell(params):
    Path(sys.argv[1], f"worker-{os.getpid()}").touch()
    time.sleep(params["sleep"])
    return {}

if __name__ == "__main__":
    run_sweep([Case(f"slow/{k}", {"sleep": 60.0}) for k in range(4)], nap_and_tell, sys.argv[1],
              workers=2, progress=False)
"""


def test_pool_workers_end_when_the_study_is_killed(tmp_path):
    """kill -9 of the study's process: its pool workers must not live on (they block on their
    own task queue and once stayed, idle, forever)."""
    import subprocess
    import sys

    script = tmp_path / "study.py"
    script.write_text(_KILLED_STUDY)
    parent = subprocess.Popen([sys.executable, str(script), str(tmp_path)])
    try:
        deadline = time.monotonic() + 60.0  # two worker processes importing fem_elastic
        while len(list(tmp_path.glob("worker-*"))) < 2 and time.monotonic() < deadline:
            time.sleep(0.1)
        pids = [int(p.name.split("-")[1]) for p in tmp_path.glob("worker-*")]
        assert len(pids) == 2
    finally:
        parent.kill()
        parent.wait()

    def alive(pid):
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        return True

    deadline = time.monotonic() + 10.0  # the workers poll their parent every 0.5 s
    while any(alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    left = [p for p in pids if alive(p)]
    for p in left:  # do not leak them into the rest of the suite if the test fails
        os.kill(p, signal.SIGKILL)
    assert not left, f"pool workers {left} outlived the killed study"
    assert not (tmp_path / RESULTS_FILE).read_text()  # no case finished, none written
