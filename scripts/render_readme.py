"""Render the README's picture: the demo's FEM beam beside its mass-spring copy.

Runs the packaged demo scene (``fem_elastic/app/scenes/demo.toml``: a Neo-Hookean
cantilever on quadratic tets and a spring network on the same mesh, released
under gravity) without rendering its movie, then draws one PNG with
:func:`fem_elastic.app.render.render_frame`: two columns (FEM, springs) and two
rows (mid-run and the last frame), coloured by von Mises stress, with the
colour range and camera of the whole run. Prints what it wrote and the
timings. About 30 s on a 2-core machine.

    python scripts/render_readme.py                     # writes docs/demo.png
    python scripts/render_readme.py --out /tmp/demo.png --runs demo_out
        # --runs: draw the run directories of an earlier `fem-elastic demo --out demo_out`
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import fem_elastic

DEMO = Path(fem_elastic.__file__).resolve().parent / "app" / "scenes" / "demo.toml"


def run_demo(work: Path, duration: float | None) -> tuple[list[Path], float]:
    """Simulate the demo's variants into ``work``; the run directories and the seconds taken."""
    from fem_elastic.app.runner import run_scene
    from fem_elastic.app.scene import load_scene

    scene = load_scene(DEMO)
    if duration is not None:
        spec = copy.deepcopy(scene.spec)
        spec["time"]["duration"] = duration
        scene = dataclasses.replace(scene, spec=spec)
    t0 = time.perf_counter()
    outcomes, _ = run_scene(scene, work, render=False)
    seconds = time.perf_counter() - t0
    for o in outcomes:
        print(f"  {o.name:<8} {o.status:<10} simulate {o.seconds_simulate:6.1f} s "
              f"(of which output {o.seconds_output:.1f} s)")
        if o.status != "completed":
            print(f"  {o.name}: {o.message}", file=sys.stderr)
    return [o.run_dir for o in outcomes], seconds


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("docs/demo.png"),
                        help="PNG to write (default docs/demo.png; its folder is created)")
    parser.add_argument("--runs", type=Path, default=None,
                        help="draw the run directories under this demo output folder instead "
                             "of running the demo")
    parser.add_argument("--size", type=int, nargs=2, default=(960, 540), metavar=("W", "H"),
                        help="picture size in pixels (default 960 540)")
    parser.add_argument("--duration", type=float, default=None,
                        help="simulate this many seconds instead of the scene's 3 s "
                             "(quick checks)")
    args = parser.parse_args(argv)

    from fem_elastic.app.vtu import read_series
    from fem_elastic.app.render import render_frame

    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="render_readme_") as tmp:
        if args.runs is None:
            print(f"running the demo scene {DEMO}")
            run_dirs, t_sim = run_demo(Path(tmp), args.duration)
        else:
            run_dirs = sorted(p.parent for p in args.runs.glob("*/series.pvd"))
            # the scene's order: the FEM body first, then its copies
            run_dirs.sort(key=lambda p: (p.name != "fem", p.name))
            if not run_dirs:
                print(f"render_readme: no run directory (*/series.pvd) under {args.runs}",
                      file=sys.stderr)
                return 2
            t_sim = 0.0
        t0 = time.perf_counter()
        series = [read_series(d) for d in run_dirs]
        t_read = time.perf_counter() - t0
        n_frames = len(series[0].times)
        frames = (n_frames // 2, n_frames - 1)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        path = render_frame(series, args.out, frame=frames, size=tuple(args.size),
                            titles=[d.name for d in run_dirs])
        t_render = time.perf_counter() - t0
    print(f"wrote {path} ({args.size[0]} x {args.size[1]} px): "
          f"{' | '.join(p.name for p in run_dirs)}, frames {frames[0]} and {frames[1]} "
          f"of {n_frames}")
    print(f"simulate {t_sim:.1f} s, read {t_read:.1f} s, render {t_render:.1f} s, total "
          f"{time.perf_counter() - t_start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
