"""The accuracy study: error against run time on cantilevers with closed-form answers.

Every run builds a cantilever (``fe.beam_mesh``, clamped on ``"left"``), solves
one problem with one method, and records its relative error against the
analytic value and its wall time. The sweep covers the body (``"springs"``:
``fe.MassSpring``; ``"linear"``, ``"corotated"``, ``"stvk"``, ``"neo_hookean"``:
``fe.ElasticBody`` of ``fe.LinearElastic``, ``fe.Corotated``, ``fe.StVK``,
``fe.NeoHookean``), the element order (P1, P2), the mesh and, for dynamics,
the integrator (all seven) and the time step.

Problems and references
-----------------------
``static_tip``, ``self_weight`` (slender beam, L / h = 20)
    Tip deflection (the area mean of u_z over the end face, the work-conjugate
    of a uniform end traction) under a small tip load and under gravity,
    against **Timoshenko** theory (``RectangularCantilever.tip_load_timoshenko``,
    ``distributed_load_timoshenko``). Timoshenko rather than Euler-Bernoulli
    because a 3-D body deforms in shear, which Timoshenko includes (+0.2 % of
    the deflection at L / h = 20); what neither includes is the 3-D clamp (the
    fixed face also stops the section's warping and Poisson contraction), which
    stiffens the root: the 3-D limit sits a few 0.1 % below Timoshenko. That
    gap is the beam model's own error floor; the report estimates it from the
    finest P2 meshes (Richardson extrapolation when three uniformly refined
    levels are present).
``large_deflection`` (same beam)
    Tip deflection under a dead tip load with ``alpha = P L^2 / (E I)`` of
    order 1, against the exact elastica (:func:`fem_elastic.physics.analytic.elastica_tip`).
    Rotations are large, strains small (alpha h / (2 L)): the geometrically
    nonlinear bodies reduce to the elastica; linear FEM cannot (it predicts
    alpha / 3) and is included to show by how much it fails.
``modal`` (same beam)
    First natural frequency from ``fe.natural_frequencies`` (consistent mass)
    against Euler-Bernoulli, ``first_bending_frequency``.
``dynamic`` (a stockier beam, L / h = 10)
    The beam is released from rest in its first mode shape (the lumped-mass
    mode of its own discretization, which every integrator uses, scaled to a
    tip amplitude of 0.1 mm) and simulated for one period; the frequency of the
    sampled tip deflection (an order-2 Prony fit, exact for a single damped
    mode) is compared with Euler-Bernoulli (``rel_error``) and with the
    discretization's own lumped modal frequency (``time_error``: the error of
    the time integration alone, which ``time_error_predicted`` gives in closed
    form from the scheme's one-step map on the modal oscillator). The stockier beam keeps the explicit
    schemes affordable: their stable step is set by the highest frequency, and
    omega_max / omega_1 grows as (L / h)^2.
``linearized`` (the dynamic beam)
    The accuracy ``fe.LinearizedImplicitEuler`` (one Newton step per time step)
    gives up against ``fe.ImplicitEuler`` (Newton to convergence) at the same
    dt, on a large motion: released from a large static deflection (alpha = 1)
    for one period. ``rel_error`` is the largest distance between the two tip
    trajectories over the run, relative to the largest tip displacement. A
    ``reference`` run (Newmark, many steps per period) also gives each
    scheme's own error.

``methods`` (the dynamic beam, P1)
    Trapezoid, velocity Verlet, PBD, XPBD, shape matching and projective
    dynamics on a static sag, the first-mode period and a large deflection,
    each against the converged FEM answer on the same mesh for the energy it
    approximates, each swept over its own knob (dt, iterations, substeps or
    clusters): :mod:`~fem_elastic.study.accuracy_methods`. Its rows have their
    own report section and figure (``methods_error_vs_time.png``).

Each row has ``rel_error`` (signed, relative), ``abs_error`` = ``|rel_error|``,
``seconds_solve`` (s, wall time of the solve, eigen-solve or simulation only:
the mesh, the model and the initial state are built outside it; a solve under
0.25 s is repeated up to five times and the fastest call kept, as timeit does,
since other load only ever adds time) and ``seconds`` (s, the whole case, from
:func:`fem_elastic.study.executor.run_sweep`). Each worker process first runs
every body and integrator once on a tiny beam, so that no case pays for
compiling kernels or importing solvers.

After the sweep, the dynamic rows get ``space_error`` (the mesh's lumped modal
frequency against the reference) and ``error_bound`` = ``|space_error| +
|time_error|``, the other rows ``error_bound`` = ``abs_error``: the report
ranks runs by it (:func:`candidates`), so that a run whose measured error is
small only because the mesh's and the integrator's errors cancel is never
recommended.

The code is split by concept: :mod:`~fem_elastic.study.accuracy_cases` (the
sweep and running one case), :mod:`~fem_elastic.study.accuracy_analysis` (the
rows' post-processing, the report's candidates, error floors),
:mod:`~fem_elastic.study.accuracy_plots` (the figure) and
:mod:`~fem_elastic.study.accuracy_report` (``report.md``); this module runs
the study and re-exports their public names.

Examples
--------
>>> from fem_elastic.study.accuracy import accuracy_cases, run_accuracy_case
>>> case = next(c for c in accuracy_cases(quick=True) if c.id == "static_tip/linear/P2/10x1x1")
>>> row = run_accuracy_case(case.params)
>>> row["reference_name"], abs(row["rel_error"]) < 0.05   # P2 on 10 cells: -2.2 %
('Timoshenko', True)
"""

