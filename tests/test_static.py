"""Tests of fem_elastic.solvers.static (and the Newton solver under it).

Physics checks: the patch test on a distorted mesh, homogeneous uniaxial stress
against its closed form; solver checks: one Newton step for a linear material,
quadratic convergence near the solution, load stepping, typed errors, the
vertex-only displacement output and the agreement of the linear solvers.
"""

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse.linalg as spla

import fem_elastic as fe
from fem_elastic.solvers.newton import newton_minimize

E, NU = 1e9, 0.3


# --- helpers -------------------------------------------------------------------------------
def distorted_box(length, width, height, cells, amplitude=0.25, seed=0):
    """beam_mesh with its interior vertices moved randomly, boundaries kept.

    Each interior vertex moves by up to ``amplitude`` cell sizes along each
    axis; boundary vertices stay on their planes so the named faces stay flat.
    The result is checked to have only positively oriented tets (a patch test
    on inverted elements would test nothing).
    """
    mesh = fe.beam_mesh(length, width, height, cells)
    p = mesh.p.copy()
    h = np.array([length, width, height]) / np.array(cells)
    interior = np.ones(p.shape[1], dtype=bool)
    interior[mesh.boundary_nodes()] = False
    rng = np.random.default_rng(seed)
    p[:, interior] += amplitude * h[:, None] * rng.uniform(-1, 1, (3, interior.sum()))
    boundaries = {name: mesh.facets[:, f].T for name, f in mesh.boundaries.items()}
    out = fe.mesh_from_arrays(p.T, mesh.t.T, boundaries)
    assert np.all(fe.signed_volumes(out) > 0)
    # the distortion is real: some interior vertex moved by > 10% of a cell
    assert np.abs(out.p - mesh.p).max() > 0.1 * h.min()
    return out, interior


def small_cantilever(material, order=2, cells=(10, 1, 1), traction=-1e4, **kw):
    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells)
    return fe.Model(mesh, 1000.0, fe.ElasticBody(material, order=order), fixed="left",
                    traction={"right": (0.0, 0.0, traction)}, **kw)


# --- patch test ----------------------------------------------------------------------------
@pytest.mark.parametrize("order", [1, 2])
def test_patch_test_linear_field_reproduced_on_distorted_mesh(order):
    """A linear displacement u = G X + c prescribed on the whole boundary is the exact
    solution of linear elasticity (constant strain, div sigma = 0), and P1/P2 contain it,
    so the FE solution must reproduce it in the interior however distorted the mesh."""
    mesh, interior = distorted_box(1.0, 0.6, 0.4, (4, 3, 3))
    assert interior.sum() >= 6
    model = fe.Model(mesh, 1000.0, fe.ElasticBody(fe.LinearElastic(E, NU), order=order),
                     fixed=~interior)
    G = 1e-3 * np.array([[1.0, 0.4, -0.3], [0.2, -0.5, 0.7], [-0.6, 0.1, 0.8]])  # not symmetric
    c = np.array([1e-4, -2e-4, 3e-4])
    Xn = model.X.reshape(-1, 3)
    exact = Xn + Xn @ G.T + c
    x0 = model.X.copy()
    fixed = ~model.free
    x0[fixed] = exact.ravel()[fixed]  # prescribed values; the interior starts at rest
    bp = model.body_potential
    res = newton_minimize(bp.energy, bp.linearize, x0, model.free, rtol=1e-10)
    assert res.converged, res.message
    # A quadratic energy: one Newton step (direct solve) is the answer.
    assert res.iterations == 1
    u = (res.x - model.X).reshape(-1, 3)
    u_exact = exact - Xn
    free_nodes = model.free.reshape(-1, 3).all(axis=1)
    err = np.abs(u[free_nodes] - u_exact[free_nodes]).max() / np.abs(u_exact).max()
    # Round-off: a direct solve of a system with condition ~1e3-1e4 at eps ~ 2e-16.
    assert err < 1e-10, err
    # and the interior did move (the check above is not vacuous)
    assert np.abs(u_exact[free_nodes]).max() > 1e-4


