"""The scene-file schema: every table and key, its type, unit, default and allowed values.

:data:`SCENE_FILE` is the one description of a scene file. :func:`validate`
walks it to check a parsed TOML document and fill in the defaults, and
:func:`schema_help` walks it to print the reference that ``fem-elastic run
--help`` shows, so the two cannot disagree. The names a scene file may use for
materials, integrators, spring calibrations, contact methods and linear
solvers are the keys of the tables below (:data:`MATERIALS`,
:data:`INTEGRATORS`, ...), which map them to the library's classes.

The value types, keys and tables it is built from, and the error
:class:`Invalid`, are in :mod:`fem_elastic.app.schema_types` (and importable
from here too).

Errors are raised as :class:`Invalid` with the *path* of the offending key, a
tuple such as ``("compare", 1, "body", "material")``; :mod:`fem_elastic.app.scene`
turns it into a :class:`fem_elastic.app.scene.SceneError` with the file and line.

Units are SI (m, s, kg, Pa, N); angles in a scene file are in degrees.
"""

from __future__ import annotations

import inspect
import re
import textwrap
from typing import Any

from ..physics.contact import METHODS as CONTACT_METHODS
from ..physics.damping import Rayleigh
from ..errors import InvalidParameter
from ..dynamics.integrators import (
    RK4,
    ExplicitEuler,
    ImplicitEuler,
    LinearizedImplicitEuler,
    Midpoint,
    Newmark,
    SymplecticEuler,
    Trapezoid,
    VelocityVerlet,
)
from ..dynamics.position_based import PBD, XPBD
from ..dynamics.projective import ProjectiveDynamics
from ..dynamics.shape_matching import MODES as SHAPE_MATCHING_MODES
from ..dynamics.shape_matching import ShapeMatching
from ..solvers.linear_solvers import AMGSolver, AutoSolver, DirectSolver
from ..solvers.cholmod import CholmodSolver  # scikit-sparse imported only when one is made
from ..solvers.petsc_solver import PETScSolver  # petsc4py imported only when one solves
from ..materials import Corotated, LinearElastic, NeoHookean, StableNeoHookean, StVK
from ..physics.springs import lloyd_stiffness, van_gelder_stiffness
from .schema_types import (
    ABSENT,
    REQUIRED,
    Array,
    Boolean,
    Choice,
    Displacements,
    Fixed,
    Integer,
    Invalid,
    Key,
    NamedVectors,
    Number,
    String,
    Table,
    TableArray,
    Type,
    Vector,
    _toml,
    closest,
    format_path,
    key_name,
    split_path,
)

__all__ = [
    "CALIBRATIONS", "INTEGRATORS", "LINEAR_SOLVERS", "MATERIALS", "SCENE_FILE",
    "Invalid", "Key", "Table", "TableArray",
    "closest", "format_path", "integrator_options", "key_name", "make_integrator",
    "schema_help", "split_path", "validate",
]

# ---------------------------------------------------------------------------------------
# the names a scene file uses, mapped to the library

MATERIALS = {
    "linear": LinearElastic,
    "stvk": StVK,
    "neo_hookean": NeoHookean,
    "stable_neo_hookean": StableNeoHookean,
    "corotated": Corotated,
}
INTEGRATORS = {
    "explicit_euler": ExplicitEuler,
    "symplectic_euler": SymplecticEuler,
    "midpoint": Midpoint,
    "rk4": RK4,
    "implicit_euler": ImplicitEuler,
    "linearized_implicit_euler": LinearizedImplicitEuler,
    "newmark": Newmark,
    "pbd": PBD,
    "xpbd": XPBD,
    "shape_matching": ShapeMatching,
    "projective_dynamics": ProjectiveDynamics,
    "trapezoid": Trapezoid,
    "velocity_verlet": VelocityVerlet,
}
CALIBRATIONS = {"van_gelder": van_gelder_stiffness, "lloyd": lloyd_stiffness}
#: ``linear_solver = "..."`` in [integrator]: the solver objects it stands for
LINEAR_SOLVERS = {"auto": AutoSolver, "direct": DirectSolver, "amg": AMGSolver, "cholmod": CholmodSolver,
                  "petsc": PETScSolver}
