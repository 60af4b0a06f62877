"""Tests of fem_elastic.geometry.mesh: beam construction, validation and repair."""

import numpy as np
import pytest
from skfem import MeshHex, MeshTet, MeshTri

from fem_elastic.errors import InvalidMesh, InvalidParameter
from fem_elastic.geometry.mesh import (
    beam_mesh,
    boundary_facets,
    mesh_from_arrays,
    mesh_quality,
    remove_unused_vertices,
    reorient,
    signed_volumes,
    validate_mesh,
)

# Unit right tetrahedron plus a second one sharing its face (0, 1, 2), below it.
POINTS = np.array(
    [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1]], dtype=float
)
TETS = np.array([[0, 1, 2, 3], [0, 2, 1, 4]])


def test_beam_counts_box_and_volume():
    L, W, H, cells = 2.0, 0.3, 0.2, (10, 3, 2)
    mesh = beam_mesh(L, W, H, cells)
    assert mesh.p.shape == (3, 11 * 4 * 3)
    assert mesh.t.shape == (4, 6 * 10 * 3 * 2)
    np.testing.assert_array_equal(mesh.p.min(axis=1), [0, 0, 0])
    # linspace endpoints are exact, so the box is too.
    np.testing.assert_array_equal(mesh.p.max(axis=1), [L, W, H])
    v = signed_volumes(mesh)
    assert np.all(v > 0)
    # Sum of 360 volumes: round-off ~ 360 * eps * L*W*H.
    assert v.sum() == pytest.approx(L * W * H, rel=1e-12)


@pytest.mark.parametrize(
    "name, axis, value, n_facets",
    [
        ("left", 0, 0.0, 2 * 3 * 2),
        ("right", 0, 2.0, 2 * 3 * 2),
        ("front", 1, 0.0, 2 * 10 * 2),
        ("back", 1, 0.3, 2 * 10 * 2),
        ("bottom", 2, 0.0, 2 * 10 * 3),
        ("top", 2, 0.2, 2 * 10 * 3),
    ],
)
def test_beam_boundaries_lie_on_their_planes(name, axis, value, n_facets):
    mesh = beam_mesh(2.0, 0.3, 0.2, (10, 3, 2))
    facets = mesh.boundaries[name]
    assert facets.size == n_facets  # each rectangle of the face is 2 triangles
    coords = mesh.p[axis, mesh.facets[:, facets]]
    np.testing.assert_array_equal(coords, value)  # grid coordinates are exact
    assert set(facets) <= set(mesh.boundary_facets())


@pytest.mark.parametrize(
    "kwargs, word",
    [
        ({"length": 0.0}, "length"),
        ({"width": -1.0}, "width"),
        ({"height": float("nan")}, "height"),
        ({"length": float("inf")}, "length"),
        ({"cells": (0, 2, 2)}, "cells"),
        ({"cells": (2.5, 2, 2)}, "cells"),
        ({"cells": (2, 2)}, "cells"),
    ],
)
def test_beam_rejects_bad_arguments(kwargs, word):
    with pytest.raises(InvalidParameter, match=word):
        beam_mesh(**kwargs)


def test_good_mesh_passes_and_is_returned():
    mesh = mesh_from_arrays(POINTS, TETS)
    assert validate_mesh(mesh) is mesh


def test_flat_tet_is_degenerate():
    points = POINTS.copy()
    points[4] = [0.3, 0.3, 0.0]  # in the plane of face (0, 1, 2): volume exactly 0
    with pytest.raises(InvalidMesh, match="zero volume") as err:
        mesh_from_arrays(points, TETS)
    np.testing.assert_array_equal(err.value.elements, [1])
    assert "[1]" in str(err.value)


def test_inverted_tet_is_reported_with_fix():
    tets = TETS.copy()
    tets[1] = tets[1, [1, 0, 2, 3]]
    with pytest.raises(InvalidMesh, match="inverted") as err:
        mesh_from_arrays(POINTS, tets)
    np.testing.assert_array_equal(err.value.elements, [1])
    assert "reorient" in str(err.value)


