"""Summaries of the stability study's rows, and the conclusions generated from them.

The largest stable dt of each swept point (:func:`largest_stable_dt`), the
predicted against observed critical dt (:func:`critical_dt_table`), the
extreme runs by scene and body (:func:`extreme_matrix`), and
:func:`conclusions`, the statements the report draws from those numbers. The
figures (:mod:`~fem_elastic.study.stability_plots`) and the report
(:mod:`~fem_elastic.study.stability_report`) read the rows through these.
"""

from __future__ import annotations

import math

import numpy as np

from . import stability_cases as sc
from .stability_sweep import _E_NU, _NEAR, _NU, EXPLICIT, INTEGRATORS, SWEEP_STEPS

__all__ = ["largest_stable_dt", "critical_dt_table", "extreme_matrix", "conclusions"]


def _verdict(row) -> str:
    """The row's verdict; a row whose function raised (``status = "error"``) is an error."""
    if row.get("status") == "error":
        return "error"
    return row.get("verdict", "error")


def _point(row):
    return (row["integrator"], row["body"], float(row["E"]), float(row["nu"]))


def _is_base_nu(row) -> bool:
    """Whether the row is on the E sweep (nu = 0.3, or 1/4 for springs) rather than the nu sweep."""
    return float(row["nu"]) in (_NU, 0.25)


def largest_stable_dt(rows) -> dict:
    """The largest dt of the sweep that ran stable, per (integrator, body, E, nu).

    Parameters
    ----------
    rows : list of dict
        The study's rows (only ``kind == "sweep"`` ones are used).

    Returns
    -------
    dict
        ``(integrator, body, E, nu) -> {"dt": s or None, "failures": [(dt, verdict, step), ...],
        "failed_below": bool}``; ``failed_below`` marks a point where some dt
        smaller than the largest stable one did not run stable (stability not
        monotone in dt).

    Examples
    --------
    >>> rows = [dict(kind="sweep", integrator="RK4", body="linear", E=1e7, nu=0.3, dt=dt,
    ...              verdict=v, step=s) for dt, v, s in ((1e-2, "diverged", 3), (1e-3, "stable", None))]
    >>> largest_stable_dt(rows)[("RK4", "linear", 1e7, 0.3)]["dt"]
    0.001
    """
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        if r.get("kind") == "sweep":
            groups.setdefault(_point(r), []).append(r)
    out = {}
    for key, rs in groups.items():
        stable = [float(r["dt"]) for r in rs if _verdict(r) == "stable"]
        best = max(stable, default=None)
        failures = sorted((float(r["dt"]), _verdict(r), r.get("step")) for r in rs if _verdict(r) != "stable")
        out[key] = {
            "dt": best,
            "failures": failures,
            "failed_below": best is not None and any(f[0] < best for f in failures),
        }
    return out


def critical_dt_table(rows) -> list:
    """Predicted against observed critical dt of the explicit schemes, one dict per critical row.

    Returns
    -------
    list of dict
        ``integrator, body, E (Pa), nu, predicted (s), lo, hi (s: the
        observed limit lies in [lo, hi]), ratio_lo, ratio_hi (over predicted;
        None when predicted is 0), h_omega_lo, h_omega_hi (dt omega_max),
        stable_at_predicted (bool or None), verdict, u_max (m: the largest
        displacement of the run at lo)``.
    """
    out = []
    for r in rows:
        if r.get("kind") != "critical":
            continue
        runs = r.get("runs") or []
        pred = r.get("dt_predicted")
        at_pred = None
        if runs and pred and math.isfinite(pred) and pred > 0 and math.isclose(runs[0][0], pred, rel_tol=1e-12):
            at_pred = runs[0][1] == "stable"
        out.append(dict(
            integrator=r["integrator"], body=r["body"], E=float(r["E"]), nu=float(r["nu"]),
            predicted=pred, lo=r.get("dt_observed_lo"), hi=r.get("dt_observed_hi"),
            ratio_lo=r.get("ratio_lo"), ratio_hi=r.get("ratio_hi"), h_omega_lo=r.get("h_omega_lo"),
            h_omega_hi=r.get("h_omega_hi"), stable_at_predicted=at_pred, verdict=_verdict(r),
            u_max=r.get("u_max"),
        ))
    return out


def _dt_label(dt) -> str:
    if dt is None:
        return "1/omega_max"
    if math.isclose(dt, 1 / 24):
        return "1/24"
    return f"{dt:.0e}" if math.isclose(dt, 10 ** round(math.log10(dt))) else f"{dt:.3g}"


def _column(row) -> str:
    """The extreme matrix's column of a row: integrator and dt rule."""
    if row["integrator"] in EXPLICIT:
        return row["integrator"]
    return f"{row['integrator']} {_dt_label(row['dt'])}"


