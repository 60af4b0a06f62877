"""The accuracy study's rows for the methods of issue 16, against converged FEM on the same beam.

Trapezoid, velocity Verlet, PBD, XPBD (Neo-Hookean and edge/volume constraints),
shape matching and projective dynamics (:data:`METHODS`) on three scenes of the
stocky cantilever (``STOCKY``: 1 m x 0.1 m x 0.1 m, rho = 1000 kg/m^3, nu = 0.3,
P1 tets, clamped on ``"left"``; :data:`METHOD_SCENES`):

``sag``
    Static sag under gravity (E = 100 MPa: tip sag 1.5 % of L, small strain),
    reached by a damped run to rest.
``period``
    First-mode frequency (E = 10 MPa, no gravity): released from rest in the
    first lumped-mass mode of the reference energy at a tip amplitude of
    ``AMPLITUDE``, one period simulated, the frequency of the sampled tip by
    :func:`~fem_elastic.study.accuracy_cases.prony_frequency`.
``large_deflection``
    Dead tip load of ``alpha = P L^2 / (E I) = 2`` (E = 10 MPa; tip rotation
    about 45 degrees), reached by a damped run to rest.

Every method runs as an integrator through :func:`fe.simulate`, so the static
scenes are run to rest: mass-proportional Rayleigh damping ``alpha = 2 omega_1``
(the reference's first mode critically damped; every mode's amplitude decays at
least as ``exp(-omega_1 t)``) for ``12 / omega_1`` s, after which a converged
method's first-mode error is below ``e^-12 (1 + 12) ~ 8e-5`` of the deflection.

**The reference** is the converged FEM answer on the same mesh for the energy
the method approximates (``reference_energy``): ``fe.solve_static`` for the
static scenes, the lumped-mass first natural frequency (the ``dt -> 0`` limit
of any consistent scheme) for the period:

- trapezoid, Verlet: the model's Neo-Hookean body;
- XPBD (``"neohookean"``): :class:`fe.ConstraintNeoHookean` with the same
  (E, nu), the energy its constraints are;
- XPBD ``"edge_volume"``: :class:`fe.MassSpring` (E) with the body at nu = 1/4,
  where the constraints are exactly van Gelder's springs (no volume constraints);
- projective dynamics: :class:`fe.Corotated`, the energy it minimises;
- PBD and shape matching have no energy: the Neo-Hookean body of the same (E, nu).

Each row also carries ``material_error``, the error against Neo-Hookean FEM of
(E, nu = 0.3) on the same mesh: what a user who asked for that material gets.

**The knob.** Trapezoid, Verlet and projective dynamics are swept over the
time step (the knob ``dt``: steps per first period, or for Verlet a fraction of
its critical step); PBD over its iterations at a fixed step (its stiffness drifts
with the iterations and with dt, so its error does not fall with either), XPBD's
edge/volume form over its iterations (it converges, as they grow, to implicit
Euler's step of the same energy), XPBD's Neo-Hookean form over substeps (it needs
``h omega_max`` below about 2: more iterations do not help, see
:mod:`fem_elastic.dynamics.position_based.xpbd`), shape matching over its number
of clusters (its stiffness is a pull towards goal shapes, not a material; with the
default overlap of one cell, 2 clusters along the beam both cover all of it, the same fit as 1).
Projective dynamics is swept over its iterations too. The row's ``knob`` and
``knob_value`` say which; the report and the figure label the series so.

Examples
--------
>>> ids = [c.id for c in method_accuracy_cases(quick=True)]
>>> "methods/period/PBD/iterations=5" in ids, "methods/period/Trapezoid/N=16" in ids
(True, True)
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from .. import dynamics as _dynamics
from ..dynamics.integrators import SymplecticEuler
from ..dynamics.observers import InversionWarning
from ..dynamics.simulate import simulate
from ..dynamics.state import State
from ..errors import Diverged, InvalidParameter
from ..geometry.mesh import beam_mesh
from ..dynamics.position_based import ConstraintNeoHookean
from ..materials import Corotated, LinearElastic, NeoHookean
from ..physics.damping import Rayleigh
from ..physics.elastic_body import ElasticBody
from ..physics.model import Model
from ..physics.springs import MassSpring
from ..solvers.linear_solvers import DirectSolver
from ..solvers.modal import critical_time_step, natural_frequencies
from ..solvers.static import solve_static
from .accuracy_cases import _tip_weights, prony_frequency
from .executor import Case

__all__ = ["METHODS", "METHOD_SCENES", "method_accuracy_cases", "run_method_accuracy_case", "method_series",
           "falls", "methods_report_lines", "plot_methods"]

#: The methods, by label: (class name in ``fem_elastic.dynamics``, fixed settings, reference energy).
METHODS = {
    "Trapezoid": ("Trapezoid", {}, "neo_hookean"),
    "VelocityVerlet": ("VelocityVerlet", {}, "neo_hookean"),
    "PBD": ("PBD", {"stiffness": 1.0}, "neo_hookean"),
    "XPBD": ("XPBD", {"iterations": 5}, "constraint_neo_hookean"),
    "XPBD edge_volume": ("XPBD", {"constraints": "edge_volume"}, "springs"),
    "ShapeMatching": ("ShapeMatching", {"mode": "quadratic", "beta": 0.5, "alpha": 0.5}, "neo_hookean"),
    "ProjectiveDynamics": ("ProjectiveDynamics", {}, "corotated"),
}
#: The scenes: (E (Pa), gravity (m/s^2), tip load alpha = P L^2 / (E I)).
METHOD_SCENES = {"sag": (1.0e8, 9.81, 0.0), "period": (1.0e7, 0.0, 0.0), "large_deflection": (1.0e7, 0.0, 2.0)}
#: The beam: the accuracy study's stocky one (m, Pa, kg/m^3).
BEAM = dict(length=1.0, width=0.1, height=0.1, nu=0.3, density=1000.0)
#: Tip amplitude of the period scene's modal release (m): L / 10^4, small enough that every body is linear.
AMPLITUDE = 1.0e-4
#: Steps per first period of the runs whose knob is not dt.
N_FIXED = 32


def _sweeps(quick, scene):
    """{method: (knob, values)} of one scene."""
    if quick:
        # the quick study (the tests' and the error_vs_runtime notebook's) keeps the cheap runs: every
        # method on the period, the position-based ones on the statics (a run to rest of an implicit
        # scheme costs seconds)
        everything = {"Trapezoid": ("N", (16, 32)), "VelocityVerlet": ("c", (0.9,)),
                      "PBD": ("iterations", (5, 20)), "XPBD": ("substeps", (1, 8)),
                      "XPBD edge_volume": ("iterations", (10, 100)), "ShapeMatching": ("clusters", (1, 3)),
                      "ProjectiveDynamics": ("iterations", (2, 6))}
        keep = {"period": tuple(everything), "sag": ("PBD", "XPBD", "XPBD edge_volume", "ShapeMatching"),
                "large_deflection": ("XPBD edge_volume",)}[scene]
        return {m: everything[m] for m in keep}
    return {"Trapezoid": ("N", (8, 16, 32, 64)), "VelocityVerlet": ("c", (0.9, 0.45)),
            "PBD": ("iterations", (5, 20, 80, 320)), "XPBD": ("substeps", (1, 4, 16, 64)),
            "XPBD edge_volume": ("iterations", (10, 50, 200, 800)), "ShapeMatching": ("clusters", (1, 3, 6)),
            "ProjectiveDynamics": ("iterations", (5, 20, 80))}


def method_accuracy_cases(quick: bool = False) -> list:
    """The ``problem = "methods"`` cases: every method on every scene, over its knob.

    Parameters
    ----------
    quick : bool
        A coarse mesh (5 x 1 x 1 cells), two knob values per method (one for Verlet), every
        method on the period and only the cheap position-based runs on the static scenes.

    Returns
    -------
    list of Case
        Ids ``methods/<scene>/<method>/<knob>=<value>``.
    """
    cells = (5, 1, 1) if quick else (10, 2, 2)
    cases = []
    for scene, (E, g, alpha) in METHOD_SCENES.items():
        for label, (knob, values) in _sweeps(quick, scene).items():
            for v in values:
                p = dict(problem="methods", scene=scene, method=label, integrator=label, body=label,
                         order=1, cells=list(cells), E=E, gravity=g, alpha=alpha, knob=knob, knob_value=v,
                         **BEAM)
                cases.append(Case(f"methods/{scene}/{label}/{knob}={v:g}", p))
    return cases


# --- one case ----------------------------------------------------------------------------------


def _body(energy, E, nu):
    """The body whose FEM energy is ``energy`` (the reference)."""
    if energy == "springs":
        return MassSpring(E=E)
    cls = {"neo_hookean": NeoHookean, "constraint_neo_hookean": ConstraintNeoHookean,
           "corotated": Corotated}[energy]
    return ElasticBody(cls(E=E, nu=nu), order=1)


def _run_body(energy, E, nu):
    """The body the method runs on: the reference's, but a P1 body of (E, 1/4) for the springs
    (XPBD's ``"edge_volume"`` derives van Gelder's springs from it)."""
    return ElasticBody(LinearElastic(E=E, nu=0.25), order=1) if energy == "springs" else _body(energy, E, nu)


def _loads(p, mesh_area_second_moment):
    area, I = mesh_area_second_moment
    loads = {}
    if p["gravity"]:
        loads["gravity"] = (0.0, 0.0, -p["gravity"])
    if p["alpha"]:
        P = p["alpha"] * p["E"] * I / p["length"] ** 2
        loads["traction"] = {"right": (0.0, 0.0, -P / area)}
    return loads


def _integrator(label, knob, value):
    name, kw, _ = METHODS[label]
    kw = dict(kw)
    if knob in ("iterations", "substeps", "clusters"):
        kw[knob] = int(value)
    return getattr(_dynamics, name)(**kw)


def _run(model, integ, dt, steps, state, energy_bounded, sample=None):
    """(final state or None, seconds, Diverged or None); ``sample(s)`` called after each step."""
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():  # an inverted run is said so in the row (``inverted``), not warned
            warnings.simplefilter("ignore", InversionWarning)
            run = simulate(model, integ, dt, steps=steps, state=state, record_every=steps, check_stability=False,
                           energy_growth=1.0 if energy_bounded else math.inf,
                           callback=None if sample is None else (lambda k, s: sample(s)))
        return run, time.perf_counter() - t0, None
    except Diverged as err:
        return None, time.perf_counter() - t0, err


def run_method_accuracy_case(p: dict) -> dict:
    """Run one ``methods`` case (see the module notes); the row.

    Returns
    -------
    dict
        ``value`` and ``reference`` (tip deflection (m) or frequency (Hz)), ``rel_error``,
        ``abs_error``, ``error_bound`` (= ``abs_error``), ``material_error`` (against
        Neo-Hookean FEM of (E, 0.3)), ``seconds_solve`` (s, the simulation only), ``dt`` (s),
        ``steps``; a diverged run (or a period run whose tip does not oscillate) sets
        ``status`` and leaves the errors None.
    """
    label, knob, value = p["method"], p["knob"], p["knob_value"]
    _warm_up()
    if label not in METHODS:
        raise InvalidParameter(f"method must be one of {tuple(METHODS)}, got {label!r}.")
    energy = METHODS[label][2]
    nu = 0.25 if energy == "springs" else p["nu"]
    mesh = beam_mesh(p["length"], p["width"], p["height"], cells=tuple(p["cells"]))
    area, I = p["width"] * p["height"], p["width"] * p["height"] ** 3 / 12.0
    loads = _loads(p, (area, I))
    run_body = _run_body(energy, p["E"], nu)
    ref_model = Model(mesh, p["density"], _body(energy, p["E"], nu), fixed="left", **loads)
    # the material the user asked for: the reference itself when that is Neo-Hookean (nu = p["nu"] then)
    mat_model = ref_model if energy == "neo_hookean" else \
        Model(mesh, p["density"], _body("neo_hookean", p["E"], p["nu"]), fixed="left", **loads)
    wz = _tip_weights(ref_model, 2)
    freqs, phi = natural_frequencies(ref_model, 1, mass="lumped", return_modes=True)
    f1_ref = float(freqs[0])
    omega1 = 2.0 * math.pi * f1_ref
    period = 1.0 / f1_ref
    extra = dict(n_dofs=ref_model.ndofs, reference_energy=energy, f_modal_lumped=f1_ref)
    static = p["scene"] != "period"
    if static:
        damping = Rayleigh(2.0 * omega1, 0.0)
        model = Model(mesh, p["density"], run_body, fixed="left", damping=damping, **loads)
        duration = 12.0 / omega1
        state = State.rest(model)
    else:
        model = Model(mesh, p["density"], run_body, fixed="left")
        duration = period
        u0 = phi[:, 0] * (-AMPLITUDE / float(wz @ phi[:, 0]))
        state = State(model.X + u0, np.zeros(model.ndofs), 0.0)
    integ = _integrator(label, knob, value)
    if knob == "N":
        dt = period / value
    elif knob == "c":
        dt = value * critical_time_step(model, integ)
    else:
        dt = period / N_FIXED
    steps = max(4, math.ceil(duration / dt - 1e-9))
    extra.update(dt=dt, steps=steps, dt_critical_symplectic=critical_time_step(model, SymplecticEuler()))
    if static:
        ref = solve_static(ref_model, linear_solver=DirectSolver(), stability=False)
        mat = ref if mat_model is ref_model else solve_static(mat_model, linear_solver=DirectSolver(),
                                                              stability=False)
        reference = -float(wz @ (ref.x - ref_model.X))
        material = -float(wz @ (mat.x - mat_model.X))
        quantity = "tip deflection (m)"
    else:
        reference = f1_ref
        material = f1_ref if mat_model is ref_model else float(natural_frequencies(mat_model, 1, mass="lumped")[0])
        quantity = "first frequency (Hz)"
    samples = [float(wz @ (state.x - model.X))]
    run, seconds, err = _run(model, integ, dt, steps, state, label in ("Trapezoid", "VelocityVerlet"),
                             sample=None if static else (lambda s: samples.append(float(wz @ (s.x - model.X)))))
    base = dict(quantity=quantity, reference=reference, material_reference=material,
                reference_name=f"converged FEM ({energy})", seconds_solve=seconds, **extra)
    if err is not None:
        return dict(status="diverged", rel_error=None, abs_error=None, error_bound=None, material_error=None,
                    diverged_step=err.step, diverged_reason=err.reason, **base)
    det = np.asarray(run.step_stats.get("min_det_F", ()), dtype=float)
    if det.size and np.isfinite(det).any():
        base["min_det_F"] = float(np.nanmin(det))  # <= 0: the run inverted elements (not physical there)
    if static:
        val = -float(wz @ (run.final_state.x - model.X))
        base["speed_max"] = float(np.abs(run.final_state.v).max())  # m/s: how close to rest the run ended
    else:
        try:
            val, sigma = prony_frequency(samples, dt)
        except InvalidParameter as exc:
            return dict(status="no oscillation", rel_error=None, abs_error=None, error_bound=None,
                        material_error=None, reason=str(exc), **base)
        base["decay_rate"] = sigma
    rel = val / reference - 1.0
    return dict(value=val, rel_error=rel, abs_error=abs(rel), error_bound=abs(rel),
                material_error=val / material - 1.0, **base)

_WARM = False


def _warm_up() -> None:
    """Compile each method's kernels (numba) and factorisations once per process, before any timed run."""
    global _WARM
    if _WARM:
        return
    _WARM = True
    mesh = beam_mesh(1.0, 0.1, 0.1, cells=(2, 1, 1))
    for label, (_, _, energy) in METHODS.items():
        model = Model(mesh, 1000.0, _run_body(energy, 1e6, 0.3), fixed="left", gravity=(0.0, 0.0, -9.81),
                      damping=Rayleigh(1.0, 0.0))
        knob = _sweeps(False, "period")[label][0]
        value = {"N": 8, "c": 0.5}.get(knob, 2)
        integ = _integrator(label, knob, value)
        dt = 0.5 * critical_time_step(model, integ) if knob == "c" else 1e-3
        _run(model, integ, dt, 2, State.rest(model), label in ("Trapezoid", "VelocityVerlet"))


