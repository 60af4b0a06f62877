"""Several bodies in one model: single-body Models stacked DOF after DOF.

Each :class:`fem_elastic.Body` becomes a full single-body
:class:`fem_elastic.Model` (its own mesh, material, order, density, supports
and loads, with the scene-wide gravity, obstacles and damping), and the
:class:`MultiBody` presents the Model interface the integrators, solvers,
observers, checkpoints and output use. The DOF vector is the bodies' DOF
vectors one after the other, body 0 first:

    x = [x_0, x_1, ..., x_{B-1}],    Pi(x) = sum_b Pi_b(x_b) + E_contact(x).

Without contact between them the bodies are independent: the gradient is
the bodies' gradients stacked, the Hessian and the mass matrices are block
diagonal, so two bodies far apart move exactly as each would alone. A
contact between bodies (``contact=``, e.g. ``fe.IPCContact``) is bound to
the whole model and acts on :meth:`MultiBody.collision_surface`, the bodies'
boundary surfaces stacked.

The vertices are stacked the same way: :attr:`MultiBody.mesh` is the
disjoint union of the placed meshes (vertex ``i`` of body ``b`` is vertex
``vertex_offsets[b] + i``), :meth:`MultiBody.to_vertices` returns the stacked
vertex values, and :attr:`MultiBody.body_of_tet` tells the tets apart (the
output writes it as the ``body`` cell array).

What a single-body Model offers and a MultiBody does not raises
:class:`fem_elastic.InvalidParameter` naming the alternative: a bare
boundary name (it belongs to one mesh; :class:`BodyBoundary` names the body),
a body energy to stand in for the bodies' (``linearize(body=...)``), and
the integrators that take one body (PBD, XPBD, shape matching, projective
dynamics). The stacked body energy has no single ``material``, so
``fe.LinearizedImplicitEuler`` takes its one Newton step on the full tangent
(no stiffness warping) and stiffness-proportional damping uses each body's
own warped stiffness; VTU output takes linear (P1) bodies.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import cached_property
from typing import TYPE_CHECKING, NamedTuple, TypeAlias, Union

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike
from skfem import MeshTet

from ..errors import InvalidParameter, UnderConstrained
from .body import Body
from .model import Model, bind_contact

if TYPE_CHECKING:  # for annotations only (pyvista is optional)
    from typing import Unpack  # Python >= 3.11

    import pyvista

    from .collision_surface import CollisionSurface
    from .damping import Rayleigh
    from .impulse_contact import ImpulseContact
    from .ipc_contact import IPCContact
    from .obstacles import Obstacle
    from .potential import Potential
    from .pyvista_grid import PlotOptions
    from .supports import Where

__all__ = ["BodyBoundary", "MultiBody", "StackedSpace", "AnyModel"]


class BodyBoundary(NamedTuple):
    """A support of one body of a MultiBody: the body's name and the support as it gave it."""

    body: str
    where: Where


class _UnownedPattern:
    """The CSR pattern of a stacked Hessian: none (block-diagonal sums are plain CSR)."""

    @staticmethod
    def owns(A) -> bool:
        return False


class StackedSpace:
    """The DOF layout of several bodies, as much of a Discretization as the solvers read.

    Parameters
    ----------
    models : sequence of Model
        The bodies' models, in stacking order.
    """

    pattern = _UnownedPattern()

    def __init__(self, models):
        self.parts = tuple(m.space for m in models)
        sizes = [m.ndofs for m in models]
        self.dof_offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self.ndofs = int(self.dof_offsets[-1])
        orders = {s.order for s in self.parts}
        #: the common element order, or None for bodies of different orders
        self.order = orders.pop() if len(orders) == 1 else None
        X = np.concatenate([m.X for m in models])
        X.setflags(write=False)
        self.X = X
        self.vertex_dofs = np.concatenate(
            [s.vertex_dofs + off for s, off in zip(self.parts, self.dof_offsets)]
        )

    def rigid_body_modes(self) -> np.ndarray:
        """``(ndofs, 6 B)``: each body's six rigid modes on its own DOFs, zero elsewhere."""
        B = np.zeros((self.ndofs, 6 * len(self.parts)))
        for b, (s, a, e) in enumerate(zip(self.parts, self.dof_offsets[:-1], self.dof_offsets[1:])):
            B[a:e, 6 * b:6 * b + 6] = s.rigid_body_modes()
        return B