MOTIONS = ("twist", "translate")
RENDER_FORMATS = ("mp4", "gif", "png")
CONTACT_TYPES = ("ipc", "impulse")  # the [contact] table's types (physics.ipc_contact, physics.impulse_contact)
COLOR_FIELDS = ("von_mises", "displacement", "body")  # "body": a [[body]] scene's bodies


# ---------------------------------------------------------------------------------------
# integrator options: taken from the constructor's signature


def _constructor_parameters(cls) -> list[inspect.Parameter]:
    """Keyword parameters of ``cls.__init__``; through ``*args, **kwargs`` to the parent's."""
    for klass in cls.__mro__:
        init = klass.__dict__.get("__init__")
        if init is None:
            continue
        params = list(inspect.signature(init).parameters.values())[1:]
        if any(p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD) for p in params):
            continue  # passes everything on: the parent's signature is the real one
        return [p for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    return []


#: integrator options whose values are names: the allowed names (for suggestions)
OPTION_CHOICES = {"mass": ("lumped", "consistent"), "linear_solver": tuple(LINEAR_SOLVERS),
                  "mode": SHAPE_MATCHING_MODES}


def _option_type(param: inspect.Parameter) -> Type | None:
    """The scene type of an integrator option: from :data:`OPTION_CHOICES`, else its default."""
    if param.name in OPTION_CHOICES:
        return Choice(OPTION_CHOICES[param.name])
    d = param.default
    if isinstance(d, bool):
        return Boolean()
    if isinstance(d, int):
        return Integer()
    if isinstance(d, float):
        return Number()
    if isinstance(d, str):
        return String()
    return None  # not expressible in TOML: the option cannot be set from a scene


def integrator_options(name: str) -> dict[str, tuple[Type, Any]]:
    """``{option: (type, default)}`` of the integrator ``name`` (see :data:`INTEGRATORS`).

    Examples
    --------
    >>> sorted(integrator_options("linearized_implicit_euler"))
    ['linear_solver', 'mass', 'project', 'warping']
    >>> sorted(integrator_options("rk4"))
    ['max_substeps', 'recheck_every', 'safety', 'substep']
    """
    out = {}
    for p in _constructor_parameters(INTEGRATORS[name]):
        t = _option_type(p)
        if t is not None:
            out[p.name] = (t, "auto" if p.name == "linear_solver" else p.default)
    return out


def make_integrator(spec: dict):
    """The integrator object of a validated ``[integrator]`` table (a fresh one each call)."""
    cls = INTEGRATORS[spec["type"]]
    kwargs = {k: v for k, v in spec.items() if k != "type"}
    if "linear_solver" in kwargs:
        kwargs["linear_solver"] = LINEAR_SOLVERS[kwargs["linear_solver"]]()
    return cls(**kwargs)


def _integrator_options(table: dict, extra: dict, path: tuple) -> dict:
    name = table["type"]
    allowed = integrator_options(name)
    out = {}
    for key, value in extra.items():
        if key not in allowed:
            near = closest(key, allowed)
            hint = f' — did you mean "{near}"?' if near else "."
            listed = ", ".join(allowed) if allowed else f"none ({name} takes no options)"
            raise Invalid(path + (key,), f'unknown option "{key}" for integrator "{name}"{hint} '
                                         f"Its options: {listed}.", near)
        out[key] = allowed[key][0].check(value, path + (key,))
    # the constructor checks the values (ranges, "lumped" | "consistent"); find the culprit
    for key in out:
        try:
            make_integrator({"type": name, key: out[key]})
        except InvalidParameter as exc:
            raise Invalid(path + (key,), f"{key} = {_toml(out[key])}: {exc}") from None
    filled = {k: d for k, (_, d) in allowed.items()}
    filled.update(out)
    return filled


# ---------------------------------------------------------------------------------------
# cross-key rules


def _damping_rule(table: dict, path: tuple) -> dict:
    by_coefficients = table["alpha"] is not None or table["beta"] is not None
    by_ratios = table["ratios"] is not None or table["frequencies"] is not None
    if by_coefficients and by_ratios:
        key = "ratios" if table["ratios"] is not None else "frequencies"
        raise Invalid(path + (key,), "[damping] takes alpha and beta, or ratios and frequencies, "
                                     "not both: remove one pair.")
    if by_ratios:
        for key in ("ratios", "frequencies"):
            if table[key] is None:
                raise Invalid(path + (key,), "[damping] needs both ratios and frequencies, e.g. "
                                             "ratios = [0.02, 0.02] and frequencies = [2.0, 20.0] (Hz).")
        (z1, z2), (f1, f2) = table["ratios"], table["frequencies"]
        try:
            r = Rayleigh.from_damping_ratios(z1, f1, z2, f2)
        except InvalidParameter as exc:
            raise Invalid(path + ("ratios",), str(exc)) from None
        table["alpha"], table["beta"] = r.alpha, r.beta
    elif not by_coefficients:
        raise Invalid(path, "[damping] is empty: give alpha (1/s) and/or beta (s), or ratios and "
                            "frequencies (Hz); remove the table for no damping.")
    table["alpha"] = table["alpha"] or 0.0
    table["beta"] = table["beta"] or 0.0
    return table


def _output_rule(table: dict, path: tuple) -> dict:
    w, h = table["size"]
    if "mp4" in table["render"] and (w % 2 or h % 2):
        # checked here, before the run: the renderer would refuse it only after simulating
        raise Invalid(path + ("size",), f"size = [{w}, {h}]: an MP4 (H.264, yuv420p) needs an "
                                        f"even width and height; use e.g. [{w + w % 2}, {h + h % 2}].")
    return table


#: The largest render width or height (px): 8K; a frame of 8192 x 8192 RGB is 200 MB already.
MAX_RENDER_SIDE = 8192


#: A run's name is the name of its directory under the output directory.
RUN_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]*")

