"""Tests of fem_elastic.geometry.mesh_io: load/save round trips and file errors."""

import logging
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import numpy as np
import pytest

from fem_elastic.errors import InvalidMesh, InvalidParameter
from fem_elastic.geometry.mesh_io import load_mesh, save_mesh
from fem_elastic.geometry.mesh import beam_mesh, signed_volumes, validate_mesh

MESHES = Path(__file__).resolve().parent.parent / "meshes"


def _triple_sets(mesh):
    return {
        name: {tuple(sorted(f)) for f in mesh.facets[:, facets].T.tolist()}
        for name, facets in (mesh.boundaries or {}).items()
    }


@pytest.mark.parametrize("ext", ["vtu", "msh", "vtk"])
def test_round_trip(tmp_path, ext):
    mesh = beam_mesh(cells=(6, 2, 1))
    back = load_mesh(save_mesh(mesh, tmp_path / f"beam.{ext}"))
    # Both formats store coordinates with 17 significant digits (or binary): exact.
    np.testing.assert_array_equal(back.p, mesh.p)
    np.testing.assert_array_equal(back.t, mesh.t)
    assert _triple_sets(back) == _triple_sets(mesh)
    assert sorted(back.boundaries) == ["back", "bottom", "front", "left", "right", "top"]


def test_save_is_atomic_and_overwrites(tmp_path):
    path = tmp_path / "beam.vtu"
    save_mesh(beam_mesh(cells=(2, 1, 1)), path)
    save_mesh(beam_mesh(cells=(3, 1, 1)), path)
    assert load_mesh(path).t.shape[1] == 6 * 3
    assert [p.name for p in tmp_path.iterdir()] == ["beam.vtu"]  # no temp file left
    umask = os.umask(0)
    os.umask(umask)
    # Same permissions as an ordinary open(path, "w"), not mkstemp's 0600.
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask


def test_file_with_only_triangles_is_rejected(tmp_path):
    path = tmp_path / "surface.vtu"
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    meshio.write(path, meshio.Mesh(points, [("triangle", np.array([[0, 1, 2], [0, 1, 3]]))]))
    with pytest.raises(InvalidMesh, match="triangle") as err:
        load_mesh(path)
    assert "gmsh -3" in str(err.value)


# Unit cube corners 0-7 plus an apex 8 above it; one tet on top, one hex below.
_CUBE_POINTS = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1],
     [0, 0, 2]],
    dtype=float,
)
_HEX = np.array([[0, 1, 2, 3, 4, 5, 6, 7]])
_TET = np.array([[4, 5, 7, 8]])


def test_tet_plus_hexahedron_is_rejected_not_dropped(tmp_path):
    path = tmp_path / "mixed.vtu"
    meshio.write(path, meshio.Mesh(_CUBE_POINTS, [("tetra", _TET), ("hexahedron", _HEX)]))
    with pytest.raises(InvalidMesh, match="hexahedron") as err:
        load_mesh(path)
    message = str(err.value)
    assert "1 hexahedron" in message and "1 tetra" in message
    assert "gmsh -3" in message and "TetGen" in message


def test_hexahedron_only_file_is_rejected_with_count(tmp_path):
    path = tmp_path / "hexes.vtu"
    hexes = np.vstack([_HEX, _HEX])  # two copies: the count must read 2
    meshio.write(path, meshio.Mesh(_CUBE_POINTS[:8], [("hexahedron", hexes)]))
    with pytest.raises(InvalidMesh, match="2 hexahedron") as err:
        load_mesh(path)
    assert "split the hexahedra" in str(err.value)


@pytest.mark.parametrize(
    "cell_type, cells",
    [("wedge", np.array([[0, 1, 2, 4, 5, 6]])), ("pyramid", np.array([[0, 1, 2, 3, 8]]))],
)
def test_other_volume_cells_beside_tets_are_rejected(tmp_path, cell_type, cells):
    path = tmp_path / f"{cell_type}.vtu"
    meshio.write(path, meshio.Mesh(_CUBE_POINTS, [("tetra", _TET), (cell_type, cells)]))
    with pytest.raises(InvalidMesh, match=f"1 {cell_type}"):
        load_mesh(path)


