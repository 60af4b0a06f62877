"""The ``fem-elastic`` command.

Subcommands::

    fem-elastic demo [--out DIR]                 the default scene: a cantilever released
                                                 under gravity, Neo-Hookean FEM beside a
                                                 mass-spring copy, rendered to MP4/PNG/VTU
    fem-elastic run SCENE.toml --out DIR         run a scene file (--ranks N, or under
                                                 mpiexec: across MPI ranks, fem_elastic.app.mpi_run)
    fem-elastic render DIR --format mp4|gif|png  render a run's VTU series
    fem-elastic info MESH                        counts, quality and boundaries of a mesh
    fem-elastic study accuracy|stability --out DIR [--quick]

Every error the user can fix (a bad scene file, a bad option, a mesh that
fails validation) is printed as one message without a traceback and gives a
non-zero exit status: 2 for command-line, scene, mesh and parameter errors
(``fe.InvalidParameter``, ``fe.InvalidMesh``) and unusable paths, 1 for a
computation that failed (a run that diverged or whose step raised an error:
``summary.json`` says "diverged" or "failed"; a static solve that did not
converge; any other ``fe.FemElasticError``) and for an unexpected error (a bug: one line that names it and points to ``--debug``,
which prints the traceback), 130 for Ctrl-C, at any moment. A closed or
broken stdout (``fem-elastic info MESH | head -c 0``) ends the command quietly,
and text that the terminal's encoding cannot show is escaped, never an error.

An output directory is written by one run at a time (a second run on it exits
2 at once, naming the first one's pid), never holds a run mixed with files it
did not write (refused unless ``--overwrite``), and a write that fails (a full
disk) exits 1 naming the file, with nothing truncated left under its name
(:mod:`fem_elastic.app.run_lock`, :mod:`fem_elastic.files`).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path
from typing import Any, Callable

__all__ = ["main"]

_EXIT_USAGE, _EXIT_FAILED, _EXIT_INTERRUPTED = 2, 1, 130
_EXIT_INTERNAL = 1  # an unexpected error: what Python itself exits with on one


class _Out:
    """Prints for the command (library code logs; only the command prints)."""

    def __init__(self, quiet: bool):
        self.quiet = quiet

    def __call__(self, text: str = "") -> None:
        if not self.quiet:
            sys.stdout.write(text + "\n")
            sys.stdout.flush()


def _int_at_least(minimum: int):
    """An argparse type: an integer >= ``minimum``."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if v < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {text}")
        return v

    return parse


_positive_int = _int_at_least(1)
_non_negative_int = _int_at_least(0)


def _render_side(text: str) -> int:
    """An argparse type: a render width or height, bounded as the scene schema bounds it."""
    from .scene_schema import MAX_RENDER_SIDE

    v = _positive_int(text)
    if v > MAX_RENDER_SIDE:
        raise argparse.ArgumentTypeError(f"must be <= {MAX_RENDER_SIDE} px, got {text}")
    return v


# ---------------------------------------------------------------------------------- run / demo


def _tip_vertices(mesh):
    """Vertex indices of the beam's free end: the vertices of its boundary "right" (x = L)."""
    import numpy as np

    from ..geometry.mesh import boundary_facets

    return np.unique(mesh.facets[:, boundary_facets(mesh, "right", what="The demo's tip")])


