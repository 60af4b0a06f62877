"""Inversion is watched: every accepted step records min det F, and a run through inverted elements warns.

det F is checked against closed forms (uniform scalings, a reflection) for
P1, P2 and spring bodies; extreme scenes (a crush to 5 % of the height, a
1080 degree twist) must end either non-inverted or with an
``fe.InversionWarning`` whose count is the recorded one; the summary and
``summary.json`` carry min det F; checkpoints of the old record layout are
refused with a typed error.
"""

from __future__ import annotations

import json
import math
import re
import warnings

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.app.output import SeriesWriter
from fem_elastic.physics.inversion import DetF


def _model(body, cells=(2, 1, 1), **options):
    return fe.Model(fe.beam_mesh(cells=cells), density=1000.0, body=body, **options)


BODIES = {
    "P1": lambda: fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)),
    "P2": lambda: fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3), order=2),
    "springs": lambda: fe.MassSpring(E=1e6),
}


@pytest.mark.parametrize("body", BODIES)
def test_det_F_of_affine_maps_is_their_determinant(body):
    model = _model(BODIES[body]())
    det = DetF(model)
    X = model.X.reshape(-1, 3)
    for A in (np.diag([1.0, 1.0, 0.05]), np.diag([2.0, 0.5, 1.5]), np.diag([1.0, 1.0, -1.0]),
              np.array([[1.0, 0.3, 0.0], [0.0, 1.0, 0.2], [0.1, 0.0, 1.0]])):
        J = det((X @ A.T + 0.3).ravel())  # an affine map: F = A everywhere
        assert J.shape == ((model.mesh.t.shape[1],) if det.where == "tets" else J.shape)
        # exact up to the round-off of differences of coordinates of size 1
        np.testing.assert_allclose(J, np.linalg.det(A), rtol=1e-12, atol=1e-12)
    assert det.where == ("quadrature points" if body == "P2" else "tets")


def test_p1_det_F_is_the_elastic_body_s_own():
    model = _model(BODIES["P1"]())
    rng = np.random.default_rng(0)
    x = model.X + 0.05 * rng.standard_normal(model.X.shape)
    F = model.body_potential.F(x)
    np.testing.assert_allclose(DetF(model)(x), np.linalg.det(np.moveaxis(F, (0, 1), (-2, -1))).ravel(),
                               rtol=1e-12)


def _steps_in_warning(caught):
    msgs = [str(w.message) for w in caught if issubclass(w.category, fe.InversionWarning)]
    assert len(msgs) <= 1, msgs
    if not msgs:
        return 0
    return int(re.match(r"(\d+) of \d+ steps ended with inverted elements", msgs[0]).group(1))


def _run_and_check(model, integrator, dt, t_end):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run = fe.simulate(model, integrator, dt, t_end=t_end, record_every=1000, check_stability=False)
    det = run.step_stats["min_det_F"]
    assert det.shape == (run.steps,) and np.isfinite(det).all()
    summary = run.summary()
    assert summary["min_det_F"] == det.min() and summary["steps_inverted"] == np.count_nonzero(det <= 0)
    # non-inverted at every step, or the warning, with the count the record holds
    assert _steps_in_warning(caught) == summary["steps_inverted"]
    return run


CRUSH_MATERIALS = {"Neo-Hookean": fe.NeoHookean, "stable Neo-Hookean": fe.StableNeoHookean,
                   "corotated": fe.Corotated}


@pytest.mark.parametrize("material", CRUSH_MATERIALS)
def test_a_crush_to_5_percent_ends_non_inverted_or_warns(material):
    mesh = fe.beam_mesh(length=0.1, width=0.1, height=0.1, cells=(2, 2, 2))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(CRUSH_MATERIALS[material](E=1e6, nu=0.3)),
                     fixed="bottom", driven={"top": fe.Translate((0.0, 0.0, -0.095), duration=0.1)})
    run = _run_and_check(model, fe.ImplicitEuler(), 0.01, 0.15)
    if material == "Neo-Hookean":  # its energy is +inf when inverted: implicit Euler never goes there
        assert run.summary()["steps_inverted"] == 0 and run.summary()["min_det_F"] > 0


