"""Driven boundaries: time-dependent Dirichlet conditions.

A motion prescribes the displacement of a boundary's nodes as a function of
their reference positions and of time. The model holds those DOFs at the
prescribed positions (and velocities) until the motion's ``release`` time;
after it they move freely. ``fe.Model(..., driven={"right": fe.Twist(...)})``
attaches a motion to a named boundary.

All motions are rigid motions of the boundary or user functions; the
prescribed velocity is the exact time derivative where it is known in
closed form (else a central difference).
"""

from __future__ import annotations

import math
import numbers

from collections.abc import Callable
from typing import Literal, overload

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InvalidParameter
from .loads import as_vector3

__all__ = ["Motion", "Twist", "Translate", "Prescribed"]


@overload
def _check_time(value: float, name: str, allow_none: Literal[False] = False) -> float: ...


@overload
def _check_time(value: float | None, name: str, allow_none: bool) -> float | None: ...


def _check_time(value, name: str, allow_none: bool = False) -> float | None:
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) or value < 0:
        raise InvalidParameter(f"{name} must be a finite time >= 0 (s), got {value!r}.")
    # numbers.Real: numpy scalars (np.float32 too) are accepted like Python floats
    return float(value)


class Motion:
    """Base class: a prescribed displacement ``u(X, t)`` of boundary nodes.

    Subclasses implement :meth:`displacement`; :meth:`velocity` defaults to
    a central difference of it.

    Parameters
    ----------
    release : float or None
        Time (s) from which the nodes are free; None holds them forever.
    """

    def __init__(self, release: float | None = None) -> None:
        self.release = _check_time(release, "release", allow_none=True)

    def active(self, t: float) -> bool:
        """Whether the nodes are held at time ``t`` (s)."""
        return self.release is None or t < self.release

    def moving(self, t: float) -> bool:
        """Whether the held nodes may still be moving at ``t`` (s), i.e. doing work on the body.

        A user motion may move at any time; :class:`Twist` and
        :class:`Translate` stop at the end of their ``duration``.
        """
        return self.active(t) and t < getattr(self, "duration", math.inf)

    def displacement(self, X: np.ndarray, t: float) -> np.ndarray:  # pragma: no cover - abstract
        """Prescribed displacement ``(n, 3)`` (m) of nodes at reference positions ``X`` ``(n, 3)``."""
        raise NotImplementedError

    def velocity(self, X: np.ndarray, t: float) -> np.ndarray:
        """Prescribed velocity ``(n, 3)`` (m/s); a central difference unless overridden."""
        h = 1e-6 * max(1.0, abs(t))
        return (self.displacement(X, t + h) - self.displacement(X, max(t - h, 0.0))) / (
            t + h - max(t - h, 0.0)
        )

    def _ramp(self, t: float, duration: float):
        """Fraction of the motion done at t and its rate (1/s): linear over ``duration``."""
        if duration == 0.0:
            return 1.0, 0.0
        if t < duration:
            return t / duration, 1.0 / duration
        return 1.0, 0.0