#: Names the output directory uses itself (PNG frames of the renders).
RESERVED_RUN_NAMES = ("png",)


def _check_run_name(name: str, path: tuple) -> None:
    if not RUN_NAME.fullmatch(name) or name in RESERVED_RUN_NAMES:
        raise Invalid(path, f'the run name "{name}" cannot name its output folder: use letters, '
                            'digits, "_" and "-" (starting with a letter or digit), and not '
                            f'{", ".join(map(repr, RESERVED_RUN_NAMES))}; e.g. name = "fem".')


def _compare_rule(table: dict, path: tuple) -> dict:
    if table["body"] is None and table["integrator"] is None:
        raise Invalid(path, "a [[compare]] run needs a body or an integrator (or both) to "
                            "differ from the main run, e.g. body = { type = \"springs\", E = 2e7, "
                            "density = 1000.0 }.")
    return table


# ---------------------------------------------------------------------------------------
# the schema

FEM, SPRINGS = {"type": ("fem",)}, {"type": ("springs",)}
_E_ALIASES = ("young", "youngs_modulus", "young_modulus", "e_modulus", "youngs")


def _body_rule(table: dict, path: tuple) -> dict:
    """A finite-element body gives its elasticity as E and nu, or as mu and lam: one pair."""
    if table["type"] != "fem":
        return table
    given = {k for k in ("E", "nu", "mu", "lam") if table.get(k) is not None}
    if given == {"E", "nu"} or given == {"mu", "lam"}:
        if given == {"mu", "lam"}:
            from ..materials.base import elastic_constants

            try:
                elastic_constants(mu=table["mu"], lam=table["lam"], who="[body]")
            except InvalidParameter as exc:
                raise Invalid(path + ("lam",), str(exc)) from None
        return table
    if not given:
        raise Invalid(path + ("E",), "missing required key E: Young's modulus (Pa), e.g. E = 2e7, "
                                     "with nu = 0.3 (or give mu and lam, both in Pa).")
    pair = ("mu", "lam") if given & {"mu", "lam"} and not given & {"E", "nu"} else ("E", "nu")
    if given & {"E", "nu"} and given & {"mu", "lam"}:
        raise Invalid(path + (sorted(given & {"mu", "lam"})[0],),
                      f"[body] gives {', '.join(sorted(given))}: give E and nu, or mu and lam, "
                      "not both (two pairs can contradict each other).")
    lacking = [k for k in pair if k not in given][0]
    raise Invalid(path + (lacking,), f"missing required key {lacking}: {pair[0]} needs {pair[1]} "
                                     f"(give E and nu, or mu and lam).")

