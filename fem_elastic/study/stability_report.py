"""The stability study's report: ``report.md``, with its tables and conclusions.

:func:`write_report` writes the setup (from the values the rows actually
swept), the verdict counts, the predicted against observed critical dt, the
largest stable dt of the sweep, the extreme cases and the conclusions of
:func:`~fem_elastic.study.stability_summary.conclusions`.
"""

from __future__ import annotations

from pathlib import Path

from . import stability_cases as sc
from .stability_summary import (
    _cell,
    _column_order,
    _dt_label,
    _is_base_nu,
    _sig,
    _verdict,
    conclusions,
    critical_dt_table,
    extreme_matrix,
    largest_stable_dt,
)
from .stability_sweep import (
    _E_EXTREME,
    _E_NU,
    _NU,
    _NU_EXTREME,
    BISECTIONS,
    EXPLICIT,
    EXPLICIT_MAX_FORCES,
    INTEGRATORS,
    SWEEP_STEPS,
    VERDICTS,
    WORK_LIMIT,
)

__all__ = ["write_report"]


def _grid(rows) -> dict:
    """The values the rows actually swept (a quick or filtered study runs a subset of the full grid)."""
    sweep = [r for r in rows if r.get("kind") == "sweep"]
    implicit_extreme = [r for r in rows if r.get("kind") == "extreme" and r.get("integrator") not in EXPLICIT]

    def values(rs, key):
        return sorted({float(r[key]) for r in rs if isinstance(r.get(key), (int, float))}, reverse=key == "dt")

    return {
        "E": values([r for r in sweep if _is_base_nu(r)], "E"),
        "nu": values([r for r in sweep if not _is_base_nu(r)], "nu"),
        "dt_explicit": values([r for r in sweep if r.get("integrator") in EXPLICIT], "dt"),
        "dt_implicit": values([r for r in sweep if r.get("integrator") not in EXPLICIT], "dt"),
        "dt_extreme": values(implicit_extreme, "dt"),
    }


def _listed(values, fmt) -> str:
    """``values`` formatted and joined, or "none" (none of them in the rows)."""
    f = fmt.format if isinstance(fmt, str) else fmt
    return ", ".join(f(v) for v in values) if values else "none"


