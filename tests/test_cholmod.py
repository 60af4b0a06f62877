"""CHOLMOD (fe.CholmodSolver): the same answers as SuperLU, factorisations reused, safe fallback.

CHOLMOD comes from scikit-sparse, an optional dependency that CI installs (the ``test`` extra
pulls in ``cholmod``; ``.ci/run`` installs Debian's SuiteSparse headers first). The tests that
need it skip where it is missing, and ``test_ci_has_cholmod`` fails in CI (``CI`` set) when it
is, so the suite cannot skip them there silently.
"""

from __future__ import annotations

import logging
import os

import numpy as np
import pytest
import scipy.sparse as sp

import fem_elastic as fe
from fem_elastic.app.scene_schema import LINEAR_SOLVERS
from fem_elastic.solvers import cholmod as chol
from fem_elastic.solvers.linear_solvers import as_linear_solver
from fem_elastic.solvers.newton import constrain


def test_ci_has_cholmod():
    if os.environ.get("CI"):
        assert chol.have_cholmod(), (
            "CI must test CHOLMOD: scikit-sparse is missing (" + chol.INSTALL_HINT + ")")
    else:
        pytest.skip("outside CI CHOLMOD is optional (the [cholmod] extra)")


def test_missing_scikit_sparse_is_a_typed_error_naming_the_extra(monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_sksparse(name, *args, **kwargs):
        if name == "sksparse" or name.startswith("sksparse."):
            raise ImportError("No module named 'sksparse'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_sksparse)
    with pytest.raises(fe.MissingDependency, match=r'\.\[cholmod\].*libsuitesparse-dev'):
        fe.CholmodSolver()
    with pytest.raises(fe.MissingDependency, match="cholmod"):
        as_linear_solver("cholmod")
    assert not chol.have_cholmod()
    # without it the automatic rule never picks CHOLMOD
    assert not fe.AutoSolver(max_factor_bytes=1e12).uses_cholmod(100, 1000)


def test_unknown_solver_name_is_refused():
    with pytest.raises(fe.InvalidParameter, match="cholmod"):
        as_linear_solver("choleski")


# not pytest.importorskip at module level: that would skip test_ci_has_cholmod above too
requires_cholmod = pytest.mark.skipif(not chol.have_cholmod(),
                                      reason="scikit-sparse is not installed (" + chol.INSTALL_HINT + ")")


@pytest.fixture(scope="module")
def system():
    """A supported linear cantilever's constrained stiffness (SPD) and gravity load."""
    model = fe.Model(fe.beam_mesh(cells=(12, 2, 2)), density=1000.0,
                     body=fe.ElasticBody(fe.LinearElastic(E=1e9, nu=0.3)), fixed="left",
                     gravity=(0, 0, -9.81))
    _, K = model.linearize(model.X.copy())
    A = constrain(K, model.free, model.space.pattern).tocsr()
    b = np.where(model.free, model.external_force(), 0.0)
    return A, b


@requires_cholmod
def test_cholmod_equals_superlu(system):
    A, b = system
    c = fe.CholmodSolver().solve(A, b)
    d = fe.DirectSolver().solve(A, b)
    assert c.method == "cholmod" and c.setups == 2  # one analysis, one factorisation
    # both are backward stable direct solves: ||x - x*|| / ||x*|| <= cond(A) eps, and cond(A)
    # of this beam's stiffness is ~1e5 (E h^2 / L^2 spread of its eigenvalues), so ~1e-11;
    # 1e-10 leaves a factor 10 for the orderings' different round-off
    np.testing.assert_allclose(c.x, d.x, rtol=0, atol=1e-10 * np.abs(d.x).max())
    assert c.residual < 1e-9  # the same bound on the residual, relative to ||b||


@requires_cholmod
def test_factor_reused_when_only_the_right_hand_side_changes(system):
    A, b = system
    s = fe.CholmodSolver()
    x1 = s.solve(A, b).x
    r2 = s.solve(A.copy(), 3.0 * b)  # an equal matrix (another object): back-substitution only
    assert (s.analyses, s.factorizations, s.solves) == (1, 1, 2) and r2.setups == 0
    np.testing.assert_allclose(r2.x, 3.0 * x1, rtol=1e-12, atol=0)  # linear in b, exactly
    B = A.copy()
    B.data = B.data * 2.0  # new values, same pattern: refactorised on the kept analysis
    r3 = s.solve(B, b)
    assert (s.analyses, s.factorizations) == (1, 2) and r3.setups == 1
    np.testing.assert_allclose(r3.x, 0.5 * x1, rtol=1e-10, atol=1e-10 * np.abs(x1).max())
    s.solve(sp.csr_matrix(A[:50, :50]), b[:50])  # another pattern: analysed anew
    assert s.analyses == 2


@requires_cholmod
def test_not_positive_definite_falls_back_to_superlu_with_a_warning(system, caplog):
    A, b = system
    shift = 0.5 * float(A.diagonal().max())  # subtracting it makes A indefinite
    N = (A - shift * sp.identity(A.shape[0], format="csr")).tocsr()
    s = fe.CholmodSolver()
    with caplog.at_level(logging.WARNING, logger="fem_elastic.solvers.cholmod"):
        r = s.solve(N, b)
    assert "not positive definite" in caplog.text and "SuperLU" in caplog.text
    assert r.method == "direct" and s.fallbacks == 1
    ref = np.linalg.solve(N.toarray(), b)  # dense LU with partial pivoting: the reference
    # a pivoting LU is backward stable: the error is cond(N) eps; N's eigenvalues straddle 0
    # at the shift, so cond(N) is large (~1e4 here), and 1e-9 of the largest entry covers it
    np.testing.assert_allclose(r.x, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    assert r.residual < 1e-10  # backward stable: the residual is round-off, whatever cond(N)
    with pytest.raises(fe.LinearSolverFailed, match="not positive definite"):
        s.strict().solve(N, b)  # what Newton uses on an exact tangent: it projects instead
    assert s.solve(A, b).method == "cholmod"  # and CHOLMOD again on a positive definite one
    # the automatic solver: SuperLU as without CHOLMOD at this size (Newton tests the direction)
    assert fe.AutoSolver(max_factor_bytes=1e12).solve(N, b).method == "direct"
    # above max_direct_dofs, Newton's strict solver raises, and Newton projects the tangent
    with pytest.raises(fe.LinearSolverFailed, match="not positive definite"):
        fe.AutoSolver(max_factor_bytes=1e12, max_direct_dofs=10).strict().solve(N, b)


@requires_cholmod
def test_auto_picks_what_the_rule_says_on_two_sizes(system):
    A, b = system
    n, nnz = A.shape[0], A.nnz
    small, large = chol.fill_bytes(n, nnz), chol.fill_bytes(1_000_000, 80_000_000)
    budget = 10 * small  # this system's factor fits, a million-DOF one (~100x more) does not
    auto = fe.AutoSolver(max_factor_bytes=budget)
    assert auto.uses_cholmod(n, nnz) and not auto.uses_cholmod(1_000_000, 80_000_000)
    assert large > budget
    assert auto.solve(A, b).method == "cholmod"
    # the same system under a budget it does not fit: the old rule (SuperLU at this size)
    assert fe.AutoSolver(max_factor_bytes=small / 2).solve(A, b).method == "direct"
    assert fe.AutoSolver(max_factor_bytes=0).solve(A, b).method == "direct"
    # and AMG-CG above max_direct_dofs when CHOLMOD does not fit
    pytest.importorskip("pyamg")
    assert fe.AutoSolver(max_factor_bytes=0, max_direct_dofs=10).solve(A, b).method == "amg-cg"
    assert fe.AutoSolver(max_factor_bytes=0, max_direct_dofs=10).reusing(n, nnz) is not None
    assert auto.reusing(n, nnz) is auto


def _cantilever(material, order=1, cells=(8, 2, 2), **kw):
    return fe.Model(fe.beam_mesh(1.0, 0.1, 0.1, cells), density=1000.0,
                    body=fe.ElasticBody(material, order=order), fixed="left", **kw)


@requires_cholmod
def test_linear_static_load_steps_factorise_once():
    model = _cantilever(fe.LinearElastic(E=1e7, nu=0.3), gravity=(0, 0, -9.81))
    s = fe.CholmodSolver()
    res = fe.solve_static(model, linear_solver=s, steps=4, stability=False)
    ref = fe.solve_static(model, linear_solver=fe.DirectSolver(), steps=4, stability=False)
    assert res.converged and s.solves >= 4
    # a linear body: one stiffness for every load step and Newton iteration
    assert (s.analyses, s.factorizations) == (1, 1)
    # both converge Newton to rtol 1e-8 of the load scale on one matrix: the same answer to
    # round-off of the two factorisations (cond ~1e4 times eps)
    np.testing.assert_allclose(res.displacement, ref.displacement, rtol=0,
                               atol=1e-9 * np.abs(ref.displacement).max())


@requires_cholmod
def test_named_everywhere():
    assert isinstance(as_linear_solver("cholmod"), fe.CholmodSolver)
    assert LINEAR_SOLVERS["cholmod"] is fe.CholmodSolver
    integ = fe.ImplicitEuler(linear_solver="cholmod")
    assert isinstance(integ.linear_solver, fe.CholmodSolver)
    model = _cantilever(fe.NeoHookean(E=1e6, nu=0.3), gravity=(0, 0, -9.81))
    a = fe.solve_static(model, linear_solver="cholmod", stability=False)
    b = fe.solve_static(model, linear_solver="direct", stability=False)
    # Newton to rtol 1e-8 of the load scale from both: equal to that tolerance, not round-off
    np.testing.assert_allclose(a.displacement, b.displacement, rtol=0,
                               atol=1e-6 * np.abs(b.displacement).max())


@requires_cholmod
def test_projective_dynamics_unchanged_with_cholmod(monkeypatch):
    model = _cantilever(fe.ProjectiveCorotated(E=1e5, nu=0.3), gravity=(0, 0, -9.81))
    pd = fe.ProjectiveDynamics(iterations=5)
    run = fe.simulate(model, pd, dt=0.01, t_end=0.05)
    assert pd.factorizations == 1  # x, y and z share one matrix (held DOFs alike in each)
    monkeypatch.setattr(chol, "have_cholmod", lambda: False)  # SuperLU, as before CHOLMOD
    ref = fe.simulate(model, fe.ProjectiveDynamics(iterations=5), dt=0.01, t_end=0.05)
    # the same global matrix factorised two ways: round-off of cond(B) ~1e3 times eps per
    # solve, over 25 global steps
    np.testing.assert_allclose(run.displacement, ref.displacement, rtol=0,
                               atol=1e-10 * np.abs(ref.displacement).max())


@requires_cholmod
def test_modal_frequencies_unchanged_with_cholmod(monkeypatch, caplog):
    model = _cantilever(fe.LinearElastic(E=2e11, nu=0.3), order=1, cells=(12, 2, 2))
    f, modes = fe.natural_frequencies(model, 4, return_modes=True)
    monkeypatch.setattr(chol, "have_cholmod", lambda: False)  # ARPACK's own SuperLU
    f0 = fe.natural_frequencies(model, 4)
    # the same Lanczos iteration on two factorisations of K: eigenvalues converge to ARPACK's
    # tol (machine precision by default) relative, so 1e-9 leaves round-off room
    np.testing.assert_allclose(f, f0, rtol=1e-9)
    monkeypatch.undo()
    free = fe.Model(fe.beam_mesh(1.0, 0.1, 0.1, (6, 2, 2)), density=1000.0,
                    body=fe.ElasticBody(fe.LinearElastic(E=1e7, nu=0.3)))
    with caplog.at_level(logging.WARNING, logger="fem_elastic.solvers.cholmod"):
        ff = fe.natural_frequencies(free, 8)  # K - sigma M, sigma < 0: positive definite
    assert "not positive definite" not in caplog.text
    assert np.all(ff[:6] < 1e-3 * ff[6])  # six rigid modes


@requires_cholmod
def test_static_stability_check_reuses_the_cholesky_factor():
    from fem_elastic.solvers import linear_solvers as ls

    model = _cantilever(fe.NeoHookean(E=1e6, nu=0.3), cells=(10, 2, 2), gravity=(0, 0, -9.81))
    res = fe.solve_static(model, linear_solver="cholmod")  # default stability="final"
    assert res.converged and res.stable is True
    assert isinstance(ls._FACTORS.lu, chol._FactorSolve)  # the factor LOBPCG was offered
    ref = fe.solve_static(model, linear_solver="direct")
    # the lowest eigenvalue by LOBPCG to its tolerance (1e-7 of max K_ii, relative to the
    # residual; the eigenvalue error is its square over the gap): 1e-6 relative is ample
    assert res.min_eigenvalue == pytest.approx(ref.min_eigenvalue, rel=1e-6)


@requires_cholmod
def test_threads_each_solve_through_their_own_factor():
    # fe.AutoSolver's CHOLMOD solver is per thread: a factor refactorised in place by one thread
    # must never serve another thread's right-hand side (a shared one gave 202 wrong answers of
    # 800 in this setting). Same pattern, different values per thread, many interleaved solves.
    import threading

    n = 4000
    base = sp.diags([-1.0, 4.0, -1.0], [-1, 0, 1], shape=(n, n)).tocsr()
    wrong, errors, solves = [], [], []

    def work(k):
        try:  # an exception in a thread would only end the thread: record it for the assert
            A = base * (1.0 + k)
            b = np.random.default_rng(k).standard_normal(n)
            solver = fe.AutoSolver()
            for _ in range(60):
                x = solver.solve(A, b).x
                solves.append(k)
                # well conditioned (cond < 3): a solve through its own factor is exact to ~1e-15
                if np.linalg.norm(A @ x - b) > 1e-10 * np.linalg.norm(b):
                    wrong.append(k)
        except Exception as e:  # noqa: BLE001 - reported by the assert below
            errors.append(repr(e))

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(solves) == 4 * 60
    assert not wrong


@requires_cholmod
def test_the_factor_offered_to_the_stability_check_is_never_stale():
    # a CHOLMOD factor is refactorised in place: the copy offered to solve_static's stability
    # check (linear_solvers._FACTORS) must be withdrawn first, or it would solve another matrix
    from fem_elastic.solvers import linear_solvers as ls

    n = 50
    A = sp.diags([-1.0, 4.0, -1.0], [-1, 0, 1], shape=(n, n)).tocsr()
    C = 2.0 * A
    indefinite = A - 5.5 * sp.identity(n, format="csr")  # same pattern, eigenvalues in (-3.5, 0.5), none 0
    b = np.ones(n)
    solver = fe.CholmodSolver()
    solver.solve(A, b)
    solver.solve(C, b)
    offered = ls._FACTORS.lu
    assert isinstance(offered, chol._FactorSolve)
    # a direct solve of 50 unknowns, cond(C) < 3: round-off only
    assert np.linalg.norm(C @ offered.solve(b) - b) < 1e-12 * np.linalg.norm(b)
    solver.solve(indefinite, b)  # CHOLMOD fails, SuperLU answers: the offered factor is withdrawn
    assert ls._FACTORS.lu is None or not (isinstance(ls._FACTORS.lu, chol._FactorSolve)
                                          and ls._FACTORS.lu.factor is offered.factor)
