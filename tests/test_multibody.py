"""Several bodies in one model (fe.Body, fe.MultiBody): stacking, diagnostics, supports,
placement, scenes, the command line, checkpoints and bad input."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

import fem_elastic as fe

MESH = fe.beam_mesh(length=0.4, width=0.1, height=0.1, cells=(4, 1, 1))
LINEAR = fe.ElasticBody(fe.LinearElastic(E=1e5, nu=0.3))
NEO = fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3))
G = (0.0, 0.0, -9.81)


def _pair(body_a=LINEAR, body_b=LINEAR, va=(0.0, 0.0, 0.0), vb=(0.3, 0.0, 0.5), **kw):
    """Two bodies 10 m apart: a cantilever and a free-flying beam."""
    a = fe.Body(MESH, 1000.0, body_a, fixed="left", name="a", velocity=va)
    b = fe.Body(MESH, 800.0, body_b, name="b", translate=(0.0, 10.0, 0.0), velocity=vb)
    return a, b, fe.MultiBody([a, b], gravity=G, **kw)


def _alone(body: fe.Body, **kw) -> fe.Model:
    return fe.Model(body.mesh, body.density, body.body, fixed=body.fixed, gravity=G, **kw)


def _run(model, integrator, dt, steps, velocity):
    state = fe.State.rest(model, velocity=velocity)
    return fe.simulate(model, integrator, dt=dt, steps=steps, state=state, energy_growth=math.inf)


@pytest.mark.parametrize("integrator, dt", [(fe.ImplicitEuler(), 1e-2), (fe.SymplecticEuler(), 2e-4)])
def test_two_bodies_far_apart_move_exactly_as_each_alone(integrator, dt):
    a, b, multi = _pair()
    run = fe.simulate(multi, integrator, dt=dt, steps=6, energy_growth=math.inf)
    nv = MESH.p.shape[1]
    for k, body in enumerate((a, b)):
        alone = _run(_alone(body), integrator, dt, 6, body.velocity)
        u = run.displacement[:, k * nv:(k + 1) * nv]
        scale = np.abs(alone.displacement).max()
        if isinstance(integrator, fe.SymplecticEuler):
            # per-DOF arithmetic on the same numbers: the same bits (measured: max diff 0)
            np.testing.assert_array_equal(u, alone.displacement)
        else:
            # linear material: Newton solves each step's quadratic in one step; what is left is
            # the round-off of an LU of the block-diagonal matrix against the single body's
            # (measured 1.2e-15 relative; 1e-12 leaves room for another LU ordering)
            np.testing.assert_allclose(u, alone.displacement, rtol=0, atol=1e-12 * scale)


def test_nonlinear_bodies_agree_to_newtons_tolerance():
    a, b, multi = _pair(NEO, NEO)
    run = fe.simulate(multi, fe.ImplicitEuler(rtol=1e-10), dt=1e-2, steps=4, energy_growth=math.inf)
    nv = MESH.p.shape[1]
    for k, body in enumerate((a, b)):
        alone = _run(_alone(body), fe.ImplicitEuler(rtol=1e-10), 1e-2, 4, body.velocity)
        u = run.displacement[:, k * nv:(k + 1) * nv]
        # the stacked Newton stops on the joint residual, each body's alone on its own, so an
        # extra iteration for one body is possible; near the quadratic convergence it moves x by
        # far less than the tolerance (measured 2.4e-15 relative; bound: 1e-9, above rtol)
        np.testing.assert_allclose(u, alone.displacement, rtol=0, atol=1e-9 * np.abs(alone.displacement).max())


def test_newmark_and_static_solve_with_two_bodies():
    _, _, multi = _pair()
    run = fe.simulate(multi, fe.Newmark(), dt=1e-2, steps=3, energy_growth=math.inf)
    assert np.isfinite(run.displacement).all()
    # statics needs every body supported: both cantilevers, then each equals its own solve
    a2 = fe.Body(MESH, 1000.0, LINEAR, fixed="left", name="a")
    b2 = fe.Body(MESH, 1000.0, LINEAR, fixed="left", name="b", translate=(0.0, 5.0, 0.0))
    static = fe.solve_static(fe.MultiBody([a2, b2], gravity=G))
    alone = fe.solve_static(_alone(a2))
    nv = MESH.p.shape[1]
    assert static.converged
    scale = np.abs(alone.displacement).max()
    # a linear static solve is one Newton step per load step: exact to LU round-off
    np.testing.assert_allclose(static.displacement[:nv], alone.displacement, atol=1e-10 * scale)
    np.testing.assert_allclose(static.displacement[nv:], alone.displacement, atol=1e-10 * scale)
    with pytest.raises(fe.UnderConstrained, match="body 'b'"):
        fe.solve_static(multi)


def test_momentum_and_energy_diagnostics_sum_per_body():
    _, _, multi = _pair(va=(0.1, -0.2, 0.0), vb=(0.3, 0.0, 0.5))
    state = fe.State.rest(multi, velocity=multi.initial_velocity().reshape(-1, 3))
    x = state.x + 1e-3 * np.sin(np.arange(multi.ndofs))
    v = state.v
    sa, sb = multi.body_slice("a"), multi.body_slice(1)
    ma, mb = multi.models
    # sums of the same numbers in a different order: equal to a few ulps
    assert multi.kinetic_energy(v) == pytest.approx(ma.kinetic_energy(v[sa]) + mb.kinetic_energy(v[sb]), rel=1e-14)
    np.testing.assert_allclose(multi.linear_momentum(v), ma.linear_momentum(v[sa]) + mb.linear_momentum(v[sb]),
                               rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(multi.angular_momentum(x, v),
                               ma.angular_momentum(x[sa], v[sa]) + mb.angular_momentum(x[sb], v[sb]),
                               rtol=1e-13, atol=1e-15)
    assert multi.energy(x) == pytest.approx(ma.energy(x[sa]) + mb.energy(x[sb]), rel=1e-14)
    np.testing.assert_allclose(multi.body_energies(x), [ma.energy(x[sa]), mb.energy(x[sb])], rtol=1e-15)
    assert multi.total_mass == pytest.approx(1000.0 * 0.004 + 800.0 * 0.004, rel=1e-12)
    np.testing.assert_allclose(multi.body_linear_momenta(v)[1], 800.0 * 0.004 * np.array([0.3, 0.0, 0.5]), rtol=1e-12)


def test_gradient_and_hessian_of_the_stack_by_finite_differences():
    _, _, multi = _pair(NEO, NEO)
    rng = np.random.default_rng(0)
    x = multi.X + 1e-3 * rng.standard_normal(multi.ndofs)
    d = rng.standard_normal(multi.ndofs)
    g, H = multi.linearize(x, project=False)
    h = 1e-6  # central differences: error O(h^2) ~ 1e-12 relative, round-off eps/h ~ 1e-10
    fd = (multi.energy(x + h * d) - multi.energy(x - h * d)) / (2 * h)
    assert fd == pytest.approx(g @ d, rel=1e-6)
    fd_g = (multi.gradient(x + h * d) - multi.gradient(x - h * d)) / (2 * h)
    np.testing.assert_allclose(H @ d, fd_g, rtol=0, atol=1e-6 * np.abs(fd_g).max())
    np.testing.assert_allclose(g, multi.gradient(x), rtol=0, atol=1e-12 * np.abs(g).max())


def test_per_body_supports_placement_and_initial_velocity():
    turn = fe.Body(MESH, 1000.0, LINEAR, name="turned", rotate=(0.0, 0.0, math.pi / 2), translate=(1.0, 2.0, 3.0),
                   velocity=(0.0, 0.0, 2.0))
    held = fe.Body(MESH, 1000.0, LINEAR, name="held", fixed="left",
                   driven={"right": fe.Translate((0.0, 0.0, 0.05), duration=0.1)})
    multi = fe.MultiBody([held, turn])
    # a quarter turn about z maps (x, y, z) to (-y, x, z), then the translation
    p = MESH.p
    np.testing.assert_allclose(turn.mesh.p, np.stack([-p[1] + 1.0, p[0] + 2.0, p[2] + 3.0]), atol=1e-15)
    X = multi.X.reshape(-1, 3)[multi.vertex_offsets[1]:]
    np.testing.assert_allclose(X, turn.mesh.p.T, atol=1e-15)
    # fixed and driven DOFs belong to the first body only, offset by nothing
    n0 = multi.models[0].ndofs
    assert multi.fixed_dofs.max() < n0 and multi.free[n0:].all()
    dofs, _, vc = multi.constraints(0.05)
    assert dofs.max() < n0 and np.isclose(vc.reshape(-1)[-1], 0.5)  # 0.05 m over 0.1 s
    run = fe.simulate(multi, fe.ImplicitEuler(), dt=1e-2, steps=3)
    v_turned = run.final_state.v[n0:].reshape(-1, 3)
    # no gravity, no support: the turned body flies at 2 m/s, undeformed (a rigid translation
    # strains nothing, so no force acts: 2 m/s to a few ulps, measured 1.8e-15; any force leaking
    # from the driven body's block would show at the 0.5 m/s scale of its drive)
    np.testing.assert_allclose(v_turned, np.tile([0.0, 0.0, 2.0], (v_turned.shape[0], 1)), atol=1e-9)


def test_output_mesh_and_body_of_tet():
    _, _, multi = _pair()
    assert multi.mesh.p.shape[1] == 2 * MESH.p.shape[1]
    np.testing.assert_array_equal(np.bincount(multi.body_of_tet), [MESH.t.shape[1]] * 2)
    u = multi.to_vertices(multi.X)
    np.testing.assert_allclose(u, multi.mesh.p.T)


@pytest.mark.parametrize("bad, match", [
    ([], "at least one body"),
    ("not a list", "list of fe.Body"),
    ([1], "must be a fe.Body"),
])
def test_bad_body_lists(bad, match):
    with pytest.raises(fe.InvalidParameter, match=match):
        fe.MultiBody(bad)


def test_duplicate_names_and_bad_bodies():
    a = fe.Body(MESH, 1000.0, LINEAR, name="same")
    with pytest.raises(fe.InvalidParameter, match="unique.*same"):
        fe.MultiBody([a, fe.Body(MESH, 1000.0, LINEAR, name="same", translate=(0, 1, 0))])
    with pytest.raises(fe.InvalidParameter, match="name"):
        fe.Body(MESH, 1000.0, LINEAR, name="")
    with pytest.raises(fe.InvalidParameter, match="rotation"):
        fe.Body(MESH, 1000.0, LINEAR, name="r", rotate=np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(fe.InvalidParameter, match="translate"):
        fe.Body(MESH, 1000.0, LINEAR, name="t", translate=(0, 1))
    with pytest.raises(fe.InvalidParameter, match="body 'bad'.*density"):
        fe.MultiBody([fe.Body(MESH, -1.0, LINEAR, name="bad")])
    multi = fe.MultiBody([a])
    with pytest.raises(fe.InvalidParameter, match="no body named"):
        multi.body_slice("other")
    with pytest.raises(fe.InvalidParameter, match="one body's mesh"):
        multi.boundary_nodes("left")
    with pytest.raises(fe.InvalidParameter, match="warping"):
        multi.linearize(multi.X, body=object())


# --- checkpoints --------------------------------------------------------------------------


class _StopAt:
    def __init__(self, k):
        self.k = k

    def __call__(self, step, state):
        if step == self.k:
            raise KeyboardInterrupt("stopped by the test")


def test_two_body_run_resumes_bit_for_bit(tmp_path):
    def run(**kw):
        _, _, multi = _pair(NEO, NEO, damping=fe.Rayleigh(0.5, 0.0))
        return fe.simulate(multi, fe.ImplicitEuler(), dt=1e-2, steps=8, record_every=2,
                           check_stability=False, checkpoint_dir=tmp_path / "ck", **kw)

    full = fe.simulate(_pair(NEO, NEO, damping=fe.Rayleigh(0.5, 0.0))[2], fe.ImplicitEuler(), dt=1e-2,
                       steps=8, record_every=2, check_stability=False)
    with pytest.raises(KeyboardInterrupt):
        run(callback=_StopAt(5))
    resumed = run(resume=True)
    assert resumed.resumed_from_step == 5
    for name in ("times", "displacement", "kinetic", "potential"):
        assert np.array_equal(getattr(full, name), getattr(resumed, name)), name
    assert np.array_equal(full.final_state.x, resumed.final_state.x)
    # the fingerprint tells a different body apart: another density refuses to resume
    a = fe.Body(MESH, 1000.0, NEO, fixed="left", name="a")
    b = fe.Body(MESH, 801.0, NEO, name="b", translate=(0.0, 10.0, 0.0), velocity=(0.3, 0.0, 0.5))
    with pytest.raises(fe.InvalidParameter):
        fe.simulate(fe.MultiBody([a, b], gravity=G, damping=fe.Rayleigh(0.5, 0.0)), fe.ImplicitEuler(),
                    dt=1e-2, steps=8, record_every=2, check_stability=False,
                    checkpoint_dir=tmp_path / "ck", resume=True)


# --- scenes and the command line ------------------------------------------------------------

SCENE = """\
[scene]
name = "pair"

