"""Tests of fem_elastic.app.output: the VTU series a run writes, read back and checked
against what fe.simulate returned, and its behaviour when a write fails midway."""

import json
import logging
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

import fem_elastic as fe
import fem_elastic.files as fio
from fem_elastic.errors import InvalidParameter
from fem_elastic.physics.fields import cell_fields
from fem_elastic.app.vtu import read_series
from fem_elastic.app.output import SeriesWriter, to_json, write_summary

BODIES = {
    "NeoHookean-P1": lambda: fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
    "NeoHookean-P2": lambda: fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3), order=2),
    "MassSpring": lambda: fe.MassSpring(E=1e5),
}


def _model(body="NeoHookean-P1"):
    return fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0, body=BODIES[body](),
                    fixed="left", gravity=(0.0, 0.0, -9.81))


def _run(model, run_dir, *, steps, every, give_n_steps, compression="zlib"):
    writer = SeriesWriter(model, run_dir, every=every, n_steps=steps if give_n_steps else None,
                          info={"name": "beam"}, compression=compression)
    state = fe.State.rest(model)
    writer.write_state(state)
    run = fe.simulate(model, fe.ImplicitEuler(), dt=0.01, steps=steps, state=state,
                      record_every=every, callback=writer.callback)
    writer.finish(run)
    return writer, run


@pytest.mark.parametrize(
    "body, every, give_n_steps, compression",
    [("NeoHookean-P1", 1, True, "zlib"), ("NeoHookean-P2", 3, False, "zlib"),
     ("MassSpring", 3, True, None)],
)
def test_series_reads_back_what_simulate_returned(tmp_path, body, every, give_n_steps, compression):
    model = _model(body)
    writer, run = _run(model, tmp_path, steps=7, every=every, give_n_steps=give_n_steps,
                       compression=compression)

    series = read_series(tmp_path)
    # frames at the same steps as the Trajectory's (first, every `every`, last); the PVD
    # holds times with 17 digits and the VTU float64 binary: the values come back exactly.
    np.testing.assert_array_equal(series.times, run.times)
    np.testing.assert_allclose(series.displacement, run.displacement, rtol=0, atol=1e-12)
    np.testing.assert_allclose(series.velocity, run.velocity, rtol=0, atol=1e-12)
    X = model.to_vertices(model.X)
    # the frames hold the reference positions themselves
    np.testing.assert_array_equal(series.points_ref, X)
    np.testing.assert_array_equal(series.tets, model.mesh.t.T)
    n_tets = model.mesh.t.shape[1]
    assert series.cell_data["von_mises"].shape == (run.times.size, n_tets)
    final = cell_fields(model, run.final_state.x)
    for name in ("von_mises", "energy_density"):
        np.testing.assert_array_equal(series.cell_data[name][-1], final[name])
    assert series.cell_data["von_mises"][-1].max() > 0  # the beam sags under gravity

    # the same files straight through meshio, as ParaView would see them
    root = ET.parse(tmp_path / "series.pvd").getroot()
    assert root.get("type") == "Collection"
    datasets = list(root.iter("DataSet"))
    np.testing.assert_array_equal([float(d.get("timestep")) for d in datasets], run.times)
    for k, d in enumerate(datasets):
        mesh = meshio.read(tmp_path / d.get("file"))
        u = mesh.point_data["displacement"][:len(X)]  # P2: the vertices come first
        np.testing.assert_allclose(u, run.displacement[k], rtol=0, atol=1e-12)
        # reference points (Warp By Vector on displacement deforms them once)
        np.testing.assert_array_equal(mesh.points, model.X.reshape(-1, 3))
        cell_type = "tetra10" if body.endswith("P2") else "tetra"
        np.testing.assert_array_equal(mesh.cells_dict[cell_type][:, :4], model.mesh.t.T)
        assert set(mesh.cell_data) >= {"von_mises", "energy_density"}

    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary == series.summary
    assert summary["status"] == "completed" and summary["name"] == "beam"
    assert summary["steps"] == 7 and summary["frames"] == run.times.size
    assert summary["wall_time"] > 0 and summary["seconds_output"] > 0
    assert summary["energy_initial"] == pytest.approx(run.total[0], rel=1e-15)
    assert summary["energy_final"] == pytest.approx(run.total[-1], rel=1e-15)
    assert summary["newton_iterations_total"] == float(run.step_stats["newton_iterations"].sum())
    assert summary["n_vertices"] == X.shape[0] and summary["n_tets"] == n_tets
    assert summary["von_mises_max"] == pytest.approx(float(final["von_mises"].max()), rel=1e-15)
    assert summary["ground"] is None
    leftovers = [p.name for p in tmp_path.rglob("*") if p.name.startswith(".")]
    assert leftovers == []  # no temporary file left behind