def _print_outcomes(out, outcomes, rendered, out_dir) -> None:
    out("")
    w = max([12] + [len(o.name) + 2 for o in outcomes])  # long variant names keep their column
    out(f"{'variant':<{w}}{'status':<12}{'steps':>7}{'cut':>6}{'frames':>8}{'simulate (s)':>14}{'output (s)':>12}")
    for o in outcomes:
        traj = o.trajectory
        steps = traj.steps if traj is not None else 0
        cut = traj.dt_cuts if traj is not None else 0
        frames = traj.times.size if traj is not None else 0
        if o.figures:  # a static run: its load steps, a frame per point of the path
            steps = o.figures["load_steps"]
            frames = len(o.result.path) if o.result is not None else 0
        out(f"{o.name:<{w}}{o.status:<12}{steps:>7d}{cut:>6d}{frames:>8d}{o.seconds_simulate:>14.2f}"
            f"{o.seconds_output:>12.2f}")
    for o in outcomes:
        if o.figures:
            _print_static(out, o)
        elif o.physics:
            _print_dynamic(out, o)
    for o in outcomes:
        traj = o.trajectory
        if o.status == "completed" and traj is not None and traj.resumed_from_step is not None:
            if traj.resumed_from_step < traj.steps:
                out(f"{o.name}: resumed from its checkpoint at step {traj.resumed_from_step}")
            else:
                out(f"{o.name}: had finished; its files are left as they were")
        if traj is not None and traj.cuts:
            first = traj.cuts[0]
            out(f"{o.name}: {traj.dt_cuts} steps cut ({len(traj.cuts)} failed attempts), the first at "
                f"step {first['step']} (t = {first['t']:.6g} s, dt = {first['dt']:.3g} s): {first['reason']}")
    out("")
    out(f"written to {out_dir}/:")
    for o in outcomes:
        out(f"  {o.run_dir.name}/series.pvd   (VTU series: open in ParaView), {o.run_dir.name}/summary.json")
    for p in _collapse_pngs(rendered, out_dir):
        out(f"  {p}")
    for o in outcomes:  # a failed run says why, on stderr, even with --quiet
        if o.status != "completed":
            sys.stderr.write(f"fem-elastic: {o.name}: {o.message}\n")


def _print_dynamic(out, o) -> None:
    """A time-stepping run's physical result: largest displacement, energy, det F, probes, reactions."""
    f, traj = o.physics, o.trajectory
    line = (f"{o.name}: max |u| = {f['max_displacement']:.4g} m at t = {f['max_displacement_time']:.4g} s "
            f"(final {f['final_max_displacement']:.4g} m)")
    if traj is not None and traj.total.size:
        line += f"; energy {traj.total[0]:.4g} -> {traj.total[-1]:.4g} J"
    det = traj.summary().get("min_det_F") if traj is not None else None
    if det is not None:
        line += f"; min det F {det:.4g}"
    out(line)
    for name, p in (f.get("probes") or {}).items():
        u = p["final"]
        out(f"{o.name}:   {name} (vertex {p['vertex']}): u = [{u[0]:.4g}, {u[1]:.4g}, {u[2]:.4g}] m at the end")
    for name, r in (f.get("reactions") or {}).items():
        out(f"{o.name}:   reaction on {name} at the end: [{r[0]:.4g}, {r[1]:.4g}, {r[2]:.4g}] N")


def _print_static(out, o) -> None:
    """A static run's physical result: largest displacement and the reaction on each support."""
    f = o.figures
    u = f["max_displacement_vector"]
    out(f"{o.name}: static, load factor {f['load_factor']:.4g} in {f['load_steps']} load step(s); "
        f"max |u| = {f['max_displacement']:.6g} m at vertex {f['max_displacement_vertex']} "
        f"(u = [{u[0]:.4g}, {u[1]:.4g}, {u[2]:.4g}] m)")
    for name, p in (f.get("probes") or {}).items():
        u = p["final"]
        out(f"{o.name}:   {name} (vertex {p['vertex']}): u = [{u[0]:.4g}, {u[1]:.4g}, {u[2]:.4g}] m")
    for name, r in f["reactions"].items():
        out(f"{o.name}:   reaction on {name}: [{r[0]:.6g}, {r[1]:.6g}, {r[2]:.6g}] N")
    if f["min_eigenvalue"] is not None:
        out(f"{o.name}:   lowest tangent eigenvalue {f['min_eigenvalue']:.4g} N/m: "
            + ("stable" if f["stable"] else "UNSTABLE equilibrium (a saddle; try [solve] stabilize = true)"))


def _collapse_pngs(paths, out_dir):
    """List movies one by one and PNG frames as one line per directory."""
    pngs: dict = {}
    lines = []
    for p in paths:
        p = Path(p)
        if p.suffix == ".png":
            pngs.setdefault(p.parent, []).append(p)
        else:
            lines.append(str(p.relative_to(out_dir)) if p.is_relative_to(out_dir) else str(p))
    for d, files in pngs.items():
        rel = d.relative_to(out_dir) if d.is_relative_to(out_dir) else d
        lines.append(f"{rel}/ ({len(files)} PNG frames)")
    return lines


