"""The accuracy study: error against run time on cantilevers with closed-form answers.

Every run builds a cantilever (``fe.beam_mesh``, clamped on ``"left"``), solves
one problem with one method, and records its relative error against the
analytic value and its wall time. The sweep covers the body (``"springs"``:
``fe.MassSpring``; ``"linear"``, ``"corotated"``, ``"stvk"``, ``"neo_hookean"``:
``fe.ElasticBody`` of ``fe.LinearElastic``, ``fe.Corotated``, ``fe.StVK``,
``fe.NeoHookean``), the element order (P1, P2), the mesh and, for dynamics,
the integrator (all seven) and the time step.

Problems and references
-----------------------
``static_tip``, ``self_weight`` (slender beam, L / h = 20)
    Tip deflection (the area mean of u_z over the end face, the work-conjugate
    of a uniform end traction) under a small tip load and under gravity,
    against **Timoshenko** theory (``RectangularCantilever.tip_load_timoshenko``,
    ``distributed_load_timoshenko``). Timoshenko rather than Euler-Bernoulli
    because a 3-D body deforms in shear, which Timoshenko includes (+0.2 % of
    the deflection at L / h = 20); what neither includes is the 3-D clamp (the
    fixed face also stops the section's warping and Poisson contraction), which
    stiffens the root: the 3-D limit sits a few 0.1 % below Timoshenko. That
    gap is the beam model's own error floor; the report estimates it from the
    finest P2 meshes (Richardson extrapolation when three uniformly refined
    levels are present).
``large_deflection`` (same beam)
    Tip deflection under a dead tip load with ``alpha = P L^2 / (E I)`` of
    order 1, against the exact elastica (:func:`fem_elastic.physics.analytic.elastica_tip`).
    Rotations are large, strains small (alpha h / (2 L)): the geometrically
    nonlinear bodies reduce to the elastica; linear FEM cannot (it predicts
    alpha / 3) and is included to show by how much it fails.
``modal`` (same beam)
    First natural frequency from ``fe.natural_frequencies`` (consistent mass)
    against Euler-Bernoulli, ``first_bending_frequency``.
``dynamic`` (a stockier beam, L / h = 10)
    The beam is released from rest in its first mode shape (the lumped-mass
    mode of its own discretization, which every integrator uses, scaled to a
    tip amplitude of 0.1 mm) and simulated for one period; the frequency of the
    sampled tip deflection (an order-2 Prony fit, exact for a single damped
    mode) is compared with Euler-Bernoulli (``rel_error``) and with the
    discretization's own lumped modal frequency (``time_error``: the error of
    the time integration alone, which ``time_error_predicted`` gives in closed
    form from the scheme's one-step map on the modal oscillator). The stockier beam keeps the explicit
    schemes affordable: their stable step is set by the highest frequency, and
    omega_max / omega_1 grows as (L / h)^2.
``linearized`` (the dynamic beam)
    The accuracy ``fe.LinearizedImplicitEuler`` (one Newton step per time step)
    gives up against ``fe.ImplicitEuler`` (Newton to convergence) at the same
    dt, on a large motion: released from a large static deflection (alpha = 1)
    for one period. ``rel_error`` is the largest distance between the two tip
    trajectories over the run, relative to the largest tip displacement. A
    ``reference`` run (Newmark, many steps per period) also gives each
    scheme's own error.

Each row has ``rel_error`` (signed, relative), ``abs_error`` = ``|rel_error|``,
``seconds_solve`` (s, wall time of the solve, eigen-solve or simulation only:
the mesh, the model and the initial state are built outside it; a solve under
0.25 s is repeated up to five times and the fastest call kept, as timeit does,
since other load only ever adds time) and ``seconds`` (s, the whole case, from
:func:`fem_elastic.study.executor.run_sweep`). Each worker process first runs
every body and integrator once on a tiny beam, so that no case pays for
compiling kernels or importing solvers.

After the sweep, the dynamic rows get ``space_error`` (the mesh's lumped modal
frequency against the reference) and ``error_bound`` = ``|space_error| +
|time_error|``, the other rows ``error_bound`` = ``abs_error``: the report
ranks runs by it (:func:`candidates`), so that a run whose measured error is
small only because the mesh's and the integrator's errors cancel is never
recommended.

Examples
--------
>>> from fem_elastic.study.accuracy import accuracy_cases, run_accuracy_case
>>> case = next(c for c in accuracy_cases(quick=True) if c.id == "static_tip/linear/P2/10x1x1")
>>> row = run_accuracy_case(case.params)
>>> row["reference_name"], abs(row["rel_error"]) < 0.05   # P2 on 10 cells: -2.2 %
('Timoshenko', True)
"""

