"""Reading and writing tet meshes and VTU time series through meshio.

This is the only module that imports meshio, and it does so inside the
functions, so ``import fem_elastic`` works without meshio installed.
Every file is written atomically (a temporary file in the same directory,
flushed and fsync'ed, then ``os.replace``): a crash or Ctrl-C leaves either
the old file or the new one, never half of one.

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
import json
import logging
import os
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from .errors import InvalidMesh, InvalidParameter
from .mesh import MeshTet, MeshTet2, _boundary_triples, _check_arrays, _from_arrays

__all__ = [
    "load_mesh", "save_mesh", "write_vtu_frame", "write_pvd", "read_series", "SeriesData",
    "write_text_atomic",
]

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


def load_mesh(path, *, reorient: bool = False, validate: bool = True) -> MeshTet:
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
        Run :func:`fem_elastic.mesh.validate_mesh` on the result.

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
    >>> import fem_elastic.mesh as fm
    >>> from fem_elastic.io import load_mesh, save_mesh
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
    other_volume = []
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


def _new_file_mode(path: Path) -> int:
    """Mode a plain ``open(path, "w")`` would give: the old file's, else 0666 & ~umask."""
    if path.exists():
        return path.stat().st_mode & 0o777
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


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


def save_mesh(mesh: MeshTet, path) -> Path:
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
    >>> import fem_elastic.mesh as fm
    >>> from fem_elastic.io import save_mesh
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


# --- atomic files ------------------------------------------------------------------------


def _fsync_directory(directory: Path) -> None:
    """Make a rename in ``directory`` durable (POSIX; a no-op where unsupported)."""
    try:
        fd = os.open(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _atomic_write(path: Path, write) -> Path:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then move it over ``path``.

    The temporary file is fsync'ed before ``os.replace`` so that the rename
    never exposes a file whose bytes are not on disk yet; on any error
    (KeyboardInterrupt included) it is removed and ``path`` is left as it was.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        with open(tmp, "rb+") as fh:
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, _new_file_mode(path))  # mkstemp makes it owner-only (0600)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    _fsync_directory(path.parent)
    return path


