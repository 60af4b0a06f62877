"""Newton near a saddle of a contact barrier: full projected steps are lengthened (``_extend``).

The model problem: ``Pi(x, y) = x^2 / 2 - a y^2 / 2 + b y^4``, started beside its saddle at the
origin. Its exact Hessian is indefinite there (``-a + 12 b y^2 < 0``); the "projected" one stands
for IPC's clamp, which leaves the unstable direction only a small stiffness ``c`` (the inertia's
``m / h^2`` under a clamped pair). A full projected step then multiplies y by ``1 + a / c`` only.
The minimisers are ``(0, +-sqrt(a / (4 b)))``.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import fem_elastic as fe
from fem_elastic.solvers import linear_solvers, newton
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


def _solve(max_step, evaluated, max_iter=200, linearize=_linearize, start=(0.3, 1e-3), energy=_energy):
    def counted(z):
        evaluated.append(z.copy())
        return energy(z)

    return newton_minimize(counted, linearize, np.array(start), np.ones(2, dtype=bool),
                           rtol=1e-10, g_scale=1.0, max_iter=max_iter, max_step=max_step,
                           linear_solver="direct", saddle_extension=max_step is not None)


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


def test_after_an_extended_step_newton_tries_the_exact_tangent_again():
    calls = []  # the project flag of every linearization, in order

    def recording(z, project):
        calls.append(project)
        return _linearize(z, project)

    res = _solve(lambda z, dz: 1.0, [], linearize=recording)
    assert res.converged and res.extensions >= 1
    # each extended iteration was: exact tried (False), found indefinite, projected (True); the
    # next linearization is the exact one again (False), not a projected one
    tried_then_projected = [i for i in range(len(calls) - 2) if calls[i] is False and calls[i + 1] is True]
    assert tried_then_projected and all(calls[i + 2] is False for i in tried_then_projected)


def test_a_convex_problem_is_never_extended():
    """Extensions are for saddles only: on a convex quartic the exact tangent is never
    indefinite, so no step is lengthened, even with the CCD passing every step."""

    def convex(z):
        return 0.5 * z[0] ** 2 + z[1] ** 4 + 0.5 * z[1] ** 2

    def lin(z, project):
        return (np.array([z[0], 4 * z[1] ** 3 + z[1]]),
                sp.csr_matrix(np.diag([1.0, 12 * z[1] ** 2 + 1.0])))

    res = _solve(lambda z, dz: 1.0, [], linearize=lin, start=(2.0, 3.0), energy=convex)
    assert res.converged and res.extensions == 0
    # the minimiser (0, 0), to the tolerance's scale: ||g|| <= 1e-10 with curvatures >= 1
    np.testing.assert_allclose(res.x, 0.0, atol=1e-9)


def test_extension_is_kept_to_models_whose_ccd_bounds_every_contact():
    """IPC with the ground (a half-space) or no obstacle: yes; a sphere or a box, checked only at
    a step's end, or no IPC: no."""
    pytest.importorskip("ipctk")
    import warnings

    from fem_elastic.solvers.newton import saddle_extension_safe

    mesh = fe.beam_mesh(length=0.1, width=0.1, height=0.1, cells=(1, 1, 1))
    body = fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3))

    def model(ground, contact):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return fe.Model(mesh, 1000.0, body, ground=ground, contact=contact)

    ipc = fe.IPCContact(dhat=1e-3)
    assert saddle_extension_safe(model(None, ipc))
    assert saddle_extension_safe(model(fe.Ground(z=-0.01, method="barrier"), ipc))
    assert not saddle_extension_safe(model(fe.Sphere(center=(0.05, 0.05, -0.2), radius=0.1,
                                                     method="barrier"), ipc))
    assert not saddle_extension_safe(model(fe.Ground(z=-0.01, method="barrier"), None))


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


def test_under_contact_an_indefinite_exact_tangent_above_the_lu_size_is_projected(monkeypatch):
    """fe.AutoSolver: where CHOLMOD proves the exact tangent indefinite, SuperLU solves it up
    to newton.CONTACT_EXACT_LU_DOFS unknowns under contact; above, Newton projects at once."""
    pytest.importorskip("sksparse")
    lus = []
    lu_solve = linear_solvers.DirectSolver.solve

    def counted(self, A, b, near_null=None, rtol=None):
        lus.append(A.shape[0])
        return lu_solve(self, A, b, near_null, rtol)

    monkeypatch.setattr(linear_solvers.DirectSolver, "solve", counted)

    def solve():
        return newton_minimize(_energy, _linearize, np.array([0.3, 1e-3]), np.ones(2, dtype=bool),
                               rtol=1e-10, g_scale=1.0, max_iter=200, max_step=lambda z, dz: 1.0,
                               linear_solver=fe.AutoSolver(), saddle_extension=True)

    below = solve()  # 2 unknowns <= 5,000: the indefinite exact tangents go to SuperLU
    assert below.converged and lus, "the exact tangent at the saddle was never solved by LU"
    lus.clear()
    monkeypatch.setattr(newton, "CONTACT_EXACT_LU_DOFS", 1)  # as if the system were larger
    above = solve()
    assert above.converged and lus == []
    np.testing.assert_allclose(above.x, below.x, atol=1e-9)  # the same minimiser (see above)
    # without contact the LU stays up to max_direct_dofs, whatever the contact's limit
    newton_minimize(_energy, _linearize, np.array([0.3, 1e-3]), np.ones(2, dtype=bool), rtol=1e-10,
                    g_scale=1.0, max_iter=200, linear_solver=fe.AutoSolver())
    assert lus


def test_a_users_lower_exact_lu_limit_is_kept_under_contact():
    assert fe.AutoSolver().strict(max_lu_dofs=5000).max_exact_lu_dofs == 5000
    assert fe.AutoSolver(max_exact_lu_dofs=100).strict(max_lu_dofs=5000).max_exact_lu_dofs == 100
    assert fe.AutoSolver(max_exact_lu_dofs=10**6).strict(max_lu_dofs=5000).max_exact_lu_dofs == 5000
    assert fe.AutoSolver().strict().fallback is False
