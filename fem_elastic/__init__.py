"""fem_elastic: elastic solids with the finite element method, built on scikit-fem.

The public surface (see ``DESIGN.md``)::

    import fem_elastic as fe
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(20, 2, 2))
    model = fe.Model(mesh, density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.45), order=2),
                     fixed="left", gravity=(0.0, 0.0, -9.81))
    static = fe.solve_static(model)

``import fem_elastic`` needs only numpy, scipy and scikit-fem: meshio is
imported inside the I/O functions, pyamg inside the AMG solver.
"""

from . import study
from .analytic import RectangularCantilever, elastica_tip
from .checkpoint import Checkpoint, load_checkpoint
from .contact import Box, Ground, Obstacle, Sphere
from .damping import Rayleigh
from .driven import Motion, Prescribed, Translate, Twist
from .elastic_body import ElasticBody, ElasticPotential
from .integrators import (
    RK4,
    ExplicitEuler,
    ImplicitEuler,
    Integrator,
    LinearizedImplicitEuler,
    Midpoint,
    Newmark,
    StepStats,
    SymplecticEuler,
)
from .errors import (
    Diverged,
    FemElasticError,
    InvalidMesh,
    InvalidParameter,
    NotConverged,
    UnderConstrained,
)
from .fields import CellFields, cell_fields, von_mises
from .io import SeriesData, load_mesh, read_series, save_mesh, write_pvd, write_vtu_frame
from .linear_solvers import AMGSolver, AutoSolver, DirectSolver, LinearSolverFailed, SingularMatrix
from .materials import (
    Corotated,
    LinearElastic,
    Material,
    NeoHookean,
    StableNeoHookean,
    StVK,
    lame_parameters,
)
from .modal import critical_time_step, max_frequency, natural_frequencies
from .mesh import (
    beam_mesh,
    mesh_from_arrays,
    mesh_quality,
    remove_unused_vertices,
    reorient,
    signed_volumes,
    validate_mesh,
)
from .model import Model
from .output import SeriesWriter, write_summary
from .potential import LinearPotential, Potential
from .scene import BuiltRun, Scene, SceneError, load_scene, parse_scene, scene_help
from .simulate import StabilityWarning, simulate
from .springs import MassSpring, SpringPotential, lloyd_stiffness, van_gelder_stiffness
from .state import State
from .stiffness_warping import WarpedStiffness
from .static import StaticResult, solve_static
from .trajectory import Trajectory

__version__ = "0.1.0"

__all__ = [
    "Checkpoint",
    "load_checkpoint",
    "study", "elastica_tip",
    "CellFields", "cell_fields", "von_mises", "SeriesData", "read_series", "write_pvd", "write_vtu_frame",
    "SeriesWriter", "write_summary",
    "BuiltRun", "Scene", "SceneError", "load_scene", "parse_scene", "scene_help",
    "critical_time_step", "max_frequency", "natural_frequencies", "WarpedStiffness",
    "MassSpring", "SpringPotential", "lloyd_stiffness", "van_gelder_stiffness",
    "Box", "Ground", "Obstacle", "Sphere",
    "ExplicitEuler", "ImplicitEuler", "Integrator", "LinearizedImplicitEuler", "Midpoint", "Motion",
    "Newmark", "Prescribed", "RK4", "Rayleigh", "StabilityWarning", "State", "StepStats",
    "SymplecticEuler", "Trajectory", "Translate", "Twist", "simulate",
    "AMGSolver", "AutoSolver", "Corotated", "DirectSolver", "Diverged", "ElasticBody",
    "ElasticPotential", "FemElasticError", "InvalidMesh", "InvalidParameter", "LinearElastic",
    "LinearPotential", "Material", "Model", "NeoHookean", "NotConverged", "Potential",
    "LinearSolverFailed", "RectangularCantilever", "SingularMatrix", "StableNeoHookean", "StaticResult", "StVK",
    "UnderConstrained", "beam_mesh", "lame_parameters", "load_mesh", "mesh_from_arrays",
    "mesh_quality", "remove_unused_vertices", "reorient", "save_mesh", "signed_volumes",
    "solve_static", "validate_mesh",
]
