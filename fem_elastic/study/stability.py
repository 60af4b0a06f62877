"""The stability study: which integrator survives which stiffness, time step and extreme case.

``fem-elastic study stability [--quick] --out DIR`` runs, through
:func:`fem_elastic.study.run_sweep`, three kinds of case, each one row of
``results.jsonl``:

``sweep``
    Every integrator on every body (springs, linear, corotated, StVK,
    Neo-Hookean) of the kicked cantilever (:func:`stability_cases.cantilever`),
    over Young's modulus E in 1e3 ... 1e11 Pa (nu = 0.3), over nu = 0.49
    and 0.4999 (E = 1e7 Pa), and over dt: 1e-6 ... 1/24 s for the explicit
    schemes, 1e-2 and 1/24 s for the implicit ones (their failures come
    with large steps, and an implicit run costs 10-50 times an explicit one).
``critical``
    For each explicit integrator and each (body, E) of the E sweep, and
    the linear body on the nu sweep: the observed stability limit,
    bracketed by bisection on dt, beside the predicted one,
    :func:`fe.critical_time_step`.
``extreme``
    Every integrator and body on the extreme scenes of
    :mod:`fem_elastic.study.stability_cases`: inverted elements, crush to
    10 % and release, a 720-degree twist and release, a drop onto the
    ground at 20 m/s, nearly flat (sliver) elements, and a degenerate sliver
    mesh that validation must reject.

A fixed number of steps, not a fixed duration
---------------------------------------------
Every sweep run takes :data:`SWEEP_STEPS` = 100 steps, whatever dt. An
instability is a per-step amplification: a mode whose one-step map has
spectral radius ``rho > 1`` multiplies its energy by ``rho^(2N)`` in N
steps, so a fixed N gives every dt the same power to reveal it, and costs
the same. A fixed duration would cost ``T / dt`` steps: 10^5 at the
smallest dt of the sweep. The kick (kinetic energy 1e-3 of the weight
times the length, spread over every mode) and the blow-up bound of
:func:`fe.simulate` (the total energy growing by more than the scene's
energy scale, here the weight times the length) then set the resolution:
with about 1/70 of the kick in the top mode, growth is detected within
N = 100 steps once ``rho^200 > ~7e4``, i.e. ``rho > 1.06``: symplectic
Euler (``rho - 1 ~ 2 sqrt(2 eps)`` at ``(1 + eps)`` times its limit
``2 / omega_max``) reaches that 0.04 % above it, RK4 (``rho - 1 ~ 7 eps``
near ``2 sqrt(2) / omega_max``) about 0.8 % above. Explicit Euler and explicit midpoint grow at
every dt on an undamped body (their predicted limit is 0); what the study
observes for them is the largest dt whose growth stays below the bound
for 100 steps, a finite-horizon limit that scales as ``N^(-1/2)``
(``N^(-1/4)`` for midpoint).

Verdicts
--------
Each run ends with one of

- ``stable``: all steps taken; with the energy drift
  ``(E_end - E_0) / S`` in % (``E_0`` the total energy once no boundary is
  driven; ``S`` the largest energy exchanged over that window: the
  largest of the swing of the total and of the potential energy and the
  kinetic energy, so that ``|drift| <= 100 %``), the largest rise of the total energy above
  ``E_0`` in the same units, and the smallest ``det F = V / V_0`` of any
  tet over the run (< 0: some element was inverted; the runs of the
  extreme cases and the soft beams do invert elements of every body but
  Neo-Hookean, which "stable" does not exclude);
- ``diverged``: :class:`fe.Diverged` at step k, with its reason
  (non-finite state, energy growth, an implicit step failing for a reason
  other than Newton);
- ``newton failed``: an implicit step whose Newton iterations did not
  converge even after halving dt (:class:`fe.Diverged` whose reason starts
  with "Newton did not converge", or :class:`fe.NotConverged`);
- ``rejected``: building the scene raised a typed error
  (:class:`fe.InvalidMesh`, :class:`fe.InvalidParameter`), with its message;
- ``work limit``: the run was stopped after :data:`WORK_LIMIT` Newton
  iterations plus line-search cuts (a deterministic cap, so that a run
  that crawls with cut after cut cannot hold the study for minutes);
- ``error``: anything else: a bug, listed first in the report.

A ``critical`` row's verdict is ``bracketed`` (a stable dt below an
unstable one, at most ``2^(1/256)`` apart, i.e. 0.27 %), ``stable at every
dt tried`` or ``unstable at every dt tried``.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from pathlib import Path

import numpy as np

from ..dynamics import integrators as _integrators
from ..errors import Diverged, FemElasticError, InvalidMesh, InvalidParameter, NotConverged
from ..geometry.mesh import _signed_volumes
from ..solvers.modal import critical_time_step, max_frequency
from ..dynamics.simulate import simulate
from . import stability_cases as sc
from .executor import Case, run_sweep
from .report import StudyResult, finish_study

__all__ = [
    "INTEGRATORS",
    "EXPLICIT",
    "SWEEP_STEPS",
    "WORK_LIMIT",
    "VERDICTS",
    "StudyResult",
    "study_cases",
    "run_stability_case",
    "run_stability_study",
    "largest_stable_dt",
    "critical_dt_table",
    "extreme_matrix",
    "conclusions",
    "plot_stability_map",
    "plot_extreme",
    "write_report",
]

log = logging.getLogger(__name__)

#: The seven integrators, in the report's order.
INTEGRATORS = ("ExplicitEuler", "SymplecticEuler", "Midpoint", "RK4", "ImplicitEuler",
               "LinearizedImplicitEuler", "Newmark")
#: Those with a step-size limit.
EXPLICIT = ("ExplicitEuler", "SymplecticEuler", "Midpoint", "RK4")
#: Steps of every sweep and bisection run (see the module notes).
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


# ----------------------------------------------------------------------------------------------
# The cases
# ----------------------------------------------------------------------------------------------
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
    """The cases of the stability study (see the module notes).

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

    Examples
    --------
    >>> cases = study_cases(quick=True)
    >>> sorted({c.params["kind"] for c in cases}), len(cases)
    (['critical', 'extreme', 'sweep'], 78)
    """
    sweep, critical, extreme = [], [], []
    for integ in INTEGRATORS:
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
    return cases


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


# ----------------------------------------------------------------------------------------------
# One run
# ----------------------------------------------------------------------------------------------
class _WorkLimit(Exception):
    def __init__(self, step):
        super().__init__(step)
        self.step = step


def _integrator(name: str):
    if name not in INTEGRATORS:
        raise InvalidParameter(f"integrator must be one of {INTEGRATORS}, got {name!r}.")
    return getattr(_integrators, name)()


def _scene(params):
    if params["kind"] == "extreme":
        return sc.extreme_scene(params["case"], params["body"], params["E"], params["nu"])
    return sc.cantilever(params["body"], params["E"], params["nu"])


def _min_J(model, x, tets, volumes0):
    """Smallest V / V_0 over the tets at positions x (dimensionless; < 0: inverted)."""
    p = model.to_vertices(x)
    return float(np.min(_signed_volumes(p, tets) / volumes0))


def _classify(err) -> str:
    if isinstance(err, NotConverged):
        return "newton failed"
    reason = getattr(err, "reason", None) or str(err)
    return "newton failed" if reason.startswith("Newton did not converge") else "diverged"


def _energy_figures(scene, traj):
    """Total energy (J) at t_free and at the end, the energy scale S (J), drift and largest rise (% of S)."""
    window = traj.times >= scene.t_free - 1e-12
    if not window.any():
        return {}
    total, kin, pot = traj.total[window], traj.kinetic[window], traj.potential[window]
    # the largest energy exchanged in the window, so |drift| <= 100 % of it. Not floored by the
    # weight times the size: the swept beam's kick is 1e-3 of that, and such a floor would report a
    # loss of 78 % of the energy in play as a drift of -0.078 %.
    S = max(float(np.ptp(total)), float(np.ptp(pot)), float(kin.max()))
    if not (S > 0 and math.isfinite(S)):
        return {"energy_scale": S}
    return {
        "energy_initial": float(total[0]),
        "energy_final": float(total[-1]),
        "energy_scale": S,
        "energy_drift_pct": 100.0 * float(total[-1] - total[0]) / S,
        "energy_rise_pct": 100.0 * float(total.max() - total[0]) / S,
    }


def _simulate(scene, integrator_name, dt, steps, work_limit=WORK_LIMIT):
    """Run one scene; the verdict and the run's figures as a dict."""
    model, state = scene.model, scene.state
    integ = _integrator(integrator_name)
    tets = np.asarray(model.mesh.t).T
    volumes0 = _signed_volumes(np.asarray(model.mesh.p, dtype=float).T, tets)
    jmin = _min_J(model, state.x, tets, volumes0)
    umax = float(np.abs(state.x - model.X).max())
    work = 0

    def watch(k, s):
        nonlocal jmin, umax, work
        jmin = min(jmin, _min_J(model, s.x, tets, volumes0))
        umax = max(umax, float(np.abs(s.x - model.X).max()))
        st = integ.last_stats
        work += st.newton_iterations + st.line_search_cuts
        if work > work_limit:
            raise _WorkLimit(k)

    out = {"dt_used": dt, "steps_used": steps}
    traj = None
    t0 = time.perf_counter()
    with np.errstate(all="ignore"), warnings.catch_warnings():
        # a blow-up overflows on its way to the non-finite check; that is the verdict, not a warning
        warnings.simplefilter("ignore", RuntimeWarning)
        try:
            traj = simulate(model, integ, dt, steps=steps, state=state, check_stability=False,
                            callback=watch)
            out.update(verdict="stable", step=None, reason="")
        except Diverged as err:
            traj = err.trajectory
            out.update(verdict=_classify(err), step=err.step, reason=err.reason or str(err))
        except NotConverged as err:
            out.update(verdict="newton failed", step=None, reason=str(err))
        except _WorkLimit as err:
            out.update(verdict="work limit", step=err.step,
                       reason=f"stopped after {work} Newton iterations and line-search cuts "
                              f"(limit {work_limit}) at step {err.step}")
        except FemElasticError as err:  # a typed error in a run: a bug of the scene or library
            out.update(verdict="error", step=None, reason=f"{type(err).__name__}: {err}")
        except Exception as err:  # noqa: BLE001 - recorded as a bug, listed first in the report
            log.warning("%s: %s: %s (a bug: recorded as verdict 'error')", integrator_name,
                        type(err).__name__, err)
            log.debug("traceback", exc_info=True)
            out.update(verdict="error", step=None, reason=f"{type(err).__name__}: {err}")
    out["wall_time"] = time.perf_counter() - t0
    out["min_J"] = jmin
    out["u_max"] = umax
    if traj is not None:
        st = traj.step_stats
        out["t_reached"] = float(traj.times[-1])
        out["newton_iterations"] = int(np.sum(st.get("newton_iterations", 0)))
        out["line_search_cuts"] = int(np.sum(st.get("line_search_cuts", 0)))
        out["steps_cut"] = int(np.count_nonzero(st.get("dt_cuts", ())))
        if out["verdict"] == "stable":
            out.update(_energy_figures(scene, traj))
    return out


