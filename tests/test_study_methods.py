"""The studies' rows for the methods of issue 16: trapezoid, Verlet, PBD, XPBD, shape matching, projective dynamics.

Accuracy (``fem_elastic.study.accuracy_methods``): a few quick cases run directly; their errors are
finite and ordered as the physics says. Stability (``fem_elastic.study.stability_methods``): a few
cells whose verdict follows from the method (an explicit scheme far past its limit diverges; the
unconditionally stable ones survive), and the report's section.
"""

import math

import pytest

from fem_elastic.study import accuracy_methods as am
from fem_elastic.study import stability_methods as sm
from fem_elastic.study.accuracy import accuracy_cases, run_accuracy_case
from fem_elastic.study.stability import run_stability_case, study_cases


def _case(cid, quick=True):
    return next(c for c in accuracy_cases(quick=quick) if c.id == cid)


def _run(cid):
    row = dict(_case(cid).params, id=cid, status="ok")
    row.update(run_accuracy_case(_case(cid).params))
    return row


@pytest.fixture(scope="module")
def rows():
    ids = ["methods/period/Trapezoid/N=16", "methods/period/Trapezoid/N=32",
           "methods/period/XPBD edge_volume/iterations=10", "methods/period/XPBD edge_volume/iterations=100",
           "methods/sag/PBD/iterations=5", "methods/sag/PBD/iterations=20",
           "methods/period/XPBD/substeps=1"]
    return {cid: _run(cid) for cid in ids}


def test_every_method_on_every_scene_of_the_full_sweep_and_on_the_quick_period():
    for quick in (True, False):
        cases = [c for c in accuracy_cases(quick) if c.params["problem"] == "methods"]
        pairs = {(c.params["scene"], c.params["method"]) for c in cases}
        if quick:  # the quick study stays quick: every method on the period, cheap runs on the statics
            assert {m for s, m in pairs if s == "period"} == set(am.METHODS)
            assert {s for s, m in pairs} == set(am.METHOD_SCENES)
            assert len(cases) <= 30
        else:
            assert pairs == {(s, m) for s in am.METHOD_SCENES for m in am.METHODS}
        # PBD's knob is its iterations, not dt (its error does not fall with dt); Trapezoid's is dt
        assert {c.params["knob"] for c in cases if c.params["method"] == "PBD"} == {"iterations"}
        assert {c.params["knob"] for c in cases if c.params["method"] == "Trapezoid"} == {"N"}
    assert len([c for c in accuracy_cases(False) if c.params["problem"] == "methods"]) > \
        len([c for c in accuracy_cases(True) if c.params["problem"] == "methods"])


def test_errors_are_finite_and_ordered_as_the_physics_says(rows):
    for cid, r in rows.items():
        if cid.endswith("XPBD/substeps=1"):
            continue
        assert r.get("status", "ok") == "ok", r
        assert math.isfinite(r["rel_error"]) and r["abs_error"] == abs(r["rel_error"]), cid
        assert r["seconds_solve"] > 0 and r["dt"] > 0
    # the trapezoid rule is second order in dt: halving dt divides the frequency error by ~4 (3 to 5:
    # the leading term (omega h)^2 / 12 has a next term of relative size (omega h)^2 ~ 0.15 at N = 16)
    e16, e32 = (rows[f"methods/period/Trapezoid/N={n}"]["abs_error"] for n in (16, 32))
    assert 3.0 < e16 / e32 < 5.0, (e16, e32)
    # XPBD's edge/volume form converges, as the iterations grow, to implicit Euler on the same energy
    # (the springs): its error against converged FEM falls by more than 5x from 10 to 100 iterations
    # (measured -54 % to -4.5 %; what is left is implicit Euler's own period error at 32 steps per period)
    x10, x100 = (rows[f"methods/period/XPBD edge_volume/iterations={n}"] for n in (10, 100))
    assert x100["abs_error"] < 0.2 * x10["abs_error"]
    assert x100["reference_energy"] == "springs"
    # PBD's answer is no material's: its sag moves by more than 2x between 5 and 20 iterations at one dt
    p5, p20 = (rows[f"methods/sag/PBD/iterations={n}"] for n in (5, 20))
    assert p5["dt"] == p20["dt"] and p5["value"] / p20["value"] > 2.0
    # the Neo-Hookean constraints at h omega_max >> 2 without substeps: no answer, said so
    nh = rows["methods/period/XPBD/substeps=1"]
    assert nh["status"] in ("no oscillation", "diverged") or nh["abs_error"] > 0.5


def test_report_section_and_figure(rows):
    lines = am.methods_report_lines(list(rows.values()))
    text = "\n".join(lines)
    for phrase in ("## The methods of issue 16 against converged FEM", "| scene | method | knob |",
                   "iterations per step = 100", "steps per period = 16", "PBD's answer drifts"):
        assert phrase in text, phrase
    assert "period, XPBD edge_volume: the error against its reference falls with every refinement" in text
    pytest.importorskip("matplotlib")
    fig = am.plot_methods(list(rows.values()))
    assert len(fig.axes) == 2  # the scenes with runs: sag and period
    assert am.plot_methods([]) is None


def test_stability_rows_for_the_methods():
    ids = {c.id for c in study_cases(quick=True)}
    assert {c.id for c in sm.method_cases()} <= ids
    verdicts = {}
    for cid in ("methods/stiff steel/VelocityVerlet", "methods/stiff steel/XPBD edge_volume",
                "methods/huge steps/ShapeMatching"):
        p = next(c for c in sm.method_cases() if c.id == cid).params
        verdicts[cid] = dict(p, id=cid, status="ok", **run_stability_case(p))
    # steel at a frame's step is ~1e3 times past Verlet's explicit limit: its first steps blow up
    v = verdicts["methods/stiff steel/VelocityVerlet"]
    assert v["verdict"] == "diverged" and v["step"] is not None and v["step"] < 5
    # XPBD's compliance makes any step stable (it is too soft, not unstable)
    x = verdicts["methods/stiff steel/XPBD edge_volume"]
    assert x["verdict"] == "stable" and x["u_max"] < sm.DISPLACEMENT_LIMIT
    # shape matching at dt = 0.5 s under gravity: the explicit external force throws the beam away
    s = verdicts["methods/huge steps/ShapeMatching"]
    assert s["verdict"] == "diverged" and "displacement" in s["reason"]
    text = "\n".join(sm.methods_report_lines(list(verdicts.values())))
    assert "## The methods of issue 16 on hard scenes" in text and "| VelocityVerlet | diverged at step" in text
