"""Fuzzing mesh validation with hypothesis: validation catches what assembly cannot handle.

A small beam (``fe.beam_mesh(cells=(3, 1, 1))``: 16 vertices, 18 tets) is broken by
a random list of mutations: vertices perturbed (by up to twice the cell size, so
tets flip), collapsed onto others, moved onto the plane of the opposite face
(slivers), tets flipped, duplicated or dropped, vertices duplicated or left
unused, coordinates set to NaN/inf, indices out of range, the whole mesh scaled
by up to 1e+-160 or moved up to 1e20 m away from the origin. Then, through
``fe.mesh_from_arrays`` (which runs ``validate_mesh``), either

- ``fe.InvalidMesh`` is raised, with a message that names the problem and says
  what to do about it, or
- the mesh is accepted, and then a ``fe.Model`` builds on it, its energy, gradient
  and Hessian at rest are finite, and a static solve and one implicit step give
  finite positions (or a typed ``fe.FemElasticError`` saying why they could not:
  a mesh that falls apart into pieces leaves a floating piece without equilibrium).

Any other exception, or a NaN after acceptance, is a hole in validation.
"""

import math
import warnings

import numpy as np
import pytest
import skfem
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import fem_elastic as fe

SETTINGS = dict(deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])

BASE = fe.beam_mesh(length=1.0, width=0.3, height=0.3, cells=(3, 1, 1))
P0 = np.ascontiguousarray(BASE.p.T)  # (16, 3), m
T0 = np.ascontiguousarray(BASE.t.T.astype(np.int64))  # (18, 4)
H = 1.0 / 3.0  # cell size (m)
LEFT = np.flatnonzero(P0[:, 0] == 0.0)  # the x = 0 face: held in the static solve
MATERIAL = fe.NeoHookean(E=1e6, nu=0.3)  # a barrier: flipped tets give +inf, not a number

#: words of which an InvalidMesh message must contain one: it says what to do
FIX_WORDS = ("remesh", "fix", "drop", "remove", "reorient", "translate", "scale", "merge",
             "expected", "use ", "convert", "subtract", "keep", "add", "needed", "check",
             "give ", "e.g.")


# ---------------------------------------------------------------------------------------
# mutations: each is a function (points, tets, draw) -> (points, tets)


def _perturb(P, T, draw):
    i = draw(st.integers(0, len(P) - 1))
    amp = draw(st.floats(0.0, 2.0)) * H
    d = np.array(draw(st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3)))
    P = P.copy()
    P[i] += amp * d
    return P, T


def _collapse(P, T, draw):
    """Vertex i moved onto vertex j: every tet with both is flat."""
    i, j = draw(st.integers(0, len(P) - 1)), draw(st.integers(0, len(P) - 1))
    P = P.copy()
    P[i] = P[j]
    return P, T


def _sliver(P, T, draw):
    """A tet's vertex moved onto (or within ~offset of) the plane of its opposite face."""
    e = draw(st.integers(0, len(T) - 1))
    a = draw(st.integers(0, 3))
    offset = draw(st.sampled_from([0.0, 1e-14, 1e-11, 1e-8, 1e-5, -1e-8]))
    face = P[[T[e, k] for k in range(4) if k != a]]
    n = np.cross(face[1] - face[0], face[2] - face[0])
    n /= np.linalg.norm(n)
    P = P.copy()
    v = T[e, a]
    P[v] = P[v] - np.dot(P[v] - face[0], n) * n + offset * H * n
    return P, T


def _flip(P, T, draw):
    e = draw(st.integers(0, len(T) - 1))
    T = T.copy()
    T[e, [0, 1]] = T[e, [1, 0]]
    return P, T


def _duplicate_vertex(P, T, draw):
    """A copy of vertex i, used by one tet instead of i (a crack) or by none (unused)."""
    i = draw(st.integers(0, len(P) - 1))
    P = np.vstack([P, P[i]])
    if draw(st.booleans()):
        users = np.argwhere(T == i)
        if len(users):
            e, k = users[draw(st.integers(0, len(users) - 1))]
            T = T.copy()
            T[e, k] = len(P) - 1
    return P, T