BODY = Table(
    "body",
    (
        Key("type", Choice(("fem", "springs")), "fem", doc="finite elements, or springs on the mesh edges"),
        Key("name", String(), lambda t: t["type"], doc="the run's name (variant)",
            default_text="the body type"),
        Key("material", Choice(tuple(MATERIALS)), REQUIRED, when=FEM,
            doc="hyperelastic material", default_text='"neo_hookean"'),
        Key("E", Number(gt=0), ABSENT, "Pa", "Young's modulus (or give mu and lam instead of E "
            "and nu)", when=FEM, aliases=_E_ALIASES, default_text="2e7"),
        Key("E", Number(gt=0), REQUIRED, "Pa", "Young's modulus", when=SPRINGS, aliases=_E_ALIASES,
            default_text="2e7"),
        Key("nu", Number(gt=-1, lt=0.5), ABSENT, doc="Poisson's ratio (or give mu and lam)", when=FEM,
            aliases=("poisson", "poisson_ratio", "poissons_ratio"), default_text="0.3"),
        Key("mu", Number(gt=0), ABSENT, "Pa", "shear modulus, with lam instead of E and nu: exact "
            "for a nearly incompressible body, where nu = 0.4999999 loses digits", when=FEM,
            aliases=("shear_modulus", "G")),
        Key("lam", Number(), ABSENT, "Pa", "Lame's first parameter, with mu", when=FEM,
            aliases=("lambda", "lame")),
        Key("formulation", Choice(("displacement", "mixed")), "displacement", when=FEM,
            doc='"mixed": displacement-pressure (order = 2), locking-free near nu = 0.5'),
        Key("nu", Number(gt=-1, lt=0.5), 0.25, doc="Poisson's ratio, the calibration's target "
            "(a spring network has 1/4 built in)", when=SPRINGS,
            aliases=("poisson", "poisson_ratio", "poissons_ratio")),
        Key("order", Integer(choices=(1, 2)), 1, doc="1: linear tets, 2: quadratic tets", when=FEM),
        Key("density", Number(gt=0), REQUIRED, "kg/m^3", "mass density", aliases=("rho",),
            default_text="1000.0"),
        Key("calibration", Choice(tuple(CALIBRATIONS)), "van_gelder", when=SPRINGS,
            doc="spring stiffness from E (fe.van_gelder_stiffness | fe.lloyd_stiffness)"),
        Key("k_d", Number(ge=0), 0.0, "N s/m", "damping along each spring", when=SPRINGS),
    ),
    "The body: a material on finite elements, or a mass-spring network.",
    rule=_body_rule,
)

INTEGRATOR = Table(
    "integrator",
    (Key("type", Choice(tuple(INTEGRATORS)), REQUIRED, doc="time integrator",
         default_text='"implicit_euler"'),),
    "The time integrator; any further key is one of its constructor's options.",
    options=_integrator_options,
)

DRIVEN = Table(
    "loads.driven",
    (
        Key("boundary", String(), REQUIRED, doc="named boundary of the mesh it moves",
            default_text='"right"'),
        Key("motion", Choice(MOTIONS), REQUIRED, doc="fe.Twist or fe.Translate",
            default_text='"twist"'),
        Key("angle", Number(), REQUIRED, "degrees", "total rotation", when={"motion": ("twist",)},
            default_text="360.0"),
        Key("axis", Vector(), [1.0, 0.0, 0.0], doc="rotation axis", when={"motion": ("twist",)}),
        Key("center", Vector(), ABSENT, "m", "a point on the axis (default: the boundary's centroid)",
            when={"motion": ("twist",)}),
        Key("offset", Vector(), REQUIRED, "m", "total displacement", when={"motion": ("translate",)},
            default_text="[0.0, 0.0, -0.05]"),
        Key("duration", Number(ge=0), REQUIRED, "s", "time over which the motion ramps linearly",
            default_text="1.0"),
        Key("release", Number(ge=0), ABSENT, "s", "time from which the boundary is free "
            "(default: held for ever)"),
    ),
    "A boundary moved in time (repeat [[loads.driven]] for several).",
)

COMPARE = Table(
    "compare",
    (
        Key("body", BODY, ABSENT, doc="a full body table, as [body] (default: the main body)"),
        Key("integrator", INTEGRATOR, ABSENT,
            doc="a full integrator table, as [integrator] (default: the main one)"),
        Key("name", String(), lambda t: (t["body"] or {}).get("name") or (t.get("integrator") or {}).get("type"),
            doc="the run's name (variant)", default_text="the body's name, else the integrator type"),
    ),
    "Another run of the same scene with another body and/or integrator (repeat for several).",
    rule=_compare_rule,
)

