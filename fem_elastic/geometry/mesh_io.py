"""Reading and writing tet meshes through meshio.

meshio is imported inside the functions (here and in :mod:`fem_elastic.app.vtu`,
the results' files), so ``import fem_elastic`` works without meshio installed.
Every file is written atomically (:mod:`fem_elastic.files`): a crash or Ctrl-C
leaves either the old file or the new one, never half of one.

Named boundaries travel with the file:

- formats with cell data (``.vtu``, ``.vtk``, ``.xdmf``) store them the way
  scikit-fem does (``skfem.io.meshio.to_meshio``): one integer per tet named
  ``skfem:b:<name>`` whose bits flag the tet's faces on that boundary;
- gmsh ``.msh`` files store them as boundary triangles in physical groups
  (gmsh's own convention, which gmsh and other tools read), because meshio's
  gmsh writer drops other cell data.

On reading, physical groups of triangles, meshio cell sets of triangles and
skfem's encoding are all turned into named boundaries.
"""

from __future__ import annotations

import errno
import logging
import os
from pathlib import Path

import numpy as np

from ..errors import InvalidMesh, InvalidParameter
from ..files import _atomic_write
from .mesh import MeshTet, MeshTet2, _boundary_triples, _check_arrays, _from_arrays

__all__ = ["load_mesh", "save_mesh"]

logger = logging.getLogger(__name__)

# Formats whose boundaries survive save_mesh -> load_mesh.
_BOUNDARY_FORMATS = {"vtu", "vtk", "xdmf", "gmsh", "gmsh22"}


def _file_format(path: Path) -> tuple[str, str, str]:
    """Return (extension, format to read/write, format meshio lists first) of ``path``.

    The two formats differ only for ``.msh``: meshio lists ansys before gmsh, but
    gmsh is what ``.msh`` almost always means. Raise InvalidParameter for an
    extension meshio does not know.
    """
    import meshio

    table = meshio.extension_to_filetypes
    name = path.name.lower()
    matches = [ext for ext in table if name.endswith(ext)]
    if not matches:
        raise InvalidParameter(
            f"Unknown mesh file extension for path {str(path)!r}. meshio reads and writes "
            f"{', '.join(sorted(table))}; use .vtu (or gmsh's .msh) for tet meshes."
        )
    ext = max(matches, key=len)
    listed_first = table[ext][0]
    return ext, "gmsh" if ext == ".msh" else listed_first, listed_first


def _triples_from_skfem_data(mio, tet_blocks, points, tets) -> dict[str, np.ndarray]:
    """Decode skfem's ``skfem:b:<name>`` cell data with skfem itself."""
    import meshio
    from skfem.io.meshio import from_meshio

    data = {
        key: [np.concatenate([np.asarray(value[i]) for i in tet_blocks])]
        for key, value in mio.cell_data.items()
        if key.startswith("skfem:b:")
    }
    if not data:
        return {}
    decoded = from_meshio(meshio.Mesh(points, [("tetra", tets)], cell_data=data))
    return _boundary_triples(decoded)


def _triples_from_triangles(mio) -> dict[str, list[np.ndarray]]:
    """Named triangle sets: gmsh physical groups and meshio cell sets."""
    found: dict[str, list[np.ndarray]] = {}
    tri_blocks = [i for i, b in enumerate(mio.cells) if b.type in ("triangle", "triangle6")]
    if not tri_blocks:
        return found

    names = {}
    for name, value in (mio.field_data or {}).items():
        value = np.ravel(value)
        if value.size >= 2 and value[1] == 2:  # (tag, dimension); dimension 2 = surfaces
            names[int(value[0])] = name
    physical = mio.cell_data.get("gmsh:physical")
    if physical is not None:
        for i in tri_blocks:
            tags = np.asarray(physical[i]).ravel()
            triangles = mio.cells[i].data[:, :3]
            for tag in np.unique(tags):
                name = names.get(int(tag), str(int(tag)))
                found.setdefault(name, []).append(triangles[tags == tag])

    for name, per_block in (mio.cell_sets or {}).items():
        if name.startswith("gmsh:"):
            continue
        for i in tri_blocks:
            if i < len(per_block) and per_block[i] is not None and len(per_block[i]):
                found.setdefault(name, []).append(mio.cells[i].data[np.asarray(per_block[i]), :3])
    return found