def _run_scene_command(scene, out_dir, out, **options) -> int:
    """Run (or resume) a scene through :func:`run_scene`, report it, and return the exit status."""
    from .runner import SceneInterrupted, run_scene

    t0 = time.perf_counter()
    try:
        outcomes, rendered = run_scene(scene, out_dir, **options)  # refuses --out "" by its text
        out_dir = Path(out_dir)
    except SceneInterrupted as stop:
        return _interrupted(stop)
    return _finish_scene_command(out_dir, outcomes, rendered, t0, out)


def _finish_scene_command(out_dir, outcomes, rendered, t0, out) -> int:
    # OUT/summary.json: run_scene wrote it while it held the directory's lock
    _print_outcomes(out, outcomes, rendered, out_dir)
    out(f"total {time.perf_counter() - t0:.1f} s")
    return 0 if all(o.status == "completed" for o in outcomes) else _EXIT_FAILED


def _interrupted(stop) -> int:
    """Ctrl-C: say what stopped (run_scene wrote the scene's summary, "interrupted"), exit 130."""
    sys.stderr.write(f"fem-elastic: {stop.outcome.name}: {stop.outcome.message}\n")
    return _EXIT_INTERRUPTED


def _run(args) -> int:
    from ..errors import InvalidParameter
    from .scene import load_scene

    out = _Out(args.quiet)
    if args.resume is not None:
        if args.scene is not None or args.out is not None or args.variant or args.checkpoint_every is not None:
            raise InvalidParameter(
                "--resume DIR continues the run in DIR with the scene, variants and checkpoint "
                "interval it was started with: give it alone (`fem-elastic run --resume DIR`)."
            )
        from .mpi_run import launcher_world

        if args.ranks is not None or launcher_world()[1] > 1:
            raise InvalidParameter(
                "--resume continues a run in one process: run `fem-elastic run --resume DIR` without "
                "--ranks and without mpiexec (its static or implicit solves then run on one rank)."
            )
        return _resume(args, out)
    if args.scene is None or args.out is None:
        raise InvalidParameter(
            "give a scene and an output directory (`fem-elastic run SCENE.toml --out DIR`), or "
            "`fem-elastic run --resume DIR` to continue a run."
        )
    if args.ranks is not None and args.ranks > 1:
        from .mpi_run import relaunch

        load_scene(args.scene)  # a bad scene is reported once, before mpiexec starts
        return relaunch(args.argv, args.ranks)
    scene = load_scene(args.scene)
    from .mpi_run import check_distributed_scene, launcher_world

    rank, size = launcher_world()
    if size > 1:  # under mpiexec: rank 0 writes and prints; the others run into a scratch dir
        check_distributed_scene(scene, size)
        if rank != 0:
            import shutil
            import tempfile

            scratch = tempfile.mkdtemp(prefix=f"fem_elastic_rank{rank}_")
            try:
                _run_scene_command(scene, Path(scratch) / "out", _Out(True), variants=args.variant or None,
                                   progress=False, render=False, checkpoint_every=args.checkpoint_every)
            finally:
                shutil.rmtree(scratch, ignore_errors=True)
            return 0
    out(f"scene {scene.name!r} from {args.scene}: variants {', '.join(scene.variants)}"
        + (f" on {size} MPI ranks" if size > 1 else ""))
    return _run_scene_command(
        scene, args.out, out, variants=args.variant or None, progress=not args.quiet,
        render=not args.no_render, checkpoint_every=args.checkpoint_every,
        overwrite=args.overwrite,
    )


def _resume(args, out) -> int:
    from .runner import read_resumable

    out_dir = Path(args.resume)
    scene, record = read_resumable(out_dir)
    out(f"resuming scene {scene.name!r} in {out_dir} from its checkpoints")
    return _run_scene_command(
        scene, out_dir, out, variants=record.get("variants"), progress=not args.quiet,
        render=False if args.no_render else record.get("render", True),
        checkpoint_every=record.get("checkpoint_every"), resume=True,
    )


