"""How far a deformed body is from inverting: det F at its quadrature points.

``J = det F`` is the volume ratio of the material around a point: 1 at rest,
below 1 compressed, 0 flattened and negative inverted (the element turned
inside out). :class:`DetF` evaluates it cheaply for every accepted step of a
run (:class:`fem_elastic.dynamics.observers.InversionWatch`):

- a P1 body, a mass-spring body or any other body on the tet mesh: per tet,
  from its vertex positions, ``J = det(Ds) / det(Dm)`` with ``Ds``, ``Dm`` the
  deformed and reference edge matrices ``[x1 - x0, x2 - x0, x3 - x0]`` (for P1
  this is F's determinant exactly; for springs, the tet the edges span);
- a P2 body: F at each quadrature point, from the shape-function gradients.

Materials differ in what they do with ``J <= 0``: Neo-Hookean's energy is
+inf there (it forbids inversion; the implicit line search never accepts
such a state), while linear, St. Venant-Kirchhoff, corotated and stable
Neo-Hookean give a finite energy (they allow it, and a run can pass through
inverted states without any other sign).
"""

from __future__ import annotations

import numpy as np

from ..discretization.fused import tet_volume_ratios
from ..materials.base import _det
from .elastic_body import ElasticPotential

__all__ = ["DetF", "det3"]


def det3(A: np.ndarray) -> np.ndarray:
    """Determinants of 3x3 matrices stored as ``A[i, j, ...]`` (any trailing shape).

    Parameters
    ----------
    A : numpy.ndarray
        ``(3, 3, ...)``.

    Returns
    -------
    numpy.ndarray
        ``(...)``: the determinant of each matrix (the rule of Sarrus; no LAPACK call per matrix).

    Examples
    --------
    >>> import numpy as np
    >>> float(det3(np.diag([1.0, 2.0, 3.0])[:, :, None])[0])
    6.0
    """
    return _det(A)  # the materials' determinant: the same operations, so the same bits


class DetF:
    """det F of a model's body at positions x (see the module notes for where it is evaluated).

    Parameters
    ----------
    model : Model
        Its body potential decides the points: a P2 :class:`fe.ElasticPotential`
        at its quadrature points, every other body per vertex tet.

    Attributes
    ----------
    where : str
        ``"quadrature points"`` or ``"tets"``.

    Examples
    --------
    >>> import numpy as np
    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)))
    >>> det = DetF(model)
    >>> x = model.X.reshape(-1, 3) * [1.0, 1.0, 0.5]  # squashed to half its height
    >>> bool(np.allclose(det(x.ravel()), 0.5)), det.where
    (True, 'tets')
    """

    def __init__(self, model):
        body = model.body_potential
        self._space = model.space
        self._body = body if isinstance(body, ElasticPotential) and model.space.order > 1 else None
        self.where = "quadrature points" if self._body is not None else "tets"
        self._to_vertices = model.to_vertices
        self._tets = np.asarray(model.mesh.t, dtype=np.int64)  # (4, n_tets)
        self._ref_det = self._tet_det(np.asarray(model.mesh.p, dtype=float).T)

    def _tet_det(self, p: np.ndarray) -> np.ndarray:
        """det of each tet's edge matrix for vertex positions ``p`` ``(n_vertices, 3)``."""
        t = self._tets
        p0 = p[t[0]]
        D = np.stack([p[t[1]] - p0, p[t[2]] - p0, p[t[3]] - p0], axis=-1)  # (n_tets, 3, 3): edges as columns
        return det3(np.moveaxis(D, 0, -1))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """det F (dimensionless) at positions ``x`` ``(ndofs,)`` (m): a flat array over the points."""
        if self._body is not None:
            return det3(self._body.F(x)).ravel()
        p = self._to_vertices(x)
        fused = tet_volume_ratios(p, self._tets, self._ref_det)  # same bits, one pass (numba)
        return fused if fused is not None else self._tet_det(p) / self._ref_det
