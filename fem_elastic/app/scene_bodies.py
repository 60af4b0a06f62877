"""Scenes with several bodies: the ``[[body]]`` tables, their schema and their model.

A scene file with ``[[body]]`` tables (an array of tables) instead of one
``[body]`` table describes a :class:`fem_elastic.MultiBody`. Each ``[[body]]``
holds everything that belongs to one body: the keys of ``[body]`` (type,
material, E, nu, order, density, ...), its own ``mesh`` table (as ``[mesh]``),
its supports and loads (``fixed``, ``displacement``, ``traction``,
``[[body.driven]]``), its placement (``translate`` in m, ``rotate`` as a
rotation vector axis * angle in degrees, like every scene angle, about the mesh's origin) and its initial ``velocity``
(m/s), and a required, unique ``name``. The rest of the file is as for one
body, without ``[mesh]``, ``[boundary]`` and ``[initial]`` (they belong to each
body) and with ``[loads]`` holding only the scene-wide ``gravity``.
``[[compare]]`` tables of a multi-body scene may change the integrator only.
The scene runs as one variant, named after the scene.

A file with a single ``[body]`` table is read exactly as before.
"""

from __future__ import annotations

from dataclasses import replace

from .schema_types import (
    REQUIRED,
    Displacements,
    Fixed,
    Invalid,
    Key,
    NamedVectors,
    String,
    Table,
    TableArray,
    Vector,
)

__all__ = ["MAIN_RUN", "build_bodies", "is_multibody", "multibody_help", "validate_bodies"]

#: The name of a multi-body scene's main run (its variant).
MAIN_RUN = "bodies"


def _key(table: Table, name: str) -> Key:
    return next(k for k in table.keys if k.name == name)


def _schema():
    """The ``[[body]]`` entry table and the rest of a multi-body scene file, from the one-body schema."""
    from .scene_schema import BODY, COMPARE, DRIVEN, SCENE_FILE, _body_rule

    mesh_key = _key(SCENE_FILE, "mesh")
    body_keys = tuple(replace(k, default=REQUIRED, default_text='"ball"', doc="the body's name (unique)")
                      if k.name == "name" else k for k in BODY.keys)
    entry = Table(
        "body",
        body_keys + (
            Key("mesh", mesh_key.type, REQUIRED, doc="the body's reference mesh, as [mesh]"),
            Key("fixed", Fixed(), [], doc="held DOFs of this body, as [boundary] fixed"),
            Key("displacement", Displacements(), {}, "m", "prescribed displacements, as [boundary]"),
            Key("traction", NamedVectors(), {}, "Pa", "dead load per reference area on this body's boundaries"),
            Key("driven", TableArray(replace(DRIVEN, title="body.driven")), [],
                doc="boundaries of this body moved in time, [[body.driven]]"),
            Key("translate", Vector(), [0.0, 0.0, 0.0], "m", "placement: translation (after the rotation)"),
            Key("rotate", Vector(), [0.0, 0.0, 0.0], "degrees", "placement: rotation vector axis * "
                "angle, about the mesh's origin, e.g. [0, 0, 90] a quarter turn about z"),
            Key("velocity", Vector(), [0.0, 0.0, 0.0], "m/s", "initial velocity of the body"),
        ),
        "One body of a multi-body scene (repeat [[body]] for each).",
        rule=_body_rule,
    )
    loads = Table("loads", (_key(_key(SCENE_FILE, "loads").type, "gravity"),),
                  "Scene-wide loads: gravity on every body (tractions and drives belong to each [[body]]).")
    compare = Table(
        "compare",
        (_key(COMPARE, "integrator"),
         Key("name", String(), lambda t: (t.get("integrator") or {}).get("type"),
             doc="the run's name", default_text="the integrator type")),
        "Another run of the same bodies with another integrator (repeat for several).",
    )
    replaced = {"body": Key("body", TableArray(entry), REQUIRED, doc="the bodies, [[body]]"),
                "loads": Key("loads", loads, {}, doc="gravity"),
                "compare": Key("compare", TableArray(compare), [], doc="further runs, [[compare]]")}
    dropped = ("mesh", "boundary", "initial")
    keys = tuple(replaced.get(k.name, k) for k in SCENE_FILE.keys if k.name not in dropped)
    return entry, replace(SCENE_FILE, title="scene file (several bodies)", keys=keys)


