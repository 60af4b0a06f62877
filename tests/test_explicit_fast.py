"""The explicit steps' fast path: the threaded fused gradient, cached inverse mass, no per-step growth.

Issue 19, item 5. The threaded gradient (:func:`fem_elastic.discretization.fused.threaded`)
sums the seam vertices' element contributions in another order than the serial loop, so
the two agree to round-off, not bit for bit; the serial kernel stays selectable.
"""

from __future__ import annotations

import gc
import tracemalloc

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.discretization import fused

pytestmark = pytest.mark.skipif(not fused.available(), reason="numba is not importable")

# A reordering of a sum of n terms changes it by at most ~n eps times the sum of the terms'
# magnitudes; a vertex has <= 24 tets here, and the entries of g are sums of terms of the size
# of the largest entries (the element forces largely cancel at interior vertices), so 1e-12
# relative to max|g| is ~50x the worst reordering error while any wrong or missing element
# contribution (~1e-2 of max|g| on this mesh) would fail it by ten orders of magnitude.
REORDER_RTOL = 1e-12


def _model(cells=(12, 3, 3), gravity=None, material=None):
    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells)
    return fe.Model(mesh, density=1000.0, body=fe.ElasticBody(material or fe.NeoHookean(E=1e6, nu=0.4)),
                    fixed="left", gravity=gravity)


def _bent(model, seed=0):
    rng = np.random.default_rng(seed)
    X = model.X.reshape(-1, 3)
    u = np.zeros_like(X)
    u[:, 2] = -0.05 * X[:, 0] ** 2  # a bend, plus noise far below the element size (8 mm)
    return model.X + u.ravel() + 1e-4 * rng.standard_normal(model.ndofs)


def _element_at_a_time(kern, x, start, stop, out):
    """The force loop as it was before the blocked kernel: one element at a time, F and P from
    the scalar kernels of ``_fused_kernels``, the scatter in Python (IEEE doubles, the same
    operations in the same order)."""
    from fem_elastic.discretization import _fused_kernels as K

    g = kern.geo
    for e in range(start, stop):
        F = K._deformation_gradient(x, g.X, g.nodes, g.Dm_inv, e)
        p = K.P(kern.kind, F, kern.prm)
        v, d = g.V[e], g.Dm_inv[e]
        k = 3 * g.nodes[e]
        for i in range(3):
            q0, q1, q2 = p[3 * i] * v, p[3 * i + 1] * v, p[3 * i + 2] * v
            f1 = q0 * d[0, 0] + q1 * d[0, 1] + q2 * d[0, 2]
            f2 = q0 * d[1, 0] + q1 * d[1, 1] + q2 * d[1, 2]
            f3 = q0 * d[2, 0] + q1 * d[2, 1] + q2 * d[2, 2]
            out[k[1] + i] += f1
            out[k[2] + i] += f2
            out[k[3] + i] += f3
            out[k[0] + i] -= f1 + f2 + f3


@pytest.mark.parametrize("material", [fe.LinearElastic(E=1e6, nu=0.4), fe.StVK(E=1e6, nu=0.4),
                                      fe.NeoHookean(E=1e6, nu=0.4),
                                      fe.StableNeoHookean(E=1e6, nu=0.4)])