def write_report(rows, path, *, quick: bool = False, wall_time: float | None = None, n_run: int | None = None):
    """Write ``report.md``: setup, verdict counts, critical dt, sweep and extreme tables, conclusions.

    Parameters
    ----------
    rows : list of dict
    path : str or os.PathLike
    quick : bool
        Whether the rows are the quick study's (said in the title).
    wall_time : float, optional
        Wall time of the study call (s).
    n_run : int, optional
        Runs made by that call (the rest came from ``results.jsonl``).

    Returns
    -------
    pathlib.Path
    """
    from ..files import write_text_atomic
    from .report import markdown_table

    lines = [f"# Stability study{' (quick)' if quick else ''}", ""]
    grid = _grid(rows)
    counts = {v: sum(_verdict(r) == v for r in rows if r.get("kind") != "critical") for v in VERDICTS}
    n_runs = sum(1 for r in rows if r.get("kind") != "critical") + sum(
        len(r.get("runs") or []) for r in rows if r.get("kind") == "critical")
    lines += [
        f"{len(rows)} cases ({n_runs} simulations, the bisections included)"
        + (f", {n_run} run by this call" if n_run is not None else "")
        + (f", in {wall_time:.1f} s wall time" if wall_time is not None else "") + ".",
        "",
        "## Setup",
        "",
        f"- **Sweep scene**: a 1 m x 0.1 m x 0.1 m cantilever on `fe.beam_mesh(cells=(6, 1, 1))` "
        f"(28 vertices, 36 P1 tets), rho = {sc.DENSITY:g} kg/m^3, fixed at x = 0, under gravity, "
        "released with a seeded random velocity field of kinetic energy 1e-3 x weight x length "
        "(0.098 J; v_rms ~ 0.14 m/s): energy in every mode, so an unstable top mode shows within tens "
        "of steps, and small against the blow-up bound of fe.simulate (the energy grown by the scene's "
        "energy scale, here weight x length), which the measured energy of symplectic Euler swings "
        "towards near its limit (by 1 / (1 - (h omega / 2)^2) in a mode of frequency omega).",
        f"- **Every sweep and bisection run takes {SWEEP_STEPS} steps**, whatever dt: instability is a "
        f"growth per step, so a fixed number of steps tests every dt alike (a fixed duration would "
        f"take 1e5 steps at dt = 1e-6 s). E in {_listed(grid['E'], '{:.0e}')} Pa at nu = {_NU} "
        f"(springs: nu = 1/4, the only value a spring network has); nu in {_listed(grid['nu'], '{:g}')} "
        f"at E = {_E_NU:.0e} Pa. Explicit schemes at dt = {_listed(grid['dt_explicit'], _dt_label)} s, "
        f"implicit ones at {_listed(grid['dt_implicit'], _dt_label)} s.",
        "- **Critical dt**: predicted by `fe.critical_time_step` (lumped mass, highest mode at rest); "
        f"observed by doubling or halving dt from the prediction until the verdict changes, then "
        f"{BISECTIONS} geometric bisections (bracket ratio 2^(1/{2 ** BISECTIONS}) = "
        f"{100 * (2 ** (1 / 2 ** BISECTIONS) - 1):.2f} %).",
        f"- **Extreme scenes** (E = {_E_EXTREME:.0e} Pa, nu = {_NU_EXTREME}): inverted (the beam's free end "
        "flipped upside down: 3 tets start inverted), crush (0.1 m cube, top pushed to 10 % height in "
        "0.2 s, released at 0.25 s), twist (the beam's free end turned 720 degrees in 0.5 s, released at "
        "0.6 s), drop (the cube thrown at a penalty ground at 20 m/s), sliver (6 tets flattened to 1e-3 "
        "of their volume, mesh quality ~4e-3), degenerate sliver (1e-12: below validation's 1e-10). "
        "Explicit schemes at dt = 1/omega_max of the scene (half symplectic Euler's limit), at most "
        f"{EXPLICIT_MAX_FORCES} force evaluations; implicit ones at "
        f"{_listed(grid['dt_extreme'], _dt_label)} s.",
        "- **Verdicts**: stable (energy drift (E_end - E_0) / S in %, S the largest energy exchanged in the "
        "run: max of the swing of the total and potential energies and the kinetic energy; "
        "E_0 from the release of driven boundaries); diverged at step k (fe.Diverged: non-finite state, or "
        "the total energy grown by more than the scene's energy scale); newton failed (an implicit step "
        "that did not converge even after halving dt 4 times); rejected (a typed error building the "
        f"scene); work limit (stopped after {WORK_LIMIT} Newton iterations plus line-search cuts); error "
        "(a bug). min det F is V / V_0 of the worst tet over the run.",
        "",
        "## Verdicts",
        "",
    ]
    table = []
    for integ in INTEGRATORS:
        rs = [r for r in rows if r.get("integrator") == integ and r.get("kind") != "critical"]
        table.append([integ] + [sum(_verdict(r) == v for r in rs) for v in VERDICTS])
    table.append(["all"] + [counts[v] for v in VERDICTS])
    lines += [markdown_table(["integrator"] + list(VERDICTS), table), ""]
    errors = [r for r in rows if _verdict(r) == "error"]
    if errors:
        lines += ["**Errors (bugs):**", ""]
        lines += [f"- `{r['id']}`: {r.get('reason') or r.get('error')}" for r in errors]
        lines += [""]

    crit = critical_dt_table(rows)
    if crit:
        lines += ["## Predicted against observed critical dt (explicit schemes)", "",
                  "The observed limit lies in [lo, hi]: stable at lo, not at hi. h omega = dt x omega_max.", ""]
        table = []
        for c in sorted(crit, key=lambda c: (INTEGRATORS.index(c["integrator"]), sc.BODIES.index(c["body"]),
                                             c["nu"], c["E"])):
            table.append([c["integrator"], sc.BODY_LABELS.get(c["body"], c["body"]), f"{c['E']:.0e}",
                          f"{c['nu']:g}", _sig(c["predicted"], 4), _sig(c["lo"], 4), _sig(c["hi"], 4),
                          _sig(c["ratio_lo"], 4), _sig(c["ratio_hi"], 4), _sig(c["h_omega_lo"], 4),
                          {True: "stable", False: "not stable", None: "-"}[c["stable_at_predicted"]]])
        lines += [markdown_table(["integrator", "body", "E (Pa)", "nu", "predicted (s)", "lo (s)", "hi (s)",
                                  "lo / predicted", "hi / predicted", "h omega (lo)", "at predicted dt"],
                                 table), ""]

    stable_dt = largest_stable_dt(rows)
    if stable_dt:
        lines += ["## Sweep: largest stable dt", "",
                  "Per body, the largest dt of the sweep that ran stable ('none': no dt did; '*': a "
                  "smaller dt failed). For explicit schemes compare with the table above; for implicit "
                  "ones this is the observed limit (predicted: unconditionally stable).", ""]
        points = sorted({k[1:] for k in stable_dt}, key=lambda k: (sc.BODIES.index(k[0]) if k[0] in sc.BODIES
                                                                     else 99, k[2], k[1]))
        integs = [i for i in INTEGRATORS if any(k[0] == i for k in stable_dt)]
        table = []
        for body, E, nu in points:
            row = [sc.BODY_LABELS.get(body, body), f"{E:.0e}", f"{nu:g}"]
            for integ in integs:
                s = stable_dt.get((integ, body, E, nu))
                if s is None:
                    row.append("")
                    continue
                row.append(("none" if s["dt"] is None else _dt_label(s["dt"])) + ("*" if s["failed_below"] else ""))
            table.append(row)
        lines += [markdown_table(["body", "E (Pa)", "nu"] + integs, table), ""]
        fails = [r for r in rows if r.get("kind") == "sweep" and _verdict(r) != "stable"]
        if fails:
            lines += ["Failed sweep runs of the implicit schemes:", ""]
            table = [[r["integrator"], sc.BODY_LABELS.get(r["body"], r["body"]), f"{float(r['E']):.0e}",
                      f"{float(r['nu']):g}", _dt_label(r["dt"]), _verdict(r), _sig(r.get("step")),
                      (r.get("reason") or r.get("error") or "")[:110]]
                     for r in fails if r["integrator"] not in EXPLICIT]
            lines += [markdown_table(["integrator", "body", "E (Pa)", "nu", "dt (s)", "verdict", "step",
                                      "reason"], table) if table else "(none)", ""]

    matrix = extreme_matrix(rows)
    if matrix:
        columns = sorted({c for v in matrix.values() for c in v}, key=_column_order)
        keys = sorted(matrix, key=lambda k: (sc.EXTREME_CASES.index(k[0]) if k[0] in sc.EXTREME_CASES else 99,
                                             sc.BODIES.index(k[1]) if k[1] in sc.BODIES else 99))
        lines += ["## Extreme cases", "",
                  "Verdict per run ('@k': at step k; 'inverted': stable, but some tet had det F < 0 during "
                  "the run). Explicit columns run at dt = 1/omega_max of the scene.", ""]
        table = [[c, sc.BODY_LABELS.get(b, b)] + [_cell(matrix[(c, b)][col]) if col in matrix[(c, b)] else ""
                                                  for col in columns] for c, b in keys]
        lines += [markdown_table(["case", "body"] + columns, table), ""]
        lines += ["Figures of the stable extreme runs (energy drift in %, min det F):", ""]
        table = []
        for c, b in keys:
            for col in columns:
                r = matrix[(c, b)].get(col)
                if r is not None and _verdict(r) == "stable":
                    table.append([c, sc.BODY_LABELS.get(b, b), col, _sig(r.get("dt_used"), 3),
                                  _sig(r.get("t_reached"), 3), _sig(r.get("energy_drift_pct"), 3),
                                  _sig(r.get("energy_rise_pct"), 3), _sig(r.get("min_J"), 3)])
        lines += [markdown_table(["case", "body", "integrator", "dt (s)", "t reached (s)", "drift (%)",
                                  "largest rise (%)", "min det F"], table) if table else "(none)", ""]
        rejected = [r for r in rows if r.get("kind") == "extreme" and _verdict(r) == "rejected"]
        if rejected:
            lines += [f"Rejected at setup ({len(rejected)} runs), e.g.: {rejected[0].get('reason')}", ""]

    from .stability_methods import methods_report_lines

    lines += methods_report_lines(rows)
    lines += ["## Conclusions", ""]
    lines += [f"- {c}" for c in conclusions(rows)] or ["- (no runs)"]
    lines += [""]
    return write_text_atomic(Path(path), "\n".join(lines))
