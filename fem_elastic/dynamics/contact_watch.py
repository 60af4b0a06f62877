"""Contact diagnostics per step: minimum distance, active contacts, contact force, intersections.

:class:`ContactWatch` is the observer :func:`fem_elastic.simulate` adds by itself for a model
whose ``contact=`` term reports ``diagnostics(x)`` (IPC, impulses). After every accepted step it
stores in ``run.stats`` (``Trajectory.step_stats``)

- ``contact_min_distance`` (m): the smallest distance between surface primitives the contact
  reports (``inf`` when none is within its range, e.g. IPC's ``dhat``),
- ``contact_active``: the number of active contact pairs,
- ``contact_force`` (N): the total contact force magnitude (an impulse contact's summed
  impulse over the step divided by ``dt``: its average force over the step),

and at the end of the run it asks the contact whether the surface intersects itself
(``has_intersections``, ipctk's exact test). A run that ends intersecting is never silent: a
:class:`ContactIntersectionWarning` is issued and ``contact_intersecting`` is 1 at the last step
(``Trajectory.summary()["contact_intersecting_at_end"]``).
"""

from __future__ import annotations

import logging
import math
import warnings

import numpy as np

from .observers import Observer

__all__ = ["CONTACT_FIELDS", "ContactIntersectionWarning", "ContactWatch", "has_contact_diagnostics"]

log = logging.getLogger(__name__)

#: the per-step statistics a contact adds to ``Trajectory.step_stats``
CONTACT_FIELDS = ("contact_min_distance", "contact_active", "contact_force", "contact_intersecting")


class ContactIntersectionWarning(UserWarning):
    """A run ended with intersecting surfaces (the contact failed to keep them apart)."""


def has_contact_diagnostics(model) -> bool:
    """Whether ``model.contact`` reports ``diagnostics(x)``."""
    return callable(getattr(getattr(model, "contact", None), "diagnostics", None))


def contact_stats(n_steps: int) -> dict:
    """Empty per-step arrays of :data:`CONTACT_FIELDS` (NaN: not measured)."""
    return {k: np.full(n_steps, np.nan) for k in CONTACT_FIELDS}


class ContactWatch(Observer):
    """Records the contact's diagnostics after every step and checks the end for intersections."""

    def on_start(self, run) -> None:
        # run.stats holds the CONTACT_FIELDS already: Run makes them (contact_stats) for a model
        # with contact diagnostics, before a resumed run refills them from its checkpoint
        reset = getattr(run.model.contact, "reset_impulse", None)
        if callable(reset):  # impulses of responses before the run are not the first step's
            reset()

    def on_step(self, run, event) -> None:
        d = run.model.contact.diagnostics(event.after.x)
        k = event.k
        run.stats["contact_min_distance"][k] = float(d.get("min_distance", math.nan))
        run.stats["contact_active"][k] = float(d.get("active_contacts", 0))
        force = float(d.get("contact_force", 0.0))
        if math.isnan(force) and "contact_impulse" in d:
            # an impulse contact acts in no time: ``contact_impulse`` sums its responses since the
            # last read (every sub-step of this step), so J / h is its average force over the step
            force = float(d["contact_impulse"]) / run.dt
        run.stats["contact_force"][k] = force

    def on_finish(self, run) -> None:
        self._check_end(run)

    def on_interrupt(self, run) -> None:
        self._check_end(run)

    @staticmethod
    def _check_end(run) -> None:
        test = getattr(run.model.contact, "has_intersections", None)
        if test is None or run.steps_done == 0:
            return
        k = run.steps_done - 1
        bad = bool(test(run.state.x))
        run.stats["contact_intersecting"][k] = float(bad)
        if bad:
            msg = (f"the run ends with intersecting surfaces at t = {run.state.t:.6g} s (step {k + 1}): "
                   "the contact did not keep the bodies apart; use a smaller dt or a larger dhat")
            log.warning(msg)
            warnings.warn(msg, ContactIntersectionWarning, stacklevel=2)


def summarize(step_stats: dict) -> dict:
    """The contact figures of a run for its summary (plain Python values; {} without contact)."""
    if "contact_active" not in step_stats:
        return {}
    d = np.asarray(step_stats["contact_min_distance"], dtype=float)
    d = d[np.isfinite(d)]
    active = np.asarray(step_stats["contact_active"], dtype=float)
    force = np.asarray(step_stats["contact_force"], dtype=float)
    inter = np.asarray(step_stats["contact_intersecting"], dtype=float)
    return {
        "contact_min_distance": float(d.min()) if d.size else None,
        "contact_active_max": int(np.nanmax(active)) if np.isfinite(active).any() else 0,
        "contact_force_max": float(np.nanmax(force)) if np.isfinite(force).any() else None,
        "contact_steps_in_contact": int(np.count_nonzero(active > 0)),
        "contact_intersecting_at_end": bool(np.nansum(inter) > 0),
    }
