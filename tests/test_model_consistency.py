"""Models that contradict themselves are refused, and failures name their real cause.

A boundary both fixed and driven, two drives on shared vertices, a DOF both
fixed and prescribed, coincident duplicate vertices (a hidden crack), a piece
of the mesh that no support reaches (in a static solve), and the diagnosis of
a static solve that fails, ahead of the generic advice.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fem_elastic as fe
from bad_inputs import cracked_beam
from fem_elastic.solvers.static import _diagnose_failure


def _model(mesh=None, **kw):
    mesh = mesh if mesh is not None else fe.beam_mesh(cells=(3, 1, 1))
    kw.setdefault("gravity", (0.0, 0.0, -9.81))
    return fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3),
                                                               order=kw.pop("order", 1)), **kw)


def test_a_boundary_both_fixed_and_driven_is_refused():
    with pytest.raises(fe.InvalidParameter, match="'right' is also fixed.*Remove 'right' from fixed"):
        _model(fixed=["left", "right"], driven={"right": fe.Translate((0.01, 0, 0), duration=1.0)})
    # component-wise: held in x only, it is driven in y and z (a designed case, kept)
    m = _model(fixed={"left": "xyz", "right": "x"}, driven={"right": fe.Translate((0, 0.01, 0), duration=1.0)})
    assert m.driven and m._driven_components[0][:, 0].sum() == 0
    # a fixed face sharing an edge with a driven one: the edge stays fixed, the rest is driven
    m = _model(fixed="left", driven={"bottom": fe.Translate((0, 0, 0.01), duration=1.0)})
    assert m.driven[0][2].shape[0] > 0


def test_two_drives_that_share_vertices_are_refused():
    with pytest.raises(fe.InvalidParameter, match="'right' and 'top' share .* node.*one motion"):
        _model(fixed="left", driven={"right": fe.Translate((0.01, 0, 0), duration=1.0),
                                     "top": fe.Twist(0.1, duration=1.0)})
    # disjoint drives are fine
    _model(fixed="bottom", driven={"left": fe.Translate((0.01, 0, 0), duration=1.0),
                                   "right": fe.Translate((-0.01, 0, 0), duration=1.0)}, gravity=None)


def test_a_dof_both_fixed_and_prescribed_is_refused():
    with pytest.raises(fe.InvalidParameter, match="right"):
        _model(fixed=["left", "right"], displacement={"right": (0.0, 0.0, -0.01)})


@settings(max_examples=12, deadline=None)
@given(nx=st.integers(2, 5), ny=st.integers(1, 2), data=st.data())
def test_coincident_duplicate_vertices_are_refused_with_their_count(nx, ny, data):
    layer = data.draw(st.integers(1, nx - 1))
    p, t, n_dup = cracked_beam((nx, ny, 1), layer)
    with pytest.raises(fe.InvalidMesh, match=rf"^{n_dup} pair\(s\) of vertices coincide.*Merge them") as err:
        fe.mesh_from_arrays(p, t)
    assert err.value.elements.size == 2 * n_dup
    # apart by more than the tolerance (a real, thin gap) they are two bodies: accepted
    p2 = p.copy()
    p2[-n_dup:, 0] += 1e-6
    fe.mesh_from_arrays(p2, t, reorient=True)


def _two_blocks(gap=0.5):
    m = fe.beam_mesh(length=1.0, cells=(3, 1, 1))
    p, t = m.p.T, m.t.T
    return fe.mesh_from_arrays(np.vstack([p, p + (0.0, 0.0, gap)]), np.vstack([t, t + len(p)])), p


def test_a_piece_no_support_reaches_is_named_in_a_static_solve():
    mesh, p = _two_blocks()
    left_lower = np.flatnonzero(np.isclose(mesh.p[0], 0) & (mesh.p[2] < 0.3))
    for order in (1, 2):
        model = _model(mesh, fixed=left_lower, order=order)
        with pytest.raises(fe.UnderConstrained, match=(
                r"2 separate pieces, 1 of which no support reaches.*16 vertices in \[0, 1\] x \[0, 0.1\] "
                r"x \[0.5, 0.6\] m.*Fix a boundary on each piece")):
            fe.solve_static(model)
    # held at one vertex only, the upper piece still turns: named too
    left_upper = np.flatnonzero(np.isclose(mesh.p[0], 0) & (mesh.p[2] > 0.3))
    model = _model(mesh, fixed=np.concatenate([left_lower, left_upper[:1]]))
    with pytest.raises(fe.UnderConstrained, match=r"the one of 16 vertices .* too few DOFs.*rotation"):
        fe.solve_static(model)
    # both held: solved
    model = _model(mesh, fixed=np.concatenate([left_lower, left_upper]))
    assert fe.solve_static(model, stability=False).converged
    # a loose piece is fine in a dynamic run: it falls
    run = fe.simulate(_model(mesh, fixed=left_lower), fe.SymplecticEuler(), 1e-4, steps=3)
    assert run.displacement[-1, mesh.p[2] > 0.3, 2].max() < 0


def test_a_failed_static_solve_names_the_inversion_before_the_advice():
    model = fe.Model(fe.beam_mesh(cells=(3, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left")
    x = model.X.reshape(-1, 3).copy()
    x[:, 0] *= -1.0  # mirrored: every tet inverted
    total = fe.solve_static(model, check=False)
    total.load_factor, total.message = 0.5, "line search failed"
    text = _diagnose_failure(model, x.ravel(), total)
    assert text.startswith("At load factor 0.5, 18 tets have det F <= 0")
    assert _diagnose_failure(model, model.X.copy(), total) == ""  # nothing to name: the generic advice


def test_a_crushing_static_solve_names_the_inversion_of_the_failed_attempt():
    # the right face pushed 1.5 lengths to the left, through the clamped one, in one load step
    # of 5 Newton iterations: the step to 1 fails, the halved step to 0.5 too, and the increment
    # then falls below min_load_step. The last converged state is the rest state (nothing
    # inverted): only the failed attempt at 0.5 shows what went wrong (StVK's energy is finite
    # for inverted tets, so Newton goes there)
    model = fe.Model(fe.beam_mesh(length=0.4, cells=(4, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.StVK(E=1e5, nu=0.3)), fixed="left",
                     displacement={"right": (-1.5 * 0.4, None, None)})
    with pytest.raises(fe.NotConverged, match=r"stalled at load factor 0:.*At load factor 0\.5, \d+ tets "
                                              r"have det F <= 0 .*the load inverts elements") as err:
        fe.solve_static(model, steps=1, max_iter=5, min_load_step=0.5, stability=False)
    assert err.value.result.load_factor == 0.0
