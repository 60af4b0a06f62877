"""fem_elastic: elastic solids with the finite element method, built on scikit-fem.

The public surface::

    import fem_elastic as fe
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(20, 2, 2))
    model = fe.Model(mesh, density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.45), order=2),
                     fixed="left", gravity=(0.0, 0.0, -9.81))
    static = fe.solve_static(model)

The package is grouped by layer; each imports only those below it
(``docs/architecture.md``, and a test keeps it so):

- :mod:`fem_elastic.errors`, :mod:`fem_elastic.files`: typed errors, atomic files;
- :mod:`fem_elastic.geometry` (meshes) and :mod:`fem_elastic.materials` (``psi(F)``);
- :mod:`fem_elastic.discretization`: the scikit-fem adapter, kernels, mass;
- :mod:`fem_elastic.physics`: every Potential and the Model;
- :mod:`fem_elastic.solvers`: Newton, linear solvers, statics, modal analysis;
- :mod:`fem_elastic.dynamics`: State, integrators, ``simulate``, checkpoints;
- :mod:`fem_elastic.study`: error-vs-run-time and stability studies (imported on first use);
- :mod:`fem_elastic.app`: scene files, runner, output, render, the command line.

``import fem_elastic`` needs only numpy, scipy and scikit-fem: meshio is
imported inside the I/O functions, pyamg inside the AMG solver, and the
studies on first use of ``fe.study``.

The user guide, the API reference and the example gallery (``examples/``)
are the Sphinx site in ``docs/``; the README's "Documentation" section
gives the command that builds it.
"""

from . import _compat
from .app import (
    BuiltRun,
    Scene,
    SceneError,
    SeriesData,
    SeriesWriter,
    load_scene,
    parse_scene,
    read_series,
    scene_help,
    write_pvd,
    write_summary,
    write_vtu_frame,
)
from .dynamics import (
    RK4,
    Checkpoint,
    ContactIntersectionWarning,
    ExplicitEuler,
    ImplicitEuler,
    Integrator,
    InversionWarning,
    LinearizedImplicitEuler,
    Midpoint,
    PBD,
    XPBD,
    ConstraintNeoHookean,
    Newmark,
    ProjectiveDynamics,
    ShapeMatcher,
    ShapeMatching,
    StabilityWarning,
    State,
    StepStats,
    SymplecticEuler,
    Trajectory,
    Trapezoid,
    VelocityVerlet,
    load_checkpoint,
    simulate,
)
from .errors import (
    Diverged,
    FemElasticError,
    InvalidMesh,
    InvalidParameter,
    MissingDependency,
    NotConverged,
    OutputInUse,
    ResourceLimit,
    StepFailed,
    UnderConstrained,
    WriteFailed,
)
from .geometry import (
    beam_mesh,
    cook_membrane_mesh,
    load_mesh,
    mesh_from_arrays,
    mesh_quality,
    remove_unused_vertices,
    reorient,
    save_mesh,
    signed_volumes,
    validate_mesh,
)
from .materials import (
    Corotated,
    LinearElastic,
    Material,
    NeoHookean,
    ProjectiveCorotated,
    StableNeoHookean,
    StVK,
    energies,
    lame_parameters,
    material_from_energy,
)
from .materials import energy_math as math  # noqa: F401  (fe.math; not in __all__: never shadows the stdlib)
from .physics import (
    Body,
    BoundImpulseContact,
    BoundingSpheres,
    BoundIPCContact,
    CollisionSurface,
    IPCContact,
    collision_surface,
    Box,
    CellFields,
    ElasticBody,
    ElasticPotential,
    Ground,
    ImpulseContact,
    LinearPotential,
    MassSpring,
    MixedPotential,
    Model,
    MultiBody,
    Motion,
    Obstacle,
    Potential,
    Prescribed,
    Rayleigh,
    RectangularCantilever,
    RestContactWarning,
    Sphere,
    SpringPotential,
    Translate,
    Twist,
    WarpedStiffness,
    cell_fields,
    collide_particles,
    elastica_tip,
    lloyd_stiffness,
    van_gelder_stiffness,
    von_mises,
)
from .solvers import (
    AMGSolver,
    AutoSolver,
    CholmodSolver,
    DirectSolver,
    LinearSolverFailed,
    PETScSolver,
    EquilibriumPoint,
    LoadPath,
    RoundoffWarning,
    SingularMatrix,
    StaticResult,
    UnstableEquilibrium,
    critical_time_step,
    load_path,
    max_frequency,
    natural_frequencies,
    solve_static,
)