class _StackedBodyPotential:
    """The bodies' own energies as one Potential of the stacked DOFs (block-diagonal Hessian)."""

    def __init__(self, multi):
        self._multi = multi

    def energy(self, x):
        total = 0.0
        for m, xb in self._multi._split(x):
            e = m.body_potential.energy(xb)
            if not math.isfinite(e):
                return math.inf
            total += e
        return total

    def gradient(self, x):
        return np.concatenate([m.body_potential.gradient(xb) for m, xb in self._multi._split(x)])

    def hessian(self, x, project=False):
        return _block_diag([m.body_potential.hessian(xb, project=project) for m, xb in self._multi._split(x)])

    def linearize(self, x, project=False):
        parts = [m.body_potential.linearize(xb, project=project) for m, xb in self._multi._split(x)]
        return np.concatenate([g for g, _ in parts]), _block_diag([H for _, H in parts])

    def energy_roundoff(self):
        return float(sum(m.body_potential.energy_roundoff() for m in self._multi.models))

    def gradient_roundoff(self):
        return float(math.hypot(*[m.gradient_roundoff() for m in self._multi.models]))


class _OnBody:
    """One body's term (a load, an obstacle contact) as a Potential of the stacked DOFs."""

    def __init__(self, term, start: int, stop: int, ndofs: int):
        self.term, self.start, self.stop, self.ndofs = term, int(start), int(stop), int(ndofs)

    def __getattr__(self, name):  # the term's own attributes (kind, obstacle, ...)
        return getattr(self.term, name)

    def _embed(self, g):
        out = np.zeros(self.ndofs)
        out[self.start:self.stop] = g
        return out

    @property
    def force(self):
        """The term's nodal force (N) on the stacked DOFs (dead loads)."""
        return self._embed(self.term.force)

    def energy(self, x):
        return self.term.energy(x[self.start:self.stop])

    def gradient(self, x):
        return self._embed(self.term.gradient(x[self.start:self.stop]))

    def _embed_matrix(self, H):
        if H is None:
            return None
        H = sp.coo_matrix(H)
        return sp.csr_matrix((H.data, (H.row + self.start, H.col + self.start)), shape=(self.ndofs, self.ndofs))

    def hessian(self, x, project=False):
        return self._embed_matrix(self.term.hessian(x[self.start:self.stop], project=project))

    def linearize(self, x, project=False):
        g, H = self.term.linearize(x[self.start:self.stop], project=project)
        return self._embed(g), self._embed_matrix(H)


def _block_diag(blocks, sizes=None):
    """Block-diagonal CSR of per-body matrices; a None block is zero of its body's size."""
    if all(b is None for b in blocks):
        return None
    if sizes is not None:
        blocks = [sp.csr_matrix((n, n)) if b is None else b for b, n in zip(blocks, sizes)]
    return sp.block_diag(blocks, format="csr")


