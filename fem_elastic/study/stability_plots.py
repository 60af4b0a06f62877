"""The stability study's figures: the stability map and the matrix of the extreme cases.

matplotlib is imported inside the functions, so that the study's other modules
import without the ``[study]`` extra.
"""

from __future__ import annotations

import numpy as np

from . import stability_cases as sc
from .stability_summary import _column_order, _is_base_nu, _verdict, critical_dt_table, extreme_matrix
from .stability_sweep import _E_NU, _NU, EXPLICIT, INTEGRATORS, SWEEP_STEPS, VERDICTS

__all__ = ["plot_stability_map", "plot_extreme"]

_VERDICT_STYLE = {  # marker, colour
    "stable": ("o", "tab:green"),
    "diverged": ("x", "tab:red"),
    "newton failed": ("s", "tab:orange"),
    "rejected": ("D", "tab:gray"),
    "work limit": ("^", "tab:purple"),
    "error": ("*", "k"),
}


def plot_stability_map(rows, fig=None):
    """The stability map: one panel per integrator, dt (s) against E (Pa), a marker per verdict.

    Each panel shows the sweep on the E axis (nu = 0.3; springs nu = 1/4),
    the bodies side by side around each E (springs, linear, corotated, StVK,
    Neo-Hookean from left to right), with the predicted critical dt of the
    explicit schemes as lines (solid: FEM bodies, dashed: springs) and the
    observed limit as short bars. The eighth panel shows the explicit
    schemes' predicted and observed critical dt against nu at E = 1e7 Pa.

    Parameters
    ----------
    rows : list of dict
    fig : matplotlib.figure.Figure, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    fig = fig or Figure(figsize=(18, 8.5))
    axes = fig.subplots(2, 4, sharey=False).ravel()
    crit = critical_dt_table(rows)
    offsets = {b: 10 ** (0.22 * (k - 2)) for k, b in enumerate(sc.BODIES)}
    for ax, integ in zip(axes, INTEGRATORS):
        pts = [r for r in rows if r.get("kind") == "sweep" and r["integrator"] == integ and _is_base_nu(r)]
        for verdict, (marker, color) in _VERDICT_STYLE.items():
            sel = [r for r in pts if _verdict(r) == verdict]
            if sel:
                ax.scatter([float(r["E"]) * offsets.get(r["body"], 1.0) for r in sel],
                           [float(r["dt"]) for r in sel], marker=marker, c=color, s=28, lw=1.2, zorder=3)
        cs = [c for c in crit if c["integrator"] == integ and c["nu"] in (_NU, 0.25)]
        for springs, style in ((False, "-"), (True, "--")):
            line = sorted((c["E"], c["predicted"]) for c in cs
                          if (c["body"] == "springs") == springs and c["predicted"] and c["predicted"] > 0)
            # FEM bodies share omega_max at rest (same E, nu, mesh): one line, from the linear body
            line = sorted({E: p for E, p in line}.items())
            if line:
                ax.plot(*zip(*line), style, c="k", lw=1.0, zorder=2, marker="_" if len(line) == 1 else None,
                        ms=14)
        for c in cs:
            if c["lo"]:
                x = c["E"] * offsets.get(c["body"], 1.0)
                ax.plot([x / 1.12, x * 1.12], [c["lo"], c["lo"]], c="tab:blue", lw=2.0, zorder=4)
        if integ in ("ExplicitEuler", "Midpoint"):
            title = f"{integ}\n(predicted: unstable at every dt; bars: {SWEEP_STEPS}-step limit)"
        elif integ in EXPLICIT:
            title = f"{integ}\n(line: predicted critical dt; bars: observed)"
        else:
            title = f"{integ}\n(predicted: stable at every dt, linear problem)"
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlim(2e2, 6e11)
        ax.set_ylim(3e-7, 0.15)
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("E (Pa)")
        ax.set_ylabel("dt (s)")
        ax.grid(True, which="major", alpha=0.3)
    ax = axes[7]
    colors = {"ExplicitEuler": "tab:brown", "SymplecticEuler": "tab:blue", "Midpoint": "tab:olive",
              "RK4": "tab:cyan"}
    for integ in EXPLICIT:
        cs = sorted((c for c in crit if c["integrator"] == integ and c["body"] == "linear" and c["E"] == _E_NU),
                    key=lambda c: c["nu"])
        if not cs:
            continue
        x = [0.5 - c["nu"] for c in cs]
        if all(c["predicted"] and c["predicted"] > 0 for c in cs):
            ax.plot(x, [c["predicted"] for c in cs], "-", c=colors[integ], lw=1.0)
        ax.plot(x, [c["lo"] for c in cs], "o", c=colors[integ], ms=5, label=integ)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.invert_xaxis()
    ax.set_xlabel("1/2 - nu")
    ax.set_ylabel("critical dt (s)")
    ax.set_title("explicit limit against nu (linear, E = 1e7 Pa)")
    ax.grid(True, which="major", alpha=0.3)
    handles = [Line2D([], [], ls="", marker=m, c=c, label=v) for v, (m, c) in _VERDICT_STYLE.items()]
    handles += [Line2D([], [], c="k", lw=1.0, label="predicted critical dt (FEM)"),
                Line2D([], [], c="k", ls="--", lw=1.0, label="predicted critical dt (springs)"),
                Line2D([], [], c="tab:blue", lw=2.0, label="observed limit (largest stable dt)")]
    handles += [Line2D([], [], ls="", marker="o", c=colors[i], label=f"{i}: observed (line: predicted)")
                for i in EXPLICIT]
    fig.legend(handles=handles, loc="lower center", ncol=6, fontsize=8, frameon=False,
               bbox_to_anchor=(0.5, -0.04))
    fig.suptitle(f"Stability of a kicked cantilever (beam_mesh 6x1x1, rho = {sc.DENSITY:g} kg/m^3, "
                 f"{SWEEP_STEPS} steps); bodies around each E, left to right: "
                 + ", ".join(sc.BODY_LABELS[b] for b in sc.BODIES), fontsize=11)
    fig.tight_layout(rect=(0, 0.03, 1, 0.97))
    return fig


def plot_extreme(rows, fig=None):
    """The extreme cases' verdicts as a coloured matrix: (case, body) rows, (integrator, dt) columns.

    Returns
    -------
    matplotlib.figure.Figure or None
        None when there are no extreme rows.
    """
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    matrix = extreme_matrix(rows)
    if not matrix:
        return None
    keys = sorted(matrix, key=lambda k: (sc.EXTREME_CASES.index(k[0]) if k[0] in sc.EXTREME_CASES else 99,
                                         sc.BODIES.index(k[1]) if k[1] in sc.BODIES else 99))
    columns = sorted({c for v in matrix.values() for c in v}, key=_column_order)
    codes = np.full((len(keys), len(columns)), np.nan)
    fig = fig or Figure(figsize=(1.1 * len(columns) + 3.5, 0.28 * len(keys) + 2.0))
    ax = fig.subplots()
    for i, k in enumerate(keys):
        for j, col in enumerate(columns):
            r = matrix[k].get(col)
            if r is None:
                continue
            v = _verdict(r)
            codes[i, j] = VERDICTS.index(v)
            if v == "stable" and isinstance(r.get("min_J"), (int, float)) and r["min_J"] < 0:
                ax.text(j, i, "inv", ha="center", va="center", fontsize=6)
            elif r.get("step") is not None:
                ax.text(j, i, str(r["step"]), ha="center", va="center", fontsize=6)
    cmap = ListedColormap([_VERDICT_STYLE[v][1] for v in VERDICTS])
    ax.imshow(codes, cmap=cmap, vmin=-0.5, vmax=len(VERDICTS) - 0.5, aspect="auto", alpha=0.75)
    ax.set_xticks(range(len(columns)), columns, rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(keys)), [f"{c} / {sc.BODY_LABELS.get(b, b)}" for c, b in keys], fontsize=8)
    ax.set_title("Extreme cases: verdict per run (number: failing step; 'inv': stable but an element "
                 "inverted)", fontsize=9)
    fig.legend(handles=[Patch(color=_VERDICT_STYLE[v][1], alpha=0.75, label=v) for v in VERDICTS],
               loc="lower center", ncol=len(VERDICTS), fontsize=8, frameon=False, bbox_to_anchor=(0.5, -0.02))
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    return fig
