"""Looking at results from Python: short reprs, HTML tables, line plots, saving.

The results (:class:`fe.Model`, :class:`fe.StaticResult`,
:class:`fe.Trajectory`) build their ``__repr__`` and ``_repr_html_`` (what
Jupyter shows) from :func:`text_table` and :func:`html_table` over a few
``(label, value)`` rows: size, material, method, timings and a key physical
result, never the arrays themselves. :func:`line_axes` draws a quantity
against time (or load factor) with matplotlib, imported inside it.

Saving a result as a run directory (the format ``fem-elastic run`` writes)
belongs to the application layer, above the layers these results live in:
:mod:`fem_elastic.app.output` registers its writers here
(:func:`register_writer`) when it is imported, which ``import fem_elastic``
does, and ``result.save(dir)`` calls them through :func:`save_result`.
"""

from __future__ import annotations

import html
from collections.abc import Callable, Sequence

import numpy as np

from ..errors import InvalidParameter, MissingDependency

__all__ = ["text_table", "html_table", "fmt", "line_axes", "register_writer", "save_result",
           "model_rows"]

_WRITERS: dict[str, Callable] = {}


def fmt(value, unit: str = "") -> str:
    """A number in 4 significant digits with its unit; None as "-"."""
    if value is None:
        return "-"
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return f"{int(value)}{' ' + unit if unit else ''}"
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.4g}{' ' + unit if unit else ''}"
    return str(value)


def text_table(title: str, rows: Sequence[tuple[str, str]]) -> str:
    """``title`` then one ``label: value`` line per row (a repr of a few lines).

    Examples
    --------
    >>> print(text_table("Result", [("steps", "3"), ("wall time", "0.1 s")]))
    Result
      steps: 3
      wall time: 0.1 s
    """
    return "\n".join([title] + [f"  {label}: {value}" for label, value in rows])


def html_table(title: str, rows: Sequence[tuple[str, str]]) -> str:
    """The same rows as an HTML table (Jupyter's rich display), every value escaped.

    Examples
    --------
    >>> html_table("R", [("a<b", "1")]).count("<tr>")
    1
    """
    body = "".join(
        f"<tr><th style='text-align:left'>{html.escape(str(label))}</th>"
        f"<td style='text-align:left'>{html.escape(str(value))}</td></tr>"
        for label, value in rows
    )
    return f"<table><caption>{html.escape(title)}</caption>{body}</table>"


def model_rows(model) -> list[tuple[str, str]]:
    """The rows that describe a model: mesh size, body, material, density, mass, terms."""
    body = model.body
    material = getattr(body, "material", None)
    order = getattr(model.space, "order", 1)
    kind = type(body).__name__ + (f" (P{order})" if hasattr(body, "order") else "")
    terms = [type(p).__name__ for p in model.potentials[1:]]
    rows = [
        ("mesh", f"{model.mesh.p.shape[1]} vertices, {model.mesh.t.shape[1]} tets, "
                 f"{model.ndofs} DOFs"),
        ("body", kind),
    ]
    if material is not None:
        rows.append(("material", repr(material)))
    rows += [
        ("density", fmt(model.density, "kg/m^3")),
        ("mass", fmt(float(model.total_mass), "kg")),
        ("held DOFs", fmt(int(np.size(model.held_dofs)))),
        ("other terms", ", ".join(terms) if terms else "none"),
    ]
    return rows


def line_axes(x, curves: dict, *, xlabel: str, ylabel: str, title: str | None = None, ax=None):
    """Draw ``{label: y}`` curves against ``x`` with matplotlib; return the Axes.

    Parameters
    ----------
    x : array_like
        ``(T,)`` abscissa (e.g. time, s).
    curves : dict of str to array_like
        ``(T,)`` ordinates, one line each.
    xlabel, ylabel : str
        Axis labels, with units.
    title : str, optional
    ax : matplotlib.axes.Axes, optional
        Draw into these axes; default a new figure's.

    Returns
    -------
    matplotlib.axes.Axes
    """
    try:
        import matplotlib.pyplot as plt
    except ModuleNotFoundError as err:
        raise MissingDependency(
            f"Plotting needs matplotlib, which is not installed ({err}): pip install matplotlib",
            name=err.name,
        ) from err
    if ax is None:
        _, ax = plt.subplots(figsize=(6.0, 3.5))
    x = np.asarray(x, dtype=float)
    for label, y in curves.items():
        y = np.asarray(y, dtype=float)
        if y.shape != x.shape:
            raise InvalidParameter(f"curve {label!r} has shape {y.shape}, x has {x.shape}.")
        ax.plot(x, y, label=label, marker="." if x.size < 30 else None)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    if len(curves) > 1:
        ax.legend()
    ax.grid(True, alpha=0.3)
    return ax


def register_writer(kind: str, writer: Callable) -> None:
    """Register the function that saves results of ``kind`` as a run directory.

    Parameters
    ----------
    kind : {"trajectory", "static"}
    writer : callable
        ``writer(result, run_dir, model, *, overwrite=False) -> pathlib.Path``.
    """
    _WRITERS[kind] = writer


def save_result(kind: str, result, run_dir, model, *, overwrite: bool = False):
    """Save ``result`` as a run directory with the writer registered for ``kind``.

    ``overwrite``: write into a directory that holds other files all the same (see
    :func:`fem_elastic.app.result_files.save_trajectory`).
    """
    writer = _WRITERS.get(kind)
    if writer is None:  # only when fem_elastic.app could not be imported
        raise MissingDependency(
            f"no writer for {kind} results is registered: import fem_elastic.app (it needs "
            "meshio) to save results as run directories.", name="meshio",
        )
    if model is None:
        raise InvalidParameter(
            "this result does not know its model; pass it: result.save(run_dir, model=model)."
        )
    return writer(result, run_dir, model, overwrite=overwrite)