@pytest.mark.parametrize("material", [fe.NeoHookean(1e6, 0.3), fe.Corotated(1e6, 0.3), fe.StVK(1e6, 0.3)],
                         ids=lambda m: type(m).__name__)
def test_patch_test_finite_homogeneous_deformation(material):
    """x = F X with a finite F (20% stretch, shear, rotation-free) prescribed on the boundary:
    F is uniform, so P(F) is too, div P = 0, and x = F X is the equilibrium of any
    hyperelastic material. Newton must find it from a perturbed interior."""
    mesh, interior = distorted_box(1.0, 0.6, 0.4, (4, 3, 3), seed=1)
    model = fe.Model(mesh, 1000.0, fe.ElasticBody(material, order=1), fixed=~interior)
    F = np.array([[1.2, 0.1, 0.0], [0.05, 0.9, 0.1], [0.0, -0.1, 1.05]])
    Xn = model.X.reshape(-1, 3)
    exact = (Xn @ F.T).ravel()
    rng = np.random.default_rng(2)
    # interior starts 2% of a cell away from the answer: Newton has work to do
    x0 = exact + np.where(model.free, 0.02 * 0.2 * rng.uniform(-1, 1, exact.size), 0.0)
    bp = model.body_potential
    res = newton_minimize(bp.energy, bp.linearize, x0, model.free, rtol=1e-10)
    assert res.converged, res.message
    assert res.iterations >= 2  # a nonlinear problem started off the solution
    err = np.abs(res.x - exact).max() / np.abs(exact - model.X).max()
    assert err < 1e-9, err  # converged to round-off of a 1e-10 residual
    # The stress at every quadrature point is the homogeneous P(F).
    P = material.dpsi_dF(bp.F(res.x))
    P_exact = material.dpsi_dF(F[:, :, None, None] * np.ones((1, 1, 1, 1)))[:, :, 0, 0]
    assert np.abs(P - P_exact[:, :, None, None]).max() < 1e-10 * np.abs(P_exact).max()  # measured <= 3e-12


# --- homogeneous uniaxial stress -----------------------------------------------------------
def _symmetry_supported(model, mesh):
    """Free mask with the three symmetry-plane rollers: u_x = 0 on x = 0, u_y = 0 on
    y = 0, u_z = 0 on z = 0. They remove rigid motion and do not restrain the Poisson
    contraction, so a bar under end traction is in exactly uniaxial stress."""
    free = np.ones(model.ndofs, dtype=bool)
    Xn = model.X.reshape(-1, 3)
    for axis in range(3):
        on_plane = np.abs(Xn[:, axis]) < 1e-12
        free[3 * np.nonzero(on_plane)[0] + axis] = False
    return free


