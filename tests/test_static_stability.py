"""Stability of static equilibria and scale-robust convergence (issue 15, items 5 and 6).

- A P2 cube under a compressive end load beyond its stability limit converges to the
  straight (symmetric) state, a saddle: it is now reported unstable, with a typed warning,
  and ``stabilize=True`` perturbs it along its lowest mode into a stable, buckled state.
- The Euler load of a pinned column is found within 2 % where the lowest eigenvalue of the
  tangent crosses zero along a load path.
- Convergence is relative to the problem's scale: a nanometre beam and its metre twin give
  the same relative answer, even where the load lies below the round-off floors, and no
  load step is ever "converged" at its start.
"""

import warnings

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.solvers.stability import lowest_eigenpair


def cube(p):
    mesh = fe.beam_mesh(1.0, 1.0, 1.0, cells=(2, 2, 2))
    return fe.Model(mesh, 1000.0, fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3), order=2),
                    fixed="bottom", traction={"top": (0.0, 0.0, -p)})


def test_compressed_cube_saddle_is_reported_unstable():
    m = cube(3e5)
    with pytest.warns(fe.UnstableEquilibrium, match="unstable equilibrium.*stabilize=True"):
        res = fe.solve_static(m)
    assert res.converged and res.stable is False and res.min_eigenvalue < 0
    assert res.path[-1].stable is False
    assert res.buckling_mode.shape == res.displacement.shape
    assert np.abs(res.displacement[:, :2]).max() < 0.1  # the straight state (only Poisson bulging)


def test_stabilize_reaches_a_stable_buckled_state():
    m = cube(3e5)
    with warnings.catch_warnings():
        warnings.simplefilter("error", fe.UnstableEquilibrium)
        res = fe.solve_static(m, stabilize=True)
    assert res.converged and res.stable and res.min_eigenvalue > 0 and res.perturbations >= 1
    straight = fe.solve_static(m, stability=False)
    assert m.energy(res.x) < m.energy(straight.x)  # lower than the saddle
    assert np.abs(res.displacement[:, :2]).max() > 0.5  # it has buckled sideways
    g = m.gradient(res.x)[m.free]
    assert np.linalg.norm(g) <= 1e-6 * np.linalg.norm(m.external_force())


def test_stable_cantilever_and_skipping_the_check():
    m = fe.Model(fe.beam_mesh(cells=(10, 2, 2)), 1000.0, fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3)),
                 fixed="left", traction={"right": (0.0, 0.0, -1e3)})
    res = fe.solve_static(m)
    assert res.stable and res.min_eigenvalue > 0 and res.seconds["stability"] > 0
    off = fe.solve_static(m, stability=False)
    assert off.min_eigenvalue is None and off.stable is None and off.seconds["stability"] == 0.0


def test_lobpcg_agrees_with_the_dense_eigensolver():
    m = cube(1e5)
    res = fe.solve_static(m)
    _, K = m.linearize(res.x, project=False)
    dense = lowest_eigenpair(K, m.free)
    import fem_elastic.solvers.stability as st

    saved, st.DENSE_MAX = st.DENSE_MAX, 10
    try:
        _, Kp = m.linearize(res.x, project=True)
        sparse = lowest_eigenpair(K, m.free, K_psd=Kp)
        amg = lowest_eigenpair(K, m.free, K_psd=Kp, near_null=m.space.rigid_body_modes(), max_direct_dofs=50)
    finally:
        st.DENSE_MAX = saved
    assert dense.method == "dense" and sparse.method == "lobpcg+lu" and amg.method == "lobpcg+amg"
    for other in (sparse, amg):
        assert other.value == pytest.approx(dense.value, rel=1e-6)
        assert abs(other.vector @ dense.vector) == pytest.approx(1.0, abs=1e-4)


def test_euler_buckling_load_of_a_pinned_column():
    """P_cr = pi^2 E I / L^2 where the lowest tangent eigenvalue crosses zero.

    A slender P2 column (L / a = 20) with knife-edge pins: both end faces held in y and z
    (rollers), the mid-height line of vertices of the left end held in x, and the same
    line of the right end pushed in x (displacement control). The faces can turn about y,
    so buckling in z is pinned-pinned. The compressive force is the reaction on the
    pushed line, read where the eigenvalue changes sign (linear interpolation).
    """
    L, a, E = 1.0, 0.05, 1e7
    mesh = fe.beam_mesh(L, a, a, cells=(20, 2, 2))
    X = mesh.p

    def line(x0):
        return np.flatnonzero(np.isclose(X[0], x0) & np.isclose(X[2], a / 2))

    p_cr = np.pi**2 * E * a**4 / 12 / L**2
    shortening = 1.2 * p_cr * L / (E * a * a)
    m = fe.Model(mesh, 1000.0, fe.ElasticBody(fe.NeoHookean(E=E, nu=0.3), order=2),
                 fixed=[("left", "yz"), ("right", "yz"), (line(0.0), "x")],
                 displacement=[(line(L), (-shortening, None, None))])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", fe.UnstableEquilibrium)  # beyond P_cr, by design
        res = fe.solve_static(m, steps=6, stability="path")
    lam = res.path.min_eigenvalues
    force = -res.path.reaction_forces(line(L))[:, 0]
    assert lam[0] > 0 and lam[-1] < 0
    k = int(np.flatnonzero((lam[:-1] > 0) & (lam[1:] <= 0))[0])
    w = lam[k] / (lam[k] - lam[k + 1])
    p_found = force[k] + w * (force[k + 1] - force[k])
    assert p_found == pytest.approx(p_cr, rel=0.02)