class MultiBody:
    """Several bodies in one model, their DOFs stacked body after body.

    Parameters
    ----------
    bodies : sequence of Body
        At least one :class:`fem_elastic.Body`, names unique.
    gravity : array_like or None
        Gravitational acceleration (m/s^2) on every body, e.g. ``(0, 0, -9.81)``.
    ground : obstacle, sequence of obstacles, or None
        Fixed obstacles (``fe.Ground(z=0.0)``, ...) every body meets.
    damping : Rayleigh or None
        Rayleigh damping of every body, ``-(alpha M_b + beta K_b) v_b`` per body.
    contact : object with ``bind(model)``, or None
        Contact between the bodies (and of each with itself), bound to the
        whole model on its stacked :meth:`collision_surface`, e.g.
        ``fe.IPCContact(dhat=1e-3)``.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> mat = fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3))
    >>> mesh = fe.beam_mesh(cells=(2, 1, 1))
    >>> model = fe.MultiBody([fe.Body(mesh, 1000.0, mat, name="a"),
    ...                       fe.Body(mesh, 1000.0, mat, name="b", translate=(0, 1, 0))],
    ...                      gravity=(0, 0, -9.81))
    >>> model.ndofs, model.names
    (72, ('a', 'b'))
    """

    def __init__(self, bodies: Sequence[Body], gravity: ArrayLike | None = None,
                 ground: Obstacle | Sequence[Obstacle] | None = None,
                 damping: Rayleigh | None = None,
                 contact: IPCContact | ImpulseContact | None = None) -> None:
        if isinstance(bodies, Body) or not isinstance(bodies, (list, tuple)):
            raise InvalidParameter(
                "bodies must be a list of fe.Body(...), e.g. [fe.Body(mesh_a, ..., name='a'), "
                f"fe.Body(mesh_b, ..., name='b')]; got {bodies!r}."
            )
        if not bodies:
            raise InvalidParameter(
                "MultiBody needs at least one body; got an empty list. Give [fe.Body(mesh, density, "
                "body, name=...), ...], or use fe.Model for a single body."
            )
        for i, b in enumerate(bodies):
            if not isinstance(b, Body):
                raise InvalidParameter(f"bodies[{i}] must be a fe.Body(...), got {type(b).__name__}.")
        names = [b.name for b in bodies]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise InvalidParameter(
                f"body names must be unique, but {dup} appear more than once; give each body "
                "its own name=..., e.g. 'ball' and 'block'."
            )
        self.bodies = tuple(bodies)
        self.names = tuple(names)
        models = []
        for b in bodies:
            try:
                models.append(Model(b.mesh, b.density, b.body, fixed=b.fixed, gravity=gravity,
                                    traction=b.traction, ground=ground, damping=damping,
                                    driven=b.driven, displacement=b.displacement))
            except InvalidParameter as err:
                raise type(err)(f"body {b.name!r}: {err}") from None
        self.models = tuple(models)
        self.space = StackedSpace(models)
        self.dof_offsets = self.space.dof_offsets
        nv = [m.mesh.p.shape[1] for m in models]
        self.vertex_offsets = np.concatenate([[0], np.cumsum(nv)]).astype(np.int64)
        self.mesh = MeshTet(
            np.concatenate([m.mesh.p for m in models], axis=1),
            np.concatenate([m.mesh.t + off for m, off in zip(models, self.vertex_offsets)], axis=1),
            sort_t=False, validate=False,
        )
        #: ``(n_tets,)`` int64: the body index of each tet of :attr:`mesh`
        self.body_of_tet = np.concatenate(
            [np.full(m.mesh.t.shape[1], b, dtype=np.int64) for b, m in enumerate(models)])
        self.body_of_tet.setflags(write=False)
        self.body = tuple(b.body for b in bodies)
        self.density = tuple(m.density for m in models)
        self.damping = models[0].damping
        self.obstacles = models[0].obstacles
        self.gravity_magnitude = models[0].gravity_magnitude
        self.body_potential = _StackedBodyPotential(self)
        o, n = self.dof_offsets, self.space.ndofs
        #: every body's loads and obstacle contacts, each a Potential of the stacked DOFs
        self.loads = tuple(_OnBody(t, o[b], o[b + 1], n) for b, m in enumerate(models) for t in m.loads)
        self.fixed_dofs = self._stack_dofs("fixed_dofs")
        self.prescribed_dofs = self._stack_dofs("prescribed_dofs")
        self.prescribed_values = np.concatenate([m.prescribed_values for m in models])
        self.held_dofs = self._stack_dofs("held_dofs")
        self.free = np.concatenate([m.free for m in models])
        self.driven = tuple(
            (motion, nodes_X, dofs + off)
            for m, off in zip(models, self.dof_offsets) for motion, nodes_X, dofs in m.driven
        )
        self._driven_components = [c for m in models for c in m._driven_components]
        #: (label, BodyBoundary, stacked DOFs) of every body's fixed and prescribed supports
        self.fixed_groups = tuple((f"{b.name}:{label}", BodyBoundary(b.name, where), dofs + off)
                                  for b, m, off in zip(bodies, models, self.dof_offsets)
                                  for label, where, dofs in m.fixed_groups)
        self.prescribed_groups = tuple((f"{b.name}:{label}", BodyBoundary(b.name, where), dofs + off)
                                       for b, m, off in zip(bodies, models, self.dof_offsets)
                                       for label, where, dofs in m.prescribed_groups)
        for arr in (self.free, self.prescribed_values):
            arr.setflags(write=False)
        self.contacts = tuple(_OnBody(t, o[b], o[b + 1], n) for b, m in enumerate(models) for t in m.contacts)
        self.potentials = (self.body_potential, *self.loads, *self.contacts)
        self.contact = bind_contact(self, contact)

    # layout -----------------------------------------------------------------------
    def _stack_dofs(self, name):
        out = np.concatenate([getattr(m, name) + off for m, off in zip(self.models, self.dof_offsets)])
        out = out.astype(np.int64)
        out.setflags(write=False)
        return out

    def _split(self, x):
        """(model, slice of x) per body."""
        o = self.dof_offsets
        return [(m, x[o[b]:o[b + 1]]) for b, m in enumerate(self.models)]

    def body_slice(self, which: int | str) -> slice:
        """The DOFs of one body (by index or name) in the stacked vector, a slice."""
        b = self.index(which)
        return slice(int(self.dof_offsets[b]), int(self.dof_offsets[b + 1]))

    def index(self, which: int | str) -> int:
        """The index of a body given by its index or its name."""
        if isinstance(which, str):
            if which not in self.names:
                raise InvalidParameter(f"no body named {which!r}; the bodies are {list(self.names)}.")
            return self.names.index(which)
        if isinstance(which, (int, np.integer)) and not isinstance(which, bool) and 0 <= which < len(self.models):
            return int(which)
        raise InvalidParameter(f"a body is a name in {list(self.names)} or an index 0..{len(self.models) - 1}; "
                               f"got {which!r}.")

    @property
    def ndofs(self) -> int:
        """Number of DOFs, all bodies together."""
        return self.space.ndofs

    @property
    def X(self) -> np.ndarray:
        """Reference positions of the DOFs, ``(ndofs,)`` (m), the placed bodies stacked."""
        return self.space.X

    def to_vertices(self, x: np.ndarray) -> np.ndarray:
        """Vertex values ``(n_vertices, 3)``, the bodies' vertices stacked (as :attr:`mesh`)."""
        return np.concatenate([m.to_vertices(xb) for m, xb in self._split(x)])

    def initial_velocity(self) -> np.ndarray:
        """``(ndofs,)`` (m/s): each body's initial velocity on its nodes.

        ``fe.simulate`` (and ``fe.State.rest(model, velocity=model.initial_velocity())``) start
        from it; fixed and driven DOFs follow their supports.
        """
        return np.concatenate([np.tile(b.velocity, m.ndofs // 3) for b, m in zip(self.bodies, self.models)])

    # mass and momenta ---------------------------------------------------------------
    @cached_property
    def mass_matrix(self) -> sp.csr_matrix:
        """Consistent mass matrix (kg), block diagonal."""
        return _block_diag([m.mass_matrix for m in self.models])

    @cached_property
    def lumped_mass(self) -> np.ndarray:
        """Lumped mass per DOF (kg), the bodies' stacked."""
        out = np.concatenate([m.lumped_mass for m in self.models])
        out.setflags(write=False)
        return out

    @cached_property
    def total_mass(self) -> float:
        """Mass of all bodies (kg)."""
        return float(sum(m.total_mass for m in self.models))

    @cached_property
    def rest_stiffness(self) -> sp.csr_matrix:
        """The bodies' stiffness K_0 at the reference configuration (N/m), block diagonal."""
        return _block_diag([m.rest_stiffness for m in self.models])

    def kinetic_energy(self, v: np.ndarray, mass: str = "lumped") -> float:
        """1/2 v^T M v (J), all bodies."""
        return float(sum(self.body_kinetic_energies(v, mass)))

    def body_kinetic_energies(self, v: np.ndarray, mass: str = "lumped") -> np.ndarray:
        """Each body's kinetic energy (J), ``(B,)``."""
        return np.array([m.kinetic_energy(vb, mass) for m, vb in self._split(v)])

    def linear_momentum(self, v: np.ndarray) -> np.ndarray:
        """Total linear momentum (kg m/s), ``(3,)``."""
        return self.body_linear_momenta(v).sum(axis=0)

    def body_linear_momenta(self, v: np.ndarray) -> np.ndarray:
        """Each body's linear momentum (kg m/s), ``(B, 3)``."""
        return np.array([m.linear_momentum(vb) for m, vb in self._split(v)])

    def angular_momentum(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Angular momentum about the origin (kg m^2/s), ``(3,)``, all bodies."""
        return self.body_angular_momenta(x, v).sum(axis=0)

    def body_angular_momenta(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Each body's angular momentum about the origin (kg m^2/s), ``(B, 3)``."""
        return np.array([m.angular_momentum(xb, vb) for (m, xb), (_, vb) in zip(self._split(x), self._split(v))])

    def body_energies(self, x: np.ndarray) -> np.ndarray:
        """Each body's total potential energy Pi_b (J), ``(B,)``, without the contact between bodies."""
        return np.array([m.energy(xb) for m, xb in self._split(x)])

    # dissipation ----------------------------------------------------------------------
    def damping_force(self, x: np.ndarray, v: np.ndarray,
                      mass: str = "lumped") -> np.ndarray | None:
        """The damping force (N), ``(ndofs,)``, or None when no body is damped."""
        parts = [m.damping_force(xb, vb, mass) for (m, xb), (_, vb) in zip(self._split(x), self._split(v))]
        if all(p is None for p in parts):
            return None
        return np.concatenate([np.zeros(m.ndofs) if p is None else p for m, p in zip(self.models, parts)])

    def damping_matrix(self, x: np.ndarray,
                       mass: str = "consistent") -> sp.csr_matrix | None:
        """C (N s/m), block diagonal, or None when no body is damped."""
        return _block_diag([m.damping_matrix(xb, mass) for m, xb in self._split(x)],
                           [m.ndofs for m in self.models])

    def damping_stiffness(self, x: np.ndarray) -> sp.csr_matrix:
        """The bodies' damping stiffness K(x) (N/m), block diagonal."""
        return _block_diag([m.damping_stiffness(xb) for m, xb in self._split(x)])

    @property
    def warped_stiffness(self) -> None:
        """None: stiffness warping takes one body (each body's is ``model.models[b].warped_stiffness``)."""
        return None

    # energy --------------------------------------------------------------------------
    def energy(self, x: np.ndarray, load_factor: float = 1.0) -> float:
        """Pi(x) (J): the bodies' energies and the contact between them; +inf if inadmissible."""
        total = 0.0
        for m, xb in self._split(x):
            e = m.energy(xb, load_factor)
            if not math.isfinite(e):
                return math.inf
            total += e
        if self.contact is not None and self.contact.kind == "potential":
            e = self.contact.energy(x)
            if not math.isfinite(e):
                return math.inf
            total += e
        return total

    def gradient(self, x: np.ndarray, load_factor: float = 1.0) -> np.ndarray:
        """dPi/dx (N), ``(ndofs,)``."""
        g = np.concatenate([m.gradient(xb, load_factor) for m, xb in self._split(x)])
        if self.contact is not None and self.contact.kind == "potential":
            g += self.contact.gradient(x)
        return g

    def linearize(self, x: np.ndarray, load_factor: float = 1.0, project: bool = True,
                  body: Potential | None = None) -> tuple[np.ndarray, sp.csr_matrix]:
        """Gradient (N) and Hessian (N/m, CSR, block diagonal plus the contact's) of Pi at x."""
        if body is not None:
            raise InvalidParameter(
                "a MultiBody has no single body energy to replace (stiffness warping takes one "
                "body); use fe.LinearizedImplicitEuler(warping=False) or fe.ImplicitEuler."
            )
        parts = [m.linearize(xb, load_factor, project) for m, xb in self._split(x)]
        g = np.concatenate([p[0] for p in parts])
        H = _block_diag([p[1] for p in parts], [m.ndofs for m in self.models])
        if self.contact is not None and self.contact.kind == "potential":
            gc, Hc = self.contact.linearize(x, project=project)
            g += gc
            if Hc is not None:
                H = Hc if H is None else H + Hc
        return g, H

    def external_force(self, load_factor: float = 1.0) -> np.ndarray:
        """The dead loads' nodal forces (N), ``(ndofs,)``."""
        return np.concatenate([m.external_force(load_factor) for m in self.models])

    def energy_roundoff(self) -> float:
        """Absolute round-off of Pi near the rest state (J): the bodies' summed."""
        return self.body_potential.energy_roundoff()

    def gradient_roundoff(self) -> float:
        """Round-off floor of ||dPi/dx|| (N): the bodies' in quadrature."""
        return self.body_potential.gradient_roundoff()

    @cached_property
    def rigid_body_modes(self) -> np.ndarray:
        """``(ndofs, 6 B)``: each body's rigid modes (read-only), the AMG near-null space."""
        B = self.space.rigid_body_modes()
        B.setflags(write=False)
        return B

    # contact, supports, driven boundaries ---------------------------------------------
    def collision_surface(self) -> CollisionSurface:
        """The bodies' boundary surfaces stacked (DOFs offset, body ids set), cached."""
        surface = self.__dict__.get("_collision_surface")
        if surface is None:
            from .collision_surface import CollisionSurface

            surface = CollisionSurface.stack([m.collision_surface() for m in self.models], self.dof_offsets[:-1])
            self.__dict__["_collision_surface"] = surface
        return surface

    def max_step(self, x: np.ndarray, dx: np.ndarray) -> float:
        """The largest collision-free fraction in (0, 1] of the step ``dx`` (1.0 without contact)."""
        if self.contact is None or self.contact.kind != "potential":
            return 1.0
        return float(self.contact.max_step(x, dx))

    @property
    def has_impulse_response(self) -> bool:
        """Whether :meth:`respond_contacts` can change x and v (a body's or the bodies' impulses)."""
        return (any(m.has_impulse_response for m in self.models)
                or (self.contact is not None and self.contact.kind == "impulse"))

    def respond_contacts(self, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each body's obstacle impulses, then the impulse contact between bodies; returns (x, v)."""
        o = self.dof_offsets
        x, v = x.copy(), v.copy()
        for b, m in enumerate(self.models):
            xb, vb = m.respond_contacts(x[o[b]:o[b + 1]], v[o[b]:o[b + 1]])
            x[o[b]:o[b + 1]], v[o[b]:o[b + 1]] = xb, vb
        if self.contact is not None and self.contact.kind == "impulse":
            x, v = self.contact.respond(x, v, self.lumped_mass[0::3])
        return x, v

    def constraints(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """DOFs held at time ``t`` (s), their positions (m) and velocities (m/s), all bodies."""
        parts = [m.constraints(t) for m in self.models]
        return (np.concatenate([d + off for (d, _, _), off in zip(parts, self.dof_offsets)]).astype(np.int64),
                np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts]))

    def free_at(self, t: float) -> np.ndarray:
        """``(ndofs,)`` bool: True for the DOFs that move freely at time ``t`` (s)."""
        return np.concatenate([m.free_at(t) for m in self.models])

    def driving(self, t: float) -> bool:
        """Whether a driven boundary of some body may still be moving at ``t`` (s)."""
        return any(m.driving(t) for m in self.models)

    def check_supported(self) -> None:
        """:class:`fe.UnderConstrained` naming the first body whose supports leave a rigid mode free."""
        for b, m in zip(self.bodies, self.models):
            try:
                m.check_supported()
            except UnderConstrained as err:
                raise UnderConstrained(f"body {b.name!r}: {err}") from None

    def boundary_nodes(self, where: BodyBoundary) -> np.ndarray:
        """Stacked scalar nodes of one body's boundary, given as ``BodyBoundary(body, where)``.

        A bare boundary name is ambiguous over several meshes: InvalidParameter.
        """
        if isinstance(where, BodyBoundary):
            b = self.index(where.body)
            return self.models[b].boundary_nodes(where.where) + int(self.dof_offsets[b]) // 3
        raise InvalidParameter(
            "boundary names belong to one body's mesh; give fe.physics.multibody.BodyBoundary(body "
            "name, where), or use model.models[b].boundary_nodes(where) "
            f"with b in 0..{len(self.models) - 1} (bodies {list(self.names)}) and offset by "
            "model.dof_offsets[b] // 3."
        )

    def _resolve_fixed(self, fixed, what: str = "fixed"):
        raise InvalidParameter(
            f"{what} supports belong to one body: give them to fe.Body(..., {what}=...), not to "
            "the MultiBody."
        )

    def to_pyvista(self, x: np.ndarray | None = None,
                   v: np.ndarray | None = None) -> pyvista.UnstructuredGrid:
        """The bodies at DOF positions ``x`` (default: at rest) as one pyvista ``UnstructuredGrid``.

        As :meth:`fem_elastic.Model.to_pyvista`, with the cell data ``body`` (each
        tet's body index); linear (P1) bodies only.
        """
        if self.space.order != 1:
            raise InvalidParameter(
                "to_pyvista of a fe.MultiBody takes linear bodies only (order=1); draw a "
                "quadratic body from its own model, model.models[b].to_pyvista(x[model.body_slice(b)])."
            )
        from .pyvista_grid import body_grid

        return body_grid(self, x, v)

    def plot(self, x: np.ndarray | None = None,
             **kwargs: Unpack[PlotOptions]) -> pyvista.Plotter:
        """Draw the bodies (at ``x``, default at rest) with pyvista; returns the plotter."""
        from .pyvista_grid import plot_grid

        return plot_grid(self.to_pyvista(x), **kwargs)

    def _rows(self):
        """(label, value) rows: the whole, then each body's model rows under its name."""
        from .result_view import fmt, model_rows

        rows = [("bodies", ", ".join(self.names)), ("DOFs", fmt(int(self.ndofs))),
                ("mass", fmt(float(self.total_mass), "kg")),
                ("contact", type(self.contact).__name__ if self.contact is not None else "none")]
        for name, m in zip(self.names, self.models):
            rows += [(f"{name}: {label}", value) for label, value in model_rows(m)]
        return rows

    def __repr__(self) -> str:
        from .result_view import text_table

        return text_table("MultiBody", self._rows())

    def _repr_html_(self) -> str:
        from .result_view import html_table

        return html_table("MultiBody", self._rows())


#: What solvers, integrators and output take as a model: one body's Model or a MultiBody.
AnyModel: TypeAlias = Union[Model, MultiBody]