def _demo(args) -> int:
    import numpy as np

    from ..physics.analytic import RectangularCantilever
    from .runner import SceneInterrupted, run_scene
    from .scene import load_scene
    from ..solvers.static import solve_static

    out = _Out(args.quiet)
    demo_path = Path(__file__).resolve().parent / "scenes" / "demo.toml"
    if args.print_scene:
        sys.stdout.write(demo_path.read_text())
        return 0
    scene = load_scene(demo_path)
    spec = scene.spec
    mesh, grav = spec["mesh"], spec["loads"]["gravity"]
    L, b, h = mesh["length"], mesh["width"], mesh["height"]
    out(f"fem-elastic demo: {scene.description}")
    out(f"scene: {demo_path} (print it with `fem-elastic demo --print-scene`)")
    t0 = time.perf_counter()
    out_dir = Path(args.out)
    try:
        outcomes, rendered = run_scene(scene, args.out, progress=not args.quiet, render=not args.no_render,
                                       overwrite=args.overwrite)
    except SceneInterrupted as stop:
        return _interrupted(stop)
    seconds = time.perf_counter() - t0  # OUT/summary.json: written by run_scene under its lock

    # Tip deflection at the end of the run against the static answer of beam theory under
    # self weight, and against the same discretization solved statically.
    g = float(np.linalg.norm(grav))
    out("")
    out(f"tip deflection at t = {spec['time']['duration']:g} s against the static value under self weight")
    header = (f"{'variant':<10}{'body':<40}{'tip (mm)':>10}{'static FE (mm)':>16}{'Timoshenko (mm)':>17}"
              f"{'vs Timo':>9}{'simulate (s)':>14}")
    out(header)
    out("-" * len(header))
    notes = []
    for o in outcomes:
        run = o.run
        body = run.info.get("body_spec") or spec["body"]
        E, nu, rho = float(run.info["E"]), float(run.info["nu"]), float(body["density"])
        beam = RectangularCantilever(length=L, width=b, height=h, E=E, nu=nu)
        w_timo = beam.distributed_load_timoshenko(rho * g * b * h)
        tip = _tip_vertices(run.model.mesh)
        w_end = -float(np.mean(o.trajectory.displacement[-1, tip, 2])) if o.trajectory is not None else float("nan")
        w_static = -float(np.mean(solve_static(run.model).displacement[tip, 2]))
        out(f"{o.name:<10}{run.info.get('body', ''):<40.40}{w_end * 1e3:>10.3f}{w_static * 1e3:>16.3f}"
            f"{w_timo * 1e3:>17.3f}{w_end / w_timo - 1:>+9.1%}{o.seconds_simulate:>14.2f}")
        notes.append((o.name, w_end, w_static, w_timo))
    out("")
    for name, w_end, w_static, w_timo in notes:
        settled = abs(w_end - w_static) / abs(w_static)
        out(f"{name}: the tip ends within {settled:.2%} of the same body's static answer (fe.solve_static), "
            f"which bends {w_static / w_timo:.2f} x as far as Timoshenko's beam.")
    out("A spring network calibrated from E is not the solid it stands for: its stiffness depends on\n"
        "the mesh and its Poisson ratio is fixed near 1/4 (notebooks/springs_vs_fem.ipynb). P2 FEM lands\n"
        "within a few percent of beam theory; the 3-D clamp makes the solid a little stiffer than a beam.")
    _print_outcomes(out, outcomes, rendered, out_dir)
    out(f"total {seconds:.1f} s")
    return 0 if all(o.status == "completed" for o in outcomes) else _EXIT_FAILED


# ---------------------------------------------------------------------------------- render / info


def _render(args) -> int:
    from ..errors import InvalidParameter
    from .render import render_runs

    out = _Out(args.quiet)
    src = Path(args.dir)
    if (src / "series.pvd").is_file():
        run_dirs = [src]
    else:
        run_dirs = sorted(p.parent for p in src.glob("*/series.pvd"))
        order = _variant_order(src)
        if order:
            run_dirs.sort(key=lambda p: order.index(p.name) if p.name in order else len(order))
    if not run_dirs:
        raise InvalidParameter(
            f"{src} holds no VTU series (no series.pvd in it or in its subdirectories): give the "
            "output directory of `fem-elastic run` or `fem-elastic demo`."
        )
    target = Path(args.output) if args.output is not None else (
        src / ("png" if args.format == "png" else f"movie.{args.format}"))
    from .run_lock import check_render_target

    check_render_target(target, args.format, run_dirs)  # never over an input; extension = format
    t0 = time.perf_counter()
    written = render_runs(
        run_dirs, target, format=args.format, size=tuple(args.size), color_by=args.color_by,
        fps=args.fps, every=args.every, progress=not args.quiet, warp=args.warp,
    )
    out(f"rendered {', '.join(p.name for p in run_dirs)} in {time.perf_counter() - t0:.1f} s:")
    for line in _collapse_pngs(written, src):
        out(f"  {line}")
    return 0


