"""Support reactions of a static solve (issue 15, item 3).

The reaction on a held DOF is the force the support exerts, R = dPi/dx there
(zero on free DOFs). At equilibrium the internal forces sum to zero, so the
reactions balance every applied load: sum R + sum f_ext = 0, to the solver's
tolerance (the free DOFs' residual, rtol ||f||, spread over their nodes).
"""

import numpy as np
import pytest

import fem_elastic as fe


def cantilever(order=2, material=None, **kw):
    material = material or fe.NeoHookean(E=1e6, nu=0.3)
    return fe.Model(fe.beam_mesh(cells=(8, 2, 2)), 1000.0, fe.ElasticBody(material, order=order), **kw)


@pytest.mark.parametrize("order", [1, 2])
def test_reaction_equals_the_applied_load(order):
    t = (0.0, 200.0, -1e3)  # Pa on the 0.01 m^2 end: (0, 2, -10) N
    res = fe.solve_static(cantilever(order, fixed="left", traction={"right": t}))
    np.testing.assert_allclose(res.reaction_force("left"), [0.0, -2.0, 10.0], rtol=1e-7, atol=1e-7)
    # the vertex reactions (P2 edge nodes lumped onto their vertices) keep the total
    np.testing.assert_allclose(res.reactions.sum(axis=0), [0.0, -2.0, 10.0], rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(res.reaction_dofs.reshape(-1, 3).sum(axis=0), [0.0, -2.0, 10.0],
                               rtol=1e-7, atol=1e-7)


@pytest.mark.parametrize("order", [1, 2])
def test_global_equilibrium_holds_to_the_solver_tolerance(order):
    m = cantilever(order, fixed={"left": "xyz", "bottom": "z"}, gravity=(3.0, 1.0, -9.81),
                   traction={"right": (500.0, 0.0, -2e3), "top": (0.0, 100.0, 0.0)})
    rtol = 1e-10
    res = fe.solve_static(m, rtol=rtol)
    f = m.external_force()
    total = res.reaction_dofs.reshape(-1, 3).sum(axis=0) + f.reshape(-1, 3).sum(axis=0)
    # the free DOFs' residual is at most rtol ||f||; summed over n nodes, sqrt(n) of it
    n = m.ndofs // 3
    assert np.linalg.norm(total) <= 3 * np.sqrt(n) * rtol * np.linalg.norm(f)
    # zero on free DOFs, and on the free components of rollers
    assert np.all(res.reaction_dofs[m.free] == 0.0)
    bottom_only = np.setdiff1d(m.boundary_nodes("bottom"), m.boundary_nodes("left"))
    np.testing.assert_array_equal(res.reaction_dofs.reshape(-1, 3)[bottom_only, :2], 0.0)


def test_prescribed_displacement_reaction_is_the_force_that_holds_it():
    m = cantilever(1, material=fe.LinearElastic(E=1e6, nu=0.3), fixed="left",
                   displacement={"right": (None, None, -0.01)})
    res = fe.solve_static(m)
    r_left, r_right = res.reaction_force("left"), res.reaction_force("right")
    np.testing.assert_allclose(r_left + r_right, 0.0, atol=1e-9 * abs(r_right[2]))
    assert r_right[2] < 0  # the support pulls the end down
    # the reaction is the stiffness's: doubling the displacement doubles it (linear material)
    m2 = cantilever(1, material=fe.LinearElastic(E=1e6, nu=0.3), fixed="left",
                    displacement={"right": (None, None, -0.02)})
    np.testing.assert_allclose(fe.solve_static(m2).reaction_force("right"), 2 * r_right, rtol=1e-9)


def test_reaction_force_accepts_names_indices_and_masks():
    m = cantilever(1, fixed="left", traction={"right": (0.0, 0.0, -1e3)})
    res = fe.solve_static(m)
    left = np.flatnonzero(np.isclose(m.mesh.p[0], 0.0))
    mask = np.isclose(m.mesh.p[0], 0.0)
    for where in (left, mask, ["left"]):
        np.testing.assert_allclose(res.reaction_force(where), res.reaction_force("left"))
    with pytest.raises(fe.InvalidParameter, match="'lefft'"):
        res.reaction_force("lefft")
