"""Scenes of the stability study: the swept cantilever and the extreme cases.

Every scene is a small body (tens of vertices) so that one run takes well
under a few seconds, built from ``(body, E, nu)``:

- ``cantilever``: the swept scene. A 1 m x 0.1 m x 0.1 m cantilever on
  ``fe.beam_mesh(cells=(6, 1, 1))`` (28 vertices, 36 tets), fixed at
  ``left``, under gravity, released with a seeded random velocity field
  whose kinetic energy is 1e-3 of the weight times the length
  (``m |g| L``, ~0.1 J; v_rms ~ 0.14 m/s). The kick puts energy into every
  mode, the highest one included, so an unstable step shows as growth
  within tens of steps whatever the stiffness. Its size is set against
  the blow-up bound of :func:`fe.simulate` (the total energy growing by
  more than the scene's energy scale, here ``m |g| L``): the energy of
  symplectic Euler, measured at the steps, swings by up to
  ``1 / (1 - (h omega / 2)^2)`` in a mode of frequency omega, and a kick
  of the order of the bound would read as a blow-up at 0.9 x the critical
  step (a strain-sized kick does on the 100 GPa beam). A stiff beam stays
  in the linear range, where the predicted critical step applies; a soft
  one sags under its weight far into the nonlinear one.
- ``inverted``: the same cantilever with its free end flipped upside down
  (the ``right`` face mirrored about the beam's mid-height), which turns
  some tets of the last cell inside out; released at rest under gravity.
- ``crush``: a 0.1 m cube on ``cells=(2, 2, 2)``, ``bottom`` fixed, its
  ``top`` pushed down to 10 % of the height in 0.2 s, held to 0.25 s and
  released; no gravity.
- ``twist``: the cantilever with its ``right`` face turned by 720 degrees
  about the beam axis in 0.5 s (:class:`fe.Twist`), released at 0.6 s; no
  gravity.
- ``drop``: the cube 5 cm above a penalty ground (:class:`fe.Ground`),
  thrown down at 20 m/s under gravity.
- ``sliver``: the cantilever on ``cells=(6, 2, 2)`` (its axis vertices are
  interior, so moving them leaves the beam's shape alone) with three axis
  vertices pushed towards the opposite face of one of their tets, until
  that tet (and any that shares its plane) keeps ``relative_volume`` of
  the mean tet volume: nearly flat elements that :func:`fe.validate_mesh`
  accepts at 1e-3 and rejects as degenerate at 1e-12 (below its 1e-10).

All scenes use density 1000 kg/m^3.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..physics.obstacles import Ground
from ..physics.driven import Translate, Twist
from ..physics.elastic_body import ElasticBody
from ..errors import InvalidParameter
from ..materials import Corotated, LinearElastic, NeoHookean, StVK
from ..geometry.mesh import _signed_volumes, beam_mesh
from ..physics.model import Model
from ..physics.springs import SPRING_POISSON_RATIO, MassSpring
from ..dynamics.state import State

__all__ = [
    "BODIES",
    "BODY_LABELS",
    "DENSITY",
    "EXTREME_CASES",
    "Scene",
    "make_body",
    "cantilever",
    "inverted",
    "crush",
    "twist",
    "drop",
    "sliver",
    "sliver_mesh",
    "extreme_scene",
]

#: Mass density of every scene (kg/m^3).
DENSITY = 1000.0
#: The bodies of the study, by key.
BODIES = ("springs", "linear", "corotated", "stvk", "neohookean")
#: How the report names them.
BODY_LABELS = {
    "springs": "springs",
    "linear": "linear",
    "corotated": "corotated",
    "stvk": "StVK",
    "neohookean": "Neo-Hookean",
}
#: The extreme cases, by key (see the module notes).
EXTREME_CASES = ("inverted", "crush", "twist", "drop", "sliver", "degenerate sliver")
_GRAVITY = (0.0, 0.0, -9.81)
_MATERIALS = {"linear": LinearElastic, "corotated": Corotated, "stvk": StVK, "neohookean": NeoHookean}


@dataclass(frozen=True)
class Scene:
    """A model, its initial state and how long to run it.

    Attributes
    ----------
    model : Model
    state : State
        Initial state.
    duration : float
        Physical time to simulate (s) for the extreme cases; the swept
        cantilever runs a fixed number of steps instead.
    t_free : float
        Time (s) from which no boundary is driven: energy drift is measured from here.
    """

    model: Model
    state: State
    duration: float
    t_free: float = 0.0


def make_body(body: str, E: float, nu: float):
    """The body ``body`` (a key of :data:`BODIES`) with Young's modulus E (Pa) and Poisson ratio nu.

    A spring network represents only nu = 1/4 (see :class:`fe.MassSpring`):
    for ``"springs"`` nu is ignored and the default 1/4 is used.

    Examples
    --------
    >>> make_body("stvk", 1e6, 0.3).material
    StVK(E=1000000.0, nu=0.3)
    """
    if body == "springs":
        return MassSpring(E=E, nu=SPRING_POISSON_RATIO)
    if body not in _MATERIALS:
        raise InvalidParameter(f"body must be one of {BODIES}, got {body!r}.")
    return ElasticBody(_MATERIALS[body](E=E, nu=nu))


def _cantilever_model(mesh, body, E, nu, **kw):
    return Model(mesh, density=DENSITY, body=make_body(body, E, nu), fixed="left", **kw)


def cantilever(body: str, E: float, nu: float, *, kick: float = 1e-3, seed: int = 0, mesh=None) -> Scene:
    """The swept scene: a kicked cantilever under gravity (see the module notes).

    Parameters
    ----------
    body : str
        A key of :data:`BODIES`.
    E : float
        Young's modulus (Pa).
    nu : float
        Poisson ratio.
    kick : float
        Kinetic energy of the initial velocity field over the weight times
        the beam's length, ``m |g| L`` (dimensionless).
    seed : int
        Seed of the velocity field (independent normal components per node).
    mesh : skfem.MeshTet, optional
        Default ``fe.beam_mesh(cells=(6, 1, 1))``.

    Examples
    --------
    >>> s = cantilever("linear", 1e7, 0.3)
    >>> m = s.model
    >>> s.model.mesh.p.shape, round(m.kinetic_energy(s.state.v) / (m.total_mass * 9.81 * 1.0), 12)
    ((3, 28), 0.001)
    """
    mesh = beam_mesh(cells=(6, 1, 1)) if mesh is None else mesh
    model = _cantilever_model(mesh, body, E, nu, gravity=_GRAVITY)
    rng = np.random.default_rng(seed)
    v = State.rest(model, velocity=rng.standard_normal((mesh.p.shape[1], 3))).v  # fixed nodes at rest
    length = float(np.ptp(mesh.p[0]))
    target = kick * model.total_mass * model.gravity_magnitude * length
    v = v * math.sqrt(target / model.kinetic_energy(v))
    return Scene(model, State.rest(model, velocity=model.to_vertices(v)), duration=math.inf)


def inverted(body: str, E: float, nu: float) -> Scene:
    """The cantilever with its free end flipped upside down: some tets start inverted.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> s = inverted("linear", 1e5, 0.3)
    >>> p = s.model.mesh.p.T + s.state.displacement(s.model)  # deformed vertices (m)
    >>> int((fe.signed_volumes(fe.mesh_from_arrays(p, s.model.mesh.t.T, validate=False)) < 0).sum())
    3
    """
    mesh = beam_mesh(cells=(6, 1, 1))
    model = _cantilever_model(mesh, body, E, nu, gravity=_GRAVITY)
    height = float(mesh.p[2].max())

    def flip(X):
        u = np.zeros_like(X)
        end = np.isclose(X[:, 0], X[:, 0].max())
        u[end, 2] = height - 2.0 * X[end, 2]  # z -> height - z
        return u

    return Scene(model, State.rest(model, displacement=flip), duration=0.5)


def _cube():
    return beam_mesh(length=0.1, width=0.1, height=0.1, cells=(2, 2, 2))


def crush(body: str, E: float, nu: float) -> Scene:
    """A cube crushed to 10 % of its height in 0.2 s, held to 0.25 s, released; run to 0.5 s."""
    release = 0.25
    model = Model(_cube(), density=DENSITY, body=make_body(body, E, nu), fixed="bottom",
                  driven={"top": Translate((0.0, 0.0, -0.09), duration=0.2, release=release)})
    return Scene(model, State.rest(model), duration=0.5, t_free=release)


def twist(body: str, E: float, nu: float) -> Scene:
    """The cantilever's free end turned by 720 degrees in 0.5 s, released at 0.6 s; run to 1 s."""
    release = 0.6
    model = _cantilever_model(beam_mesh(cells=(6, 1, 1)), body, E, nu,
                              driven={"right": Twist(4.0 * math.pi, duration=0.5, release=release)})
    return Scene(model, State.rest(model), duration=1.0, t_free=release)