def test_nan_coordinate_names_the_vertex():
    points = POINTS.copy()
    points[3, 2] = np.nan
    with pytest.raises(InvalidMesh, match="NaN") as err:
        mesh_from_arrays(points, TETS)
    np.testing.assert_array_equal(err.value.elements, [3])
    # the same check runs on an already built skfem mesh
    with pytest.raises(InvalidMesh, match="NaN"):
        validate_mesh(MeshTet(points.T, TETS.T))


def test_unused_vertex_is_reported_with_fix():
    points = np.vstack([POINTS, [[5.0, 5.0, 5.0]]])
    with pytest.raises(InvalidMesh, match="not used") as err:
        mesh_from_arrays(points, TETS)
    np.testing.assert_array_equal(err.value.elements, [5])
    assert "remove_unused_vertices" in str(err.value)


def test_out_of_range_index_is_caught_before_skfem():
    tets = TETS.copy()
    tets[1, 3] = 7  # only 5 points; MeshTet(p, t) itself would accept this
    with pytest.raises(InvalidMesh, match="outside") as err:
        mesh_from_arrays(POINTS, tets)
    np.testing.assert_array_equal(err.value.elements, [1])
    with pytest.raises(InvalidMesh, match="outside"):
        validate_mesh(MeshTet(POINTS.T, tets.T))


def test_2d_points_are_rejected():
    with pytest.raises(InvalidMesh, match="3"):
        mesh_from_arrays(POINTS[:, :2], TETS)


@pytest.mark.parametrize("mesh", [MeshHex(), MeshTri()], ids=["hex", "tri"])
def test_non_tet_mesh_is_rejected(mesh):
    with pytest.raises(InvalidMesh, match="MeshTet"):
        validate_mesh(mesh)


def test_many_offenders_are_listed_up_to_ten():
    mesh = MeshTet.init_tensor(*(np.linspace(0, 1, 4),) * 3)
    with pytest.raises(InvalidMesh) as err:
        validate_mesh(mesh)
    n_negative = int(np.sum(signed_volumes(mesh) < 0))
    assert n_negative > 10  # init_tensor gives mixed orientations
    assert len(err.value.elements) == n_negative
    assert f"({n_negative} in all)" in str(err.value)


def test_reorient_fixes_inverted_tets_and_keeps_boundaries():
    beam = beam_mesh(cells=(4, 2, 2))
    flipped = MeshTet(beam.p, beam.t[[1, 0, 2, 3]]).with_boundaries(
        {k: v for k, v in beam.boundaries.items()}
    )
    assert np.all(signed_volumes(flipped) < 0)
    fixed = reorient(flipped)
    validate_mesh(fixed)
    np.testing.assert_allclose(signed_volumes(fixed), -signed_volumes(flipped), rtol=0, atol=0)
    for name, facets in beam.boundaries.items():
        assert _triples(fixed, fixed.boundaries[name]) == _triples(beam, facets)


def test_remove_unused_vertices_keeps_boundaries():
    points = np.vstack([[[9.0, 9.0, 9.0]], POINTS])  # unused vertex first: all indices shift
    mesh = mesh_from_arrays(points, TETS + 1, {"base": [[1, 2, 4]]}, validate=False)
    clean = remove_unused_vertices(mesh)
    validate_mesh(clean)
    np.testing.assert_array_equal(clean.p, POINTS.T)
    np.testing.assert_array_equal(clean.t, TETS.T)
    assert _triples(clean, clean.boundaries["base"]) == {(0, 1, 3)}


def test_boundary_triangle_not_a_face_is_rejected():
    with pytest.raises(InvalidMesh, match="not faces"):
        mesh_from_arrays(POINTS, TETS, {"bad": [[1, 3, 4]]})


