"""The accuracy study's cases: the problems, the beams, the sweep, and running one case.

:func:`accuracy_cases` lists the sweep (one :class:`~fem_elastic.study.executor.Case`
per problem, body, element order, mesh and, for dynamics, integrator and time
step); :func:`run_accuracy_case` runs one of them (the sweep's function, at
module level so that worker processes can unpickle it) and returns its row.
The problems and their analytic references are described in
:mod:`fem_elastic.study.accuracy`.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from ..dynamics import integrators as _integrators
from ..dynamics.integrators import SymplecticEuler
from ..dynamics.simulate import simulate
from ..dynamics.state import State
from ..errors import Diverged, InvalidParameter
from ..geometry.mesh import beam_mesh
from ..materials import Corotated, LinearElastic, NeoHookean, StVK
from ..physics.analytic import RectangularCantilever, elastica_tip
from ..physics.elastic_body import ElasticBody
from ..physics.loads import traction_load
from ..physics.model import Model
from ..physics.springs import MassSpring
from ..solvers.linear_solvers import DirectSolver
from ..solvers.modal import critical_time_step, natural_frequencies
from ..solvers.static import solve_static
from .executor import Case

__all__ = [
    "accuracy_cases",
    "run_accuracy_case",
    "prony_frequency",
    "PROBLEMS",
    "BODIES",
    "INTEGRATORS",
]

# the study's logger, under the name it had before the study was split into modules
logger = logging.getLogger("fem_elastic.study.accuracy")

#: The problems, in the order of the report and the figure's panels.
PROBLEMS = ("static_tip", "self_weight", "large_deflection", "modal", "dynamic", "linearized")
#: Bodies: the mass-spring network and the four elastic materials.
BODIES = ("springs", "linear", "corotated", "stvk", "neo_hookean")
#: The seven integrators, by class name in ``fem_elastic``.
INTEGRATORS = ("ExplicitEuler", "SymplecticEuler", "Midpoint", "RK4", "ImplicitEuler",
               "LinearizedImplicitEuler", "Newmark")

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
        needs (geometry, material constants, loads, method). Then the
        ``methods/...`` cases of :mod:`~fem_elastic.study.accuracy_methods`
        (trapezoid, Verlet, PBD, XPBD, shape matching, projective dynamics).

    Examples
    --------
    >>> cases = accuracy_cases(quick=True)
    >>> sorted({c.params["problem"] for c in cases}) == sorted(PROBLEMS + ("methods",))
    True
    """
    static_bodies: tuple[str, ...]
    large_bodies: tuple[str, ...]
    # (body, order (None: springs), cells, dt / critical dt, steps per period)
    dyn_combos: list[tuple[str, int | None, tuple[int, int, int], tuple[float, ...], tuple[int, ...]]]
    lin_n: tuple[int, ...]
    order: int | None  # the loops below: 1 or 2, None for the springs
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
    from .accuracy_methods import method_accuracy_cases  # the methods of issue 16 against converged FEM

    return cases + method_accuracy_cases(quick)


# --- one case ------------------------------------------------------------------------------

def _beam(p) -> RectangularCantilever:
    return RectangularCantilever(p["length"], p["width"], p["height"], p["E"], p["nu"])


def _body(p):
    if p["body"] == "springs":
        return MassSpring(E=p["E"], nu=SPRING_NU)
    materials = {"linear": LinearElastic, "corotated": Corotated, "stvk": StVK,
                 "neo_hookean": NeoHookean}
    if p["body"] not in materials:
        raise InvalidParameter(f"body must be one of {BODIES}, got {p['body']!r}")
    return ElasticBody(materials[p["body"]](E=p["E"], nu=p["nu"]), order=p["order"])


def _model(p, mesh=None, **loads):
    """The case's clamped beam under ``loads``; on ``mesh`` when given (a second model of the same beam)."""
    if mesh is None:
        mesh = beam_mesh(p["length"], p["width"], p["height"], cells=tuple(p["cells"]))
    return Model(mesh, p["density"], _body(p), fixed="left", **loads)


def _elastica_traction(p, beam) -> tuple[float, float, float]:
    """The end-face traction (Pa) of the tip load P = alpha E I / L^2 (N), spread uniformly, downward."""
    P = p["alpha"] * p["E"] * beam.second_moment / p["length"] ** 2
    return (0.0, 0.0, -P / beam.area)


