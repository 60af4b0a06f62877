"""Newton near a saddle of a contact barrier: full projected steps are lengthened (``_extend``).

The model problem: ``Pi(x, y) = x^2 / 2 - a y^2 / 2 + b y^4``, started beside its saddle at the
origin. Its exact Hessian is indefinite there (``-a + 12 b y^2 < 0``); the "projected" one stands
for IPC's clamp, which leaves the unstable direction only a small stiffness ``c`` (the inertia's
``m / h^2`` under a clamped pair). A full projected step then multiplies y by ``1 + a / c`` only.
The minimisers are ``(0, +-sqrt(a / (4 b)))``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from fem_elastic.solvers.newton import newton_minimize

A, B, C = 1.0, 0.25, 5.0  # a / c = 0.2: a full projected step grows y by 1.2 only
Y_STAR = np.sqrt(A / (4 * B))  # 1.0


def _energy(z):
    x, y = z
    return 0.5 * x * x - 0.5 * A * y * y + B * y ** 4


def _linearize(z, project):
    x, y = z
    g = np.array([x, -A * y + 4 * B * y ** 3])
    hyy = -A + 12 * B * y * y
    if project and hyy < C:  # the clamp: what is left of a negative curvature is c
        hyy = max(hyy, 0.0) + C
    return g, sp.csr_matrix(np.diag([1.0, hyy]))


def _solve(max_step, evaluated, max_iter=200):
    def energy(z):
        evaluated.append(z.copy())
        return _energy(z)

    return newton_minimize(energy, _linearize, np.array([0.3, 1e-3]), np.ones(2, dtype=bool),
                           rtol=1e-10, g_scale=1.0, max_iter=max_iter, max_step=max_step,
                           linear_solver="direct")


def test_full_projected_steps_at_a_saddle_are_extended_and_reach_the_same_minimum():
    plain = _solve(None, [])  # without a CCD bound: no extension (it needs the bound)
    free = _solve(lambda z, dz: 1.0, [])
    assert plain.converged and free.converged
    # the same minimiser, to the tolerance's scale (||g|| <= 1e-10 N with unit curvature ~ 1)
    np.testing.assert_allclose(free.x, [0.0, Y_STAR], atol=1e-9)
    np.testing.assert_allclose(plain.x, free.x, atol=1e-9)
    # from y = 1e-3 at 1.2x per step the plain solve needs ~38 steps to leave the saddle; with
    # the doubling (up to 64x per step) a handful
    assert plain.extensions == 0 and free.extensions >= 1
    assert free.iterations <= plain.iterations // 3, (free.iterations, plain.iterations)


def test_an_extension_never_steps_past_the_ccd_bound():
    """A wall at y = 0.5 (below the minimiser): every trial point stays on this side of it."""
    wall = 0.5

    def max_step(z, dz):  # like ipctk's CCD: stop at 0.9 of the remaining gap
        if dz[1] <= 0:
            return 1.0
        return min(1.0, 0.9 * (wall - z[1]) / dz[1])

    evaluated = []
    # six iterations: each CCD-bounded one closes 0.9 of the gap, so the iterates stay at least
    # 0.5 * 0.1^6 = 5e-7 from the wall, far above round-off (no minimiser lies on this side)
    res = _solve(max_step, evaluated, max_iter=6)
    assert max(z[1] for z in evaluated) < wall
    assert res.extensions >= 1  # the first steps, far from the wall, were extended
    assert not res.converged and res.x[1] > 0.4  # it went towards the wall, and stopped short
