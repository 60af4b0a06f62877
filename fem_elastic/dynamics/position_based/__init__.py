"""Position-based dynamics: PBD and XPBD, integrators whose elasticity is constraints on the mesh.

- :class:`PBD` (Mueller et al. 2007; the lecture notes' "Position Based
  Dynamics", ``seeds/002_942bade499ba35f4.txt``): edge-distance and tet-volume
  constraints with a stiffness k in [0, 1] whose effect depends on the
  iteration count and the time step;
- :class:`XPBD` (Macklin, Mueller and Chentanez 2016): constraints with a
  compliance from the body's material (E, nu), the stable Neo-Hookean
  constraints of Macklin and Mueller (2021) by default, whose steps approach
  those of implicit Euler on :class:`ConstraintNeoHookean` as the iterations grow.

Both are integrators, ``step(model, state, dt) -> State``, for
:func:`fe.simulate`, the scene files (``integrator = "pbd"``, ``"xpbd"``) and
checkpoints. The shared loop (prediction, constraint sweeps, contact, velocity
update and correction) is :mod:`.base`; the constraints and their vectorised
projection :mod:`.constraints` (numba sweeps in :mod:`._kernels`, numpy
fallback); the graph colouring that lets a Gauss-Seidel sweep vectorise
:mod:`.coloring`. The layer is dynamics: it imports solvers, physics,
discretization, geometry and materials, never study or app.
"""

from .base import METHODS, PositionBased
from .coloring import color_constraints, coloring_is_valid
from .constraints import ConstraintSet, EdgeDistance, TetNeoHookean, TetVolume
from .energy import ConstraintNeoHookean
from .pbd import PBD
from .xpbd import CONSTRAINTS, XPBD

__all__ = [
    "CONSTRAINTS", "METHODS", "PBD", "XPBD", "ConstraintNeoHookean", "ConstraintSet", "EdgeDistance",
    "PositionBased", "TetNeoHookean", "TetVolume", "color_constraints", "coloring_is_valid",
]