def _unused_vertex(P, T, draw):
    return np.vstack([P, draw(st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3))]), T


def _duplicate_tet(P, T, draw):
    e = draw(st.integers(0, len(T) - 1))
    row = T[e][draw(st.permutations(range(4)))]  # the same tet in any vertex order
    return P, np.vstack([T, row])


def _drop_tet(P, T, draw):
    e = draw(st.integers(0, len(T) - 1))
    return P, np.delete(T, e, axis=0) if len(T) > 1 else T


def _repeat_index(P, T, draw):
    """A tet that uses one vertex twice."""
    e = draw(st.integers(0, len(T) - 1))
    T = T.copy()
    T[e, 3] = T[e, draw(st.integers(0, 2))]
    return P, T


def _non_finite(P, T, draw):
    i = draw(st.integers(0, len(P) - 1))
    P = P.copy()
    P[i, draw(st.integers(0, 2))] = draw(st.sampled_from([math.nan, math.inf, -math.inf]))
    return P, T


def _out_of_range(P, T, draw):
    e = draw(st.integers(0, len(T) - 1))
    T = T.copy()
    T[e, draw(st.integers(0, 3))] = draw(st.sampled_from([len(P), len(P) + 7, -1, 2**40]))
    return P, T


def _scale(P, T, draw):
    return P * 10.0 ** draw(st.integers(-160, 160)), T


def _translate(P, T, draw):
    d = np.array(draw(st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3)))
    return P + d * 10.0 ** draw(st.integers(0, 20)), T


def _rotate(P, T, draw):
    q = np.array(draw(st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4)))
    n = np.linalg.norm(q)
    if n < 1e-3:
        return P, T
    w, x, y, z = q / n
    R = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])
    return P @ R.T, T


MUTATIONS = {
    "perturb": _perturb, "collapse": _collapse, "sliver": _sliver, "flip": _flip,
    "duplicate_vertex": _duplicate_vertex, "unused_vertex": _unused_vertex,
    "duplicate_tet": _duplicate_tet, "drop_tet": _drop_tet, "repeat_index": _repeat_index,
    "non_finite": _non_finite, "out_of_range": _out_of_range, "scale": _scale,
    "translate": _translate, "rotate": _rotate,
}


@st.composite
def broken_meshes(draw):
    """(points, tets, names of the mutations applied)."""
    P, T = P0.copy(), T0.copy()
    names = draw(st.lists(st.sampled_from(sorted(MUTATIONS)), min_size=0, max_size=3))
    with np.errstate(all="ignore"):  # a sliver of a mesh scaled to 1e160 overflows here
        for name in names:
            P, T = MUTATIONS[name](P, T, draw)
    return P, T, names


# ---------------------------------------------------------------------------------------
# the property


def check_message(err: fe.InvalidMesh) -> None:
    """The message names the problem (some numbers, several words) and the fix."""
    msg = str(err)
    assert len(msg) > 60, msg
    assert any(w in msg.lower() for w in FIX_WORDS), msg


def check_assembly(mesh) -> None:
    """An accepted mesh assembles: finite energy, gradient, Hessian; solves give no NaN."""
    fixed = LEFT[LEFT < mesh.p.shape[1]]
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(MATERIAL), fixed=fixed,
                     gravity=(0.0, 0.0, -9.81))
    x = model.X
    assert math.isfinite(model.energy(x))
    assert np.isfinite(model.gradient(x)).all()
    g, K = model.linearize(x)
    assert np.isfinite(g).all() and np.isfinite(K.data).all()
    assert np.isfinite(model.lumped_mass).all() and (model.lumped_mass > 0).all()
    try:
        result = fe.solve_static(model, max_iter=15)
        assert np.isfinite(result.x).all()
    except fe.FemElasticError as err:  # e.g. a floating piece: no equilibrium
        assert str(err)
    try:
        run = fe.simulate(model, fe.ImplicitEuler(), dt=1e-3, steps=1)
        assert np.isfinite(run.displacement).all()
    except fe.FemElasticError as err:
        assert str(err)