def test_tets_with_boundary_triangles_and_lines_still_load(tmp_path):
    path = tmp_path / "tet_tri_line.vtu"
    cells = [("tetra", _TET), ("triangle", np.array([[4, 5, 7]])), ("line", np.array([[4, 5]]))]
    meshio.write(path, meshio.Mesh(_CUBE_POINTS, cells))
    assert load_mesh(path).t.shape == (4, 1)


def test_missing_file(tmp_path):
    path = tmp_path / "nope.vtu"
    with pytest.raises(FileNotFoundError, match="nope.vtu"):
        load_mesh(path)


@pytest.mark.parametrize("content", [b"garbage", b'<VTKFile type="UnstructuredGrid"><Unstr'])
def test_unreadable_file_is_invalid_mesh_not_an_exit(tmp_path, content, capsys):
    # meshio prints the reader's error and calls sys.exit(1) when no reader succeeds; that
    # must reach the caller as InvalidMesh (with meshio's reason), not end the process
    path = tmp_path / "broken.vtu"
    path.write_bytes(content)
    with pytest.raises(InvalidMesh, match="could not read .*broken.vtu"):
        load_mesh(path)
    assert capsys.readouterr().out == ""  # nothing printed by the library


def test_directory_is_not_a_mesh_file(tmp_path):
    with pytest.raises(IsADirectoryError):
        load_mesh(tmp_path)


def test_unknown_extension(tmp_path):
    path = tmp_path / "beam.xyz"
    path.write_text("1 2 3\n")
    with pytest.raises(InvalidParameter, match=r"\.vtu"):
        load_mesh(path)
    with pytest.raises(InvalidParameter, match="extension"):
        save_mesh(beam_mesh(cells=(1, 1, 1)), path)


def test_inverted_file_needs_reorient(tmp_path):
    mesh = beam_mesh(cells=(2, 1, 1))
    path = tmp_path / "flipped.vtu"
    meshio.write(path, meshio.Mesh(mesh.p.T, [("tetra", mesh.t.T[:, [1, 0, 2, 3]])]))
    with pytest.raises(InvalidMesh, match="reorient"):
        load_mesh(path)
    fixed = load_mesh(path, reorient=True)
    np.testing.assert_allclose(signed_volumes(fixed), signed_volumes(mesh), rtol=0, atol=0)


def test_tetra10_is_linearized_and_gmsh_groups_become_boundaries(tmp_path, caplog):
    mesh = beam_mesh(cells=(2, 1, 1))
    n = mesh.p.shape[1]
    # Quadratic tets: corners, then 6 mid-edge nodes appended as new points.
    pairs = [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)]
    t = mesh.t.T
    mids = np.stack([(mesh.p.T[t[:, i]] + mesh.p.T[t[:, j]]) / 2 for i, j in pairs], axis=1)
    mid_points = mids.reshape(-1, 3)
    mid_index = n + np.arange(mid_points.shape[0]).reshape(-1, 6)
    points = np.vstack([mesh.p.T, mid_points])
    left = mesh.facets[:, mesh.boundaries["left"]].T
    mio = meshio.Mesh(
        points,
        [("tetra10", np.hstack([t, mid_index])), ("triangle", left)],
        cell_data={
            "gmsh:physical": [np.zeros(len(t), int), np.full(len(left), 7)],
            "gmsh:geometrical": [np.zeros(len(t), int), np.full(len(left), 7)],
        },
        field_data={"clamp": np.array([7, 2])},
    )
    path = tmp_path / "quadratic.msh"
    meshio.write(path, mio, file_format="gmsh22", binary=False)
    with caplog.at_level(logging.INFO, logger="fem_elastic.geometry.mesh_io"):
        back = load_mesh(path)
    assert "linearized" in caplog.text
    np.testing.assert_array_equal(back.p, mesh.p)  # mid-edge nodes dropped, corners kept in order
    np.testing.assert_array_equal(back.t, mesh.t)
    assert _triple_sets(back) == {"clamp": _triple_sets(mesh)["left"]}


