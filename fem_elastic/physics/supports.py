"""Supports: which DOFs a model holds, in which components, and where it moves them.

Three user-facing forms are resolved here, all to flat DOF indices of the
model's space (3 per node, P2 edge nodes included):

* ``fixed`` — DOFs held at their reference position. A *where* (a boundary
  name, several names, vertex indices or a boolean vertex mask) holds all
  three components; a mapping ``{where: components}`` (or a list of
  ``(where, components)`` pairs, for masks and index arrays, which cannot be
  dict keys) holds only the components given: ``"x"``, ``"yz"``, ``"xyz"`` or
  a bool triple ``(True, False, True)``.
* ``displacement`` — prescribed displacements ``{where: (ux, uy, uz)}`` (m),
  ``None`` leaving a component free, or ``{where: function}``, a field
  ``function(X) -> (n, 3)`` of the reference node positions (NaN: free).
* ``driven`` — time-dependent motions (kept in :mod:`.model`).

A P2 edge node belongs to a *where* when its edge lies on the named boundary
facets, or when both its vertices are in the mask: a support acts on whole
edges, not on vertices alone.

:func:`describe_rigid_modes` names the rigid-body motions a set of held DOFs
leaves free ("translation along x", "rotation about an axis along z through
(0, 0.05, 0.05)"), for :meth:`Model.check_supported`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import TypeAlias, Union

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InvalidParameter
from ..geometry.mesh import boundary_facets

__all__ = [
    "COMPONENT_FORMS", "FIXED_FORMS", "DISPLACEMENT_FORMS",
    "parse_components", "nodes_of", "resolve_fixed", "resolve_displacement",
    "describe_rigid_modes", "label_of",
    "Where", "Components", "FixedSpec", "DisplacementSpec",
]

# The forms below as types (for annotations; the checks at run time are the functions here).
#: Where: a boundary name, several names, vertex indices or a boolean vertex mask.
Where: TypeAlias = Union[str, Sequence[str], ArrayLike]
#: Components held: "x", "yz", "xyz", ... or a bool triple.
Components: TypeAlias = Union[str, tuple[bool, bool, bool], Sequence[bool]]
#: ``fixed=``: a where (all three components), ``{where: components}`` or ``[(where, components)]``.
FixedSpec: TypeAlias = Union[Where, Mapping[str, Components], Sequence[tuple[Where, Components]]]
#: One prescribed displacement: ``(ux, uy, uz)`` (m, None: free) or ``function(X (n, 3)) -> (n, 3)``.
DisplacementValue: TypeAlias = Union[Sequence[Union[float, None]], Callable[[np.ndarray], ArrayLike]]
#: ``displacement=``: ``{where: value}`` or ``[(where, value)]``.
DisplacementSpec: TypeAlias = Union[Mapping[str, DisplacementValue],
                                    Sequence[tuple[Where, DisplacementValue]]]

#: How the components of a support may be written (for error messages).
COMPONENT_FORMS = (
    'a string of the components held, "x", "y", "z", "xy", "yz", "xz" or "xyz", '
    "or a bool triple such as (True, False, True)"
)
#: How ``fixed`` may be written (for error messages).
FIXED_FORMS = (
    'a boundary name ("left"), a list of names, vertex indices, a boolean vertex mask, or a '
    'mapping from any of these to the components held, e.g. {"left": "xyz", "front": "z"} '
    "(components: " + COMPONENT_FORMS + "); for a mask or an index array with components, "
    'a list of (where, components) pairs, e.g. [(mask, "z")]'
)
#: How ``displacement`` may be written (for error messages).
DISPLACEMENT_FORMS = (
    'a mapping {where: (ux, uy, uz)} in metres with None for a free component, e.g. '
    '{"right": (0.01, None, None)}, or {where: function} with function(X) -> (n, 3) '
    'displacements (m, NaN: free) of the reference node positions X (n, 3), where "where" is a '
    'boundary name (or a tuple of names or vertex indices); or a list of (where, value) pairs '
    'for a vertex mask or index array'
)

_AXES = "xyz"


def parse_components(value, where: str = "fixed") -> np.ndarray:
    """``"x"``, ``"yz"``, ``"xyz"`` or a bool triple -> ``(3,)`` bool mask of held components.

    Examples
    --------
    >>> parse_components("xz").tolist(), parse_components((False, True, False)).tolist()
    ([True, False, True], [False, True, False])
    """
    if isinstance(value, str):
        s = value.strip()
        if s and all(c in _AXES for c in s) and len(set(s)) == len(s):
            return np.array([a in s for a in _AXES])
    elif isinstance(value, (tuple, list, np.ndarray)) and len(value) == 3 and all(
        isinstance(v, (bool, np.bool_)) for v in value
    ):
        comps = np.array([bool(v) for v in value])
        if comps.any():
            return comps
        raise InvalidParameter(
            f"{where} holds no component ({value!r}): drop the entry, or give "
            f"{COMPONENT_FORMS}."
        )
    raise InvalidParameter(f"{where} must be {COMPONENT_FORMS}; got {value!r}.")


def label_of(where) -> str:
    """A short name of a *where* for messages: the boundary name, or 'n vertices'."""
    if isinstance(where, str):
        return repr(where)
    if isinstance(where, (list, tuple)) and where and all(isinstance(w, str) for w in where):
        return "+".join(repr(w) for w in where)
    arr = np.asarray(where)
    if arr.dtype == bool:
        return f"a vertex mask ({int(arr.sum())} vertices)"
    return f"vertex indices ({arr.size} vertices)"


def nodes_of(space, where, what: str = "fixed") -> np.ndarray:
    """Sorted scalar nodes (vertices and P2 edge nodes) of a *where*.

    A *where* is a boundary name, a sequence of names, vertex indices or a
    boolean mask over the vertices.
    """
    mesh = space.mesh
    nv = mesh.p.shape[1]
    if isinstance(where, str):
        names = [where]
    elif isinstance(where, (list, tuple)) and len(where) > 0 and all(isinstance(w, str) for w in where):
        names = list(where)
    else:
        names = None
    if names is not None:
        nodes = []
        for name in names:
            facets = boundary_facets(mesh, name, what=what)
            nodes.append(space.facet_nodes(facets))
        return np.unique(np.concatenate(nodes)).astype(np.int64)
    try:
        arr = np.asarray(where)
    except Exception:  # ragged sequences
        arr = np.asarray([], dtype=float).reshape(0, 1)
    if arr.dtype == bool:
        if arr.shape != (nv,):
            raise InvalidParameter(
                f"a boolean {what} mask must have one entry per vertex ({nv}), got shape {arr.shape}."
            )
        mask = arr
    elif np.issubdtype(arr.dtype, np.integer) and arr.ndim <= 1:
        arr = arr.ravel()
        if arr.size and (arr.min() < 0 or arr.max() >= nv):
            raise InvalidParameter(
                f"{what} vertex indices must lie in [0, {nv - 1}], got values from "
                f"{arr.min()} to {arr.max()}."
            )
        mask = np.zeros(nv, dtype=bool)
        mask[arr] = True
    else:
        raise InvalidParameter(f"{what} must be {FIXED_FORMS}; got {where!r}.")
    nodes = [np.asarray(space.dofs.nodal_dofs[0])[mask]]
    if space.order == 2:
        edge_on = mask[mesh.edges].all(axis=0)
        nodes.append(np.asarray(space.dofs.edge_dofs)[0, edge_on])
    return np.unique(np.concatenate(nodes)).astype(np.int64)


def _is_where_list(spec) -> bool:
    """Whether ``spec`` is a list of (where, value) pairs (not a list of names or indices)."""
    return (
        isinstance(spec, (list, tuple))
        and len(spec) > 0
        and all(isinstance(p, tuple) and len(p) == 2 for p in spec)
        and not all(isinstance(v, (int, np.integer, bool, np.bool_)) for p in spec for v in p)
    )


def _entries(spec):
    """(where, value) pairs of a mapping or a list of pairs; None for another form."""
    if isinstance(spec, Mapping):
        out = []
        for where, value in spec.items():
            if isinstance(where, tuple) and where and not all(isinstance(w, str) for w in where):
                where = np.asarray(where)
            out.append((where, value))
        return out
    if _is_where_list(spec):
        return list(spec)
    return None


def resolve_fixed(space, fixed, what: str = "fixed"):
    """Flat, sorted held DOFs of ``fixed``, and the groups ``[(label, where, dofs)]`` it is made of.

    Raises
    ------
    InvalidParameter
        With the allowed forms, for anything else.
    """
    empty = np.zeros(0, dtype=np.int64)
    if fixed is None:
        return empty, []
    entries = _entries(fixed)
    if entries is None:
        if not isinstance(fixed, str):
            try:
                size = np.size(fixed)
            except Exception:
                size = 1
            if size == 0:
                return empty, []
        if isinstance(fixed, (set, frozenset)):
            raise InvalidParameter(f"{what} must be {FIXED_FORMS}; got {fixed!r}.")
        entries = [(fixed, "xyz")]
    groups = []
    all_dofs = [empty]
    for where, comps in entries:
        held = parse_components(comps, where=f"{what}[{label_of(where)}]")
        nodes = nodes_of(space, where, what)
        dofs = (3 * nodes[:, None] + np.flatnonzero(held)[None, :]).ravel()
        dofs = np.sort(dofs).astype(np.int64)
        groups.append((label_of(where), where, dofs))
        all_dofs.append(dofs)
    return np.unique(np.concatenate(all_dofs)).astype(np.int64), groups


def _parse_vector(value, where: str) -> np.ndarray:
    """``(ux, uy, uz)`` with None for free components -> ``(3,)`` floats with NaN for free."""
    if isinstance(value, (str, bytes, Mapping)) or not hasattr(value, "__len__") or len(value) != 3:
        raise InvalidParameter(
            f"displacement[{where}] must be three components (ux, uy, uz) in metres, None for a "
            f"free one, e.g. (0.01, None, None); got {value!r}."
        )
    out = np.full(3, np.nan)
    for i, v in enumerate(value):
        if v is None:
            continue
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise InvalidParameter(
                f"displacement[{where}] component {_AXES[i]} must be a number (m) or None, got {v!r}."
            )
        if not math.isfinite(float(v)):
            raise InvalidParameter(
                f"displacement[{where}] component {_AXES[i]} must be finite (m), got {v!r}."
            )
        out[i] = float(v)
    if np.isnan(out).all():
        raise InvalidParameter(
            f"displacement[{where}] prescribes no component ({value!r}): give at least one number."
        )
    return out


def _field_values(space, nodes, fn, label):
    """DOFs and values of a prescribed displacement field ``fn(X) -> (n, 3)`` (m; NaN: free)."""
    X = np.asarray(space.X, dtype=float).reshape(-1, 3)[nodes]
    try:
        u = np.asarray(fn(X.copy()), dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidParameter(
            f"displacement[{label}] is a function of the reference node positions (n, 3) (m) that "
            f"must return their displacements (n, 3) (m); calling it failed: {exc}"
        ) from None
    if u.shape != X.shape:
        raise InvalidParameter(
            f"displacement[{label}] returned shape {u.shape}; it must return one displacement per "
            f"node, shape {X.shape} (m), NaN for a free component."
        )
    if np.isinf(u).any():
        raise InvalidParameter(f"displacement[{label}] returned infinite values.")
    keep = ~np.isnan(u)
    dofs = (3 * nodes[:, None] + np.arange(3)[None, :])[keep]
    return dofs, u[keep]


def resolve_displacement(space, displacement, fixed_groups=()):
    """Prescribed DOFs (flat, sorted), their displacements (m) and the groups ``[(label, where, dofs)]``.

    A DOF both fixed and prescribed, or prescribed twice with two values, is
    an error naming both supports.
    """
    empty = np.zeros(0, dtype=np.int64)
    if displacement is None:
        return empty, np.zeros(0), []
    entries = _entries(displacement)
    if entries is None:
        raise InvalidParameter(f"displacement must be {DISPLACEMENT_FORMS}; got {displacement!r}.")
    groups = []
    owner: dict[int, tuple[str, float]] = {}
    for where, value in entries:
        label = label_of(where)
        nodes = nodes_of(space, where, "displacement")
        if callable(value):
            dofs2, vals2 = _field_values(space, nodes, value, label)
        else:
            u = _parse_vector(value, label)
            held = np.flatnonzero(~np.isnan(u))
            dofs2 = 3 * nodes[:, None] + held[None, :]
            vals2 = np.broadcast_to(u[held], dofs2.shape)
        order = np.argsort(dofs2.ravel())
        dofs, vals = dofs2.ravel()[order].astype(np.int64), vals2.ravel()[order]
        for flabel, _, fdofs in fixed_groups:
            common = np.intersect1d(dofs, fdofs)
            if common.size:
                comps = "".join(sorted({_AXES[d % 3] for d in common}))
                raise InvalidParameter(
                    f"boundary {label} is prescribed a displacement in component(s) {comps!r} at "
                    f"{common.size // len(comps) or 1} node(s) that fixed {flabel} also holds: a DOF "
                    f"is either fixed or prescribed. Drop {comps!r} from one of them (fixed "
                    f"components: {COMPONENT_FORMS})."
                )
        for d, v in zip(dofs.tolist(), vals.tolist()):
            if d in owner and owner[d][1] != v:
                raise InvalidParameter(
                    f"displacement of {label} and of {owner[d][0]} prescribe different values "
                    f"({v} m and {owner[d][1]} m) to component {_AXES[d % 3]!r} of a node they "
                    "share: give the shared nodes one value."
                )
            owner.setdefault(d, (label, v))
        groups.append((label, where, dofs))
    if not owner:
        return empty, np.zeros(0), groups
    all_dofs = np.array(sorted(owner), dtype=np.int64)
    values = np.array([owner[d][1] for d in all_dofs.tolist()])
    return all_dofs, values, groups


def _fmt(v) -> str:
    return "(" + ", ".join(f"{c:.4g}" for c in np.where(np.abs(v) < 1e-12, 0.0, v)) + ")"


def _axis_name(a: np.ndarray) -> str:
    a = a / np.linalg.norm(a)
    for i, name in enumerate(_AXES):
        if abs(abs(a[i]) - 1.0) < 1e-6:
            return name
    return _fmt(a if a[np.argmax(np.abs(a))] > 0 else -a)


def describe_rigid_modes(X: np.ndarray, held: np.ndarray, rtol: float = 1e-8) -> list[str]:
    """Names of the rigid-body motions that the held DOFs leave free (empty when none).

    Parameters
    ----------
    X : numpy.ndarray
        Reference DOF positions, ``(ndofs,)`` (m).
    held : numpy.ndarray
        Indices of the held DOFs.

    Examples
    --------
    >>> import numpy as np
    >>> X = np.array([0., 0, 0, 1, 0, 0, 0, 1, 0])
    >>> describe_rigid_modes(X, np.array([2, 5, 8]))  # every z held: in-plane motion free
    ['translation along x', 'translation along y', 'rotation about z']
    >>> describe_rigid_modes(X, np.array([0, 1, 2, 5, 8]))  # and a pin at the origin
    ['rotation about an axis along z through (0, 0, 0)']
    """
    P = X.reshape(-1, 3)
    c = P.mean(axis=0)
    size = float(np.ptp(P, axis=0).max()) or 1.0
    r = (P - c) / size
    B = np.zeros((P.shape[0], 3, 6))
    for k in range(3):
        B[:, k, k] = 1.0
    B[:, 1, 3], B[:, 2, 3] = -r[:, 2], r[:, 1]
    B[:, 0, 4], B[:, 2, 4] = r[:, 2], -r[:, 0]
    B[:, 0, 5], B[:, 1, 5] = -r[:, 1], r[:, 0]
    B = B.reshape(-1, 6)[np.asarray(held, dtype=np.int64)]
    if B.shape[0] == 0:
        return ["translation along x", "translation along y", "translation along z",
                "rotation about x", "rotation about y", "rotation about z"]
    _, s, vt = np.linalg.svd(B, full_matrices=True)
    rank = int(np.sum(s > rtol * s[0])) if s.size else 0
    N = vt[rank:].T  # (6, k) null space, orthonormal
    k = N.shape[1]
    if k == 0:
        return []
    names = []
    # translations inside the null space: combinations with no rotation part
    _, sr, vr = np.linalg.svd(N[3:, :], full_matrices=True)
    rot_rank = int(np.sum(sr > 1e-8))
    trans = N @ vr[rot_rank:].T  # (6, k - rot_rank), pure translations
    if trans.shape[1]:
        # a tidy basis: the coordinate axes where they are free
        T = trans[:3]
        for i, name in enumerate(_AXES):
            e = np.eye(3)[i]
            if np.linalg.norm(e - T @ np.linalg.lstsq(T, e, rcond=None)[0]) < 1e-6:
                names.append(f"translation along {name}")
        if len(names) < T.shape[1]:
            names = [f"translation along {_axis_name(T[:, j])}" for j in range(T.shape[1])]
    rots = N @ vr[:rot_rank].T  # the rest: rotations (possibly screws)
    if rot_rank == 3:
        # every rotation is free: about one point (a single held vertex), if there is one
        A = np.zeros((9, 3))
        b = np.zeros(9)
        for j in range(3):  # t_j + w_j x (p - c) / size = 0  <=>  [w_j]x (p - c) = -size t_j
            t, w = rots[:3, j], rots[3:, j]
            A[3 * j:3 * j + 3] = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
            b[3 * j:3 * j + 3] = -size * t
        q, *_ = np.linalg.lstsq(A, b, rcond=None)
        if np.linalg.norm(A @ q - b) <= 1e-6 * size:
            names.append(f"rotation about every axis through {_fmt(c + q)} (3 modes)")
            return names
    T = trans[:3]
    for j in range(rots.shape[1]):
        t, w = rots[:3, j], rots[3:, j]
        a = w / np.linalg.norm(w)
        perp = np.linalg.svd(a[None, :])[2][1:]  # two unit vectors across the axis
        if T.shape[1] and all(np.linalg.norm(e - T @ np.linalg.lstsq(T, e, rcond=None)[0]) < 1e-6
                              for e in perp):
            names.append(f"rotation about {_axis_name(w)}")  # sliding across it is free too: any such axis
            continue
        wn2 = float(w @ w)
        # a point on the axis: the rigid motion t + w x (X - c) vanishes there (up to the pitch)
        p = c + size * np.cross(w, t) / wn2
        pitch = float(t @ w) / wn2
        name = f"rotation about an axis along {_axis_name(w)} through {_fmt(p)}"
        if abs(pitch) > 1e-6:
            name += " (a screw motion)"
        names.append(name)
    return names