def multibody_help() -> str:
    """The ``[[body]]`` tables in the scene-file reference (:func:`fem_elastic.app.scene_schema.schema_help`)."""
    from .scene_schema import _key_lines

    entry, _ = _schema()
    lines = ["[[body]]  (several bodies, instead of [body], [mesh], [boundary] and [initial]) " + entry.doc,
             "  Each table is one body; [loads] then holds only gravity, [[compare]] only integrator and",
             "  name. The run is named \"bodies\". Keys:"]
    lines += _key_lines(entry, "  ")
    return "\n".join(lines) + "\n"


def is_multibody(document) -> bool:
    """Whether a parsed scene document has ``[[body]]`` tables (an array) rather than ``[body]``."""
    return isinstance(document, dict) and isinstance(document.get("body"), list)


def validate_bodies(document: dict) -> dict:
    """Check a multi-body scene document and fill its defaults (see the module notes).

    Parameters
    ----------
    document : dict
        What ``tomllib.loads`` returned, with ``body`` a list of tables.

    Returns
    -------
    dict
        The validated spec; ``spec["bodies"]`` is the list of body tables and
        ``spec["body"]`` is ``{"name": <the run's name>}``.

    Raises
    ------
    Invalid
        With the path of the first offending key: no body, a duplicate body
        name, a static solve, a key that belongs to each body given at the top.
    """
    for top in ("mesh", "boundary", "initial"):
        if top in document:
            raise Invalid((top,), f"[{top}] belongs to each body in a scene with [[body]] tables: "
                                  f"move it into the [[body]] tables ([body.{top}] keys such as "
                                  f"mesh, fixed, velocity), or use a single [body].")
    if not document["body"]:
        raise Invalid(("body",), "a scene with [[body]] needs at least one body table.")
    solve = document.get("solve")
    if isinstance(solve, dict) and solve.get("kind") == "static":
        raise Invalid(("solve", "kind"), "a scene with [[body]] tables is dynamic only; solve the "
                                         "statics of several bodies with fe.solve_static(fe.MultiBody(...)).")
    _, scene_file = _schema()
    spec = scene_file.check(document, ())
    names: list[str] = []
    for i, body in enumerate(spec["body"]):
        if body["name"] in names:
            raise Invalid(("body", i, "name"), f'the body name "{body["name"]}" is already used (bodies '
                                               f'so far: {", ".join(names)}); give each [[body]] its own name.')
        names.append(body["name"])
    spec["bodies"] = spec.pop("body")
    spec["body"] = {"name": MAIN_RUN}
    spec["initial"] = None
    spec["boundary"] = {"fixed": [], "displacement": {}}
    spec["loads"].update({"traction": {}, "driven": []})
    spec["solve"] = spec.get("solve") or {"kind": "dynamic"}
    return spec


def _check_boundaries(scene, mesh, body: dict, path: tuple) -> None:
    """A SceneError for a boundary name this body's mesh lacks or a vertex index out of range."""
    check = scene._boundary_check(mesh, f'the mesh of body "{body["name"]}"')
    fixed, nv = body["fixed"], mesh.p.shape[1]
    for i, f in enumerate(fixed.items() if isinstance(fixed, dict) else fixed):
        f = f[0] if isinstance(fixed, dict) else f
        where = path + ("fixed", f if isinstance(fixed, dict) else i)
        if isinstance(f, str):
            check(f, where)
        elif f >= nv:
            raise scene._error(where, f"fixed vertex index {f} is out of range: the mesh of body "
                                      f'"{body["name"]}" has {nv} vertices (0 to {nv - 1}).')
    for name in body["displacement"] or {}:
        check(name, path + ("displacement", name))
    for name in body["traction"]:
        check(name, path + ("traction", name))
    for i, d in enumerate(body["driven"]):
        check(d["boundary"], path + ("driven", i, "boundary"))


