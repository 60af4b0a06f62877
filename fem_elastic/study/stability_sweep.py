"""The stability study's sweep: its constants and its list of cases.

:func:`study_cases` lists the runs of the study (sweep, critical and extreme
cases over integrators, bodies, E, nu and dt); the constants here (the
integrators, the step count of every sweep run, the work limit, the verdicts)
are the study's, shared by the runner, the summaries, the figures and the
report. The scenes themselves are built by
:mod:`fem_elastic.study.stability_cases`; why the sweep is what it is, is told
in :mod:`fem_elastic.study.stability`.
"""

from __future__ import annotations

from . import stability_cases as sc
from .executor import Case

__all__ = [
    "INTEGRATORS",
    "EXPLICIT",
    "SWEEP_STEPS",
    "BISECTIONS",
    "WORK_LIMIT",
    "EXPLICIT_MAX_FORCES",
    "VERDICTS",
    "study_cases",
]

#: The seven integrators, in the report's order.
INTEGRATORS = ("ExplicitEuler", "SymplecticEuler", "Midpoint", "RK4", "ImplicitEuler",
               "LinearizedImplicitEuler", "Newmark")
#: Those with a step-size limit.
EXPLICIT = ("ExplicitEuler", "SymplecticEuler", "Midpoint", "RK4")
#: Steps of every sweep and bisection run (see :mod:`fem_elastic.study.stability`).
SWEEP_STEPS = 100
#: Geometric bisections of the bracket [lo, 2 lo]: the observed limit to 2^(1/256) = 0.27 %.
BISECTIONS = 8
#: Newton iterations plus line-search cuts after which a run is stopped ("work limit"):
#: a 100-step implicit run of the soft nonlinear beam takes 300-500, so 1000 is twice that.
WORK_LIMIT = 1000
#: Most force evaluations of an explicit extreme run. Its dt is fixed by the scene
#: (1 / omega_max), so a scene may need more steps than this allows: the run then covers
#: less time (``t_reached``); an unstable step shows within tens of steps anyway.
EXPLICIT_MAX_FORCES = 1200
#: The verdicts of a run, in the report's order.
VERDICTS = ("stable", "diverged", "newton failed", "rejected", "work limit", "error")

_FORCES_PER_STEP = {"ExplicitEuler": 1, "SymplecticEuler": 1, "Midpoint": 2, "RK4": 4}
# Full sweep: E at nu = 0.3 (springs represent nu = 1/4 only), nu at E = 1e7 Pa, dt (s).
_E_GRID = (1e3, 1e5, 1e7, 1e9, 1e11)
_NU = 0.3
_NU_GRID = (0.49, 0.4999)
_E_NU = 1e7
_DT_EXPLICIT = (1 / 24, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6)
# Implicit schemes at the two large steps only: their failures (Newton, nonlinear energy
# growth) come with large steps, and each implicit run costs ~1-5 s on this beam.
_DT_IMPLICIT = (1 / 24, 1e-2)
# Extreme cases: a rubber-like body (E = 1e5 Pa); implicit schemes at frame rate and at 1/100 s.
_E_EXTREME, _NU_EXTREME = 1e5, 0.3
_DT_EXTREME = (1 / 24, 1e-2)
# A limit observed within this fraction below the prediction is "near" it: a scheme at its
# exact limit (symplectic Euler's double eigenvalue -1) grows linearly, and the bisection
# resolves 0.27 %; 1 % is a few bisection steps.
_NEAR = 0.01
# Quick: a few points that still give every kind of case and verdict (the degenerate sliver
# is rejected).
_QUICK_POINTS = (("linear", 1e7, _NU), ("neohookean", 1e3, _NU), ("neohookean", _E_NU, 0.4999),
                 ("springs", 1e11, 0.25))
# The very soft corotated beam (it sags metres): at dt = 1/24 s Newton fails, at 1/100 s implicit
# Euler runs into the work limit (about 2 s each).
_QUICK_EXTRA = (("ImplicitEuler", "corotated", 1e3, _NU, 1 / 24),
                ("ImplicitEuler", "corotated", 1e3, _NU, 1e-2))
_QUICK_DT_EXPLICIT = (1 / 24, 1e-3, 1e-5)
_QUICK_DT_IMPLICIT = (1 / 24,)
_QUICK_CRITICAL = (("linear", 1e7, _NU),)


def _sweep_points(quick: bool):
    """(body, E (Pa), nu) of the sweep."""
    if quick:
        return list(_QUICK_POINTS)
    points = []
    for b in sc.BODIES:
        if b == "springs":  # nu is not a parameter of a spring network (it is 1/4)
            points += [(b, E, 0.25) for E in _E_GRID]
        else:
            points += [(b, E, _NU) for E in _E_GRID] + [(b, _E_NU, nu) for nu in _NU_GRID]
    return points


