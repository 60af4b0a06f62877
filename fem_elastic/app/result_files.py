"""Saving results made in Python as run directories: ``traj.save(dir)``, ``result.save(dir)``.

The same format ``fem-elastic run`` writes (:mod:`fem_elastic.app.output`):
``series.pvd``, ``frames/`` and ``summary.json``, so :func:`fe.read_series`,
``fe.render`` and ParaView read a saved result as they read a scene's run.
The writers are registered with :mod:`fem_elastic.physics.result_view` when
this module is imported (``import fem_elastic`` does), since the results live
in layers below this one.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..dynamics.state import State
from ..physics import result_view
from .output import LOAD_FACTOR_UNIT, SeriesWriter
from .run_lock import RunLock, _is_run_dir, check_output_dir
from .static_run import static_figures

__all__ = ["save_trajectory", "save_static_result", "dynamic_figures", "probe_figures"]


def _open_run_dir(run_dir, overwrite: bool) -> Path:
    """The checked, existing ``run_dir`` to save into (see :func:`save_trajectory`)."""
    path = Path(run_dir) if run_dir is not None else None
    # a directory that holds a saved result (and nothing else) is replaced without asking
    again = path is not None and path.is_dir() and _is_run_dir(path)
    path = check_output_dir(run_dir, overwrite=overwrite or again, option="save(..., overwrite=True)")
    path.mkdir(parents=True, exist_ok=True)
    return path


def save_trajectory(traj, run_dir, model, *, overwrite: bool = False) -> Path:
    """Write a :class:`fe.Trajectory` of ``model`` as a run directory; return ``run_dir``.

    Every recorded frame is written; the trajectory's final state is the last
    frame exactly. Frames record vertex values only, so for a P2 body the
    mid-edge nodes of the other frames are at their edge's mean
    (:func:`~fem_elastic.physics.pyvista_grid.nodal_positions`), and so are the
    stresses computed there.

    ``run_dir`` must be new, empty or a result saved before (which is replaced);
    a directory holding other files is refused (:class:`fe.InvalidParameter`)
    unless ``overwrite`` (then files with a run's names, ``series.pvd``,
    ``summary.json``, ``frames/frame_*.vtu``, are replaced and the others left).
    The directory is locked (:class:`~fem_elastic.app.run_lock.RunLock`) while
    it is written: a second writer gets :class:`fe.OutputInUse`.
    """
    run_dir = _open_run_dir(run_dir, overwrite)
    with RunLock(run_dir):
        _write_trajectory(traj, run_dir, model)
    return run_dir


def _write_trajectory(traj, run_dir: Path, model) -> None:
    writer = SeriesWriter(model, run_dir, every=1, info={"variant": Path(run_dir).name})
    for k, t in enumerate(traj.times):
        x, v = traj._frame_dofs(k, model)  # the DOFs traj.to_pyvista(k) draws
        writer.write_state(State(x, v, float(t)))
    # as the command records it: "diverged" / "failed" from fe.Diverged / fe.StepFailed's
    # trajectory (its message says which), "interrupted" for one stopped any other way
    word = traj.message.split(" ", 1)[0] if traj.message else ""
    status = word if word in ("completed", "diverged", "failed") else "interrupted"
    writer.finish(traj, status=status, extra=dynamic_figures(model, traj))


def save_static_result(result, run_dir, model, *, overwrite: bool = False) -> Path:
    """Write a :class:`fe.StaticResult`'s load path as a run directory; return ``run_dir``.

    Each converged point is a frame whose time is its load factor (as a static
    scene's run); ``summary.json`` holds :func:`~fem_elastic.app.static_run.static_figures`.
    ``run_dir`` and ``overwrite`` as in :func:`save_trajectory` (checked, locked).
    """
    run_dir = _open_run_dir(run_dir, overwrite)
    with RunLock(run_dir):
        _write_static_result(result, run_dir, model)
    return run_dir


def _write_static_result(result, run_dir: Path, model) -> None:
    writer = SeriesWriter(model, run_dir, every=1, info={"variant": Path(run_dir).name},
                          time_unit=LOAD_FACTOR_UNIT)
    v0 = np.zeros(model.ndofs)
    points = list(result.path) or []
    for point in points:
        writer.write_state(State(point.x, v0, float(point.load_factor)))
    extra = static_figures(model, result)
    extra.update({"steps": max(len(points) - 1, 0), "t_end": float(result.load_factor)})
    writer.finish(None, status="completed" if result.converged else "failed",
                  message=result.message, extra=extra,
                  final_state=State(result.x, v0, float(result.load_factor)))


def probe_figures(model, probes, times, displacement) -> dict:
    """The displacement over time of named points (the scene's ``[probe]``), for ``summary.json``.

    Each point is followed at the mesh vertex nearest to it (the vertex and
    its distance are recorded with it).

    Parameters
    ----------
    model : Model
    probes : dict of str to (3,) array_like
        Named reference points (m).
    times : array_like
        ``(T,)`` frame times (s) or load factors.
    displacement : array_like
        ``(T, n_vertices, 3)`` vertex displacements (m).

    Returns
    -------
    dict
        ``{name: {"point", "vertex", "distance" (m), "times", "displacement" ((T, 3), m),
        "final" ((3,), m)}}``.
    """
    X = np.asarray(model.mesh.p, dtype=float).T
    u = np.asarray(displacement, dtype=float)
    out = {}
    for name, point in (probes or {}).items():
        point = np.asarray(point, dtype=float)
        d = np.linalg.norm(X - point, axis=1)
        k = int(np.argmin(d))
        out[name] = {"point": point.tolist(), "vertex": k, "distance": float(d[k]),
                     "times": np.asarray(times, dtype=float).tolist(),
                     "displacement": u[:, k].tolist(), "final": u[-1, k].tolist()}
    return out


def dynamic_figures(model, traj, probes=None) -> dict:
    """The physical result of a time-stepping run, for ``summary.json`` and the run table.

    ``max_displacement`` (m, over every frame) with its vertex, vector and time
    (``max_displacement_time``, s); ``final_max_displacement`` (m); the support
    reactions at the final state (``reactions``, N per support: the model's
    energy gradient on the held DOFs, the inertia of held nodes being zero with
    a lumped mass); ``probes`` (:func:`probe_figures`) when points are named.
    Energies and ``min_det_F`` are in the trajectory's own summary.
    """
    u = np.asarray(traj.displacement, dtype=float)
    norms = np.linalg.norm(u, axis=2)
    norms = np.where(np.isfinite(norms), norms, -1.0)
    t, k = np.unravel_index(int(np.argmax(norms)), norms.shape) if norms.size else (0, 0)
    out = {"max_displacement": float(max(norms[t, k], 0.0)) if norms.size else 0.0,
           "max_displacement_vertex": int(k), "max_displacement_time": float(traj.times[t]),
           "max_displacement_vector": u[t, k].tolist() if norms.size else [0.0] * 3,
           "final_max_displacement": float(max(norms[-1].max(), 0.0)) if norms.size else 0.0}
    final = traj.final_state
    groups = list(model.fixed_groups) + list(model.prescribed_groups)
    if final is not None and groups:
        from .static_run import reactions_by_support

        g = np.asarray(model.gradient(final.x), dtype=float).reshape(-1, 3)
        held = np.zeros(model.ndofs, dtype=bool)
        held[model.held_dofs] = True
        g = np.where(held.reshape(-1, 3), g, 0.0)
        out["reactions"] = reactions_by_support(model, lambda where: g[model.boundary_nodes(where)].sum(axis=0))
    if probes:
        out["probes"] = probe_figures(model, probes, traj.times, u)
    return out


result_view.register_writer("trajectory", save_trajectory)
result_view.register_writer("static", save_static_result)
