"""Benchmark: what checkpoints cost a run, as a ratio against the same run without them.

One model (default the demo's body: Neo-Hookean P2 on a 1 x 0.1 x 0.1 m beam of 20 x 1 x 1
cells under gravity, implicit Euler at dt = 1/60 s), simulated in one process

1. without checkpoints (the reference),
2. with ``checkpoint_every`` = 1, 10 and 50 steps (and always one at the end),

interleaved (one of each per round, so that the machine's load hits them alike),

recording a frame every 2 steps as the demo does. Prints each variant's median wall time
over the repeats, its ratio to the reference, the seconds per checkpoint written, and the
bytes on disk. A checkpoint appends the frames and per-step statistics recorded since the
last one and rewrites only the state (``checkpoint.npz``, fsynced and renamed), so its cost
is one fsync'd small file plus the new history, not the whole history again.

A resume is timed too: the run is stopped (Ctrl-C raised by a callback) half way, then
resumed; the resumed trajectory is checked to be the reference's bit for bit.

Usage::

    python scripts/bench_checkpoint.py              # 180 steps, 3 repeats, ~1 min
    python scripts/bench_checkpoint.py --quick      # 30 steps, P1, seconds
    python scripts/bench_checkpoint.py --steps 600 --repeats 5 --dir /fast/disk
"""

from __future__ import annotations

import argparse
import platform
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import fem_elastic as fe


def build(order: int, cells):
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=tuple(cells))
    return fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=2e7, nu=0.3), order=order),
                    fixed="left", gravity=(0.0, 0.0, -9.81))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="30 steps of a P1 beam")
    p.add_argument("--steps", type=int, default=180)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--cells", type=int, nargs=3, default=(20, 1, 1))
    p.add_argument("--order", type=int, default=2)
    p.add_argument("--dir", default=None, help="where to write the checkpoints (default a temporary folder)")
    args = p.parse_args(argv)
    steps, order, repeats = args.steps, args.order, args.repeats
    if args.quick:
        steps, order, repeats = 30, 1, 3
    model = build(order, args.cells)
    dt = 1.0 / 60.0
    root = Path(tempfile.mkdtemp(prefix="bench_ck_", dir=args.dir))
    print(f"{platform.node()}: Neo-Hookean P{order}, cells {tuple(args.cells)}, {model.ndofs} DOFs, "
          f"{steps} implicit Euler steps, a frame every 2 steps; medians of {repeats}; disk {root}")

    def run(every):
        if every is None:
            return fe.simulate(model, fe.ImplicitEuler(), dt, steps=steps, record_every=2)
        return fe.simulate(model, fe.ImplicitEuler(), dt, steps=steps, record_every=2,
                           checkpoint_dir=root / f"every_{every}", checkpoint_every=every)

    # warm-up: numba compilation and caches out of the timings
    fe.simulate(model, fe.ImplicitEuler(), dt, steps=2, record_every=2)
    variants = (None, 1, 10, 50)
    times = {v: [] for v in variants}
    runs = {}
    for _ in range(repeats):  # interleaved, so that a change in the machine's load hits all alike
        for v in variants:
            t0 = time.perf_counter()
            runs[v] = run(v)
            times[v].append(time.perf_counter() - t0)
    ref = runs[None]
    t_ref = statistics.median(times[None])
    print(f"{'checkpoint_every':>18}{'median (s)':>12}{'ratio':>8}{'checkpoints':>13}{'ms each':>9}{'MB on disk':>12}")
    print(f"{'none':>18}{t_ref:>12.3f}{1.0:>8.3f}{0:>13d}{'':>9}{'':>12}")
    for every in variants[1:]:
        assert np.array_equal(runs[every].displacement, ref.displacement)
        t = statistics.median(times[every])
        n = len(range(every, steps, every)) + 1
        d = root / f"every_{every}"
        size = sum(f.stat().st_size for f in d.iterdir()) / 1e6
        print(f"{every:>18d}{t:>12.3f}{t / t_ref:>8.3f}{n:>13d}{(t - t_ref) / n * 1e3:>9.2f}{size:>12.2f}")

    d = root / "resume"
    half = steps // 2

    def stop(k, state):
        if k == half:
            raise KeyboardInterrupt

    try:
        fe.simulate(model, fe.ImplicitEuler(), dt, steps=steps, record_every=2, checkpoint_dir=d,
                    checkpoint_every=10, callback=stop)
    except KeyboardInterrupt:
        pass
    t0 = time.perf_counter()
    resumed = fe.simulate(model, fe.ImplicitEuler(), dt, steps=steps, record_every=2, checkpoint_dir=d,
                          checkpoint_every=10, resume=True)
    t_resume = time.perf_counter() - t0
    same = all(np.array_equal(getattr(resumed, k), getattr(ref, k))
               for k in ("times", "displacement", "velocity", "kinetic", "potential"))
    print(f"resume at step {resumed.resumed_from_step}: {t_resume:.3f} s for the remaining "
          f"{steps - resumed.resumed_from_step} steps; trajectory identical to the reference: {same}")
    shutil.rmtree(root, ignore_errors=True)
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