def _writer_with_two_frames(tmp_path):
    model = _model()
    writer = SeriesWriter(model, tmp_path)
    state = fe.State.rest(model)
    writer.write_state(state)
    state = fe.ImplicitEuler().step(model, state, 0.01)
    writer.write_state(state)
    return model, writer, fe.ImplicitEuler().step(model, state, 0.01)


def _assert_two_frames_intact(tmp_path):
    series = read_series(tmp_path)
    np.testing.assert_allclose(series.times, [0.0, 0.01], rtol=1e-15)
    assert not (tmp_path / "frames" / "frame_000002.vtu").exists()
    assert [p.name for p in tmp_path.rglob(".*")] == []  # the temporary file was removed


def test_failed_rename_leaves_the_previous_series(tmp_path, monkeypatch):
    model, writer, state = _writer_with_two_frames(tmp_path)

    def failing_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(fio.os, "replace", failing_replace)
    with pytest.raises(OSError, match="disk full"):
        writer.write_state(state)
    _assert_two_frames_intact(tmp_path)
    assert len(writer.frames) == 2
    monkeypatch.undo()
    writer.write_state(state)  # the writer carries on where it was
    assert read_series(tmp_path).times.size == 3


def test_interrupt_in_the_middle_of_a_vtu_write(tmp_path, monkeypatch):
    model, writer, state = _writer_with_two_frames(tmp_path)

    def half_write(filename, mesh, *args, **kwargs):
        with open(filename, "wb") as fh:  # a partial file under the temporary name
            fh.write(b'<?xml version="1.0"?>\n<VTKFile type="UnstructuredGrid"')
        raise KeyboardInterrupt

    monkeypatch.setattr(meshio, "write", half_write)
    with pytest.raises(KeyboardInterrupt):
        writer.write_state(state)
    _assert_two_frames_intact(tmp_path)


def test_failed_pvd_write_keeps_the_listed_frames(tmp_path, monkeypatch):
    model, writer, state = _writer_with_two_frames(tmp_path)
    real = fio.os.replace

    def replace(src, dst):
        if str(dst).endswith(".pvd"):
            raise OSError("disk full")
        real(src, dst)

    monkeypatch.setattr(fio.os, "replace", replace)
    with pytest.raises(OSError):
        writer.write_state(state)
    # the new frame file exists but is not listed: the series is still the two frames
    np.testing.assert_allclose(read_series(tmp_path).times, [0.0, 0.01], rtol=1e-15)
    assert len(writer.frames) == 2


def test_deleted_frame_is_skipped_with_a_warning(tmp_path, caplog):
    model = _model()
    writer, run = _run(model, tmp_path, steps=3, every=1, give_n_steps=True)
    (tmp_path / "frames" / "frame_000001.vtu").unlink()
    with caplog.at_level(logging.WARNING, logger="fem_elastic.app.vtu"):
        series = read_series(tmp_path)
    np.testing.assert_array_equal(series.times, run.times[[0, 2, 3]])
    np.testing.assert_allclose(series.displacement, run.displacement[[0, 2, 3]], rtol=0, atol=1e-12)
    assert "frame_000001.vtu" in caplog.text and "missing" in caplog.text