def drop(body: str, E: float, nu: float, *, speed: float = 20.0) -> Scene:
    """A cube 5 cm above a penalty ground, thrown down at ``speed`` (m/s) under gravity; 0.25 s."""
    cube = _cube().translated((0.0, 0.0, 0.05))
    model = Model(cube, density=DENSITY, body=make_body(body, E, nu), gravity=_GRAVITY,
                  ground=Ground(z=0.0))
    return Scene(model, State.rest(model, velocity=(0.0, 0.0, -speed)), duration=0.25)


def sliver_mesh(relative_volume: float, n_slivers: int = 3):
    """``fe.beam_mesh(cells=(6, 2, 2))`` with ``n_slivers`` nearly flat tets.

    Each of ``n_slivers`` interior vertices on the beam's axis (spread along
    it) is moved along the normal of the face opposite it in one of its
    tets, towards that face, by ``(1 - relative_volume)`` of the distance
    that flattens the tet; of all (tet, vertex) choices the shortest move
    that inverts none of the vertex's other tets is taken. The tet then has
    ``relative_volume`` of its volume (as has any tet of the star whose
    face lies in the same plane), and the beam's outer shape is unchanged.

    Parameters
    ----------
    relative_volume : float
        Volume left to the flattened tets, as a fraction of their own
        volume (dimensionless, in (0, 1)).
    n_slivers : int
        How many axis vertices to move (at most 5).

    Returns
    -------
    skfem.MeshTet
        Not validated (so a degenerate one can be built to show
        :func:`fe.validate_mesh` rejecting it).

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> m = sliver_mesh(1e-3)
    >>> v = fe.signed_volumes(m)
    >>> bool(v.min() > 0), round(float(v.min() / v.mean()), 6)
    (True, 0.001)
    """
    if not (0.0 < relative_volume < 1.0):
        raise InvalidParameter(f"relative_volume must be in (0, 1), got {relative_volume!r}.")
    mesh = beam_mesh(cells=(6, 2, 2))
    p = np.asarray(mesh.p, dtype=float).T.copy()
    t = np.asarray(mesh.t).T
    lo, hi = p.min(axis=0), p.max(axis=0)
    interior = np.flatnonzero(np.all((p > lo + 1e-12) & (p < hi - 1e-12), axis=1))
    interior = interior[np.argsort(p[interior, 0])]
    if not 1 <= n_slivers <= interior.size:
        raise InvalidParameter(f"n_slivers must be in [1, {interior.size}], got {n_slivers!r}.")
    picks = interior[np.round(np.linspace(0, interior.size - 1, n_slivers)).astype(int)]
    for v in picks:
        p[v] += _flattening_move(p, t, v) * (1.0 - relative_volume)
    return dataclasses.replace(mesh, doflocs=p.T.copy())


