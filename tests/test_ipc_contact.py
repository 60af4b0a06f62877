"""IPC contact through ipctk: collision surface, barrier derivatives, CCD, momentum, friction, bad input."""

from __future__ import annotations

import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

import fem_elastic as fe

ipctk = pytest.importorskip("ipctk")

SIZE = 0.1  # m, edge of the small cubes


def cube(size=SIZE, n=1, shift=(0.0, 0.0, 0.0)):
    m = fe.beam_mesh(length=size, width=size, height=size, cells=(n, n, n))
    return m.p.T + np.asarray(shift), m.t.T


def pieces(*parts):
    """One mesh made of disjoint pieces ``(points, tets)``."""
    pts, tets, base = [], [], 0
    for p, t in parts:
        pts.append(p)
        tets.append(t + base)
        base += len(p)
    return fe.mesh_from_arrays(np.vstack(pts), np.vstack(tets))


def two_cubes(gap):
    """Two cubes face to face along x (aligned: a head-on impact has no sideways way round)."""
    return pieces(cube(n=2), cube(n=2, shift=(SIZE + gap, 0.0, 0.0)))


def body(E=1e5):
    return fe.ElasticBody(fe.NeoHookean(E=E, nu=0.3))


# --- the collision surface ---------------------------------------------------------------------


def test_collision_surface_is_closed_and_outward():
    model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), 1000.0, body())
    s = model.collision_surface()
    assert s is model.collision_surface()  # cached
    # a closed surface of genus 0: V - E + F = 2
    assert s.n_vertices - len(s.edges) + len(s.faces) == 2
    # outward: the divergence theorem gives the enclosed volume with a + sign
    P = s.positions(model.X)
    a, b, c = (P[s.faces[:, i]] for i in range(3))
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    assert volume == pytest.approx(1.0 * 0.1 * 0.1, rel=1e-12)  # round-off of a sum of products
    assert np.array_equal(s.rest, P)


def test_stack_offsets_dofs_and_sets_body_ids():
    model = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), 1000.0, body())
    s = model.collision_surface()
    both = fe.CollisionSurface.stack([s, s], [0, model.ndofs])
    assert both.n_vertices == 2 * s.n_vertices
    assert np.array_equal(both.vertex_dofs[s.n_vertices:], s.vertex_dofs + model.ndofs)
    assert np.array_equal(both.faces[len(s.faces):], s.faces + s.n_vertices)
    assert set(both.body[: s.n_vertices]) == {0} and set(both.body[s.n_vertices:]) == {1}


def test_p2_surface_uses_vertices_only():
    mesh = fe.beam_mesh(cells=(2, 1, 1))
    m1 = fe.Model(mesh, 1000.0, body())
    m2 = fe.Model(mesh, 1000.0, fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3), order=2))
    s1, s2 = m1.collision_surface(), m2.collision_surface()
    assert np.array_equal(s1.faces, s2.faces)
    assert np.array_equal(m2.X[s2.vertex_dofs], s2.rest)


# --- the barrier's derivatives ---------------------------------------------------------------------


def _fd_model():
    gap = 5e-4  # inside dhat: several pairs active
    model = fe.Model(two_cubes(gap), 1000.0, body(),
                     contact=fe.IPCContact(dhat=1e-3, kappa=1e6))
    return model, model.contact


@pytest.mark.filterwarnings("ignore:IPC contact")
def test_barrier_gradient_and_hessian_match_finite_differences():
    model, c = _fd_model()
    rng = np.random.default_rng(0)
    x = model.X + 2e-5 * rng.standard_normal(model.ndofs)  # small: the gap stays > 0
    assert c.diagnostics(x)["active_contacts"] > 0
    g = c.gradient(x)
    H = c.hessian(x, project=False).toarray()
    d = rng.standard_normal(model.ndofs)
    eps = 1e-8  # m: central differences, truncation O(eps^2 |E'''|) far below round-off
    fd = (c.energy(x + eps * d) - c.energy(x - eps * d)) / (2 * eps)
    assert fd == pytest.approx(g @ d, rel=1e-5)  # eps_machine |E| / eps relative round-off
    fdH = (c.gradient(x + eps * d) - c.gradient(x - eps * d)) / (2 * eps)
    np.testing.assert_allclose(fdH, H @ d, rtol=1e-5, atol=1e-6 * np.abs(H @ d).max())
    # only surface DOFs are touched, the Hessian is symmetric, the projected one PSD
    assert np.all(g[np.setdiff1d(np.arange(model.ndofs), c.surface.vertex_dofs.ravel())] == 0)
    np.testing.assert_allclose(H, H.T, atol=1e-9 * np.abs(H).max())
    Hp = c.hessian(x, project=True).toarray()
    assert np.linalg.eigvalsh(Hp).min() >= -1e-9 * np.abs(Hp).max()  # PSD to round-off


