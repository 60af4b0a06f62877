"""The stability study's rows for the methods of issue 16: trapezoid, velocity Verlet, PBD, XPBD,
shape matching and projective dynamics, on four hard scenes.

Each ``kind = "methods"`` case runs one method (:data:`METHODS`, a label and the
settings it is built with) on one scene (:data:`METHOD_SCENES`), all on the
corotated body (:data:`BODY`) of :mod:`fem_elastic.study.stability_cases` (the position-based
methods derive their constraints' compliance from its (E, nu); projective
dynamics minimises its energy):

``stiff steel``
    The kicked cantilever (:func:`~fem_elastic.study.stability_cases.cantilever`)
    with steel's stiffness, E = 200 GPa, nu = 0.3, at dt = 1/30 s (a frame),
    :data:`~fem_elastic.study.stability_sweep.SWEEP_STEPS` steps: ``h omega_max``
    is of order 1e3, far past every explicit limit.
``near-incompressible``
    The same cantilever at E = 10 MPa, nu = 0.4999, dt = 1/100 s, the same steps.
``crush``
    The crush scene (a cube pushed to 10 % of its height, released) at E = 0.1 MPa,
    nu = 0.3, dt = 1/100 s, to its end (0.5 s).
``huge steps``
    The kicked cantilever at E = 0.1 MPa, nu = 0.3, at dt = 0.5 s, the same steps.

Verdicts are the study's (:data:`~fem_elastic.study.stability_sweep.VERDICTS`), with
one difference for the methods whose update does not minimise the model's energy
(every one here but the trapezoid rule and velocity Verlet): PBD and shape
matching have no energy at all, XPBD's and projective dynamics' differ from the
model's corotated energy at large strain. For them the blow-up watch's energy
bound is off (the recorded energy is still the model's, reported as for the
others) and a run is ``diverged`` when its state is not finite or a displacement
exceeds :data:`DISPLACEMENT_LIMIT` times the body's size (its bounding-box
diagonal): a bounded, finite run is stable whatever the model's energy says.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .. import dynamics as _dynamics
from ..errors import InvalidParameter
from . import stability_cases as sc
from .executor import Case

__all__ = ["METHODS", "METHOD_SCENES", "DISPLACEMENT_LIMIT", "method_cases", "method_integrator",
           "method_scene", "methods_matrix", "methods_report_lines"]

#: The methods, by label: (class name in ``fem_elastic.dynamics``, keyword settings).
METHODS: dict[str, tuple[str, dict[str, Any]]] = {
    "Trapezoid": ("Trapezoid", {}),
    "VelocityVerlet": ("VelocityVerlet", {}),
    "PBD": ("PBD", {"stiffness": 1.0, "iterations": 10}),
    "XPBD": ("XPBD", {"iterations": 20}),
    "XPBD edge_volume": ("XPBD", {"iterations": 20, "constraints": "edge_volume"}),
    "ShapeMatching": ("ShapeMatching", {"mode": "linear", "clusters": 3}),
    "ProjectiveDynamics": ("ProjectiveDynamics", {"iterations": 10}),
}
#: The body of every scene (a key of :data:`~fem_elastic.study.stability_cases.BODIES`): corotated,
#: whose energy is finite in every state (an inverted tet included), so that the recorded energy of a
#: method that does not minimise it is never +inf; projective dynamics minimises it exactly.
BODY = "corotated"
#: Methods whose energy is the model's: the blow-up watch's energy bound applies to them.
ENERGY_METHODS = ("Trapezoid", "VelocityVerlet")
#: The scenes, by label: (scene key, E (Pa), nu, dt (s), steps; None: the scene's duration).
METHOD_SCENES = {
    "stiff steel": ("cantilever", 2.0e11, 0.3, 1.0 / 30.0, None),
    "near-incompressible": ("cantilever", 1.0e7, 0.4999, 1.0e-2, None),
    "crush": ("crush", 1.0e5, 0.3, 1.0e-2, None),
    "huge steps": ("cantilever", 1.0e5, 0.3, 0.5, None),
}
#: A displacement beyond this many body sizes is a blow-up for the methods without an energy bound:
#: every scene's body is held on one face (the cantilevers, the crushed cube), and a point at most
#: one size from that face cannot move further than twice the size unless the body stretches to
#: more than twice its length. (10 sizes let an XPBD run through whose 1 m beam moved 4 m with
#: tets inverted to det F = -25.)
DISPLACEMENT_LIMIT = 2.0


def method_integrator(label: str):
    """A new integrator of method ``label`` (a key of :data:`METHODS`).

    Examples
    --------
    >>> method_integrator("XPBD edge_volume").constraints
    'edge_volume'
    """
    if label not in METHODS:
        raise InvalidParameter(f"method must be one of {tuple(METHODS)}, got {label!r}.")
    name, kw = METHODS[label]
    return getattr(_dynamics, name)(**kw)


def method_scene(case: str) -> tuple:
    """(Scene, dt (s), steps) of scene ``case`` (a key of :data:`METHOD_SCENES`)."""
    if case not in METHOD_SCENES:
        raise InvalidParameter(f"case must be one of {tuple(METHOD_SCENES)}, got {case!r}.")
    key, E, nu, dt, steps = METHOD_SCENES[case]
    from .stability_sweep import SWEEP_STEPS

    if key == "cantilever":
        return sc.cantilever(BODY, E, nu), dt, SWEEP_STEPS if steps is None else steps
    scene = sc.extreme_scene(key, BODY, E, nu)
    return scene, dt, max(1, math.ceil(scene.duration / dt - 1e-9)) if steps is None else steps


def method_cases() -> list:
    """The ``kind = "methods"`` cases: every method on every scene (the same in the quick study).

    Examples
    --------
    >>> cases = method_cases()
    >>> len(cases), cases[0].id
    (28, 'methods/stiff steel/Trapezoid')
    """
    out = []
    for case, (_, E, nu, dt, _) in METHOD_SCENES.items():
        for label in METHODS:
            p = dict(kind="methods", case=case, integrator=label, body=BODY, E=E, nu=nu, dt=dt,
                     steps=None)
            out.append(Case(f"methods/{case}/{label}", p))
    return out


def run_method_case(params: dict, simulate_scene) -> dict:
    """Run one ``methods`` case through the study's ``simulate_scene(scene, name, dt, steps, **kw)``."""
    label = params["integrator"]
    scene, dt, steps = method_scene(params["case"])
    integ = method_integrator(label)
    if label in ENERGY_METHODS:
        return simulate_scene(scene, label, dt, steps, integrator=integ)
    X = scene.model.X.reshape(-1, 3)
    size = float(np.linalg.norm(np.ptp(X, axis=0)))
    return simulate_scene(scene, label, dt, steps, integrator=integ, energy_growth=math.inf,
                          displacement_limit=DISPLACEMENT_LIMIT * size)


