"""The State of a simulation: positions, velocities and time, nothing else.

A :class:`State` is an immutable value: a step of an integrator returns a
new one. Derived quantities (energies, momenta, stresses) are computed from
it by the Model, never stored in it.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Union

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InvalidParameter

if TYPE_CHECKING:  # for annotations only
    from ..physics.multibody import AnyModel

#: A per-node field: None (zero), one vector for every node, an ``(n_nodes, 3)`` array, or
#: ``function(X (n_nodes, 3)) -> (n_nodes, 3)`` of the reference node positions.
NodeField = Union[ArrayLike, Callable[[np.ndarray], ArrayLike], None]

__all__ = ["State"]


def _readonly(a) -> np.ndarray:
    try:
        a = np.array(a, dtype=float)  # a private copy, so nobody else can change it
    except (TypeError, ValueError):
        raise InvalidParameter(f"State x and v must be arrays of numbers, got {a!r}.") from None
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class State:
    """Positions and velocities of every DOF at a time.

    Parameters
    ----------
    x : numpy.ndarray
        DOF positions, ``(ndofs,)`` (m), scikit-fem's node-major interleaved order.
    v : numpy.ndarray
        DOF velocities, ``(ndofs,)`` (m/s).
    t : float
        Time (s).

    Examples
    --------
    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)))
    >>> s = fe.State.rest(model, velocity=(0.0, 0.0, -1.0))
    >>> s.t, float(s.v[2]), s.x.flags.writeable
    (0.0, -1.0, False)
    """

    x: np.ndarray
    v: np.ndarray
    t: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "x", _readonly(self.x))
        object.__setattr__(self, "v", _readonly(self.v))
        t = self.t
        if isinstance(t, bool) or not isinstance(t, numbers.Real) or not math.isfinite(t):
            raise InvalidParameter(f"State time t must be a finite number (s), got {t!r}.")
        object.__setattr__(self, "t", float(t))
        if self.x.ndim != 1 or self.x.shape != self.v.shape:
            raise InvalidParameter(
                f"State needs flat x and v of equal shape (ndofs,), got {self.x.shape} and {self.v.shape}."
            )

    @classmethod
    def _adopt(cls, x: np.ndarray, v: np.ndarray, t: float) -> "State":
        """A State that takes ``x`` and ``v`` as they are, without the copies (for integrators).

        Only for new float64 arrays of shape ``(ndofs,)`` that nobody else
        holds (an integrator's fresh step result): they are made read-only
        and become the State's own, as the copies of ``State(x, v, t)`` would.
        ``t`` must be a finite float.
        """
        x.setflags(write=False)
        v.setflags(write=False)
        # read-only views of read-only buffers: numpy refuses setflags(write=True) on them, so
        # the integrator's "checked finite" mark on this State cannot be bypassed by a writer
        x, v = x[:], v[:]
        state = object.__new__(cls)
        object.__setattr__(state, "x", x)
        object.__setattr__(state, "v", v)
        object.__setattr__(state, "t", float(t))
        return state

    @classmethod
    def rest(cls, model: AnyModel, *, displacement: NodeField = None, velocity: NodeField = None,
             t: float = 0.0) -> "State":
        """A state of ``model`` built from per-node fields.

        Parameters
        ----------
        model : Model
        displacement, velocity : None, array_like or callable
            None (zero), a constant 3-vector, an ``(n_nodes, 3)`` or
            ``(n_vertices, 3)`` array (P2 edge nodes then get the mean of their
            edge's vertices), or a function of the reference node positions
            ``(n_nodes, 3)`` (m) returning ``(n_nodes, 3)``. Units m and m/s.
        t : float
            Time (s).
        """
        x = model.X + _node_field(model, displacement, "displacement")
        v = _node_field(model, velocity, "velocity")
        # constrained DOFs follow their prescription from the first instant
        dofs, xc, vc = model.constraints(t)
        x[dofs], v[dofs] = xc, vc
        return cls(x, v, t)

    def displacement(self, model: AnyModel) -> np.ndarray:
        """Vertex displacements ``(n_vertices, 3)`` (m)."""
        return model.to_vertices(self.x - model.X)

    def velocity(self, model: AnyModel) -> np.ndarray:
        """Vertex velocities ``(n_vertices, 3)`` (m/s)."""
        return model.to_vertices(self.v)


def _node_field(model, value, name: str) -> np.ndarray:
    nodes = model.X.reshape(-1, 3)
    nn = nodes.shape[0]
    nv = model.mesh.p.shape[1]
    if value is None:
        return np.zeros(model.ndofs)
    unit = "m" if name == "displacement" else "m/s"
    if callable(value):
        arr = np.asarray(value(nodes.copy()), dtype=float)
        if arr.shape != (nn, 3):
            raise InvalidParameter(f"the {name} function must return shape ({nn}, 3), got {arr.shape}.")
        _check_finite(arr, f"the {name} function", unit)
        return arr.ravel()
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidParameter(
            f"{name} must be None, a 3-vector, an (n, 3) array or a function of the node "
            f"positions; got {value!r}."
        ) from None
    _check_finite(arr, name, unit)
    if arr.shape == (3,):
        return np.tile(arr, nn)
    if arr.shape == (nn, 3):
        return arr.ravel().copy()
    if arr.shape == (nv, 3):
        space = model.space
        out = np.zeros((nn, 3))
        out[space.vertex_dofs[:, 0] // 3] = arr
        if nn > nv:  # P2: edge nodes follow the mean of their edge's vertices
            edges = model.mesh.edges
            out[np.asarray(space.dofs.edge_dofs)[0]] = 0.5 * (arr[edges[0]] + arr[edges[1]])
        return out.ravel()
    shapes = f"({nn}, 3)" if nn == nv else f"({nn}, 3) (every node) or ({nv}, 3) (the vertices)"
    raise InvalidParameter(
        f"{name} must be None, a 3-vector, an array of shape {shapes}, or a "
        f"function of the node positions; got an array of shape {arr.shape}."
    )


def _check_finite(arr: np.ndarray, what: str, unit: str) -> None:
    """:class:`InvalidParameter` naming the first NaN or infinite entry of an initial field."""
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise InvalidParameter(
            f"{what} has {bad.size} NaN or infinite value(s) (first at flat index {bad[0]}), so "
            f"the simulation would start from a non-finite state; give finite values ({unit})."
        )