def test_one_pair_pushes_with_the_barriers_force_and_its_small_gap_asymptote():
    """A vertex at gap d above a triangle, the only pair within dhat: the force on it is
    kappa |b'(d^2)| 2d (ipctk's b(s, t) = -(s - t)^2 ln(s / t) on squared distances), and for
    d << dhat 2 kappa dhat^4 / d, the law IPCContact's kappa docstring and the user guide's
    "Choosing kappa" give for the resting gap."""
    dhat, kappa = 1e-3, 1e7
    lower = (np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]),
             np.array([[0, 2, 1, 3]]))  # its top face is the triangle z = 0
    # a tet pointing down at (0.25, 0.25), its other edges and vertices 0.1 m and more away
    upper = (np.array([[0.25, 0.25, 0.01], [0.15, 0.25, 0.3], [0.35, 0.2, 0.3], [0.3, 0.35, 0.3]]),
             np.array([[0, 1, 2, 3]]))
    model = fe.Model(pieces(lower, upper), 1000.0, body(),
                     contact=fe.IPCContact(dhat=dhat, kappa=kappa))
    c = model.contact
    apex_z = 3 * 4 + 2  # the upper tet's first node (4 in the mesh), z
    t = dhat ** 2
    for d in (1e-5, 1e-4, 5e-4):
        x = model.X.copy()
        x[apex_z] = d
        diag = c.diagnostics(x)
        assert diag["active_contacts"] == 1 and diag["min_distance"] == pytest.approx(d, rel=1e-12)
        force = -c.gradient(x)[apex_z]  # upward, on the vertex
        s = d * d
        db_ds = -2.0 * (s - t) * np.log(s / t) - (s - t) ** 2 / s
        assert force == pytest.approx(-kappa * db_ds * 2.0 * d, rel=1e-10)  # round-off
        # with r = (d/dhat)^2 the force over the asymptote is exactly (1 - r)^2 + 2 r (1 - r)
        # ln(1/r) = 1 + 2 r (ln(1/r) - 1) + r^2 (1 - 2 ln(1/r)): the first correction is 0.16 %
        # at d = dhat / 100 and 1.6 % at dhat / 10, the rest 1.7e-7 and 8.2e-4, below (d/dhat)^3
        if d <= 1e-4:
            rel = 2 * (d / dhat) ** 2 * (np.log(t / s) - 1.0)
            assert force / (2.0 * kappa * dhat ** 4 / d) == pytest.approx(1.0 + rel, abs=(d / dhat) ** 3)


# --- CCD and no intersection ---------------------------------------------------------------------


def _colliding(speed=10.0, gap=0.05, **kw):
    model = fe.Model(two_cubes(gap), 1000.0, body(E=1e8), contact=fe.IPCContact(dhat=1e-3, **kw))
    n = model.ndofs // 2  # the first cube's DOFs come first
    v = np.zeros(model.ndofs)
    v[0:n:3] = speed
    v[n::3] = -speed
    return model, fe.State(model.X.copy(), v, 0.0)


def test_max_step_never_steps_into_intersection():
    model, state = _colliding()
    c = model.contact
    dx = state.v * (1 / 30)  # 10 m/s against 10 m/s over 1/30 s: the cubes pass through
    V0 = c._V(model.X)
    accd = ipctk.AdditiveCCD()  # ipctk's default (Tight-Inclusion) is slow on coplanar faces
    assert not ipctk.is_step_collision_free(c.mesh, V0, c._V(model.X + dx), narrow_phase_ccd=accd)
    alpha = model.max_step(model.X, dx)
    # additive CCD stops at 0.9 of the gap: 0.05 m of a 0.667 m closing distance, x 0.9
    assert 0.5 * 0.9 * 0.05 / (20 / 30) < alpha < 0.05 / (20 / 30)
    V1 = c._V(model.X + alpha * dx)
    assert ipctk.is_step_collision_free(c.mesh, V0, V1, narrow_phase_ccd=accd)
    assert not any(c.has_intersections(model.X + t * alpha * dx) for t in np.linspace(0, 1, 11))
    assert not c.has_intersections(model.X + alpha * dx)


