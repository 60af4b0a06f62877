"""Position-based dynamics (Mueller et al. 2007): distance and volume constraints with a stiffness k.

The lecture notes' loop (``seeds/002_942bade499ba35f4.txt``, "Position Based
Integration"; the shared loop is :mod:`~fem_elastic.dynamics.position_based.base`)
with the mesh's constraints: ``|x_b - x_a| - l0`` on every edge and
``V / V0 - 1`` on every tet (:mod:`~fem_elastic.dynamics.position_based.constraints`).
Each projection moves the vertices by ``k'`` times the full correction
``dx_i = -s w_i grad_i C`` (the notes' "Stiffness: scale corrections by
k in [0..1]").

Stiffness and its drift
-----------------------
``k`` is not a material constant. Following Mueller et al. (2007, section 3.3),
the factor applied at every iteration is ``k' = 1 - (1 - k)^(1/n)`` for ``n``
iterations (``stiffness_per_iteration=False``, the default): after n
projections an isolated constraint keeps the fraction ``(1 - k')^n = 1 - k``
of its error, whatever n. With ``stiffness_per_iteration=True`` each
projection is scaled by k itself, and the error left is ``(1 - k)^n``: the
body stiffens with the iteration count. Either way the effect of k depends on
the time step (the notes: "easy to tune but effect dependent on time step!"):
in a body held against gravity, each step adds ``h^2 g`` to the prediction
and the projections remove the fraction ``k`` of what is there, so the sag
settles where ``(1 - k)(sag + h^2 g) = sag``: ``sag = (1 - k) h^2 g / k`` for
one constraint, an effective stiffness ``k m / ((1 - k) h^2)`` that grows as
``1 / h^2``. On a mesh the constraints are coupled and a finite number of
Gauss-Seidel sweeps does not converge, so the iteration count enters as well.
``tests/test_pbd.py`` measures both drifts. :class:`fe.XPBD` removes them.

The energies :func:`fe.simulate` records are the model's, its material's FEM
energy, which PBD does not minimise: a PBD body far softer than its material
sags far below the material's equilibrium, gains "elastic energy" in that
measure, and the blow-up watch may stop it as an energy growth; pass
``energy_growth=float("inf")`` to ``fe.simulate`` for such a study, or give
the model a material of about PBD's stiffness.

Examples
--------
>>> import fem_elastic as fe
>>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
...                  body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
...                  fixed="left", gravity=(0, 0, -9.81))
>>> pbd = fe.PBD(stiffness=0.5, iterations=10)
>>> s = pbd.step(model, fe.State.rest(model), 0.01)
>>> s.t, pbd.last_stats.linear_iterations, bool(s.x[2::3].min() < model.X[2::3].min())
(0.01, 10, True)
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from ...errors import InvalidParameter
from .base import PositionBased, _number
from .constraints import EdgeDistance, TetVolume

__all__ = ["PBD"]


class PBD(PositionBased):
    """Position-based dynamics with edge-distance and tet-volume constraints.

    Parameters
    ----------
    stiffness : float
        k of the distance constraints, in [0, 1] (0 drops them).
    iterations : int
        Constraint sweeps per step, >= 1.
    volume_stiffness : float
        k of the volume constraints, in [0, 1] (0 drops them).
    method : {"gauss_seidel", "jacobi"}
        Gauss-Seidel sweeps (graph-coloured) or Jacobi sweeps.
    damping : float
        Velocity damping per step in [0, 1] towards the rigid motion
        (Mueller et al. 2007, section 3.5).
    relaxation : float
        Jacobi only: over-relaxation of the averaged corrections, in (0, 2).
    stiffness_per_iteration : bool
        False (default): each projection is scaled by ``k' = 1 - (1 - k)^(1/n)``
        (Mueller et al. 2007), True: by k (see the module notes).
    substeps : int
        Steps of ``dt / substeps`` per step, each with ``iterations`` sweeps.

    Examples
    --------
    >>> fe_pbd = PBD(stiffness=0.9, iterations=4)
    >>> round(fe_pbd.per_iteration(0.9), 6)   # 1 - 0.1 ** (1/4)
    0.437659
    """

    _who = "fe.PBD"

    def __init__(self, stiffness: float = 1.0, iterations: int = 10, volume_stiffness: float = 1.0,
                 method: Literal["gauss_seidel", "jacobi"] = "gauss_seidel", damping: float = 0.0,
                 relaxation: float = 1.0, stiffness_per_iteration: bool = False,
                 substeps: int = 1) -> None:
        super().__init__(iterations, method, damping, relaxation, substeps)
        self.stiffness = _number(stiffness, "stiffness", 0.0, 1.0, example=" (e.g. stiffness=0.5)")
        self.volume_stiffness = _number(volume_stiffness, "volume_stiffness", 0.0, 1.0)
        if not isinstance(stiffness_per_iteration, (bool, np.bool_)):
            raise InvalidParameter(
                f"stiffness_per_iteration must be True or False, got {stiffness_per_iteration!r}."
            )
        self.stiffness_per_iteration = bool(stiffness_per_iteration)

    def __repr__(self) -> str:
        return (f"fe.PBD(stiffness={self.stiffness:g}, iterations={self.iterations}, "
                f"volume_stiffness={self.volume_stiffness:g}, method={self.method!r}, "
                f"damping={self.damping:g}, relaxation={self.relaxation:g}, "
                f"stiffness_per_iteration={self.stiffness_per_iteration}, substeps={self.substeps})")

    def per_iteration(self, k: float) -> float:
        """The factor on each projection for a stiffness k (see the module notes)."""
        if self.stiffness_per_iteration or k >= 1.0:
            return float(k)
        return 1.0 - (1.0 - float(k)) ** (1.0 / self.iterations)

    def _constraint_sets(self, model):
        sets = []
        if self.stiffness > 0.0:
            sets.append(EdgeDistance.of_mesh(model.mesh))
        if self.volume_stiffness > 0.0:
            sets.append(TetVolume(model.mesh))
        return sets

    def _coefficients(self, sets, h):
        out = []
        for s in sets:
            k = self.stiffness if isinstance(s, EdgeDistance) else self.volume_stiffness
            out.append((np.zeros((len(s), s.m)), np.full(len(s), self.per_iteration(k))))
        return out