def load_mesh(path: str | os.PathLike[str], *, reorient: bool = False,
              validate: bool = True) -> MeshTet:
    """Read a tetrahedral mesh from any file format meshio reads.

    The "tetra" cells form the mesh. Quadratic "tetra10" cells are reduced to
    their 4 corners (the geometry is linearized and an INFO message logged).
    Any other volume cell (hexahedron, wedge, pyramid, ...) is an error rather
    than being dropped. Lower-dimensional cells (triangles, lines, vertices) are
    ignored, except named or tagged boundary triangles
    (gmsh physical groups, meshio cell sets, or what :func:`save_mesh` wrote),
    which become named boundaries. Vertices used by no tet (gmsh geometry
    points, the mid-edge nodes of tetra10) are dropped, so vertex numbering may
    differ from the file's.

    Parameters
    ----------
    path : str or os.PathLike
        Mesh file (``.vtu``, ``.msh``, ``.mesh``, ``.xdmf``, ...). Coordinates
        are taken to be in m.
    reorient : bool, optional
        Swap two vertices of every negatively oriented tet, for files written
        with the opposite orientation convention.
    validate : bool, optional
        Run :func:`fem_elastic.geometry.mesh.validate_mesh` on the result.

    Returns
    -------
    skfem.MeshTet
        The mesh, with named boundaries as skfem facet-index arrays.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist. The built-in error is used (not a
        FemElasticError) because it is what every Python caller expects for a
        missing file, and it carries ``filename``.
    InvalidParameter
        The extension is not one meshio knows.
    InvalidMesh
        The file has no tetrahedra, holds non-tetrahedral volume cells
        (hexahedra, wedges, pyramids, ...), cannot be parsed, or fails validation.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> import fem_elastic.geometry.mesh as fm
    >>> from fem_elastic.geometry.mesh_io import load_mesh, save_mesh
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     mesh = load_mesh(save_mesh(fm.beam_mesh(), pathlib.Path(tmp) / "beam.vtu"))
    >>> mesh.t.shape, mesh.boundaries["left"].size
    ((4, 480), 8)
    """
    import meshio

    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, "Is a directory, not a mesh file", str(path))
    if not path.is_file():
        raise FileNotFoundError(errno.ENOENT, "Mesh file not found", str(path))
    _, file_format, listed_first = _file_format(path)  # unknown extension -> InvalidParameter
    try:
        mio = _meshio_read(meshio, path, file_format)
    except meshio.ReadError:
        if file_format == listed_first:
            raise InvalidMesh(f"meshio could not read {str(path)!r} as {file_format}: "
                              f"{_READ_FAILURES.pop(path, 'unknown reason')}. Check that it is a "
                              "tet mesh in that format (re-export it, e.g. with gmsh or "
                              "fe.save_mesh).") from None
        try:
            mio = _meshio_read(meshio, path, None)  # e.g. an ANSYS .msh: try every candidate
        except meshio.ReadError:
            raise InvalidMesh(f"meshio could not read {str(path)!r} in any format of its "
                              f"extension: {_READ_FAILURES.pop(path, 'unknown reason')}. Check "
                              "that it is a tet mesh file.") from None

    types = [block.type for block in mio.cells]
    linear = [i for i, t in enumerate(types) if t == "tetra"]
    quadratic = [i for i, t in enumerate(types) if t == "tetra10"]
    counts: dict[str, int] = {}
    other_volume: list[str] = []
    for block in mio.cells:
        counts[block.type] = counts.get(block.type, 0) + len(block.data)
        dim = getattr(block, "dim", None)
        if dim is None:
            dim = meshio.topological_dimension.get(block.type, 0)
        if dim == 3 and block.type not in ("tetra", "tetra10", *other_volume):
            other_volume.append(block.type)
    if other_volume:
        found = ", ".join(f"{n} {t}" for t, n in sorted(counts.items()))
        raise InvalidMesh(
            f"{str(path)!r} holds non-tetrahedral volume cells "
            f"({', '.join(sorted(other_volume))}); cells found: {found}. fem_elastic "
            "solves on tet meshes only: tetrahedralize the volume (e.g. gmsh -3 or "
            "TetGen), or split the hexahedra (wedges, pyramids) into tets, and export "
            "tetra cells only."
        )
    if not linear and not quadratic:
        raise InvalidMesh(
            f"{str(path)!r} holds no tetrahedra (cell types found: "
            f"{sorted(set(types)) or 'none'}). A volume tet mesh is needed: mesh the "
            "surface with gmsh -3 or TetGen, or split hexahedra into tets."
        )
    if linear and quadratic:
        raise InvalidMesh(
            f"{str(path)!r} mixes linear (tetra) and quadratic (tetra10) tets; export "
            "one kind only."
        )
    if quadratic:
        logger.info(
            "%s: quadratic tetra10 cells reduced to their corners (geometry linearized).", path
        )
    blocks = linear or quadratic
    points, tets = _check_arrays(
        mio.points, np.vstack([mio.cells[i].data[:, :4] for i in blocks])
    )

    triples = {k: [v] for k, v in _triples_from_skfem_data(mio, blocks, points, tets).items()}
    for name, parts in _triples_from_triangles(mio).items():
        triples.setdefault(name, []).extend(parts)

    used, tets = np.unique(tets, return_inverse=True)
    tets = tets.reshape(-1, 4)
    if used.size < points.shape[0]:
        logger.info("%s: dropped %d vertices used by no tet.", path, points.shape[0] - used.size)
    old_to_new = np.full(points.shape[0], -1, dtype=np.int64)
    old_to_new[used] = np.arange(used.size)
    boundaries = {k: old_to_new[np.vstack(v).astype(np.int64)] for k, v in triples.items()}

    return _from_arrays(
        points[used], tets, boundaries, reorient=reorient, validate=validate, missing="warn"
    )