def _boundary_rule(table: dict, path: tuple) -> dict:
    if not table.get("displacement"):  # the spec names only the supports a scene has
        table.pop("displacement", None)
    return table


SOLVE = Table(
    "solve",
    (
        Key("kind", Choice(("dynamic", "static")), "dynamic",
            doc='"dynamic": simulate in time ([integrator], [time]); "static": the equilibrium '
                "under the loads and prescribed displacements, along a load path (fe.solve_static)"),
        Key("steps", Integer(ge=1), 1, doc="equal load steps; each is a frame of the series (a "
            "failed step is halved)", when={"kind": ("static",)}),
        Key("stability", Boolean(), True, doc="check the lowest eigenvalue of the tangent at the "
            "equilibrium (warn when unstable)", when={"kind": ("static",)}),
        Key("stabilize", Boolean(), False, doc="perturb an unstable equilibrium along its lowest "
            "mode until it is stable", when={"kind": ("static",)}),
        Key("linear_solver", Choice(("auto", "direct", "amg", "cholmod", "petsc")), "auto",
            doc='linear solver of the Newton iterations; "petsc" solves across MPI ranks '
                "(mpiexec -n N fem-elastic run ...; no stability check)", when={"kind": ("static",)}),
    ),
    'What is solved. A static scene has no [integrator], [time], [initial], [damping] or '
    "[[loads.driven]]: leave them out.",
)

#: Tables and keys that only a dynamic scene has (a static solve has no time).
DYNAMIC_ONLY = ("integrator", "time", "initial", "damping")

