"""The stability study: which integrator survives which stiffness, time step and extreme case.

``fem-elastic study stability [--quick] --out DIR`` runs, through
:func:`fem_elastic.study.run_sweep`, three kinds of case, each one row of
``results.jsonl``:

``sweep``
    Every integrator on every body (springs, linear, corotated, StVK,
    Neo-Hookean) of the kicked cantilever (:func:`stability_cases.cantilever`),
    over Young's modulus E in 1e3 ... 1e11 Pa (nu = 0.3), over nu = 0.49
    and 0.4999 (E = 1e7 Pa), and over dt: 1e-6 ... 1/24 s for the explicit
    schemes, 1e-2 and 1/24 s for the implicit ones (their failures come
    with large steps, and an implicit run costs 10-50 times an explicit one).
``critical``
    For each explicit integrator and each (body, E) of the E sweep, and
    the linear body on the nu sweep: the observed stability limit,
    bracketed by bisection on dt, beside the predicted one,
    :func:`fe.critical_time_step`.
``extreme``
    Every integrator and body on the extreme scenes of
    :mod:`fem_elastic.study.stability_cases`: inverted elements, crush to
    10 % and release, a 720-degree twist and release, a drop onto the
    ground at 20 m/s, nearly flat (sliver) elements, and a degenerate sliver
    mesh that validation must reject.
``methods``
    The methods of issue 16 (trapezoid, velocity Verlet, PBD, XPBD, shape
    matching, projective dynamics) on four hard scenes: stiff steel at
    dt = 1/30 s, near-incompressible, crush, huge steps
    (:mod:`fem_elastic.study.stability_methods`, which also says how their
    verdicts are judged).

A fixed number of steps, not a fixed duration
---------------------------------------------
Every sweep run takes :data:`SWEEP_STEPS` = 100 steps, whatever dt. An
instability is a per-step amplification: a mode whose one-step map has
spectral radius ``rho > 1`` multiplies its energy by ``rho^(2N)`` in N
steps, so a fixed N gives every dt the same power to reveal it, and costs
the same. A fixed duration would cost ``T / dt`` steps: 10^5 at the
smallest dt of the sweep. The kick (kinetic energy 1e-3 of the weight
times the length, spread over every mode) and the blow-up bound of
:func:`fe.simulate` (the total energy growing by more than the scene's
energy scale, here the weight times the length) then set the resolution:
with about 1/70 of the kick in the top mode, growth is detected within
N = 100 steps once ``rho^200 > ~7e4``, i.e. ``rho > 1.06``: symplectic
Euler (``rho - 1 ~ 2 sqrt(2 eps)`` at ``(1 + eps)`` times its limit
``2 / omega_max``) reaches that 0.04 % above it, RK4 (``rho - 1 ~ 7 eps``
near ``2 sqrt(2) / omega_max``) about 0.8 % above. Explicit Euler and explicit midpoint grow at
every dt on an undamped body (their predicted limit is 0); what the study
observes for them is the largest dt whose growth stays below the bound
for 100 steps, a finite-horizon limit that scales as ``N^(-1/2)``
(``N^(-1/4)`` for midpoint).

Verdicts
--------
Each run ends with one of

- ``stable``: all steps taken; with the energy drift
  ``(E_end - E_0) / S`` in % (``E_0`` the total energy once no boundary is
  driven; ``S`` the largest energy exchanged over that window: the
  largest of the swing of the total and of the potential energy and the
  kinetic energy, so that ``|drift| <= 100 %``), the largest rise of the total energy above
  ``E_0`` in the same units, and the smallest ``det F = V / V_0`` of any
  tet over the run (< 0: some element was inverted; the runs of the
  extreme cases and the soft beams do invert elements of every body but
  Neo-Hookean, which "stable" does not exclude);
- ``diverged``: :class:`fe.Diverged` at step k, with its reason
  (non-finite state, energy growth, an implicit step failing for a reason
  other than Newton);
- ``newton failed``: an implicit step whose Newton iterations did not
  converge even after halving dt (:class:`fe.Diverged` whose reason starts
  with "Newton did not converge", or :class:`fe.NotConverged`);
- ``rejected``: building the scene raised a typed error
  (:class:`fe.InvalidMesh`, :class:`fe.InvalidParameter`), with its message;
- ``work limit``: the run was stopped after :data:`WORK_LIMIT` Newton
  iterations plus line-search cuts (a deterministic cap, so that a run
  that crawls with cut after cut cannot hold the study for minutes);
- ``error``: anything else: a bug, listed first in the report.

A ``critical`` row's verdict is ``bracketed`` (a stable dt below an
unstable one, at most ``2^(1/256)`` apart, i.e. 0.27 %), ``stable at every
dt tried`` or ``unstable at every dt tried``.

The code is split by concept: :mod:`~fem_elastic.study.stability_sweep` (the
study's constants and its list of cases), :mod:`~fem_elastic.study.stability_cases`
(the scenes), :mod:`~fem_elastic.study.stability_run` (one run and its verdict),
:mod:`~fem_elastic.study.stability_summary` (summaries of the rows and the
conclusions), :mod:`~fem_elastic.study.stability_plots` (the figures) and
:mod:`~fem_elastic.study.stability_report` (``report.md``); this module runs the
study and re-exports their public names.
"""

