"""The incremental potential that implicit schemes minimise.

Implicit Euler and Newmark's average-acceleration rule both make the new
positions the minimiser of

    G(x) = 1/(2 k^2) ||x - y||_M^2 + Pi(x) + 1/(2 c) (x - z)^T C (x - z),

with an inertial target ``y``, a damping reference ``z`` and step factors
``k, c`` (s) set by the scheme: implicit Euler has ``k = c = h``,
``y = x_n + h v_n``, ``z = x_n``. ``dG/dx = 0`` is then the discrete
momentum balance of the scheme, and the same Newton solver (with line
search) as statics finds it. ``Pi`` is the model's total potential energy;
``M`` the lumped or consistent mass and ``C`` the model's damping matrix,
frozen at the step's start.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

__all__ = ["IncrementalPotential"]

_EPS = np.finfo(float).eps


class IncrementalPotential:
    """G(x) for one implicit step; see the module notes.

    Parameters
    ----------
    model : Model
    y : numpy.ndarray
        Inertial target (m).
    k : float
        Inertia step factor (s): the mass term is ``||x - y||_M^2 / (2 k^2)``.
    mass : {"lumped", "consistent"}
    x_start : numpy.ndarray
        Positions at the start of the step (m), where C is frozen.
    z : numpy.ndarray, optional
        Damping reference (m); default ``x_start``.
    c : float, optional
        Damping step factor (s); default ``k``.
    """

    def __init__(self, model, y, k, mass, x_start, z=None, c=None):
        self.model = model
        self.y = y
        self.k2 = k * k
        self.mass = mass
        self.C = model.damping_matrix(x_start, mass)
        self.z = x_start if z is None else z
        self.c = k if c is None else c

    def _M(self, d):
        if self.mass == "lumped":
            return self.model.lumped_mass * d
        return self.model.mass_matrix @ d

    def inertia_energy(self, x) -> float:
        d = x - self.y
        return 0.5 * float(np.einsum("i,i->", d, self._M(d))) / self.k2

    def energy(self, x) -> float:
        e = self.model.energy(x)
        if not math.isfinite(e):
            return math.inf
        e += self.inertia_energy(x)
        if self.C is not None:
            dz = x - self.z
            e += 0.5 * float(dz @ (self.C @ dz)) / self.c
        return e

    def gradient(self, x) -> np.ndarray:
        g = self.model.gradient(x)
        g += self._M(x - self.y) / self.k2
        if self.C is not None:
            g += (self.C @ (x - self.z)) / self.c
        return g

    def linearize(self, x, project=True, body=None):
        """Gradient (N) and Hessian (N/m) of G; ``body`` may replace the model's (g, H)."""
        g, H = self.model.linearize(x, project=project) if body is None else body
        g = g + self._M(x - self.y) / self.k2
        H = self._add_mass(H)
        if self.C is not None:
            g += (self.C @ (x - self.z)) / self.c
            H = H + self.C / self.c
        return g, H

    def _add_mass(self, H):
        pattern = self.model.space.pattern
        if self.mass == "lumped":
            m = self.model.lumped_mass / self.k2
            if pattern.owns(H):  # add on the diagonal in place: H keeps its pattern
                H.data[pattern.diagonal_positions] += m
                return H
            return H + sp.diags(m, format="csr")
        M = self.model.mass_matrix
        if pattern.owns(H):
            M.sort_indices()
            pos = pattern.positions_of(M)
            if pos is not None:
                H.data[pos] += M.data / self.k2
                return H
        return H + M / self.k2

    def scale(self, state, free) -> float:
        """Force scale (N) for Newton's relative tolerance.

        The larger of the momentum flux ``||M v_n|| / h`` (the inertial force
        of the step) and the external load, on the free DOFs; Newton takes
        the larger of this and its first residual (the out-of-balance force
        of the first guess).
        """
        m = self.model
        parts = [
            np.linalg.norm(self._M(state.v)[free]) / np.sqrt(self.k2),
            np.linalg.norm(m.external_force()[free]),
        ]
        return float(max(parts))

    def gradient_roundoff(self, x) -> float:
        """Round-off floor of ||dG/dx|| (N): the model's plus the inertia term's.

        The inertia force ``M (x - y) / k^2`` is a difference of positions of
        size |x|, each known to eps |x|: ``eps ||m |x| || / k^2``.
        """
        m = self.model
        inertia = _EPS * np.linalg.norm(m.lumped_mass * np.abs(x)) / self.k2
        return m.gradient_roundoff() + float(inertia)

    def energy_roundoff(self, x) -> float:
        """Absolute round-off of G (J) beyond eps |G|: the model's plus the inertia term's."""
        d = np.abs(x - self.y)
        inertia = _EPS * float(np.einsum("i,i,i->", self.model.lumped_mass, np.abs(x), d)) / self.k2
        return self.model.energy_roundoff() + inertia
