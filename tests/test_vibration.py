"""Free vibration of a slender cantilever: the first bending frequency from the
modal problem and from a simulated free vibration, against Euler-Bernoulli."""

import numpy as np
import pytest

import fem_elastic as fe

L, B, H, E, NU, RHO = 1.0, 0.05, 0.05, 1e7, 0.3, 1000.0  # L/h = 20: Euler-Bernoulli regime


@pytest.fixture(scope="module")
def beam():
    mesh = fe.beam_mesh(length=L, width=B, height=H, cells=(20, 1, 1))
    body = fe.ElasticBody(fe.LinearElastic(E=E, nu=NU), order=2)  # P2: no shear locking
    model = fe.Model(mesh, density=RHO, body=body, fixed="left")
    f_eb = fe.RectangularCantilever(length=L, width=B, height=H, E=E, nu=NU).first_bending_frequency(RHO)
    return model, f_eb


def test_first_frequency_from_the_modal_problem(beam):
    model, f_eb = beam
    f1 = fe.natural_frequencies(model, 1)[0]
    # consistent-mass P2 on 20 elements: +0.6 % (shear and clamp effects at L/h = 20 are
    # below 1 %); 2 % is the bound
    assert abs(f1 / f_eb - 1) < 0.02


def test_first_frequency_from_a_simulated_free_vibration(beam):
    """Release the beam from its static shape under a tip load and read the frequency
    off the FFT of the tip deflection (Hann window, zero padding, parabolic peak fit)."""
    model, f_eb = beam
    loaded = fe.Model(model.mesh, density=RHO, body=model.body, fixed="left",
                      traction={"right": (0.0, 0.0, -10.0)})
    s0 = fe.State(fe.solve_static(loaded).x, np.zeros(model.ndofs))
    per_period, periods = 32, 16
    dt = 1.0 / (per_period * f_eb)
    # Newmark (trapezoidal rule): no amplitude loss, period elongation (omega h)^2 / 12 = 0.3 %
    run = fe.simulate(model, fe.Newmark(), dt, steps=per_period * periods, state=s0)
    tip = np.isclose(model.mesh.p[0], L)
    w = run.displacement[:, tip, 2].mean(axis=1)
    w = (w - w.mean()) * np.hanning(w.size)
    n = 16 * w.size
    spectrum = np.abs(np.fft.rfft(w, n))
    k = int(np.argmax(spectrum[1:])) + 1
    a, b, c = np.log(spectrum[k - 1 : k + 2])
    k_peak = k + 0.5 * (a - c) / (a - 2 * b + c)  # parabola through the log-magnitudes
    f_sim = k_peak / (n * dt)
    assert abs(f_sim / f_eb - 1) < 0.02, (f_sim, f_eb)
    # and the simulation agrees with the modal problem of the same discretization
    f_modal = fe.natural_frequencies(model, 1, mass="lumped")[0]
    assert abs(f_sim / f_modal - 1) < 0.01, (f_sim, f_modal)