@pytest.mark.parametrize("material, sigma", [
    (fe.LinearElastic(E, NU), 1e6),          # strain 1e-3
    (fe.NeoHookean(1e6, 0.3), 2e5),          # 20% stress/E: a finite stretch
    (fe.Corotated(1e6, 0.3), -1e5),          # compression
], ids=["linear", "neohookean", "corotated-compression"])
def test_uniaxial_traction_gives_uniform_closed_form_stress(material, sigma):
    """A bar with symmetry rollers and a dead traction (sigma, 0, 0) per reference area on
    its end: the first Piola stress is P = diag(sigma, 0, 0) at every point for any
    material (P N = t on the end, zero on the free sides, uniform field), on a distorted
    mesh too. For linear elasticity also u = (sigma/E) (X, -nu Y, -nu Z)."""
    L, W, H = 1.0, 0.3, 0.2
    mesh, _ = distorted_box(L, W, H, (5, 3, 3), seed=3)
    model = fe.Model(mesh, 1000.0, fe.ElasticBody(material, order=1),
                     traction={"right": (sigma, 0.0, 0.0)})
    free = _symmetry_supported(model, mesh)
    f = model.external_force()
    assert np.sum(f) == pytest.approx(sigma * W * H, rel=1e-12)  # total end force
    res = newton_minimize(model.energy, lambda x, p: model.linearize(x, project=p),
                          model.X.copy(), free, rtol=1e-10, g_scale=np.linalg.norm(f[free]),
                          near_null=None)
    assert res.converged, res.message
    P = material.dpsi_dF(model.body_potential.F(res.x))
    P_exact = np.diag([sigma, 0.0, 0.0])
    # residual 1e-10 of the load; the stress is that accurate relative to sigma, with a
    # margin of 100 for the conditioning of the bar.
    assert np.abs(P - P_exact[:, :, None, None]).max() < 1e-8 * abs(sigma)
    if isinstance(material, fe.LinearElastic):
        Xn = model.X.reshape(-1, 3)
        u = (res.x - model.X).reshape(-1, 3)
        eps = sigma / E
        u_exact = Xn * np.array([eps, -NU * eps, -NU * eps])
        assert np.abs(u - u_exact).max() < 1e-8 * eps * L
        assert res.iterations == 1


# --- Newton ------------------------------------------------------------------------------------
def test_linear_elastic_needs_exactly_one_newton_iteration():
    """The energy is quadratic: the Newton step from rest is the exact solution."""
    res = fe.solve_static(small_cantilever(fe.LinearElastic(E, NU)))
    assert res.converged
    assert res.iterations == 1
    assert res.load_steps == [1.0]
    # residual history: the load, then round-off far below rtol = 1e-8
    assert res.residual_history[-1] < 1e-8 * res.residual_history[0]


def test_which_models_are_quadratic():
    """Model.quadratic: a linear elastic body under dead loads (gravity, traction) only."""
    lin = small_cantilever(fe.LinearElastic(E, NU))
    assert lin.quadratic
    assert fe.Model(lin.mesh, 1000.0, fe.ElasticBody(fe.LinearElastic(E, NU)), fixed="left",
                    gravity=(0.0, 0.0, -9.81), traction={"right": (0.0, 0.0, -1e3)}).quadratic
    assert not small_cantilever(fe.NeoHookean(E, NU)).quadratic
    assert not fe.Model(lin.mesh, 1000.0, fe.ElasticBody(fe.LinearElastic(E, NU)), fixed="left",
                        ground=fe.Ground(-1.0)).quadratic  # contact: not quadratic
    mixed = fe.ElasticBody(fe.LinearElastic(E, 0.45), order=2, formulation="mixed")
    assert not fe.Model(lin.mesh, 1000.0, mixed, fixed="left").quadratic

    class Stiffening(fe.LinearElastic):  # a user's law on top of LinearElastic: not quadratic
        def psi(self, F):
            return super().psi(F) * (1.0 + super().psi(F) / E)

    assert not small_cantilever(Stiffening(E, NU)).quadratic


def test_quadratic_model_keeps_its_first_hessian(monkeypatch):
    """A linear static solve needs its second Newton iteration only for the round-off test:
    with Model.quadratic the first Hessian is kept (no second assembly), and the answer is the
    same bits as with a second assembly (the direct solver sees an identical matrix). A stiff
    steel beam: its residual after the step is at round-off, above rtol = 1e-8 of the load, so
    the round-off test (which needs a Newton direction) is what ends the solve."""
    model = fe.Model(fe.beam_mesh(1.0, 0.05, 0.05, (10, 1, 1)), 7850.0,
                     fe.ElasticBody(fe.LinearElastic(2.1e11, 0.3), order=2), fixed="left",
                     traction={"right": (0.0, 0.0, -1e5)})
    calls = []
    original = type(model).linearize

    def counted(self, *a, **k):
        calls.append(1)
        return original(self, *a, **k)

    monkeypatch.setattr(type(model), "linearize", counted)
    kept = fe.solve_static(model, linear_solver="direct", stability=False)
    n_kept = len(calls)
    monkeypatch.setattr(type(model), "quadratic", property(lambda self: False))
    calls.clear()
    assembled = fe.solve_static(model, linear_solver="direct", stability=False)
    assert kept.converged and assembled.converged
    assert (n_kept, len(calls)) == (1, 2)
    assert np.array_equal(kept.x, assembled.x)