def _warp(text: str):
    """``--warp``: ``auto`` or a magnification > 0."""
    if text == "auto":
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither 'auto' nor a number") from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"{text!r} must be a magnification > 0")
    return value


def _variant_order(out_dir: Path) -> list:
    try:
        return list(json.loads((out_dir / "summary.json").read_text())["variants"])
    except (OSError, ValueError, KeyError, TypeError):
        return []


def _info(args) -> int:
    """Each MESH in turn (``fem-elastic info meshes/*``); the worst exit status of them."""
    status = 0
    for i, mesh in enumerate(args.mesh):
        if i:
            _Out(False)("")
        status = max(status, _info_one(Path(mesh)))
    return status


def _info_one(path: Path) -> int:
    import numpy as np

    from ..errors import FemElasticError
    from ..geometry.mesh_io import load_mesh
    from ..geometry.mesh import mesh_quality, validate_mesh

    out = _Out(False)
    if path.suffix == ".toml":
        from .scene import load_scene

        scene = load_scene(path)
        mesh = scene.mesh()
        out(f"{path}: the mesh of scene {scene.name!r}")
    else:
        mesh = load_mesh(path, validate=False)
        out(f"{path}")
    q = mesh_quality(mesh)
    lo, hi = q["bounding_box"]
    out(f"  vertices        {q['n_vertices']}")
    out(f"  tetrahedra      {q['n_elements']}")
    out(f"  volume          {q['volume']:.6g} m^3 (tets from {q['min_volume']:.3g} to {q['max_volume']:.3g} m^3)")
    out(f"  bounding box    [{lo[0]:.4g}, {hi[0]:.4g}] x [{lo[1]:.4g}, {hi[1]:.4g}] x [{lo[2]:.4g}, {hi[2]:.4g}] m")
    out(f"  quality         mean ratio min {q['min_quality']:.3f}, mean {q['mean_quality']:.3f} "
        "(1 = regular tet, near 0 = sliver, < 0 = inverted)")
    out(f"  inverted tets   {q['n_inverted']}")
    if q["boundaries"]:
        out("  boundaries      " + ", ".join(f"{k} ({v} facets)" for k, v in q["boundaries"].items()))
    else:
        out("  boundaries      none named (fix vertices by index, or name facets in the file)")
    edges = np.sort(np.asarray(mesh.edges).T, axis=1) if hasattr(mesh, "edges") else None
    if edges is not None:
        lengths = np.linalg.norm(mesh.p[:, edges[:, 0]] - mesh.p[:, edges[:, 1]], axis=0)
        out(f"  edge length     {lengths.min():.4g} to {lengths.max():.4g} m ({edges.shape[0]} edges)")
    try:
        validate_mesh(mesh)
        out("  validation      ok")
    except FemElasticError as err:
        out(f"  validation      FAILED: {err}")
        return _EXIT_FAILED
    return 0


# ---------------------------------------------------------------------------------- study


def _study(args) -> int:
    from .. import study

    from ..errors import InvalidParameter

    out = _Out(args.quiet)
    executor: Any = "serial" if args.serial else None  # "serial", None (the default) or a dask Client
    client = None
    if args.scheduler is not None:
        address = args.scheduler.strip()
        if args.serial:
            raise InvalidParameter("--serial and --scheduler exclude each other: give one of them.")
        if not address:
            raise InvalidParameter("--scheduler needs the scheduler's address, e.g. tcp://host:8786.")
        try:
            from dask.distributed import Client
        except ImportError:
            raise InvalidParameter(
                "--scheduler needs Dask: pip install \"fem_elastic[cluster]\"."
            ) from None
        try:
            client = executor = Client(address)
        except (OSError, ValueError, TypeError) as exc:  # unreachable (OSError, TimeoutError), malformed
            raise InvalidParameter(
                f"cannot use the Dask scheduler at {address!r} ({type(exc).__name__}: {exc}); check the "
                "address (tcp://host:8786) and that a scheduler runs there (`dask scheduler`, with workers "
                "started by `dask worker ADDRESS --nthreads 1`)."
            ) from None
    run = {"accuracy": study.run_accuracy_study, "stability": study.run_stability_study}[args.which]
    t0 = time.perf_counter()
    try:
        result = run(Path(args.out), quick=args.quick, executor=executor, workers=args.workers,
                     progress=not args.quiet)
    finally:
        if client is not None:
            client.close()
    n_err = sum(1 for r in result.rows if r.get("status") == "error")
    resumed = len(result.rows) - result.n_run
    out(f"study {args.which}: {len(result.rows)} cases in {time.perf_counter() - t0:.1f} s"
        + (f" ({resumed} read back from results.jsonl)" if resumed > 0 else "")
        + (f", {n_err} ended in an error (see results.csv)" if n_err else ""))
    for p in [result.csv_path, result.report_path, *result.figures]:
        out(f"  {p}")
    return 0