# --- after the sweep: the report's section and the figure --------------------------------------

#: Which way each knob refines: +1 (a larger value is more accurate) or -1.
_REFINES = {"N": 1, "c": -1, "iterations": 1, "substeps": 1, "clusters": 1}
_KNOB_TEXT = {"N": "steps per period", "c": "dt / critical dt", "iterations": "iterations per step",
              "substeps": "substeps", "clusters": "clusters"}


def method_series(rows) -> dict:
    """{(scene, method): [rows in the order their knob refines]} of the completed ``methods`` rows."""
    out: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        if r.get("problem") == "methods" and r.get("status") == "ok":
            out.setdefault((r["scene"], r["method"]), []).append(r)
    for key, rs in out.items():
        rs.sort(key=lambda r: _REFINES[r["knob"]] * r["knob_value"])
    return out


def falls(series) -> bool:
    """Whether |error| falls at every refinement of the knob along ``series`` (>= 2 rows)."""
    e = [r["abs_error"] for r in series]
    return len(e) >= 2 and all(b < a for a, b in zip(e, e[1:]))


def methods_report_lines(rows) -> list:
    """The accuracy report's section on the methods of issue 16 (empty without their rows)."""
    from .report import fmt_pct, fmt_seconds, markdown_table

    mrows = [r for r in rows if r.get("problem") == "methods"]
    if not mrows:
        return []
    series = method_series(rows)
    r0 = mrows[0]
    lines = ["", "## The methods of issue 16 against converged FEM", "",
             f"Beam {r0['length']:g} x {r0['width']:g} x {r0['height']:g} m, P1 tets "
             f"{'x'.join(str(c) for c in r0['cells'])}, rho = {r0['density']:g} kg/m^3, nu = {r0['nu']:g}; "
             "scenes: " + "; ".join(f"**{s}** (E = {E:.0e} Pa" + (f", gravity {g:g} m/s^2" if g else "")
                                    + (f", tip load alpha = {a:g}" if a else "") + ")"
                                    for s, (E, g, a) in METHOD_SCENES.items())
             + ". The static scenes are run to rest (Rayleigh alpha = 2 omega_1, 12 / omega_1 s); the period is "
             "the Prony frequency of one simulated period from the first mode. Errors are against the converged "
             "FEM answer on the same mesh for the energy the method approximates (the column 'reference'), and "
             "against Neo-Hookean FEM of the same (E, nu) ('vs Neo-Hookean'). Each method is swept over its "
             "own knob (the column 'knob'): dt only where the error is a time-step error.", ""]
    table = []
    for (scene, method), rs in sorted(series.items()):
        for r in rs:
            J = r.get("min_det_F")
            table.append([scene, method, f"{_KNOB_TEXT[r['knob']]} = {r['knob_value']:g}",
                          f"{r['dt']:.3g}", r["reference_energy"], fmt_pct(r["rel_error"], 3),
                          fmt_pct(r["material_error"], 3), "" if J is None else f"{J:.2g}",
                          fmt_seconds(r["seconds_solve"])])
    lines += [markdown_table(["scene", "method", "knob", "dt (s)", "reference", "error", "vs Neo-Hookean",
                              "min det F", "time"], table), "",
              "A run with min det F <= 0 inverted elements on its way: its number is not physical. The static "
              "scenes' runs to rest leave about e^-12 (1 + 12) ~ 8e-5 of the deflection undamped: no error "
              "there falls below that floor.", ""]
    failed = [r for r in mrows if r.get("status") != "ok"]
    if failed:
        lines += ["Runs that gave no error: " + "; ".join(f"{r['id']} ({r.get('status')})" for r in failed), ""]
    for (scene, method), rs in sorted(series.items()):
        if len(rs) < 2:
            continue
        knob = _KNOB_TEXT[rs[0]["knob"]]
        errs = ", ".join(f"{fmt_pct(r['rel_error'], 2)} ({r['knob_value']:g})" for r in rs)
        verdict = "falls with every refinement" if falls(rs) else "does not fall steadily"
        signs = [r["rel_error"] for r in rs]
        flip = next((i for i in range(1, len(signs)) if signs[i - 1] * signs[i] < 0), None)
        note = "" if flip is None else (f" (its sign changes between {rs[flip - 1]['knob_value']:g} and "
                                        f"{rs[flip]['knob_value']:g}: it passes the reference there)")
        lines.append(f"- {scene}, {method}: the error against its reference {verdict} of {knob}{note}: {errs}.")
    pbd = [rs for (s, m), rs in series.items() if m == "PBD" and len(rs) >= 2]
    if pbd:
        spans = [max(r["value"] for r in rs) / min(r["value"] for r in rs) for rs in pbd if
                 min(r["value"] for r in rs) > 0]
        if spans:
            lines.append(f"- PBD's answer drifts with its iterations at a fixed dt, by up to a factor "
                         f"{max(spans):.3g} over this sweep: its stiffness is no material constant.")
    lines.append("")
    lines.append("![the methods: error against run time](methods_error_vs_time.png)")
    return lines