def test_newton_converges_quadratically_for_neohookean():
    """Moderate nonlinearity (tip load alpha = P L^2 / EI = 0.12, ~3.6% L deflection).
    Quadratic convergence: r_{k+1} <= C r_k^2 with C bounded over the last iterations.
    Measured (r normalised by r_0): ..., 0.15, 6.6e-4, 6.0e-9 with r_{k+1}/r_k^2 = 0.016-0.025;
    a linearly converging method would show that ratio growing like 1/r_k (1e3 - 1e5 here)."""
    model = small_cantilever(fe.NeoHookean(E, NU), traction=-1e5)
    res = fe.solve_static(model)
    assert res.converged and res.load_steps == [1.0]
    r = np.array(res.residual_history) / res.residual_history[0]
    assert len(r) >= 4
    tail = r[-3:]
    ratios = tail[1:] / tail[:-1] ** 2
    assert np.all(ratios < 1.0), ratios  # bounded (measured <= 0.025)
    # the last step gains several orders of magnitude (measured: 6.6e-4 -> 6e-9)
    assert tail[-1] < 1e-3 * tail[-2]


# --- load stepping -------------------------------------------------------------------------
def test_load_stepping_reaches_a_load_the_full_step_cannot():
    """A soft Neo-Hookean beam (E = 1e5 Pa) hanging under 50 g: the beam swings down to
    hang vertically and stretches several times its length. Measured: the full load fails
    in one go, the solver halves to 0.5 and reaches 1.0 in two steps (66 Newton
    iterations). The equilibrium is the same one reached with forced quarter steps."""
    mesh = fe.beam_mesh(1.0, 0.1, 0.1, (10, 1, 1))
    model = fe.Model(mesh, 1000.0, fe.ElasticBody(fe.NeoHookean(1e5, 0.3), order=2),
                     fixed="left", gravity=(0.0, 0.0, -500.0))
    res = fe.solve_static(model)
    assert res.converged and res.load_factor == 1.0
    assert len(res.load_steps) > 1
    assert res.load_steps[0] < 1.0  # the first (full) attempt failed
    assert res.load_steps[-1] == 1.0
    assert np.all(np.diff(res.load_steps) > 0)
    # equilibrium at the full load
    g = model.gradient(res.x)[model.free]
    assert np.linalg.norm(g) <= 1e-8 * np.linalg.norm(model.external_force()[model.free])
    # the tip hangs: swings to x ~ 0 (u_x ~ -L) and far below the clamp
    tip = np.isclose(mesh.p[0], 1.0)
    u_tip = res.displacement[tip].mean(axis=0)
    assert -1.0 < u_tip[0] < -0.95
    assert u_tip[2] < -2.0

    forced = fe.solve_static(model, initial_load_step=0.25)
    assert forced.load_steps[0] == 0.25
    np.testing.assert_allclose(forced.displacement, res.displacement, atol=1e-6 * np.abs(u_tip).max())


def test_forced_load_steps_give_the_same_equilibrium():
    """initial_load_step=0.25 on a large-deflection tip load (which also converges in one
    step): quarter steps, each > 5 Newton iterations so the increment is not doubled."""
    model = small_cantilever(fe.NeoHookean(1e5, 0.3), traction=-1e4)
    one = fe.solve_static(model)
    steps = fe.solve_static(model, initial_load_step=0.25)
    assert one.load_steps == [1.0]
    assert steps.load_steps == [0.25, 0.5, 0.75, 1.0]
    assert steps.converged
    scale = np.abs(one.displacement).max()
    assert scale > 0.5  # large deflection (measured ~1.07 m tip drop of a 1 m beam)
    np.testing.assert_allclose(steps.displacement, one.displacement, atol=1e-6 * scale)