__version__ = "0.1.0"

__all__ = [
    "Checkpoint",
    "load_checkpoint",
    "study", "elastica_tip",
    "render", "render_runs", "render_frame",
    "CellFields", "cell_fields", "von_mises", "SeriesData", "read_series", "write_pvd", "write_vtu_frame",
    "SeriesWriter", "write_summary",
    "BuiltRun", "Scene", "SceneError", "load_scene", "parse_scene", "scene_help",
    "critical_time_step", "max_frequency", "natural_frequencies", "WarpedStiffness",
    "MassSpring", "SpringPotential", "lloyd_stiffness", "van_gelder_stiffness",
    "Box", "Ground", "Obstacle", "Sphere",
    "ExplicitEuler", "ImplicitEuler", "Integrator", "LinearizedImplicitEuler", "Midpoint", "Motion",
    "Newmark", "Prescribed", "RK4", "Rayleigh", "StabilityWarning", "State", "StepStats",
    "SymplecticEuler", "Trajectory", "Translate", "Trapezoid", "Twist", "VelocityVerlet", "simulate",
    "AMGSolver", "AutoSolver", "CholmodSolver", "Corotated", "DirectSolver", "Diverged", "ElasticBody",
    "ElasticPotential", "FemElasticError", "InvalidMesh", "InvalidParameter", "LinearElastic",
    "LinearPotential", "Material", "Model", "NeoHookean", "NotConverged", "Potential",
    "LinearSolverFailed", "RectangularCantilever", "SingularMatrix", "StableNeoHookean", "StaticResult", "StVK",
    "MixedPotential", "cook_membrane_mesh",
    "UnderConstrained", "beam_mesh", "lame_parameters", "load_mesh", "mesh_from_arrays",
    "material_from_energy", "energies", "MissingDependency",
    "mesh_quality", "remove_unused_vertices", "reorient", "save_mesh", "signed_volumes",
    "solve_static", "validate_mesh",
    "InversionWarning", "StepFailed", "ContactIntersectionWarning",
    "OutputInUse", "ResourceLimit", "WriteFailed",
    "EquilibriumPoint", "LoadPath", "RoundoffWarning", "UnstableEquilibrium", "load_path",
    "ProjectiveCorotated", "ProjectiveDynamics", "ShapeMatcher", "ShapeMatching",
    "PBD", "XPBD", "ConstraintNeoHookean",
    "CollisionSurface", "collision_surface", "IPCContact", "BoundIPCContact",
    "Body", "MultiBody", "PETScSolver",
    "ImpulseContact", "BoundImpulseContact", "RestContactWarning", "collide_particles", "BoundingSpheres",
]

_compat.install()


#: public names imported on first use, as (module, attribute; None: the module itself):
#: fe.study pulls in the runner's and the studies' code, fe.render (public since issue 20) pyvista
_LAZY = {
    "study": (".study", None),
    "render": (".app.render", None),
    "render_runs": (".app.render", "render_runs"),
    "render_frame": (".app.render", "render_frame"),
}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        module_name, attribute = _LAZY[name]
        module = importlib.import_module(module_name, __name__)
        return module if attribute is None else getattr(module, attribute)
    if name in _compat.MOVED:  # fe.mesh, fe.analytic, ...: the modules' old places
        return _compat.moved_module(name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