def test_large_step_never_intersects():
    """dt = 1/30 s at 10 m/s against 10 m/s: every step and every Newton trial is intersection-free.

    (At this step the minimiser of the incremental potential lies past the other cube, and
    Newton's CCD-bounded path slides the soft pieces round each other instead of through:
    no intersection, but not a bounce; the bounce is checked at a smaller step below.)
    """
    model, state = _colliding()
    c = model.contact
    seen = []
    orig = c.max_step

    def checked(x, dx):
        alpha = orig(x, dx)
        seen.append(c.has_intersections(x + alpha * dx))
        return alpha

    c.max_step = checked
    ie = fe.ImplicitEuler(max_iter=200)
    state = ie.step(model, state, 1 / 30)
    assert not c.has_intersections(state.x)
    assert len(seen) > 10 and not any(seen)  # every Newton iterate of the step was checked


def test_two_pieces_bounce_without_intersection_and_keep_momentum():
    """Head on at 5 m/s each, dt = 5 ms: no step intersects, the pieces bounce, momentum is kept.

    Every force in G but the inertia (elasticity, barrier) is invariant under translation, so
    only Newton's residual moves the momentum: below rtol = 1e-10 of the momentum flux
    ||M v|| / h, times h, per step (relative 1e-10 sqrt(ndofs)), far below the 1e-8 asserted.
    """
    model, state = _colliding(speed=5.0, gap=0.01, kappa=1e9)
    ie = fe.ImplicitEuler(max_iter=200, rtol=1e-10)
    c = model.contact
    p_ref = 0.5 * np.abs(model.lumped_mass * state.v).sum() / 3 * 2  # |p| of one piece (kg m/s)
    p0 = model.linear_momentum(state.v)
    touched = False
    for _ in range(5):
        state = ie.step(model, state, 0.005)
        assert not c.has_intersections(state.x)
        d = c.diagnostics(state.x)
        touched |= d["active_contacts"] > 0
        drift = np.linalg.norm(model.linear_momentum(state.v) - p0) / p_ref
        assert drift < 1e-8
    n = model.ndofs // 2
    assert touched
    assert state.v[0:n:3].mean() < 0 < state.v[n::3].mean()  # they met and bounced back


def test_projective_dynamics_steps_are_cut_by_ccd():
    """Projective dynamics adds the barrier's gradient to its local/global iterations and cuts
    every global update to its collision-free fraction: the pieces bounce, never intersecting."""
    mesh = pieces(cube(n=2), cube(n=2, shift=(SIZE + 0.01, 0.0, 0.0)))
    model = fe.Model(mesh, 1000.0, fe.ElasticBody(fe.ProjectiveCorotated(E=1e6, nu=0.3)),
                     contact=fe.IPCContact(dhat=1e-3, kappa=1e9))
    n = model.ndofs // 2
    v = np.zeros(model.ndofs)
    v[0:n:3], v[n::3] = 3.0, -3.0
    state = fe.State(model.X.copy(), v, 0.0)
    pd = fe.ProjectiveDynamics()
    for _ in range(4):
        state = pd.step(model, state, 0.005)
        assert not model.contact.has_intersections(state.x)
    assert state.v[0:n:3].mean() < 0 < state.v[n::3].mean()


def test_simulate_records_contact_diagnostics_and_reports_intersection_at_the_end():
    from fem_elastic.dynamics.contact_watch import ContactIntersectionWarning

    model, state = _colliding(speed=5.0, gap=0.01, kappa=1e9)
    tr = fe.simulate(model, fe.ImplicitEuler(max_iter=200), dt=0.005, steps=3, state=state)
    st, summary = tr.step_stats, tr.summary()
    assert st["contact_active"].shape == (3,) and st["contact_active"][0] > 0
    assert 0 < summary["contact_min_distance"] < 1e-3  # inside dhat, never 0
    assert summary["contact_force_max"] > 0 and summary["contact_intersecting_at_end"] is False
    # a contact that ends intersecting is reported, never silent
    model.contact.has_intersections = lambda x: True
    with pytest.warns(ContactIntersectionWarning, match="intersecting"):
        tr = fe.simulate(model, fe.ImplicitEuler(max_iter=200), dt=0.005, steps=1, state=state)
    assert tr.summary()["contact_intersecting_at_end"] is True