from __future__ import annotations

import logging
import math
import time
from pathlib import Path

import numpy as np

from ..physics.analytic import RectangularCantilever, elastica_tip
from ..errors import InvalidParameter
from .executor import Case, run_sweep
from .report import (
    MARKERS,
    StudyResult,
    draw_pareto,
    fastest_within,
    finish_study,
    finite,
    fmt_float,
    fmt_pct,
    fmt_seconds,
    markdown_table,
    pareto_front,
)

__all__ = [
    "StudyResult",
    "run_accuracy_study",
    "accuracy_cases",
    "run_accuracy_case",
    "prony_frequency",
    "error_floor",
    "candidates",
    "write_report",
    "plot_error_vs_time",
    "PROBLEMS",
    "BODIES",
    "INTEGRATORS",
    "BUDGETS",
]

logger = logging.getLogger(__name__)

#: The problems, in the order of the report and the figure's panels.
PROBLEMS = ("static_tip", "self_weight", "large_deflection", "modal", "dynamic", "linearized")
#: Bodies: the mass-spring network and the four elastic materials.
BODIES = ("springs", "linear", "corotated", "stvk", "neo_hookean")
#: The seven integrators, by class name in ``fem_elastic``.
INTEGRATORS = ("ExplicitEuler", "SymplecticEuler", "Midpoint", "RK4", "ImplicitEuler",
               "LinearizedImplicitEuler", "Newmark")
#: Error budgets of the report's recommendations (relative errors).
BUDGETS = (0.10, 0.01, 0.001)

_TITLES = {
    "static_tip": "static tip load vs Timoshenko",
    "self_weight": "self weight vs Timoshenko",
    "large_deflection": "large deflection vs elastica",
    "modal": "first frequency, modal vs Euler-Bernoulli",
    "dynamic": "first frequency, simulated: |space| + |time| error",
    "dynamic_time": "first frequency, simulated vs the mesh's modal (time error)",
    "linearized": "large swing vs Newmark reference",
}

# --- the beams (SI units) ---------------------------------------------------------------
# Slender beam for the statics and the modal problem: L / h = 20 keeps shear (+0.2 %) and the
# clamp (a few 0.1 %) small. E = 1 GPa: the loads below keep the small-load problems linear
# (tip deflection ~ L / 200, so geometric effects ~ 1e-5).
SLENDER = dict(length=1.0, width=0.05, height=0.05, E=1.0e9, nu=0.3, density=1000.0)
TIP_TRACTION = -3.0e3  # Pa on the end face: P = 7.5 N, w = 4.8 mm = L / 208
GRAVITY = 9.81  # m/s^2: self weight q = rho g A = 24.5 N/m, w = 5.9 mm
# P L^2 / (E I): elastica deflection 0.49 L, tip rotation 45 degrees, root strain alpha h / (2 L) = 5 %
ALPHA_LARGE = 2.0
# Stocky beam for the dynamics: L / h = 10. E = 10 MPa (a soft solid): first period 0.62 s, so
# the implicit steps (8 to 128 per period) span the frame rates animation uses.
STOCKY = dict(length=1.0, width=0.1, height=0.1, E=1.0e7, nu=0.3, density=1000.0)
AMPLITUDE = 1.0e-4  # m: tip amplitude of the modal release. L / 10^4 keeps the nonlinear bodies' motion a
# single mode to ~1e-5 (their quadratic terms couple other modes in proportion to the amplitude)
ALPHA_RELEASE = 1.0  # the linearized problem's initial bend: tip deflection 0.30 L, tip rotation 26 degrees
SPRING_NU = 0.25  # a spring network's own Poisson ratio (Cauchy relation); van Gelder ignores nu anyway