def _flattening_move(p, t, v):
    """The shortest move of vertex v onto the plane of the opposite face of one of its tets
    that leaves every other tet of its star with volume >= 0 (m, (3,))."""
    star = np.flatnonzero(np.any(t == v, axis=1))
    v0 = _signed_volumes(p, t[star])
    best = None
    for e in star:
        face = [w for w in t[e] if w != v]
        n = np.cross(p[face[1]] - p[face[0]], p[face[2]] - p[face[0]])
        n /= np.linalg.norm(n)
        move = -n * float((p[v] - p[face[0]]) @ n)  # the foot of the perpendicular
        q = p.copy()
        q[v] += move
        # round-off: a tet sharing the plane is flattened too, to ~eps * V
        if _signed_volumes(q, t[star]).min() >= -1e-12 * v0.max():
            if best is None or np.linalg.norm(move) < np.linalg.norm(best):
                best = move
    if best is None:  # pragma: no cover - every axis vertex of beam_mesh has one
        raise InvalidParameter(f"no tet around vertex {v} can be flattened without inverting another.")
    return best


def sliver(body: str, E: float, nu: float, *, relative_volume: float = 1e-3) -> Scene:
    """The kicked cantilever of :func:`cantilever` on :func:`sliver_mesh`; 0.5 s.

    Building the Model validates the mesh: a ``relative_volume`` below
    ``fe.mesh.DEGENERATE_TOL`` (relative to the mean) raises :class:`fe.InvalidMesh`.
    """
    scene = cantilever(body, E, nu, mesh=sliver_mesh(relative_volume))
    return dataclasses.replace(scene, duration=0.5)


def extreme_scene(case: str, body: str, E: float, nu: float) -> Scene:
    """The scene of extreme case ``case`` (a key of :data:`EXTREME_CASES`)."""
    if case == "inverted":
        return inverted(body, E, nu)
    if case == "crush":
        return crush(body, E, nu)
    if case == "twist":
        return twist(body, E, nu)
    if case == "drop":
        return drop(body, E, nu)
    if case == "sliver":
        return sliver(body, E, nu, relative_volume=1e-3)
    if case == "degenerate sliver":
        return sliver(body, E, nu, relative_volume=1e-12)
    raise InvalidParameter(f"case must be one of {EXTREME_CASES}, got {case!r}.")