class Twist(Motion):
    """Rotate a boundary about an axis, by ``angle`` over ``duration``, then hold.

    Parameters
    ----------
    angle : float
        Total rotation (rad), e.g. ``2 * pi`` for a full turn.
    duration : float
        Time (s) over which the angle grows linearly from 0.
    axis : array_like
        Rotation axis (any length), default the x axis (a beam's length).
    center : array_like or None
        A point on the axis (m); None takes the centroid of the driven nodes.
    release : float or None
        Time (s) from which the boundary is free.

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> tw = fe.Twist(np.pi / 2, duration=1.0, center=(0, 0, 0))
    >>> np.round(tw.displacement(np.array([[0.0, 1.0, 0.0]]), 1.0), 12)  # (0,1,0) -> (0,0,1)
    array([[ 0., -1.,  1.]])
    """

    def __init__(self, angle: float, duration: float, axis: ArrayLike = (1.0, 0.0, 0.0),
                 center: ArrayLike | None = None, release: float | None = None) -> None:
        super().__init__(release)
        if isinstance(angle, bool) or not isinstance(angle, numbers.Real) or not math.isfinite(angle):
            raise InvalidParameter(f"Twist angle must be a finite number (rad), got {angle!r}.")
        self.angle = float(angle)
        self.duration = _check_time(duration, "Twist duration")
        a = as_vector3(axis, "Twist axis", "a direction", "(1.0, 0.0, 0.0)")
        n = np.linalg.norm(a)
        if n == 0:
            raise InvalidParameter("Twist axis must be a non-zero vector, e.g. (1, 0, 0).")
        self.axis = a / n
        self.center = None if center is None else as_vector3(center, "Twist center", "m", "(0.0, 0.05, 0.05)")

    def _geometry(self, X, t):
        c = X.mean(axis=0) if self.center is None else self.center
        s, rate = self._ramp(t, self.duration)
        theta = self.angle * s
        r = X - c
        k = self.axis
        kxr = np.cross(k, r)
        kdr = r @ k
        return r, k, kxr, kdr, theta, self.angle * rate

    def displacement(self, X: np.ndarray, t: float) -> np.ndarray:
        r, k, kxr, kdr, th, _ = self._geometry(np.asarray(X, float), t)
        # Rodrigues' rotation of r about k by th
        rot = r * math.cos(th) + kxr * math.sin(th) + np.outer(kdr, k) * (1 - math.cos(th))
        return rot - r

    def velocity(self, X: np.ndarray, t: float) -> np.ndarray:
        r, k, kxr, kdr, th, omega = self._geometry(np.asarray(X, float), t)
        rot = r * math.cos(th) + kxr * math.sin(th) + np.outer(kdr, k) * (1 - math.cos(th))
        return omega * np.cross(k, rot)


class Translate(Motion):
    """Move a boundary by ``offset`` at constant speed over ``duration``, then hold.

    Parameters
    ----------
    offset : array_like
        Total displacement (m), e.g. ``(0, 0, -0.08)`` to push a face down.
    duration : float
        Time (s) over which it is applied.
    release : float or None
        Time (s) from which the boundary is free.

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> fe.Translate((0, 0, -1.0), duration=2.0).displacement(np.zeros((1, 3)), 1.0)
    array([[ 0. ,  0. , -0.5]])
    """

    def __init__(self, offset: ArrayLike, duration: float, release: float | None = None) -> None:
        super().__init__(release)
        self.offset = as_vector3(offset, "Translate offset", "m", "(0.0, 0.0, -0.05)")
        self.duration = _check_time(duration, "Translate duration")

    def displacement(self, X: np.ndarray, t: float) -> np.ndarray:
        s, _ = self._ramp(t, self.duration)
        return np.broadcast_to(s * self.offset, np.shape(X)).copy()

    def velocity(self, X: np.ndarray, t: float) -> np.ndarray:
        _, rate = self._ramp(t, self.duration)
        return np.broadcast_to(rate * self.offset, np.shape(X)).copy()


class Prescribed(Motion):
    """A user motion: ``function(X, t) -> (n, 3)`` displacement (m).

    Parameters
    ----------
    function : callable
        ``(X (n, 3) m, t s) -> (n, 3)`` displacement (m).
    velocity : callable, optional
        Its time derivative, same signature (m/s); default a central difference.
    release : float or None
        Time (s) from which the boundary is free.

    Examples
    --------
    >>> import numpy as np, fem_elastic as fe
    >>> shake = fe.Prescribed(lambda X, t: np.outer(np.ones(len(X)), (0.01 * np.sin(t), 0, 0)))
    >>> round(float(shake.velocity(np.zeros((1, 3)), 0.0)[0, 0]), 9)  # d/dt 0.01 sin t at 0
    0.01
    """

    def __init__(self, function: Callable[[np.ndarray, float], ArrayLike],
                 velocity: Callable[[np.ndarray, float], ArrayLike] | None = None,
                 release: float | None = None) -> None:
        super().__init__(release)
        if not callable(function):
            raise InvalidParameter(f"Prescribed needs a function (X, t) -> displacement, got {function!r}.")
        self.function = function
        self._velocity = velocity

    def displacement(self, X: np.ndarray, t: float) -> np.ndarray:
        u = np.asarray(self.function(X, t), dtype=float)
        if u.shape != np.shape(X):
            raise InvalidParameter(
                f"the prescribed displacement function returned shape {u.shape}, expected {np.shape(X)}."
            )
        return u

    def velocity(self, X: np.ndarray, t: float) -> np.ndarray:
        if self._velocity is None:
            return super().velocity(X, t)
        return np.asarray(self._velocity(X, t), dtype=float)