# --- errors --------------------------------------------------------------------------------
def test_no_fixed_dofs_raises_under_constrained():
    model = fe.Model(fe.beam_mesh(1.0, 0.1, 0.1, (4, 1, 1)), 1000.0,
                     fe.ElasticBody(fe.LinearElastic(E, NU)), traction={"right": (0.0, 0.0, -1e4)})
    with pytest.raises(fe.UnderConstrained, match="fixe"):
        fe.solve_static(model)


@pytest.mark.parametrize("order", [1, 2])
def test_vertices_on_one_line_raise_under_constrained(order):
    """Fixing the vertices on the edge y = z = 0 leaves the rotation about that line free."""
    mesh = fe.beam_mesh(1.0, 0.1, 0.1, (4, 1, 1))
    line = np.nonzero((mesh.p[1] == 0.0) & (mesh.p[2] == 0.0))[0]
    assert line.size == 5
    model = fe.Model(mesh, 1000.0, fe.ElasticBody(fe.LinearElastic(E, NU), order=order),
                     fixed=line, gravity=(0.0, 0.0, -9.81))
    with pytest.raises(fe.UnderConstrained, match="fixed") as info:
        fe.solve_static(model)
    assert "1 rigid-body mode" in str(info.value)
    assert isinstance(info.value, fe.FemElasticError)
    # three non-collinear vertices are enough
    corner = np.nonzero((mesh.p[1] == 0.0) & (mesh.p[2] == 0.1) & (mesh.p[0] == 0.0))[0]
    model = fe.Model(mesh, 1000.0, fe.ElasticBody(fe.LinearElastic(E, NU), order=order),
                     fixed=np.concatenate([line, corner]), gravity=(0.0, 0.0, -9.81))
    assert fe.solve_static(model).converged


def test_not_converged_carries_the_result():
    """max_iter=1 cannot solve a large-deflection Neo-Hookean problem at any load step."""
    model = small_cantilever(fe.NeoHookean(E, NU), traction=-1e6)
    with pytest.raises(fe.NotConverged, match="max_iter") as info:
        fe.solve_static(model, max_iter=1, min_load_step=0.25)
    result = info.value.result
    assert isinstance(result, fe.StaticResult)
    assert result.converged is False
    assert result.load_factor < 1.0
    assert result.displacement.shape == (model.mesh.p.shape[1], 3)
    assert len(result.residual_history) > 0

    res = fe.solve_static(model, max_iter=1, min_load_step=0.25, check=False)
    assert res.converged is False
    assert res.load_factor < 1.0
    assert "stalled" in res.message


# --- output ------------------------------------------------------------------------------
@pytest.mark.parametrize("order", [1, 2])
def test_displacement_is_reported_at_vertices(order):
    mesh = fe.beam_mesh(1.0, 0.1, 0.1, (6, 2, 1))
    model = small_cantilever(fe.LinearElastic(E, NU), order=order, cells=(6, 2, 1))
    res = fe.solve_static(model)
    assert res.displacement.shape == (mesh.p.shape[1], 3)
    assert res.x.shape == (model.ndofs,)
    if order == 2:
        assert model.ndofs > 3 * mesh.p.shape[1]  # edge nodes exist but are not reported
    # the reported values are the vertex DOFs of x
    np.testing.assert_array_equal(res.displacement, model.to_vertices(res.x - model.X))
    np.testing.assert_array_equal(res.displacement[np.isclose(mesh.p[0], 0.0)], 0.0)
    assert res.displacement[:, 2].min() < 0  # it bends down


