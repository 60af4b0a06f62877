"""The run directory's VTU frames as ParaView reads them (issue 20, item 4).

Reference points plus a ``displacement`` array (Warp By Vector deforms them
once), P2 bodies as quadratic tets (VTK type 24) with their mid-edge values,
field data with the time and the units; frames written before the change
(deformed points, no units) still read back right.
"""

from __future__ import annotations

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.app.output import SeriesWriter
from fem_elastic.app.vtu import REFERENCE_POINTS, read_series, vtu_units, write_pvd, write_vtu_frame

vtk_xml = pytest.importorskip("vtkmodules.vtkIOXML")
from vtkmodules.util.numpy_support import vtk_to_numpy  # noqa: E402


def _series(tmp_path, order):
    model = fe.Model(fe.beam_mesh(cells=(3, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3), order=order),
                     fixed="left", gravity=(0.0, 0.0, -9.81))
    writer = SeriesWriter(model, tmp_path)
    state = fe.State.rest(model)
    writer.write_state(state)
    run = fe.simulate(model, fe.ImplicitEuler(), dt=0.02, steps=3, state=state, observers=[writer])
    writer.finish(run)
    return model, run


def _vtk_read(path):
    reader = vtk_xml.vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    assert reader.GetErrorCode() == 0
    return reader.GetOutput()


@pytest.mark.parametrize("order", [1, 2])
def test_warp_by_vector_gives_the_deformed_body_once(tmp_path, order):
    model, run = _series(tmp_path, order)
    grid = _vtk_read(tmp_path / "frames" / f"frame_{run.times.size - 1:06d}.vtu")
    points = vtk_to_numpy(grid.GetPoints().GetData())
    u = vtk_to_numpy(grid.GetPointData().GetArray("displacement"))
    X = np.asarray(model.X).reshape(-1, 3)
    np.testing.assert_array_equal(points, X)  # the reference positions, bit for bit
    # ParaView's Warp By Vector (scale 1): points + displacement = the final DOF positions;
    # the sum of two float64 rounds once (|x| <= 1 m: 1e-15 m)
    np.testing.assert_allclose(points + u, run.final_state.x.reshape(-1, 3), rtol=0, atol=1e-15)
    assert grid.GetCellType(0) == (24 if order == 2 else 10)
    assert grid.GetCell(0).GetNumberOfPoints() == (10 if order == 2 else 4)


def test_p2_mid_edge_values_are_the_solution_at_the_edge_nodes(tmp_path):
    """The mid-edge nodes carry the P2 solution itself, not the mean of the vertices."""
    model, run = _series(tmp_path, 2)
    grid = _vtk_read(tmp_path / "frames" / f"frame_{run.times.size - 1:06d}.vtu")
    u = vtk_to_numpy(grid.GetPointData().GetArray("displacement"))
    cells = vtk_to_numpy(grid.GetCells().GetConnectivityArray()).reshape(-1, 10)
    u_dofs = (run.final_state.x - model.X).reshape(-1, 3)
    np.testing.assert_array_equal(u, u_dofs)
    # the geometry is VTK's quadratic tet: node 4 is the middle of edge 0-1, node 6 of 2-0 ...
    X = np.asarray(model.X).reshape(-1, 3)
    for j, (a, b) in enumerate([(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)]):
        # doflocs of the edge nodes are computed by scikit-fem's mapping: 1e-15 m round-off
        np.testing.assert_allclose(X[cells[:, 4 + j]], 0.5 * (X[cells[:, a]] + X[cells[:, b]]),
                                   rtol=0, atol=1e-15)
    # a bending beam's edges curve: the mid-edge values differ from the vertex mean by a share
    # of the deflection (measured 10 % of max |u| on edge 0-1), where round-off of the mean, or
    # edge nodes written as the mean, would leave 1e-16 of it
    mean = 0.5 * (u[cells[:, 0]] + u[cells[:, 1]])
    assert np.max(np.abs(u[cells[:, 4]] - mean)) > 1e-3 * np.max(np.abs(u))
    series = read_series(tmp_path)  # read back at the vertices, as fe.simulate records them
    # the frames store each state's x - X, the values fe.simulate records: bit for bit
    np.testing.assert_array_equal(series.displacement, run.displacement)
    np.testing.assert_array_equal(series.tets, model.mesh.t.T)


def test_field_data_holds_time_and_units(tmp_path):
    _, run = _series(tmp_path, 1)
    grid = _vtk_read(tmp_path / "frames" / "frame_000002.vtu")
    time = vtk_to_numpy(grid.GetFieldData().GetArray("TimeValue"))
    assert time.tolist() == [run.times[2]]  # written with repr: exact
    units = vtu_units({"units": vtk_to_numpy(grid.GetFieldData().GetArray("units"))})
    assert units["displacement"] == "m" and units["von_mises"] == "Pa"
    assert units["points"] == REFERENCE_POINTS and units["TimeValue"] == "s"
    pv = pytest.importorskip("pyvista")
    mesh = pv.read(tmp_path / "frames" / "frame_000002.vtu")
    assert float(mesh.field_data["TimeValue"][0]) == run.times[2]


def test_frames_of_the_old_convention_still_read_back(tmp_path):
    """Frames written before (deformed points, no units field) give the same reference."""
    mesh = fe.beam_mesh(cells=(1, 1, 1))
    ref, tets = mesh.p.T, mesh.t.T
    u = np.full(ref.shape, 0.25)
    (tmp_path / "frames").mkdir()
    write_vtu_frame(tmp_path / "frames/old.vtu", ref + u, tets,
                    {"displacement": u, "velocity": 0 * u})
    write_pvd(tmp_path / "series.pvd", [(0.0, "frames/old.vtu")])
    old = read_series(tmp_path)
    write_vtu_frame(tmp_path / "frames/old.vtu", ref, tets, {"displacement": u, "velocity": 0 * u},
                    field_data={"TimeValue": [0.0]}, units={"points": REFERENCE_POINTS})
    new = read_series(tmp_path)
    # old: (ref + u) - u, two roundings of coordinates <= 1.25 m (~2e-16 m each)
    np.testing.assert_allclose(old.points_ref, ref, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(new.points_ref, ref)  # new: the stored reference itself
    np.testing.assert_array_equal(old.displacement, new.displacement)


def test_bad_cells_are_refused(tmp_path):
    with pytest.raises(fe.InvalidParameter, match=r"\(m, 4\) or \(m, 10\)"):
        write_vtu_frame(tmp_path / "x.vtu", np.zeros((4, 3)), [[0, 1, 2]])
