"""Load paths of a static solve (issue 15, item 4): every converged step with its load factor."""

import numpy as np
import pytest

import fem_elastic as fe


def bar(material=None, order=1, **kw):
    material = material or fe.LinearElastic(E=1e6, nu=0.3)
    return fe.Model(fe.beam_mesh(cells=(6, 1, 1)), 1000.0, fe.ElasticBody(material, order=order), **kw)


def test_steps_give_every_point_and_a_one_line_force_displacement_curve():
    m = bar(fixed={"left": "x", "front": "y", "bottom": "z"}, displacement={"right": (0.01, None, None)})
    res = fe.solve_static(m, steps=5)
    path = res.path
    np.testing.assert_allclose(path.load_factors, np.linspace(0.0, 1.0, 6), rtol=0, atol=1e-15)
    tip = np.argmax(m.mesh.p[0])
    u, F = path.displacements[:, tip, 0], path.reaction_forces("right")[:, 0]  # the curve
    np.testing.assert_allclose(u, 0.01 * path.load_factors, atol=1e-15)
    np.testing.assert_allclose(F, 1e6 * 0.01 * 0.01 * path.load_factors, rtol=1e-10, atol=1e-9)
    assert path[-1].x is not None and path[-1].reaction_force("left")[0] == pytest.approx(-100.0)
    assert res.load_steps == list(path.load_factors[1:])


def test_load_path_function_and_adaptive_cuts_join_the_path():
    m = bar(fe.NeoHookean(E=1e5, nu=0.3), fixed="left", traction={"right": (0.0, 0.0, -4e3)})
    path = fe.load_path(m, steps=2, max_iter=8, min_load_step=1 / 64)
    s = path.load_factors
    assert s[0] == 0.0 and s[-1] == 1.0 and np.all(np.diff(s) > 0)
    assert len(s) > 3  # 8 Newton iterations cannot take half of this load: steps were cut
    assert 0.5 in s.tolist()  # ...and the path still passes through the requested points
    tip = path.displacements[:, :, 2].min(axis=1)
    assert np.all(np.diff(tip) < 0)  # the tip goes down monotonically with the load


def test_bad_steps_are_typed_errors():
    m = bar(fixed="left", gravity=(0, 0, -9.81))
    for steps in (0, 2.5, True, "3"):
        with pytest.raises(fe.InvalidParameter, match="steps"):
            fe.solve_static(m, steps=steps)
    with pytest.raises(fe.InvalidParameter, match="stability"):
        fe.solve_static(m, stability="sometimes")


def test_nonlinear_prescribed_stretch_uses_the_predictor():
    """A 50 % stretch of a Neo-Hookean bar in 5 steps: each step starts from the linearised
    response of the free DOFs, so no element near the end is stretched by the whole increment."""
    m = bar(fe.NeoHookean(E=1e6, nu=0.45), order=2, fixed="left", displacement={"right": (0.5, 0.0, 0.0)})
    res = fe.solve_static(m, steps=5)
    assert res.converged and len(res.path) == 6
    F = res.path.reaction_forces("right")[:, 0]
    assert np.all(np.diff(F) > 0)
    assert res.iterations <= 5 * 8


def test_static_scene_writes_the_load_path(tmp_path):
    from pathlib import Path

    from fem_elastic.app.cli import main
    from fem_elastic.app.vtu import read_series

    scene = Path(__file__).resolve().parent.parent / "scenes" / "uniaxial_static.toml"
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    series = read_series(tmp_path / "out" / "fem")
    np.testing.assert_allclose(series.times, [0.0, 0.25, 0.5, 0.75, 1.0])
    s = series.summary
    assert s["status"] == "completed" and s["solve"] == "static" and s["stable"] is True
    assert s["max_displacement"] == pytest.approx(np.hypot(0.01, np.hypot(0.0003, 0.0003)), rel=1e-9)
    np.testing.assert_allclose(s["reactions"]["right"], [100.0, 0.0, 0.0], atol=1e-8)
    np.testing.assert_allclose(s["reactions"]["left"], [-100.0, 0.0, 0.0], atol=1e-8)
    import json

    top = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert top["variants"]["fem"]["reactions"]["right"][0] == pytest.approx(100.0)


def test_static_scene_errors():
    from fem_elastic.app.scene import SceneError, parse_scene

    base = '''
[mesh]
kind = "beam"
[body]
material = "linear"
E = 1e6
nu = 0.3
density = 1000.0
[boundary]
fixed = { left = "xyz" }
[solve]
kind = "static"
'''
    scene = parse_scene(base)
    assert scene.static and scene.build()[0].kind == "static"
    with pytest.raises(SceneError, match=r"\[integrator\] applies only to a dynamic scene"):
        parse_scene(base + '[integrator]\ntype = "rk4"\n')
    with pytest.raises(SceneError, match="components held"):
        parse_scene(base.replace('left = "xyz"', 'left = "xw"'))
    with pytest.raises(SceneError, match='"free"'):
        parse_scene(base.replace('fixed = { left = "xyz" }', 'fixed = { left = "xyz" }\n'
                                 'displacement = { right = [0.01, "loose", 0.0] }'))
    with pytest.raises(SceneError, match='no boundary "rigth"'):
        parse_scene(base.replace('fixed = { left = "xyz" }',
                                 'fixed = { left = "xyz" }\ndisplacement = { rigth = [0.01, "free", "free"] }')).build()
    with pytest.raises(fe.InvalidParameter, match="is static"):
        scene.build()[0].simulate()