from __future__ import annotations

import time
from pathlib import Path

from .executor import run_sweep
from .report import StudyResult, finish_study
from .stability_plots import plot_extreme, plot_stability_map
from .stability_report import write_report
from .stability_run import run_stability_case
from .stability_summary import conclusions, critical_dt_table, extreme_matrix, largest_stable_dt
from .stability_sweep import EXPLICIT, INTEGRATORS, SWEEP_STEPS, VERDICTS, WORK_LIMIT, study_cases

# constants not in __all__, importable from here as before the study was split into modules
from .stability_sweep import (
    BISECTIONS as BISECTIONS,
    EXPLICIT_MAX_FORCES as EXPLICIT_MAX_FORCES,
)

__all__ = [
    "INTEGRATORS",
    "EXPLICIT",
    "SWEEP_STEPS",
    "WORK_LIMIT",
    "VERDICTS",
    "StudyResult",
    "study_cases",
    "run_stability_case",
    "run_stability_study",
    "largest_stable_dt",
    "critical_dt_table",
    "extreme_matrix",
    "conclusions",
    "plot_stability_map",
    "plot_extreme",
    "write_report",
]


# ----------------------------------------------------------------------------------------------
# The study
# ----------------------------------------------------------------------------------------------
def run_stability_study(out_dir, *, quick: bool = False, executor=None, workers=None, progress: bool = True,
                        _case_filter=None) -> StudyResult:
    """Run the stability study and write its results, figures and report to ``out_dir``.

    Parameters
    ----------
    out_dir : str or os.PathLike
        Created if missing. Holds ``results.jsonl`` (every run, appended as it
        finishes; a second call resumes and runs only what is missing),
        ``results.csv``, ``stability_map.png``, ``extreme.png`` and ``report.md``.
    quick : bool
        The small study (78 cases, about 13 s on 2 cores) instead of the full
        one (1398 cases, about 3 min on 2 cores).
    executor : None, "process", "serial", concurrent.futures.Executor or dask.distributed.Client
        Where the runs go (:func:`fem_elastic.study.run_sweep`): by default a
        process pool of ``workers`` processes. On a Dask cluster::

            from dask.distributed import Client
            fe.study.run_stability_study("results/stability", executor=Client("tcp://scheduler:8786"))

    workers : int, optional
        Processes of the default pool (``os.cpu_count()`` if None).
    progress : bool
        Show a progress bar (tqdm).

    Returns
    -------
    StudyResult
        ``rows``, ``csv_path``, ``report_path``, ``figures``, ``n_run``, ``wall_time``.

    Raises
    ------
    fem_elastic.study.SweepIncomplete
        When the executor lost runs; what finished is kept, call again to resume.
    """
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    cases = study_cases(quick)
    if _case_filter is not None:  # tests: a subset of the study
        cases = [c for c in cases if _case_filter(c)]
    rows = run_sweep(cases, run_stability_case, out_dir, executor=executor, workers=workers, progress=progress,
                     desc="stability study")

    def figures():
        return [(plot_stability_map(rows), "stability_map.png"), (plot_extreme(rows), "extreme.png")]

    return finish_study("stability study", rows, out_dir, t0=t0, n_run=rows.n_run, quick=quick, table=rows,
                        figures=figures, write_report=write_report)