def test_blocked_gradient_is_the_element_loop_bit_for_bit(material):
    """The blocked, vectorised force loop gives the same bits as the element-at-a-time loop: the
    same operations in the same order (no fastmath, no FMA), the scatter in element order. The
    ranges start and stop off the block boundaries (a part's interior), and 5 x 3 x 3 cells give
    270 tets, not a multiple of the block, so the remainder of a block is checked too."""
    from fem_elastic.discretization import _fused_gradient_kernels as B

    model = _model(cells=(5, 3, 3), material=material)
    kern = fused.kernels_for(model.body_potential.material, model.space)
    x = _bent(model)
    g = kern.geo
    ne = g.nodes.shape[0]
    assert ne % B.BLOCK != 0
    blocked = np.empty(model.ndofs)
    B.gradient_p1(x, g.X, np.empty(model.ndofs), g.nodes, g.blocks, kern.kind, kern.prm, blocked)
    ref = np.zeros(model.ndofs)
    _element_at_a_time(kern, x, 0, ne, ref)
    assert np.array_equal(blocked, ref)
    part = np.zeros(model.ndofs)
    DB, first = B.blocks(g.Dm_inv, g.V, [0, 7, ne - 3])  # the middle range's blocks start at 7
    B.gradient_range(x - g.X, g.nodes, DB, first[1], kern.kind, kern.prm, 7, ne - 3, part)
    ref = np.zeros(model.ndofs)
    _element_at_a_time(kern, x, 7, ne - 3, ref)
    assert np.array_equal(part, ref)


def test_kernel_caches_are_dropped_when_a_module_they_inline_changes(tmp_path):
    """numba's cache checks only a kernel's own file: drop_stale_caches removes a kernel
    module's cache files when a file it depends on changed, and leaves them otherwise."""
    from fem_elastic.discretization._fused_kernels import drop_stale_caches

    mod, dep = tmp_path / "kern.py", tmp_path / "laws.py"
    mod.write_text("x = 1\n")
    dep.write_text("def P(F): return F\n")
    cache = tmp_path / "__pycache__"
    cache.mkdir()
    files = [cache / "kern.f-10.py311.nbi", cache / "kern.f-10.py311.1.nbc"]
    other = cache / "laws.g-3.py311.nbi"  # another module's cache: never touched
    for f in (*files, other):
        f.write_bytes(b"cached")
    assert drop_stale_caches(str(mod), str(dep))  # no digest yet: dropped, digest written
    assert not any(f.exists() for f in files) and other.exists()
    for f in files:
        f.write_bytes(b"cached")
    assert not drop_stale_caches(str(mod), str(dep))  # unchanged dependency: kept
    assert all(f.exists() for f in files)
    dep.write_text("def P(F): return 2 * F\n")
    assert drop_stale_caches(str(mod), str(dep))  # edited dependency: dropped again
    assert not any(f.exists() for f in files) and other.exists()


def test_blocked_gradient_keeps_nan_for_inverted_elements():
    """An inverted tet (J < 0) makes the Neo-Hookean force NaN, as the numpy material does (the
    explicit integrators stop on it); the blocked ln J pass must not hide it."""
    model = _model(cells=(5, 3, 3))
    kern = fused.kernels_for(model.body_potential.material, model.space)
    x = model.X.copy().reshape(-1, 3)
    x[kern.geo.nodes[100, 0]] += np.array([0.0, 0.0, 0.3])  # 0.3 m through its neighbours (8 mm cells)
    g = kern.gradient(x.ravel())
    assert np.isnan(g).any()