def _raw_mesh(P, T):
    """The same arrays as a MeshTet built directly (what a user of skfem passes to
    fe.Model), or None where they are not numeric (n, 3) and (m, 4) arrays, or where
    skfem's int32 connectivity would wrap an index."""
    try:
        P, T = np.asarray(P), np.asarray(T)
    except ValueError:
        return None
    if P.dtype.kind not in "iuf" or T.dtype.kind not in "iu" or P.ndim != 2 or T.ndim != 2 \
            or P.shape[1] != 3 or T.shape[1] != 4 or not len(T) or not len(P):
        return None
    if np.abs(T).max() > np.iinfo(np.int32).max:
        return None  # skfem stores t as int32 and wraps 2**40 to 0 silently: nothing to check
    return skfem.MeshTet(np.ascontiguousarray(P.T, dtype=float), np.ascontiguousarray(T.T))


def run_case(P, T) -> str:
    """'rejected' or 'accepted'; fails on anything else.

    mesh_from_arrays and validate_mesh on a MeshTet of the same arrays agree.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # an overflow or NaN on the way is a hole
        raw = _raw_mesh(P, T)
        try:
            mesh = fe.mesh_from_arrays(P, T)
        except fe.InvalidMesh as err:
            check_message(err)
            if raw is not None:
                with pytest.raises(fe.InvalidMesh):
                    fe.validate_mesh(raw)
            return "rejected"
        assert fe.validate_mesh(raw) is raw
        check_assembly(mesh)
    return "accepted"


def test_the_base_mesh_is_accepted():
    assert run_case(P0, T0) == "accepted"


def _generic_tet(scale):
    """One positively oriented tet whose edge vectors have no zero component pairs, scaled."""
    return np.array([[0, 0, 0], [1, 1, 0], [0, 1, 1], [1, 0, 1]], dtype=float) * scale, [[0, 1, 2, 3]]


@settings(max_examples=250, **SETTINGS)
@given(case=broken_meshes())
# regressions: each was accepted by validate_mesh before it checked them
@example(case=(*_generic_tet(1e160), ["scale"]))  # volumes inf - inf = NaN: energy inf, gradient NaN
@example(case=(P0 * 1e51, T0, ["scale"]))  # forces ~1e157 overflow in ||g||^2 of the solvers
@example(case=(P0 * 1e-40, T0, ["scale"]))  # facet areas ~L^4 underflow
@example(case=(P0, np.vstack([T0, T0[[0]]]), ["duplicate_tet"]))  # silently double stiffness
@example(case=(P0 + 1e12, T0, ["translate"]))  # edges resolved to 6e-4 of their length
def test_broken_mesh_is_rejected_or_assembles(case):
    P, T, _ = case
    run_case(P, T)


@pytest.mark.parametrize("points, tets, boundaries, words", [
    (*_generic_tet(1e160), None, ["spans", "scale"]),
    (P0 * 1e51, T0, None, ["spans 1e+51 m", "mesh.scaled"]),
    (P0 * 1e-40, T0, None, ["spans 1e-40 m", "mesh.scaled"]),
    (P0 + 1e12, T0, None, ["from the origin", "mesh.translated"]),
    (P0, np.vstack([T0, T0[[0, 1, 2, 3]][:, ::-1]]), None, ["repeat another tet", "drop"]),
    (P0, np.vstack([T0, [[0, 1, 1, 2]]]), None, ["use a vertex twice", "element 18"]),
    (np.zeros((4, 3)), [[0, 1, 2, 3]], None, ["coincide"]),
    (P0.astype(str), T0, None, ["real coordinates", "dtype=float"]),
    ([[0.0, 0.0, 0.0], [1.0, 0.0]], [[0, 1, 2, 3]], None, ["rectangular"]),
    (P0, T0.astype(float), None, ["integer vertex indices", "astype"]),
    (P0, T0, {"b": [["a", "b", "c"]]}, ["integer vertex indices"]),
    (P0, T0, {"b": [[None, 1, 2]]}, ["integer vertex indices"]),
    (P0, T0, {"b": [[0, 1, 2], [0, 1]]}, ["different lengths"]),
    (P0, T0, [[0, 1, 2]], ["must be a dict"]),
])
def test_rejected_with_the_problem_and_the_fix(points, tets, boundaries, words):
    """Inputs that slipped through or raised a raw numpy error, with what the message says."""
    with pytest.raises(fe.InvalidMesh) as info:
        fe.mesh_from_arrays(points, tets, boundaries)
    check_message(info.value)
    for w in words:
        assert w in str(info.value), (w, str(info.value))


# ---------------------------------------------------------------------------------------
# raw arrays and boundaries of any type and shape

anything = st.one_of(
    st.none(), st.booleans(), st.integers(-5, 40), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=3), st.complex_numbers(max_magnitude=10.0),
)


@st.composite
def raw_arrays(draw):
    """Points and tets of random dtype, shape and raggedness, now and then the valid ones."""
    def array_like(valid, width):
        kind = draw(st.sampled_from(["valid", "cast", "lists", "shape"]))
        if kind == "valid":
            return valid
        if kind == "cast":
            return valid.astype(draw(st.sampled_from([str, bool, complex, np.float32, np.int8, object])))
        if kind == "lists":  # rows of random length and content
            return draw(st.lists(st.lists(anything, min_size=width - 1, max_size=width + 1),
                                 min_size=0, max_size=6))
        rows, cols = draw(st.integers(0, 6)), draw(st.integers(0, 5))
        return np.array(draw(st.lists(st.integers(-2, 20), min_size=rows * cols,
                                      max_size=rows * cols))).reshape(rows, cols)
    return array_like(P0, 3), array_like(T0, 4)


@settings(max_examples=150, **SETTINGS)
@given(arrays=raw_arrays())
def test_raw_arrays_are_rejected_or_assemble(arrays):
    run_case(*arrays)


FACES = np.sort(BASE.facets.T, axis=1)  # (nf, 3) every face of the base mesh


@st.composite
def boundary_maps(draw):
    """{name: triangles}: real faces, non-faces, wrong shapes and dtypes, odd names."""
    out = {}
    for _ in range(draw(st.integers(0, 3))):
        name = draw(st.one_of(st.text(max_size=6), st.integers(), st.none()))
        kind = draw(st.sampled_from(["faces", "random", "anything", "empty"]))
        if kind == "faces":
            rows = draw(st.lists(st.integers(0, len(FACES) - 1), min_size=1, max_size=4))
            value = FACES[rows][:, draw(st.permutations(range(3)))]
        elif kind == "random":
            value = draw(st.lists(st.lists(st.integers(-3, 30), min_size=2, max_size=4),
                                  min_size=1, max_size=3))
        elif kind == "anything":
            value = draw(st.lists(st.lists(anything, min_size=3, max_size=3), max_size=2))
        else:
            value = []
        out[name] = value
    return out


@settings(max_examples=100, **SETTINGS)
@given(boundaries=boundary_maps())
def test_boundaries_are_rejected_or_usable(boundaries):
    """Either InvalidMesh, or every named boundary is a set of faces a support can use."""
    try:
        mesh = fe.mesh_from_arrays(P0, T0, boundaries)
    except fe.InvalidMesh as err:
        check_message(err)
        return
    for name, facets in (mesh.boundaries or {}).items():
        assert isinstance(name, str)
        assert np.all((0 <= facets) & (facets < mesh.facets.shape[1]))
        if facets.size:
            model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(MATERIAL), fixed=name)
            assert (~model.free).sum() >= 9  # a whole triangle: its three vertices' DOFs


# ---------------------------------------------------------------------------------------
# found by the fuzzing, not fixable in mesh validation (a mesh 10 m from the origin is fine)


def test_a_steel_beam_100_m_from_the_origin_solves():
    """The same steel beam solves at x in [0, 1] m and at x in [100, 101] m (Newton's round-off
    floor grows with the coordinates' size against the body's: ElasticPotential._offset_factor)."""
    body = fe.ElasticBody(fe.LinearElastic(E=2e11, nu=0.3))
    for offset in (0.0, 100.0):
        mesh = fe.mesh_from_arrays(P0 + [offset, 0.0, 0.0], T0)
        model = fe.Model(mesh, density=7850.0, body=body, fixed=LEFT, gravity=(0.0, 0.0, -9.81))
        assert fe.solve_static(model, max_iter=10, min_load_step=0.5).converged  # fast: one try