# ---------------------------------------------------------------------------------- parser


class _Formatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Keeps the epilog's layout; shows a default only where there is one worth showing."""

    def _get_help_string(self, action):
        if action.default in (None, False, argparse.SUPPRESS) or action.required:
            return action.help
        return super()._get_help_string(action)


def _scene_help() -> str:
    try:
        from .scene import scene_help
    except ImportError:  # pragma: no cover - the scene layer is part of the package
        return ""
    return "scene file schema:\n\n" + scene_help()


def _add_common(p, top: bool = False) -> None:
    # given before or after the command; a subcommand must not reset what the top level set
    default = False if top else argparse.SUPPRESS
    p.add_argument("-q", "--quiet", action="store_true", default=default,
                   help="no progress bars or tables (for scripts)")
    p.add_argument("-v", "--verbose", action="store_true", default=default, help="log solver progress")
    p.add_argument("--debug", action="store_true", default=default,
                   help="show the traceback of an error (for a bug report)")


def _add_run_options(p, out_default=None, out_required: bool = True) -> None:
    """--out (required, or ``out_default``), --no-render and --overwrite of `demo` and `run`."""
    if out_default is None:
        p.add_argument("--out", required=out_required, metavar="DIR", help="output directory (created)")
    else:
        p.add_argument("--out", default=out_default, metavar="DIR", help="output directory (created)")
    p.add_argument("--no-render", action="store_true",
                   help="write the VTU series and summary only, no movie or PNG frames")
    p.add_argument("--overwrite", action="store_true", help=_OVERWRITE_HELP)