def test_overlapping_pieces_at_start_are_refused():
    mesh = pieces(cube(), cube(shift=(0.5 * SIZE, 0.3 * SIZE, 0.2 * SIZE)))
    with pytest.raises(fe.InvalidParameter, match="overlapping"):
        fe.Model(mesh, 1000.0, body(), contact=fe.IPCContact(dhat=1e-3))


@pytest.mark.parametrize("dhat", [0.0, -1e-3, float("nan"), "1e-3"])
def test_bad_dhat(dhat):
    with pytest.raises(fe.InvalidParameter, match="dhat"):
        fe.IPCContact(dhat=dhat)


def test_bad_contact_arguments():
    with pytest.raises(fe.InvalidParameter, match="kappa"):
        fe.IPCContact(dhat=1e-3, kappa="big")
    with pytest.raises(fe.InvalidParameter, match="friction"):
        fe.IPCContact(dhat=1e-3, friction=-0.1)
    with pytest.raises(fe.InvalidParameter, match="broad_phase"):
        fe.IPCContact(dhat=1e-3, broad_phase="octree")
    with pytest.raises(fe.InvalidParameter, match="bind"):
        fe.Model(fe.beam_mesh(cells=(2, 1, 1)), 1000.0, body(), contact=fe.IPCContact)


def test_body_without_surface_is_refused():
    empty = types.SimpleNamespace(
        mesh=types.SimpleNamespace(p=np.zeros((3, 0)), t=np.zeros((4, 0), dtype=np.int64)),
        space=types.SimpleNamespace(vertex_dofs=np.zeros((0, 3), dtype=np.int64)),
    )
    with pytest.raises(fe.InvalidMesh, match="no surface"):
        fe.collision_surface(empty)


# --- friction on an incline ----------------------------------------------------------------------


def _incline(theta, mu, steps, dt=0.01):
    """A stiff block resting on a fixed slab, gravity tilted by theta (the incline's frame).

    Tilting gravity instead of the slab keeps the contact faces on mesh-aligned planes, so the
    slope is exact; the slab is held (fixed), so it is the incline.
    """
    gap = 5e-4
    slab = cube(size=1.0, n=1)
    slab = (slab[0] * np.array([0.6, 0.6, 0.05]) + np.array([-0.3, -0.3, -0.05]), slab[1])
    block = cube(size=SIZE, shift=(-0.05, -0.05, gap))
    mesh = pieces(slab, block)
    fixed = np.zeros(mesh.p.shape[1], dtype=bool)
    fixed[: len(slab[0])] = True
    g = 9.81
    model = fe.Model(
        mesh, 1000.0, body(E=1e7), fixed=fixed,
        gravity=(g * np.sin(theta), 0.0, -g * np.cos(theta)),
        # two lagged solves per step: the normal force of the landing is re-lagged at the solution
        contact=fe.IPCContact(dhat=1e-3, kappa=1e9, friction=mu, epsv=1e-4, friction_iterations=2),
    )
    ie = fe.ImplicitEuler(max_iter=200)
    state = fe.State.rest(model)
    free_block = np.zeros(model.ndofs, dtype=bool)
    free_block[model.space.vertex_dofs[len(slab[0]):, 0]] = True
    vx = []
    for _ in range(steps):
        state = ie.step(model, state, dt)
        assert not model.contact.has_intersections(state.x)
        vx.append(state.v[free_block].mean())
    return np.array(vx)


@pytest.mark.filterwarnings("ignore:IPC contact")
def test_block_on_incline_slides_with_coulomb_acceleration():
    theta, mu, dt = np.radians(30.0), 0.3, 0.01
    vx = _incline(theta, mu, steps=25, dt=dt)
    a = np.polyfit(dt * np.arange(10, 25), vx[10:], 1)[0]  # after the block has settled
    expected = 9.81 * (np.sin(theta) - mu * np.cos(theta))
    # measured 0.13 % off: IPC's friction is Coulomb's only above the smoothing speed epsv
    # (1e-4 m/s, against ~0.2 m/s here) and the barrier lets the block bob on the slab after the
    # landing; 2 % is the margin for those, while a friction force 2 % off would shift a by
    # 0.02 mu g cos(theta) = 0.05 m/s^2, i.e. by 2.2 % of the expected 2.36 m/s^2
    assert a == pytest.approx(expected, rel=0.02)


