"""The blow-up watch stays on while driven boundaries move, and never calls a converged state diverged.

The energy bound counts the work the drives do (``fem_elastic.dynamics.observers``:
``E <= E_0 + W + growth * max(S, |W|_1)``), in the loop, so every integrator,
new ones included, gets it; and Newton's tolerance is relative to the force
the held DOFs carry, so a body held crushed converges instead of stalling at
an absolute residual.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import fem_elastic as fe

CUBE = dict(length=0.1, width=0.1, height=0.1, cells=(2, 2, 2))


def test_a_neo_hookean_crush_held_still_runs_to_the_end():
    # crushed to 5 % of its height in 0.1 s, then held still for 0.9 s (90 steps): each held step
    # starts at the converged state, with ||g|| ~ 1e-9 N of round-off against element forces of
    # ~1e4 N; an absolute tolerance stopped it at step 14 ("Newton did not converge")
    model = fe.Model(fe.beam_mesh(**CUBE), density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3)),
                     fixed="bottom", driven={"top": fe.Translate((0.0, 0.0, -0.095), duration=0.1)})
    run = fe.simulate(model, fe.ImplicitEuler(), 0.01, t_end=1.0, record_every=10)
    assert run.steps == 100 and run.times[-1] == pytest.approx(1.0)
    assert run.summary()["min_det_F"] > 0  # Neo-Hookean under implicit Euler never inverts
    # held still, the stored energy stays what the crush put in (implicit Euler only dissipates)
    assert run.total[-1] <= run.total[1] * (1 + 1e-9) and run.total[-1] > 0


def _stretched_beam(duration=1.0):
    """A beam stretched by 2 % of its length, slowly (Prescribed: a drive that never stops moving)."""
    def pull(X, t):
        return np.outer(np.ones(len(X)), (0.02 * min(t / duration, 1.0), 0.0, 0.0))

    return fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
                    body=fe.ElasticBody(fe.StVK(E=1e5, nu=0.3)), fixed="left",
                    driven={"right": fe.Prescribed(pull, velocity=lambda X, t: np.outer(
                        np.ones(len(X)), (0.02 / duration if t < duration else 0.0, 0.0, 0.0)))})


def test_the_work_of_a_slow_drive_is_the_energy_it_stores(tmp_path):
    model = _stretched_beam()
    run = fe.simulate(model, fe.ImplicitEuler(), 0.01, t_end=1.0, checkpoint_dir=tmp_path)
    ck = fe.load_checkpoint(tmp_path)  # the watch's bookkeeping at the end of the run
    stored = run.total[-1] - run.total[0]
    # quasi-static: the work equals the elastic energy stored, up to the kinetic energy implicit
    # Euler dissipated (~(L / T)^2 / c^2 of it, c the wave speed) and the trapezoid rule's
    # O(dt^2) error on a quadratic energy path; 1 % covers both
    assert stored > 0 and ck.work == pytest.approx(stored, rel=1e-2)
    assert ck.work >= stored  # E_end - E_0 = W - (what damping and the scheme dissipate)
    assert ck.work_abs >= ck.work


def test_a_blow_up_while_driving_is_caught_by_the_energy_bound():
    # symplectic Euler at 3 x its stable step: the energy grows by orders of magnitude per step
    # while the drive moves; skipping the bound while driving let it run to NaN
    model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.LinearElastic(E=1e5, nu=0.3)), fixed="left",
                     driven={"right": fe.Twist(math.pi, duration=10.0)})
    dt = 3.0 * fe.critical_time_step(model, fe.SymplecticEuler())
    with pytest.raises(fe.Diverged) as info:
        fe.simulate(model, fe.SymplecticEuler(), dt, steps=2000, check_stability=False)
    err = info.value
    assert "the total energy grew" in err.reason and "driven boundaries did" in err.reason
    assert err.time < 10.0  # while the drive was still turning


class _Pumping(fe.ImplicitEuler):
    """A scheme no part of the library knows, which feeds energy in: 1.5 x the velocity per step."""

    def step(self, model, state, dt):
        out = super().step(model, state, dt)
        free = model.free_at(out.t)
        v = out.v.copy()
        v[free] *= 1.5
        return fe.State(out.x, v, out.t)


def test_every_integrator_gets_the_watch_while_driving():
    model = _stretched_beam(duration=10.0)
    with pytest.raises(fe.Diverged, match="driven boundaries did"):
        fe.simulate(model, _Pumping(), 0.01, steps=100)
    # the honest scheme on the same drive runs through
    run = fe.simulate(model, fe.ImplicitEuler(), 0.01, steps=100, record_every=50)
    assert run.steps == 100


@pytest.mark.parametrize("integrator, dt, t_end", [(fe.ImplicitEuler(), 5e-3, 0.1),
                                                   (fe.SymplecticEuler(), 2e-5, 0.02), (fe.RK4(), 5e-5, 0.02)])
def test_a_fast_twist_is_not_called_diverged(integrator, dt, t_end):
    # two turns in 0.2 s, the drive's work far above every initial energy of the scene
    model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.StableNeoHookean(E=1e6, nu=0.3)), fixed="left",
                     driven={"right": fe.Twist(4 * math.pi, duration=0.2)})
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", fe.InversionWarning)
            run = fe.simulate(model, integrator, dt, t_end=t_end, record_every=100)
    assert np.isfinite(run.total).all() and run.times[-1] == pytest.approx(t_end)
    # the drive fed in energy far above the bound's scale without it (1e3 x the round-off at rest)
    assert run.total[-1] > 1e6 * model.energy_roundoff()