def test_mesh_quality_of_regular_tet_is_one():
    # Regular tetrahedron: alternate corners of a cube.
    points = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)
    mesh = mesh_from_arrays(points, [[0, 1, 2, 3]], reorient=True)
    q = mesh_quality(mesh)
    assert q["min_quality"] == pytest.approx(1.0, rel=1e-12)  # round-off only
    assert q["volume"] == pytest.approx(8.0 / 3.0, rel=1e-12)  # cube 8 minus 4 corners of 4/3
    assert q["n_inverted"] == 0
    assert q["bounding_box"] == ([-1, -1, -1], [1, 1, 1])


def test_mesh_quality_reports_beam():
    q = mesh_quality(beam_mesh())
    assert (q["n_vertices"], q["n_elements"]) == (21 * 3 * 3, 480)
    assert q["boundaries"]["left"] == 8
    assert 0 < q["min_quality"] <= q["mean_quality"] < 1


def _triples(mesh, facets):
    return {tuple(sorted(f)) for f in mesh.facets[:, facets].T.tolist()}


def test_boundary_facets_returns_named_facets():
    mesh = beam_mesh()
    facets = boundary_facets(mesh, "left", what="Support")
    np.testing.assert_array_equal(facets, mesh.boundaries["left"])


def test_boundary_facets_unknown_name_lists_boundaries():
    mesh = beam_mesh()
    with pytest.raises(InvalidParameter) as err:
        boundary_facets(mesh, "lefft", what="Load 'push'")
    assert str(err.value) == (
        "Load 'push' names boundary 'lefft', which the mesh does not have; its boundaries "
        "are ['back', 'bottom', 'front', 'left', 'right', 'top']."
    )


def test_boundary_facets_without_boundaries_and_empty_boundary():
    mesh = MeshTet(POINTS.T, TETS.T)
    with pytest.raises(InvalidParameter, match=r"boundaries are \[\]"):
        boundary_facets(mesh, "left", what="Support")
    empty = beam_mesh().with_boundaries({"hole": np.array([], dtype=np.int64)})
    with pytest.raises(InvalidParameter, match="'hole'.*empty \\(no facets\\)"):
        boundary_facets(empty, "hole", what="Support")


def test_a_very_short_edge_is_not_a_crack_but_coincident_vertices_are():
    from fem_elastic import mesh_from_arrays

    # two tets on a shared face; the second's apex is 0.87e-9 m off the face's vertex (1, 0, 0),
    # below the coincidence tolerance (1e-9 of the diameter, 1.7e-9 m) but an edge of that tet:
    # the vertices are connected through it (its volume, 3e-9 of the mean, passes the
    # degenerate check at 1e-10)
    eps = 5e-10
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1 + eps, eps, eps]], dtype=float)
    t = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    mesh = mesh_from_arrays(p, t, reorient=True)
    assert validate_mesh(mesh) is mesh
    # the same two points as two copies of one vertex in tets that do not share them: a crack
    p2 = np.vstack([p[:4], [[1, 1, 1]], p[1:2]])  # vertex 5 duplicates vertex 1
    t2 = np.array([[0, 1, 2, 3], [5, 2, 3, 4]])
    with pytest.raises(InvalidMesh, match=r"1 pair\(s\) of vertices coincide"):
        mesh_from_arrays(p2, t2, reorient=True)


def test_beam_mesh_facets_are_those_scikit_fem_builds():
    # beam_mesh hands its named copy the facets it built to name the faces (scikit-fem drops
    # them with the copy): they must be what scikit-fem builds for the same tets
    mesh = beam_mesh(0.7, 0.3, 0.2, (5, 2, 3))
    fresh = MeshTet(mesh.p.copy(), mesh.t.copy())
    np.testing.assert_array_equal(mesh.facets, fresh.facets)
    np.testing.assert_array_equal(mesh.t2f, fresh.t2f)
    np.testing.assert_array_equal(mesh.boundary_facets(), fresh.boundary_facets())