_OVERWRITE_HELP = ("write into --out even when it holds files a run did not write (they are left "
                   "alone); without it such a directory is refused")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="fem-elastic",
        description="Elastic solids with the finite element method (scikit-fem based).",
        epilog="Run `fem-elastic COMMAND --help` for each command's options.",
    )
    _add_common(p, top=True)
    # the package is imported already (this module is part of it): its __version__, no upward import
    version = getattr(sys.modules.get(__name__.split(".")[0]), "__version__", "unknown")
    p.add_argument("--version", action="version", version=f"fem-elastic {version}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    demo = sub.add_parser(
        "demo", formatter_class=_Formatter,
        help="run the default scene: a cantilever under gravity, FEM beside springs",
        description=(
            "Run the default scene (shipped with the package): a cantilever released from rest "
            "under gravity, Neo-Hookean FEM beside a mass-spring copy on the same mesh, implicit "
            "Euler. Writes a VTU series per body, an MP4 and PNG frames side by side, and prints "
            "each body's tip deflection against the static value of beam theory with its run time."
        ),
    )
    _add_run_options(demo, out_default="demo_output")
    demo.add_argument("--print-scene", action="store_true", help="print the demo's scene file and exit")
    _add_common(demo)
    demo.set_defaults(func=_demo)

    run = sub.add_parser(
        "run", formatter_class=_Formatter,
        help="run a scene file (TOML)",
        description="Run a scene file: simulate each body variant, write VTU series and render.",
        epilog=_scene_help(),
    )
    run.add_argument("scene", metavar="SCENE.toml", nargs="?", help="the scene file")
    _add_run_options(run, out_required=False)  # --out is checked in _run: --resume DIR needs none
    run.add_argument("--variant", action="append", metavar="NAME",
                     help="run only this variant (repeatable; default all)")
    run.add_argument("--checkpoint-every", type=_non_negative_int, metavar="N",
                     help="write a checkpoint every N steps (default the scene's [output] "
                          "checkpoint_every; checkpoints are always written on Ctrl-C and at the end)")
    run.add_argument("--ranks", type=_positive_int, metavar="N",
                     help="run on N MPI ranks: starts `mpiexec -n N` on this command (the scene must "
                          'solve with linear_solver = "petsc"; needs the [mpi] extra)')
    run.add_argument("--resume", metavar="DIR",
                     help="continue the run whose output is in DIR from its last checkpoints; the "
                          "result is bit for bit that of an uninterrupted run")
    _add_common(run)
    run.set_defaults(func=_run)

    render = sub.add_parser(
        "render", formatter_class=_Formatter,
        help="render a run's VTU series to MP4, GIF or PNG frames",
        description=(
            "Render the VTU series in DIR (a run directory with series.pvd, or the output "
            "directory of `run`/`demo`, whose variants are drawn side by side) off-screen."
        ),
    )
    render.add_argument("dir", metavar="DIR", help="output directory of a run")
    render.add_argument("--format", choices=("mp4", "gif", "png"), default="mp4")
    render.add_argument("--output", "-o", metavar="PATH",
                        help="file (mp4/gif) or directory (png) to write; default DIR/movie.FORMAT or DIR/png")
    render.add_argument("--size", type=_render_side, nargs=2, default=(960, 540), metavar=("W", "H"),
                        help="image size in pixels (at most 8192 each)")
    render.add_argument("--color-by", choices=("von_mises", "displacement", "body"), default="von_mises")
    render.add_argument("--fps", type=_positive_int, default=30, help="frames per second (mp4, gif)")
    render.add_argument("--every", type=_positive_int, default=1, help="render every N-th frame")
    render.add_argument("--warp", type=_warp, default="auto", metavar="auto|FACTOR",
                        help="magnify the displacement drawn: auto (when the deflection is under "
                             "5%% of the body's size, no ground), or a factor such as 1 or 100")
    _add_common(render)
    render.set_defaults(func=_render)

    info = sub.add_parser(
        "info", formatter_class=_Formatter,
        help="counts, quality and boundaries of a mesh file",
        description="Print a tet mesh's counts, element quality, boundaries and validation verdict. "
                    "MESH is any tet mesh meshio reads (.vtu, .msh, ...) or a scene file (.toml).",
    )
    info.add_argument("mesh", metavar="MESH", nargs="+", help="mesh files, or scene files")
    _add_common(info)
    info.set_defaults(func=_info)

    study = sub.add_parser(
        "study", formatter_class=_Formatter,
        help="error against run time, and stability on stiff and extreme cases",
        description=(
            "accuracy: sweep bodies, element orders, meshes, integrators and time steps on "
            "analytic cantilevers; record error and wall time; plot error against run time with "
            "the Pareto front.  stability: sweep stiffness, Poisson ratio and time step for every "
            "integrator and body, plus extreme cases; a verdict per run and a stability map. "
            "Results are written as each run finishes; run again to resume."
        ),
    )
    study.add_argument("which", choices=("accuracy", "stability"))
    study.add_argument("--out", required=True, metavar="DIR", help="output directory (created; resumable)")
    study.add_argument("--quick", action="store_true", help="a small sweep (seconds, for tests and a first look)")
    study.add_argument("--workers", type=_positive_int, default=None,
                       help="worker processes (default: one per core)")
    study.add_argument("--serial", action="store_true", help="run in this process, one run at a time")
    study.add_argument("--scheduler", metavar="ADDRESS",
                       help="run on a Dask cluster, e.g. tcp://host:8786 (needs fem_elastic[cluster])")
    _add_common(study)
    study.set_defaults(func=_study)
    return p


def main(argv=None) -> int:
    """Entry point of the ``fem-elastic`` command; returns the exit status.

    No input ends it with a raw traceback: see the module notes for what each
    outcome prints and the exit statuses; ``--debug`` adds the traceback.
    """
    _usable_streams()
    debug = "--debug" in (sys.argv[1:] if argv is None else [str(a) for a in argv])
    restore = _watch_ctrl_c()
    try:
        return _main(argv)
    except SystemExit:  # argparse's --help and usage errors: their own message and status
        raise
    except BaseException as exc:  # noqa: BLE001 - the one place every error becomes a message
        return _report(exc, debug)
    finally:
        restore()


#: Set when a Ctrl-C (SIGINT) reached the command (see :func:`_watch_ctrl_c`).
_ctrl_c_seen = False