# --- linear solvers ------------------------------------------------------------------------
def test_direct_and_amg_solvers_agree():
    """AMG-CG stops at a relative residual of 1e-8, and Newton accepts it once ||g|| <=
    1e-8 ||f||. For a symmetric positive definite K, ||x_amg - x_direct|| <= (||r_amg|| +
    ||r_direct||) / lambda_min(K), a rigorous bound computed here from the reported final
    residuals and the smallest eigenvalue of K on the free DOFs. (Measured: the difference
    is ~5e-12 of the displacement, far inside the bound.)"""
    pytest.importorskip("pyamg")
    model = small_cantilever(fe.LinearElastic(E, NU), cells=(20, 2, 2))
    rd = fe.solve_static(model, linear_solver=fe.DirectSolver())
    ra = fe.solve_static(model, linear_solver=fe.AMGSolver())
    assert rd.converged and ra.converged
    assert ra.linear_iterations > 0 and rd.linear_iterations == 0
    _, K = model.linearize(model.X, project=False)
    Kf = K[model.free][:, model.free]
    lam_min = spla.eigsh(Kf.tocsc(), k=1, sigma=0, which="LM", return_eigenvectors=False)[0]
    assert lam_min > 0
    bound = (ra.residual_history[-1] + rd.residual_history[-1]) / lam_min
    diff = np.linalg.norm(ra.x - rd.x)
    assert diff <= bound
    # and in plain terms: the same displacement to well within the 1e-8 solver tolerance * 100
    assert np.abs(ra.displacement - rd.displacement).max() < 1e-6 * np.abs(rd.displacement).max()


@pytest.mark.parametrize("iterative", [fe.AMGSolver(), fe.AutoSolver(max_direct_dofs=10, max_factor_bytes=0)],
                         ids=["AMGSolver", "AutoSolver"])
def test_amg_with_an_indefinite_exact_tangent_falls_back_to_the_projection(iterative, caplog):
    """Axial compression makes the exact corotated tangent indefinite; CG on it stalls.

    Newton must then go back to the PSD projection (on which AMG-CG converges) instead
    of failing the whole solve, or, with AutoSolver, of factorizing the matrix by LU;
    the direct solver gives the reference answer.
    """
    def solve(solver):
        model = fe.Model(fe.beam_mesh(1.0, 0.1, 0.1, (20, 2, 2)), density=1000.0,
                         body=fe.ElasticBody(fe.Corotated(E=1e9, nu=0.3), order=2), fixed="left",
                         traction={"right": (-2e6, 0.0, -1e3)})
        return fe.solve_static(model, linear_solver=solver)

    with caplog.at_level("WARNING", logger="fem_elastic.solvers.linear_solvers"):
        amg = solve(iterative)
    assert "Falling back to the direct solver" not in caplog.text
    direct = solve(fe.DirectSolver())
    assert amg.converged and direct.converged
    # both meet rtol = 1e-8 on the same equilibrium: the answers agree far below 1e-6
    scale = np.abs(direct.displacement).max()
    np.testing.assert_allclose(amg.displacement, direct.displacement, rtol=0, atol=1e-6 * scale)


