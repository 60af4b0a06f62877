"""IPC contact in statics and between bodies only: review findings that must stay fixed.

- A prescribed displacement that pushes one body against another must reach its full value:
  when CCD cuts the load step's predictor, Newton starts from the last equilibrium with the
  prescribed DOFs at the target (Newton moves only free DOFs).
- ``self_contact=False`` filters pairs inside one body with ipctk's native filter (a Python
  callable there ran inside ipctk's parallel broad phase and deadlocked).
"""

import warnings

import numpy as np
import pytest

import fem_elastic as fe

pytest.importorskip("ipctk", reason="IPC contact needs the [contact] extra (ipctk)")

SIZE = 0.1  # m, the cubes' edge


def _cube():
    return fe.beam_mesh(length=SIZE, width=SIZE, height=SIZE, cells=(2, 2, 2))


def _material():
    return fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3))


def test_prescribed_push_into_a_second_body_reaches_its_full_value():
    gap, push = 5e-3, 0.02  # m: the push closes the 5 mm gap and presses 15 mm further
    bodies = fe.MultiBody(
        [fe.Body(_cube(), 1000.0, _material(), name="a", displacement={"left": (push, 0.0, 0.0)}),
         fe.Body(_cube(), 1000.0, _material(), name="b", fixed="right", translate=(SIZE + gap, 0, 0))],
        contact=fe.IPCContact(dhat=1e-3, kappa=1e6))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = fe.solve_static(bodies, steps=1)
    assert result.converged
    u = (result.x - bodies.X)[bodies.prescribed_dofs]
    # the prescribed values are (push, 0, 0) on every node of a's left face
    assert np.isclose(u.max(), push, rtol=0, atol=1e-12) and np.isclose(u.min(), 0.0, atol=1e-12)
    assert not bodies.contact.has_intersections(result.x)
    # the push reached body b: its free side moved, pressed through the barrier (> 0.1 mm)
    b = (result.x - bodies.X)[bodies.body_slice("b")].reshape(-1, 3)
    assert b[:, 0].max() > 1e-4


def test_contact_between_bodies_only_uses_the_native_filter():
    gap = 5e-4  # m, inside dhat: pairs between the bodies are active from the start
    with pytest.warns(UserWarning, match="within dhat"):  # said once, at the start
        bodies = fe.MultiBody(
            [fe.Body(_cube(), 1000.0, _material(), name="a"),
             fe.Body(_cube(), 1000.0, _material(), name="b", translate=(SIZE + gap, 0, 0))],
            contact=fe.IPCContact(dhat=1e-3, kappa=1e6, self_contact=False))
    # the filter itself: two vertices of one body never collide, a vertex of each body may
    same = np.flatnonzero(bodies.contact.surface.body == 0)[:2]
    other = np.flatnonzero(bodies.contact.surface.body == 1)[0]
    assert not bodies.contact.mesh.can_collide(*same) and bodies.contact.mesh.can_collide(same[0], other)
    dx = np.zeros(bodies.ndofs)
    view = dx[bodies.body_slice("b")]
    view[0::3] = -0.05  # body b driven 5 cm into body a: CCD must stop it at the gap
    for _ in range(10):  # the deadlock came at random: several calls
        alpha = bodies.max_step(bodies.X, dx)
    assert 0.0 < alpha < gap / 0.05
    assert bodies.contact.diagnostics(bodies.X)["active_contacts"] > 0


def test_a_driven_face_moved_through_another_body_in_one_step_is_refused_not_intersected():
    """CCD also checks the driven DOFs' own jump over a step (review finding): a face driven
    5 cm in one step through a 5 mm gap makes implicit Euler cut the step back and, since the
    prescribed motion really goes through the other body, fail with that reason."""
    gap = 5e-3
    bodies = fe.MultiBody(
        [fe.Body(_cube(), 1000.0, _material(), name="a", fixed="left",
                 driven={"right": fe.Translate((0.05, 0.0, 0.0), duration=0.01)}),
         fe.Body(_cube(), 1000.0, _material(), name="b", fixed="right", translate=(SIZE + gap, 0, 0))],
        contact=fe.IPCContact(dhat=1e-3, kappa=1e6))
    integrator = fe.ImplicitEuler(max_dt_cuts=3)
    with pytest.raises(fe.FemElasticError, match="through a contact"):
        integrator.step(bodies, fe.State.rest(bodies), 0.01)
