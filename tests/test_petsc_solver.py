"""fe.PETScSolver in this process (one rank): the linear solve, the distributed path on one rank
against the serial solvers, the METIS partition, and the typed errors (issue 21).

Two ranks: tests/test_mpi.py.
"""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import fem_elastic as fe
from fem_elastic.solvers.partition import partition_elements, partition_space
from mpi_support import require_mpi


def _beam(material, order=1, cells=(8, 2, 2), **kw):
    return fe.Model(fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=cells), density=1000.0,
                    body=fe.ElasticBody(material, order=order), fixed="left", **kw)


@pytest.mark.parametrize("pc", ["gamg", "lu"])
def test_solve_matches_a_direct_solve(pc):
    require_mpi()
    m = _beam(fe.LinearElastic(E=1e7, nu=0.3))
    K = m.rest_stiffness.tocsr()
    free = m.free
    A = (sp.diags(free * 1.0) @ K @ sp.diags(free * 1.0) + sp.diags((~free) * 1.0)).tocsr()
    b = np.where(free, np.random.default_rng(1).standard_normal(m.ndofs), 0.0)
    res = fe.PETScSolver(preconditioner=pc).solve(A, b, m.rigid_body_modes)
    x = spla.spsolve(A.tocsc(), b)
    # CG stops at a relative residual of 1e-10; the error is at most cond(A) times that in the
    # worst direction, far less in practice (LU: round-off)
    assert np.linalg.norm(res.x - x) < 1e-7 * np.linalg.norm(x)
    assert res.residual < 1e-9 and res.method == f"petsc-{pc}"


def test_one_rank_static_equals_the_serial_solve_linear_and_neo_hookean():
    require_mpi()
    for material, load in ((fe.LinearElastic(E=1e7, nu=0.3), -1e3), (fe.NeoHookean(E=1e6, nu=0.4), -5e2)):
        m = _beam(material, gravity=(0, 0, -9.81), traction={"right": (0, 0, load)})
        s0 = fe.solve_static(m, rtol=1e-11, stability=False)
        r = fe.solve_static(m, linear_solver="petsc", rtol=1e-11)  # the scene name works too
        # 1e-8: issue 21's bar; the two stop at 1e-11 of the force scale (measured 1e-13)
        assert np.linalg.norm(r.x - s0.x) < 1e-8 * np.linalg.norm(s0.x - m.X)
        # rtol: the bar above; atol for the components that vanish (x and y: the loads are along
        # z), zero to round-off against reactions of ~10 N, where a relative bar means nothing
        assert np.allclose(r.reaction_force("left"), s0.reaction_force("left"), rtol=1e-8, atol=1e-9)
        assert r.converged and r.min_eigenvalue is None and "1 MPI rank" in r.message


def test_one_rank_implicit_euler_with_consistent_mass_equals_serial():
    require_mpi()
    m = _beam(fe.NeoHookean(E=1e6, nu=0.3), gravity=(0, 0, -9.81))
    a = b = fe.State.rest(m)
    ser = fe.ImplicitEuler(rtol=1e-11, mass="consistent")
    par = fe.ImplicitEuler(rtol=1e-11, mass="consistent", linear_solver=fe.PETScSolver())
    for _ in range(3):
        a, b = ser.step(m, a, 0.01), par.step(m, b, 0.01)
    # the same minimiser to the Newton tolerance (1e-11 of the step's force scale)
    assert np.linalg.norm(b.x - a.x) < 1e-8 * np.linalg.norm(a.x - m.X)
    assert np.linalg.norm(b.v - a.v) < 1e-8 * np.linalg.norm(a.v)
    assert par.last_stats.newton_iterations > 0 and par.last_stats.linear_iterations > 0


