"""One run of the stability study: :func:`run_stability_case`, its verdict, and the critical-dt bisection.

:func:`run_stability_case` is the sweep's function (at module level, so that
worker processes can unpickle it): it builds a case's scene, simulates it with
a watch on the smallest det F and on the Newton work, and classifies how the
run ended; a ``critical`` case brackets the observed stability limit of an
explicit scheme by bisection on dt.
"""

from __future__ import annotations

import logging
import math
import time
import warnings

import numpy as np

from ..dynamics import integrators as _integrators
from ..dynamics.simulate import simulate
from ..errors import Diverged, FemElasticError, InvalidMesh, InvalidParameter, NotConverged
from ..geometry.mesh import _signed_volumes
from ..solvers.modal import critical_time_step, max_frequency
from . import stability_cases as sc
from .stability_sweep import _FORCES_PER_STEP, BISECTIONS, EXPLICIT, EXPLICIT_MAX_FORCES, INTEGRATORS, WORK_LIMIT

__all__ = ["run_stability_case"]

# the study's logger, under the name it had before the study was split into modules
log = logging.getLogger("fem_elastic.study.stability")


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


class _Unbounded(Exception):
    def __init__(self, step, u):
        super().__init__(step)
        self.step, self.u = step, u


def _simulate(scene, integrator_name, dt, steps, work_limit=WORK_LIMIT, *, integrator=None,
              energy_growth=1.0, displacement_limit=math.inf):
    """Run one scene; the verdict and the run's figures as a dict.

    ``integrator`` (default: a new ``integrator_name``), ``energy_growth`` (the blow-up
    watch's bound, :func:`fe.simulate`) and ``displacement_limit`` (m: a larger displacement
    is a divergence) serve the methods rows (:mod:`~fem_elastic.study.stability_methods`).
    """
    model, state = scene.model, scene.state
    integ = _integrator(integrator_name) if integrator is None else integrator
    tets = np.asarray(model.mesh.t).T
    volumes0 = _signed_volumes(np.asarray(model.mesh.p, dtype=float).T, tets)
    jmin = _min_J(model, state.x, tets, volumes0)
    umax = float(np.abs(state.x - model.X).max())
    work = 0

    def watch(k, s):
        nonlocal jmin, umax, work
        jmin = min(jmin, _min_J(model, s.x, tets, volumes0))
        umax = max(umax, float(np.abs(s.x - model.X).max()))
        if not umax <= displacement_limit:
            raise _Unbounded(k, umax)
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
                            callback=watch, energy_growth=energy_growth)
            out.update(verdict="stable", step=None, reason="")
        except Diverged as err:
            traj = err.trajectory
            out.update(verdict=_classify(err), step=err.step, reason=err.reason or str(err))
        except NotConverged as err:
            out.update(verdict="newton failed", step=None, reason=str(err))
        except _Unbounded as err:
            out.update(verdict="diverged", step=err.step,
                       reason=f"displacement {err.u:.3g} m past the limit of {displacement_limit:.3g} m")
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
        ``verdict`` (see the notes of :mod:`fem_elastic.study.stability`), ``step`` (the failing step or
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
    if kind == "methods":
        from .stability_methods import run_method_case

        return run_method_case(params, _simulate)
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
