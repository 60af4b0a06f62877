"""Velocity Verlet (Stoermer-Verlet, kick-drift-kick) with the lumped mass.

With ``a(x, v) = M^-1 (-dPi/dx(x) - C v)`` on the free DOFs (0 on held ones):

    v_half = v0 + h/2 a(x0, v0)               (kick)
    x1     = x0 + h v_half                     (drift; held DOFs at their prescription)
    v1     = v_half + h/2 a(x1, v~)            (kick)

Undamped, ``v~`` does not matter and this is the Stoermer-Verlet method:
explicit, symplectic, time-reversible, second order; it conserves linear and
angular momentum exactly (in exact arithmetic) and, below its critical time
step ``h omega_max <= 2`` (that of symplectic Euler), keeps the energy
bounded: on a linear body it conserves the modified energy

    KE + Pi - (h^2/8) g . M^-1 g,      g = dPi/dx on the free DOFs,

exactly, so ``KE + Pi`` only oscillates, by up to ``1 / (1 - r^2)`` times a
mode's energy, ``r = h omega / 2``.

One force evaluation per step: the force at x1 serves the second kick and,
remembered, the first kick of the next step, unless an impulse contact moved
the positions at the end of the step (then the next step evaluates it
again: two a step while a body rests on an impulse obstacle). It is saved in
checkpoints like symplectic Euler's cached gradient, so a resumed run
repeats the uninterrupted one bit for bit, its force counts included.

Damping (Rayleigh, a body's dashpots) takes the velocity ``v~ = 2 v_half -
v0 = v0 + h a(x0, v0)`` in the second kick: it is ``v1 + O(h^2)``, which keeps
the scheme second order with damping (``v~ = v_half`` would make it first
order), at the cost of a second evaluation of the damping force per step (no
extra elastic force). On a damped mode the stability limit and the step map
are those of :meth:`VelocityVerlet.step_matrix`; a purely viscous mode is
stable for ``h c <= 2``. Contacts: penalty forces are part of ``dPi/dx``;
impulse responses are applied at the end of the step, as in every explicit
scheme.

The adaptive sub-stepping of the explicit schemes (``substep=True``,
``safety``, ``recheck_every``, ``max_substeps``; see
:mod:`fem_elastic.dynamics.integrators.explicit`) judges a step by the
modified energy above, which costs nothing extra (the force at the end is
the one the scheme computed), and rejects one whose ``KE + Pi`` grows by
more than a stable mode's swing ``1 / (1 - r^2)`` allows, ``r = h / dt_crit``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .base import restored_gradient
from .explicit import _Explicit

if TYPE_CHECKING:  # for annotations only
    from ...physics.multibody import AnyModel
    from ..state import State

__all__ = ["VelocityVerlet"]


class VelocityVerlet(_Explicit):
    """Velocity Verlet (kick-drift-kick): explicit, symplectic, second order.

    Stable up to ``h = 2 / omega_max`` on an undamped body; one force
    evaluation per step. Parameters are those of the explicit schemes'
    sub-stepping (see :mod:`fem_elastic.dynamics.integrators.explicit`):
    ``substep``, ``safety``, ``recheck_every``, ``max_substeps``. The scheme,
    its damping and its energy: :mod:`fem_elastic.dynamics.integrators.verlet`.

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> [round(float(max(abs(np.linalg.eigvals(fe.VelocityVerlet().step_matrix(h, 1.0))))), 9)
    ...  for h in (1.9, 2.1)]  # below and above h = 2 / omega (symplectic Euler's eigenvalues)
    [1.0, 1.877328045]
    >>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left")
    >>> vv = fe.VelocityVerlet()
    >>> s = fe.State.rest(model, velocity=(0.0, 0.0, -0.1))
    >>> counts = []
    >>> for _ in range(3):
    ...     s = vv.step(model, s, 1e-4)
    ...     counts.append(vv.last_stats.gradient_evaluations)
    >>> counts  # the force at the end of a step starts the next one
    [2, 1, 1]
    """

    order = 2
    _modified_energy = True

    # -- what it remembers: the force at the end of the step ---------------------------------
    def step(self, model: AnyModel, state: State, dt: float) -> State:
        """Advance ``state`` by ``dt`` (s): one step, or ``n`` sub-steps with ``substep``."""
        if not self.substep and self._model is not model:  # (sub-stepping keeps its own watch)
            if self._model is not None:  # a force of another model: forget it
                self._gradient = (None, None)
            self._model = model
        return super().step(model, state, dt)

    def checkpoint_state(self, state: State) -> dict:
        """What the next step reuses, for a checkpoint at ``state``.

        Returns
        -------
        dict of str to numpy.ndarray
            ``gradient`` (N, dPi/dx at ``state.x``) when the step that ended
            there left it; with ``substep`` also the sub-stepping memory (see
            :meth:`fem_elastic.dynamics.integrators.explicit._Explicit.checkpoint_state`).
        """
        if self.substep:
            return super().checkpoint_state(state)
        at, g = self._gradient
        return {"gradient": g.copy()} if at is state.x else {}

    def restore_state(self, state: State, saved: dict) -> None:
        """Take back what :meth:`checkpoint_state` returned (an empty dict starts afresh)."""
        if self.substep:
            return super().restore_state(state, saved)
        g = restored_gradient(self.name, state, saved, self._forget,
                              "another integrator (or with substep=True)")
        if g is not None:
            self._gradient = (state.x, g)

    # -- the scheme --------------------------------------------------------------------------
    def _advance(self, model, state, h, t1, stats):
        x0, v0 = state.x, state.v
        a = self._acceleration(model, x0, v0, self._free(model, state.t), stats)  # the kept force, if any
        a *= 0.5 * h
        vh = a
        vh += v0  # v_half, in place of a temporary
        x1 = x0 + h * vh
        w = self._work(model)
        if w.free is None:  # a driven boundary: the held DOFs of t1, from the model
            dofs, xc, _ = model.constraints(t1)
            free1 = np.ones(model.ndofs, dtype=bool)
            free1[dofs] = False
        else:  # nothing driven: the cached ones (the same DOFs and values at every t)
            dofs, xc, free1 = w.held, w.x_held, w.free
        x1[dofs] = xc  # the force below is taken where the step ends
        g1 = model.gradient(x1)
        stats.gradient_evaluations += 1
        self._gradient = (x1, g1)
        a1 = self._acceleration(model, x1, 2.0 * vh - v0, free1, stats)  # v~ = 2 v_half - v0
        a1 *= 0.5 * h
        a1 += vh  # v1
        out = self._finish(model, x1, a1, t1)
        # the force at x1 starts the next step, unless an impulse contact moved the positions
        self._gradient = (out.x, g1) if np.array_equal(out.x, x1) else (None, None)
        return out

    def _attempt(self, model, state, h, n, stats, start, judge_energy):
        kept = self._gradient  # the force at the start; a rejected attempt leaves it valid
        out, why = super()._attempt(model, state, h, n, stats, start, judge_energy)
        if out is None:
            self._gradient = kept
        return out, why

    # -- its modified energy, for the sub-stepping judge -------------------------------------
    def _energy_term(self, model, state, g) -> float:
        """``g . M^-1 g`` (W/s) on the free DOFs at ``state``."""
        free = model.free_at(state.t)
        gf = g[free]
        return float(gf @ (gf / model.lumped_mass[free]))

    def _judged(self, energies, hs) -> float:
        ke, pe, gmg = energies
        return ke + pe if gmg is None else ke + pe - 0.125 * hs * hs * gmg

    def _swing(self, r) -> float:
        return 1.0 / (1.0 - r * r) if r < 1.0 else np.inf

    def step_matrix(self, h: float, omega: float, zeta: float = 0.0) -> np.ndarray:
        """One-step map of (q, v) on the modal oscillator; of one sub-step with ``substep``."""
        w2, c = omega * omega, 2.0 * zeta * omega
        vh = np.array([-0.5 * h * w2, 1.0 - 0.5 * h * c])  # rows: coefficients of (q, v)
        q1 = np.array([1.0, 0.0]) + h * vh
        vt = 2.0 * vh - np.array([0.0, 1.0])
        v1 = vh - 0.5 * h * (w2 * q1 + c * vt)
        return np.array([q1, v1])