SCENE_FILE = Table(
    "scene file",
    (
        Key("scene", Table("scene", (
            Key("name", String(), ABSENT, doc="the scene's name", default_text="the file name"),
            Key("description", String(), "", doc="one line on what it shows"),
        ), "Name and description."), {}, doc="name and description"),
        Key("mesh", Table("mesh", (
            Key("kind", Choice(("beam", "file")), REQUIRED, doc="a generated box (fe.beam_mesh) or a "
                "mesh file (fe.load_mesh)", default_text='"beam"'),
            Key("length", Number(gt=0), 1.0, "m", "extent along x", when={"kind": ("beam",)}),
            Key("width", Number(gt=0), 0.1, "m", "extent along y", when={"kind": ("beam",)}),
            Key("height", Number(gt=0), 0.1, "m", "extent along z", when={"kind": ("beam",)}),
            Key("cells", Array(Integer(ge=1), 3, "[nx, ny, nz] integers >= 1"), [20, 2, 2],
                doc="hexahedral cells along x, y, z (6 tets each)", when={"kind": ("beam",)}),
            Key("path", String(), REQUIRED, doc="mesh file, relative to the scene file's folder",
                when={"kind": ("file",)}, default_text='"meshes/blob.vtu"'),
            Key("reorient", Boolean(), False, doc="fix tets written with the opposite orientation",
                when={"kind": ("file",)}),
            Key("translate", Vector(), ABSENT, "m", "move the mesh by this offset"),
        ), "The reference mesh. A beam has boundaries left (x = 0), right, front, back, bottom, "
           "top."), REQUIRED, doc="the reference mesh"),
        Key("body", BODY, REQUIRED, doc="the body"),
        Key("boundary", Table("boundary", (
            Key("fixed", Fixed(), [], doc="held at their reference positions: all components, "
                'or those a table gives, e.g. { left = "x", bottom = "z" } (rollers)'),
            Key("displacement", Displacements(), {}, "m", "prescribed displacements, e.g. "
                '{ right = [0.01, "free", "free"] }; ramped with the load steps of a static solve, '
                "held from the start in dynamics"),
        ), "Supports.", rule=_boundary_rule), {}, doc="supports"),
        Key("loads", Table("loads", (
            Key("gravity", Vector(), ABSENT, "m/s^2", "gravitational acceleration (none if absent)"),
            Key("traction", NamedVectors(), {}, "Pa", "dead load per reference area on named boundaries"),
            Key("driven", TableArray(DRIVEN), [], doc="boundaries moved in time, [[loads.driven]]"),
        ), "External loads; only those given are built."), {}, doc="loads"),
        Key("ground", Table("ground", (
            Key("z", Number(), 0.0, "m", "height of the ground plane"),
            Key("method", Choice(CONTACT_METHODS), "penalty",
                doc="penalty springs | log barrier (implicit integrators) | impulses (explicit ones)"),
            Key("stiffness", Number(gt=0), ABSENT, "N/m", "per-node stiffness (default: carries the "
                "weight at the design penetration or gap)", when={"method": ("penalty", "barrier")}),
            Key("penetration", Number(gt=0), 1e-3, "m", "design resting penetration",
                when={"method": ("penalty",)}),
            Key("dhat", Number(gt=0), 1e-3, "m", "barrier activation distance",
                when={"method": ("barrier",)}),
            Key("restitution", Number(ge=0, le=1), 0.0, doc="0: no bounce, 1: elastic",
                when={"method": ("impulse",)}),
            Key("friction", Number(ge=0), 0.0, doc="Coulomb coefficient", when={"method": ("impulse",)}),
        ), "A ground plane z = const (fe.Ground); no contact if absent."), ABSENT, doc="ground contact"),
        Key("contact", Table("contact", (
            Key("type", Choice(CONTACT_TYPES), REQUIRED,
                doc="ipc: barrier contact between bodies and with itself, through ipctk | impulse: the "
                "notes' impulse collisions after each explicit or position-based step"),
            Key("dhat", Number(gt=0), 1e-3, "m", "IPC barrier activation distance",
                when={"type": ("ipc",)}),
            Key("kappa", Number(gt=0), ABSENT, "N/m^3", "IPC barrier stiffness (default: adaptive)",
                when={"type": ("ipc",)}),
            Key("friction", Number(ge=0), 0.0, doc="Coulomb coefficient (lagged IPC friction)",
                when={"type": ("ipc",)}),
            Key("epsv", Number(gt=0), 1e-3, "m/s", "friction smoothing velocity",
                when={"type": ("ipc",)}),
            Key("self_contact", Boolean(), True, doc="surfaces of one body collide with each other",
                when={"type": ("ipc", "impulse")}),
            Key("restitution", Number(ge=0, le=1), 0.0, doc="impulse: 0 no bounce, 1 elastic",
                when={"type": ("impulse",)}),
            Key("friction", Number(ge=0), 0.0, doc="Coulomb coefficient on the impulses",
                when={"type": ("impulse",)}),
            Key("thickness", Number(gt=0), 1e-3, "m", "impulse contact distance (above relative "
                "speed times dt)", when={"type": ("impulse",)}),
        ), "Contact between bodies and self-contact (fe.IPCContact or fe.ImpulseContact); none if "
           "absent."), ABSENT,
            doc="contact between bodies"),
        Key("damping", Table("damping", (
            Key("alpha", Number(ge=0), ABSENT, "1/s", "mass-proportional coefficient"),
            Key("beta", Number(ge=0), ABSENT, "s", "stiffness-proportional coefficient"),
            Key("ratios", Vector(2, Number(ge=0, lt=1)), ABSENT, doc="damping ratios zeta1, zeta2 ..."),
            Key("frequencies", Vector(2, Number(gt=0)), ABSENT, "Hz", "... at these frequencies f1 < f2"),
        ), "Rayleigh damping C = alpha M + beta K: alpha and/or beta, or ratios and frequencies; "
           "none if absent.", rule=_damping_rule), ABSENT, doc="Rayleigh damping"),
        Key("initial", Table("initial", (
            Key("velocity", Vector(), [0.0, 0.0, 0.0], "m/s", "uniform initial velocity"),
        ), "Initial state (default: at rest in the reference configuration)."), ABSENT,
            doc="initial state"),
        Key("solve", SOLVE, {}, doc="dynamic (time stepping, the default) or static (a load path)"),
        Key("probe", Table("probe", (
            Key("points", NamedVectors(), {}, "m", "{name = [x, y, z]} reference points, e.g. "
                "{ tip = [1.0, 0.05, 0.05] }"),
        ), "Named points whose displacement is recorded over time (at the nearest vertex) in "
           "summary.json and printed by `fem-elastic run`."), ABSENT, doc="probe points"),
        Key("integrator", INTEGRATOR, REQUIRED, doc="the time integrator"),
        Key("time", Table("time", (
            Key("dt", Number(gt=0), REQUIRED, "s", "time step", default_text="0.0166667"),
            Key("duration", Number(gt=0), REQUIRED, "s", "simulated time", default_text="2.0"),
        ), "Time stepping: ceil(duration / dt) steps."), REQUIRED, doc="time stepping"),
        Key("output", Table("output", (
            Key("every", Integer(ge=1), 1, doc="record a frame every this many steps"),
            Key("checkpoint_every", Integer(ge=0), 0,
                doc="write a checkpoint every this many steps, for `fem-elastic run --resume` (0: only on Ctrl-C)"),
            Key("vtu", Boolean(), True, doc="keep the VTU frames and the PVD series (false: only summary.json and the renders)"),
            Key("render", Array(Choice(RENDER_FORMATS), None, 'array of "mp4" | "gif" | "png"'),
                ["mp4"], doc="movies and pictures to render ([] for none)"),
            Key("color_by", Choice(COLOR_FIELDS), "von_mises", doc="field the renders are coloured by"),
            Key("size", Array(Integer(ge=16, le=MAX_RENDER_SIDE), 2,
                              f"[width, height] integers from 16 to {MAX_RENDER_SIDE}"), [960, 540], "px",
                "render size (bounded: an 8K frame is 8192 px wide; larger ones exhaust memory)"),
            Key("fps", Integer(ge=1), 30, "frames/s", "movie frame rate"),
        ), "What the run writes.", rule=_output_rule), {}, doc="outputs"),
        Key("compare", TableArray(COMPARE), [], doc="further runs, [[compare]]"),
    ),
    "A scene file.",
)