[[body]]
name = "soft"
material = "neo_hookean"
E = 1e5
nu = 0.3
density = 1000.0
mesh = { kind = "beam", length = 0.1, width = 0.1, height = 0.1, cells = [1, 1, 1] }
translate = [0.0, 0.0, 0.3]
velocity = [0.0, 0.0, -1.0]

[[body]]
name = "beam"
material = "stvk"
E = 1e6
nu = 0.3
density = 2000.0
mesh = { kind = "beam", length = 0.4, width = 0.1, height = 0.1, cells = [4, 1, 1] }
fixed = ["left"]
traction = { right = [0.0, 0.0, -100.0] }
rotate = [0.0, 0.0, 90.0]  # degrees

[loads]
gravity = [0.0, 0.0, -9.81]

[integrator]
type = "implicit_euler"

[time]
dt = 0.01
duration = 0.04

[output]
render = []
color_by = "body"
"""


def test_scene_with_body_tables_builds_a_multibody():
    from fem_elastic.app.scene import parse_scene

    scene = parse_scene(SCENE, source="pair.toml")
    assert scene.variants == ["bodies"]
    run = scene.build()[0]
    model = run.model
    assert isinstance(model, fe.MultiBody) and model.names == ("soft", "beam")
    np.testing.assert_allclose(run.state.v[:model.models[0].ndofs].reshape(-1, 3)[:, 2], -1.0)
    # the beam is turned a quarter about z: its right end (x = 0.4) now lies at y = 0.4
    assert np.isclose(model.models[1].mesh.p[1].max(), 0.4) and np.isclose(model.models[1].mesh.p[0].min(), -0.1)
    assert model.models[1].loads and model.models[1].fixed_dofs.size
    assert run.info["bodies"][1]["name"] == "beam" and run.steps == 4


def test_single_body_scene_is_unchanged():
    from fem_elastic.app.scene import load_scene

    run = load_scene(Path(__file__).resolve().parent.parent / "scenes" / "twist.toml").build()[0]
    assert type(run.model) is fe.Model


@pytest.mark.parametrize("edit, key, match", [
    (lambda s: s.replace('name = "beam"', 'name = "soft"'), "body[1].name", "already used"),
    (lambda s: s.replace('translate = [0.0, 0.0, 0.3]', 'translat = [0.0, 0.0, 0.3]'), "body[0].translat",
     "translate"),
    (lambda s: s.replace('fixed = ["left"]', 'fixed = ["lft"]'), "body[1].fixed[0]", "left"),
    (lambda s: s.replace('name = "pair"', 'name = "pair"\n[initial]\nvelocity = [0, 0, 1]'), "initial",
     "belongs to each body"),
    (lambda s: s.replace('[[body]]\nname = "beam"', '[[body]]\nmass = 2\nname = "beam"'), "body[1].mass", "Allowed"),
    (lambda s: s.replace('name = "soft"\n', ''), "body[0].name", "name"),
    (lambda s: s + '[[compare]]\nname = "bodies"\n[compare.integrator]\ntype = "newmark"\n', "compare[0].name",
     "already used"),
    (lambda s: s + '[[compare]]\n[compare.body]\nmaterial = "stvk"\n', "compare[0].body", "Allowed"),
])
def test_bad_body_tables_are_scene_errors(edit, key, match):
    from fem_elastic.app.scene import SceneError, parse_scene

    with pytest.raises(SceneError, match=match) as info:
        parse_scene(edit(SCENE), source="pair.toml").build()
    assert info.value.key == key


def test_cli_runs_a_two_body_scene_and_writes_a_readable_series(tmp_path):
    from fem_elastic.app.cli import main
    from fem_elastic.app.vtu import read_series

    scene = tmp_path / "pair.toml"
    scene.write_text(SCENE)
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "-q"]) == 0
    series = read_series(tmp_path / "out" / "bodies")
    n_soft = 8  # the one-cell cube's vertices
    assert series.displacement.shape[1] == n_soft + MESH.p.shape[1]
    body = series.cell_data["body"]
    np.testing.assert_array_equal(body[0], np.repeat([0.0, 1.0], [6, 6 * 4]))
    # the soft cube falls freely: 1 m/s down plus gravity's 9.81 * t^2 / 2 (implicit Euler's
    # first-order error in t is O(g dt t) = 4e-3 m here, so a loose 5e-3 m tolerance)
    t = series.times[-1]
    assert series.displacement[-1, :n_soft, 2].mean() == pytest.approx(-t - 9.81 * t * t / 2, abs=5e-3)
    summary = json.loads((tmp_path / "out" / "bodies" / "summary.json").read_text())
    assert [b["name"] for b in summary["bodies"]] == ["soft", "beam"]


def test_two_bodies_scene_runs_a_few_steps_with_ipc_between_the_bodies():
    pytest.importorskip("ipctk")
    from fem_elastic.app.scene import load_scene

    run = load_scene(Path(__file__).resolve().parent.parent / "scenes" / "two_bodies.toml").build()[0]
    model = run.model
    assert model.names == ("ball", "block") and isinstance(run.integrator, fe.ImplicitEuler)
    assert model.contact is not None and model.contact.kind == "potential"
    intersecting = []
    traj = fe.simulate(model, run.integrator, dt=run.dt, steps=3, state=run.state,
                       callback=lambda k, s: intersecting.append(model.contact.has_intersections(s.x)))
    assert intersecting == [False] * 3
    # the ball falls freely in these first steps (it meets the block at t ~ 0.13 s)
    v_ball = traj.final_state.v[model.body_slice("ball")].reshape(-1, 3)[:, 2]
    # implicit Euler with alpha = 1/s drag: v = (v0 - g h) / (1 + alpha h) per step, to 1e-9 m/s
    v = -0.5
    for _ in range(3):
        v = (v - 9.81 * run.dt) / (1.0 + 1.0 * run.dt)
    np.testing.assert_allclose(v_ball, v, rtol=0, atol=1e-9)


def test_ipc_contact_between_two_bodies_runs_and_never_intersects():
    pytest.importorskip("ipctk")
    cube = fe.beam_mesh(0.1, 0.1, 0.1, (1, 1, 1))
    # turned by 0.3 rad and shifted: no edge of one cube parallel to the other's (ipctk's CCD is
    # slow on exactly parallel, touching edges; see the report of issue 17)
    soft = fe.Body(cube, 1000.0, fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), name="soft",
                   rotate=(0.0, 0.0, 0.3), translate=(0.02, 0.0, 0.104), velocity=(0.0, 0.0, -1.0))
    base = fe.Body(cube, 1000.0, fe.ElasticBody(fe.NeoHookean(E=1e7, nu=0.3)), name="base", fixed="bottom")
    model = fe.MultiBody([soft, base], gravity=G, contact=fe.IPCContact(dhat=1e-3))
    surface = model.collision_surface()
    np.testing.assert_array_equal(np.bincount(surface.body), [8, 8])
    assert surface.vertex_dofs[8:].min() == model.dof_offsets[1]
    intersecting = []
    run = fe.simulate(model, fe.ImplicitEuler(), dt=1e-2, steps=3,
                      callback=lambda k, s: intersecting.append(model.contact.has_intersections(s.x)))
    assert intersecting == [False] * 3
    z = run.final_state.x.reshape(-1, 3)[:, 2]
    # thrown at 1 m/s from 4 mm above: without contact it would be 26 mm deep by now; with it
    # the soft cube rests on the base's top (z = 0.1 m, compressed by less than 0.1 mm)
    assert z[:8].min() > z[8:].max() - 1e-4
    assert model.contact.diagnostics(run.final_state.x)["active_contacts"] > 0


def test_static_solve_of_mixed_orders_and_reactions_sum_to_the_weight():
    p2 = fe.Body(MESH, 1000.0, fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3), order=2), fixed="left", name="p2")
    p1 = fe.Body(MESH, 1000.0, LINEAR, fixed="left", name="p1", translate=(0.0, 1.0, 0.0))
    model = fe.MultiBody([p2, p1], gravity=G)
    assert model.space.order is None  # bodies of different orders
    result = fe.solve_static(model)
    alone = fe.solve_static(fe.Model(MESH, 1000.0, p2.body, fixed="left", gravity=G))
    nv = MESH.p.shape[1]
    # the same Newton iterations on a block-diagonal system: equal to round-off (1e-12 relative)
    np.testing.assert_allclose(result.displacement[:nv], alone.displacement,
                               atol=1e-12 * np.abs(alone.displacement).max())
    # equilibrium: the supports carry both bodies' weight, 2 * rho * V * g (to Newton's tolerance)
    np.testing.assert_allclose(result.reactions.sum(axis=0), [0.0, 0.0, 2 * 1000.0 * 0.004 * 9.81], atol=1e-6)


def test_vtu_output_of_quadratic_bodies_is_a_typed_error(tmp_path):
    p2 = fe.Body(MESH, 1000.0, fe.ElasticBody(fe.LinearElastic(E=1e5, nu=0.3), order=2), name="p2")
    with pytest.raises(fe.InvalidParameter, match="order=1"):
        fe.SeriesWriter(fe.MultiBody([p2]), tmp_path / "out")


def test_render_colours_each_body_in_its_own_colour(tmp_path):
    pytest.importorskip("pyvista")
    iio = pytest.importorskip("imageio.v3")
    from fem_elastic.app.render import render_frame

    model = fe.MultiBody([fe.Body(MESH, 1000.0, LINEAR, name="a"),
                          fe.Body(MESH, 1000.0, LINEAR, name="b", translate=(0.0, 0.0, 0.2))])
    writer = fe.SeriesWriter(model, tmp_path / "out")
    fe.simulate(model, fe.SymplecticEuler(), dt=1e-4, steps=1, observers=[writer])
    png = render_frame([tmp_path / "out"], tmp_path / "pair.png", color_by="body", size=(160, 120))
    rgb = iio.imread(png)[..., :3].astype(int)
    r, b = rgb[..., 0], rgb[..., 2]
    # tab10: body 0 blue (31, 119, 180), body 1 orange (255, 127, 14); shading scales both, so
    # count pixels by which of red and blue dominates by a clear margin (60 of 255)
    assert np.count_nonzero(b - r > 60) > 50 and np.count_nonzero(r - b > 60) > 50


@pytest.mark.parametrize("orders", [(2, 2), (2, 1)])
def test_drawing_a_trajectory_of_quadratic_bodies_is_a_typed_error(orders):
    pytest.importorskip("pyvista")
    bodies = [fe.Body(MESH, 1000.0, fe.ElasticBody(fe.LinearElastic(E=1e5, nu=0.3), order=o), fixed="left",
                      name=f"b{i}", translate=(0.0, float(i), 0.0)) for i, o in enumerate(orders)]
    model = fe.MultiBody(bodies, gravity=G)
    traj = fe.simulate(model, fe.SymplecticEuler(), dt=1e-4, steps=1)
    # as MultiBody.to_pyvista: P1 only for several bodies (a P2 body's nodes are not the
    # stacked mesh's vertices, so a mixed grid would be drawn wrong)
    for draw in (traj.to_pyvista, lambda: traj.plot(off_screen=True)):
        with pytest.raises(fe.InvalidParameter, match=r"linear bodies only \(order=1\)"):
            draw()
    with pytest.raises(fe.InvalidParameter, match=r"linear bodies only"):
        model.to_pyvista()