def _body_terms(scene, body: dict, path: tuple) -> dict:
    """fe.Body keywords for this body's supports, tractions and driven boundaries."""
    import math

    from ..physics.driven import Translate, Twist

    terms = {}
    if body["fixed"]:
        terms["fixed"] = dict(body["fixed"]) if isinstance(body["fixed"], dict) else list(body["fixed"])
    if body["displacement"]:
        terms["displacement"] = {k: tuple(v) for k, v in body["displacement"].items()}
    if body["traction"]:
        terms["traction"] = {k: tuple(v) for k, v in body["traction"].items()}
    driven = {}
    for i, d in enumerate(body["driven"]):
        where = path + ("driven", i)
        if d["boundary"] in driven:
            raise scene._error(where + ("boundary",), f'boundary "{d["boundary"]}" of body "{body["name"]}" '
                                                      "is driven twice; give each boundary one motion.")
        if d["motion"] == "twist":
            driven[d["boundary"]] = scene._guard(
                where, Twist, math.radians(d["angle"]), d["duration"], axis=tuple(d["axis"]),
                center=None if d["center"] is None else tuple(d["center"]), release=d["release"])
        else:
            driven[d["boundary"]] = scene._guard(where, Translate, tuple(d["offset"]), d["duration"],
                                                 release=d["release"])
    if driven:
        terms["driven"] = driven
    return terms


def build_bodies(scene, name: str):
    """The :class:`fem_elastic.app.scene.BuiltRun` of a multi-body scene's run ``name``.

    Every body's mesh is built and checked (SceneErrors name the ``[[body]]``
    table), each becomes a :class:`fem_elastic.Body`, and the scene-wide
    terms (gravity, ground, damping, contact) go to the :class:`fem_elastic.MultiBody`.
    """
    import math

    from ..dynamics.state import State
    from ..physics.body import Body
    from ..physics.multibody import MultiBody
    from .scene import BuiltRun
    from .scene_schema import MATERIALS, make_integrator

    spec = scene.spec
    steps = scene._steps()
    bodies, infos = [], []
    for i, b in enumerate(spec["bodies"]):
        path = ("body", i)
        mesh, mesh_info = scene._mesh(b["mesh"], path + ("mesh",))
        _check_boundaries(scene, mesh, b, path)
        body = scene._guard(path, Body, mesh, b["density"], scene._body(b, path), name=b["name"],
                            translate=tuple(b["translate"]), rotate=tuple(math.radians(a) for a in b["rotate"]),
                            velocity=tuple(b["velocity"]), **_body_terms(scene, b, path))
        bodies.append(body)
        kind = (f'{MATERIALS[b["material"]].__name__} FEM, P{b["order"]} tets' if b["type"] == "fem"
                else f'mass-spring ({b["calibration"]} calibration)')
        infos.append({"name": b["name"], "body": kind, "mesh": mesh_info, "spec": dict(b)})
    terms = {k: v for k, v in scene._terms().items() if k in ("gravity", "ground", "damping", "contact")}
    model = scene._guard(("body",), MultiBody, bodies, **terms)
    if name == MAIN_RUN:
        ipath: tuple = ("integrator",)
        integ = spec["integrator"]
    else:
        i = next(i for i, c in enumerate(spec["compare"]) if c["name"] == name)
        integ, ipath = spec["compare"][i]["integrator"], ("compare", i, "integrator")
    integrator = scene._guard(ipath, make_integrator, integ)
    state = State.rest(model, velocity=model.initial_velocity().reshape(-1, 3))
    out = spec["output"]
    output = {"vtu": out["vtu"], "render": list(out["render"]), "color_by": out["color_by"],
              "size": tuple(out["size"]), "fps": out["fps"], "checkpoint_every": out["checkpoint_every"]}
    g, d = spec["ground"], spec["damping"]
    info = {
        "scene": scene.name, "description": scene.description, "variant": name,
        "body": " + ".join(f'{x["name"]}: {x["body"]}' for x in infos),
        "bodies": infos,
        "n_vertices": int(model.mesh.p.shape[1]), "n_tets": int(model.mesh.t.shape[1]),
        "gravity": None if spec["loads"]["gravity"] is None else list(spec["loads"]["gravity"]),
        "ground": None if g is None else {"kind": "plane", "z": g["z"], "method": g["method"]},
        "damping": None if d is None else {"alpha": d["alpha"], "beta": d["beta"]},
        "integrator": integrator.name,
        "integrator_options": {k: v for k, v in integ.items() if k != "type"},
        "dt": spec["time"]["dt"], "duration": spec["time"]["duration"], "steps_planned": steps,
    }
    return BuiltRun(name=name, model=model, integrator=integrator, dt=spec["time"]["dt"], steps=steps,
                    state=state, record_every=out["every"], output=output, info=info)