def _gmsh_meshio(mesh: MeshTet):
    """meshio.Mesh with tets plus one physical group of triangles per boundary."""
    import meshio

    cells = [("tetra", mesh.t.T)]
    physical = [np.zeros(mesh.t.shape[1], dtype=np.int32)]
    field_data = {}
    for tag, (name, facets) in enumerate(sorted((mesh.boundaries or {}).items()), start=1):
        facets = np.asarray(facets)
        cells.append(("triangle", mesh.facets[:, facets].T))
        physical.append(np.full(facets.size, tag, dtype=np.int32))
        field_data[name] = np.array([tag, 2])
    cell_data = {"gmsh:physical": physical, "gmsh:geometrical": [p.copy() for p in physical]}
    return meshio.Mesh(mesh.p.T, cells, cell_data=cell_data, field_data=field_data)


_READ_FAILURES: dict = {}  # path -> why its last _meshio_read failed


def _meshio_read(meshio, path: Path, file_format):
    """``meshio.read``, with every failure turned into ``meshio.ReadError``.

    When no reader succeeds, meshio prints the reader's error to stdout and
    calls ``sys.exit(1)``; a reader may also raise anything a malformed file
    provokes (XML, zlib, struct, value errors). Both would end the caller's
    process or escape as an untyped error, so they are caught here, the
    printed text is kept, and the reason is left in ``_READ_FAILURES[path]``.
    """
    import contextlib
    import io as _io

    printed = _io.StringIO()
    try:
        with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(printed):
            return meshio.read(path, file_format=file_format)
    except SystemExit:
        reason = printed.getvalue().replace("Error:", "").strip() or "not readable"
    except meshio.ReadError as err:
        reason = str(err)
    except Exception as err:  # a malformed file: ParseError, zlib.error, ValueError, ...
        reason = f"{type(err).__name__}: {err}"
    _READ_FAILURES[path] = " ".join(reason.split())
    raise meshio.ReadError(_READ_FAILURES[path])


def save_mesh(mesh: MeshTet, path: str | os.PathLike[str]) -> Path:
    """Write a tet mesh, with its named boundaries, atomically.

    The file is written to a temporary file in the same directory and then
    moved over ``path``, so a crash never leaves a half-written mesh.

    Parameters
    ----------
    mesh : skfem.MeshTet
        Linear tet mesh (points in m).
    path : str or os.PathLike
        Destination; the format follows the extension. Boundaries survive a
        round trip for ``.vtu``, ``.vtk``, ``.msh`` and ``.xdmf`` (which needs h5py); other
        formats keep points and tets only (a warning is logged).

    Returns
    -------
    pathlib.Path
        ``path``, so that ``load_mesh(save_mesh(mesh, path))`` works.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> import fem_elastic.geometry.mesh as fm
    >>> from fem_elastic.geometry.mesh_io import save_mesh
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     print(save_mesh(fm.beam_mesh(), pathlib.Path(tmp) / "beam.msh").name)
    beam.msh
    """
    import meshio
    from skfem.io.meshio import to_meshio

    if isinstance(mesh, MeshTet2) or not isinstance(mesh, MeshTet):
        raise InvalidMesh(
            f"save_mesh writes linear tet meshes (skfem.MeshTet), got {type(mesh).__name__}."
        )
    path = Path(path)
    _, file_format, _ = _file_format(path)
    options = {}
    if file_format.startswith("gmsh"):
        mio = _gmsh_meshio(mesh)
        # MSH 2.2 text: read by every gmsh version and tool, and it needs no gmsh
        # entity (dim_tags) bookkeeping to hold tets and triangles together.
        file_format = "gmsh22"
        options["binary"] = False
    else:
        mio = to_meshio(mesh, encode_cell_data=file_format in _BOUNDARY_FORMATS)
    if mesh.boundaries and file_format not in _BOUNDARY_FORMATS:
        logger.warning("%s: format %s does not keep named boundaries.", path, file_format)

    return _atomic_write(
        path, lambda tmp: meshio.write(tmp, mio, file_format=file_format, **options)
    )