def test_shipped_blob_hangs_in_force_and_moment_balance():
    """The non-box shipped mesh, standing on its fixed underside under gravity.

    Elastic energy is invariant under translations and (for a frame-indifferent material)
    rotations of the deformed body, so at equilibrium the support reactions r must carry
    the whole weight and its moment about any point, evaluated in the deformed positions:
    sum r = -sum f, sum x x r = -sum x x f.
    """
    mesh = fe.load_mesh(Path(__file__).resolve().parent.parent / "meshes" / "blob.vtu")
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=2e4, nu=0.4)),
                     fixed="bottom", gravity=(3.0, 0.0, -9.81))  # a sideways pull makes a moment
    res = fe.solve_static(model)
    assert res.converged
    assert res.displacement[:, 2].min() < -1e-3  # m: a soft blob visibly settles
    x = res.x.reshape(-1, 3)
    f = model.external_force().reshape(-1, 3)
    r = (model.body_potential.gradient(res.x) - model.external_force()).reshape(-1, 3)
    fixed_nodes = np.unique(model.fixed_dofs // 3)
    free_r = np.delete(r, fixed_nodes, axis=0)
    weight = np.linalg.norm(f.sum(axis=0))
    # Newton stopped at ||g_free|| <= 1e-8 ||f||: free-node residuals are that small
    assert np.linalg.norm(free_r) <= 1e-8 * np.linalg.norm(f) * 1.01
    R = r[fixed_nodes]
    # the balances hold to the free-node residual (1e-8 ||f||) times the number of nodes
    # it is spread over, sqrt(n) ~ 30: 1e-6 of the weight leaves a margin of ~3
    np.testing.assert_allclose(R.sum(axis=0), -f.sum(axis=0), rtol=0, atol=1e-6 * weight)
    size = np.ptp(x, axis=0).max()
    moment = np.cross(x[fixed_nodes], R).sum(axis=0) + np.cross(x, f).sum(axis=0)
    assert np.linalg.norm(moment) <= 1e-6 * weight * size
    # and the moment balance needs the deformed positions: with X it fails visibly
    X = model.X.reshape(-1, 3)
    moment_ref = np.cross(X[fixed_nodes], R).sum(axis=0) + np.cross(X, f).sum(axis=0)
    assert np.linalg.norm(moment_ref) > 1e3 * np.linalg.norm(moment)


def test_inexact_newton_reaches_the_same_solution_with_fewer_krylov_iterations():
    """An AMG-CG solve stopped at eta = min(1e-2, 0.1 ||g|| / ||g_0||) gives a direction
    good enough far from the solution; Newton's own test on the true gradient is unchanged."""
    pytest.importorskip("pyamg")
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(20, 3, 3))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3)),
                     fixed="left", traction={"right": (0.0, 0.0, -2e3)})
    solver = fe.AutoSolver(max_direct_dofs=0, max_factor_bytes=0)  # AMG-CG even on this small problem
    out = {}
    for inexact in (False, True):
        out[inexact] = newton_minimize(
            model.energy, lambda x, p: model.linearize(x, project=p), model.X, model.free,
            linear_solver=solver, near_null=model.rigid_body_modes, inexact=inexact,
            g_scale=float(np.linalg.norm(model.external_force())), gradient=model.gradient,
        )
    assert out[True].converged and out[False].converged
    assert out[True].linear_iterations < out[False].linear_iterations
    # both stop at ||g|| <= 1e-8 |f|: the minimisers agree to that relative accuracy
    # divided by the stiffness, far below the 0.1 m deflection
    np.testing.assert_allclose(out[True].x, out[False].x, rtol=0, atol=1e-8)


def test_solver_rtol_check_keeps_no_user_solver_alive():
    # Newton asks once per solve function whether it takes rtol, and keeps the answer weakly:
    # a user's solve (bound per instance, capturing data) and what it holds must still go away
    import gc
    import types
    import weakref

    from fem_elastic.solvers.newton import _takes_rtol

    class Data:
        pass

    def make(data, with_rtol):
        if with_rtol:
            def solve(self, A, b, near_null=None, rtol=None):
                return data
        else:
            def solve(self, A, b, near_null=None):
                return data
        return solve

    class UserSolver:
        pass

    answers, refs = [], []
    for with_rtol in (True, False):
        data, solver = Data(), UserSolver()
        solver.solve = types.MethodType(make(data, with_rtol), solver)
        answers.append((_takes_rtol(solver), _takes_rtol(solver)))  # asked, then answered from the cache
        refs.append(weakref.ref(data))
        del data, solver
    gc.collect()
    assert answers == [(True, True), (False, False)]
    assert all(r() is None for r in refs)
