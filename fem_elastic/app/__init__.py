"""The application: scene files, running them, their output, renders and the command line.

Holds the TOML scene format (:mod:`~fem_elastic.app.scene` and its schema),
the runner that simulates a scene's variants and writes what it asks for
(:mod:`~fem_elastic.app.runner`), the VTU series and summaries
(:mod:`~fem_elastic.app.vtu`, :mod:`~fem_elastic.app.output`), off-screen
rendering of run directories through pyvista (:mod:`~fem_elastic.app.render`;
the one-call ``result.plot()`` of a Python result is
:mod:`fem_elastic.physics.pyvista_grid`, both import pyvista inside functions),
saving Python results as run directories (:mod:`~fem_elastic.app.result_files`)
and the ``fem-elastic`` command (:mod:`~fem_elastic.app.cli`). The top layer: it
may import every layer below, and nothing below imports it.
"""

from .output import SeriesWriter, write_summary
from . import result_files  # noqa: F401  (registers traj.save and result.save)
from .scene import BuiltRun, Scene, SceneError, load_scene, parse_scene, scene_help
from .vtu import SeriesData, read_series, write_pvd, write_vtu_frame

__all__ = [
    "BuiltRun", "Scene", "SceneError", "SeriesData", "SeriesWriter", "load_scene", "parse_scene",
    "read_series", "scene_help", "write_pvd", "write_summary", "write_vtu_frame",
]
