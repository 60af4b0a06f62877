"""One body of a multi-body model: its mesh, material, supports, placement and velocity.

A :class:`Body` is a description, not a model: :class:`fem_elastic.MultiBody`
builds a single-body :class:`fem_elastic.Model` from each (with the scene-wide
gravity, obstacles and damping) and stacks their DOFs. The placement is a
rigid transform of the mesh's reference configuration,

    X' = R X + t,

the rotation ``R`` about the origin of the mesh's coordinates first, then the
translation ``t`` (m); the placed mesh is the body's reference configuration
(its supports, tractions and driven motions refer to it). The initial
velocity is uniform over the body's nodes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InvalidParameter

if TYPE_CHECKING:  # for annotations only
    from skfem import MeshTet

    from .driven import Motion
    from .elastic_body import ElasticBody
    from .springs import MassSpring
    from .supports import DisplacementSpec, FixedSpec

__all__ = ["Body", "rotation_matrix"]


def rotation_matrix(rotate) -> np.ndarray:
    """The rotation ``R`` (3, 3) of a placement.

    Parameters
    ----------
    rotate : None, array_like (3,) or (3, 3)
        None (no rotation); a rotation vector ``axis * angle`` (rad), e.g.
        ``(0, 0, math.pi / 2)`` for a quarter turn about z; or a proper
        orthogonal 3x3 matrix.

    Returns
    -------
    numpy.ndarray
        ``(3, 3)`` with ``R^T R = I`` and ``det R = +1``.
    """
    if rotate is None:
        return np.eye(3)
    try:
        r = np.asarray(rotate, dtype=float)
    except (TypeError, ValueError):
        r = None
    if r is None or r.shape not in ((3,), (3, 3)) or not np.isfinite(r).all():
        raise InvalidParameter(
            "rotate must be None, a rotation vector axis * angle (rad) such as (0, 0, 1.5708), "
            f"or a 3x3 rotation matrix; got {rotate!r}."
        )
    if r.shape == (3, 3):
        # a rotation matrix is orthogonal to round-off: 1e-9 leaves room for matrices typed
        # with ~10 significant digits while rejecting any shear or scaling
        if not np.allclose(r.T @ r, np.eye(3), atol=1e-9) or np.linalg.det(r) <= 0:
            raise InvalidParameter(
                "rotate as a matrix must be a proper rotation (R^T R = I, det R = +1); a "
                "reflection or scaling would turn the body inside out or change its size. Got "
                f"{r.tolist()}."
            )
        return r
    angle = float(np.linalg.norm(r))
    if angle == 0.0:
        return np.eye(3)
    k = r / angle
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)  # Rodrigues


def _vector(value, what: str, unit: str) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        v = None
    if v is None or v.shape != (3,) or not np.isfinite(v).all():
        raise InvalidParameter(f"{what} must be a finite 3-vector ({unit}), e.g. (0, 0, 0); got {value!r}.")
    return v


class Body:
    """One body of a :class:`fem_elastic.MultiBody`.

    Parameters
    ----------
    mesh : skfem.MeshTet
        The body's tet mesh (m), in its own coordinates.
    density : float
        Mass density (kg/m^3), > 0.
    body : ElasticBody or MassSpring
        The body's energy and element order, e.g.
        ``fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.4), order=1)``.
    fixed, driven, displacement, traction
        Supports and loads of this body, as :class:`fem_elastic.Model` takes
        them (boundary names of this body's mesh).
    name : str
        The body's name (unique in a MultiBody), e.g. ``"ball"``.
    translate : array_like (3,)
        Translation of the placement (m), applied after the rotation.
    rotate : None, array_like (3,) or (3, 3)
        Rotation of the placement about the mesh's origin: a rotation vector
        (rad) or a rotation matrix (see :func:`rotation_matrix`).
    velocity : array_like (3,)
        Initial velocity of every node (m/s); fixed and driven DOFs follow
        their supports instead.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> b = fe.Body(fe.beam_mesh(cells=(2, 1, 1)), 1000.0,
    ...             fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)), name="beam",
    ...             translate=(0.0, 0.0, 1.0), velocity=(0.0, 0.0, -1.0))
    >>> float(b.mesh.p[2].min())
    1.0
    """

    def __init__(self, mesh: MeshTet, density: float, body: ElasticBody | MassSpring,
                 fixed: FixedSpec | None = None, driven: Mapping[str, Motion] | None = None,
                 displacement: DisplacementSpec | None = None,
                 traction: Mapping[str, ArrayLike] | None = None, name: str = "body",
                 translate: ArrayLike = (0.0, 0.0, 0.0), rotate: ArrayLike | None = None,
                 velocity: ArrayLike = (0.0, 0.0, 0.0)) -> None:
        if not isinstance(name, str) or not name.strip():
            raise InvalidParameter(f"a body's name must be a non-empty string, e.g. 'ball'; got {name!r}.")
        if not hasattr(mesh, "p") or not hasattr(mesh, "t"):
            raise InvalidParameter(
                f"body {name!r}: mesh must be a tet mesh such as fe.beam_mesh(...) or "
                f"fe.load_mesh(path); got {type(mesh).__name__}."
            )
        self.name = name
        self.translate = _vector(translate, f"body {name!r}: translate", "m")
        self.rotation = rotation_matrix(rotate)
        self.velocity = _vector(velocity, f"body {name!r}: velocity", "m/s")
        self.source_mesh = mesh
        #: the placed mesh: the body's reference configuration (m)
        self.mesh = self._placed(mesh)
        self.density = density
        self.body = body
        self.fixed, self.driven, self.displacement, self.traction = fixed, driven, displacement, traction

    def _placed(self, mesh):
        if np.array_equal(self.rotation, np.eye(3)) and not self.translate.any():
            return mesh
        p = self.rotation @ np.asarray(mesh.p, dtype=float) + self.translate[:, None]
        return replace(mesh, doflocs=p)  # same topology and named boundaries

    def __repr__(self) -> str:
        return (f"Body(name={self.name!r}, vertices={self.mesh.p.shape[1]}, density={self.density!r}, "
                f"body={self.body!r})")