def methods_matrix(rows) -> dict:
    """{scene: {method: row}} of the ``methods`` rows."""
    out: dict[str, dict] = {}
    for r in rows:
        if r.get("kind") == "methods":
            out.setdefault(r["case"], {})[r["integrator"]] = r
    return out


def _cell(r) -> str:
    from .stability_summary import _verdict

    v = _verdict(r)
    if v == "stable":
        drift = r.get("energy_drift_pct")
        text = "stable" + (f" ({drift:+.3g} %)" if drift is not None and math.isfinite(drift) else "")
        J = r.get("min_J")
        return text + (f", inverted (min det F {J:.2g})" if J is not None and J < 0 else "")
    step = r.get("step")
    return v + (f" at step {step}" if step is not None else "")


def methods_report_lines(rows) -> list:
    """The report's section on the methods of issue 16: a verdict matrix and what it shows."""
    matrix = methods_matrix(rows)
    if not matrix:
        return []
    from .report import markdown_table
    from .stability_summary import _verdict

    scenes = [c for c in METHOD_SCENES if c in matrix]
    labels = [m for m in METHODS if any(m in matrix[c] for c in scenes)]
    lines = ["## The methods of issue 16 on hard scenes", "",
             "Trapezoid, velocity Verlet, PBD (k = 1, 10 iterations), XPBD (20 iterations; Neo-Hookean and "
             "edge/volume constraints), shape matching (linear, 3 clusters) and projective dynamics (10 "
             "iterations), on the corotated body: " + "; ".join(
                 f"**{c}** (E = {METHOD_SCENES[c][1]:.0e} Pa, nu = {METHOD_SCENES[c][2]:g}, dt = "
                 f"{METHOD_SCENES[c][3]:.4g} s)" for c in scenes)
             + ". A cell gives the verdict and, for a stable run, the drift of the model's energy "
               f"(% of its scale) and, where a tet turned inside out, the smallest det F. All but trapezoid and Verlet are judged on a finite state and "
               f"displacements within {DISPLACEMENT_LIMIT:g} body sizes, not on the model's energy, "
               "which they do not minimise.", ""]
    table = [[m] + [_cell(matrix[c][m]) if m in matrix[c] else "" for c in scenes] for m in labels]
    lines += [markdown_table(["method"] + scenes, table), ""]
    stable = {m: [c for c in scenes if m in matrix[c] and _verdict(matrix[c][m]) == "stable"] for m in labels}
    every = [m for m in labels if len(stable[m]) == len(scenes)]
    never = [m for m in labels if not stable[m]]
    if every:
        lines.append(f"- Stable on every scene: {', '.join(every)}.")
    for m in labels:
        if stable[m] and len(stable[m]) < len(scenes):
            fails = [f"{c} ({_verdict(matrix[c][m])})" for c in scenes if c not in stable[m] and m in matrix[c]]
            lines.append(f"- {m}: not stable on {', '.join(fails)}.")
    if never:
        lines.append(f"- Stable on none: {', '.join(never)}.")
    lines.append("")
    return lines
