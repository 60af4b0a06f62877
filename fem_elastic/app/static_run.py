"""Running a static scene (``[solve] kind = "static"``): its load path as a VTU series.

:func:`run_static_variant` solves one built run with :func:`fe.solve_static`
and writes every converged point of the load path as a frame of the run
directory's series (``series.pvd``, whose "time" is the load factor), then
``summary.json`` with the physical result: the largest displacement and the
reaction on each support (:func:`static_figures`). A solve that stops short of
the full load writes the path it reached and the summary says ``"failed"`` and why.
"""

from __future__ import annotations

import logging
import time
import warnings
from pathlib import Path

import numpy as np

from ..errors import NotConverged

__all__ = ["run_static_variant", "static_figures"]

log = logging.getLogger(__name__)


def _support_name(where) -> str:
    if hasattr(where, "body") and hasattr(where, "where"):  # a fe.MultiBody's BodyBoundary
        return f"{where.body}:{_support_name(where.where)}"
    if isinstance(where, str):
        return where
    if isinstance(where, (list, tuple)) and where and all(isinstance(w, str) for w in where):
        return "+".join(where)
    return f"vertices ({np.size(where)})"


def reactions_by_support(model, force_on) -> dict:
    """``{support name: [Fx, Fy, Fz]}`` (N) over the model's fixed and prescribed supports.

    ``force_on(where)`` gives the total force on one support; a name held by
    several groups (e.g. rollers in x and in z on one boundary) is reported once.
    """
    reactions: dict = {}
    for _, where, _ in list(model.fixed_groups) + list(model.prescribed_groups):
        name = _support_name(where)
        if name not in reactions:
            reactions[name] = [float(v) for v in force_on(where)]
    return reactions


def static_figures(model, result) -> dict:
    """The physical result of a static solve, in plain values for ``summary.json``.

    ``max_displacement`` (m) and the vertex it is at, ``reactions`` (N) on every
    fixed or prescribed support by name, the load factor reached, the number of
    load steps and the stability check.
    """
    u = np.asarray(result.displacement)
    norms = np.linalg.norm(u, axis=1)
    k = int(np.argmax(norms)) if norms.size else 0
    reactions = reactions_by_support(model, result.reaction_force)
    return {
        "solve": "static",
        "converged": bool(result.converged),
        "load_factor": float(result.load_factor),
        "load_steps": len(result.load_steps),
        "newton_iterations": int(result.iterations),
        "max_displacement": float(norms[k]) if norms.size else 0.0,
        "max_displacement_vertex": k,
        "max_displacement_vector": [float(v) for v in u[k]] if norms.size else [0.0, 0.0, 0.0],
        "reactions": reactions,
        "min_eigenvalue": None if result.min_eigenvalue is None else float(result.min_eigenvalue),
        "stable": result.stable,
        "wall_time": float(result.wall_time),
    }


def run_static_variant(run, out_dir):
    """Solve one static run of a scene and write its load path and summary.

    Parameters
    ----------
    run : BuiltRun
        With ``run.static`` set (``[solve] kind = "static"``).
    out_dir : path-like
        The scene's output directory; the run goes to ``out_dir / run.name``.

    Returns
    -------
    RunOutcome
        ``status`` ``"completed"`` or ``"failed"`` (the full load not reached);
        ``result`` is the :class:`fe.StaticResult`, ``figures`` the physical result.
    """
    from ..dynamics.state import State
    from .output import LOAD_FACTOR_UNIT, SeriesWriter
    from .runner import RunOutcome

    model = run.model
    run_dir = Path(out_dir) / run.name
    writer = SeriesWriter(model, run_dir, every=1, info=run.info, time_unit=LOAD_FACTOR_UNIT)
    t0 = time.perf_counter()
    status, message = "completed", ""
    caught = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = run.solve()
    except NotConverged as err:
        result, status, message = err.result, "failed", str(err)
    except KeyboardInterrupt:
        writer.finish(None, status="interrupted", message="interrupted during the static solve")
        raise
    for w in caught:  # an unstable equilibrium, say: keep it in the log and the summary
        log.warning("%s: %s", run.name, w.message)
    v0 = np.zeros(model.ndofs)
    for point in result.path:
        writer.write_state(State(point.x, v0, float(point.load_factor)))
    elapsed = time.perf_counter() - t0
    figures = static_figures(model, result)
    probes = (run.info or {}).get("probe")
    if probes and len(result.path):
        from .result_files import probe_figures

        figures["probes"] = probe_figures(model, probes, result.path.load_factors,
                                          result.path.displacements)
    if caught:
        figures["warnings"] = [str(w.message) for w in caught]
    message = message or result.message
    extra = dict(figures)
    extra.update({"steps": len(result.path) - 1, "t_end": float(result.load_factor),
                  "wall_time": elapsed})
    last = result.path[-1]
    writer.finish(None, status=status, message=message, extra=extra,
                  final_state=State(last.x, v0, float(last.load_factor)))
    return RunOutcome(run.name, run_dir, status, message, None, elapsed, writer.seconds_output, run,
                      result=result, figures=figures)
