"""The Potential protocol: every physical term is an energy of the DOF positions.

A Potential ``E(x)`` of the flat position vector ``x`` (m, scikit-fem's
node-major interleaved DOF order) provides

    energy(x)   -> float                     (J); +inf where x is inadmissible
    gradient(x) -> (ndofs,)                  (N); the force on the DOFs is -gradient
    hessian(x, project=False) -> (ndofs, ndofs) sparse, or None where it is zero (N/m)

``project=True`` asks for a positive semi-definite approximation of the
Hessian (per-element eigenvalue clamping), which Newton's method uses to
guarantee a descent direction. Solvers and integrators see only this
protocol, never the concrete terms.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["Potential", "LinearPotential"]


class Potential:
    """Base class of every energy term."""

    #: The energy is (at most) quadratic in x: its Hessian is the same matrix at every x
    #: (Newton may keep it, see ``newton_minimize(hessian_constant=...)``).
    quadratic: bool = False

    def energy(self, x: np.ndarray) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    def gradient(self, x: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def hessian(self, x: np.ndarray, project: bool = False) -> sp.spmatrix | None:  # pragma: no cover
        raise NotImplementedError

    def linearize(self, x: np.ndarray,
                  project: bool = False) -> tuple[np.ndarray, sp.spmatrix | None]:
        """Gradient and Hessian at once (terms that share work override this)."""
        return self.gradient(x), self.hessian(x, project=project)


class LinearPotential(Potential):
    """A dead load: E(x) = -f . (x - X), with a constant force vector f (N).

    Parameters
    ----------
    force : numpy.ndarray
        ``(ndofs,)`` nodal forces (N).
    X : numpy.ndarray
        ``(ndofs,)`` reference positions (m); the energy is zero there.
    """

    quadratic = True  # linear in x

    def __init__(self, force: np.ndarray, X: np.ndarray) -> None:
        self.force = np.asarray(force, dtype=float)
        self.X = X

    def energy(self, x: np.ndarray) -> float:
        return -float(self.force @ (x - self.X))

    def gradient(self, x: np.ndarray) -> np.ndarray:
        return -self.force

    def hessian(self, x: np.ndarray, project: bool = False) -> None:
        return None
