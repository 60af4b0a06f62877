"""The results' files: VTU frames of a run and their PVD collection, written and read back.

A run directory holds ``series.pvd`` (the collection ParaView opens, with each
frame's time), ``frames/`` (one XML VTU file per recorded frame) and
``summary.json``. meshio writes and reads the frames, imported inside the
functions; every file is written atomically (:mod:`fem_elastic.files`).
"""

from __future__ import annotations

import json
import logging
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Literal
from xml.sax.saxutils import quoteattr

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InvalidParameter
from ..files import _atomic_write, write_text_atomic

__all__ = ["write_vtu_frame", "write_pvd", "read_series", "SeriesData", "vtu_units",
           "REFERENCE_POINTS"]

logger = logging.getLogger(__name__)

#: The ``units`` entry of ``"points"`` in frames whose points are the REFERENCE positions (the
#: convention of felupe, SfePy and FEniCS: ParaView's Warp By Vector on ``displacement`` gives
#: the deformed body once). Frames without it (written before) hold the deformed positions.
REFERENCE_POINTS = "m, reference position"


def write_vtu_frame(path: str | os.PathLike[str], points: ArrayLike, tets: ArrayLike,
                    point_data: Mapping[str, ArrayLike] | None = None,
                    cell_data: Mapping[str, ArrayLike] | None = None, *,
                    compression: Literal["zlib", "lzma"] | None = "zlib",
                    field_data: Mapping[str, ArrayLike] | None = None,
                    units: Mapping[str, str] | None = None) -> Path:
    """Write one frame of a series: a tet grid with point, cell and field data, as XML VTU.

    Written with meshio's VTU writer (VTK XML ``UnstructuredGrid``, binary,
    zlib-compressed by default), which ParaView, VisIt and pyvista open, and atomically.
    Linear tets are VTK cells of type 10, quadratic ones (``(m, 10)`` cells:
    the vertices, then the mid-edge nodes of edges 01, 12, 20, 03, 13, 23,
    scikit-fem's P2 order) of type 24. meshio's writer drops field data, so
    ``field_data`` and ``units`` are added to the file's ``<FieldData>``
    (ASCII arrays) here.

    Parameters
    ----------
    path : str or os.PathLike
        Destination ``.vtu`` file; its directory must exist.
    points : array_like
        ``(n, 3)`` point coordinates (m), usually the deformed positions.
    tets : array_like
        ``(m, 4)`` vertex indices of linear tets, or ``(m, 10)`` node indices of
        quadratic ones (VTK order, see above).
    point_data : dict of str to array_like, optional
        Arrays of shape ``(n,)`` or ``(n, k)``, e.g. ``"displacement"`` (m).
    cell_data : dict of str to array_like, optional
        Arrays of shape ``(m,)`` or ``(m, k)``, e.g. ``"von_mises"`` (Pa).
        NaN and inf are stored as such.
    compression : {"zlib", "lzma", None}
        Compression of the binary arrays. On a 10k-tet frame zlib halves the
        file (~0.5 MB instead of ~1.1 MB) and takes ~30 ms against ~4 ms
        without: pass None where write time matters more than disk.
    field_data : dict of str to array_like, optional
        Whole-grid values, e.g. ``{"TimeValue": [t]}`` (s: the name VTK and
        ParaView read as the time of a lone file).
    units : dict of str to str, optional
        The unit of each array, e.g. ``{"displacement": "m"}``; stored as the
        field array ``"units"``: the UTF-8 bytes (UInt8) of ``name=unit`` lines,
        read back by :func:`vtu_units` (meshio cannot read VTK string arrays).

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
    >>> from fem_elastic.app.vtu import write_vtu_frame
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
    if points.ndim != 2 or points.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] not in (4, 10):
        raise InvalidParameter(
            f"write_vtu_frame needs points (n, 3) and tets (m, 4) or (m, 10), got {points.shape} "
            f"and {tets.shape}."
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
    fdata = {name: np.atleast_1d(np.asarray(value)) for name, value in (field_data or {}).items()}
    if units:
        text = "\n".join(f"{name}={unit}" for name, unit in units.items())
        fdata["units"] = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
    cell_type = "tetra" if tets.shape[1] == 4 else "tetra10"
    mio = meshio.Mesh(points, [(cell_type, tets)], point_data=pdata, cell_data=cdata)

    def write(tmp):
        meshio.write(tmp, mio, file_format="vtu", compression=compression)
        if fdata:
            _insert_field_data(Path(tmp), fdata)

    return _atomic_write(Path(path), write)


def _insert_field_data(path: Path, fdata: dict) -> None:
    """Add ``<FieldData>`` (ASCII arrays) to a VTU file meshio wrote, which has none."""
    arrays = []
    for name, value in fdata.items():
        value = np.asarray(value).ravel()
        if value.dtype == np.uint8:
            vtk_type, text = "UInt8", " ".join(str(int(b)) for b in value)
        elif np.issubdtype(value.dtype, np.integer):
            vtk_type, text = "Int64", " ".join(str(int(b)) for b in value)
        else:
            vtk_type, text = "Float64", " ".join(repr(float(b)) for b in value)
        arrays.append(f'<DataArray type="{vtk_type}" Name={quoteattr(name)} '
                      f'NumberOfTuples="{value.size}" format="ascii">{text}</DataArray>')
    block = ("<FieldData>" + "".join(arrays) + "</FieldData>").encode("utf-8")
    data = path.read_bytes()
    tag = b"<UnstructuredGrid>"
    at = data.find(tag)
    if at < 0:  # meshio's layout changed: fail loudly rather than write a file without its time
        raise InvalidParameter(f"{path}: no <UnstructuredGrid> element to add field data to.")
    path.write_bytes(data[:at + len(tag)] + block + data[at + len(tag):])


def vtu_units(field_data: dict) -> dict:
    """The ``{array name: unit}`` of a frame's field data (``units`` of :func:`write_vtu_frame`).

    Parameters
    ----------
    field_data : dict of str to array_like
        A frame's field data as meshio or pyvista read it.

    Returns
    -------
    dict of str to str
        Empty when the frame has no ``"units"`` array (frames written before it existed).

    Examples
    --------
    >>> import numpy as np
    >>> vtu_units({"units": np.frombuffer(b"displacement=m", dtype=np.uint8)})
    {'displacement': 'm'}
    """
    raw = field_data.get("units")
    if raw is None:
        return {}
    text = bytes(np.asarray(raw, dtype=np.uint8).ravel()).decode("utf-8", errors="replace")
    return dict(line.split("=", 1) for line in text.splitlines() if "=" in line)


def write_pvd(path: str | os.PathLike[str], entries: Iterable[tuple[float, str]]) -> Path:
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
    >>> from fem_elastic.app.vtu import write_pvd
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
        (minus its displacement in frames written before the points were the
        reference ones, see :data:`REFERENCE_POINTS`).
    tets : numpy.ndarray
        ``(m, 4)`` vertex indices of the tets (the vertices of quadratic ones).
    displacement, velocity : numpy.ndarray
        ``(T, n, 3)`` vertex displacement (m) and velocity (m/s) (the mid-edge
        nodes of quadratic tets are left out).
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
        # None when missing: float(None) and Path / None raise the TypeError caught below.
        file: Any = ds.get("file")
        time: Any = ds.get("timestep")
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
    blocks = [i for i, b in enumerate(mio.cells) if b.type in ("tetra", "tetra10")]
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
    # quadratic tets: their first four nodes are the vertices, numbered before the edge nodes
    tets = np.vstack([mio.cells[i].data[:, :4] for i in blocks]).astype(np.int64)
    nv = int(tets.max()) + 1
    cells = {
        name: np.concatenate([np.asarray(value[i], dtype=np.float64).ravel() for i in blocks])
        for name, value in mio.cell_data.items()
        if all(np.asarray(value[i]).ndim == 1 for i in blocks)
    }
    pdata = {k: np.asarray(mio.point_data[k], dtype=np.float64)[:nv]
             for k in ("displacement", "velocity")}
    points = np.asarray(mio.points, dtype=np.float64)[:nv]
    if vtu_units(mio.field_data).get("points") != REFERENCE_POINTS:
        points = points - pdata["displacement"]  # an older frame: its points are deformed
    return points, tets, pdata, cells


def read_series(run_dir: str | os.PathLike[str]) -> SeriesData:
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
    >>> from fem_elastic.app.vtu import write_vtu_frame, write_pvd, read_series
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
    # Both are set together from the first frame read (and are arrays once `times` is not empty).
    points_ref: Any = None
    tets: Any = None
    for time, path in _pvd_entries(pvd):
        frame = _read_frame(path)
        if frame is None:
            continue
        points, frame_tets, pdata, cdata = frame
        if tets is None:
            tets = frame_tets
            points_ref = points
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