def extreme_matrix(rows) -> dict:
    """The extreme runs by ``(case, body)`` then by column ("RK4", "ImplicitEuler 1/24", ...).

    Returns
    -------
    dict
        ``(case, body) -> {column: row}``.
    """
    out: dict[tuple[str, str], dict[str, dict]] = {}
    for r in rows:
        if r.get("kind") == "extreme":
            out.setdefault((r["case"], r["body"]), {})[_column(r)] = r
    return out


def _cell(row) -> str:
    """A short verdict for a table cell."""
    v = _verdict(row)
    if v == "stable":
        j = row.get("min_J")
        return "stable, inverted" if isinstance(j, (int, float)) and j < 0 else "stable"
    if v in ("diverged", "newton failed", "work limit"):
        return f"{v} @{row.get('step')}"
    return v


# ----------------------------------------------------------------------------------------------
# Conclusions, generated from the numbers
# ----------------------------------------------------------------------------------------------
def _where(key) -> str:
    _, body, E, nu = key
    return f"{sc.BODY_LABELS.get(body, body)} E={E:.0e} nu={nu:g}"


def conclusions(rows) -> list:
    """Statements that follow from the rows, as markdown bullet texts.

    Every number quoted is computed here from the rows; nothing is assumed.
    """
    out = []
    errors = [r for r in rows if _verdict(r) == "error"]
    if errors:
        out.append(f"**{len(errors)} run(s) ended in an error (a bug, see the list above)**; "
                   "their cells read 'error'.")
    crit = [c for c in critical_dt_table(rows) if c["verdict"] == "bracketed"]
    for integ in EXPLICIT:
        cs = [c for c in crit if c["integrator"] == integ]
        if not cs:
            continue
        if all(c["ratio_lo"] is not None for c in cs):
            lo = min(c["ratio_lo"] for c in cs)
            hi = max(c["ratio_hi"] for c in cs)
            above = [c for c in cs if c["ratio_lo"] >= 1.0]
            near = [c for c in cs if c["ratio_lo"] < 1.0 and c["ratio_hi"] >= 1.0 - _NEAR]
            below = sorted((c for c in cs if c["ratio_hi"] < 1.0 - _NEAR), key=lambda c: c["ratio_hi"])
            parts = [f"at or above the prediction in {len(above)}"]
            if near:
                parts.append(f"within {100 * _NEAR:g} % below it in {len(near)}")
            text = (f"{integ}: the observed stability limit is {lo:.4g} to {hi:.4g} times the predicted "
                    f"critical dt over {len(cs)} (body, E, nu): " + ", ".join(parts))
            if below:
                text += (f", and further below it (the prediction is not conservative) in {len(below)}: "
                         + "; ".join(f"{_where((integ, c['body'], c['E'], c['nu']))} ({c['ratio_lo']:.3g} to "
                                     f"{c['ratio_hi']:.3g}; displacement up to {_sig(c['u_max'])} m)"
                                     for c in below)
                         + ". The prediction linearizes at rest; compare those displacements with the "
                           "beam's 0.1 m section")
            out.append(text + ".")
        else:
            hw = [c["h_omega_lo"] for c in cs if c["h_omega_lo"] is not None]
            out.append(
                f"{integ}: predicted critical dt 0 (an undamped mode grows at every dt); within "
                f"{SWEEP_STEPS} steps the energy stayed within its bound up to dt omega_max = "
                f"{min(hw):.3g} to {max(hw):.3g} over {len(cs)} (body, E, nu): a finite-horizon limit, "
                "not a stability limit.")
    drifts = []
    for integ in INTEGRATORS:
        d = [float(r["energy_drift_pct"]) for r in rows if r.get("kind") == "sweep" and r.get("integrator") == integ
             and _verdict(r) == "stable" and isinstance(r.get("energy_drift_pct"), (int, float))
             and math.isfinite(r["energy_drift_pct"])]
        if d:
            drifts.append(f"{integ} {min(d):+.3g} to {max(d):+.3g} % ({len(d)} runs)")
    if drifts:
        out.append(f"Energy drift of the stable sweep runs over their {SWEEP_STEPS} steps (% of the largest "
                   "energy exchanged): " + "; ".join(drifts) + ".")
    pred = {(c["integrator"], c["body"], c["E"], c["nu"]): c["predicted"] for c in critical_dt_table(rows)}
    slopes = []
    for body in sc.BODIES:
        pts = sorted((E, p) for (i, b, E, nu), p in pred.items()
                     if i == "SymplecticEuler" and b == body and nu in (_NU, 0.25) and p and p > 0)
        if len(pts) >= 3:
            x, y = np.log10([p[0] for p in pts]), np.log10([p[1] for p in pts])
            slopes.append(float(np.polyfit(x, y, 1)[0]))
    if slopes:
        out.append(f"Symplectic Euler's predicted critical dt scales as E^{min(slopes):.3f} to "
                   f"E^{max(slopes):.3f} across the bodies (on a fixed mesh omega_max ~ sqrt(E / rho)).")
    nu_pts = sorted((nu, p) for (i, b, E, nu), p in pred.items()
                    if i == "SymplecticEuler" and b == "linear" and E == _E_NU and p and p > 0)
    if len(nu_pts) >= 2 and nu_pts[0][0] <= _NU:
        base = nu_pts[0][1]
        out.append("With nu -> 1/2, symplectic Euler's predicted dt on the linear beam at E = 1e7 Pa falls "
                   "to " + ", ".join(f"{p / base:.3g} x (nu = {nu:g})" for nu, p in nu_pts[1:])
                   + " of its nu = 0.3 value (the volumetric stiffness lambda grows as 1 / (1 - 2 nu)).")
    stable_dt = largest_stable_dt(rows)
    for integ in INTEGRATORS:
        if integ in EXPLICIT:
            continue
        at = {k: v for k, v in stable_dt.items() if k[0] == integ}
        if not at:
            continue
        clean = [k for k, v in at.items() if not v["failures"]]
        text = f"{integ}: stable at every dt of the sweep on {len(clean)} of {len(at)} (body, E, nu)"
        bad = sorted((k for k in at if at[k]["failures"]), key=lambda k: (k[1], k[2], k[3]))
        if bad:
            text += "; not on " + "; ".join(
                f"{_where(k)} ({', '.join(f'{v} at dt={_dt_label(dt)}' for dt, v, _ in at[k]['failures'])})"
                for k in bad)
        out.append(text + ".")
    matrix = extreme_matrix(rows)
    tally: dict[str, tuple[int, int]] = {}
    for (case, body), v in matrix.items():
        for col, r in v.items():
            if _verdict(r) != "rejected":
                n, k = tally.get(col, (0, 0))
                tally[col] = (n + 1, k + (_verdict(r) == "stable"))
    if tally:
        ranked = sorted(tally, key=lambda c: (-tally[c][1] / tally[c][0], _column_order(c)))
        out.append("Extreme runs that ran stable, of those not rejected at setup: "
                   + ", ".join(f"{c} {tally[c][1]}/{tally[c][0]}" for c in ranked) + ".")
    for case in sc.EXTREME_CASES:
        cells = {k: v for k, v in matrix.items() if k[0] == case}
        if not cells:
            continue
        columns = sorted({c for v in cells.values() for c in v}, key=_column_order)
        survive, fail = [], []
        for col in columns:
            got = [v[col] for v in cells.values() if col in v]
            verdicts = [_verdict(r) for r in got]
            if all(v == "stable" for v in verdicts):
                survive.append(col)
            elif not any(v == "stable" for v in verdicts):
                fail.append(col)
        if all(_verdict(r) == "rejected" for v in cells.values() for r in v.values()):
            msg = next(iter(next(iter(cells.values())).values())).get("reason", "")
            out.append(f"{case}: rejected by validation before any step, for every integrator and body "
                       f"({msg.split(':', 1)[-1].strip().split('.')[0]}).")
            continue
        bodies = sorted({b for _, b in cells}, key=lambda b: sc.BODIES.index(b) if b in sc.BODIES else 99)
        on = ", ".join(sc.BODY_LABELS.get(b, b) for b in bodies)
        text = f"{case} ({on}): "
        text += ("stable on every body with " + ", ".join(survive)) if survive else \
            "no integrator was stable on every body"
        if fail:
            text += "; stable on none with " + ", ".join(fail)
        inv = sorted({sc.BODY_LABELS.get(b, b) for (c, b), v in cells.items() for r in v.values()
                      if _verdict(r) == "stable" and isinstance(r.get("min_J"), (int, float)) and r["min_J"] < 0})
        if inv:
            text += f"; stable runs passed through inverted elements (min det F < 0) on: {', '.join(inv)}"
        out.append(text + ".")
    return out


def _column_order(col: str):
    name, _, dt = col.partition(" ")
    return (INTEGRATORS.index(name), -_label_dt(dt) if dt else 0.0)


def _label_dt(label: str) -> float:
    """The time step (s) of a dt label ("1/24", "1e-02")."""
    if "/" in label:
        num, den = label.split("/")
        return float(num) / float(den)
    return float(label)


def _sig(x, digits=3) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-" if x is None or math.isnan(x) else ("inf" if x > 0 else "-inf")
    return f"{x:.{digits}g}"
