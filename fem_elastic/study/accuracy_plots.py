"""The accuracy study's figure: error against run time, one panel per problem, with Pareto fronts.

matplotlib is imported inside :func:`plot_error_vs_time`, so that the study's
other modules import without the ``[study]`` extra.
"""

from __future__ import annotations

import math

from .accuracy_analysis import _ok, candidates
from .accuracy_cases import _TITLES, BODIES, INTEGRATORS
from .report import MARKERS, draw_pareto, finite, pareto_front

__all__ = ["plot_error_vs_time"]


def _plot_points(rows, panel):
    """The (row, x, y) points of one figure panel: wall time (s) and |relative error|."""
    if panel == "dynamic_time":
        return [(r, r["seconds_solve"], abs(r["time_error"])) for r in _ok(rows, "dynamic")
                if finite(r.get("time_error"))]
    if panel == "linearized":
        pts = []
        for r in _ok(rows, "linearized"):
            if r["integrator"] == "Newmark":
                continue
            if finite(r.get("lie_error_vs_reference")):
                pts.append((dict(r, integrator="LinearizedImplicitEuler"), r["seconds_solve"],
                            r["lie_error_vs_reference"]))
            if finite(r.get("ie_error_vs_reference")):
                pts.append((dict(r, integrator="ImplicitEuler"), r["seconds_implicit_euler"],
                            r["ie_error_vs_reference"]))
        return pts
    return [(r, r["seconds_solve"], r["error_bound"]) for r in _ok(rows, panel) if finite(r.get("error_bound"))]


def plot_error_vs_time(rows, fig=None):
    """Log-log error against run time, one panel per problem, with each panel's Pareto front.

    Markers: one style per body (and springs). Colours: by element order in the
    static and modal panels, by integrator in the dynamic ones. The Pareto front
    (the runs no other run beats in both time and error) is a black step line.

    Parameters
    ----------
    rows : list of dict
        The study's rows (after :func:`run_accuracy_study`'s post-processing, for
        the linearized panel).
    fig : matplotlib.figure.Figure, optional
        Drawn into (resized); a new one, not attached to pyplot, if None. In a
        notebook pass ``plt.figure()`` so that the inline backend shows it.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.ticker import NullFormatter

    panels = [p for p in ("static_tip", "self_weight", "large_deflection", "modal", "dynamic",
                          "dynamic_time", "linearized") if _plot_points(rows, p)]
    ncol = 4
    nrow = max(1, math.ceil((len(panels) + 1) / ncol))
    if fig is None:
        fig = Figure()
    fig.set_size_inches(4.0 * ncol, 3.5 * nrow)
    axes = fig.subplots(nrow, ncol, squeeze=False).ravel()
    marker = {b: MARKERS[i] for i, b in enumerate(BODIES)}
    order_colour = {1: "C0", 2: "C1", None: "0.4"}
    integ_colour = {n: f"C{i}" for i, n in enumerate(INTEGRATORS)}
    for ax, panel in zip(axes, panels):
        pts = _plot_points(rows, panel)
        dynamic = panel in ("dynamic", "dynamic_time", "linearized")
        for r, x, y in pts:
            colour = integ_colour[r["integrator"]] if dynamic else order_colour[r.get("order")]
            filled = r.get("order") == 2
            ax.plot(x, max(y, 1e-16), marker[r["body"]], color=colour, ms=5,
                    mfc=colour if filled else "none", alpha=0.85, zorder=2)
        # the front over the runs the report may recommend (no linear FEM on the large deflection)
        eligible = {id(r) for r in candidates(rows, panel)} if panel == "large_deflection" else None
        front = pareto_front([{"x": x, "y": max(y, 1e-16)} for r, x, y in pts
                              if eligible is None or id(r) in eligible], "x", "y")
        draw_pareto(ax, front, "x", "y")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(_TITLES[panel], fontsize=9)
        ax.set_xlabel("wall time of the solve (s)", fontsize=8)
        ax.set_ylabel({"dynamic": "|space error| + |time error|", "dynamic_time": "|time-integration error|",
                       "linearized": "max tip distance / max tip displacement"}.get(panel, "|relative error|"),
                      fontsize=8)
        ax.tick_params(labelsize=7)
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.grid(True, which="major", alpha=0.3)
    for ax in axes[len(panels):]:
        ax.axis("off")
    legend_ax = axes[len(panels)] if len(panels) < len(axes) else axes[-1]
    handles = [Line2D([], [], ls="none", marker=marker[b], color="k", mfc="none", label=b) for b in BODIES]
    handles += [Line2D([], [], ls="none", marker="s", color=order_colour[o], label=lab)
                for o, lab in ((1, "P1 (hollow)"), (2, "P2 (filled)"))]
    handles += [Line2D([], [], ls="none", marker="o", color=integ_colour[n], label=n) for n in INTEGRATORS]
    handles += [Line2D([], [], color="k", lw=1, label="Pareto front")]
    legend_ax.legend(handles=handles, loc="center", fontsize=7, ncol=2, frameon=False,
                     title="marker: body; colour: order (static) / integrator (dynamic)", title_fontsize=7)
    fig.tight_layout()
    return fig