def _build(params):
    """(scene, None) or (None, rejected-row) when the scene is refused with a typed error."""
    try:
        return _scene(params), None
    except (InvalidMesh, InvalidParameter) as err:
        return None, {"verdict": "rejected", "step": None, "reason": f"{type(err).__name__}: {err}"}


def run_stability_case(params: dict) -> dict:
    """Run one case of the study (a module-level function of its params, for the executor).

    Parameters
    ----------
    params : dict
        As made by :func:`study_cases`: ``kind``, ``case``, ``integrator``,
        ``body``, ``E`` (Pa), ``nu``, ``dt`` (s or None), ``steps``.

    Returns
    -------
    dict
        ``verdict`` (see the module notes), ``step`` (the failing step or
        None), ``reason``, ``dt_used`` (s) and ``steps_used`` (the params'
        dt and steps, or what the scene set for None), ``wall_time`` (s), ``min_J``,
        ``energy_drift_pct`` and ``energy_rise_pct`` (stable runs),
        ``u_max`` (m, the largest displacement component over the run; for a
        critical row, of the stable run at ``dt_observed_lo``),
        ``newton_iterations``, ``line_search_cuts``, ``steps_cut``; critical
        and extreme rows add ``dt_predicted`` (s; inf for implicit schemes)
        and, for explicit schemes, ``omega_max`` (rad/s); critical
        rows ``dt_observed_lo``, ``dt_observed_hi`` (s), ``ratio_lo``,
        ``ratio_hi`` (observed over predicted) and ``runs`` (each bisection
        run as ``[dt, verdict, step]``).

    Examples
    --------
    >>> row = run_stability_case(dict(kind="sweep", case="cantilever", integrator="ImplicitEuler",
    ...                               body="linear", E=1e7, nu=0.3, dt=1e-2, steps=10))
    >>> row["verdict"], row["step"], row["energy_drift_pct"] < 0  # implicit Euler dissipates
    ('stable', None, True)
    """
    kind = params["kind"]
    scene, rejected = _build(params)
    if rejected is not None:
        return rejected
    integ = params["integrator"]
    extra = {}
    if kind != "sweep":  # the sweep's predictions are its critical rows'
        if integ in EXPLICIT:
            extra["omega_max"] = max_frequency(scene.model)
            extra["dt_predicted"] = critical_time_step(scene.model, _integrator(integ))
        else:
            extra["dt_predicted"] = math.inf
    if kind == "critical":
        return {**extra, **_bracket(scene, integ, params["steps"], extra["omega_max"], extra["dt_predicted"])}
    dt, steps = params["dt"], params["steps"]
    if dt is None:  # an explicit extreme run: half symplectic Euler's limit, 1 / omega_max
        dt = 0.5 * critical_time_step(scene.model, _integrator("SymplecticEuler"))
    if steps is None:
        steps = max(1, math.ceil(scene.duration / dt - 1e-9))
        if integ in EXPLICIT:
            steps = min(steps, EXPLICIT_MAX_FORCES // _FORCES_PER_STEP[integ])
    return {**extra, **_simulate(scene, integ, dt, steps)}


def _bracket(scene, integ, steps, omega_max, predicted):
    """The observed stability limit of an explicit scheme, by doubling/halving then bisection."""
    runs = []

    u_max = {}

    def stable(dt):
        r = _simulate(scene, integ, dt, steps)
        runs.append([dt, r["verdict"], r["step"]])
        u_max[dt] = r["u_max"]
        return r["verdict"] == "stable", r

    start = predicted if 0.0 < predicted < math.inf else 2.0 / omega_max
    ok, _ = stable(start)
    lo = hi = None
    if ok:
        lo = start
        for _ in range(20):
            if not stable(2.0 * lo)[0]:
                hi = 2.0 * lo
                break
            lo *= 2.0
    else:
        hi = start
        for _ in range(30):
            if stable(0.5 * hi)[0]:
                lo = 0.5 * hi
                break
            hi *= 0.5
    out = {"runs": runs}
    if lo is None or hi is None:
        out.update(verdict="unstable at every dt tried" if lo is None else "stable at every dt tried",
                   dt_observed_lo=lo, dt_observed_hi=hi, step=None, reason="")
        return out
    for _ in range(BISECTIONS):
        mid = math.sqrt(lo * hi)
        if stable(mid)[0]:
            lo = mid
        else:
            hi = mid
    last_hi = next(r for r in reversed(runs) if r[0] == hi)
    out.update(verdict="bracketed", dt_observed_lo=lo, dt_observed_hi=hi, step=last_hi[2], u_max=u_max[lo],
               reason=f"stable at {lo:.6g} s, {last_hi[1]} at {hi:.6g} s (step {last_hi[2]})")
    if 0.0 < predicted < math.inf:
        out.update(ratio_lo=lo / predicted, ratio_hi=hi / predicted)
    out.update(h_omega_lo=lo * omega_max, h_omega_hi=hi * omega_max)
    return out


# ----------------------------------------------------------------------------------------------
# Summaries of the rows
# ----------------------------------------------------------------------------------------------
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
    groups = {}
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
    out = {}
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
        pts = {k: v for k, v in stable_dt.items() if k[0] == integ}
        if not pts:
            continue
        clean = [k for k, v in pts.items() if not v["failures"]]
        text = f"{integ}: stable at every dt of the sweep on {len(clean)} of {len(pts)} (body, E, nu)"
        bad = sorted((k for k in pts if pts[k]["failures"]), key=lambda k: (k[1], k[2], k[3]))
        if bad:
            text += "; not on " + "; ".join(
                f"{_where(k)} ({', '.join(f'{v} at dt={_dt_label(dt)}' for dt, v, _ in pts[k]['failures'])})"
                for k in bad)
        out.append(text + ".")
    matrix = extreme_matrix(rows)
    tally = {}
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


# ----------------------------------------------------------------------------------------------
# Figures
# ----------------------------------------------------------------------------------------------
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


# ----------------------------------------------------------------------------------------------
# The report
# ----------------------------------------------------------------------------------------------
def _sig(x, digits=3) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-" if x is None or math.isnan(x) else ("inf" if x > 0 else "-inf")
    return f"{x:.{digits}g}"


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

    lines += ["## Conclusions", ""]
    lines += [f"- {c}" for c in conclusions(rows)] or ["- (no runs)"]
    lines += [""]
    return write_text_atomic(Path(path), "\n".join(lines))


# ----------------------------------------------------------------------------------------------
# The study
# ----------------------------------------------------------------------------------------------
def run_stability_study(out_dir, *, quick: bool = False, executor=None, workers=None, progress: bool = True,
                        _case_filter=None) -> StudyResult:
    """Run the stability study and write its results, figures and report to ``out_dir``.

    Parameters
    ----------
    out_dir : str or os.PathLike
        Created if missing. Holds ``results.jsonl`` (every run, appended as it
        finishes; a second call resumes and runs only what is missing),
        ``results.csv``, ``stability_map.png``, ``extreme.png`` and ``report.md``.
    quick : bool
        The small study (78 cases, about 13 s on 2 cores) instead of the full
        one (1398 cases, about 3 min on 2 cores).
    executor : None, "process", "serial", concurrent.futures.Executor or dask.distributed.Client
        Where the runs go (:func:`fem_elastic.study.run_sweep`): by default a
        process pool of ``workers`` processes. On a Dask cluster::

            from dask.distributed import Client
            fe.study.run_stability_study("results/stability", executor=Client("tcp://scheduler:8786"))

    workers : int, optional
        Processes of the default pool (``os.cpu_count()`` if None).
    progress : bool
        Show a progress bar (tqdm).

    Returns
    -------
    StudyResult
        ``rows``, ``csv_path``, ``report_path``, ``figures``, ``n_run``, ``wall_time``.

    Raises
    ------
    fem_elastic.study.SweepIncomplete
        When the executor lost runs; what finished is kept, call again to resume.
    """
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    cases = study_cases(quick)
    if _case_filter is not None:  # tests: a subset of the study
        cases = [c for c in cases if _case_filter(c)]
    rows = run_sweep(cases, run_stability_case, out_dir, executor=executor, workers=workers, progress=progress,
                     desc="stability study")

    def figures():
        return [(plot_stability_map(rows), "stability_map.png"), (plot_extreme(rows), "extreme.png")]

    return finish_study("stability study", rows, out_dir, t0=t0, n_run=rows.n_run, quick=quick, table=rows,
                        figures=figures, write_report=write_report)