@pytest.mark.filterwarnings("ignore:IPC contact")
def test_block_on_incline_sticks_below_the_friction_angle():
    theta, mu = np.radians(10.0), 0.3  # tan(10 deg) = 0.18 < 0.3
    vx = _incline(theta, mu, steps=15)
    # frictionless, the block would slide at g sin(theta) t = 0.26 m/s after 0.15 s; the smoothed
    # (IPC) friction sticks by creeping below epsv = 1e-4 m/s once the landing's vibration (a few
    # 1e-4 m/s in the first steps) has died out
    assert np.abs(vx[-5:]).max() < 1e-4
    assert np.abs(vx[5:]).max() < 1e-3  # after the 5e-4 m fall onto the slab (first 5 steps)


def test_bench_ipc_quick_prints_its_figures():
    """The drop of scenes/two_bodies.toml: a row per step, the summary by kind of step, and the
    broad phase's fitted exponent."""
    script = Path(__file__).resolve().parent.parent / "scripts" / "bench_ipc.py"
    r = subprocess.run([sys.executable, str(script), "--quick", "--repeats", "1"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    out = r.stdout
    rows = [line for line in out.splitlines() if line[:5].strip().isdigit() and "|" in line]
    assert len(rows) == 20  # --quick: 20 steps, one row each
    # the ball meets the block within those 20 steps (at t ~ 0.14 s): both kinds of step occur
    assert "steps with no IPC pair within dhat" in out and "steps with IPC pairs" in out
    assert "whole drop:" in out and "ratio (IPC / no contact)" in out and "fitted exponent" in out
    assert "kappa = 1e+07" in out  # the scene's own barrier stiffness


def test_bench_ipc_kappa_replaces_the_scenes_stiffness():
    script = Path(__file__).resolve().parent.parent / "scripts" / "bench_ipc.py"
    r = subprocess.run([sys.executable, str(script), "--quick", "--steps", "2", "--no-broad-phase",
                        "--kappa", "auto"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "kappa = auto" in r.stdout
    for bad_value in ("stiff", "-1", "nan"):
        bad = subprocess.run([sys.executable, str(script), "--quick", "--kappa", bad_value],
                             capture_output=True, text=True, timeout=300)
        assert bad.returncode == 2 and "--kappa takes a stiffness in N/m^3 (finite, > 0)" in bad.stderr
    cubes = subprocess.run([sys.executable, str(script), "--quick", "--cubes", "--kappa", "1e7"],
                           capture_output=True, text=True, timeout=300)
    assert cubes.returncode == 2 and "the cubes use IPC's adaptive one" in cubes.stderr


def test_bench_ipc_cubes_prints_both_steps():
    script = Path(__file__).resolve().parent.parent / "scripts" / "bench_ipc.py"
    r = subprocess.run([sys.executable, str(script), "--quick", "--cubes", "--repeats", "1",
                        "--no-broad-phase"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "first contact: ratio (IPC / no contact)" in r.stdout
    assert "resting contact: ratio (IPC / no contact)" in r.stdout


@pytest.mark.filterwarnings("ignore:IPC contact")
@pytest.mark.parametrize("kappa", ["scene", "auto"])
def test_an_ipc_impact_that_runs_out_of_newton_iterations_says_to_raise_max_iter(kappa):
    """Halving dt does not shorten an IPC impact: the error names max_iter and kappa, not only
    dt (and says what "auto" does only when the barrier's stiffness is IPC's adaptive one)."""
    from fem_elastic.app.scene import load_scene

    scene = load_scene(Path(__file__).resolve().parent.parent / "scenes" / "two_bodies.toml")
    if kappa == "auto":
        scene.spec["contact"]["kappa"] = "auto"
    run = scene.build()[0]
    state = run.state
    for _ in range(13):  # to the step where the ball meets the block (t = 0.13 s)
        state = run.integrator.step(run.model, state, run.dt)
    assert run.model.contact.diagnostics(state.x)["active_contacts"] == 0
    with pytest.raises(fe.Diverged, match=r"max_iter \(e\.g\. fe\.ImplicitEuler\(max_iter=200\)") as err:
        fe.ImplicitEuler(max_iter=3, max_dt_cuts=1).step(run.model, state, run.dt)
    assert "stiffen the barrier (fe.IPCContact(kappa=...)" in str(err.value)
    assert ("'auto' keeps them far closer" in str(err.value)) == (kappa == "auto")
    # the same step with the scene's own budget takes more than 3 iterations and lands apart
    ie = fe.ImplicitEuler(max_iter=200)
    out = ie.step(run.model, state, run.dt)
    assert ie.last_stats.newton_iterations > 3
    assert run.model.contact.diagnostics(out.x)["active_contacts"] > 0
    assert not run.model.contact.has_intersections(out.x)


def test_bench_ipc_trace_logs_both_steps():
    """--trace: each Newton iteration and CCD bound of the first-contact and the resting step."""
    script = Path(__file__).resolve().parent.parent / "scripts" / "bench_ipc.py"
    # one stream, unbuffered: the Newton log (stderr) in order with the prints (stdout)
    r = subprocess.run([sys.executable, str(script), "--quick", "--cubes", "--trace"],
                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=300,
                       env={**os.environ, "PYTHONUNBUFFERED": "1"})
    assert r.returncode == 0, r.stdout
    first, _, rest = r.stdout.partition("first contact with IPC")
    assert "Newton 0: ||g||" in first and "resting contact with IPC" in rest
    # the resting step alone: its iterations, each after the CCD bound of its step (the settling
    # steps between the two are not logged)
    rest = rest.split("\n", 1)[1]
    assert rest.count("CCD: collision-free fraction") >= 2 and rest.count("Newton ") >= 2


# --- adaptive stiffness and Newton's convergence in contact --------------------------------------


def _resting_drop(n=3):
    """The benchmark's scene, small: a cube dropped from dhat / 2 onto a cube with a fixed bottom."""
    size, gap = 0.2, 5e-4
    m = fe.beam_mesh(length=size, width=size, height=size, cells=(n, n, n))
    p, t = m.p.T, m.t.T
    mesh = pieces((p, t), (p + np.array([0.0, 0.0, size + gap]), t))
    fixed = np.zeros(mesh.p.shape[1], dtype=bool)
    fixed[: len(p)] = mesh.p[2, : len(p)] < 1e-12
    return fe.Model(mesh, 1000.0, fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3)), fixed=fixed,
                    gravity=(0.0, 0.0, -9.81), contact=fe.IPCContact(dhat=1e-3))


@pytest.mark.filterwarnings("ignore:IPC contact")
def test_auto_kappa_is_constant_inside_a_step_and_newton_converges_quadratically_in_contact(
        monkeypatch):
    import fem_elastic.dynamics.integrators.implicit as implicit

    model = _resting_drop()
    c = model.contact
    seen, histories = [], []
    linearize, newton = c.linearize, implicit.newton_minimize

    def spy(x, project=False):
        out = linearize(x, project)
        seen.append(c.kappa)
        return out

    def newton_spy(*args, **kw):
        res = newton(*args, **kw)
        histories.append(res.residual_history)
        return res

    c.linearize = spy
    monkeypatch.setattr(implicit, "newton_minimize", newton_spy)
    ie, state = fe.ImplicitEuler(max_iter=200), fe.State.rest(model)
    for _ in range(5):
        seen.clear()
        state = ie.step(model, state, 0.01)
        # IPC's rule: set at the first contact, updated only between steps (begin_solve)
        assert len(set(seen)) == 1
    assert c.diagnostics(state.x)["active_contacts"] > 0 and not c.has_intersections(state.x)
    # in resting contact Newton ends on the barrier's exact tangent: quadratic convergence, the
    # last residual below 1e-2 of the one before (measured 5e-2 -> 1e-4 -> 6e-8 here; a linear
    # tail, as the clamped tangent alone gave on the 2592-tet version of this scene, shrinks by a
    # factor of about 0.3 per iteration)
    r = histories[-1]
    assert r[-1] <= 1e-2 * r[-2]


@pytest.mark.filterwarnings("ignore:IPC contact")
def test_linearize_gives_the_exact_barrier_hessian_when_newton_asks_for_it():
    model, c = _fd_model()
    x = model.X.copy()
    # ipctk assembles the pair Hessians in parallel, so two calls may sum in another order:
    # equal to 1e-12 of the largest entry (round-off), while exact and projected differ at O(1)
    _, H = c.linearize(x, project=False)
    scale = abs(H).max()
    assert abs(H - c.hessian(x, project=False)).max() <= 1e-12 * scale
    _, Hp = c.linearize(x, project=True)
    assert abs(Hp - c.hessian(x, project=True)).max() <= 1e-12 * scale
    assert abs(H - Hp).max() > 1e-3 * scale  # the two are different matrices here
