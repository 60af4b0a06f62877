"""Direct and AMG-CG solvers on an elasticity system, and their failure modes."""

import numpy as np
import pytest
import scipy.sparse as sp

import fem_elastic as fe
from fem_elastic.solvers.newton import constrain


@pytest.fixture(scope="module")
def system():
    model = fe.Model(fe.beam_mesh(cells=(30, 3, 3)), density=1000.0,
                     body=fe.ElasticBody(fe.LinearElastic(E=1e9, nu=0.3)), fixed="left",
                     gravity=(0, 0, -9.81))
    _, K = model.linearize(model.X.copy())
    A = constrain(K, model.free, model.space.pattern)
    b = np.where(model.free, model.external_force(), 0.0)
    B = model.space.rigid_body_modes() * model.free[:, None]
    return A, b, B


def test_direct_and_amg_agree(system):
    A, b, B = system
    d = fe.DirectSolver().solve(A, b)
    a = fe.AMGSolver(rtol=1e-10).solve(A, b, near_null=B)
    assert d.residual < 1e-10  # LU: residual at round-off times the condition growth
    # CG stops when its updated residual is below rtol = 1e-10 of ||b|| (the 2-norm); the true
    # residual reported here drifts from it by round-off (measured 5.8e-11): 10x covers the drift
    assert a.residual <= 1e-9
    assert a.iterations > 0 and a.method == "amg-cg"
    # ||x - x*|| / ||x*|| <= cond(A) * residual; cond ~ 1e5 here, so ~1e-5 at worst
    np.testing.assert_allclose(a.x, d.x, rtol=0, atol=1e-5 * np.abs(d.x).max())


def test_auto_solver_switches_on_size(system):
    A, b, B = system
    assert fe.AutoSolver(max_direct_dofs=10, max_factor_bytes=0).solve(A, b, B).method == "amg-cg"
    assert fe.AutoSolver(max_direct_dofs=10**9, max_factor_bytes=0).solve(A, b, B).method == "direct"


def test_singular_matrix_is_a_typed_error():
    A = sp.csr_matrix(np.array([[1.0, 1.0], [1.0, 1.0]]))
    with pytest.raises(fe.SingularMatrix, match="singular"):
        fe.DirectSolver().solve(A, np.array([1.0, 0.0]))


def test_amg_rtol_validated():
    with pytest.raises(fe.InvalidParameter, match="rtol"):
        fe.AMGSolver(rtol=0.0)


def test_amg_failure_is_reported_and_auto_falls_back_to_direct(system):
    A, b, B = system
    starved = fe.AMGSolver(rtol=1e-10, maxiter=2)  # two CG iterations cannot reach 1e-10
    with pytest.raises(fe.LinearSolverFailed, match="DirectSolver") as info:
        starved.solve(A, b, near_null=B)
    assert info.value.result.iterations == 2
    res = fe.AutoSolver(max_direct_dofs=10, max_factor_bytes=0, amg=starved).solve(A, b, B)
    assert res.method == "direct" and res.residual < 1e-10


def test_strict_auto_solver_reraises(system):
    A, b, B = system
    strict = fe.AutoSolver(max_direct_dofs=10, max_factor_bytes=0,
                           amg=fe.AMGSolver(rtol=1e-10, maxiter=2)).strict()
    with pytest.raises(fe.LinearSolverFailed):
        strict.solve(A, b, B)


def test_direct_solver_reuses_the_factor_of_an_identical_matrix_only():
    from fem_elastic.solvers import linear_solvers

    rng = np.random.default_rng(7)
    n = 40
    R = sp.random(n, n, density=0.2, random_state=1)
    A = (R @ R.T + 10 * sp.identity(n)).tocsr()
    b = rng.standard_normal(n)
    x1 = fe.DirectSolver().solve(A, b).x
    lu = linear_solvers._FACTORS.lu
    x2 = fe.DirectSolver().solve(A.copy(), 2 * b).x  # equal arrays, another object: reused
    assert linear_solvers._FACTORS.lu is lu
    np.testing.assert_allclose(x2, 2 * x1, rtol=1e-12)
    B = A.copy()
    B.data[0] *= 1.0 + 1e-15 if B.data[0] != 0 else 1.0  # any change, however small: refactor
    B.data[1] += 1.0
    y = fe.DirectSolver().solve(B, b).x
    assert linear_solvers._FACTORS.lu is not lu
    np.testing.assert_allclose(B @ y, b, rtol=0, atol=1e-10 * np.abs(b).max())