def test_interrupted_run_finishes_with_a_readable_series(tmp_path):
    model = _model()

    def stop_at_4(k, state):
        writer.callback(k, state)
        if k == 4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        with SeriesWriter(model, tmp_path, every=3) as writer:
            writer.write_state(fe.State.rest(model))
            fe.simulate(model, fe.ImplicitEuler(), dt=0.01, steps=10, callback=stop_at_4)
    series = read_series(tmp_path)
    # frames: the start, step 2 (every 3rd), and the last state seen (step 4) on the way out
    np.testing.assert_allclose(series.times, [0.0, 0.03, 0.05], rtol=1e-12)
    s = series.summary
    assert s["status"] == "interrupted" and "Ctrl-C" in s["message"] and "step 4" in s["message"]
    assert s["steps"] == 5 and s["frames"] == 3 and np.isfinite(s["energy_final"])


def test_diverged_run_finishes_as_diverged(tmp_path):
    model = _model()
    dt = 1.1 * fe.critical_time_step(model, fe.SymplecticEuler())  # beyond stability: ~16 steps
    with pytest.raises(fe.Diverged):
        with SeriesWriter(model, tmp_path, every=1) as writer:
            writer.write_state(fe.State.rest(model))
            fe.simulate(model, fe.SymplecticEuler(), dt=dt, steps=200, check_stability=False,
                        callback=writer.callback)
    series = read_series(tmp_path)
    assert series.summary["status"] == "diverged"
    assert "diverged" in series.summary["message"]
    assert np.all(np.isfinite(series.displacement))  # only good states were written
    assert series.summary["frames"] == series.times.size >= 2


def test_rerun_in_the_same_directory_replaces_the_series(tmp_path):
    model = _model()
    _run(model, tmp_path, steps=5, every=1, give_n_steps=True)
    writer = SeriesWriter(model, tmp_path)
    assert not (tmp_path / "series.pvd").exists() and not (tmp_path / "summary.json").exists()
    writer.write_state(fe.State.rest(model))
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == ["frame_000000.vtu"]
    assert read_series(tmp_path).times.size == 1


def test_ground_and_summary_json_conversion(tmp_path):
    model = fe.Model(fe.beam_mesh(cells=(2, 1, 1)).translated((0, 0, 0.5)), density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), gravity=(0, 0, -9.81),
                     ground=fe.Ground(z=-0.25))
    writer = SeriesWriter(model, tmp_path)
    writer.write_state(fe.State.rest(model))
    summary = json.loads(writer.finish(extra={"tip": np.float64(-1e-3), "nan": np.nan}).read_text())
    assert summary["ground"]["kind"] == "plane" and summary["ground"]["z"] == -0.25
    assert summary["tip"] == -1e-3 and summary["nan"] is None  # strict JSON: NaN -> null
    assert summary["von_mises_max"] == 0.0  # at rest
    with pytest.raises(InvalidParameter, match="finish"):
        writer.finish()
    with pytest.raises(InvalidParameter, match="JSON"):
        write_summary(tmp_path / "bad.json", {"x": object()})
    assert to_json({1: (np.int32(2), np.array([np.inf]))}) == {"1": [2, [None]]}


def test_bad_arguments(tmp_path):
    model = _model()
    with pytest.raises(InvalidParameter, match="every"):
        SeriesWriter(model, tmp_path, every=0)
    with pytest.raises(InvalidParameter, match="compression"):
        SeriesWriter(model, tmp_path, compression="gzip")
    writer = SeriesWriter(model, tmp_path)
    with pytest.raises(InvalidParameter, match="status"):
        writer.finish(status="crashed")