def _static_table(table: Table) -> Table:
    """``table`` without the keys of time stepping (the scene file of a static solve)."""
    from dataclasses import replace

    keys = []
    for key in table.keys:
        if key.name in DYNAMIC_ONLY:
            continue
        if key.name == "loads":
            loads = key.type
            key = replace(key, type=replace(loads, keys=tuple(k for k in loads.keys if k.name != "driven")))
        if key.name == "compare":
            compare = key.type.table
            key = replace(key, type=replace(key.type, table=replace(
                compare, keys=tuple(k for k in compare.keys if k.name != "integrator"),
                rule=_static_compare_rule)))
        keys.append(key)
    return replace(table, keys=tuple(keys))


def _static_compare_rule(table: dict, path: tuple) -> dict:
    if table["body"] is None:
        raise Invalid(path, "a [[compare]] run of a static scene needs a body to differ from the "
                            'main run, e.g. body = { material = "linear", E = 2e7, nu = 0.3, '
                            "density = 1000.0 }.")
    table["integrator"] = None
    return table


#: The scene file of a static solve ([solve] kind = "static").
STATIC_SCENE_FILE = _static_table(SCENE_FILE)


def validate(document: dict) -> dict:
    """Check a parsed scene document against :data:`SCENE_FILE` and fill the defaults.

    Parameters
    ----------
    document : dict
        What ``tomllib.loads`` returned.

    Returns
    -------
    dict
        The validated spec: every key of every present table, with its
        default where the file leaves it out (None for optional keys and
        tables that are absent).

    Raises
    ------
    Invalid
        With the path of the first offending key.

    Examples
    --------
    >>> spec = validate({"mesh": {"kind": "beam"}, "body": {"material": "stvk", "E": 1e6,
    ...                  "nu": 0.3, "density": 1000.0}, "integrator": {"type": "rk4"},
    ...                  "time": {"dt": 1e-3, "duration": 0.01}})
    >>> spec["mesh"]["cells"], spec["body"]["order"], spec["ground"], spec["loads"]["gravity"]
    ([20, 2, 2], 1, None, None)
    """
    solve = document.get("solve") if isinstance(document, dict) else None
    from .scene_bodies import is_multibody, validate_bodies

    if is_multibody(document):  # [[body]] tables: several bodies (fem_elastic.app.scene_bodies)
        spec = validate_bodies(document)
    elif isinstance(solve, dict) and solve.get("kind") == "static":
        spec = _validate_static(document)
    else:
        spec = SCENE_FILE.check(document, ())
    names = [spec["body"]["name"]]
    _check_run_name(names[0], ("body", "name"))
    for i, run in enumerate(spec["compare"]):
        _check_run_name(run["name"], ("compare", i, "name"))
        if run["name"] in names:
            raise Invalid(
                ("compare", i, "name"),
                f'the run name "{run["name"]}" is already used (runs so far: '
                f'{", ".join(names)}); give this [[compare]] a name = "...".',
            )
        names.append(run["name"])
    return spec