@pytest.mark.parametrize("n_parts", [2, 3, 5])
def test_partitioned_gradient_matches_the_serial_one(n_parts):
    model = _model(cells=(24, 3, 3))  # long enough for 5 slabs with interiors
    kern = fused.kernels_for(model.body_potential.material, model.space)
    x = _bent(model)
    k, g = kern._g, kern.geo
    serial = np.empty(model.ndofs)
    k.gradient_p1(x, g.X, np.empty(model.ndofs), g.nodes, g.blocks, kern.kind, kern.prm, serial)
    parts = g.parts(n_parts)
    threaded = np.empty(model.ndofs)
    k.gradient_p1_parts(x, g.X, np.empty(model.ndofs), parts.nodes, parts.DB, parts.first_block,
                        kern.kind, kern.prm, parts.part_start, threaded)
    assert np.max(np.abs(threaded - serial)) <= REORDER_RTOL * np.max(np.abs(serial))
    # the parts' interiors touch disjoint vertex sets (what makes the scatter race-free)
    start = parts.part_start
    seen = np.full(model.ndofs // 3, -1)
    for p in range(n_parts):
        verts = np.unique(parts.nodes[start[p]:start[p + 1]])
        assert np.all(seen[verts] == -1)
        seen[verts] = p
    assert 0 < start[-1] - start[-2] < g.nodes.shape[0] / 2  # a seam, and not everything
    assert np.array_equal(np.sort(parts.order), np.arange(g.nodes.shape[0]))  # every element once


def test_gradient_through_the_api_threaded_and_serial(monkeypatch):
    numba = pytest.importorskip("numba")
    model = _model()
    pot = model.body_potential
    x = _bent(model, seed=1)
    monkeypatch.setenv(fused.THREADS_ENV, "0")
    serial = pot.gradient(x)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        monkeypatch.setenv(fused.THREADS_ENV, "1")
        assert np.array_equal(pot.gradient(x), serial)  # below MIN_THREADED_ELEMENTS: serial
        monkeypatch.setattr(fused, "MIN_THREADED_ELEMENTS", 0)
        threaded = pot.gradient(x)
        out = np.full(model.ndofs, np.nan)
        assert fused.kernels_for(pot.material, model.space).gradient(x, out=out) is out
        assert np.array_equal(out, threaded)  # the same kernel, the same bits
        numba.set_num_threads(1)
        assert np.array_equal(pot.gradient(x), serial)  # one thread: the serial kernel itself
    finally:
        numba.set_num_threads(before)
    assert np.max(np.abs(threaded - serial)) <= REORDER_RTOL * np.max(np.abs(serial))


def test_threaded_energy_and_volume_ratios_are_the_serial_bits(monkeypatch):
    numba = pytest.importorskip("numba")
    model = _model(cells=(30, 3, 3))  # 1,620 tets: two 1024-element blocks, the second partial
    kern = fused.kernels_for(model.body_potential.material, model.space)
    x = _bent(model, seed=4)
    p = x.reshape(-1, 3)
    tets = np.ascontiguousarray(model.space.mesh.t, dtype=np.int64)
    ref = np.ones(tets.shape[1])
    monkeypatch.setenv(fused.THREADS_ENV, "0")
    e_serial, r_serial = kern.energy(x), fused.tet_volume_ratios(p, tets, ref)
    monkeypatch.setenv(fused.THREADS_ENV, "1")
    monkeypatch.setattr(fused, "MIN_THREADED_ELEMENTS", 0)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        e_threaded, r_threaded = kern.energy(x), fused.tet_volume_ratios(p, tets, ref)
        inverted = x.copy()
        inverted[2::3] *= -1.0  # mirror the body: every tet inverted, psi = +inf
        assert kern.energy(inverted) == np.inf
    finally:
        numba.set_num_threads(before)
    assert e_threaded == e_serial  # the blocks are summed as the serial loop sums them
    assert np.array_equal(r_threaded, r_serial)


def _reference_symplectic(model, state, h, steps):
    """Symplectic Euler as the integrator computed it before the fast path: a new force each
    step, divided by the lumped mass, held DOFs from ``free_at``."""
    x, v, t = state.x.copy(), state.v.copy(), state.t
    for _ in range(steps):
        f = -model.gradient(x)
        f /= model.lumped_mass
        f[~model.free_at(t)] = 0.0
        v = v + h * f
        x = x + h * v
        t += h
        dofs, xc, vc = model.constraints(t)
        x[dofs], v[dofs] = xc, vc
    return x, v


@pytest.mark.parametrize("gravity", [None, (0.0, 0.0, -9.81)])
def test_symplectic_run_unchanged_to_roundoff(monkeypatch, gravity):
    monkeypatch.setattr(fused, "MIN_THREADED_ELEMENTS", 0)  # the threaded kernel where numba
    # has threads: the run then differs from the reference by its reordering too
    model = _model(gravity=gravity)
    s0 = fe.State(_bent(model, seed=2), np.zeros(model.ndofs), 0.0)
    h = 0.5 * fe.critical_time_step(model, fe.SymplecticEuler())
    xr, vr = _reference_symplectic(model, s0, h, 40)
    integ, s = fe.SymplecticEuler(), s0
    states = []
    for _ in range(40):
        s = integ.step(model, s, h)
        states.append(s)
    # the step writes x1, v1 into the integrator's buffers: each State must own its copies
    w = integ._workspace
    assert not any(np.shares_memory(a, b) for a in (states[-2].x, states[-2].v, states[-1].x)
                   for b in (w.x_next, w.v_next, w.buffer, states[-1].v))
    assert not np.shares_memory(states[-2].x, states[-1].x)
    import pickle  # the buffers stay behind; a copy steps on as the original does

    copy = pickle.loads(pickle.dumps(integ))
    assert copy._workspace is None
    assert np.array_equal(copy.step(model, s, h).x, integ.step(model, s, h).x)
    # f * (1/m) and f / m differ by <= 1 ulp per step; a stable step (h at half the limit)
    # amplifies nothing, so 40 steps stay within ~1e3 eps of the motion's scale
    scale_x = np.max(np.abs(s0.x - model.X))
    assert np.max(np.abs(s.x - xr)) <= 1e-12 * scale_x
    assert np.max(np.abs(s.v - vr)) <= 1e-12 * (np.max(np.abs(vr)) + scale_x / h)
    assert s.t == pytest.approx(40 * h, rel=1e-14)


def test_explicit_step_allocations_do_not_grow():
    model = _model(cells=(10, 2, 2))
    integ = fe.SymplecticEuler()
    h = 0.5 * fe.critical_time_step(model, integ)
    s = fe.State(_bent(model, seed=3), np.zeros(model.ndofs), 0.0)
    for _ in range(3):  # build the caches (workspace, fused geometry) before measuring
        s = integ.step(model, s, h)
    vec = 8 * model.ndofs  # bytes of one DOF vector
    tracemalloc.start()
    try:
        for _ in range(3):  # the state alive now was allocated before tracing: replace it first
            s = integ.step(model, s, h)
        peaks = [0] * 50
        # a full collection empties CPython's free lists (tuples, floats): blocks parked there
        # count as traced, and their number at the end depended on where the steps left them
        # (up to ~50 spare 2-tuples, 2.8 kB, the test's failures), not on anything the step keeps
        gc.collect()
        base = tracemalloc.get_traced_memory()[0]
        for k in range(50):
            tracemalloc.reset_peak()
            before = tracemalloc.get_traced_memory()[0]
            s = integ.step(model, s, h)
            peaks[k] = tracemalloc.get_traced_memory()[1] - before
        gc.collect()
        grown = tracemalloc.get_traced_memory()[0] - base
    finally:
        tracemalloc.stop()
    # the new State's x and v replace the previous ones: nothing accumulates over 50 steps
    # (4 kB of slack for Python's own small-object arenas; measured 1376 B, a leak of one
    # vector a step would be 50 x 2376 B)
    assert grown <= 4096, grown
    # within a step, only the new State's x and v: the fused update writes them in arrays the
    # State adopts (the numpy path: the State's copies of x1, v1 from the cached buffers); the
    # force lives in the integrator's cached buffer; 2 vectors plus 4 kB for the small objects
    # (StepStats, the State, index scalars)
    assert max(peaks) <= 2 * vec + 4096, (max(peaks), vec)


def test_bench_explicit_quick_prints_its_figures():
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "scripts" / "bench_explicit.py"
    cmd = [sys.executable, str(script), "--cells", "6", "2", "2", "--repeats", "1", "--threads", "1"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=True).stdout
    assert "step after (fe.SymplecticEuler)" in out and "1 thread(s): before" in out
    dv = float(out.rsplit("max relative difference of v1:", 1)[1].split()[0].rstrip(";"))
    assert dv <= 1e-12  # the two paths agree to round-off (see REORDER_RTOL)
    assert "old and new serial kernels give the same bits: True" in out
