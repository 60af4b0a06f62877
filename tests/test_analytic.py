"""Closed-form beam formulas: hand-checked values and limits."""

import math

import pytest

import fem_elastic as fe


def test_euler_bernoulli_values():
    b = fe.RectangularCantilever(length=2.0, width=0.1, height=0.2, E=2e11, nu=0.3)
    I = 0.1 * 0.2**3 / 12
    assert b.second_moment == pytest.approx(I, rel=1e-15)
    assert b.tip_load_euler_bernoulli(1e3) == pytest.approx(1e3 * 8 / (3 * 2e11 * I), rel=1e-14)
    assert b.distributed_load_euler_bernoulli(1e3) == pytest.approx(1e3 * 16 / (8 * 2e11 * I), rel=1e-14)


def test_timoshenko_adds_shear_that_vanishes_for_slender_beams():
    def ratio(L):
        b = fe.RectangularCantilever(length=L, width=0.1, height=0.1, E=1e9, nu=0.3)
        return b.tip_load_timoshenko(1.0) / b.tip_load_euler_bernoulli(1.0) - 1
    # the shear share scales as (h / L)^2: ten times longer, a hundred times smaller
    assert ratio(1.0) > 0
    assert ratio(1.0) / ratio(10.0) == pytest.approx(100.0, rel=1e-12)


def test_shear_coefficient_of_rectangle():
    b = fe.RectangularCantilever(length=1.0, width=1.0, height=1.0, E=1.0, nu=0.0)
    assert b.shear_coefficient == pytest.approx(10 / 12)  # Cowper at nu = 0


def test_first_frequency():
    b = fe.RectangularCantilever(length=1.0, width=0.1, height=0.1, E=1e9, nu=0.3)
    I, A = 0.1**4 / 12, 0.01
    f = 1.8751040687**2 / (2 * math.pi) * math.sqrt(1e9 * I / (1000 * A))
    assert b.first_bending_frequency(1000.0) == pytest.approx(f, rel=1e-9)


@pytest.mark.parametrize("kw", [dict(length=0.0), dict(width=-1.0), dict(height=math.nan), dict(E=-1.0), dict(nu=0.5)])
def test_bad_geometry_raises(kw):
    args = dict(length=1.0, width=0.1, height=0.1, E=1e9, nu=0.3) | kw
    with pytest.raises(fe.InvalidParameter):
        fe.RectangularCantilever(**args)