def test_partition_owns_every_node_once_in_contiguous_blocks():
    require_mpi()
    m = _beam(fe.LinearElastic(E=1e6, nu=0.3), order=2, cells=(12, 3, 3))
    t = m.mesh.t
    for nparts in (2, 3, 5):
        parts = partition_elements(t, nparts)
        counts = np.bincount(parts, minlength=nparts)
        # METIS balances to within its default 3 % imbalance (allow 10 %: tiny parts round)
        assert counts.min() > 0 and counts.max() <= 1.10 * t.shape[1] / nparts
        p = partition_space(m.space.element_dofs, m.ndofs, parts, nparts)
        new = p.new_dofs(np.arange(m.ndofs))
        assert np.array_equal(np.sort(new), np.arange(m.ndofs))  # a permutation of the DOFs
        nodes = m.space.element_dofs[0::3] // 3
        for r in range(nparts):
            lo, hi = p.dof_range(r)
            owned = np.flatnonzero(p.node_owner == r)
            assert np.array_equal(np.sort(p.new_node[owned]), np.arange(lo // 3, hi // 3))
            # a node is owned by the lowest rank among its tets (so every owner assembles it)
            held_by_r = np.unique(nodes[:, parts == r])
            assert np.all(p.node_owner[held_by_r] <= r)
        # the cut is small: METIS on the dual graph, not a random split
        shared = np.unique(nodes[:, parts == 0]).size + np.unique(nodes[:, parts != 0]).size - m.ndofs // 3
        assert shared < 0.5 * m.ndofs // 3


def test_bad_input_is_a_typed_error_naming_the_fix(monkeypatch):
    # (an unknown preconditioner, more ranks than tets and an obstacle are rows of
    # tests/bad_inputs.py, run by test_bad_inputs)
    with pytest.raises(fe.InvalidParameter, match="rtol"):
        fe.PETScSolver(rtol=2.0)
    require_mpi()
    # damping is not distributed yet: said, with the serial way out
    m = _beam(fe.LinearElastic(E=1e6, nu=0.3), gravity=(0, 0, -9.81), damping=fe.Rayleigh(1.0, 0.0))
    with pytest.raises(fe.InvalidParameter, match="damping"):
        fe.ImplicitEuler(linear_solver=fe.PETScSolver()).step(m, fe.State.rest(m), 0.01)
    # the launcher started 2 processes but PETSc sees one: PETSc without MPI (or another MPI)
    from fem_elastic.solvers.petsc_solver import comm_world, petsc

    petsc()  # MPI starts here as a one-process singleton, before the launcher's variable is faked
    monkeypatch.setenv("OMPI_COMM_WORLD_SIZE", "2")
    with pytest.raises(fe.MissingDependency, match="built without MPI"):
        comm_world()


def test_ranks_without_a_launcher_is_a_typed_error(monkeypatch, tmp_path):
    from fem_elastic.app.mpi_run import relaunch_command

    monkeypatch.setenv("PATH", str(tmp_path))  # no mpiexec anywhere
    with pytest.raises(fe.MissingDependency, match="no mpiexec on the PATH"):
        relaunch_command(["run", "scene.toml", "--ranks", "2"], 2)


def test_gamg_solves_p2_and_many_solves_fit_petsc_options():
    require_mpi()
    # P2 tangents need another GAMG smoother than P1 (petsc_solver.PETScSolver.settings)
    m = _beam(fe.NeoHookean(E=1e6, nu=0.3), order=2, cells=(6, 2, 2), gravity=(0, 0, -9.81))
    s0 = fe.solve_static(m, rtol=1e-10, stability=False)
    r = fe.solve_static(m, linear_solver=fe.PETScSolver(), rtol=1e-10)
    assert np.linalg.norm(r.x - s0.x) < 1e-8 * np.linalg.norm(s0.x - m.X)  # both at 1e-10 of the load
    # PETSc 3.18 holds 512 options: a solver configuration writes its options once, not per KSP
    A = sp.diags([2.0, 3.0, 4.0]).tocsr()
    for _ in range(600):
        x = fe.PETScSolver(preconditioner="lu").solve(A, np.ones(3)).x
    assert np.allclose(x, [0.5, 1 / 3, 0.25], rtol=1e-14)  # LU: exact to round-off


def test_tiny_implicit_steps_converge_at_the_inertia_round_off_floor():
    require_mpi()
    # at dt = 1e-6 s the inertia term's round-off (grows as 1/h^2) is far above the body's: Newton
    # must stop there, as the serial one does, instead of failing to reach rtol
    m = _beam(fe.NeoHookean(E=1e6, nu=0.3), gravity=(0, 0, -9.81))
    a = fe.ImplicitEuler().step(m, fe.State.rest(m), 1e-6)
    b = fe.ImplicitEuler(linear_solver=fe.PETScSolver()).step(m, fe.State.rest(m), 1e-6)
    assert np.abs(a.x - m.X).max() > 1e-12  # it moved: about g h^2 = 1e-11 m
    # the step moves ~1e-11 m on coordinates of ~1 m: both stop at the round-off of those
    # coordinates, a few ulp of 1 m (eps = 2.2e-16), hence 1e-15 m
    assert np.abs(b.x - a.x).max() < 1e-15


def test_strip_ranks_removes_every_spelling():
    from fem_elastic.app.mpi_run import _strip_ranks

    for argv in (["run", "s.toml", "--ranks", "2"], ["run", "--ranks=2", "s.toml"],
                 ["run", "s.toml", "--rank", "2"], ["run", "--ran=3", "s.toml"]):
        assert _strip_ranks(argv) == ["run", "s.toml"], argv
    assert _strip_ranks(["run", "--resume", "d"]) == ["run", "--resume", "d"]  # not a --ranks


def test_mixed_formulation_runs_on_the_distributed_path():
    require_mpi()
    # the displacement-pressure body's potential is an ElasticPotential summed over tets (the
    # element pressure is condensed per tet), so a rank's sub-mesh carries its share exactly
    body = fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.499), order=2, formulation="mixed")
    m = fe.Model(fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(6, 2, 2)), 1000.0, body,
                 fixed="left", gravity=(0, 0, -9.81))
    s0 = fe.solve_static(m, rtol=1e-10, stability=False)
    r = fe.solve_static(m, linear_solver=fe.PETScSolver(preconditioner="lu"), rtol=1e-10)
    # both stop at 1e-10 of the load; nu = 0.499 conditions the tangent by ~1e3, hence 1e-7
    # (measured 6.7e-10: one Newton step each, LU against the serial solver)
    assert np.linalg.norm(r.x - s0.x) < 1e-7 * np.linalg.norm(s0.x - m.X)


def test_load_steps_on_the_distributed_path_are_the_serial_ones():
    """steps=10: the distributed load path takes the serial path's load factors, bit for bit
    (0.1, ..., 1.0 on the grid; it once took 0.9999999999999999 and then 1.0, one solve too many)."""
    require_mpi()
    m = _beam(fe.NeoHookean(E=1e6, nu=0.4), traction={"right": (0, 0, -5e2)})
    serial = fe.solve_static(m, steps=10, stability=False)
    dist = fe.solve_static(m, linear_solver="petsc", steps=10)
    assert dist.load_steps == serial.load_steps and len(dist.load_steps) == 10


def test_a_model_solved_on_the_distributed_path_is_freed():
    """The cached distributed problem holds its model weakly: once the caller drops the model,
    the model and its PETSc objects go (a strong reference kept every solved model alive)."""
    import gc
    import weakref

    from fem_elastic.solvers import distributed

    require_mpi()
    m = _beam(fe.LinearElastic(E=1e7, nu=0.3), traction={"right": (0, 0, -1e3)})
    fe.solve_static(m, linear_solver="petsc")
    assert len(distributed._PROBLEMS) >= 1
    alive = weakref.ref(m)
    del m
    gc.collect()
    assert alive() is None