from __future__ import annotations

import time
from pathlib import Path

from .accuracy_analysis import _postprocess, _public, candidates, error_floor
from .accuracy_cases import BODIES, INTEGRATORS, PROBLEMS, accuracy_cases, prony_frequency, run_accuracy_case
from .accuracy_methods import METHODS, plot_methods
from .accuracy_plots import plot_error_vs_time
from .accuracy_report import BUDGETS, write_report
from .executor import run_sweep
from .report import StudyResult, finish_study

# the beams' constants, importable from here as before the study was split into modules
from .accuracy_cases import (
    ALPHA_LARGE as ALPHA_LARGE,
    ALPHA_RELEASE as ALPHA_RELEASE,
    AMPLITUDE as AMPLITUDE,
    GRAVITY as GRAVITY,
    SLENDER as SLENDER,
    SPRING_NU as SPRING_NU,
    STOCKY as STOCKY,
    TIP_TRACTION as TIP_TRACTION,
)

__all__ = [
    "StudyResult",
    "run_accuracy_study",
    "accuracy_cases",
    "run_accuracy_case",
    "prony_frequency",
    "error_floor",
    "candidates",
    "write_report",
    "plot_error_vs_time",
    "PROBLEMS",
    "BODIES",
    "INTEGRATORS",
    "METHODS",
    "plot_methods",
    "BUDGETS",
]


# --- the study ------------------------------------------------------------------------------


def run_accuracy_study(out_dir, *, quick: bool = False, executor=None, workers=None, progress: bool = True,
                       _case_filter=None) -> StudyResult:
    """Run the accuracy study and write its results, figure and report to ``out_dir``.

    Parameters
    ----------
    out_dir : str or os.PathLike
        Created if missing. Holds ``results.jsonl`` (every run, appended as it
        finishes; a second call resumes and runs only what is missing),
        ``results.csv``, ``error_vs_time.png`` and ``report.md``.
    quick : bool
        The small sweep (seconds) instead of the full one (minutes).
    executor : None, "process", "serial", concurrent.futures.Executor or dask.distributed.Client
        Where the runs go (:func:`fem_elastic.study.executor.run_sweep`): by
        default a process pool of ``workers`` processes. On a Dask cluster::

            from dask.distributed import Client
            client = Client("tcp://scheduler:8786")
            fe.study.run_accuracy_study("results/accuracy", executor=client)

        Note that run times measured on a cluster depend on its nodes.
    workers : int, optional
        Processes of the default pool (``os.cpu_count()`` if None).
    progress : bool
        Show a progress bar (tqdm).

    Returns
    -------
    StudyResult

    Raises
    ------
    fem_elastic.study.SweepIncomplete
        When the executor lost runs; what finished is kept, call again to resume.
    """
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    cases = accuracy_cases(quick)
    if _case_filter is not None:  # tests: a subset of the sweep
        cases = [c for c in cases if _case_filter(c)]
    rows = run_sweep(cases, run_accuracy_case, out_dir, executor=executor, workers=workers, progress=progress,
                     desc="accuracy study")
    _postprocess(rows)
    return finish_study("accuracy study", rows, out_dir, t0=t0, n_run=rows.n_run, quick=quick,
                        table=_public(rows),
                        figures=lambda: [(plot_error_vs_time(rows), "error_vs_time.png"),
                                         (plot_methods(rows), "methods_error_vs_time.png")],
                        write_report=write_report)
