"""The fused symplectic Euler update (issue 19.5): the same bits as the numpy path, no copies,
and a blow-up still caught (the finiteness the update measured replaces the next step's scan)."""

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.discretization import fused
from fem_elastic.dynamics.integrators import explicit

pytestmark = pytest.mark.skipif(not fused.available(), reason="numba is not importable")


def _model(**kw):
    return fe.Model(fe.beam_mesh(cells=(6, 2, 2)), density=1000.0,
                    body=fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.4)), fixed="left", **kw)


def _bent(model):
    X = model.X.reshape(-1, 3)
    u = np.zeros_like(X)
    u[:, 2] = 0.02 * X[:, 0] ** 2  # a bend that is zero at the clamped end
    return fe.State.rest(model, displacement=u)


def _run(model, integrator, state, dt, n, fused_update):
    """n steps, with the fused update or with the numpy path it replaces (monkeypatched off)."""
    saved = explicit._update_kernel
    if not fused_update:
        explicit._update_kernel = lambda: None
    try:
        for _ in range(n):
            state = integrator.step(model, state, dt)
    finally:
        explicit._update_kernel = saved
    return state


@pytest.mark.parametrize("damping", [None, fe.Rayleigh(alpha=0.5, beta=0.0)])
@pytest.mark.parametrize("substep", [False, True])
def test_same_bits_as_numpy_update(damping, substep):
    kw = {} if damping is None else {"damping": damping}
    model = _model(**kw)
    s0 = _bent(model)
    dt = 0.5 * fe.critical_time_step(model, fe.SymplecticEuler())
    if substep:
        dt *= 6.0  # several sub-steps a step
    a = _run(model, fe.SymplecticEuler(substep=substep), s0, dt, 20, True)
    b = _run(model, fe.SymplecticEuler(substep=substep), s0, dt, 20, False)
    assert not np.array_equal(a.x, s0.x)  # it moved
    # bit for bit: the same operations in the same order (no FMA contraction in numba)
    assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)
    assert a.t == b.t
    assert not a.x.flags.writeable and not a.v.flags.writeable
    # the State's own arrays, not a shared buffer: views of read-only buffers nothing else holds
    assert a.x.base.flags.owndata and a.v.base.flags.owndata and not a.x.base.flags.writeable
    held = model.constraints(a.t)[0]
    assert np.array_equal(a.x[held], model.X[held]) and not a.v[held].any()


def test_states_kept_by_the_caller_are_not_overwritten():
    """No buffer is reused across returned States: an earlier State keeps its values."""
    model = _model()
    integrator = fe.SymplecticEuler()
    dt = 0.5 * fe.critical_time_step(model, integrator)
    s1 = integrator.step(model, _bent(model), dt)
    x1 = s1.x.copy()
    s2 = integrator.step(model, s1, dt)
    integrator.step(model, s2, dt)
    assert np.array_equal(s1.x, x1)
    assert s2.x is not s1.x and not np.shares_memory(s1.x, s2.x)


def test_a_state_checked_finite_cannot_be_made_writable():
    """The next step skips the finiteness scan of a State it produced: nobody may write into it."""
    model = _model()
    integrator = fe.SymplecticEuler()
    s1 = integrator.step(model, _bent(model), 0.5 * fe.critical_time_step(model, integrator))
    for a in (s1.x, s1.v):
        with pytest.raises(ValueError, match="WRITEABLE"):
            a.setflags(write=True)


def test_blow_up_without_substeps_is_caught_at_the_next_step():
    """Far above the critical step the positions overflow; the update's finiteness test marks
    the non-finite State as unchecked, so the next step scans it and refuses it, as before."""
    model = _model()
    integrator = fe.SymplecticEuler()
    dt = 3.0 * fe.critical_time_step(model, integrator)  # unstable: |eigenvalue| > 1 per step
    s = _bent(model)
    with np.errstate(all="ignore"):
        for k in range(5000):
            nxt = integrator.step(model, s, dt)
            if not (np.isfinite(nxt.x).all() and np.isfinite(nxt.v).all()):
                break
            assert integrator._workspace.finite_state is nxt  # vouched for: the next step skips the scan
            s = nxt
        else:
            pytest.fail("the unstable run never overflowed")
        assert integrator._workspace.finite_state is None
        with pytest.raises(fe.InvalidParameter, match="NaN or infinite"):
            integrator.step(model, nxt, dt)


def test_blow_up_in_simulate_stops_with_step_reason_and_last_good_state():
    model = _model()
    integrator = fe.SymplecticEuler()
    dt = 3.0 * fe.critical_time_step(model, integrator)
    with (np.errstate(all="ignore"), pytest.warns(fe.StabilityWarning, match="critical time step"),
          pytest.raises(fe.Diverged) as info):
        fe.simulate(model, integrator, dt, steps=5000, state=_bent(model), record_every=1000)
    err = info.value
    assert err.step is not None and 0 <= err.step < 5000
    assert err.reason
    good = err.last_good_state
    assert isinstance(good, fe.State)
    assert np.isfinite(good.x).all() and np.isfinite(good.v).all()
    # the last good state is the one the failed step started from: step k ends at (k + 1) dt
    # simulate stamps step k's end as t0 + (k + 1) dt with t0 = 0: the same product, bit for bit
    assert good.t == err.step * dt