def test_a_1080_degree_twist_ends_non_inverted_or_warns():
    model = _model(fe.ElasticBody(fe.StableNeoHookean(E=1e6, nu=0.3)), cells=(6, 1, 1), fixed="left",
                   driven={"right": fe.Twist(6.0 * math.pi, duration=0.5)})
    _run_and_check(model, fe.ImplicitEuler(), 0.01, 0.5)


def test_passing_through_inversion_with_a_stable_material_warns_with_the_count():
    # a stable Neo-Hookean cube crushed through itself: its energy stays finite, so only the watch sees it
    mesh = fe.beam_mesh(length=0.1, width=0.1, height=0.1, cells=(2, 2, 2))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.StableNeoHookean(E=1e4, nu=0.3)),
                     fixed="bottom", driven={"top": fe.Translate((0.0, 0.0, -0.12), duration=0.05)})
    with pytest.warns(fe.InversionWarning, match=r"steps ended with inverted elements .*StableNeoHookean"):
        run = fe.simulate(model, fe.ImplicitEuler(), 0.01, steps=8)
    assert run.summary()["steps_inverted"] > 0 and run.summary()["min_det_F"] <= 0


def test_summary_json_carries_min_det_F(tmp_path):
    model = _model(BODIES["P1"](), fixed="left", gravity=(0.0, 0.0, -9.81))
    writer = SeriesWriter(model, tmp_path, every=2, n_steps=4)
    writer.write_state(fe.State.rest(model))
    run = fe.simulate(model, fe.ImplicitEuler(), 0.01, steps=4, record_every=2, observers=[writer])
    writer.finish(run)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["min_det_F"] == pytest.approx(run.step_stats["min_det_F"].min(), rel=1e-15)
    assert 0.9 < summary["min_det_F"] < 1.1 and summary["steps_inverted"] == 0
    assert "min_det_F_total" not in summary


def test_a_checkpoint_with_the_old_step_records_is_refused_with_the_fix(tmp_path):
    model = _model(BODIES["P1"](), fixed="left", gravity=(0.0, 0.0, -9.81))
    fe.simulate(model, fe.ImplicitEuler(), 0.01, steps=3, checkpoint_dir=tmp_path)
    # rewrite it as the version before min_det_F wrote it: no field names, ten fields a record
    path = tmp_path / "checkpoint.npz"
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["meta"]))
    del meta["step_fields"]
    arrays["meta"] = np.array(json.dumps(meta))
    arrays["scalars"] = arrays["scalars"][:4]
    np.savez(path, **arrays)
    steps = np.fromfile(tmp_path / "steps.f64").reshape(3, -1)[:, :10]
    steps.tofile(tmp_path / "steps.f64")
    with pytest.raises(fe.InvalidParameter, match="written by another version.*lacks min_det_F.*afresh"):
        fe.load_checkpoint(tmp_path)
    with pytest.raises(fe.InvalidParameter, match="Start the run afresh"):
        fe.simulate(model, fe.ImplicitEuler(), 0.01, steps=3, checkpoint_dir=tmp_path, resume=True)


def test_the_fused_det_F_is_the_numpy_one_to_the_bit(monkeypatch):
    """The per-step watch's numba kernel (one pass per tet) against the numpy path, inverted tets included."""
    from fem_elastic.discretization import fused
    from fem_elastic.physics.inversion import DetF

    if not fused.available():
        pytest.skip("numba is not installed: only the numpy path exists")
    model = fe.Model(fe.beam_mesh(cells=(6, 2, 2)), density=1000.0,
                     body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)))
    x = model.X + 0.05 * np.random.default_rng(3).standard_normal(model.ndofs)  # some tets inverted
    det = DetF(model)
    fast = det(x)
    monkeypatch.setenv("FEM_ELASTIC_NUMBA", "0")
    slow = det(x)
    assert (slow <= 0).any() and (slow > 0).any()
    np.testing.assert_array_equal(fast, slow)