def test_vtk_reads_the_series(tmp_path):
    """VTK's own XML reader (what ParaView uses for .vtu) and pyvista's PVD reader."""
    vtk_xml = pytest.importorskip("vtkmodules.vtkIOXML")
    from vtkmodules.util.numpy_support import vtk_to_numpy

    model = _model("NeoHookean-P2")
    writer, run = _run(model, tmp_path, steps=3, every=2, give_n_steps=False)
    reader = vtk_xml.vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(tmp_path / "frames" / f"frame_{run.times.size - 1:06d}.vtu"))
    reader.Update()
    assert reader.GetErrorCode() == 0
    grid = reader.GetOutput()
    assert grid.GetNumberOfCells() == model.mesh.t.shape[1]
    u = vtk_to_numpy(grid.GetPointData().GetArray("displacement"))
    nv = model.mesh.p.shape[1]
    # P2: quadratic tets (VTK type 24) over vertices and mid-edge nodes, vertices first
    assert u.shape == (model.ndofs // 3, 3) and grid.GetCellType(0) == 24
    np.testing.assert_allclose(u[:nv], run.displacement[-1], rtol=0, atol=1e-12)
    assert grid.GetCellData().GetArray("von_mises") is not None
    time = vtk_to_numpy(grid.GetFieldData().GetArray("TimeValue"))
    assert time.tolist() == [run.times[-1]]
    pv = pytest.importorskip("pyvista")
    np.testing.assert_allclose(pv.get_reader(str(tmp_path / "series.pvd")).time_values, run.times,
                               rtol=1e-15)


def test_finish_on_a_given_final_state(tmp_path):
    model = _model()
    writer = SeriesWriter(model, tmp_path, every=100)
    rest = fe.State.rest(model)
    writer.write_state(rest)
    run = fe.simulate(model, fe.ImplicitEuler(), dt=0.01, steps=3, callback=writer.callback)
    moved = fe.State(run.final_state.x, run.final_state.v, 0.5)
    writer.finish(run, status="diverged", message="stopped by hand", final_state=moved)
    series = read_series(tmp_path)
    np.testing.assert_array_equal(series.times, [0.0, 0.5])  # the callback wrote no frame
    np.testing.assert_allclose(series.displacement[-1], run.displacement[-1], rtol=0, atol=1e-12)
    assert series.summary["message"] == "stopped by hand" and series.summary["steps"] == 3


def test_run_figures_win_over_the_scene_info_of_the_same_name(tmp_path):
    # The scene passes its plan as info (e.g. "steps" it meant to take); a run that stopped
    # early must report the steps it took, not the plan.
    model = _model()
    writer = SeriesWriter(model, tmp_path, info={"steps": 100, "t_end": 1.0, "variant": "fem"})
    writer.write_state(fe.State.rest(model))
    run = fe.simulate(model, fe.ImplicitEuler(), dt=0.01, steps=3, callback=writer.callback)
    writer.finish(run, status="diverged", message="stopped")
    s = read_series(tmp_path).summary
    assert s["steps"] == 3 and s["t_end"] == pytest.approx(0.03, rel=1e-12)  # round-off of 3 x 0.01
    assert s["variant"] == "fem"  # info that the run does not know is kept


def test_interrupted_summary_survives_a_failing_energy(tmp_path, monkeypatch):
    # Ctrl-C can land in the middle of a lazy import (numba's, on the first energy
    # evaluation); evaluating the energy again for the summary then fails too. The summary,
    # which says how the run ended, must still be written.
    model = _model()
    writer = SeriesWriter(model, tmp_path)
    writer.write_state(fe.State.rest(model))

    def broken(*args, **kwargs):
        raise AttributeError("partially initialized module 'numba.core.types'")

    monkeypatch.setattr(type(model), "energy", broken)
    writer.finish(None, status="interrupted", message="interrupted after 0 steps")
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["status"] == "interrupted" and s["energy_final"] is None and s["frames"] == 1
