"""The shipped contact scenes keep every step intersection-free (issue 17's verification).

The two-body drop runs in full (60 implicit Euler steps of 0.01 s); after every accepted
step ipctk's exact intersection test must find no crossing triangles, and the ball must end
on the block: it came down onto it, and did not pass into it.
"""

from functools import lru_cache
from pathlib import Path

import pytest

import fem_elastic as fe
from fem_elastic.app.scene import load_scene

pytest.importorskip("ipctk", reason="IPC contact needs the [contact] extra (ipctk)")

ROOT = Path(__file__).resolve().parent.parent


@lru_cache(maxsize=None)  # the scene's own two-body drop serves two tests: run it once
def _run_checking_every_step(scene: str, kappa: str | None = None
                             ) -> tuple[fe.Model | fe.MultiBody, fe.Trajectory, list[int]]:
    """Run ``scenes/<scene>`` in full, asserting no intersection after every accepted step.

    ``kappa``: replaces the scene's ``[contact] kappa`` (None: the scene's own). Returns the
    model, the trajectory and the number of active contact pairs after each step.
    """
    scene_ = load_scene(ROOT / "scenes" / scene)
    if kappa is not None:
        scene_.spec["contact"]["kappa"] = kappa
    run = scene_.build()[0]
    model = run.model
    active = []

    def no_intersection(step: int, state: fe.State) -> None:
        assert not model.contact.has_intersections(state.x), f"intersecting at t = {state.t:.3f} s"
        active.append(model.contact.diagnostics(state.x)["active_contacts"])

    traj = fe.simulate(model, run.integrator, run.dt, steps=run.steps, state=run.state,
                       callback=no_intersection)
    assert len(active) == run.steps  # the check ran after every step
    return model, traj, active


def test_two_body_drop_never_intersects_and_the_ball_ends_on_the_block():
    model, traj, active = _run_checking_every_step("two_bodies.toml")
    assert max(active) > 0  # the ball did come within dhat of the block: contact was tested
    assert traj.summary()["contact_intersecting_at_end"] is False
    ball = model.body_slice("ball")  # the ball's DOFs (P1: 3 per vertex, first body)
    z = traj.final_state.x[ball][2::3]
    # the block's top face is at z = 0.102 m (0.1 m tall, lifted 2 mm onto the ground's
    # barrier); the ball started at z >= 0.25 m: it must now touch the block from above,
    # its lowest vertex within the barrier's reach (dhat = 1 mm) plus the block's own sag
    assert 0.102 - 1e-3 < z.min() < 0.102 + 5e-3


def test_self_contact_fold_never_intersects():
    """The beam folded onto itself: the driven end meets the clamped part, every step clean."""
    _, _, active = _run_checking_every_step("self_contact.toml")
    assert max(active) > 0  # the fold did bring the surfaces within dhat: contact was tested


def test_the_scenes_kappa_sets_the_gap_the_ball_rests_at():
    """docs/guide/contact.md, "Choosing kappa": the barrier stiffness sets the resting gap. The
    scene's kappa (1e7 N/m^3) against IPC's adaptive one on the same drop: both stay
    intersection-free at every step, and the ball ends resting on the block at gaps in the ratio
    of the two stiffnesses."""
    gaps, kappas = {}, {}
    for kappa in ("scene", "auto"):
        model, traj, _ = _run_checking_every_step("two_bodies.toml",
                                                  None if kappa == "scene" else kappa)
        d = model.contact.diagnostics(traj.final_state.x)
        assert d["active_contacts"] > 0  # the ball rests on the block at the end
        gaps[kappa], kappas[kappa] = d["min_distance"], d["kappa"]
    assert kappas["scene"] == 1e7 and kappas["auto"] < kappas["scene"]
    # for d << dhat a pair pushes with 2 kappa dhat^4 / d (ipctk's barrier on squared distances;
    # the next term is under 5 % at the 6 % of dhat met here; test_ipc_contact pins both), so a
    # pair under one load rests at a gap in proportion to kappa. The ball is no rigid load: as
    # it rests higher its own deformation shares the weight differently among its 51 pairs, and
    # the gap grows a little faster than kappa (2.30x per doubling around 1e7, 2.46 against
    # 2.25 here). 25 % bounds that; a gap as sqrt(kappa) (1.5) or none (1) fails
    assert gaps["scene"] / gaps["auto"] == pytest.approx(kappas["scene"] / kappas["auto"], rel=0.25), \
        (gaps, kappas)