def write_text_atomic(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Destination; its directory must exist.
    text : str

    Returns
    -------
    pathlib.Path
        ``path``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from fem_elastic.io import write_text_atomic
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     print(write_text_atomic(pathlib.Path(tmp) / "a.txt", "hi").read_text())
    hi
    """

    def write(tmp):
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)

    return _atomic_write(Path(path), write)


# --- VTU frames and the PVD collection ----------------------------------------------------


def write_vtu_frame(path, points, tets, point_data=None, cell_data=None, *,
                    compression: str | None = "zlib") -> Path:
    """Write one frame of a series: a tet grid with point and cell data, as XML VTU.

    Written with meshio's VTU writer (VTK XML ``UnstructuredGrid``, binary,
    zlib-compressed by default), which ParaView, VisIt and pyvista open, and atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Destination ``.vtu`` file; its directory must exist.
    points : array_like
        ``(n, 3)`` point coordinates (m), usually the deformed positions.
    tets : array_like
        ``(m, 4)`` vertex indices of the linear tets.
    point_data : dict of str to array_like, optional
        Arrays of shape ``(n,)`` or ``(n, k)``, e.g. ``"displacement"`` (m).
    cell_data : dict of str to array_like, optional
        Arrays of shape ``(m,)`` or ``(m, k)``, e.g. ``"von_mises"`` (Pa).
        NaN and inf are stored as such.
    compression : {"zlib", "lzma", None}
        Compression of the binary arrays. On a 10k-tet frame zlib halves the
        file (~0.5 MB instead of ~1.1 MB) and takes ~30 ms against ~4 ms
        without: pass None where write time matters more than disk.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    InvalidParameter
        An array's leading dimension does not match the points or tets, or
        ``compression`` is not one of the above.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> import numpy as np
    >>> import meshio
    >>> from fem_elastic.io import write_vtu_frame
    >>> pts = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     f = write_vtu_frame(pathlib.Path(tmp) / "f.vtu", pts, [[0, 1, 2, 3]],
    ...                         {"displacement": np.zeros((4, 3))}, {"von_mises": [1.5]})
    ...     print(meshio.read(f).cell_data["von_mises"][0])
    [1.5]
    """
    import meshio

    points = np.ascontiguousarray(points, dtype=np.float64)
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    if points.ndim != 2 or points.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] != 4:
        raise InvalidParameter(
            f"write_vtu_frame needs points (n, 3) and tets (m, 4), got {points.shape} and "
            f"{tets.shape}."
        )
    pdata = {}
    for name, value in (point_data or {}).items():
        value = np.ascontiguousarray(value, dtype=np.float64)
        if value.shape[:1] != (points.shape[0],):
            raise InvalidParameter(
                f"point_data[{name!r}] has shape {value.shape}; it needs one row per point "
                f"({points.shape[0]})."
            )
        pdata[name] = value
    cdata = {}
    for name, value in (cell_data or {}).items():
        value = np.ascontiguousarray(value, dtype=np.float64)
        if value.shape[:1] != (tets.shape[0],):
            raise InvalidParameter(
                f"cell_data[{name!r}] has shape {value.shape}; it needs one row per tet "
                f"({tets.shape[0]})."
            )
        cdata[name] = [value]
    if compression not in ("zlib", "lzma", None):
        raise InvalidParameter(
            f"compression must be 'zlib', 'lzma' or None, got {compression!r}."
        )
    mio = meshio.Mesh(points, [("tetra", tets)], point_data=pdata, cell_data=cdata)
    return _atomic_write(
        Path(path),
        lambda tmp: meshio.write(tmp, mio, file_format="vtu", compression=compression),
    )


def write_pvd(path, entries) -> Path:
    """Write a ParaView collection (``.pvd``) listing the frames of a series with their times.

    Parameters
    ----------
    path : str or os.PathLike
        Destination ``.pvd`` file.
    entries : iterable of (float, str)
        ``(time, file)`` pairs: time in s, file relative to the ``.pvd``'s
        directory (e.g. ``"frames/frame_000000.vtu"``). Times are written
        with 17 significant digits, so they read back exactly.

    Returns
    -------
    pathlib.Path
        ``path``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from fem_elastic.io import write_pvd
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     text = write_pvd(pathlib.Path(tmp) / "s.pvd", [(0.0, "frames/f0.vtu")]).read_text()
    >>> 'timestep="0"' in text and 'file="frames/f0.vtu"' in text
    True
    """
    lines = [
        '<?xml version="1.0"?>',
        '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
        "  <Collection>",
    ]
    for time, file in entries:
        time = float(time)
        lines.append(
            f'    <DataSet timestep="{time:.17g}" group="" part="0" '
            f"file={quoteattr(Path(file).as_posix())}/>"
        )
    lines += ["  </Collection>", "</VTKFile>", ""]
    return write_text_atomic(path, "\n".join(lines))


@dataclass
class SeriesData:
    """A VTU time series read back by :func:`read_series`.

    Attributes
    ----------
    times : numpy.ndarray
        ``(T,)`` frame times (s), in the PVD's order.
    points_ref : numpy.ndarray
        ``(n, 3)`` reference vertex positions (m): the first frame's points
        minus its displacement.
    tets : numpy.ndarray
        ``(m, 4)`` vertex indices of the tets.
    displacement, velocity : numpy.ndarray
        ``(T, n, 3)`` vertex displacement (m) and velocity (m/s).
    cell_data : dict of str to numpy.ndarray
        ``(T, m)`` per-tet fields present in every frame read, e.g.
        ``"von_mises"`` (Pa) and ``"energy_density"`` (J/m^3).
    summary : dict
        The run's ``summary.json``, or ``{}`` when there is none (yet).
    files : list of pathlib.Path
        The frame files read, one per time.
    """

    times: np.ndarray
    points_ref: np.ndarray
    tets: np.ndarray
    displacement: np.ndarray
    velocity: np.ndarray
    cell_data: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)
    files: list = field(default_factory=list)

    @property
    def points(self) -> np.ndarray:
        """``(T, n, 3)`` deformed vertex positions (m)."""
        return self.points_ref[None] + self.displacement


def _pvd_entries(pvd: Path) -> list[tuple[float, Path]]:
    try:
        root = ET.parse(pvd).getroot()
    except (ET.ParseError, OSError) as err:
        raise InvalidParameter(
            f"{str(pvd)!r} is not a readable ParaView collection ({err}); it is written "
            "atomically by fem_elastic, so it was made or changed by something else: "
            "rerun the simulation to rewrite it."
        ) from err
    entries = []
    for ds in root.iter("DataSet"):
        file, time = ds.get("file"), ds.get("timestep")
        try:
            entries.append((float(time), pvd.parent / file))
        except (TypeError, ValueError):
            logger.warning("%s: skipping a DataSet without a valid file and timestep", pvd)
    return entries


def _read_frame(path: Path):
    """(points, tets, point_data, cell_data) of one frame, or None with a warning."""
    import meshio

    if not path.is_file():
        logger.warning("%s: frame listed in the series but missing; skipped", path)
        return None
    try:
        # meshio's VTU reader itself: meshio.read(..., file_format=...) calls sys.exit
        # when the reader fails.
        mio = meshio.vtu.read(path)
    except Exception as err:  # meshio raises ReadError, ParseError, zlib.error, ValueError...
        logger.warning("%s: frame could not be read (%s: %s); skipped", path,
                       type(err).__name__, err)
        return None
    blocks = [i for i, b in enumerate(mio.cells) if b.type == "tetra"]
    n = mio.points.shape[0]
    problems = []
    if not blocks:
        problems.append("no tetra cells")
    for name in ("displacement", "velocity"):
        value = mio.point_data.get(name)
        if value is None or np.shape(value) != (n, 3):
            problems.append(f"no (n, 3) point data {name!r}")
    if problems:
        logger.warning("%s: incomplete frame (%s); skipped", path, ", ".join(problems))
        return None
    tets = np.vstack([mio.cells[i].data for i in blocks]).astype(np.int64)
    cells = {
        name: np.concatenate([np.asarray(value[i], dtype=np.float64).ravel() for i in blocks])
        for name, value in mio.cell_data.items()
        if all(np.asarray(value[i]).ndim == 1 for i in blocks)
    }
    pdata = {k: np.asarray(mio.point_data[k], dtype=np.float64)
             for k in ("displacement", "velocity")}
    return np.asarray(mio.points, dtype=np.float64), tets, pdata, cells


def read_series(run_dir) -> SeriesData:
    """Read a run directory's VTU series (``series.pvd``, ``frames/``, ``summary.json``).

    Only frames that the PVD lists, that exist and that read back complete
    (tets, ``displacement`` and ``velocity``, the same grid as the first
    frame) are returned; any other is skipped with a logged warning, so a
    run interrupted mid-write still reads back up to its last whole frame.

    Parameters
    ----------
    run_dir : str or os.PathLike
        Directory holding ``series.pvd``.

    Returns
    -------
    SeriesData

    Raises
    ------
    InvalidParameter
        ``run_dir`` has no ``series.pvd``, the PVD cannot be parsed, or none
        of its frames can be read.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> import numpy as np
    >>> from fem_elastic.io import write_vtu_frame, write_pvd, read_series
    >>> pts = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> zero = {"displacement": np.zeros((4, 3)), "velocity": np.zeros((4, 3))}
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     run = pathlib.Path(tmp)
    ...     _ = write_vtu_frame(run / "f0.vtu", pts, [[0, 1, 2, 3]], zero, {"von_mises": [0.0]})
    ...     _ = write_pvd(run / "series.pvd", [(0.0, "f0.vtu")])
    ...     series = read_series(run)
    >>> series.times, series.displacement.shape, series.cell_data["von_mises"].shape
    (array([0.]), (1, 4, 3), (1, 1))
    """
    run_dir = Path(run_dir)
    pvd = run_dir / "series.pvd"
    if not pvd.is_file():
        raise InvalidParameter(
            f"{str(run_dir)!r} holds no series.pvd, so it is not a fem_elastic run directory "
            "(or the run wrote no frame yet). Pass the directory given to --out / "
            "SeriesWriter, the one that contains series.pvd."
        )
    times, disp, vel, cells, files = [], [], [], [], []
    points_ref = tets = None
    for time, path in _pvd_entries(pvd):
        frame = _read_frame(path)
        if frame is None:
            continue
        points, frame_tets, pdata, cdata = frame
        if tets is None:
            tets = frame_tets
            points_ref = points - pdata["displacement"]
        elif not np.array_equal(frame_tets, tets) or points.shape != points_ref.shape:
            logger.warning("%s: frame has a different grid from the first frame; skipped", path)
            continue
        times.append(time)
        disp.append(pdata["displacement"])
        vel.append(pdata["velocity"])
        cells.append(cdata)
        files.append(path)
    if not times:
        raise InvalidParameter(
            f"none of the frames listed in {str(pvd)!r} could be read (see the warnings "
            "logged above): the run stopped before writing a whole frame; rerun it."
        )
    names = [k for k in cells[0] if all(k in c and c[k].shape == cells[0][k].shape for c in cells)]
    summary = {}
    summary_path = run_dir / "summary.json"
    if summary_path.is_file():
        try:
            summary = json.loads(summary_path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as err:
            logger.warning("%s: could not be read (%s); summary left empty", summary_path, err)
    return SeriesData(
        times=np.array(times, dtype=np.float64),
        points_ref=points_ref,
        tets=tets,
        displacement=np.stack(disp),
        velocity=np.stack(vel),
        cell_data={k: np.stack([c[k] for c in cells]) for k in names},
        summary=summary,
        files=files,
    )
