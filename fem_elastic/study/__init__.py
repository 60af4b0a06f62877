"""Studies of fem_elastic against analytic answers: error against run time, and stability.

- :func:`run_accuracy_study` (``fem-elastic study accuracy``): analytic
  cantilevers swept over body, element order, mesh, integrator and dt; the
  error of each run against its closed form and its wall time, with the
  Pareto front of error against run time.
- :func:`run_stability_study` (``fem-elastic study stability``): every
  integrator on stiff and extreme cases, with a verdict per run.
- :func:`measure_scaling`: the time of assembly, an implicit and an explicit
  step against the number of tets on this machine, and the fitted exponents
  (:class:`ScalingResult`, :func:`fit_power_law`).

The accuracy and stability studies run their cases through :func:`run_sweep`
(``fem_elastic.study.executor``): processes by default, or a Dask cluster by
passing a ``dask.distributed.Client`` as ``executor``; each row is appended to
``results.jsonl`` as it finishes, so an interrupted study resumes where it stopped.
"""

from .accuracy import StudyResult, run_accuracy_study
from .executor import Case, SweepIncomplete, read_results, run_sweep, write_csv
from .scaling import ScalingResult, fit_power_law, measure_scaling
from .stability import run_stability_study

__all__ = [
    "Case",
    "StudyResult",
    "SweepIncomplete",
    "read_results",
    "run_sweep",
    "write_csv",
    "run_accuracy_study",
    "run_stability_study",
    "ScalingResult",
    "fit_power_law",
    "measure_scaling",
]