@pytest.mark.parametrize("name, n_tets", [("beam", 480), ("blob", None)])
def test_shipped_meshes_load_and_validate(name, n_tets):
    mesh = validate_mesh(load_mesh(MESHES / f"{name}.vtu"))
    assert "bottom" in mesh.boundaries and mesh.boundaries["bottom"].size > 0
    if n_tets is not None:
        assert mesh.t.shape[1] == n_tets
    else:
        assert 1000 <= mesh.t.shape[1] <= 5000  # "a few thousand tets at most"
        # The blob rests on z = 0 and its "bottom" facets lie in a thin band above it.
        assert mesh.p[2].min() == 0.0
        z_bottom = mesh.p[2, mesh.facets[:, mesh.boundaries["bottom"]]]
        assert z_bottom.max() < 0.1 * mesh.p[2].max()
    assert (MESHES / f"{name}.vtu").stat().st_size < 300_000


# --- VTU series: write_vtu_frame, write_pvd, read_series ---------------------------------


def _write_tiny_series(run, n_frames=3):
    """A 2-tet series with known arrays; returns (times, points_ref, tets, displacements)."""
    from fem_elastic.app.vtu import write_pvd, write_vtu_frame

    mesh = beam_mesh(cells=(1, 1, 1))
    ref, tets = mesh.p.T, mesh.t.T
    (run / "frames").mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    times = np.array([0.0, 0.1, 0.30000000000000004])[:n_frames]  # not a short decimal
    disps, entries = [], []
    for i, t in enumerate(times):
        u = 1e-3 * rng.standard_normal(ref.shape)
        name = f"frames/frame_{i:06d}.vtu"
        write_vtu_frame(run / name, ref + u, tets, {"displacement": u, "velocity": 2 * u},
                        {"von_mises": np.full(len(tets), float(i)),
                         "energy_density": np.arange(len(tets)) + t})
        entries.append((t, name))
        disps.append(u)
        write_pvd(run / "series.pvd", entries)
    return times, ref, tets, np.array(disps)


def test_series_round_trip(tmp_path):
    from fem_elastic.app.vtu import read_series

    times, ref, tets, disps = _write_tiny_series(tmp_path)
    series = read_series(tmp_path)
    # float64 binary VTU and 17-digit PVD times: everything reads back bit for bit,
    # except points_ref = (ref + u) - u, exact to one rounding of the coordinates.
    np.testing.assert_array_equal(series.times, times)
    np.testing.assert_array_equal(series.tets, tets)
    np.testing.assert_array_equal(series.displacement, disps)
    np.testing.assert_array_equal(series.velocity, 2 * disps)
    np.testing.assert_allclose(series.points_ref, ref, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(series.cell_data["von_mises"][:, 0], [0.0, 1.0, 2.0])
    assert series.cell_data["energy_density"].shape == (3, len(tets))
    assert series.summary == {}
    # ParaView reads the files: a VTKFile Collection, and VTU 1.0-style UnstructuredGrid.
    root = ET.parse(tmp_path / "series.pvd").getroot()
    assert root.tag == "VTKFile" and root.get("type") == "Collection"
    assert meshio.read(tmp_path / "frames/frame_000001.vtu").points.shape == ref.shape
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frames", "series.pvd"]  # no temp files


def test_series_skips_missing_and_truncated_frames(tmp_path, caplog):
    from fem_elastic.app.vtu import read_series

    times, _, _, disps = _write_tiny_series(tmp_path)
    (tmp_path / "frames/frame_000001.vtu").unlink()
    truncated = tmp_path / "frames/frame_000002.vtu"
    truncated.write_bytes(truncated.read_bytes()[:200])
    with caplog.at_level(logging.WARNING, logger="fem_elastic.app.vtu"):
        series = read_series(tmp_path)
    np.testing.assert_array_equal(series.times, times[:1])
    np.testing.assert_array_equal(series.displacement, disps[:1])
    assert "frame_000001.vtu" in caplog.text and "missing" in caplog.text
    assert "frame_000002.vtu" in caplog.text


def test_read_series_without_pvd(tmp_path):
    from fem_elastic.app.vtu import read_series

    with pytest.raises(InvalidParameter, match="series.pvd"):
        read_series(tmp_path)