# -- scale-robust convergence --------------------------------------------------------------------
def beam(scale, order, material, traction):
    mesh = fe.beam_mesh(1.0 * scale, 0.1 * scale, 0.1 * scale, cells=(10, 2, 2))
    return fe.Model(mesh, 7850.0, fe.ElasticBody(material, order=order), fixed="left",
                    traction={"right": (0.0, 0.0, -traction)})


@pytest.mark.parametrize("order", [1, 2])
def test_nanometre_beam_gives_the_relative_answer_of_its_metre_twin(order):
    """Steel under 0.01 Pa: the load is below ten times the gradient's round-off floor, where
    the old test stopped at iteration 0 with u = 0. Now a Newton step is always taken and the
    nanometre beam, its metre twin and the linearly scaled 10 Pa answer all agree."""
    steel = fe.LinearElastic(E=2e11, nu=0.3)
    tips = {}
    for scale in (1.0, 1e-9):
        m = beam(scale, order, steel, 0.01)
        assert 10 * m.gradient_roundoff() > np.linalg.norm(m.external_force())  # the old trap
        res = fe.solve_static(m)
        assert res.iterations >= 1
        tips[scale] = -res.displacement[:, 2].min() / scale
    ref = -fe.solve_static(beam(1.0, order, steel, 10.0)).displacement[:, 2].min() * 1e-3
    assert tips[1.0] > 0
    assert tips[1e-9] == pytest.approx(tips[1.0], rel=1e-6)
    assert tips[1.0] == pytest.approx(ref, rel=1e-4)


def test_nanometre_neo_hookean_beam_matches_its_twin():
    rubber = fe.NeoHookean(E=1e6, nu=0.3)
    tips = [-fe.solve_static(beam(s, 2, rubber, 1e3)).displacement[:, 2].min() / s for s in (1.0, 1e-9)]
    assert tips[1] == pytest.approx(tips[0], rel=1e-8)


def test_nu_star_slab_is_solved_not_returned_at_rest():
    """The plane-strain conversion nu* = nu / (1 - nu) of nu = 1/3 is 0.49999999999999994:
    the gradient's round-off floor (~600 N) is far above the load (0.04 N). The solve used to
    return u = 0, converged, after 0 iterations; now it takes a Newton step, and warns that
    lambda / mu ~ 1e16 is beyond what the displacement formulation resolves in double
    precision."""
    nu_star = (1 / 3) / (1 - 1 / 3)
    assert nu_star == 0.49999999999999994
    mesh = fe.beam_mesh(1.0, 1.0, 0.1, cells=(4, 4, 1))
    m = fe.Model(mesh, 1000.0, fe.ElasticBody(fe.LinearElastic(E=1e3, nu=nu_star)),
                 fixed={"left": "xyz", "bottom": "z", "top": "z"}, traction={"right": (0.0, -1.3, 0.0)})
    assert m.gradient_roundoff() > 1e3 * np.linalg.norm(m.external_force())
    with pytest.warns(fe.RoundoffWarning, match="lambda / mu"):
        res = fe.solve_static(m)
    assert res.iterations >= 1 and np.abs(res.displacement).max() > 1e-4


def test_nearly_incompressible_slab_matches_its_well_conditioned_twin():
    """nu = 0.5 - 1e-9 (lambda / mu = 5e8, no warning) and nu = 0.4999999 give the same
    locked answer: the floors no longer stop the solve early, whatever the stiffness scale."""
    out = []
    for nu in (0.4999999, 0.5 - 1e-9):
        mesh = fe.beam_mesh(1.0, 1.0, 0.1, cells=(4, 4, 1))
        m = fe.Model(mesh, 1000.0, fe.ElasticBody(fe.LinearElastic(E=1e3, nu=nu)),
                     fixed={"left": "xyz", "bottom": "z", "top": "z"}, traction={"right": (0.0, -1.3, 0.0)})
        with warnings.catch_warnings():
            warnings.simplefilter("error", fe.RoundoffWarning)
            out.append(np.abs(fe.solve_static(m).displacement).max())
    assert out[1] == pytest.approx(out[0], rel=1e-4)


def test_never_converged_at_iteration_zero_with_a_load():
    m = beam(1.0, 1, fe.LinearElastic(E=2e11, nu=0.3), 1e-6)
    res = fe.solve_static(m)
    assert res.iterations >= 1 and res.displacement[:, 2].min() < 0