def _validate_static(document: dict) -> dict:
    """A static scene: the scene file without the tables of time stepping."""
    for name in DYNAMIC_ONLY:
        if name in document:
            raise Invalid((name,), f"[{name}] applies only to a dynamic scene; this one has [solve] "
                                   f'kind = "static" (a load path, no time): remove [{name}].')
    loads = document.get("loads")
    if isinstance(loads, dict) and "driven" in loads:
        raise Invalid(("loads", "driven"), "[[loads.driven]] moves a boundary in time; a static "
                      'scene has no time: prescribe its displacement instead, [boundary] displacement '
                      '= { right = [0.01, "free", "free"] }.')
    for i, c in enumerate(document.get("compare") or []):
        if isinstance(c, dict) and "integrator" in c:
            raise Invalid(("compare", i, "integrator"), "a static scene has no integrator: a "
                          "[[compare]] run of it differs by its body only.")
    spec = STATIC_SCENE_FILE.check(document, ())  # its [[compare]] rule sets each run's integrator None
    for name in DYNAMIC_ONLY:
        spec[name] = None
    spec["loads"]["driven"] = []
    return spec


# ---------------------------------------------------------------------------------------
# the help


def _default_text(key: Key) -> str:
    if key.default is REQUIRED:
        return "required" + (f", e.g. {key.default_text}" if key.default_text else "")
    if key.default_text is not None:
        return f"default {key.default_text}"
    if key.default is ABSENT or isinstance(key.default, dict):
        return "optional"
    return f"default {_toml(key.default)}"


def _key_lines(table: Table, indent: str) -> list[str]:
    lines = []
    pad = indent + " " * 13
    for key in table.keys:
        if isinstance(key.type, TableArray):
            typ = f"[[{key.type.table.title}]] tables (below)"
        elif isinstance(key.type, Table):
            typ = f"table, as [{key.type.title}]"
        else:
            typ = key.type.label
        if key.unit:
            typ += f", {key.unit}"
        name = f"{key.name:<12} "  # a longer name still keeps a space before its type
        lines.append(f"{indent}{name}{typ}; {_default_text(key)}")
        cond = ""
        if key.when:
            cond = " (if " + ", ".join(f"{k} = {' | '.join(_toml(v) for v in vals)}"
                                       for k, vals in key.when.items()) + ")"
        lines += textwrap.wrap(key.doc + cond, 96, initial_indent=pad, subsequent_indent=pad)
    return lines


def schema_help() -> str:
    """The scene-file reference: every table and key with type, unit, default and allowed values.

    Generated from :data:`SCENE_FILE` and the integrators' signatures.

    Examples
    --------
    >>> text = schema_help()
    >>> "[body]" in text and "neo_hookean" in text and "rtol" in text
    True
    """
    out = [
        "Scene files are TOML. Units are SI (m, s, kg, Pa, N); angles are in degrees.",
        "A table or key marked 'required' must be given; 'optional' ones are built only if present.",
        "",
    ]
    for key in SCENE_FILE.keys:
        t = key.type
        table = t.table if isinstance(t, TableArray) else t
        header = f"[[{key.name}]]" if isinstance(t, TableArray) else f"[{key.name}]"
        status = "required" if key.default is REQUIRED else "optional"
        if isinstance(t, TableArray):
            status = "optional, repeatable"
        out.append(f"{header}  ({status}) {table.doc}")
        out += _key_lines(table, "  ")
        if key.name == "loads":
            out.append(f"  [[loads.driven]]  {DRIVEN.doc}")
            out += _key_lines(DRIVEN, "    ")
        if key.name == "integrator":
            out.append("  options, by type (name = default):")
            for name in INTEGRATORS:
                opts = integrator_options(name)
                text = ", ".join(
                    f"{k} = {_toml(d)}" + (f" ({t.label})" if isinstance(t, Choice) else "")
                    for k, (t, d) in opts.items()
                ) or "none"
                out += textwrap.wrap(f"{name}: {text}", 96, initial_indent="    ",
                                     subsequent_indent="      ")
        out.append("")
    from .scene_bodies import multibody_help

    out.append(multibody_help())  # [[body]] tables: several bodies (fem_elastic.app.scene_bodies)
    return "\n".join(out).rstrip() + "\n"
