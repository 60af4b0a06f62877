"""Helpers shared by the studies' reports: Pareto fronts, markdown tables, number formats, figures,
and :func:`finish_study`, what every study does once its sweep has run.

Nothing here knows about a particular study: rows are dicts (as
:func:`fem_elastic.study.executor.run_sweep` returns them) and the helpers
take the names of the keys to use. matplotlib is imported only inside the
functions that draw.
"""

from __future__ import annotations

import importlib.util
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

__all__ = [
    "StudyResult",
    "finish_study",
    "finite",
    "pareto_front",
    "fastest_within",
    "markdown_table",
    "fmt_pct",
    "fmt_seconds",
    "fmt_float",
    "draw_pareto",
    "save_figure",
    "MARKERS",
]

logger = logging.getLogger(__name__)

#: Marker styles, one per method/body, in a fixed order (readable in black and white too).
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "*")


def finite(value) -> bool:
    """True for a real, finite number (not None, NaN or inf)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def pareto_front(rows, x: str = "seconds_solve", y: str = "abs_error", rtol: float = 1e-9) -> list[dict]:
    """The rows not dominated in (x, y), both to be minimised, sorted by x.

    A row is on the front if no other row is at least as good in both and
    strictly better in one. Rows whose x or y is not a finite number (failed
    runs) are ignored; ties in x keep the smaller y.

    Parameters
    ----------
    rows : iterable of dict
    x, y : str
        Keys of the two objectives (e.g. wall time in s and relative error).
    rtol : float
        y values within this relative distance count as equal, so that runs
        whose errors differ only by round-off (the same discretization with
        materials that agree at small strain) do not all join the front.

    Returns
    -------
    list of dict
        The front, by increasing x (and so decreasing y).

    Examples
    --------
    >>> rows = [{"t": 1, "e": 0.5}, {"t": 2, "e": 0.1}, {"t": 3, "e": 0.2}, {"t": 0.5, "e": float("nan")}]
    >>> [r["t"] for r in pareto_front(rows, "t", "e")]
    [1, 2]
    """
    ok = [r for r in rows if finite(r.get(x)) and finite(r.get(y))]
    ok.sort(key=lambda r: (r[x], r[y]))
    front, best = [], math.inf
    for r in ok:
        if r[y] < best * (1.0 - rtol):
            front.append(r)
            best = r[y]
    return front


def fastest_within(rows, budget: float, x: str = "seconds_solve", y: str = "abs_error"):
    """The row with the smallest x among those with y <= budget, or None.

    Examples
    --------
    >>> rows = [{"t": 1, "e": 0.5}, {"t": 2, "e": 0.1}, {"t": 3, "e": 0.01}]
    >>> fastest_within(rows, 0.2, "t", "e")["t"], fastest_within(rows, 1e-3, "t", "e")
    (2, None)
    """
    ok = [r for r in rows if finite(r.get(x)) and finite(r.get(y)) and r[y] <= budget]
    return min(ok, key=lambda r: (r[x], r[y]), default=None)


def markdown_table(headers, rows) -> str:
    """A GitHub-flavoured markdown table; cells are converted with ``str``, ``|`` escaped.

    Examples
    --------
    >>> print(markdown_table(["a", "b"], [[1, "x|y"]]))
    | a | b |
    |---|---|
    | 1 | x\\|y |
    """

    def cell(v):
        return str(v).replace("|", "\\|").replace("\n", " ")

    lines = ["| " + " | ".join(cell(h) for h in headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def fmt_pct(value, digits: int = 2, signed: bool = True) -> str:
    """A ratio as a percentage with ``digits`` significant digits (``-0.35%``); '-' when not finite.

    Examples
    --------
    >>> fmt_pct(-0.0034567), fmt_pct(0.5, signed=False), fmt_pct(None), fmt_pct(-6.8e-12)
    ('-0.35%', '50%', '-', '-6.8e-10%')
    """
    if not finite(value):
        return "-"
    p = 100.0 * value
    if p == 0:
        return "0%"
    if abs(p) < 1e-3:  # tiny: scientific, not a string of zeros
        return f"{p:+.{max(digits - 1, 0)}e}%" if signed else f"{abs(p):.{max(digits - 1, 0)}e}%"
    decimals = max(0, digits - 1 - int(math.floor(math.log10(abs(p)))))
    return f"{p:+.{decimals}f}%" if signed else f"{p:.{decimals}f}%"


def fmt_seconds(value) -> str:
    """Wall time with 3 significant digits (``0.0123 s``); '-' when not finite.

    Examples
    --------
    >>> fmt_seconds(0.012345), fmt_seconds(12.5)
    ('0.0123 s', '12.5 s')
    """
    return f"{value:.3g} s" if finite(value) else "-"


def fmt_float(value, digits: int = 4) -> str:
    """``digits`` significant digits, '-' when not finite.

    Examples
    --------
    >>> fmt_float(3.14159), fmt_float(float("inf"))
    ('3.142', '-')
    """
    return f"{value:.{digits}g}" if finite(value) else "-"


def draw_pareto(ax, front, x: str = "seconds_solve", y: str = "abs_error", **style):
    """Draw a Pareto front as a step line (each member holds its error until the next, faster-but-worse one).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    front : list of dict
        As :func:`pareto_front` returns it (sorted by x).
    x, y : str
        Keys of the axes.
    **style
        Passed to ``ax.step`` (default: black, thin, ``where="post"``).
    """
    if not front:
        return None
    xs = [r[x] for r in front]
    ys = [r[y] for r in front]
    # extend to the right edge so that the last (most accurate) member's level is visible
    xs.append(xs[-1] * 3.0)
    ys.append(ys[-1])
    kw = dict(where="post", color="k", lw=1.0, alpha=0.7, label="Pareto front", zorder=1)
    kw.update(style)
    return ax.step(xs, ys, **kw)


def save_figure(fig, path) -> Path:
    """Save a matplotlib figure atomically (temporary file beside ``path``, fsync, ``os.replace``).

    The format follows ``path``'s suffix (``.png``, ``.pdf``, ``.svg``).
    """
    from ..files import _atomic_write

    path = Path(path)
    fmt = path.suffix.lstrip(".") or "png"
    return _atomic_write(path, lambda tmp: fig.savefig(tmp, format=fmt, bbox_inches="tight"))


@dataclass
class StudyResult:
    """What a study (:func:`fem_elastic.study.run_accuracy_study`, ``run_stability_study``) wrote.

    Attributes
    ----------
    rows : list of dict
        One per case (see the study's module docstring for the columns).
    csv_path, report_path : pathlib.Path
        ``results.csv`` and ``report.md``.
    figures : list of pathlib.Path
        The PNG figures written (none without matplotlib).
    n_run : int
        Cases run by this call (the others came from ``results.jsonl``).
    wall_time : float
        Wall time of this call (s).
    """

    rows: list
    csv_path: Path
    report_path: Path
    figures: list = field(default_factory=list)
    n_run: int = 0
    wall_time: float = 0.0


def finish_study(name, rows, out_dir, *, t0: float, n_run: int, quick: bool, table, figures,
                 write_report) -> StudyResult:
    """Write a swept study's ``results.csv``, figures and ``report.md``; return its :class:`StudyResult`.

    Parameters
    ----------
    name : str
        The study, for the log (e.g. ``"accuracy study"``).
    rows : list of dict
        The sweep's rows (``StudyResult.rows``).
    out_dir : pathlib.Path
        The study's directory (it exists: the sweep wrote ``results.jsonl`` there).
    t0 : float
        ``time.perf_counter()`` when the call started (s).
    n_run : int
        Cases the sweep ran in this call (``SweepRows.n_run``).
    quick : bool
        Passed to ``write_report``.
    table : list of dict
        The rows as written to ``results.csv`` and given to ``write_report``.
    figures : callable
        ``figures() -> [(matplotlib Figure or None, file name), ...]``, called only
        when matplotlib is installed; a None figure is skipped.
    write_report : callable
        ``write_report(table, path, *, quick, wall_time, n_run) -> Path``.

    Returns
    -------
    StudyResult
    """
    from .executor import write_csv

    csv_path = write_csv(table, out_dir / "results.csv")
    written = []
    if importlib.util.find_spec("matplotlib") is None:
        logger.warning("matplotlib is not installed (the [study] extra): the %s draws no figures", name)
    else:
        for fig, filename in figures():
            if fig is not None:
                written.append(save_figure(fig, out_dir / filename))
    wall = time.perf_counter() - t0
    report = write_report(table, out_dir / "report.md", quick=quick, wall_time=wall, n_run=n_run)
    logger.info("%s: %d cases (%d run by this call) in %.1f s; report %s", name, len(rows), n_run, wall, report)
    return StudyResult(rows=rows, csv_path=csv_path, report_path=report, figures=written, n_run=n_run,
                       wall_time=wall)