def _critical_points(quick: bool):
    """(body, E (Pa), nu) of the bisections: every body on the E sweep, the linear body on the nu sweep."""
    if quick:
        return list(_QUICK_CRITICAL)
    return [(b, E, nu) for b, E, nu in _sweep_points(False) if nu == _NU or b in ("springs", "linear")]


def _fmt(x: float) -> str:
    return f"{x:.6g}"


def study_cases(quick: bool = False) -> list:
    """The cases of the stability study (see :mod:`fem_elastic.study.stability`).

    Parameters
    ----------
    quick : bool
        A small subset that still has every kind of case, every extreme
        scene and every verdict of the full study but "error" (which must
        not happen): stable, diverged, newton failed, rejected, work limit.

    Returns
    -------
    list of Case
        Params: ``kind`` ("sweep", "critical", "extreme"), ``case`` (the
        scene), ``integrator``, ``body``, ``E`` (Pa), ``nu``, ``dt`` (s; None
        for a critical case and for an explicit extreme run, whose dt is
        1 / omega_max of the scene) and ``steps`` (None: the scene's duration).
        Last, the ``kind = "methods"`` cases (the methods of issue 16, the same in
        both sweeps; :func:`fem_elastic.study.stability_methods.method_cases`), whose
        ``integrator`` is a label of :data:`~fem_elastic.study.stability_methods.METHODS`.

    Examples
    --------
    >>> cases = study_cases(quick=True)
    >>> sorted({c.params["kind"] for c in cases}), len(cases)
    (['critical', 'extreme', 'methods', 'sweep'], 106)
    """
    sweep, critical, extreme = [], [], []
    for integ in INTEGRATORS:
        dts: tuple[float, ...]
        if integ in EXPLICIT:
            dts = _QUICK_DT_EXPLICIT if quick else _DT_EXPLICIT
        else:
            dts = _QUICK_DT_IMPLICIT if quick else _DT_IMPLICIT
        for body, E, nu in _sweep_points(quick):
            for dt in dts:
                p = dict(kind="sweep", case="cantilever", integrator=integ, body=body, E=E, nu=nu,
                         dt=dt, steps=SWEEP_STEPS)
                sweep.append(Case(f"sweep/{integ}/{body}/E={_fmt(E)}/nu={_fmt(nu)}/dt={_fmt(dt)}", p))
    if quick:
        for integ, body, E, nu, dt in _QUICK_EXTRA:
            p = dict(kind="sweep", case="cantilever", integrator=integ, body=body, E=E, nu=nu, dt=dt,
                     steps=SWEEP_STEPS)
            sweep.append(Case(f"sweep/{integ}/{body}/E={_fmt(E)}/nu={_fmt(nu)}/dt={_fmt(dt)}", p))
    for integ in EXPLICIT:
        for body, E, nu in _critical_points(quick):
            p = dict(kind="critical", case="cantilever", integrator=integ, body=body, E=E, nu=nu,
                     dt=None, steps=SWEEP_STEPS)
            critical.append(Case(f"critical/{integ}/{body}/E={_fmt(E)}/nu={_fmt(nu)}", p))
    for case, integ, body, dt in _extreme_points(quick):
        p = dict(kind="extreme", case=case, integrator=integ, body=body, E=_E_EXTREME,
                 nu=0.25 if body == "springs" else _NU_EXTREME, dt=dt, steps=None)
        extreme.append(Case(f"extreme/{case}/{integ}/{body}/dt={'auto' if dt is None else _fmt(dt)}", p))
    # the long runs first, so that a process pool ends on short ones
    implicit = [c for c in sweep if c.params["integrator"] not in EXPLICIT]
    cases = implicit + extreme + critical + [c for c in sweep if c.params["integrator"] in EXPLICIT]
    from .stability_methods import method_cases

    return cases + method_cases()


def _extreme_points(quick: bool):
    """(case, integrator, body, dt) of the extreme runs; dt None: 1 / omega_max."""
    pts = []
    for case in sc.EXTREME_CASES:
        if quick:
            pts += [(case, "SymplecticEuler", "neohookean", None), (case, "ImplicitEuler", "neohookean", 1 / 24)]
            continue
        for integ in INTEGRATORS:
            for body in sc.BODIES:
                if integ in EXPLICIT:
                    pts.append((case, integ, body, None))
                else:
                    pts += [(case, integ, body, dt) for dt in _DT_EXTREME]
    return pts
