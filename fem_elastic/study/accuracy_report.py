"""The accuracy study's report: ``report.md``, with its conclusions generated from the rows.

:func:`write_report` writes the setup, each problem's error floor, the fastest
run within each of the :data:`BUDGETS`, the Pareto fronts, the statements on
locking, springs, the materials, large deflection and time integration, and
the table of every run.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..physics.analytic import elastica_tip
from .accuracy_analysis import _cells, _label, _ok, candidates, error_floor
from .accuracy_cases import _TITLES, ALPHA_LARGE, INTEGRATORS, PROBLEMS
from .report import fastest_within, finite, fmt_float, fmt_pct, fmt_seconds, markdown_table, pareto_front

__all__ = ["write_report", "BUDGETS"]

#: Error budgets of the report's recommendations (relative errors).
BUDGETS = (0.10, 0.01, 0.001)


def _describe(r) -> str:
    if r["problem"] in ("dynamic", "linearized"):
        dt = f"N={r['steps_per_period']}" if "steps_per_period" in r else f"dt={r['dt_over_critical']:g} dt_crit"
        integ = r["integrator"] if r["problem"] == "dynamic" else "LinearizedImplicitEuler"
        return f"{integ} {dt}, {_label(r)} {_cells(r)}"
    return f"{_label(r)} {_cells(r)}"


def _error_text(r) -> str:
    if r["problem"] == "dynamic":
        return (f"error {fmt_pct(r['rel_error'])} = space {fmt_pct(r['space_error'])} + time "
                f"{fmt_pct(r['time_error'])}")
    return f"error {fmt_pct(r['rel_error'])}"


def _budget_lines(rows, floor=None, exact=False):
    lines = []
    for budget in BUDGETS:
        best = fastest_within(rows, budget, y="error_bound")
        if best is not None:
            lines.append(f"  - within {fmt_pct(budget, signed=False)}: **{_describe(best)}**, "
                         f"{fmt_seconds(best['seconds_solve'])} ({_error_text(best)})")
            continue
        # the most accurate run, the fastest of those equally accurate to round-off: the front's end
        front = pareto_front(rows, y="error_bound")
        closest = front[-1] if front else None
        text = f"  - within {fmt_pct(budget, signed=False)}: no run"
        if closest is not None:
            text += (f" (the most accurate: {_describe(closest)}, {_error_text(closest)}, in "
                     f"{fmt_seconds(closest['seconds_solve'])})")
        if floor is not None and exact and abs(floor) > budget:
            text += f"; the budget is below the floor of {fmt_pct(floor)}"
        elif floor is not None:
            text += "; finer meshes than this sweep's would be needed"
        lines.append(text)
    return lines


def _front_line(rows):
    front = pareto_front(rows, y="error_bound")

    def err(r):
        if r["problem"] == "dynamic":
            return f"|space| + |time| {fmt_pct(r['error_bound'], signed=False)}"
        return fmt_pct(r["rel_error"])

    parts = [f"{_describe(r)} ({fmt_seconds(r['seconds_solve'])}, {err(r)})" for r in front]
    return "  - Pareto front, fastest first: " + "; ".join(parts) + "."


def _locking_lines(rows):
    p1 = {_cells(r): r for r in _ok(rows, "static_tip", body="linear", order=1)}
    p2 = {_cells(r): r for r in _ok(rows, "static_tip", body="linear", order=2)}
    shared = [c for c in p1 if c in p2]
    if not p1:
        return []
    parts = [f"{c}: P1 {fmt_pct(p1[c]['rel_error'])} vs P2 {fmt_pct(p2[c]['rel_error'])}" for c in shared]
    finest1 = max(p1.values(), key=lambda r: r["n_dofs"])
    lines = ["- **P1 locking** (linear body, tip load; the same mesh with linear and quadratic tets): "
             + "; ".join(parts) + "."]
    if p2:
        better = [r for r in p2.values() if r["abs_error"] < finest1["abs_error"]]
        if better:
            cheap = min(better, key=lambda r: r["seconds_solve"])
            lines.append(f"  The finest P1 mesh ({_cells(finest1)}, {finest1['n_dofs']} DOFs, "
                         f"{fmt_seconds(finest1['seconds_solve'])}) is still {fmt_pct(finest1['rel_error'])} off; "
                         f"P2 on {_cells(cheap)} ({cheap['n_dofs']} DOFs, {fmt_seconds(cheap['seconds_solve'])}) "
                         f"is {fmt_pct(cheap['rel_error'])} off.")
    dyn1 = _ok(rows, "modal", body="linear", order=1)
    if dyn1:
        fin = max(dyn1, key=lambda r: r["n_dofs"])
        lines.append(f"  In the frequency the locked P1 beam is too stiff by {fmt_pct(fin['rel_error'])} "
                     f"on {_cells(fin)}.")
    return lines


def _springs_lines(rows):
    lines = []
    for problem in ("static_tip", "self_weight", "large_deflection", "modal"):
        sp = sorted(_ok(rows, problem, body="springs"), key=lambda r: r["n_dofs"])
        if len(sp) < 2:
            continue
        errs = [r["rel_error"] for r in sp]
        text = "  - " + problem + ": " + ", ".join(f"{fmt_pct(e)} ({_cells(r)})" for e, r in zip(errs, sp))
        if len(errs) >= 3:
            d1, d2 = errs[-2] - errs[-3], errs[-1] - errs[-2]
            if d1 != 0 and (d1 > 0) == (d2 > 0) and abs(d2) < abs(d1):
                limit = errs[-1] - d2 * d2 / (d2 - d1)  # Aitken: the limit of a geometric approach
                text += (f"; the error shrinks by {d2 / d1:.2f} per refinement, which extrapolates (Aitken, three "
                         f"meshes: indicative only) to {fmt_pct(limit)}")
        lines.append(text + ".")
    if lines:
        lines.insert(0, "- **Springs' error** (van Gelder calibration, on the P1 meshes' edges; a spring network "
                        "has its own Poisson ratio and anisotropy, so it need not converge to the continuum):")
    return lines


def _linearized_lines(rows):
    runs = [r for r in _ok(rows, "linearized") if r["integrator"] != "Newmark"]
    if not runs:
        return [], []
    table = []
    lines = ["- **LinearizedImplicitEuler against ImplicitEuler** (Newton converged), same dt, large swing "
             "(released from alpha = 1): the largest distance between the tip trajectories over one period, "
             "relative to the largest tip displacement:"]
    for method in sorted({(_label(r), _cells(r)) for r in runs}):
        rs = sorted([r for r in runs if (_label(r), _cells(r)) == method], key=lambda r: r["dt"])
        name = f"{method[0]} {method[1]}"
        parts = []
        for r in rs:
            parts.append(f"N={r['steps_per_period']}: {fmt_pct(r['rel_error'], signed=False)}")
            table.append([name, r["steps_per_period"], fmt_float(r["dt"], 3), fmt_pct(r["rel_error"], signed=False),
                          fmt_pct(r.get("ie_error_vs_reference"), signed=False),
                          fmt_pct(r.get("lie_error_vs_reference"), signed=False),
                          fmt_seconds(r["seconds_implicit_euler"]), fmt_seconds(r["seconds_solve"])])
        text = f"  - {name}: " + ", ".join(parts)
        if len(rs) >= 2:
            slope = float(np.polyfit(np.log([r["dt"] for r in rs]), np.log([r["rel_error"] for r in rs]), 1)[0])
            text += f" (fitted order in dt {slope:.2f})"
            if slope < 0.5 and rs[0]["body"] == "corotated" and rs[0]["order"] == 2:
                text += (": it hardly shrinks with dt because on quadratic tets stiffness warping, which "
                         "LinearizedImplicitEuler uses for a corotated body, takes one rotation per element and "
                         "only approximates the corotated force (fem_elastic.physics.stiffness_warping): a different "
                         "force, not a different time step")
        ie = [r for r in rs if finite(r.get("ie_error_vs_reference"))]
        if ie:
            ratios = [r["ie_error_vs_reference"] / r["rel_error"] for r in ie if r["rel_error"] > 0]
            if ratios:
                text += (f"; ImplicitEuler's own error against the reference is {min(ratios):.3g} to "
                         f"{max(ratios):.3g} times this gap at the same dt")
        speed = [r["seconds_implicit_euler"] / r["seconds_solve"] for r in rs]
        text += f"; LinearizedImplicitEuler runs {min(speed):.2g} to {max(speed):.2g} times faster"
        lines.append(text + ".")
    return lines, table


def _dynamic_lines(rows):
    dyn = [r for r in rows if r.get("problem") == "dynamic"]
    if not dyn:
        return []
    lines = []
    for name in INTEGRATORS:
        rs = [r for r in dyn if r["integrator"] == name]
        if not rs:
            continue
        div = [r for r in rs if r.get("status") == "diverged"]
        if div and len(div) == len(rs):
            crit = {fmt_float(r.get("dt_critical"), 3) for r in rs if "dt_critical" in r}
            lines.append(f"  - {name}: diverged in every run ({len(rs)}, dt from "
                         f"{min(r['dt'] for r in rs):.3g} s; predicted critical dt: {', '.join(sorted(crit))} s).")
    ok = [r for r in dyn if r.get("status") == "ok" and finite(r.get("time_error"))]
    for name in ("ImplicitEuler", "LinearizedImplicitEuler", "Newmark"):
        rs = sorted([r for r in ok if r["integrator"] == name and r["body"] == "linear" and r["order"] == 2],
                    key=lambda r: r["steps_per_period"])
        if rs:
            parts = ", ".join(f"N={r['steps_per_period']} {fmt_pct(r['time_error'])}" for r in rs)
            lines.append(f"  - {name} (linear P2), frequency error of the time integration alone: {parts}.")
    pred = [r for r in ok if finite(r.get("time_error_predicted"))]
    if pred:
        dev = {}
        for r in pred:
            key = "linear" if r["body"] == "linear" else "nonlinear and springs"
            dev[key] = max(dev.get(key, 0.0), abs(r["time_error"] - r["time_error_predicted"]))
        lines.append("  - The measured time-integration error against the one predicted by each scheme's one-step map "
                     "on the mode's oscillator (arg of its eigenvalue over omega dt): largest difference "
                     + ", ".join(f"{v:.1e} ({k} bodies)" for k, v in sorted(dev.items())) + ".")
    if lines:
        lines.insert(0, "- **Time integration** (first frequency from a simulated free vibration; N = steps per "
                        "period, c = dt / critical dt):")
    return lines


def _floors_text(rows):
    lines = []
    for problem in ("static_tip", "self_weight", "modal", "large_deflection", "dynamic"):
        floor, exact, how = error_floor(rows, problem)
        if floor is None:
            continue
        what = "is" if exact else "is at most about"
        lines.append(f"- {problem}: the floor {what} {fmt_pct(floor)} ({how}).")
    return lines


def _materials_lines(rows):
    """The elastic materials at small strain: how far apart their answers are, and their cost against linear."""
    lines = []
    for problem in ("static_tip", "self_weight", "modal"):
        groups = {}
        for r in _ok(rows, problem):
            if r["body"] != "springs":
                groups.setdefault((r["order"], _cells(r)), {})[r["body"]] = r
        spreads, ratios = [], {}
        for g in groups.values():
            if len(g) < 2:
                continue
            vals = [r["value"] for r in g.values()]
            spreads.append((max(vals) - min(vals)) / abs(np.mean(vals)))
            if "linear" in g:
                for body, r in g.items():
                    if body != "linear" and g["linear"]["seconds_solve"] > 0:
                        ratios.setdefault(body, []).append(r["seconds_solve"] / g["linear"]["seconds_solve"])
        if not spreads:
            continue
        cost = ", ".join(f"{b} {np.median(v):.2g}x" for b, v in sorted(ratios.items()))
        lines.append(f"  - {problem}: the elastic materials agree to {max(spreads):.1e} (relative spread on the same "
                     f"mesh); median solve time against linear on the same mesh: {cost}.")
    if lines:
        lines.insert(0, "- **The elastic materials at small strain** (each linearizes to linear elasticity "
                        "at F = I, so their answers should agree; their costs differ):")
    return lines


def _large_linear_line(rows):
    lin = _ok(rows, "large_deflection", body="linear")
    nl = [r for r in _ok(rows, "large_deflection") if r["body"] not in ("linear", "springs")]
    if not lin or not nl:
        return []
    p2 = [r for r in nl if r["order"] == 2] or nl
    finest = max(r["n_dofs"] for r in p2)
    at = sorted((r for r in p2 if r["n_dofs"] == finest), key=lambda r: r["body"])
    lin2 = [r for r in lin if r["order"] == 2]
    lin1 = [r for r in lin if r["order"] == 1]
    d = elastica_tip(ALPHA_LARGE)[0]
    text = (f"- **Large deflection needs a nonlinear body**: linear theory predicts alpha / 3 = "
            f"{ALPHA_LARGE / 3:.3f} L against the elastica's {d:.3f} L ({fmt_pct(ALPHA_LARGE / 3 / d - 1)}): a dead "
            f"load's lever arm shrinks as the beam rotates, and linear FEM cannot see it")
    if lin2:
        text += (f"; linear P2 is {', '.join(fmt_pct(r['rel_error']) for r in sorted(lin2, key=lambda r: r['n_dofs']))}"
                 " off, coarse to fine")
    if lin1:
        best1 = min(lin1, key=lambda r: r["abs_error"])
        text += (f"; linear P1 comes to {fmt_pct(best1['rel_error'])} ({_cells(best1)}) only because its locking "
                 "(too stiff) cancels part of that overestimate")
    text += (f". The nonlinear bodies on {_cells(at[0])} P2 are "
             + ", ".join(f"{fmt_pct(r['rel_error'])} ({r['body']})" for r in at) + " off.")
    return [text]


def _setup_text(r) -> str:
    beam = (f"beam {r['length']:g} x {r['width']:g} x {r['height']:g} m (L / h = {r['length'] / r['height']:g}), "
            f"E = {r['E']:.3g} Pa, nu = {r['nu']:g}, rho = {r['density']:g} kg/m^3")
    what = {
        "static_tip": lambda: f"tip traction {r['traction']:g} Pa on the end face; reference: Timoshenko",
        "self_weight": lambda: f"gravity {r['gravity']:g} m/s^2; reference: Timoshenko (uniform load rho g A)",
        "large_deflection": lambda: (f"dead tip load alpha = P L^2 / (E I) = {r['alpha']:g}; reference: the elastica "
                                     f"(linear theory would give alpha / 3 = {r['alpha'] / 3:.3f} L)"),
        "modal": lambda: "consistent mass; reference: Euler-Bernoulli",
        "dynamic": lambda: (f"released from the first (lumped-mass) mode, tip amplitude {r['amplitude']:g} m, "
                            f"{r['periods']:g} period simulated; frequency by an order-2 Prony fit of the tip; "
                            "reference: Euler-Bernoulli"),
        "linearized": lambda: (f"released from rest in the static deflection under alpha = {r['alpha']:g}, "
                               f"{r['periods']:g} period; LinearizedImplicitEuler against ImplicitEuler at the "
                               "same dt, and both against a Newmark reference"
                               + (f" ({r['steps_per_period']} steps per period)" if r["integrator"] == "Newmark"
                                  else "")),
    }[r["problem"]]()
    return f"{beam}; {what}."


def _results_table(rows):
    headers = ["id", "status", "DOFs", "value", "reference", "rel. error", "solve (s)", "total (s)"]
    body = []
    for r in rows:
        body.append([r["id"], r.get("status"), r.get("n_dofs", ""), fmt_float(r.get("value"), 6),
                     fmt_float(r.get("reference"), 6), fmt_pct(r.get("rel_error"), 3),
                     fmt_float(r.get("seconds_solve"), 3), fmt_float(r.get("seconds"), 3)])
    return markdown_table(headers, body)


def write_report(rows, path, *, quick: bool, wall_time: float | None = None, n_run: int | None = None) -> Path:
    """Write ``report.md``: setup, conclusions generated from the rows, and the table of every run.

    Parameters
    ----------
    rows : list of dict
        Post-processed rows (see :func:`run_accuracy_study`).
    path : str or os.PathLike
    quick : bool
        Whether this was the quick sweep (said in the report).
    wall_time : float, optional
        The wall time (s) of the call that wrote the report, reported when given.
    n_run : int, optional
        How many runs that call computed (the others were read back).

    Returns
    -------
    pathlib.Path
    """
    from ..files import write_text_atomic

    n_ok = sum(r.get("status") == "ok" for r in rows)
    status: dict[str | None, int] = {}
    for r in rows:
        status[r.get("status")] = status.get(r.get("status"), 0) + 1
    out = ["# Accuracy study: error against run time", ""]
    total = sum(r.get("seconds", 0.0) for r in rows if finite(r.get("seconds")))
    out.append(f"{'Quick' if quick else 'Full'} sweep: {len(rows)} runs "
               f"({', '.join(f'{v} {k}' for k, v in sorted(status.items()))}); the runs' own wall times add up "
               f"to {total:.0f} s" + (f", and the call that wrote this report took {wall_time:.1f} s"
                                       + (f" ({n_run} runs computed, the rest read from results.jsonl)"
                                          if n_run is not None else "")
                                       if wall_time is not None else "") + ".")
    out += ["", "Setup (SI units). Errors are relative to the analytic value; times are the solve, eigen-solve "
            "or simulation alone (mesh, model and initial state built outside the timer).", ""]
    for problem in PROBLEMS:
        r = next((r for r in rows if r.get("problem") == problem), None)
        if r is not None:
            out.append(f"- {problem}: {_setup_text(r)}")
    out += ["", "The floor of each problem: the error no run of this sweep can get below.", ""]
    out += _floors_text(rows)
    out += ["", "![error against run time](error_vs_time.png)", "", "## Conclusions", "",
            "Generated from the runs below. For each problem, the fastest run within each error budget "
            "and the Pareto front (no other run is both faster and more accurate). For the simulated "
            "frequency, runs are ranked by |space error| + |time error| (the mesh's modal error plus the "
            "integrator's), never by a measured error made small by their cancellation; linear FEM is no "
            "candidate for the large deflection (see below).", ""]
    for problem in PROBLEMS:
        if problem == "linearized":
            continue
        prs = candidates(rows, problem)
        if not prs:
            continue
        floor, exact, _ = error_floor(rows, problem)
        out.append(f"- **{problem}** ({_TITLES[problem]}):")
        out += _budget_lines(prs, floor, exact)
        out.append(_front_line(prs))
    out += _materials_lines(rows)
    out += _locking_lines(rows)
    out += _springs_lines(rows)
    out += _large_linear_line(rows)
    out += _dynamic_lines(rows)
    lin_lines, lin_table = _linearized_lines(rows)
    out += lin_lines
    if lin_table:
        out += ["", "### LinearizedImplicitEuler against ImplicitEuler", "",
                markdown_table(["method", "steps per period", "dt (s)", "gap LIE vs IE", "IE vs reference",
                                "LIE vs reference", "IE time", "LIE time"], lin_table)]
    from .accuracy_methods import methods_report_lines

    out += methods_report_lines(rows)
    out += ["", "## All runs", "", f"{n_ok} of {len(rows)} runs completed.", "", _results_table(rows), ""]
    return write_text_atomic(Path(path), "\n".join(out))
