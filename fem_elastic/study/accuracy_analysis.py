"""The accuracy study's rows after the sweep: post-processing, the report's candidates, error floors.

:func:`_postprocess` adds the figures that need more than one row (the dynamic
runs' space error and error bound, the linearized runs' errors against their
reference); :func:`candidates` picks the runs the report may recommend and
:func:`error_floor` estimates the error no run of a problem can get below.
The figure (:mod:`~fem_elastic.study.accuracy_plots`) and the report
(:mod:`~fem_elastic.study.accuracy_report`) read the rows through these.
"""

from __future__ import annotations

import math

import numpy as np

from .accuracy_cases import _cells_id
from .report import finite

__all__ = ["candidates", "error_floor"]


def _label(r) -> str:
    return "springs" if r["body"] == "springs" else f"{r['body']} P{r['order']}"


def _cells(r) -> str:
    return _cells_id(r["cells"])


def _ok(rows, problem=None, **match):
    out = []
    for r in rows:
        if r.get("status") != "ok" or (problem is not None and r.get("problem") != problem):
            continue
        if all(r.get(k) == v for k, v in match.items()):
            out.append(r)
    return out


def _postprocess(rows) -> None:
    """Add the figures that need more than one row, or the whole row, in place.

    - ``space_error``, ``error_bound`` (dynamic): the mesh's own error (its lumped modal
      frequency against the reference) and ``|space_error| + |time_error|``. The measured
      ``rel_error`` is their sum, and where the two have opposite signs it can be small by
      cancellation (Newmark's period elongation against a too-stiff mesh); the report picks runs
      by the bound so that it never recommends a run for a cancellation. Other rows:
      ``error_bound = abs_error``.
    - ``ie_error_vs_reference``, ``lie_error_vs_reference`` (linearized): each scheme's largest
      distance from its body's Newmark reference over the run, relative to the reference's
      largest tip displacement. The reference samples every ``sample_every`` of its steps, i.e.
      on the grid of the finest run's steps; a run with n steps per period matches every
      (N_finest / n)-th sample.
    """
    for r in _ok(rows):
        if r["problem"] == "dynamic":
            r["space_error"] = r["f_modal_lumped"] / r["reference"] - 1.0
            r["error_bound"] = abs(r["space_error"]) + abs(r["time_error"])
        elif finite(r.get("abs_error")):
            r["error_bound"] = r["abs_error"]
    def method(r):
        return r["body"], r["order"], _cells(r)

    refs = {method(r): r for r in _ok(rows, "linearized") if r["integrator"] == "Newmark"}
    for r in _ok(rows, "linearized"):
        ref = refs.get(method(r))
        if r["integrator"] == "Newmark" or ref is None:
            continue
        w_ref = np.asarray(ref["tip_history"])
        stride = round(ref["steps_per_period"] / ref["sample_every"] / r["steps_per_period"])
        sub = w_ref[::stride]
        amp = float(np.max(np.linalg.norm(sub, axis=1)))
        for key, out in (("tip_history", "lie_error_vs_reference"),
                         ("tip_history_implicit_euler", "ie_error_vs_reference")):
            w = np.asarray(r[key])
            n = min(len(w), len(sub))
            r[out] = float(np.max(np.linalg.norm(w[:n] - sub[:n], axis=1))) / amp


def candidates(rows, problem) -> list:
    """The completed runs of a problem that the report may recommend, with their selection error.

    Every completed run, except linear FEM on ``large_deflection``: it lacks the geometric
    nonlinearity the problem is about, and where it comes close to the elastica it is by a
    cancellation (P1 locking against the missing nonlinearity). The runs are ranked by
    ``error_bound`` (see :func:`run_accuracy_study`'s post-processing).

    Parameters
    ----------
    rows : list of dict
        The study's rows, post-processed (``RESULT.rows``).
    problem : str

    Returns
    -------
    list of dict
    """
    out = [r for r in _ok(rows, problem) if finite(r.get("error_bound"))]
    if problem == "large_deflection":
        out = [r for r in out if r["body"] != "linear"]
    return out


def _public(rows):
    """Rows without the trajectory histories (kept in results.jsonl, too long for the CSV)."""
    return [{k: v for k, v in r.items() if not k.startswith("tip_history")} for r in rows]


def _richardson(values):
    """(limit, observed order) from three values on meshes refined by 2; None when not monotone."""
    a, b, c = values
    d1, d2 = b - a, c - b
    if d1 == 0 or d2 == 0 or (d1 > 0) != (d2 > 0) or abs(d2) >= abs(d1):
        return None
    p = math.log2(d1 / d2)
    return c + d2 / (2.0**p - 1.0), p


def error_floor(rows, problem):
    """The error the problem's method cannot get below: the reference's own error, or the mesh's.

    - static_tip, self_weight, modal: the 3-D body's limit against beam theory (the clamp; shear
      and rotary inertia for the frequency), by Richardson extrapolation of the linear P2 runs on
      20x1x1, 40x2x2 and 80x4x4 when the sweep has them (exact), else the finest linear P2 run
      (its FE error adds to the floor: not exact, its size bounds the floor's);
    - large_deflection: the finest nonlinear P2 run (not exact);
    - dynamic: the dt -> 0 limit of the best mesh, its lumped-mass modal frequency (exact).

    Parameters
    ----------
    rows : list of dict
        The study's rows.
    problem : str
        One of :data:`PROBLEMS` except ``"linearized"``.

    Returns
    -------
    floor : float or None
        Relative error (signed); None when the rows have nothing to estimate it from.
    exact : bool
        Whether ``floor`` is an estimate of the limit (True) or a bound on its size (False).
    how : str
        How it was obtained, for the report.
    """
    if problem == "dynamic":
        dyn = _ok(rows, "dynamic")
        if not dyn:
            return None, False, ""
        best = min(dyn, key=lambda r: abs(r["f_modal_lumped"] / r["reference"] - 1.0))
        return (best["f_modal_lumped"] / best["reference"] - 1.0, True,
                f"the dt -> 0 limit on the best mesh ({_label(best)} {_cells(best)}): its lumped-mass modal frequency")
    if problem == "large_deflection":
        nl = [r for r in _ok(rows, problem) if r["body"] not in ("linear", "springs") and r["order"] == 2]
        if not nl:
            return None, False, ""
        finest = max(r["n_dofs"] for r in nl)
        best = min((r for r in nl if r["n_dofs"] == finest), key=lambda r: r["abs_error"])
        return (best["rel_error"], False,
                f"the finest nonlinear P2 run, {_label(best)} {_cells(best)}; the elastica ignores shear, the clamp "
                f"and material nonlinearity at strains ~ alpha h / (2 L)")
    p2 = {_cells(r): r for r in _ok(rows, problem, body="linear", order=2)}
    if not p2:
        return None, False, ""
    chain = [p2.get(c) for c in ("20x1x1", "40x2x2", "80x4x4")]
    if all(chain):
        rich = _richardson([r["value"] for r in chain])
        if rich is not None:
            limit, p = rich
            return (limit / chain[-1]["reference"] - 1.0, True,
                    f"Richardson extrapolation of linear P2 on 20x1x1, 40x2x2, 80x4x4, observed order {p:.2f}")
    finest = max(p2.values(), key=lambda r: r["n_dofs"])
    return (finest["rel_error"], False,
            f"the finest linear P2 mesh, {_cells(finest)}: the FE error adds to the floor, so this bounds its size")
