"""The bad inputs a user can give fem_elastic, and what each one gets.

One list, :data:`BAD_INPUTS`, walked by ``tests/test_bad_inputs.py`` (each
entry is tried and must give exactly its documented outcome) and printed as
the README's table "Bad input and what you get" by
``scripts/bad_inputs_table.py`` (``--write`` puts it in the README; the test
checks the README holds exactly :func:`markdown_table`).

Each entry is a :class:`BadInput`: the input in a user's words, a function
that tries it on a tiny model (each well under a second), the outcome (an
error class, a warning class, or the exit status of ``fem-elastic``), a
fragment of the message naming the problem and one naming the fix. The table
quotes those fragments, so what it says is what the test checks.

This module is not a test module (no ``test_`` prefix): it holds data.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

import fem_elastic as fe

__all__ = ["BadInput", "BAD_INPUTS", "START_MARKER", "END_MARKER", "markdown_table", "outcome_name", "cracked_beam"]

START_MARKER = "<!-- bad-inputs:start -->"
END_MARKER = "<!-- bad-inputs:end -->"


@dataclasses.dataclass(frozen=True)
class BadInput:
    """One bad input and what the user gets for it.

    Attributes
    ----------
    name : str
        The input in a user's words ("Poisson ratio nu = 0.5").
    attempt : callable
        ``attempt(tmp)`` tries it; ``tmp`` is an empty folder (``pathlib.Path``)
        for files it writes. For a command-line entry it returns the argument
        list of ``fem-elastic`` instead (the test runs ``fem_elastic.app.cli.main``).
    outcome : type or int
        The error class raised, the warning class issued (the call then
        returns normally), or the exit status of the command.
    problem, fix : str
        Fragments of the message (the command's stderr and stdout): one names
        what is wrong, the other what to do.
    note : str
        More words for the table's "what you get", checked by ``check``.
    check : callable or None
        ``check(error)`` (or ``check(result)`` for a warning) asserts what
        ``note`` claims, e.g. the attributes a ``fe.Diverged`` carries.
    xfail_reason : str or None
        Set while the library gets this input wrong: the test is a strict
        xfail (it fails loudly once fixed, so the entry is updated) and the
        README table leaves the entry out, to stay true.
    """

    name: str
    attempt: Callable
    outcome: type | int
    problem: str
    fix: str
    note: str = ""
    check: Callable | None = None
    xfail_reason: str | None = None

    @property
    def kind(self) -> str:
        """``"exit"`` (the command), ``"warns"`` or ``"raises"``."""
        if isinstance(self.outcome, int):
            return "exit"
        return "warns" if issubclass(self.outcome, Warning) else "raises"


# -- tiny models ---------------------------------------------------------------------------
def _mesh():
    """A 1 m x 0.1 m x 0.1 m beam of 2 cells (12 vertices, 12 tets)."""
    return fe.beam_mesh(cells=(2, 1, 1))


def _body(material=None):
    return fe.ElasticBody(material or fe.LinearElastic(E=1e6, nu=0.3))


def _model(mesh=None, **options):
    options.setdefault("fixed", "left")
    return fe.Model(_mesh() if mesh is None else mesh, density=1000.0, body=_body(), **options)


def _partition(mesh, nparts):
    from fem_elastic.solvers.partition import partition_elements

    return partition_elements(mesh.t, nparts)


def _inverted_mesh():
    mesh = _mesh()
    t = mesh.t.T.copy()
    t[0, [0, 1]] = t[0, [1, 0]]  # swap two vertices of tet 0: negative volume
    return fe.mesh_from_arrays(mesh.p.T, t, validate=False)


def _overlapping_cubes():
    """Two unit-cell cubes, the second pushed half into the first: one mesh, two pieces."""
    cube = fe.beam_mesh(length=0.1, width=0.1, height=0.1, cells=(1, 1, 1))
    P, T = cube.p.T, cube.t.T
    return fe.mesh_from_arrays(np.vstack([P, P + [0.05, 0.01, 0.02]]), np.vstack([T, T + len(P)]))


_TET = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]


def _simulate(model, integrator, dt=0.01, **options):
    options.setdefault("steps", 1)
    return fe.simulate(model, integrator, dt, **options)


def _blow_up(tmp):
    """Symplectic Euler at 5 x its stable step, the warning switched off: it blows up."""
    model = _model(gravity=(0.0, 0.0, -9.81))
    return fe.simulate(model, fe.SymplecticEuler(), dt=0.01, steps=200, check_stability=False)


def _stopped_run(tmp, dt=0.01):
    """A run stopped (Ctrl-C) after 2 of 4 steps, its checkpoint in ``tmp/ck``."""
    def stop(k, state):
        if k == 2:
            raise KeyboardInterrupt
    try:
        fe.simulate(_model(gravity=(0.0, 0.0, -9.81)), fe.ImplicitEuler(), dt, steps=4,
                    checkpoint_dir=Path(tmp) / "ck", callback=stop)
    except KeyboardInterrupt:
        pass
    return Path(tmp) / "ck"


def _resume_other_run(tmp):
    ck = _stopped_run(tmp)
    return fe.simulate(_model(gravity=(0.0, 0.0, -9.81)), fe.ImplicitEuler(), 0.02, steps=4,
                       checkpoint_dir=ck, resume=True)


def _resume_damaged(tmp):
    ck = _stopped_run(tmp)
    (ck / "checkpoint.npz").write_bytes(b"half a file")
    return fe.simulate(_model(gravity=(0.0, 0.0, -9.81)), fe.ImplicitEuler(), 0.01, steps=4,
                       checkpoint_dir=ck, resume=True)


def _check_diverged(err) -> None:
    assert isinstance(err.last_good_state, fe.State) and err.last_good_state.t == err.time
    # the failed step starts at step * dt (s), up to the round-off of adding dt step times
    assert err.step >= 1 and math.isclose(err.time, err.step * 0.01, rel_tol=1e-12)
    assert "energy" in err.reason
    traj = err.trajectory  # every step recorded: the frames up to the last good state
    assert isinstance(traj, fe.Trajectory) and traj.times.size == err.step + 1
    assert np.all(np.isfinite(traj.displacement))


def _unreachable_load(tmp):
    """A soft beam pulled by 1e7 Pa, two Newton iterations per load step, at most 4 load steps."""
    model = fe.Model(_mesh(), density=1000.0, body=_body(fe.NeoHookean(E=1e3, nu=0.3)), fixed="left",
                     traction={"right": (0.0, 0.0, -1e7)})
    return fe.solve_static(model, max_iter=2, min_load_step=0.25)


def _check_not_converged(err) -> None:
    assert isinstance(err.result, fe.StaticResult) and not err.result.converged
    assert err.result.load_factor < 1.0


def _motion_that_raises(tmp):
    """A user motion that raises at t > 0.015 s: step 2 of a run fails."""
    def pull(X, t):
        if t > 0.015:
            raise ValueError("my motion table ends at 0.015 s")
        return np.zeros_like(X)

    return _simulate(_model(driven={"right": fe.Prescribed(pull)}), fe.ImplicitEuler(), steps=4)


def _check_step_failed(err) -> None:
    assert isinstance(err, fe.Diverged) and isinstance(err.__cause__, ValueError)
    assert err.step == 1 and err.reason.startswith("ValueError")
    assert err.trajectory.times.size == 2 and err.last_good_state.t == err.time


def _nan_in_state(tmp):
    model = _model()
    x = model.X.copy()
    x[4] = np.nan
    return _simulate(model, fe.ImplicitEuler(), state=fe.State(x, np.zeros_like(x)))


# -- scene files -----------------------------------------------------------------------------
SCENE = """\
[mesh]
kind = "beam"
cells = [2, 1, 1]
[body]
material = "linear"
E = 1e6
nu = 0.3
density = 1000.0
[boundary]
fixed = ["left"]
[integrator]
type = "implicit_euler"
[time]
dt = 0.01
duration = 0.02
"""


STATIC_SCENE = """
[mesh]
kind = "beam"
cells = [2, 1, 1]
[body]
material = "linear"
E = 1e6
nu = 0.3
density = 1000.0
[boundary]
fixed = { left = "xyz" }
[solve]
kind = "static"
"""


def _compressed_cube():
    """A P2 cube of one cell fixed at its bottom, its top pushed down by 5e5 Pa: Newton
    converges to the straight state, whose tangent has a negative eigenvalue."""
    return fe.Model(fe.beam_mesh(1.0, 1.0, 1.0, cells=(1, 1, 1)), 1000.0,
                    fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3), order=2), fixed="bottom",
                    traction={"top": (0.0, 0.0, -5e5)})


def _scene(old, new):
    """The scene with one edit, parsed and built (names are checked against the mesh at build)."""
    assert old in SCENE, old
    return fe.parse_scene(SCENE.replace(old, new, 1), source="scene.toml").build()


def _check_suggestion(expected):
    def check(err):
        assert err.suggestion == expected and err.line is not None and err.file == "scene.toml"
    return check


def _write(tmp, name, text):
    path = Path(tmp) / name
    path.write_text(text)
    return path


def _write_bytes(tmp, name, data: bytes):
    path = Path(tmp) / name
    path.write_bytes(data)
    return path


def _cli_scene(tmp, old, new, *options):
    assert old in SCENE, old
    path = _write(tmp, "scene.toml", SCENE.replace(old, new, 1))
    return ["run", str(path), "--out", str(Path(tmp) / "out"), "--quiet", "--no-render", *options]


def _without_sympy(tmp):
    """fe.material_from_energy as if sympy were not installed (``import sympy`` fails)."""
    import sys

    saved = sys.modules.get("sympy")
    sys.modules["sympy"] = None  # makes `import sympy` raise ModuleNotFoundError
    try:
        return fe.material_from_energy(lambda I1, I2, J, mu: mu / 2 * (I1 - 3 - 2 * fe.math.log(J)), mu=1e6)
    finally:
        if saved is None:
            del sys.modules["sympy"]
        else:
            sys.modules["sympy"] = saved


# -- the list ----------------------------------------------------------------------------------
IP, IM, SE = fe.InvalidParameter, fe.InvalidMesh, fe.SceneError

# -- output directories, resources, contradictions, checkpoints (issue 18) -------------------------
def _check_holder(err):
    import os

    assert err.pid == os.getpid()


def _check_limit(available):
    def check(err):
        assert err.available == available and err.needed > available
    return check


def _second_run(tmp):
    """A run into a directory whose lock is held (here by this process, through another descriptor)."""
    from fem_elastic.app.run_lock import RunLock
    from fem_elastic.app.runner import run_scene

    out = Path(tmp) / "out"
    out.mkdir()
    with RunLock(out):
        return run_scene(fe.parse_scene(SCENE, source="scene.toml"), out, render=False)


def _fake_run(tmp):
    """A run directory as a render sees it: series.pvd and frames/."""
    run = Path(tmp) / "out" / "fem"
    (run / "frames").mkdir(parents=True, exist_ok=True)
    (run / "series.pvd").write_text("<VTKFile/>")
    return run


def _fifo(tmp):
    import os

    path = Path(tmp) / "scene.toml"
    os.mkfifo(path)
    return path


def _sparse(tmp, size):
    path = Path(tmp) / "huge.toml"
    with open(path, "wb") as fh:
        fh.truncate(size)  # sparse: no disk used
    return path


def _with_env(name, value, call):
    import os

    old = os.environ.get(name)
    os.environ[name] = value
    try:
        return call()
    finally:
        if old is None:
            del os.environ[name]
        else:
            os.environ[name] = old


def _too_big(tmp):
    return _with_env("FEM_ELASTIC_MEMORY_LIMIT", "256K", lambda: fe.Model(
        fe.beam_mesh(cells=(10, 3, 3)), density=1000.0, body=_body(), fixed="left"))


def _disk_full(tmp):
    from fem_elastic.app.runner import run_scene

    scene = fe.parse_scene(SCENE, source="scene.toml")
    return _with_env("FEM_ELASTIC_DISK_LIMIT", "1K", lambda: run_scene(scene, Path(tmp) / "out", render=False))


def cracked_beam(cells, layer):
    """A unit-length beam whose vertices on the plane x = layer / cells[0] are duplicated for the
    tets beyond it (a hidden crack): ``(points, tets, number of duplicated vertices)``."""
    mesh = fe.beam_mesh(length=1.0, cells=cells)
    p, t = mesh.p.T.copy(), mesh.t.T.copy()
    x0 = layer / cells[0]
    on = np.flatnonzero(np.isclose(p[:, 0], x0))
    beyond = p[t].mean(axis=1)[:, 0] > x0
    tb = t[beyond]
    for i, v in enumerate(on):
        tb[tb == v] = len(p) + i
    t[beyond] = tb
    return np.vstack([p, p[on]]), t, on.size


def _cracked_mesh():
    """The 2-cell beam cut at x = 0.5: the right cell's tets get their own copies of the plane's 4 vertices."""
    points, tets, _ = cracked_beam((2, 1, 1), 1)
    return fe.mesh_from_arrays(points, tets)


def _loose_piece(tmp):
    """Two 2-cell beams 0.5 m apart, only the lower one fixed: the upper one floats."""
    p, t = _mesh().p.T, _mesh().t.T
    mesh = fe.mesh_from_arrays(np.vstack([p, p + (0.0, 0.0, 0.5)]), np.vstack([t, t + len(p)]))
    fixed = np.flatnonzero(np.isclose(mesh.p[0], 0.0) & (mesh.p[2] < 0.3))
    return fe.solve_static(fe.Model(mesh, density=1000.0, body=_body(), fixed=fixed, gravity=(0.0, 0.0, -9.81)))


def _resume_altered(tmp):
    ck = _stopped_run(tmp)
    data = bytearray((ck / "frames.f64").read_bytes())
    data[8] ^= 0x01  # one bit of the first frame's kinetic energy
    (ck / "frames.f64").write_bytes(bytes(data))
    return fe.simulate(_model(gravity=(0.0, 0.0, -9.81)), fe.ImplicitEuler(), 0.01, steps=4,
                       checkpoint_dir=ck, resume=True)


def _resume_edited_scene(tmp):
    from fem_elastic.app import cli

    args = _cli_scene(tmp, "", "")
    out = Path(args[3])
    assert cli.main(args) == 0
    copy = out / "scene.toml"
    copy.write_text(copy.read_text().replace("E = 1e6", "E = 2e6"))
    return ["run", "--resume", str(out), "--quiet"]


BAD_INPUTS: list[BadInput] = [
    # materials and the model
    BadInput("Poisson ratio nu = 0.5", lambda tmp: fe.NeoHookean(E=1e6, nu=0.5), IP,
             "nu must be < 0.5", "Use a value such as 0.49 or 0.499"),
    BadInput("Young's modulus E <= 0", lambda tmp: fe.StVK(E=0.0, nu=0.3), IP,
             "E must be > 0 Pa, got E = 0.0", "Pass the stiffness in pascals, e.g. E=1e6"),
    BadInput("two pairs of elastic constants (E, nu and mu, lam)",
             lambda tmp: fe.NeoHookean(E=1e6, nu=0.3, mu=4e5, lam=6e5), IP,
             "NeoHookean got E and nu and mu and lam", "give exactly one pair of (E, nu), (mu, lam) or (mu, K)"),
    BadInput("a lone shear modulus (fe.StVK(mu=4e5))", lambda tmp: fe.StVK(mu=4e5), IP,
             "StVK got mu", "give exactly one pair of (E, nu), (mu, lam) or (mu, K)"),
    BadInput("a negative bulk modulus (mu=4e5, K=-1e6)", lambda tmp: fe.Corotated(mu=4e5, K=-1e6), IP,
             "the bulk modulus K must be > 0 Pa, got K = -1000000.0", "e.g. K=1e9"),
    BadInput("an energy whose first arguments are not F or I1, I2, J",
             lambda tmp: fe.material_from_energy(lambda C, mu: mu * C, mu=1e6), IP,
             "its first arguments are named ('C', 'mu')",
             "psi(F, <params>) (an energy of the deformation gradient) or psi(I1, I2, J, <params>)"),
    BadInput("an energy parameter left out",
             lambda tmp: fe.material_from_energy(fe.energies.neo_hookean, mu=1e6), IP,
             "the energy neo_hookean needs a value for lam", "pass lam=... to material_from_energy"),
    BadInput("an energy parameter it does not have",
             lambda tmp: fe.material_from_energy(fe.energies.neo_hookean, mu=1e6, lam=2e6, kappa=1e9), IP,
             "the energy neo_hookean has no parameter kappa", "its parameters are ['mu', 'lam']"),
    BadInput("an energy written with numpy.log",
             lambda tmp: fe.material_from_energy(lambda I1, I2, J, mu: mu * (I1 - 3 - 2 * np.log(J)), mu=1e6),
             IP, "could not be evaluated on symbols", "write psi with fe.math (fe.math.log"),
    BadInput("an energy that returns a matrix",
             lambda tmp: fe.material_from_energy(lambda F, mu: mu * (F.T @ F), mu=1e6), IP,
             "must return one scalar energy density (J/m^3), got a MutableDenseMatrix of shape (3, 3)",
             "sum its terms into one number"),
    BadInput("fe.material_from_energy without sympy installed", _without_sympy, fe.MissingDependency,
             "derives the energy's derivatives with sympy, which is not installed",
             'pip install "fem_elastic[energy]"'),
    BadInput("density <= 0", lambda tmp: fe.Model(_mesh(), density=-1.0, body=_body()), IP,
             "density must be finite and > 0 kg/m^3, got -1.0", "e.g. 1000.0 for rubber-like solids"),
    BadInput("element order 3", lambda tmp: fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3), order=3), IP,
             "element order must be 1 (linear tets) or 2 (quadratic tets), got 3",
             "1 (linear tets) or 2 (quadratic tets)"),
    BadInput("a material where the body goes (body=fe.NeoHookean(...))",
             lambda tmp: fe.Model(_mesh(), density=1000.0, body=fe.NeoHookean(E=1e6, nu=0.3)), IP,
             "got NeoHookean(E=1000000.0, nu=0.3)", "body must be e.g. fe.ElasticBody(fe.NeoHookean"),
    BadInput("a static problem with rigid-body motion left free (nothing fixed)",
             lambda tmp: fe.solve_static(_model(fixed=None, gravity=(0.0, 0.0, -9.81))), fe.UnderConstrained,
             "the model fixes nothing", "Fix a boundary, e.g. fe.Model(..., fixed='left')"),
    BadInput("a static problem fixed only along one line of vertices",
             lambda tmp: fe.solve_static(_model(fixed=[0, 1], gravity=(0.0, 0.0, -9.81))), fe.UnderConstrained,
             "leave 1 rigid-body mode(s) free",
             "Fix a whole face (fixed='left') or at least three vertices that are not on one line"),
    BadInput("supports given as components the library does not know (fixed={\"left\": (1, 0, 0)})",
             lambda tmp: _model(fixed={"left": (1, 0, 0)}), IP,
             "fixed['left'] must be a string of the components held",
             'or a bool triple such as (True, False, True)'),
    BadInput("rollers only, leaving rigid motions free (fixed={\"left\": \"x\"})",
             lambda tmp: fe.solve_static(_model(fixed={"left": "x"}, gravity=(0.0, 0.0, -9.81))),
             fe.UnderConstrained, "leave 3 rigid-body mode(s) free: translation along y; translation along z",
             "add component-wise supports that hold the motions named"),
    BadInput("a component both fixed and prescribed",
             lambda tmp: _model(fixed={"left": "xyz", "front": "x"}, displacement={"right": (0.01, None, None)}),
             IP, "boundary 'right' is prescribed a displacement in component(s) 'x'",
             "a DOF is either fixed or prescribed. Drop 'x' from one of them"),
    BadInput("a prescribed displacement with two components (displacement={\"right\": (0.01, None)})",
             lambda tmp: _model(displacement={"right": (0.01, None)}), IP,
             "must be three components (ux, uy, uz) in metres", "None for a free one, e.g. (0.01, None, None)"),
    BadInput("a static solve in zero load steps (steps=0)",
             lambda tmp: fe.solve_static(_model(gravity=(0.0, 0.0, -9.81)), steps=0), IP,
             "steps must be a whole number >= 1", "e.g. steps=10"),
    BadInput("a static equilibrium that is a saddle (a cube compressed past its stability limit)",
             lambda tmp: fe.solve_static(_compressed_cube()), fe.UnstableEquilibrium,
             "converged to an unstable equilibrium", "Pass stabilize=True to perturb it along its lowest mode"),
    BadInput("nu so close to 0.5 that lambda / mu ~ 1 / eps (nu* = 0.49999999999999994)",
             lambda tmp: fe.solve_static(fe.Model(_mesh(), 1000.0, _body(fe.LinearElastic(E=1e3, nu=0.49999999999999994)),
                                                  fixed="left", traction={"right": (0.0, -1.3, 0.0)})),
             fe.RoundoffWarning, "the stiffness's shear part is lost below the round-off",
             "Use nu <= 0.4999999 (lambda / mu <= 5e6), or a mixed formulation"),
    BadInput("a static scene with a time table",
             lambda tmp: fe.parse_scene(STATIC_SCENE + "[time]\ndt = 0.01\nduration = 1.0\n", source="scene.toml"),
             SE, "[time] applies only to a dynamic scene", 'remove [time]'),
    BadInput("a fixed boundary the mesh does not have (fixed=\"lefft\")", lambda tmp: _model(fixed="lefft"), IP,
             "fixed names boundary 'lefft', which the mesh does not have",
             "its boundaries are ['back', 'bottom', 'front', 'left', 'right', 'top']"),
    BadInput("a traction on a boundary that does not exist",
             lambda tmp: _model(traction={"rigth": (0.0, 0.0, -1e3)}), IP,
             "traction names boundary 'rigth', which the mesh does not have",
             "its boundaries are ['back', 'bottom', 'front', 'left', 'right', 'top']"),
    BadInput("a traction given as a list, not {boundary: vector}",
             lambda tmp: _model(traction=[(0.0, 0.0, -1e3)]), IP,
             "got [(0.0, 0.0, -1000.0)]", "traction must be a dict {boundary name: traction vector (Pa)}"),
    BadInput("a fixed vertex index out of range", lambda tmp: _model(fixed=[0, 999]), IP,
             "fixed vertex indices must lie in [0, 11], got values from 0 to 999", "must lie in [0, 11]"),
    BadInput("gravity with two components", lambda tmp: _model(gravity=(0.0, -9.81)), IP,
             "gravity must be three finite numbers (m/s^2)", "e.g. (0.0, 0.0, -9.81)"),
    BadInput("an obstacle class instead of an instance (ground=fe.Ground)", lambda tmp: _model(ground=fe.Ground),
             IP, "got <class 'fem_elastic.physics.obstacles.Ground'>", "ground must be an obstacle such as fe.Ground(z=0.0)"),
    BadInput("a ground through the body's start (penalty contact)",
             lambda tmp: _model(fixed=None, gravity=(0.0, 0.0, -9.81), ground=fe.Ground(z=0.05)), IP,
             "node(s) of the reference configuration start inside Ground(",
             "Move the mesh (mesh.translated(...)) or the obstacle"),
    BadInput("a barrier ground touching the body's start",
             lambda tmp: _model(fixed=None, ground=fe.Ground(z=0.0, method="barrier")), IP,
             "are not strictly outside Ground(", "so the body starts with a gap, e.g. dhat / 2"),
    BadInput("negative Rayleigh damping", lambda tmp: fe.Rayleigh(alpha=-1.0), IP,
             "Rayleigh damping alpha must be a finite number >= 0 (1/s), got -1.0", "a finite number >= 0"),
    BadInput("impulse contact with restitution above 1", lambda tmp: fe.ImpulseContact(restitution=1.5), IP,
             "restitution must be a number in [0, 1], got 1.5", "(0: no bounce, 1: elastic bounce)"),
    BadInput("impulse contact with a thickness of 0", lambda tmp: fe.ImpulseContact(thickness=0.0), IP,
             "thickness must be a finite distance > 0 (m), got 0.0", "e.g. thickness=1e-3"),
    BadInput("impulse contact with implicit Euler",
             lambda tmp: fe.ImplicitEuler().step(m := _model(contact=fe.ImpulseContact()), fe.State.rest(m), 1e-3),
             IP, "fe.ImplicitEuler cannot apply fe.ImpulseContact",
             "Use contact=fe.IPCContact(dhat=...) with this solver"),
    BadInput("IPC contact with dhat = 0", lambda tmp: fe.IPCContact(dhat=0.0), IP,
             "dhat must be a finite number > 0", "e.g. 1e-3 for a body of about 1 m"),
    BadInput("two bodies overlapping at t = 0 with IPC contact",
             lambda tmp: fe.Model(_overlapping_cubes(), density=1000.0, body=_body(),
                                  contact=fe.IPCContact(dhat=1e-3, kappa=1e4)), IP,
             "surfaces intersect in the reference configuration (overlapping bodies at t = 0)",
             "Move the bodies apart"),
    # meshes
    BadInput("an inverted element in the mesh", lambda tmp: _model(_inverted_mesh()), IM,
             "1 tets are inverted (negative signed volume): elements [0]", "fem_elastic.reorient(mesh)"),
    BadInput("a degenerate (zero-volume) tet",
             lambda tmp: fe.mesh_from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2, 3]]), IM,
             "1 tets have (nearly) zero volume", "remesh (e.g. TetGen or gmsh with a quality constraint)"),
    BadInput("NaN in the mesh coordinates",
             lambda tmp: fe.mesh_from_arrays(np.array(_TET) * [[1, 1, 1], [1, 1, 1], [1, 1, 1], [1, 1, np.nan]],
                                             [[0, 1, 2, 3]]), IM,
             "1 vertices have NaN or infinite coordinates: vertices [3]",
             "drop those vertices and the tets that use them"),
    BadInput("a tet index out of range", lambda tmp: fe.mesh_from_arrays(_TET, [[0, 1, 2, 4]]), IM,
             "1 tets refer to vertex indices outside [0, 3]", "0-based indices are expected"),
    BadInput("a vertex that no tet uses", lambda tmp: fe.mesh_from_arrays(_TET + [[5.0, 5.0, 5.0]], [[0, 1, 2, 3]]),
             IM, "1 vertices are not used by any tet", "fem_elastic.remove_unused_vertices(mesh)"),
    BadInput("a hexahedral mesh", lambda tmp: _model(__import__("skfem").MeshHex()), IM,
             "A tetrahedral mesh (skfem.MeshTet) is needed, got MeshHex1",
             "a MeshHex can be split with skfem.MeshTet.init_tensor"),
    BadInput("a mesh file meshio cannot read", lambda tmp: fe.load_mesh(_write(tmp, "broken.vtu", "garbage")), IM,
             "meshio could not read", "Check that it is a tet mesh in that format"),
    BadInput("a mesh file with an unknown extension", lambda tmp: fe.load_mesh(_write(tmp, "beam.xyz", "1 2 3\n")),
             IP, "Unknown mesh file extension", "use .vtu (or gmsh's .msh) for tet meshes"),
    # time stepping
    BadInput("dt <= 0", lambda tmp: _simulate(_model(), fe.ImplicitEuler(), dt=0.0), IP,
             "dt must be a finite number > 0 (s), got 0.0", "e.g. dt=1e-3"),
    BadInput("dt = nan", lambda tmp: _simulate(_model(), fe.ImplicitEuler(), dt=float("nan")), IP,
             "dt must be a finite number > 0 (s), got nan", "e.g. dt=1e-3"),
    BadInput("a negative velocity tolerance (velocity_tol = -1e-3 m/s)",
             lambda tmp: fe.ImplicitEuler(velocity_tol=-1e-3), IP,
             "velocity_tol must be a finite number >= 0", "0 turns it off"),
    BadInput("an end time too far away (t_end = 1e308 s)",
             lambda tmp: _simulate(_model(), fe.SymplecticEuler(), dt=1e-3, steps=None, t_end=1e308), IP,
             "inf steps asked", "raise dt or split the run"),
    BadInput("t_end before the start", lambda tmp: _simulate(_model(), fe.ImplicitEuler(), steps=None, t_end=-1.0),
             IP, "t_end = -1.0 s is not after the initial state's time 0.0 s",
             "use steps=N for a number of steps"),
    BadInput("record_every = 0", lambda tmp: _simulate(_model(), fe.ImplicitEuler(), record_every=0), IP,
             "record_every must be an integer >= 1, got 0", "an integer >= 1"),
    BadInput("a state of the wrong size",
             lambda tmp: _simulate(_model(), fe.ImplicitEuler(), state=fe.State(np.zeros(6), np.zeros(6))), IP,
             "the state has 6 DOFs but the model has 36", "build it with fe.State.rest(model, ...)"),
    BadInput("NaN in an initial velocity", lambda tmp: fe.State.rest(_model(), velocity=(0.0, 0.0, np.nan)), IP,
             "velocity has 1 NaN or infinite value(s)", "give finite values (m/s)"),
    BadInput("NaN in the positions of the state given to simulate", _nan_in_state, IP,
             "NaN or infinite", "finite"),
    BadInput("an integrator class instead of an instance (fe.ImplicitEuler)",
             lambda tmp: _simulate(_model(), fe.ImplicitEuler), IP, "class", "fe.ImplicitEuler()"),
    BadInput("dt so large that dt^2 overflows (dt = 1e200 s)",
             lambda tmp: _simulate(_model(gravity=(0.0, 0.0, -9.81)), fe.ImplicitEuler(), dt=1e200), IP,
             "dt = 1e+200 s is too large", "a fraction of the run's duration"),
    BadInput("dt so small that dt^2 underflows (dt = 1e-300 s)",
             lambda tmp: _simulate(_model(gravity=(0.0, 0.0, -9.81)), fe.ImplicitEuler(), dt=1e-300), IP,
             "dt = 1e-300 s is too small", "use a dt of at least"),
    BadInput("resuming a checkpoint written by a different run (another dt)", _resume_other_run, IP,
             "was written by a different run (dt: checkpoint 0.01, now 0.02)",
             "Resume with the same model, integrator, dt"),
    BadInput("a damaged checkpoint file", _resume_damaged, IP,
             "checkpoint.npz cannot be read", "remove the directory to start the run afresh"),
    BadInput("checkpoint_every without a checkpoint_dir",
             lambda tmp: _simulate(_model(), fe.ImplicitEuler(), checkpoint_every=10), IP,
             "checkpoint_every and resume need checkpoint_dir=DIR", "checkpoint_dir=DIR"),
    BadInput("an explicit dt above the critical step",
             lambda tmp: _simulate(_model(gravity=(0.0, 0.0, -9.81)), fe.SymplecticEuler()), fe.StabilityWarning,
             "dt = 0.01 s exceeds SymplecticEuler's critical time step", "Use dt <= "),
    BadInput("explicit Euler on an undamped body",
             lambda tmp: _simulate(_model(gravity=(0.0, 0.0, -9.81)), fe.ExplicitEuler(), dt=1e-5),
             fe.StabilityWarning, "ExplicitEuler is unstable at every time step on an undamped body",
             "add damping (fe.Rayleigh) or use fe.SymplecticEuler"),
    BadInput("a simulation that blows up", _blow_up, fe.Diverged,
             "the simulation diverged at step", "Try a smaller dt, an implicit integrator (fe.ImplicitEuler)",
             note="carrying .step, .time, .reason, .last_good_state and .trajectory (the frames so far)",
             check=_check_diverged),
    BadInput("a user motion (fe.Prescribed) that raises during a run", _motion_that_raises, fe.StepFailed,
             "step 1 (from t = 0.01 s) failed with ValueError: my motion table ends", "Fix what raised it",
             note="a fe.Diverged carrying the step, .last_good_state, .trajectory and the error as __cause__",
             check=_check_step_failed),
    BadInput("a static load the solver cannot reach", _unreachable_load, fe.NotConverged,
             "solve_static did not reach the full load", "Try more Newton iterations (max_iter=...)",
             note="carrying .result (the equilibrium reached so far)", check=_check_not_converged),
    # scene files (Python)
    BadInput("an unknown key in a scene file", lambda tmp: _scene("E = 1e6", "Young = 1e6"), SE,
             'scene.toml, line 6: [body] unknown key "Young"', 'did you mean "E"?', check=_check_suggestion("E")),
    BadInput("a wrong type in a scene file", lambda tmp: _scene("dt = 0.01", 'dt = "fast"'), SE,
             'scene.toml, line 14: [time] dt must be a number (s), got "fast" (a string)', "dt must be a number"),
    BadInput("a TOML syntax error", lambda tmp: _scene("[time]", "[time"), SE,
             "scene.toml, line 13: TOML syntax error", "Check the quotes, brackets and '=' there"),
    BadInput("a misspelt material in a scene file", lambda tmp: _scene('"linear"', '"neohookean"'), SE,
             '[body] material = "neohookean" is not allowed', 'did you mean "neo_hookean"?',
             check=_check_suggestion("neo_hookean")),
    BadInput("an unknown boundary name in a scene file", lambda tmp: _scene('["left"]', '["lefft"]'), SE,
             'scene.toml, line 10: [boundary] the mesh has no boundary "lefft"', 'did you mean "left"?',
             check=_check_suggestion("left")),
    BadInput("a missing table in a scene file", lambda tmp: _scene("[time]\ndt = 0.01\nduration = 0.02\n", ""), SE,
             "missing table [time]", "add [time] with dt, duration"),
    BadInput("a scene's mesh file that does not exist",
             lambda tmp: _scene('kind = "beam"\ncells = [2, 1, 1]', 'kind = "file"\npath = "nope.vtu"'), SE,
             'mesh file "nope.vtu" not found', "the path is relative to the scene file's folder"),
    # the command
    BadInput("a CLI run of a scene with an unknown key", lambda tmp: _cli_scene(tmp, "E = 1e6", "Young = 1e6"), 2,
             '[body] unknown key "Young"', 'did you mean "E"?'),
    BadInput("a CLI scene path that does not exist",
             lambda tmp: ["run", str(Path(tmp) / "nope.toml"), "--out", str(Path(tmp) / "out")], 2,
             "nope.toml' not found", "check the path"),
    BadInput("a CLI --out below a file",
             lambda tmp: ["run", str(_write(tmp, "scene.toml", SCENE)), "--out", str(_write(tmp, "a_file", "") / "out"),
                          "--quiet"], 2,
             "Not a directory", "check the path and its permissions"),
    BadInput("fem-elastic run --resume on a folder that holds no run", lambda tmp: ["run", "--resume", str(tmp)], 2,
             "is not the output directory of", "give the --out directory of the run to resume"),
    BadInput("a CLI option out of range (--fps -5)", lambda tmp: ["render", str(tmp), "--fps", "-5"], 2,
             "argument --fps", "must be >= 1"),
    BadInput("fem-elastic info on a file meshio cannot read",
             lambda tmp: ["info", str(_write(tmp, "broken.vtu", "garbage"))], 2,
             "meshio could not read", "Check that it is a tet mesh in that format"),
    BadInput("fem-elastic render on a folder with no run in it", lambda tmp: ["render", str(tmp), "--format", "png"],
             2, "holds no VTU series", "give the output directory of"),
    BadInput("a CLI run that blows up",
             lambda tmp: _cli_scene(tmp, 'type = "implicit_euler"\n[time]\ndt = 0.01\nduration = 0.02',
                                    'type = "symplectic_euler"\n[time]\ndt = 0.02\nduration = 2.0\n'
                                    "[loads]\ngravity = [0.0, 0.0, -9.81]"), 1,
             "diverged at step", "smaller dt"),
    BadInput("a scene file nested 100000 brackets deep",
             lambda tmp: ["run", str(_write(tmp, "deep.toml", "a = " + "[" * 100_000 + "]" * 100_000)),
                          "--out", str(Path(tmp) / "out")], 2,
             "nests arrays or inline tables too deeply", "check the brackets"),
    BadInput("a scene file that is not UTF-8 (Latin-1)",
             lambda tmp: ["run", str(_write_bytes(tmp, "latin1.toml", SCENE.replace("[body]", "[body]\n# d\xe9j\xe0 vu")
                                                  .encode("latin-1"))), "--out", str(Path(tmp) / "out")], 2,
             "is not UTF-8 text (byte 0xe9", "save it as UTF-8"),
    BadInput("a CLI scene with an absurd time step (dt = 1e200 s)",
             lambda tmp: _cli_scene(tmp, "dt = 0.01", "dt = 1e200"), 2,
             "dt = 1e+200 s is too large", "e.g. dt=1e-3"),
    # output directories, writes and resources (issue 18: items 1, 2, 3)
    BadInput("a second run on an output directory another run is writing", _second_run, fe.OutputInUse,
             "is in use by process", "give another --out directory", note="at once, carrying .pid",
             check=_check_holder),
    BadInput("fem-elastic run --out \"\"", lambda tmp: _cli_scene(tmp, "", "")[:3] + ["", "--quiet"], 2,
             "the output directory is empty", "e.g. --out results/run1"),
    BadInput("an --out directory that holds the user's own files",
             lambda tmp: _cli_scene(tmp, "", "")[:2] + ["--out", str(tmp), "--quiet"], 2,
             "holds files that a run did not write (scene.toml)", "or --overwrite to write there all the same"),
    BadInput("fem-elastic render -o with another format's extension",
             lambda tmp: ["render", str(_fake_run(tmp)), "--format", "mp4", "-o", str(Path(tmp) / "movie.gif")], 2,
             "does not end in .mp4, the format asked for", "name the file movie.mp4"),
    BadInput("fem-elastic render -o into the run's own frames",
             lambda tmp: ["render", str(_fake_run(tmp)), "--format", "png", "-o", str(_fake_run(tmp) / "frames")],
             2, "is a file of the runs being rendered", "Give a path outside the run directories"),
    BadInput("a scene path that is a FIFO (named pipe)", lambda tmp: ["run", str(_fifo(tmp)), "--out",
                                                                      str(Path(tmp) / "out")], 2,
             "is a FIFO (named pipe), not a file", "give the path of a file"),
    BadInput("a scene file of 64 MiB", lambda tmp: ["run", str(_sparse(tmp, 64 * 2**20)), "--out",
                                                     str(Path(tmp) / "out")], 2,
             "is 64 MiB, more than the 4 MiB", "check that this is the right file"),
    BadInput("a model larger than the free memory", _too_big, fe.ResourceLimit,
             "would need about", "Use a coarser mesh",
             note="before any assembly (the model's own share; its tangent and linear solver's before a static "
             "solve, an implicit run or a modal analysis), carrying .needed and .available (bytes)",
             check=_check_limit(2**18)),
    BadInput("a series larger than the free disk", _disk_full, fe.ResourceLimit,
             "would need about", "Record fewer frames ([output] every = N)",
             note="before the first frame is written, carrying .needed and .available (bytes)",
             check=_check_limit(1024)),
    BadInput("a render size above 8192 px", lambda tmp: _scene("[time]", "[output]\nsize = [10000, 540]\n[time]"),
             SE, "size[0] = 10000 is out of range: it must be <= 8192", "<= 8192"),
    BadInput("max_dt_cuts = 100", lambda tmp: fe.ImplicitEuler(max_dt_cuts=100), IP,
             "max_dt_cuts must be an integer from 0 to 20", "lower dt instead"),
    BadInput("max_substeps = 10^9", lambda tmp: fe.SymplecticEuler(max_substeps=10**9), IP,
             "max_substeps must be at most 1,000,000", "a smaller dt or an implicit integrator"),
    # models that contradict themselves (item 7) and the real cause (item 10)
    BadInput("a boundary both fixed and driven",
             lambda tmp: _model(fixed=["left", "right"], driven={"right": fe.Twist(1.0, duration=1.0)}), IP,
             "driven boundary 'right' is also fixed", "Remove 'right' from fixed (or displacement), or from driven"),
    BadInput("two drives that share vertices",
             lambda tmp: _model(driven={"right": fe.Twist(1.0, duration=1.0),
                                        "top": fe.Translate((0.0, 0.0, 0.01), duration=1.0)}), IP,
             "driven boundaries 'right' and 'top' share", "Drive the union with one motion"),
    BadInput("coincident duplicate vertices (a hidden crack)", lambda tmp: _cracked_mesh(), IM,
             "pair(s) of vertices coincide", "Merge them with a tolerance"),
    BadInput("a piece of the mesh no support reaches, solved statically", _loose_piece, fe.UnderConstrained,
             "2 separate pieces, 1 of which no support reaches (no fixed or driven DOF): 12 vertices",
             "Fix a boundary on each piece"),
    # several bodies (issue 17, item 1)
    BadInput("fe.MultiBody([]) (no body)", lambda tmp: fe.MultiBody([]), IP,
             "MultiBody needs at least one body", "use fe.Model for a single body"),
    BadInput("two fe.Body with the same name in one MultiBody",
             lambda tmp: fe.MultiBody([fe.Body(fe.beam_mesh(cells=(1, 1, 1)), 1000.0,
                                               fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)), name="a")] * 2),
             IP, "body names must be unique, but ['a'] appear more than once", "give each body its own name"),
    # the distributed backend (issue 21)
    BadInput("fe.PETScSolver() on a model with an obstacle (contact)",
             lambda tmp: fe.solve_static(_model(gravity=(0, 0, -9.81), ground=fe.Ground(z=-1.0)),
                                         linear_solver=fe.PETScSolver()), IP,
             "does not handle contact (obstacles or contact=) yet", "use a serial linear solver"),
    BadInput("more MPI ranks than tets (a 6-tet mesh split 7 ways)",
             lambda tmp: _partition(fe.beam_mesh(cells=(1, 1, 1)), 7), IP,
             "cannot split 6 tets among 7 MPI ranks", "Run with at most 6 rank(s)"),
    BadInput('fe.PETScSolver(preconditioner="ilu")', lambda tmp: fe.PETScSolver(preconditioner="ilu"), IP,
             "preconditioner must be one of ('gamg', 'lu')", "got 'ilu'"),
    # checkpoints (item 8)
    BadInput("a checkpoint's frames.f64 changed after it was written", _resume_altered, IP,
             "frames.f64 does not hold what its checkpoint recorded (CRC-32", "to start the run afresh"),
    BadInput("a run's scene.toml edited before --resume", _resume_edited_scene, 2,
             "scene.toml was edited after the run started", "Undo the edit to resume"),
]



# -- the table -------------------------------------------------------------------------------------
def outcome_name(outcome) -> str:
    """``fe.InvalidParameter`` for a class of the public namespace, else its qualified name."""
    name = outcome.__name__
    if getattr(fe, name, None) is outcome:
        return f"fe.{name}"
    return f"{outcome.__module__}.{name}" if outcome.__module__ != "builtins" else name


def _code(text: str) -> str:
    assert "`" not in text and "\n" not in text, text
    return "`" + text.replace("|", "\\|") + "`"


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def markdown_table(entries=None) -> str:
    """The README table (markdown, ending in a newline) of the entries the library handles."""
    rows = ["| bad input | what you get | what the message tells you to do |", "|---|---|---|"]
    for e in BAD_INPUTS if entries is None else entries:
        if e.xfail_reason:
            continue
        if e.kind == "exit":
            gets = f"exit status {e.outcome}, no traceback: {_code(e.problem)}"
        elif e.kind == "warns":
            gets = f"`{outcome_name(e.outcome)}` (a warning; the run goes on): {_code(e.problem)}"
        else:
            gets = f"`{outcome_name(e.outcome)}`: {_code(e.problem)}"
        if e.note:
            gets += f", {_cell(e.note)}"
        rows.append(f"| {_cell(e.name)} | {gets} | {_code(e.fix)} |")
    return "\n".join(rows) + "\n"
