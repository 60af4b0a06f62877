"""Results you can look at from Python (issue 20, item 2).

Short reprs and HTML tables of Model, Trajectory and StaticResult;
``to_pyvista`` grids on reference points (P2 as VTK type 24); ``plot`` off
screen; ``plot_energy`` / ``plot_history`` (matplotlib Axes); ``save`` as a
run directory; ``fe.render`` public.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.physics.pyvista_grid import auto_magnification, nodal_positions

pv = pytest.importorskip("pyvista")
matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")


def _model(order=1, E=1e5):
    return fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
                    body=fe.ElasticBody(fe.NeoHookean(E=E, nu=0.3), order=order),
                    fixed="left", gravity=(0.0, 0.0, -9.81))


@pytest.fixture(scope="module")
def runs():
    model = _model(order=2)
    traj = fe.simulate(model, fe.ImplicitEuler(), dt=0.01, steps=3)
    static = fe.solve_static(model)
    return model, traj, static


def test_reprs_are_short_and_say_what_matters(runs):
    model, traj, static = runs
    for obj, title, must in [
        (model, "Model", ["24 tets", "NeoHookean", "kg"]),
        (traj, "Trajectory", ["ImplicitEuler", "wall time", "max |u|", "energy", "min det F"]),
        (static, "StaticResult", ["converged: True", "max |u|", "total reaction", "stable"]),
    ]:
        text = repr(obj)
        assert text.startswith(title) and len(text.splitlines()) <= 12 and len(text) < 800, text
        for word in must:
            assert word in text, (word, text)
        html = obj._repr_html_()
        assert html.startswith("<table>") and html.count("<tr>") == len(text.splitlines()) - 1
    # the key physical result is the number itself: the largest vertex displacement
    u = np.linalg.norm(traj.displacement, axis=-1).max()
    assert f"max |u|: {u:.4g} m" in repr(traj)
    # the total reaction balances the weight (10 kg x 9.81 m/s^2), to the repr's 4 digits
    assert "98.1) N" in repr(static)


@pytest.mark.parametrize("order, cell_type, nodes", [(1, 10, 4), (2, 24, 10)])
def test_to_pyvista_is_the_reference_grid_with_the_displacement(order, cell_type, nodes):
    model = _model(order=order)
    traj = fe.simulate(model, fe.ImplicitEuler(), dt=0.01, steps=2)
    grid = traj.to_pyvista(-1)
    assert set(grid.celltypes) == {cell_type} and grid.get_cell(0).n_points == nodes
    np.testing.assert_array_equal(grid.points, np.asarray(model.X).reshape(-1, 3))
    # the last frame is the final state itself: warping gives the final positions, X + (x - X)
    # rounded twice on coordinates <= 1 m (2.2e-16 m each)
    np.testing.assert_allclose(grid.warp_by_vector("displacement").points,
                               traj.final_state.x.reshape(-1, 3), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(grid.point_data["velocity"], traj.final_state.v.reshape(-1, 3))
    assert grid.cell_data["von_mises"].shape == (model.mesh.t.shape[1],)
    assert float(grid.field_data["TimeValue"][0]) == traj.times[-1]
    # an earlier frame: its vertex values exactly (P2 edge nodes at their edge's mean)
    first = traj.to_pyvista(1)
    nv = model.mesh.p.shape[1]
    np.testing.assert_array_equal(first.point_data["displacement"][:nv], traj.displacement[1])
    static = fe.solve_static(model).to_pyvista()
    assert set(static.celltypes) == {cell_type}
    assert model.to_pyvista().point_data["displacement"].max() == 0.0  # the body at rest


def test_nodal_positions_puts_edge_nodes_at_the_middle():
    model = _model(order=2)
    X = np.asarray(model.X).reshape(-1, 3)
    # linear in x, so the P2 interpolant of the vertex values is exact: 1e-15 m round-off
    np.testing.assert_allclose(nodal_positions(model, model.mesh.p.T).reshape(-1, 3), X,
                               rtol=0, atol=1e-15)
    with pytest.raises(fe.InvalidParameter, match="n_vertices, 3"):
        nodal_positions(model, np.zeros((3, 3)))


def test_auto_magnification_rule():
    assert auto_magnification(0.1, 1.0) == 1.0  # 10 % of the size: seen as it is
    assert auto_magnification(0.049, 1.0) == 2.0  # 0.15 / 0.049 = 3.06 -> 2
    assert auto_magnification(1e-5, 1.0) == 1e4  # 15000 -> 1e4
    assert auto_magnification(0.0, 1.0) == 1.0 and auto_magnification(float("nan"), 1.0) == 1.0


def test_plot_off_screen_writes_a_picture(tmp_path, runs):
    model, traj, static = runs
    for obj, name in [(traj, "traj.png"), (static, "static.png"), (model, "model.png")]:
        obj.plot(screenshot=tmp_path / name, window_size=(200, 120))
        image = pv.read(tmp_path / name)
        assert image.dimensions[:2] == (200, 120)
    with pytest.raises(fe.InvalidParameter, match="colour by one of"):
        traj.plot(scalars="nope", off_screen=True)
    with pytest.raises(fe.InvalidParameter, match="magnification"):
        traj.plot(magnification=-1, off_screen=True)


def test_energy_and_history_plots_return_axes(runs):
    _, traj, static = runs
    ax = traj.plot_energy()
    assert [line.get_label() for line in ax.get_lines()] == ["kinetic", "potential", "total"]
    np.testing.assert_array_equal(ax.get_lines()[2].get_ydata(), traj.total)
    ax = traj.plot_history("max_displacement")
    np.testing.assert_allclose(ax.get_lines()[0].get_ydata(),
                               np.linalg.norm(traj.displacement, axis=-1).max(axis=-1))
    assert traj.plot_history("newton_iterations").get_xlabel() == "step"
    assert static.plot_history("residual").get_yscale() == "log"
    ax = static.plot_history("left")  # the reaction on the clamp against the load factor
    # the internal forces sum to zero (a rigid translation stores no energy), so the reaction is
    # the weight less the free DOFs' residual: Newton's quadratic steps end far below rtol
    # (measured 1e-15 relative), 1e-9 leaves room for another BLAS
    assert ax.get_lines()[2].get_ydata()[-1] == pytest.approx(98.1, rel=1e-9)  # 10 kg x g
    with pytest.raises(fe.InvalidParameter, match="unknown quantity"):
        traj.plot_history("nope")
    matplotlib.pyplot.close("all")


def test_save_writes_a_run_directory_that_reads_back(tmp_path, runs):
    model, traj, static = runs
    traj.save(tmp_path / "dyn")
    series = fe.read_series(tmp_path / "dyn")
    np.testing.assert_array_equal(series.times, traj.times)
    # frames before the last are written as (X + u) - X: one rounding of coordinates <= 1 m
    # (1.1e-16 m) plus one of u; the last is the final state's own displacement
    np.testing.assert_allclose(series.displacement, traj.displacement, rtol=0, atol=1e-15)
    summary = json.loads((tmp_path / "dyn" / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["steps"] == 3
    assert summary["max_displacement"] == pytest.approx(
        np.linalg.norm(traj.displacement, axis=-1).max(), rel=1e-15)
    static.save(tmp_path / "static")
    series = fe.read_series(tmp_path / "static")
    np.testing.assert_array_equal(series.times, static.path.load_factors)
    summary = json.loads((tmp_path / "static" / "summary.json").read_text())
    assert summary["reactions"]["left"][2] == pytest.approx(98.1, rel=1e-9)  # as plot_history's
    bare = fe.Trajectory(**{k: getattr(traj, k) for k in (
        "times", "displacement", "velocity", "kinetic", "potential", "total", "linear_momentum",
        "angular_momentum")})
    with pytest.raises(fe.InvalidParameter, match="does not know its model"):
        bare.save(tmp_path / "x")
    bare.save(tmp_path / "x", model=model)  # given the model, it saves
    assert (tmp_path / "x" / "series.pvd").is_file()


def test_render_is_public():
    from fem_elastic.app import render

    assert fe.render is render and fe.render_runs is render.render_runs
    assert fe.render_frame is render.render_frame and "render" in fe.__all__


def test_save_does_not_delete_a_users_files_and_locks_the_directory(tmp_path, runs):
    from fem_elastic.app.run_lock import RunLock

    model, traj, static = runs
    user = tmp_path / "mine"
    (user / "frames").mkdir(parents=True)
    (user / "notes.txt").write_text("keep me")
    (user / "summary.json").write_text('{"mine": true}')
    (user / "frames" / "frame_000000.vtu").write_text("my frame")
    for result in (traj, static):
        with pytest.raises(fe.InvalidParameter, match=r"notes\.txt.*overwrite=True"):
            result.save(user)
        assert (user / "summary.json").read_text() == '{"mine": true}'  # nothing removed
        assert (user / "frames" / "frame_000000.vtu").read_text() == "my frame"
    static.save(user, overwrite=True)  # files with a run's names replaced, the others left
    assert (user / "notes.txt").read_text() == "keep me"
    assert json.loads((user / "summary.json").read_text())["status"] == "completed"
    saved = traj.save(tmp_path / "dyn")
    traj.save(saved)  # a result saved before is replaced without asking
    with RunLock(saved):  # another writer holds it (flock locks are per open file): refused
        with pytest.raises(fe.OutputInUse):
            traj.save(saved)


def test_saved_static_frames_say_their_time_is_the_load_factor(tmp_path, runs):
    meshio = pytest.importorskip("meshio")
    from fem_elastic.app.vtu import vtu_units

    model, traj, static = runs
    for result, unit in ((static, "1 (load factor)"), (traj, "s")):
        run_dir = result.save(tmp_path / unit.split()[0])
        frame = sorted((run_dir / "frames").glob("frame_*.vtu"))[-1]
        assert vtu_units(meshio.read(frame).field_data)["TimeValue"] == unit


def test_a_saved_diverged_trajectory_says_diverged(tmp_path):
    model = _model()
    # 9x the critical time step (5.7 ms) with no sub-steps: the energy blows up at the first step
    with pytest.warns(fe.StabilityWarning), pytest.raises(fe.Diverged) as err:
        fe.simulate(model, fe.SymplecticEuler(), dt=0.05, steps=20)
    traj = err.value.trajectory
    traj.save(tmp_path / "div", model=model)
    summary = json.loads((tmp_path / "div" / "summary.json").read_text())
    assert summary["status"] == "diverged" and summary["message"].startswith("diverged at step")
