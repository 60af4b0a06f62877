"""Scene files: a simulation described in TOML, checked, and built into runs.

A scene file names a mesh, a body, its supports and loads, optionally a ground,
damping, driven boundaries and an initial velocity, an integrator, a time step
and duration, and what to write; or, with ``[solve] kind = "static"``, the
load steps of a static solve (:meth:`BuiltRun.solve`) instead of the time stepping. :func:`load_scene` reads and checks one;
:meth:`Scene.build` turns it into :class:`BuiltRun` objects (a
:class:`fem_elastic.Model`, an integrator, ``dt``, the number of steps, the
initial :class:`fem_elastic.State`) ready for :func:`fem_elastic.dynamics.simulate`.
A scene builds only the terms it declares: no gravity term without
``[loads] gravity``, no contact without ``[ground]``, no damping without
``[damping]``.

Each ``[[compare]]`` table adds a *variant*: another run of the same scene
with another body and/or integrator (a mass-spring copy beside an FEM body,
say). :attr:`Scene.variants` lists their names, the main run's first.

Every mistake in a file (TOML syntax, an unknown key, a wrong type, a missing
key, a value out of range, a boundary the mesh does not have) raises
:class:`SceneError`, which names the key, the file and the line, and suggests
the near miss the user probably meant. The schema (tables, keys, types, units,
defaults) lives in :mod:`fem_elastic.app.scene_schema`; :func:`scene_help` prints it.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, cast

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python < 3.11
    import tomli as tomllib  # type: ignore[no-redef]  # the same API on Python 3.10

from ..errors import FemElasticError, InvalidParameter

if TYPE_CHECKING:  # for annotations only
    from typing import Unpack  # Python >= 3.11

    from skfem import MeshTet

    from ..dynamics.integrators.base import Integrator
    from ..dynamics.simulate import SimulateOptions
    from ..dynamics.state import State
    from ..physics.multibody import AnyModel
    from ..dynamics.trajectory import Trajectory
    from ..solvers.static import SolveOptions, StaticResult
from ..materials.base import elastic_constants
from ..resources import check_input_file
from .toml_lines import KeyLines as _KeyLines
from .scene_schema import (
    CALIBRATIONS,
    MATERIALS,
    Invalid,
    closest,
    format_path,
    make_integrator,
    schema_help,
    split_path,
    validate,
)

__all__ = ["BuiltRun", "Scene", "SceneError", "load_scene", "parse_scene", "scene_help"]


# ---------------------------------------------------------------------------------------
# the error


class SceneError(InvalidParameter):
    """A scene file is wrong: the message names the key, the file and the line.

    ``str(error)`` reads like
    ``scenes/x.toml, line 12: [body] unknown key "Young" — did you mean "E"? ...``.

    Attributes
    ----------
    key : str or None
        Dotted path of the offending key, e.g. ``"body.E"`` or
        ``"compare[1].body.material"`` (array indices from 0); None for a
        TOML syntax error.
    line : int or None
        1-based line in the file, None when it cannot be told (a missing table).
    file : str or None
        The file (or the ``source`` given to :func:`parse_scene`).
    suggestion : str or None
        The near-miss key or value the user probably meant.
    message : str
        The message without the place.
    """

    def __init__(self, message: str, *, key: str | None = None, line: int | None = None,
                 file: str | None = None, suggestion: str | None = None) -> None:
        self.message = message
        self.key = key
        self.line = line
        self.file = file
        self.suggestion = suggestion
        place = ", ".join(p for p in (file, None if line is None else f"line {line}") if p)
        super().__init__(f"{place}: {message}" if place else message)


# ---------------------------------------------------------------------------------------
# reading


def _syntax_error(exc: Exception, text: str, source: str) -> SceneError:
    msg = str(exc)
    m = re.search(r"\(at line (\d+), column (\d+)\)", msg)
    line = None
    if m:
        line = int(m.group(1))
        msg = msg[:m.start()].rstrip() + f" (column {m.group(2)})"
    elif "end of document" in msg:
        line = text.count("\n") + (0 if text.endswith("\n") else 1)
        msg = msg.replace("(at end of document)", "at the end of the file").strip()
    return SceneError(
        f"TOML syntax error: {msg}. Check the quotes, brackets and '=' there "
        "(strings need quotes, arrays [ ], tables { } on one line).",
        line=line, file=source,
    )


def parse_scene(text: str, *, source: str = "<string>",
                base_dir: str | os.PathLike[str] = ".") -> "Scene":
    """Check a scene given as TOML text and return it as a :class:`Scene`.

    Parameters
    ----------
    text : str
        The scene file's content.
    source : str
        Where it came from, for messages (a file name).
    base_dir : str or os.PathLike
        Folder that ``[mesh] path`` is relative to (the scene file's folder).

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        The text is not TOML, or it breaks the schema (see :func:`scene_help`).

    Examples
    --------
    >>> from fem_elastic.app.scene import SceneError, parse_scene
    >>> scene = parse_scene('''
    ... [mesh]
    ... kind = "beam"
    ... cells = [4, 1, 1]
    ... [body]
    ... material = "neo_hookean"
    ... E = 1e6
    ... nu = 0.3
    ... density = 1000.0
    ... [boundary]
    ... fixed = ["left"]
    ... [integrator]
    ... type = "implicit_euler"
    ... [time]
    ... dt = 0.01
    ... duration = 0.05
    ... ''', source="tiny.toml")
    >>> scene.name, scene.variants, scene.spec["output"]["render"]
    ('tiny', ['fem'], ['mp4'])
    >>> run = scene.build()[0]
    >>> run.steps, run.model.loads, run.model.obstacles   # nothing it did not declare
    (5, (), ())
    >>> try:
    ...     parse_scene('[mesh]\\nkind = "beem"\\n', source="bad.toml")
    ... except SceneError as err:
    ...     print(err.key, err.line, err.suggestion)
    mesh.kind 2 beam
    """
    if not isinstance(text, str):
        raise SceneError(
            f"a scene is TOML text (str), got {type(text).__name__}; read the file first "
            "(fe.load_scene(path) does), or decode bytes with .decode('utf-8').", file=source)
    try:
        document = tomllib.loads(text)
        locations = _KeyLines(text).lines
        try:
            spec = validate(document)
        except Invalid as exc:
            raise _located(exc, locations, source) from None
    except tomllib.TOMLDecodeError as exc:
        raise _syntax_error(exc, text, source) from None
    except RecursionError:  # arrays or inline tables nested thousands deep: no scene needs that
        raise SceneError(
            "the file nests arrays or inline tables too deeply to be read (deeper than Python's "
            "recursion limit); a scene needs at most a few levels: check the brackets.", file=source,
        ) from None
    if spec["scene"]["name"] is None:
        stem = Path(source).stem if source and not source.startswith("<") else "scene"
        spec["scene"]["name"] = stem
    variants = [spec["body"]["name"]] + [c["name"] for c in spec["compare"]]
    return Scene(
        name=spec["scene"]["name"],
        description=spec["scene"]["description"],
        source=source,
        spec=spec,
        variants=variants,
        base_dir=Path(base_dir),
        locations=locations,
        text=text,
    )


#: The largest scene file read (bytes): a scene is a page of TOML; beyond this it is the wrong file.
MAX_SCENE_BYTES = 4 * 2**20


def load_scene(path: str | os.PathLike[str]) -> "Scene":
    """Read and check a scene file (see :func:`parse_scene`).

    Parameters
    ----------
    path : str or os.PathLike
        The ``.toml`` file; ``[mesh] path`` is relative to its folder.

    Raises
    ------
    SceneError
        The file is unreadable, not TOML, or breaks the schema.
    """
    path = Path(path)
    try:
        # by type and size before reading: a FIFO or device would block or never end
        check_input_file(path, MAX_SCENE_BYTES, "scene file")
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SceneError(f"scene file {str(path)!r} not found; check the path.", file=str(path)) from None
    except UnicodeDecodeError as exc:
        line = path.read_bytes()[:exc.start].count(b"\n") + 1
        raise SceneError(
            f"the scene file is not UTF-8 text (byte 0x{exc.object[exc.start]:02x} cannot be "
            "decoded); save it as UTF-8 (e.g. `iconv -f latin1 -t utf-8`).",
            file=str(path), line=line,
        ) from None
    except OSError as exc:
        raise SceneError(f"cannot read the scene file: {exc}.", file=str(path)) from None
    return parse_scene(text, source=str(path), base_dir=path.parent)


def _line_of(path: tuple, locations: dict) -> int | None:
    """Line of ``path``, else of the nearest enclosing table or key that is written."""
    p = tuple(path)
    while p:
        if p in locations:
            return locations[p]
        p = p[:-1]
    return None


def _located(exc: Invalid, locations: dict, source: str) -> SceneError:
    table, _ = split_path(exc.path)
    # a missing key is reported at its table's header; an element at its array's key
    prefix = f"[{format_path(table)}] " if table and not exc.message.startswith("[") else ""
    return SceneError(
        prefix + exc.message,
        key=format_path(exc.path) or None,
        line=_line_of(exc.path, locations),
        file=source,
        suggestion=exc.suggestion,
    )


def scene_help() -> str:
    """The scene-file reference (tables, keys, types, units, defaults, allowed values).

    Generated from the schema that :func:`parse_scene` checks against, so it
    is always current. ``fem-elastic run --help`` prints it.

    Examples
    --------
    >>> print(scene_help().splitlines()[0])
    Scene files are TOML. Units are SI (m, s, kg, Pa, N); angles are in degrees.
    """
    return schema_help()


# ---------------------------------------------------------------------------------------
# the scene and its runs


@dataclass(frozen=True)
class BuiltRun:
    """One run of a scene, ready for :func:`fem_elastic.dynamics.simulate`.

    Attributes
    ----------
    name : str
        The variant's name.
    model : Model
    integrator : Integrator
        A fresh instance (integrators may keep per-run state).
    dt : float
        Time step (s).
    steps : int
        ``ceil(duration / dt)``.
    state : State
        Initial state.
    record_every : int
        Record a frame every this many steps.
    output : dict
        ``vtu`` (bool), ``render`` (list of "mp4", "gif", "png"),
        ``color_by`` ("von_mises" | "displacement"), ``size`` ((width, height) px),
        ``fps`` (frames/s), ``checkpoint_every`` (steps; 0 for checkpoints only on Ctrl-C).
    info : dict
        Plain values describing the run, for ``summary.json``.
    """

    name: str
    model: AnyModel
    integrator: Integrator | None
    dt: float
    steps: int
    state: State | None
    record_every: int
    output: dict
    info: dict
    static: dict | None = None

    @property
    def kind(self) -> str:
        """``"static"`` for a scene with ``[solve] kind = "static"``, else ``"dynamic"``."""
        return "dynamic" if self.static is None else "static"

    def solve(self, **options: Unpack[SolveOptions]) -> StaticResult:
        """Solve a static scene's run through :func:`fem_elastic.solve_static`.

        Parameters
        ----------
        **options
            Passed on to :func:`fem_elastic.solve_static`; ``steps``, ``stability``
            and ``stabilize`` default to the scene's ``[solve]`` table.

        Returns
        -------
        StaticResult
        """
        from ..solvers.static import solve_static

        if self.static is None:
            raise InvalidParameter(
                f'run "{self.name}" is dynamic: use .simulate() (or [solve] kind = "static" in the scene).'
            )
        settings = dict(self.static)
        settings.update(options)
        return solve_static(self.model, **settings)

    def simulate(self, **options: Unpack[SimulateOptions]) -> Trajectory:
        """Run it through :func:`fem_elastic.dynamics.simulate`.

        Parameters
        ----------
        **options
            Passed on to :func:`fem_elastic.dynamics.simulate` (``progress``,
            ``callback``, ``check_stability``, ...); the model, integrator,
            ``dt`` are this run's; ``steps`` (or ``t_end``), ``state`` and
            ``record_every`` default to this run's and may be overridden.

        Returns
        -------
        Trajectory
        """
        from ..dynamics.simulate import simulate

        if self.static is not None:
            raise InvalidParameter(
                f'run "{self.name}" is static ([solve] kind = "static"): use .solve() for its load path.'
            )
        settings: SimulateOptions = {"steps": self.steps, "state": self.state,
                                     "record_every": self.record_every}
        if "t_end" in options:  # an end time replaces the scene's step count
            settings.pop("steps")
        settings.update(options)
        # a dynamic run always has its integrator (None only for a static one, refused above)
        return simulate(self.model, cast("Integrator", self.integrator), self.dt, **settings)


@dataclass(frozen=True)
class Scene:
    """A checked scene file (see :func:`parse_scene`, :func:`load_scene`).

    Attributes
    ----------
    name, description : str
    source : str
        The file it was read from (or the ``source`` given to :func:`parse_scene`).
    spec : dict
        The validated document with every default filled in.
    variants : list of str
        Run names: the main body's first, then each ``[[compare]]``'s.
    base_dir : pathlib.Path
        Folder ``[mesh] path`` is relative to.
    locations : dict
        1-based line of each table and key in the source, by path
        (``("compare", 0, "body", "E")``), for messages about the scene.
    text : str
        The TOML text it was parsed from (kept with a run's output, for ``--resume``).
    """

    name: str
    description: str
    source: str
    spec: dict = field(repr=False)
    variants: list = field(default_factory=list)
    base_dir: Path = Path(".")
    locations: dict = field(default_factory=dict, repr=False, compare=False)
    text: str = field(default="", repr=False, compare=False)

    # errors at build time, placed in the file ---------------------------------------
    def _error(self, path: tuple, message: str, suggestion: str | None = None) -> SceneError:
        return _located(Invalid(path, message, suggestion), self.locations, self.source)

    def _guard(self, path: tuple, make, *args, **kwargs):
        """``make(*args, **kwargs)``, with a library InvalidParameter placed at ``path``."""
        try:
            return make(*args, **kwargs)
        except SceneError:
            raise
        except (InvalidParameter, FemElasticError) as exc:
            raise self._error(path, str(exc)) from None

    # building --------------------------------------------------------------------
    def build(self, variants: Sequence[str] | None = None) -> list[BuiltRun]:
        """Build the runs: one :class:`BuiltRun` per variant.

        Parameters
        ----------
        variants : sequence of str or None
            Names from :attr:`variants`; None builds all, in order.

        Returns
        -------
        list of BuiltRun

        Raises
        ------
        SceneError
            A boundary the mesh does not have, a mesh file that cannot be
            read, a vertex index out of range, an unknown variant name, or
            more steps (duration / dt) than a run takes.
        """
        names = list(self.variants) if variants is None else list(variants)
        for name in names:
            if name not in self.variants:
                near = closest(name, self.variants)
                hint = f' — did you mean "{near}"?' if near else "."
                raise SceneError(f'the scene has no run "{name}"{hint} Its runs: '
                                 f'{", ".join(self.variants)}.', key="variants", file=self.source,
                                 suggestion=near)
        if self.spec.get("bodies") is not None:  # [[body]] tables: one fe.MultiBody per run
            from .scene_bodies import build_bodies

            return [build_bodies(self, name) for name in names]
        if not self.static:
            self._steps()  # before the mesh: a wrong time table is cheap to tell
        mesh, mesh_info = self._mesh()
        self._check_boundaries(mesh)
        return [self._run(name, mesh, mesh_info) for name in names]

    @property
    def static(self) -> bool:
        """Whether the scene asks for a static solve (``[solve] kind = "static"``)."""
        return (self.spec.get("solve") or {}).get("kind") == "static"

    def mesh(self) -> MeshTet:
        """The scene's mesh (points in m), checked against the boundaries the scene names.

        What :meth:`build` gives every run, without building a model.

        Returns
        -------
        skfem.MeshTet

        Raises
        ------
        SceneError
            As :meth:`build`: a mesh file that cannot be read, a boundary the
            mesh does not have, a vertex index out of range.
        """
        if self.spec.get("bodies") is not None:  # [[body]] tables: the placed meshes as one
            return self.build()[0].model.mesh
        mesh, _ = self._mesh()
        self._check_boundaries(mesh)
        return mesh

    def _mesh(self, m=None, where=("mesh",)):
        """(mesh, info) of the ``[mesh]`` table, or of the mesh table ``m`` at path ``where``."""
        m = self.spec["mesh"] if m is None else m
        from ..geometry.mesh import beam_mesh

        if m["kind"] == "beam":
            mesh = self._guard(where, beam_mesh, m["length"], m["width"], m["height"], tuple(m["cells"]))
            info = {"kind": "beam", "length": m["length"], "width": m["width"], "height": m["height"],
                    "cells": list(m["cells"])}
        else:
            path = Path(m["path"])
            full = path if path.is_absolute() else self.base_dir / path
            if not full.is_file():
                raise self._error(where + ("path",), f'mesh file "{m["path"]}" not found (looked for '
                                  f"{full}; the path is relative to the scene file's folder).")
            from ..geometry.mesh_io import load_mesh

            try:
                mesh = load_mesh(full, reorient=m["reorient"])
            except Exception as exc:  # any reader failure is a problem of this file
                fix = " Try reorient = true." if "invert" in str(exc).lower() and not m["reorient"] else ""
                raise self._error(where + ("path",), f"cannot use the mesh file {full}: {exc}{fix}") from None
            info = {"kind": "file", "path": str(m["path"]), "reorient": m["reorient"]}
        if m["translate"] is not None:
            mesh = mesh.translated(tuple(m["translate"]))
            info["translate"] = list(m["translate"])
        info["n_vertices"], info["n_tets"] = int(mesh.p.shape[1]), int(mesh.t.shape[1])
        info["boundaries"] = sorted(mesh.boundaries or {})
        return mesh, info

    def _steps(self) -> int:
        """``ceil(duration / dt)``, checked against what :func:`fem_elastic.dynamics.simulate` runs."""
        from ..dynamics.simulate import MAX_STEPS

        dt, duration = self.spec["time"]["dt"], self.spec["time"]["duration"]
        ratio = duration / dt  # both finite and > 0 (the schema): inf only by overflow
        if not ratio <= MAX_STEPS:
            raise self._error(
                ("time", "duration"),
                f"duration = {duration:g} s at dt = {dt:g} s is {ratio:.3g} steps, more than the "
                f"{MAX_STEPS:.0e} a run takes: raise dt or shorten the duration (or split the run "
                "and continue it with fem-elastic run --resume).")
        # 1e-9: duration / dt in floating point may land a hair above an integer
        return max(1, math.ceil(ratio - 1e-9))

    def _boundary_check(self, mesh: MeshTet, what: str = "the mesh") -> Callable[[str, tuple], None]:
        """``check(name, path)``: a SceneError at ``path`` when ``mesh`` (``what``) has no boundary ``name``."""
        names = sorted(mesh.boundaries or {})
        known = ", ".join(f'"{n}"' for n in names) or "none (fix vertices by index instead)"

        def check(name: str, path: tuple) -> None:
            if name not in names:
                near = closest(name, names)
                hint = f' — did you mean "{near}"?' if near else "."
                raise self._error(path, f'{what} has no boundary "{name}"{hint} Its boundaries: '
                                        f"{known}.", near)

        return check

    def _check_boundaries(self, mesh) -> None:
        check = self._boundary_check(mesh)
        fixed = self.spec["boundary"]["fixed"]
        nv = mesh.p.shape[1]
        if isinstance(fixed, dict):
            for name in fixed:
                check(name, ("boundary", "fixed", name))
        else:
            for i, f in enumerate(fixed):
                if isinstance(f, str):
                    check(f, ("boundary", "fixed", i))
                elif f >= nv:
                    raise self._error(("boundary", "fixed", i), f"fixed vertex index {f} is out of range: "
                                      f"the mesh has {nv} vertices (0 to {nv - 1}).")
        for name in self.spec["boundary"].get("displacement") or {}:
            check(name, ("boundary", "displacement", name))
        for name in self.spec["loads"]["traction"]:
            check(name, ("loads", "traction", name))
        for i, d in enumerate(self.spec["loads"]["driven"]):
            check(d["boundary"], ("loads", "driven", i, "boundary"))

    def _variant(self, name: str):
        """(body spec, its path, integrator spec, its path) of a variant."""
        spec = self.spec
        if name == spec["body"]["name"]:
            return spec["body"], ("body",), spec["integrator"], ("integrator",)
        for i, c in enumerate(spec["compare"]):
            if c["name"] == name:
                body, bpath = (c["body"], ("compare", i, "body")) if c["body"] else (spec["body"], ("body",))
                integ, ipath = ((c["integrator"], ("compare", i, "integrator")) if c["integrator"]
                                else (spec["integrator"], ("integrator",)))
                return body, bpath, integ, ipath
        raise KeyError(name)  # pragma: no cover - names are checked in build()

    def _body(self, body: dict, path: tuple):
        if body["type"] == "fem":
            from ..physics.elastic_body import ElasticBody

            if body.get("mu") is not None:  # Lame's pair: exact where nu = 0.4999999 loses digits
                material = self._guard(path, MATERIALS[body["material"]], mu=body["mu"], lam=body["lam"])
            else:
                material = self._guard(path, MATERIALS[body["material"]], E=body["E"], nu=body["nu"])
            return self._guard(path + ("order",), ElasticBody, material, order=body["order"],
                               formulation=body.get("formulation", "displacement"))
        from ..physics.springs import MassSpring

        return self._guard(path, MassSpring, E=body["E"], nu=body["nu"],
                           calibration=CALIBRATIONS[body["calibration"]], k_d=body["k_d"])

    def _terms(self):
        """Model keywords for the loads, ground, damping and driven boundaries that are declared."""
        from ..physics.obstacles import Ground
        from ..physics.damping import Rayleigh
        from ..physics.driven import Translate, Twist

        spec, terms = self.spec, {}
        loads = spec["loads"]
        if spec["boundary"]["fixed"]:
            fixed = spec["boundary"]["fixed"]
            terms["fixed"] = dict(fixed) if isinstance(fixed, dict) else fixed
        if spec["boundary"].get("displacement"):
            terms["displacement"] = {k: tuple(v) for k, v in spec["boundary"]["displacement"].items()}
        if loads["gravity"] is not None:
            terms["gravity"] = tuple(loads["gravity"])
        if loads["traction"]:
            terms["traction"] = {k: tuple(v) for k, v in loads["traction"].items()}
        if loads["driven"]:
            driven = {}
            for i, d in enumerate(loads["driven"]):
                path = ("loads", "driven", i)
                if d["boundary"] in driven:
                    raise self._error(path + ("boundary",), f'boundary "{d["boundary"]}" is driven '
                                      "twice; give each boundary one motion.")
                if d["motion"] == "twist":
                    driven[d["boundary"]] = self._guard(
                        path, Twist, math.radians(d["angle"]), d["duration"], axis=tuple(d["axis"]),
                        center=None if d["center"] is None else tuple(d["center"]), release=d["release"])
                else:
                    driven[d["boundary"]] = self._guard(
                        path, Translate, tuple(d["offset"]), d["duration"], release=d["release"])
            terms["driven"] = driven
        g = spec["ground"]
        if g is not None:
            options = {k: v for k, v in g.items() if k not in ("z",) and v is not None}
            terms["ground"] = self._guard(("ground",), Ground, z=g["z"], **options)
        d = spec["damping"]
        if d is not None:
            terms["damping"] = self._guard(("damping",), Rayleigh, d["alpha"], d["beta"])
        c = spec.get("contact")
        if c is not None and c["type"] == "ipc":
            from ..physics.ipc_contact import IPCContact

            terms["contact"] = self._guard(
                ("contact",), IPCContact, c["dhat"], kappa="auto" if c["kappa"] is None else c["kappa"],
                friction=c["friction"], epsv=c["epsv"], self_contact=c["self_contact"])
        elif c is not None and c["type"] == "impulse":
            from ..physics.impulse_contact import ImpulseContact

            terms["contact"] = self._guard(
                ("contact",), ImpulseContact, restitution=c["restitution"], friction=c["friction"],
                thickness=c["thickness"], self_contact=c["self_contact"])
        return terms

    def _run(self, name: str, mesh, mesh_info: dict) -> BuiltRun:
        from ..physics.model import Model
        from ..dynamics.state import State

        spec = self.spec
        body, bpath, integ, ipath = self._variant(name)
        model = self._guard(bpath, Model, mesh, body["density"], self._body(body, bpath), **self._terms())
        if self.static:
            return self._static_run(name, model, body, mesh_info)
        integrator = self._guard(ipath, make_integrator, integ)
        dt = spec["time"]["dt"]
        steps = self._steps()
        initial = spec["initial"]
        state = State.rest(model) if initial is None else self._guard(
            ("initial", "velocity"), State.rest, model, velocity=tuple(initial["velocity"]))
        out = spec["output"]
        return BuiltRun(
            name=name, model=model, integrator=integrator, dt=dt, steps=steps, state=state,
            record_every=out["every"], output=self._output(out["checkpoint_every"]),
            info=self._info(name, body, integ, integrator, mesh_info, steps),
        )

    def _static_run(self, name: str, model, body: dict, mesh_info: dict) -> BuiltRun:
        """A run of a static scene: the model and the load steps of ``[solve]``."""
        from ..dynamics.state import State

        solve = self.spec["solve"]
        static = {"steps": solve["steps"], "stability": solve["stability"],
                  "stabilize": solve["stabilize"], "linear_solver": solve["linear_solver"]}
        info = self._info(name, body, None, None, mesh_info, solve["steps"])
        return BuiltRun(
            name=name, model=model, integrator=None, dt=0.0, steps=solve["steps"],
            state=State.rest(model), record_every=1, output=self._output(0), info=info, static=static,
        )

    def _output(self, checkpoint_every: int) -> dict:
        """``BuiltRun.output``: the ``[output]`` table's settings of the renders and the series."""
        out = self.spec["output"]
        return {"vtu": out["vtu"], "render": list(out["render"]), "color_by": out["color_by"],
                "size": tuple(out["size"]), "fps": out["fps"], "checkpoint_every": checkpoint_every}

    def _info(self, name, body, integ, integrator, mesh_info, steps) -> dict:
        spec = self.spec
        if body["type"] == "fem":
            described = f'{MATERIALS[body["material"]].__name__} FEM, P{body["order"]} tets'
            if body.get("formulation", "displacement") == "mixed":
                described += " + pressure (mixed)"
            body_info = {"type": "fem", "material": body["material"], "order": body["order"]}
        else:
            described = f'mass-spring ({body["calibration"]} calibration)'
            body_info = {"type": "springs", "calibration": body["calibration"], "k_d": body["k_d"],
                         "order": 1}
        if body.get("mu") is not None:  # Lame's pair (a fem body's): E and nu derived, for reference
            c = elastic_constants(mu=body["mu"], lam=body["lam"], who="[body]")
            body_info.update({"mu": body["mu"], "lam": body["lam"], "E": c.E, "nu": c.nu})
        else:
            body_info.update({"E": body["E"], "nu": body["nu"]})
        body_info["density"] = body["density"]
        if body["type"] == "fem" and body.get("formulation", "displacement") != "displacement":
            body_info["formulation"] = body["formulation"]
        g = spec["ground"]
        d = spec["damping"]
        return {
            "scene": self.name,
            "description": self.description,
            "variant": name,
            "body": described,
            **body_info,
            "body_spec": dict(body),
            "mesh": dict(mesh_info),
            "n_vertices": mesh_info["n_vertices"],
            "n_tets": mesh_info["n_tets"],
            "fixed": (dict(spec["boundary"]["fixed"]) if isinstance(spec["boundary"]["fixed"], dict)
                      else list(spec["boundary"]["fixed"])),
            "prescribed_displacement": {k: list(v) for k, v in
                                        (spec["boundary"].get("displacement") or {}).items()},
            "gravity": None if spec["loads"]["gravity"] is None else list(spec["loads"]["gravity"]),
            "traction": {k: list(v) for k, v in spec["loads"]["traction"].items()},
            "probe": {k: list(v) for k, v in ((spec.get("probe") or {}).get("points") or {}).items()},
            "driven": [dict(x) for x in spec["loads"]["driven"]],
            "ground": None if g is None else {"kind": "plane", "z": g["z"], "method": g["method"]},
            "damping": None if d is None else {"alpha": d["alpha"], "beta": d["beta"]},
            "initial_velocity": None if spec["initial"] is None else list(spec["initial"]["velocity"]),
            **({"solve": "static", "load_steps_planned": steps, "stability": spec["solve"]["stability"],
                "stabilize": spec["solve"]["stabilize"]} if integrator is None else {
                "integrator": integrator.name,
                "integrator_options": {k: v for k, v in integ.items() if k != "type"},
                "dt": spec["time"]["dt"],
                "duration": spec["time"]["duration"],
                "steps_planned": steps,
            }),
        }