def _note_ctrl_c(signum, frame):
    """Python's own SIGINT behaviour (raise KeyboardInterrupt), remembering that it happened."""
    global _ctrl_c_seen
    _ctrl_c_seen = True
    raise KeyboardInterrupt


def _watch_ctrl_c() -> Callable[[], None]:
    """Remember a Ctrl-C, so that it is reported as one whatever exception it turns into.

    A KeyboardInterrupt raised inside some C code does not come out as itself: numpy's array
    comparison, interrupted, falls back to another path and raises ``TypeError: Cannot compare
    structured arrays ...`` (seen once in ``tests/test_cli_robustness.py``). Only where the
    handler is still Python's default one, in the main thread. Returns what puts the default
    handler back (the command may run inside a longer process: a test, a notebook).
    """
    import signal

    try:
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, _note_ctrl_c)

            def restore() -> None:
                signal.signal(signal.SIGINT, signal.default_int_handler)

            return restore
    except ValueError:  # not the main thread: leave it
        pass
    return lambda: None


def _main(argv) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else [str(a) for a in argv])  # for --ranks
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    logging.captureWarnings(True)  # a StabilityWarning reads as a message, not a source line
    if args.command is None:
        parser.print_help()
        return _EXIT_USAGE
    return args.func(args)


def _usable_streams() -> None:
    """Give the command a stdout and stderr it can always write to.

    A stream closed by the caller (``fem-elastic ... >&-``: Python then has
    None) becomes the null device; text the stream's encoding cannot show (an
    ASCII locale) is escaped (``\\xe9``) instead of raising UnicodeEncodeError.
    """
    import os

    for name in ("stdout", "stderr"):
        stream = getattr(sys, name)
        if stream is None:
            setattr(sys, name, open(os.devnull, "w", encoding="utf-8"))  # noqa: SIM115 - lives to exit
        elif hasattr(stream, "reconfigure"):
            try:
                stream.reconfigure(errors="backslashreplace")
            except (ValueError, OSError):  # a stream that cannot change now (already used, detached)
                pass


def _one_line(text: object) -> str:
    return " ".join(part.strip() for part in str(text).splitlines() if part.strip())


def _report(exc: BaseException, debug: bool) -> int:
    """Say what ended the command in one line on stderr (with the traceback under --debug)."""
    from ..errors import FemElasticError, InvalidMesh, InvalidParameter

    if isinstance(exc, BrokenPipeError):
        # the reader of our output went away (`fem-elastic info MESH | head`): stop quietly
        import os

        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return _EXIT_FAILED
    if debug and not isinstance(exc, KeyboardInterrupt):
        import traceback

        traceback.print_exception(type(exc), exc, exc.__traceback__, file=sys.stderr)
    if isinstance(exc, KeyboardInterrupt) or _ctrl_c_seen:
        # (an error that a Ctrl-C turned into, in C code, is the interruption too)
        message, status = "interrupted", _EXIT_INTERRUPTED
    elif isinstance(exc, FemElasticError):  # a bad input (2), or a computation that failed (1:
        # fe.Diverged and fe.StepFailed among them)
        message = f"error: {_one_line(exc)}"
        status = _EXIT_USAGE if isinstance(exc, (InvalidParameter, InvalidMesh)) else _EXIT_FAILED
    elif isinstance(exc, FileNotFoundError):
        message, status = f"error: no such file: {exc.filename}", _EXIT_USAGE
    elif isinstance(exc, OSError):
        # a path the user gave that cannot be read or written: a directory where a file is
        # expected, a file where a directory is, no permission, a full disk
        where = f": {exc.filename}" if exc.filename else ""
        message = f"error: {exc.strerror or _one_line(exc)}{where}; check the path and its permissions."
        status = _EXIT_USAGE
    else:
        hint = "" if debug else " Run the command again with --debug to see the traceback."
        message = (f"unexpected error: {type(exc).__name__}: {_one_line(exc)[:500]} (a bug, or an input "
                   f"fem_elastic does not check yet; please report it).{hint}")
        status = _EXIT_INTERNAL
    try:
        sys.stderr.write(f"fem-elastic: {message}\n")
        sys.stderr.flush()
    except (OSError, ValueError):  # stderr is gone too: the status says it
        pass
    return status


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