# --- the sweep ----------------------------------------------------------------------------


def _cells_id(cells) -> str:
    return "x".join(str(c) for c in cells)


def _method_id(body, order) -> str:
    return "springs" if body == "springs" else f"{body}/P{order}"


def accuracy_cases(quick: bool = False) -> list[Case]:
    """The cases of the accuracy study.

    Parameters
    ----------
    quick : bool
        A small sweep (coarse meshes, three bodies, one dt per integrator) that
        runs in seconds, for tests and smoke runs; its dynamic beam is stockier
        still (L / h = 5) so that explicit schemes need fewer steps.

    Returns
    -------
    list of Case
        Ids like ``static_tip/neo_hookean/P2/20x1x1`` or
        ``dynamic/linear/P2/10x1x1/RK4/c0.9``; params hold everything the case
        needs (geometry, material constants, loads, method).

    Examples
    --------
    >>> cases = accuracy_cases(quick=True)
    >>> sorted({c.params["problem"] for c in cases}) == sorted(PROBLEMS)
    True
    """
    if quick:
        static_bodies = ("springs", "linear", "neo_hookean")
        large_bodies = static_bodies
        p1_cells = [(20, 1, 1), (40, 2, 2)]
        p2_cells = [(10, 1, 1), (20, 1, 1)]
        p2_reference = []
        spring_cells = p1_cells
        stocky = dict(STOCKY, width=0.2, height=0.2)
        dyn_combos = [("linear", 2, (5, 1, 1), (0.9,), (16,))]
        lin_combos, lin_n, lin_ref = [("neo_hookean", 2, (5, 1, 1))], (8, 16), 32
    else:
        static_bodies = BODIES
        large_bodies = BODIES
        p1_cells = [(20, 1, 1), (40, 2, 2), (80, 4, 4)]
        p2_cells = [(10, 1, 1), (20, 1, 1), (40, 2, 2)]
        p2_reference = [(80, 4, 4)]  # linear only (39k DOFs): the third uniform level for Richardson
        spring_cells = p1_cells
        stocky = STOCKY
        # (body, order, cells, dt / critical dt of the explicit schemes, steps per period of the implicit
        # ones): the whole dt sweep on linear P2; the other bodies at fewer steps (an explicit step of a
        # nonlinear P2 body costs several times a linear one, and they take thousands per period)
        few_c, few_n = (0.9,), (8, 32, 128)
        dyn_combos = [("linear", 2, (10, 1, 1), (0.9, 0.45), (8, 16, 32, 64, 128)),
                      ("corotated", 2, (10, 1, 1), few_c, few_n), ("stvk", 2, (10, 1, 1), few_c, few_n),
                      ("neo_hookean", 2, (10, 1, 1), few_c, few_n), ("linear", 1, (20, 2, 2), few_c, few_n),
                      ("springs", None, (20, 2, 2), few_c, few_n)]
        # corotated on P1 too: there the one-step scheme is exact stiffness warping (fe.stiffness_warping),
        # on P2 warping's one rotation per element only approximates the corotated force
        lin_combos = [("corotated", 2, (10, 1, 1)), ("neo_hookean", 2, (10, 1, 1)), ("corotated", 1, (20, 2, 2))]
        lin_n, lin_ref = (8, 16, 32, 64), 256

    cases = []

    def add(problem, body, order, cells, beam, suffix="", **extra):
        cid = f"{problem}/{_method_id(body, order)}/{_cells_id(cells)}" + (f"/{suffix}" if suffix else "")
        params = dict(problem=problem, body=body, order=order, cells=list(cells), **beam, **extra)
        cases.append(Case(cid, params))

    loads = {"static_tip": dict(traction=TIP_TRACTION), "self_weight": dict(gravity=GRAVITY),
             "large_deflection": dict(alpha=ALPHA_LARGE), "modal": {}}
    for problem, extra in loads.items():
        bodies = large_bodies if problem == "large_deflection" else static_bodies
        for body in bodies:
            if body == "springs":
                for cells in spring_cells:
                    add(problem, body, None, cells, SLENDER, **extra)
                continue
            for order, levels in ((1, p1_cells), (2, p2_cells)):
                for cells in levels:
                    add(problem, body, order, cells, SLENDER, **extra)
            if body == "linear" and problem in ("static_tip", "self_weight"):
                for cells in p2_reference:
                    add(problem, body, 2, cells, SLENDER, **extra)

    for body, order, cells, explicit_c, implicit_n in dyn_combos:
        for name in INTEGRATORS:
            explicit = name in ("ExplicitEuler", "SymplecticEuler", "Midpoint", "RK4")
            if explicit:
                for c in explicit_c:
                    add("dynamic", body, order, cells, stocky, f"{name}/c{c:g}", integrator=name,
                        dt_over_critical=c, periods=1.0, amplitude=AMPLITUDE)
            else:
                for n in implicit_n:
                    add("dynamic", body, order, cells, stocky, f"{name}/N{n}", integrator=name,
                        steps_per_period=n, periods=1.0, amplitude=AMPLITUDE)

    for body, order, cells in lin_combos:
        add("linearized", body, order, cells, stocky, "reference", integrator="Newmark",
            steps_per_period=lin_ref, sample_every=lin_ref // max(lin_n), alpha=ALPHA_RELEASE, periods=1.0)
        for n in lin_n:
            add("linearized", body, order, cells, stocky, f"N{n}", integrator="LinearizedImplicitEuler",
                steps_per_period=n, sample_every=1, alpha=ALPHA_RELEASE, periods=1.0)
    return cases


# --- one case ------------------------------------------------------------------------------


def _fe():
    import fem_elastic as fe

    return fe


def _beam(p) -> RectangularCantilever:
    return RectangularCantilever(p["length"], p["width"], p["height"], p["E"], p["nu"])


def _body(p):
    fe = _fe()
    if p["body"] == "springs":
        return fe.MassSpring(E=p["E"], nu=SPRING_NU)
    materials = {"linear": fe.LinearElastic, "corotated": fe.Corotated, "stvk": fe.StVK,
                 "neo_hookean": fe.NeoHookean}
    if p["body"] not in materials:
        raise InvalidParameter(f"body must be one of {BODIES}, got {p['body']!r}")
    return fe.ElasticBody(materials[p["body"]](E=p["E"], nu=p["nu"]), order=p["order"])


def _model(p, mesh=None, **loads):
    """The case's clamped beam under ``loads``; on ``mesh`` when given (a second model of the same beam)."""
    fe = _fe()
    if mesh is None:
        mesh = fe.beam_mesh(p["length"], p["width"], p["height"], cells=tuple(p["cells"]))
    return fe.Model(mesh, p["density"], _body(p), fixed="left", **loads)


def _elastica_traction(p, beam) -> tuple[float, float, float]:
    """The end-face traction (Pa) of the tip load P = alpha E I / L^2 (N), spread uniformly, downward."""
    P = p["alpha"] * p["E"] * beam.second_moment / p["length"] ** 2
    return (0.0, 0.0, -P / beam.area)


def _tip_weights(model, axis: int) -> np.ndarray:
    """w such that w . (x - X) is the area mean of u_axis over the end face (m).

    The nodal forces of a unit traction on "right", over the face's area: the
    work-conjugate of a uniform end load (for P2 it weighs the mid-edge nodes too).
    """
    from ..physics.loads import traction_load

    t = np.zeros(3)
    t[axis] = 1.0
    f = traction_load(model.space, "right", t).force
    return f / f.sum()


# Timing: a solve shorter than _REPEAT_BUDGET is repeated (up to _REPEATS calls in all, while their total
# stays under the budget) and the fastest call is kept, timeit's convention: other load on the machine
# only ever adds time, so the minimum is the least disturbed estimate. Longer solves run once.
_REPEATS = 5
_REPEAT_BUDGET = 0.25  # s


def _timed(call):
    """(result of the first call, fastest wall time (s), calls made)."""
    t0 = time.perf_counter()
    out = call()
    best = total = time.perf_counter() - t0
    n = 1
    while n < _REPEATS and total + best < _REPEAT_BUDGET:
        t0 = time.perf_counter()
        call()
        dt = time.perf_counter() - t0
        best, total, n = min(best, dt), total + dt, n + 1
    return out, best, n


def _result(value, reference, reference_name, quantity, seconds_solve, **extra) -> dict:
    rel = value / reference - 1.0
    return dict(quantity=quantity, value=value, reference=reference, reference_name=reference_name,
                rel_error=rel, abs_error=abs(rel), seconds_solve=seconds_solve, **extra)


def _static(p) -> dict:
    fe = _fe()
    beam = _beam(p)
    if p["problem"] == "static_tip":
        model = _model(p, traction={"right": (0.0, 0.0, p["traction"])})
        reference, name = beam.tip_load_timoshenko(-p["traction"] * beam.area), "Timoshenko"
    elif p["problem"] == "self_weight":
        model = _model(p, gravity=(0.0, 0.0, -p["gravity"]))
        reference, name = beam.distributed_load_timoshenko(p["density"] * p["gravity"] * beam.area), "Timoshenko"
    else:  # large_deflection: P = alpha E I / L^2 as a uniform traction on the end face
        model = _model(p, traction={"right": _elastica_traction(p, beam)})
        d, s = elastica_tip(p["alpha"])
        reference, name = d * p["length"], "elastica"
    res, seconds, calls = _timed(lambda: fe.solve_static(model, linear_solver=fe.DirectSolver()))
    w = -float(_tip_weights(model, 2) @ (res.x - model.X))
    extra = dict(n_dofs=model.ndofs, newton_iterations=res.iterations, load_steps=len(res.load_steps),
                 timed_calls=calls)
    if p["problem"] == "large_deflection":
        u = -float(_tip_weights(model, 0) @ (res.x - model.X))
        extra["shortening_error"] = u / (s * p["length"]) - 1.0
    return _result(w, reference, name, "tip deflection (m)", seconds, **extra)


def _modal(p) -> dict:
    fe = _fe()
    model = _model(p)
    f, seconds, calls = _timed(lambda: fe.natural_frequencies(model, 1))
    return _result(float(f[0]), _beam(p).first_bending_frequency(p["density"]), "Euler-Bernoulli",
                   "first frequency (Hz)", seconds, n_dofs=model.ndofs, timed_calls=calls)


def prony_frequency(w, dt: float) -> tuple[float, float]:
    """Frequency and decay rate of a sampled damped oscillation, by an order-2 Prony fit.

    A single damped mode sampled every dt, ``w_n = Re(c z^n)`` with
    ``z = exp((-sigma + i 2 pi f) dt)``, satisfies ``w_{n+1} = a w_n + b w_{n-1}``
    exactly; a and b are fitted by least squares over all samples, and z is a
    root of ``z^2 - a z - b``. Every linear one-step integrator maps a modal
    oscillator to such a sequence, so the fit returns the frequency the
    integrator actually produced (with no window or interpolation error), from
    as little as half a period of samples.

    Parameters
    ----------
    w : array_like, shape (n,)
        Samples (any unit), n >= 4, about zero.
    dt : float
        Sampling interval (s).

    Returns
    -------
    f : float
        Frequency (Hz).
    sigma : float
        Decay rate (1/s); negative when the oscillation grows.

    Raises
    ------
    InvalidParameter
        Too few samples, or a fit with real roots (the samples do not oscillate).

    Examples
    --------
    >>> t = np.arange(40) * 0.01
    >>> f, sigma = prony_frequency(np.exp(-0.5 * t) * np.cos(2 * np.pi * 3.0 * t + 0.3), 0.01)
    >>> round(f, 10), round(sigma, 10)
    (3.0, 0.5)
    """
    w = np.asarray(w, dtype=float)
    if w.size < 4:
        raise InvalidParameter(f"a Prony fit needs at least 4 samples, got {w.size}: sample more densely.")
    scale = np.max(np.abs(w))
    if not (scale > 0 and np.isfinite(scale)):
        raise InvalidParameter("the samples are all zero or not finite: nothing oscillates.")
    w = w / scale
    A = np.column_stack([w[1:-1], w[:-2]])
    (a, b), *_ = np.linalg.lstsq(A, w[2:], rcond=None)
    disc = a * a + 4.0 * b
    if disc >= 0:
        raise InvalidParameter("the samples do not oscillate (the Prony fit has real roots).")
    z = complex(0.5 * a, 0.5 * math.sqrt(-disc))
    return abs(math.atan2(z.imag, z.real)) / (2.0 * math.pi * dt), -math.log(abs(z)) / dt


def _integrator(name):
    fe = _fe()
    if name not in INTEGRATORS:
        raise InvalidParameter(f"integrator must be one of {INTEGRATORS}, got {name!r}")
    return getattr(fe, name)()


def _simulate_tip(model, integrator, dt, steps, state, sample_every, weights):
    """Run (timed as :func:`_timed` does), sampling the tip every ``sample_every`` steps.

    Returns (samples (k, len(weights)) in m, seconds, Diverged or None, Trajectory or None).
    """
    fe = _fe()
    X = model.X

    def once():
        samples = [[float(w @ (state.x - X)) for w in weights]]

        def sample(k, s):
            if (k + 1) % sample_every == 0:
                samples.append([float(w @ (s.x - X)) for w in weights])

        try:
            run = fe.simulate(model, integrator, dt, steps=steps, state=state, record_every=steps,
                              check_stability=False, callback=sample)
            return np.array(samples), None, run
        except fe.Diverged as exc:
            return np.array(samples), exc, None

    (samples, err, run), seconds, _ = _timed(once)
    return samples, seconds, err, run


def _dynamic(p) -> dict:
    fe = _fe()
    model = _model(p)
    beam = _beam(p)
    f_ref = beam.first_bending_frequency(p["density"])
    integrator = _integrator(p["integrator"])
    f_h, phi = fe.natural_frequencies(model, 1, mass="lumped", return_modes=True)
    f_h, phi = float(f_h[0]), phi[:, 0]
    wz = _tip_weights(model, 2)
    u0 = phi * (-p["amplitude"] / float(wz @ phi))  # tip down by the amplitude
    state = fe.State(model.X + u0, np.zeros(model.ndofs), 0.0)
    dt_se = fe.critical_time_step(model, fe.SymplecticEuler())
    extra = dict(n_dofs=model.ndofs, f_modal_lumped=f_h, dt_critical_symplectic=dt_se)
    if "steps_per_period" in p:
        dt = 1.0 / (p["steps_per_period"] * f_ref)
    else:
        crit = fe.critical_time_step(model, integrator)
        extra["dt_critical"] = crit
        dt = p["dt_over_critical"] * (crit if 0.0 < crit < math.inf else dt_se)
    # the scheme's own frequency on this mode's oscillator: arg of its one-step map's eigenvalue
    omega_h = 2.0 * math.pi * f_h * dt
    theta = float(np.max(np.abs(np.angle(np.linalg.eigvals(integrator.step_matrix(dt, 2.0 * math.pi * f_h))))))
    extra["time_error_predicted"] = theta / omega_h - 1.0
    steps = max(4, math.ceil(p["periods"] / (f_ref * dt) - 1e-9))
    per_period = 1.0 / (f_ref * dt)
    sample_every = max(1, int(per_period // 32))  # >= 32 samples per period for the Prony fit
    extra.update(dt=dt, steps=steps, steps_per_period_actual=per_period)
    w, seconds, diverged, run = _simulate_tip(model, integrator, dt, steps, state, sample_every, [wz])
    if diverged is not None:
        return dict(status="diverged", quantity="first frequency (Hz)", reference=f_ref,
                    reference_name="Euler-Bernoulli", rel_error=None, abs_error=None, time_error=None,
                    seconds_solve=seconds, diverged_step=diverged.step, diverged_reason=diverged.reason, **extra)
    f, sigma = prony_frequency(w[:, 0], sample_every * dt)
    extra.update(decay_rate=sigma, time_error=f / f_h - 1.0, dt_cuts=run.dt_cuts,
                 newton_iterations=int(np.sum(run.step_stats["newton_iterations"])))
    return _result(f, f_ref, "Euler-Bernoulli", "first frequency (Hz)", seconds, **extra)


def _linearized(p) -> dict:
    """One scheme (or the reference) from the large release; histories for the report's comparison."""
    fe = _fe()
    beam = _beam(p)
    model = _model(p)
    bent = fe.solve_static(_model(p, model.mesh, traction={"right": _elastica_traction(p, beam)}))
    weights = [_tip_weights(model, 0), _tip_weights(model, 2)]
    state = fe.State(bent.x, np.zeros(model.ndofs), 0.0)
    f_ref = beam.first_bending_frequency(p["density"])
    dt = 1.0 / (p["steps_per_period"] * f_ref)
    steps = round(p["periods"] * p["steps_per_period"])
    extra = dict(n_dofs=model.ndofs, dt=dt, steps=steps, quantity="tip trajectory (m)")
    runs = {}
    names = ["Newmark"] if p["integrator"] == "Newmark" else ["ImplicitEuler", "LinearizedImplicitEuler"]
    for name in names:
        w, seconds, diverged, _ = _simulate_tip(model, _integrator(name), dt, steps, state,
                                                p["sample_every"], weights)
        if diverged is not None:
            return dict(status="diverged", rel_error=None, abs_error=None, seconds_solve=seconds,
                        diverged_scheme=name, diverged_step=diverged.step, diverged_reason=diverged.reason,
                        **extra)
        runs[name] = (w, seconds)
    if p["integrator"] == "Newmark":
        w, seconds = runs["Newmark"]
        return dict(rel_error=0.0, abs_error=0.0, seconds_solve=seconds, reference_name="itself",
                    tip_history=w.tolist(), **extra)
    (w_ie, s_ie), (w_lie, s_lie) = runs["ImplicitEuler"], runs["LinearizedImplicitEuler"]
    amplitude = float(np.max(np.linalg.norm(w_ie, axis=1)))
    gap = float(np.max(np.linalg.norm(w_lie - w_ie, axis=1))) / amplitude
    return dict(rel_error=gap, abs_error=gap, reference_name="ImplicitEuler (Newton converged)",
                seconds_solve=s_lie, seconds_implicit_euler=s_ie, amplitude=amplitude,
                tip_history=w_lie.tolist(), tip_history_implicit_euler=w_ie.tolist(), **extra)


_WARM = False


def _warm_up() -> None:
    """Pay each process's one-time costs before the first timed run.

    The first use of a material compiles (or loads from cache) its fused numba kernels and
    imports the solvers; without this the first case a worker runs would look a second slower.
    Runs every body and order on a 2-cell beam: a static solve, a modal solve and two steps of
    every integrator.
    """
    global _WARM
    if _WARM:
        return
    _WARM = True
    fe = _fe()
    t0 = time.perf_counter()
    for body in BODIES:
        for order in (None,) if body == "springs" else (1, 2):
            p = dict(SLENDER, body=body, order=order, cells=[2, 1, 1])
            fe.solve_static(_model(p, traction={"right": (0.0, 0.0, -1.0)}), linear_solver=fe.DirectSolver())
            model = _model(p)
            fe.natural_frequencies(model, 1, mass="lumped")
            state = fe.State.rest(model, displacement=lambda X: 1e-6 * X[:, [2, 2, 0]] ** 2)
            for name in INTEGRATORS:
                fe.simulate(model, _integrator(name), 1e-6, steps=2, state=state, check_stability=False)
    logger.debug("warm-up in %.2f s", time.perf_counter() - t0)


_RUNNERS = {"static_tip": _static, "self_weight": _static, "large_deflection": _static, "modal": _modal,
            "dynamic": _dynamic, "linearized": _linearized}


def run_accuracy_case(params: dict) -> dict:
    """Run one case of the accuracy study (the sweep's function; module level, so it pickles).

    Parameters
    ----------
    params : dict
        A :class:`Case`'s params, from :func:`accuracy_cases`.

    Returns
    -------
    dict
        The row (without the executor's ``id``, ``status`` and ``seconds``):
        value, reference, ``rel_error``, ``abs_error``, ``seconds_solve`` (s) and
        problem-specific figures. A diverged simulation sets ``status = "diverged"``
        and leaves the errors None.
    """
    if params.get("problem") not in _RUNNERS:
        raise InvalidParameter(f"problem must be one of {PROBLEMS}, got {params.get('problem')!r}")
    _warm_up()
    return _RUNNERS[params["problem"]](params)


# --- after the sweep -----------------------------------------------------------------------


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


# --- the report ------------------------------------------------------------------------------


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
    status = {}
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
    out += ["", "## All runs", "", f"{n_ok} of {len(rows)} runs completed.", "", _results_table(rows), ""]
    return write_text_atomic(Path(path), "\n".join(out))


# --- the study ------------------------------------------------------------------------------


def run_accuracy_study(out_dir, *, quick: bool = False, executor=None, workers=None, progress: bool = True,
                       _case_filter=None) -> StudyResult:
    """Run the accuracy study and write its results, figure and report to ``out_dir``.

    Parameters
    ----------
    out_dir : str or os.PathLike
        Created if missing. Holds ``results.jsonl`` (every run, appended as it
        finishes; a second call resumes and runs only what is missing),
        ``results.csv``, ``error_vs_time.png`` and ``report.md``.
    quick : bool
        The small sweep (seconds) instead of the full one (minutes).
    executor : None, "process", "serial", concurrent.futures.Executor or dask.distributed.Client
        Where the runs go (:func:`fem_elastic.study.executor.run_sweep`): by
        default a process pool of ``workers`` processes. On a Dask cluster::

            from dask.distributed import Client
            client = Client("tcp://scheduler:8786")
            fe.study.run_accuracy_study("results/accuracy", executor=client)

        Note that run times measured on a cluster depend on its nodes.
    workers : int, optional
        Processes of the default pool (``os.cpu_count()`` if None).
    progress : bool
        Show a progress bar (tqdm).

    Returns
    -------
    StudyResult

    Raises
    ------
    fem_elastic.study.SweepIncomplete
        When the executor lost runs; what finished is kept, call again to resume.
    """
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    cases = accuracy_cases(quick)
    if _case_filter is not None:  # tests: a subset of the sweep
        cases = [c for c in cases if _case_filter(c)]
    rows = run_sweep(cases, run_accuracy_case, out_dir, executor=executor, workers=workers, progress=progress,
                     desc="accuracy study")
    _postprocess(rows)
    return finish_study("accuracy study", rows, out_dir, t0=t0, n_run=rows.n_run, quick=quick,
                        table=_public(rows),
                        figures=lambda: [(plot_error_vs_time(rows), "error_vs_time.png")],
                        write_report=write_report)