def plot_methods(rows, fig=None):
    """Error against run time of the ``methods`` rows, one panel per scene, one line per method.

    Each line joins a method's runs in the order its knob refines (the legend names the knob).
    Returns None when the rows have no ``methods`` run.
    """
    series = method_series(rows)
    if not series:
        return None
    from matplotlib.figure import Figure

    scenes = [s for s in METHOD_SCENES if any(k[0] == s for k in series)]
    if fig is None:
        fig = Figure()
    fig.set_size_inches(4.2 * len(scenes) + 2.5, 3.6)
    axes = fig.subplots(1, len(scenes), squeeze=False).ravel()
    colour = {m: f"C{i}" for i, m in enumerate(METHODS)}
    knob_of = {}
    for ax, scene in zip(axes, scenes):
        for method in METHODS:
            rs = series.get((scene, method))
            if not rs:
                continue
            knob_of[method] = rs[0]["knob"]
            ax.plot([r["seconds_solve"] for r in rs], [max(r["abs_error"], 1e-16) for r in rs], "o-",
                    color=colour[method], ms=4, lw=1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(f"{scene}: vs converged FEM", fontsize=9)
        ax.set_xlabel("wall time of the run (s)", fontsize=8)
        ax.set_ylabel("|relative error|", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="major", alpha=0.3)
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=colour[m], marker="o", ms=4, label=f"{m} ({_KNOB_TEXT[knob_of[m]]})")
               for m in METHODS if m in knob_of]
    fig.legend(handles=handles, loc="center right", fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0, 1.0 - 2.5 / (4.2 * len(scenes) + 2.5), 1))
    return fig
