"""fe.study.measure_scaling: cost against mesh size and the fitted power law (issue 19.6)."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.study import scaling


def test_fit_recovers_a_power_law():
    n = np.array([1e3, 3e3, 1e4, 5e4])
    t = np.exp(-2.0) * n**1.3
    a, p = fe.study.fit_power_law(n, t)
    # exact data: the least-squares line through four collinear points in log-log, to the
    # round-off of log and polyfit (~1e-15 relative; 1e-12 leaves room)
    assert p == pytest.approx(1.3, abs=1e-12)
    assert a == pytest.approx(-2.0, abs=1e-12)


def test_fit_is_least_squares_on_the_logs():
    rng = np.random.default_rng(3)
    n = np.geomspace(1e3, 1e5, 7)
    t = 1e-6 * n * np.exp(rng.normal(0.0, 0.2, n.size))
    a, p = fe.study.fit_power_law(n, t)
    # the normal equations: the residuals of the fit are orthogonal to 1 and to log n. Each
    # residual is a difference of terms of size |a| ~ 14, so it carries ~ eps x 14 = 3e-15; over
    # 7 points the sum carries up to 2e-14, and weighted by log n <= 11.5 up to 2.5e-13
    # (measured 2.2e-14 and 2.1e-13): bounds 45-50x the measured values
    r = np.log(t) - (a + p * np.log(n))
    assert abs(r.sum()) < 1e-12 and abs(r @ np.log(n)) < 1e-11


@pytest.mark.parametrize("n, t, what", [
    ([1e3], [1.0], "two distinct"),
    ([1e3, 1e3], [1.0, 2.0], "two distinct"),
    ([1e3, 2e3], [1.0, -2.0], "positive"),
    ([1e3, 2e3], [1.0, np.nan], "positive"),
    ([1e3, 2e3, 3e3], [1.0, 2.0], "equal length"),
])
def test_fit_refuses_what_has_no_power_law(n, t, what):
    with pytest.raises(fe.InvalidParameter, match=what):
        fe.study.fit_power_law(n, t)


def test_beam_cells_keep_the_cells_near_cubes():
    assert scaling.beam_cells(153600) == (100, 16, 16)   # the beam of scripts/bench_step.py
    for target in (1000, 5000, 20000, 80000):
        nx, k, k2 = scaling.beam_cells(target)
        n = 6 * nx * k * k2
        # nx is rounded to the nearest integer of target / (6 k^2): off by at most half a
        # slab of 6 k^2 tets, under 10 % of the target from 1000 tets on (k >= 3)
        assert k == k2 and abs(n - target) <= 3 * k * k < 0.1 * target
        assert 4.0 < nx / k < 9.0                         # a 10:1 beam of near-cubic cells
    with pytest.raises(fe.InvalidParameter, match="n_tets"):
        scaling.beam_cells(3)


def test_result_fits_and_predicts_from_its_medians():
    n = np.array([1000, 4000, 16000])
    # each size's samples have the median 2e-6 n s (and an outlier the median ignores)
    samples = {"assembly": [np.array([2e-6 * k, 2e-6 * k, 9.0]) for k in n]}
    r = scaling.ScalingResult(n, 3 * n, ((1, 1, 1),) * 3, samples, fused=True)
    assert r.operations == ("assembly",)
    assert r.exponents["assembly"] == pytest.approx(1.0, abs=1e-12)
    assert r.predict("assembly", 64000) == pytest.approx(2e-6 * 64000, rel=1e-12)
    assert "assembly 1.00" in r.summary()
    with pytest.raises(fe.InvalidParameter, match="was not timed"):
        r.fit("implicit step")


def test_measure_scaling_times_every_operation_on_small_beams():
    r = fe.study.measure_scaling((200, 1600), repeats=1, clock="process")
    assert r.clock == "process" and "CPU ms" in r.summary()
    assert r.n_tets.tolist() == [192, 1620]
    assert r.n_dofs.tolist() == [3 * 9 * 3 * 3, 3 * 31 * 4 * 4]   # 3 (nx + 1)(k + 1)^2
    assert r.operations == scaling.OPERATIONS
    assert all([len(s) for s in r.samples[op]] == [1, 1] for op in r.operations)
    # a step from rest under gravity needs Newton (at least one iteration) on every mesh,
    # and with AMG-CG (the default where pyamg is installed) at least one CG iteration each
    assert np.all(r.newton_iterations >= 1)
    if importlib.util.find_spec("pyamg"):
        assert np.all(r.linear_iterations >= r.newton_iterations)
    assert "Newton iterations" in r.summary()
    seconds = r.seconds
    for op in r.operations:
        assert np.all(seconds[op] > 0) and np.isfinite(r.exponents[op])
    # a Newton step assembles the tangent at least once, an explicit step needs the gradient
    # alone: the ordering holds at any size (measured 10x margins at 1k tets)
    assert np.all(seconds["implicit step"] > seconds["assembly"])
    assert np.all(seconds["explicit step"] < seconds["assembly"])


def test_plot_draws_points_and_fits(tmp_path):
    pytest.importorskip("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = np.array([1000, 4000, 16000])
    samples = {op: [np.array([c * k]) for k in n]
               for op, c in (("assembly", 1e-5), ("explicit step", 1e-7))}
    ax = scaling.ScalingResult(n, 3 * n, ((1, 1, 1),) * 3, samples, fused=True).plot()
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["assembly: p = 1.00", "explicit step: p = 1.00"]
    assert len(ax.get_lines()) == 4 and ax.get_xscale() == ax.get_yscale() == "log"
    plt.close(ax.figure)


@pytest.mark.parametrize("kwargs, what", [
    ({"n_tets": (1000, 1001)}, "two distinct"),
    ({"n_tets": (1e3, 1e4)}, "n_tets must be an integer"),
    ({"operations": ("assembly", "contact")}, "operations"),
    ({"repeats": 0}, "repeats"),
    ({"implicit_repeats": 0}, "implicit_repeats"),
    ({"blas_threads": 0}, "blas_threads"),
    ({"clock": "cpu"}, "clock"),
])
def test_measure_scaling_refuses_bad_input(kwargs, what):
    kwargs = {"n_tets": (200, 1600), **kwargs}
    with pytest.raises(fe.InvalidParameter, match=what):
        fe.study.measure_scaling(**kwargs)