def _tip_weights(model, axis: int) -> np.ndarray:
    """w such that w . (x - X) is the area mean of u_axis over the end face (m).

    The nodal forces of a unit traction on "right", over the face's area: the
    work-conjugate of a uniform end load (for P2 it weighs the mid-edge nodes too).
    """
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
    res, seconds, calls = _timed(lambda: solve_static(model, linear_solver=DirectSolver(), stability=False))
    w = -float(_tip_weights(model, 2) @ (res.x - model.X))
    extra = dict(n_dofs=model.ndofs, newton_iterations=res.iterations, load_steps=len(res.load_steps),
                 timed_calls=calls)
    if p["problem"] == "large_deflection":
        u = -float(_tip_weights(model, 0) @ (res.x - model.X))
        extra["shortening_error"] = u / (s * p["length"]) - 1.0
    return _result(w, reference, name, "tip deflection (m)", seconds, **extra)


def _modal(p) -> dict:
    model = _model(p)
    f, seconds, calls = _timed(lambda: natural_frequencies(model, 1))
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
    if name not in INTEGRATORS:
        raise InvalidParameter(f"integrator must be one of {INTEGRATORS}, got {name!r}")
    return getattr(_integrators, name)()


def _simulate_tip(model, integrator, dt, steps, state, sample_every, weights):
    """Run (timed as :func:`_timed` does), sampling the tip every ``sample_every`` steps.

    Returns (samples (k, len(weights)) in m, seconds, Diverged or None, Trajectory or None).
    """
    X = model.X

    def once():
        samples = [[float(w @ (state.x - X)) for w in weights]]

        def sample(k, s):
            if (k + 1) % sample_every == 0:
                samples.append([float(w @ (s.x - X)) for w in weights])

        try:
            run = simulate(model, integrator, dt, steps=steps, state=state, record_every=steps,
                              check_stability=False, callback=sample)
            return np.array(samples), None, run
        except Diverged as exc:
            return np.array(samples), exc, None

    (samples, err, run), seconds, _ = _timed(once)
    return samples, seconds, err, run


def _dynamic(p) -> dict:
    model = _model(p)
    beam = _beam(p)
    f_ref = beam.first_bending_frequency(p["density"])
    integrator = _integrator(p["integrator"])
    freqs, phi = natural_frequencies(model, 1, mass="lumped", return_modes=True)
    f_h, phi = float(freqs[0]), phi[:, 0]
    wz = _tip_weights(model, 2)
    u0 = phi * (-p["amplitude"] / float(wz @ phi))  # tip down by the amplitude
    state = State(model.X + u0, np.zeros(model.ndofs), 0.0)
    dt_se = critical_time_step(model, SymplecticEuler())
    extra = dict(n_dofs=model.ndofs, f_modal_lumped=f_h, dt_critical_symplectic=dt_se)
    if "steps_per_period" in p:
        dt = 1.0 / (p["steps_per_period"] * f_ref)
    else:
        crit = critical_time_step(model, integrator)
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
    beam = _beam(p)
    model = _model(p)
    bent = solve_static(_model(p, model.mesh, traction={"right": _elastica_traction(p, beam)}), stability=False)
    weights = [_tip_weights(model, 0), _tip_weights(model, 2)]
    state = State(bent.x, np.zeros(model.ndofs), 0.0)
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
    t0 = time.perf_counter()
    for body in BODIES:
        for order in (None,) if body == "springs" else (1, 2):
            p = dict(SLENDER, body=body, order=order, cells=[2, 1, 1])
            solve_static(_model(p, traction={"right": (0.0, 0.0, -1.0)}), linear_solver=DirectSolver(), stability=False)
            model = _model(p)
            natural_frequencies(model, 1, mass="lumped")
            state = State.rest(model, displacement=lambda X: 1e-6 * X[:, [2, 2, 0]] ** 2)
            for name in INTEGRATORS:
                simulate(model, _integrator(name), 1e-6, steps=2, state=state, check_stability=False)
    logger.debug("warm-up in %.2f s", time.perf_counter() - t0)


def _methods(p) -> dict:
    from .accuracy_methods import run_method_accuracy_case

    return run_method_accuracy_case(p)


_RUNNERS = {"static_tip": _static, "self_weight": _static, "large_deflection": _static, "modal": _modal,
            "dynamic": _dynamic, "linearized": _linearized, "methods": _methods}


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
        raise InvalidParameter(f"problem must be one of {PROBLEMS + ('methods',)}, got {params.get('problem')!r}")
    if params["problem"] != "methods":  # those warm up their own methods
        _warm_up()
    return _RUNNERS[params["problem"]](params)
