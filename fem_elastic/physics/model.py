"""The Model: everything about a simulated body that does not change in time.

A model holds the mesh, the finite element space, the body's energy, the
loads (only those the user asked for), the fixed DOFs and the mass. It is
immutable; solvers and integrators read it and return new values.

The total potential energy is the sum of the terms,

    Pi(x) = E_body(x) + s * sum_loads E_load(x) + sum_obstacles E_contact(x),

with ``s`` a load factor in [0, 1] that the static solver's load stepping
uses (1 is the full load). Only the terms a model declares are built: no
gravity term without gravity, no contact term without an obstacle.

Dissipation is not an energy: Rayleigh damping (and a body's own damping,
such as the mass-spring dashpots) enters as a force ``-C v`` that the
integrators apply. Driven boundaries are time-dependent Dirichlet
conditions: :meth:`Model.constraints` gives the held DOFs and their
prescribed positions and velocities at any time.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from ..discretization.space import Discretization
from ..errors import InvalidParameter, UnderConstrained
from .loads import gravity_load, traction_load
from .supports import describe_rigid_modes, nodes_of, resolve_displacement, resolve_fixed
from ..discretization.mass import consistent_mass, lumped_mass
from ..geometry.mesh import validate_mesh
from ..resources import check_memory, model_memory

if TYPE_CHECKING:  # for annotations only (pyvista is optional; the others import this module)
    from typing import Unpack  # Python >= 3.11

    import pyvista
    from skfem import MeshTet

    from .collision_surface import CollisionSurface
    from .damping import Rayleigh
    from .driven import Motion
    from .elastic_body import ElasticBody
    from .impulse_contact import ImpulseContact
    from .ipc_contact import IPCContact
    from .obstacles import Obstacle
    from .potential import Potential
    from .pyvista_grid import PlotOptions
    from .springs import MassSpring
    from .supports import DisplacementSpec, FixedSpec, Where

__all__ = ["Model"]

log = logging.getLogger(__name__)


def bind_contact(model, contact):
    """Bind ``contact=`` to ``model`` (a Model or a MultiBody); the bound object, or None.

    A bound potential (``kind == "potential"``, e.g. IPC) joins ``model.contacts`` and
    ``model.potentials``; an impulse response (``kind == "impulse"``) is applied by
    ``model.respond_contacts``. Anything else is an InvalidParameter.
    """
    if contact is None:
        return None
    if isinstance(contact, type) or not hasattr(contact, "bind"):
        raise InvalidParameter(
            "contact must be an object with bind(model), e.g. fe.IPCContact(dhat=1e-3), or "
            f"None; got {contact!r}."
        )
    bound = contact.bind(model)
    kind = getattr(bound, "kind", None)
    if kind == "potential":
        model.contacts = (*model.contacts, bound)
        model.potentials = (*model.potentials, bound)
    elif kind != "impulse":
        raise InvalidParameter(
            f"contact {contact!r} bound to an object of kind {kind!r}; it must be "
            "'potential' (a barrier energy such as fe.IPCContact) or 'impulse'."
        )
    return bound


class Model:
    """A body on a tet mesh with its material, loads and supports.

    Parameters
    ----------
    mesh : skfem.MeshTet
        Reference configuration (m), e.g. ``fe.beam_mesh()``.
    density : float
        Mass density (kg/m^3), > 0.
    body : ElasticBody
        The body's energy, e.g. ``fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.45), order=2)``.
    fixed : str, sequence of str, array of int or bool, mapping, or None
        DOFs held at their reference position: a boundary name of the mesh
        (``"left"``), several names, vertex indices, or a boolean mask over
        vertices, all three components held; or a mapping from any of these
        to the components held, ``"x"``, ``"yz"``, ``"xyz"`` or a bool triple:
        ``{"left": "x", "bottom": "z"}`` (rollers), ``{"left": "xyz", "front":
        "z", "back": "z"}`` (plane strain). A mask or an index array (not
        hashable) goes in a list of ``(where, components)`` pairs instead. With
        P2 tets, the edge nodes of a fixed boundary (or of an edge whose two
        vertices are fixed) are fixed too.
    displacement : mapping or None
        Prescribed displacements (m): ``{where: (ux, uy, uz)}`` with None for
        a free component, e.g. ``{"right": (0.01, None, None)}``, or ``{where:
        function}`` with ``function(X) -> (n, 3)`` the displacements of the
        reference node positions ``X`` (n, 3) (NaN: free). A static solve ramps
        them with the load factor; dynamics holds them from the first instant.
        A component both fixed and prescribed is an error naming both.
    gravity : array_like or None
        Gravitational acceleration (m/s^2), e.g. ``(0, 0, -9.81)``. None
        builds no gravity term at all.
    traction : dict or None
        ``{boundary name: traction vector (Pa)}``, dead loads per unit
        reference area.
    ground : obstacle, sequence of obstacles, or None
        ``fe.Ground(z=0.0)``, ``fe.Sphere(...)``, ``fe.Box(...)``: contact as a
        penalty or barrier potential, or an impulse response applied after
        each step. None builds no contact term.
    damping : Rayleigh or None
        ``fe.Rayleigh(alpha, beta)``: damping force ``-(alpha M + beta K_0) v``.
    driven : dict or None
        ``{boundary name: motion}``, e.g. ``{"right": fe.Twist(2 * np.pi, duration=1.0)}``:
        the boundary's DOFs follow the motion until its release time. A
        static solve holds them at the reference position.
    contact : object with ``bind(model)``, or None
        Contact between bodies and of a body with itself, on the model's
        :meth:`collision_surface`, e.g. ``fe.IPCContact(dhat=1e-3)``. Its
        bound object (``model.contact``) is either a Potential (``kind ==
        "potential"``: added to the energy, and its ``max_step`` bounds every
        Newton step, see :meth:`max_step`) or an impulse response (``kind ==
        "impulse"``: applied after each explicit step). None: no such contact.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(4, 1, 1)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)),
    ...                  fixed="left", gravity=(0, 0, -9.81))
    >>> model.ndofs, len(model.loads)
    (60, 1)
    """

    def __init__(
        self, mesh: MeshTet, density: float, body: ElasticBody | MassSpring,
        fixed: FixedSpec | None = None, gravity: ArrayLike | None = None,
        traction: Mapping[str, ArrayLike] | None = None,
        ground: Obstacle | Sequence[Obstacle] | None = None, damping: Rayleigh | None = None,
        driven: Mapping[str, Motion] | None = None, displacement: DisplacementSpec | None = None,
        contact: IPCContact | ImpulseContact | None = None,
    ) -> None:
        validate_mesh(mesh)
        # memory, from the counts alone: a model that cannot fit says so now, not after minutes;
        # its own share only (the tangent and the solver are checked at the first linearize)
        check_memory(model_memory(mesh.t.shape[1], mesh.p.shape[1], getattr(body, "order", 1), tangent=False),
                     f"this model ({mesh.t.shape[1]} tets, order {getattr(body, 'order', 1)})")
        if isinstance(density, bool) or not isinstance(density, (int, float, np.number)):
            raise InvalidParameter(f"density must be a number (kg/m^3), got {density!r}.")
        if not math.isfinite(density) or density <= 0:
            raise InvalidParameter(
                f"density must be finite and > 0 kg/m^3, got {density!r} "
                "(e.g. 1000.0 for rubber-like solids, 7850.0 for steel)."
            )
        if not hasattr(body, "build"):
            raise InvalidParameter(
                f"body must be e.g. fe.ElasticBody(fe.NeoHookean(E=..., nu=...)), got {body!r}."
            )
        self.mesh = mesh
        self.density = float(density)
        self.body = body
        self.space = Discretization(mesh, getattr(body, "order", 1))
        self.body_potential = body.build(self.space)
        loads = []
        if gravity is not None:
            loads.append(gravity_load(self.space, self.density, gravity))
        if traction is not None and not isinstance(traction, Mapping):
            raise InvalidParameter(
                "traction must be a dict {boundary name: traction vector (Pa)}, e.g. "
                f"traction={{'right': (0.0, 0.0, -1e3)}}; got {traction!r}."
            )
        for name, t in (traction or {}).items():
            loads.append(traction_load(self.space, name, t))
        self.loads = tuple(loads)
        self.damping = self._check_damping(damping)
        self.obstacles = self._check_obstacles(ground)
        self.gravity_magnitude = 0.0 if gravity is None else float(np.linalg.norm(gravity))
        contacts = []
        for obstacle in self.obstacles:
            term = obstacle.build(self.space, self.lumped_mass[0::3], self.gravity_magnitude or None)
            if term is not None:
                contacts.append(term)
        self.contacts = tuple(contacts)
        self.potentials = (self.body_potential, *self.loads, *self.contacts)
        self.fixed_dofs, self.fixed_groups = resolve_fixed(self.space, fixed)
        self.prescribed_dofs, self.prescribed_values, self.prescribed_groups = resolve_displacement(
            self.space, displacement, self.fixed_groups
        )
        #: DOFs held by the static supports (fixed and prescribed), sorted
        self.held_dofs = np.union1d(self.fixed_dofs, self.prescribed_dofs).astype(np.int64)
        self.driven = self._resolve_driven(driven)
        free = np.ones(self.ndofs, dtype=bool)
        free[self.held_dofs] = False
        for (_, _, dofs), comp in zip(self.driven, self._driven_components):
            free[dofs[comp]] = False
        self.free = free
        # a Model is immutable: its arrays are read-only views for everyone
        for arr in (self.free, self.fixed_dofs, self.prescribed_dofs, self.prescribed_values,
                    self.held_dofs):
            arr.setflags(write=False)
        #: the bound ``contact=`` object (IPC potential or impulse response), or None
        self.contact = bind_contact(self, contact)

    # contact between bodies (the ``contact=`` argument) --------------------------------------
    def collision_surface(self) -> CollisionSurface:
        """The boundary triangles of the mesh on the model's DOFs (cached), for contact.

        See :func:`fem_elastic.physics.collision_surface.collision_surface`:
        outward triangles, P2 meshes by their vertices; :class:`fe.InvalidMesh`
        for a mesh with no surface.
        """
        surface = self.__dict__.get("_collision_surface")
        if surface is None:
            from .collision_surface import collision_surface

            surface = self.__dict__["_collision_surface"] = collision_surface(self)
        return surface

    def max_step(self, x: np.ndarray, dx: np.ndarray) -> float:
        """The largest fraction in (0, 1] of the step ``dx`` from ``x`` free of collisions.

        Continuous collision detection of a potential contact (IPC); 1.0 for
        a model without one. Newton's line search starts at this fraction.
        """
        bound = self.contact
        if bound is None or getattr(bound, "kind", None) != "potential":
            return 1.0
        return float(bound.max_step(x, dx))

    # sizes and maps -----------------------------------------------------------
    @property
    def ndofs(self) -> int:
        """Number of DOFs (3 per node; nodes include P2 edge nodes)."""
        return self.space.ndofs

    @property
    def X(self) -> np.ndarray:
        """Reference positions of the DOFs, ``(ndofs,)`` (m)."""
        return self.space.X

    def to_vertices(self, x: np.ndarray) -> np.ndarray:
        """Vertex values ``(n_vertices, 3)`` of a flat DOF vector."""
        return self.space.to_vertices(x)

    # looking at it (fem_elastic.physics.result_view, pyvista_grid) -----------------------
    def __repr__(self) -> str:
        from .result_view import model_rows, text_table

        return text_table("Model", model_rows(self))

    def _repr_html_(self) -> str:
        from .result_view import html_table, model_rows

        return html_table("Model", model_rows(self))

    def to_pyvista(self, x: np.ndarray | None = None,
                   v: np.ndarray | None = None) -> pyvista.UnstructuredGrid:
        """The body at DOF positions ``x`` (default: at rest) as a pyvista ``UnstructuredGrid``.

        Reference points, point data ``displacement`` (m) and ``velocity`` (m/s),
        cell data ``von_mises`` (Pa) and ``energy_density`` (J/m^3); P2 bodies as
        quadratic tets (VTK type 24). See :func:`fem_elastic.physics.pyvista_grid.body_grid`.
        """
        from .pyvista_grid import body_grid

        return body_grid(self, x, v)

    def plot(self, x: np.ndarray | None = None,
             **kwargs: Unpack[PlotOptions]) -> pyvista.Plotter:
        """Draw the body (at ``x``, default at rest) with pyvista; returns the plotter.

        Keywords go to :func:`fem_elastic.physics.pyvista_grid.plot_grid`
        (``off_screen=True``, ``screenshot=path``, ``magnification``, ...).
        """
        from .pyvista_grid import plot_grid

        return plot_grid(self.to_pyvista(x), **kwargs)

    @cached_property
    def mass_matrix(self) -> sp.csr_matrix:
        """Consistent mass matrix (kg), built on first use."""
        return consistent_mass(self.space, self.density)

    @cached_property
    def lumped_mass(self) -> np.ndarray:
        """Lumped mass per DOF (kg), built on first use."""
        return lumped_mass(self.space, self.density)

    # energy: every term through the Potential protocol ----------------------------
    def _scaled_terms(self, load_factor: float, body=None):
        """(potential, factor) pairs: the body and contacts at 1, each load at the load factor."""
        return (
            [(self.body_potential if body is None else body, 1.0)]
            + [(load, load_factor) for load in self.loads]
            + [(c, 1.0) for c in self.contacts]
        )

    @cached_property
    def total_mass(self) -> float:
        """Mass of the body (kg)."""
        return float(self.lumped_mass[0::3].sum())

    @cached_property
    def rest_stiffness(self) -> sp.csr_matrix:
        """Body stiffness K_0 at the reference configuration (N/m), on first use."""
        return self.body_potential.hessian(self.X, project=False)

    def kinetic_energy(self, v: np.ndarray, mass: str = "lumped") -> float:
        """1/2 v^T M v (J) with the lumped or consistent mass."""
        if mass == "lumped":  # einsum, not a BLAS dot: no thread start-up for a reduction
            return 0.5 * float(np.einsum("i,i,i->", self.lumped_mass, v, v))
        return 0.5 * float(np.einsum("i,i->", v, self.mass_matrix @ v))

    def linear_momentum(self, v: np.ndarray) -> np.ndarray:
        """Total linear momentum (kg m/s), ``(3,)``; the same for lumped and consistent mass."""
        return (self.lumped_mass * v).reshape(-1, 3).sum(axis=0)

    def angular_momentum(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Angular momentum about the origin (kg m^2/s), ``(3,)``, with the lumped mass."""
        p = (self.lumped_mass * v).reshape(-1, 3)
        return np.cross(x.reshape(-1, 3), p).sum(axis=0)

    # dissipation ----------------------------------------------------------------
    def damping_force(self, x: np.ndarray, v: np.ndarray, mass: str = "lumped") -> np.ndarray | None:
        """The damping force (N), ``(ndofs,)``, or None when the model has no damping.

        Rayleigh ``-(alpha M + beta K(x)) v`` plus the body's own dashpots
        (a mass-spring body's ``k_d``), if any. ``K(x)`` is the corotated rest
        stiffness of a finite element body (see :meth:`damping_stiffness`).
        """
        f = None
        if self.damping is not None and (self.damping.alpha or self.damping.beta):
            f = np.zeros(self.ndofs)
            if self.damping.alpha:
                mv = self.lumped_mass * v if mass == "lumped" else self.mass_matrix @ v
                f -= self.damping.alpha * mv
            if self.damping.beta:
                warped = self.warped_stiffness
                Kv = warped.apply(x, v) if warped is not None else self.damping_stiffness(x) @ v
                f -= self.damping.beta * Kv
        body_damping = getattr(self.body_potential, "damping_force", None)
        if body_damping is not None:
            fb = body_damping(x, v)
            if fb is not None and np.any(fb):
                f = fb.copy() if f is None else f + fb
        return f

    def damping_matrix(self, x: np.ndarray, mass: str = "consistent") -> sp.csr_matrix | None:
        """C (N s/m) with damping force ``-C v``, or None when the model has no damping."""
        C = None
        if self.damping is not None and (self.damping.alpha or self.damping.beta):
            M = sp.diags(self.lumped_mass) if mass == "lumped" else self.mass_matrix
            C = self.damping.alpha * M
            if self.damping.beta:
                C = C + self.damping.beta * self.damping_stiffness(x)
        body_matrix = getattr(self.body_potential, "damping_matrix", None)
        if body_matrix is not None:
            Cb = body_matrix(x)
            if Cb is not None:
                C = Cb if C is None else C + Cb
        return None if C is None else sp.csr_matrix(C)

    def damping_stiffness(self, x: np.ndarray) -> sp.csr_matrix:
        """The stiffness K(x) of stiffness-proportional damping (N/m), CSR.

        A finite element body uses its linear-elastic rest stiffness rotated
        element by element to the current configuration, ``sum_e R_e K_e
        R_e^T`` (stiffness warping, :class:`fem_elastic.WarpedStiffness`): it is
        positive semi-definite, so the damping only dissipates, and it
        annihilates rigid motion at any orientation, so a spinning or
        tumbling body is not braked (the plain rest stiffness K_0 would
        brake it). Other bodies use their PSD-projected Hessian at x.
        """
        warped = self.warped_stiffness
        if warped is not None:
            return warped.hessian(x)
        return self.body_potential.hessian(x, project=True)

    @cached_property
    def warped_stiffness(self):
        """The body's linear-elastic element stiffness, rotated per element (stiffness warping).

        A :class:`fem_elastic.WarpedStiffness` of a finite element body, built
        on first use and shared by stiffness-proportional damping and
        :class:`fe.LinearizedImplicitEuler`; None for a body without a
        material (springs).
        """
        material = getattr(self.body_potential, "material", None)
        if material is None or not hasattr(material, "mu"):
            return None
        from .stiffness_warping import WarpedStiffness

        return WarpedStiffness(self.space, material)

    # contact and driven boundaries ---------------------------------------------------
    @property
    def has_impulse_response(self) -> bool:
        """Whether :meth:`respond_contacts` can change x and v (an impulse obstacle or ``contact=``)."""
        return (any(getattr(o, "method", None) == "impulse" for o in self.obstacles)
                or (self.contact is not None and self.contact.kind == "impulse"))

    def respond_contacts(self, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Apply the impulse responses: obstacles with ``method="impulse"``, then an
        impulse ``contact=`` (``fe.ImpulseContact``, between bodies and self-contact); (x, v)."""
        for obstacle in self.obstacles:
            if getattr(obstacle, "method", None) == "impulse":
                x, v = obstacle.respond(x, v, self.lumped_mass[0::3])
        if self.contact is not None and self.contact.kind == "impulse":  # kind checked at binding
            x, v = self.contact.respond(x, v, self.lumped_mass[0::3])
        return x, v

    def constraints(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """DOFs held at time ``t`` (s), their positions (m) and velocities (m/s).

        Fixed DOFs sit at the reference position at rest, prescribed ones at
        their prescribed displacement, at rest; driven ones follow their
        motion until its release time.
        """
        dofs = [self.fixed_dofs, self.prescribed_dofs]
        xs = [self.X[self.fixed_dofs], self.X[self.prescribed_dofs] + self.prescribed_values]
        vs = [np.zeros(self.fixed_dofs.size), np.zeros(self.prescribed_dofs.size)]
        for (motion, nodes_X, ndofs), comp in zip(self.driven, self._driven_components):
            if motion.active(t):
                c = comp.ravel()
                v = np.broadcast_to(np.asarray(motion.velocity(nodes_X, t), dtype=float), nodes_X.shape)
                dofs.append(ndofs.ravel()[c])
                xs.append((nodes_X + motion.displacement(nodes_X, t)).ravel()[c])
                vs.append(v.ravel()[c])
        return np.concatenate(dofs), np.concatenate(xs), np.concatenate(vs)

    def free_at(self, t: float) -> np.ndarray:
        """``(ndofs,)`` bool: True for the DOFs that move freely at time ``t`` (s)."""
        free = np.ones(self.ndofs, dtype=bool)
        free[self.constraints(t)[0]] = False
        return free

    def driving(self, t: float) -> bool:
        """Whether a driven boundary may still be moving (an energy source) at ``t`` (s)."""
        return any(motion.moving(t) for motion, _, _ in self.driven)

    def _check_damping(self, damping):
        if damping is None:
            return None
        from .damping import Rayleigh

        if not isinstance(damping, Rayleigh):
            raise InvalidParameter(
                f"damping must be fe.Rayleigh(alpha, beta) (an instance) or None, got {damping!r}."
            )
        return damping

    @staticmethod
    def _check_obstacles(ground):
        if ground is None:
            return ()
        obstacles = tuple(ground) if isinstance(ground, (list, tuple)) else (ground,)
        for ob in obstacles:
            if isinstance(ob, type) or not (hasattr(ob, "build") and hasattr(ob, "respond")):
                raise InvalidParameter(
                    f"ground must be an obstacle such as fe.Ground(z=0.0), fe.Sphere(...) or "
                    f"fe.Box(...), or a list of them; got {ob!r}."
                )
        return obstacles

    def _resolve_driven(self, driven):
        from .driven import Motion

        self._driven_components = []
        if driven is None:
            return ()
        if not isinstance(driven, dict):
            raise InvalidParameter(
                "driven must be a dict {boundary name: motion}, e.g. "
                f"{{'right': fe.Twist(6.283, duration=1.0)}}; got {driven!r}."
            )
        out, names = [], []
        held = self.held_dofs
        for name, motion in driven.items():
            if not isinstance(name, str):
                raise InvalidParameter(f"driven keys must be boundary names (str), got {name!r}.")
            if not isinstance(motion, Motion):
                raise InvalidParameter(
                    f"driven[{name!r}] must be a motion instance such as fe.Twist(angle, duration), "
                    f"fe.Translate(offset, duration) or fe.Prescribed(function); got {motion!r}."
                )
            dofs = self._resolve_fixed(name, what="driven").reshape(-1, 3)
            # a node that is both fixed (or prescribed) and driven stays fixed (e.g. the edge
            # a fixed face shares with a driven one)
            # (a node held in some components only is driven in the others)
            free_comp = ~np.isin(dofs, held)
            keep = free_comp.any(axis=1)
            if not keep.any():  # a boundary both fixed and driven: the motion would move nothing
                raise InvalidParameter(
                    f"driven boundary {name!r} is also fixed (or prescribed) in every component of "
                    "every node, so its motion would move nothing: a boundary cannot be both held "
                    f"and driven. Remove {name!r} from fixed (or displacement), or from driven."
                )
            if not free_comp.all():
                log.info("driven boundary %r: %d node(s) are also fixed and stay fixed", name,
                         int((~free_comp).any(axis=1).sum()))
            dofs = dofs[keep]
            for (_, _, other), other_name in zip(out, names):  # two motions for one vertex
                shared = np.intersect1d(dofs[:, 0], other[:, 0])
                if shared.size:
                    raise InvalidParameter(
                        f"driven boundaries {other_name!r} and {name!r} share {shared.size} node(s) "
                        f"(e.g. node {shared[0] // 3} at {np.round(self.X[shared[0]:shared[0] + 3], 6).tolist()} m), "
                        "which would follow two motions at once. Drive the union with one motion, "
                        "fix the shared edge, or drive boundaries that do not touch."
                    )
            names.append(name)
            self._driven_components.append(free_comp[keep])
            out.append((motion, self.X[dofs], dofs))
        return tuple(out)

    def external_force(self, load_factor: float = 1.0) -> np.ndarray:
        """Sum of the dead loads' nodal forces (N), ``(ndofs,)``."""
        f = np.zeros(self.ndofs)
        for load in self.loads:
            f += load.force
        return load_factor * f

    def energy(self, x: np.ndarray, load_factor: float = 1.0) -> float:
        """Total potential energy Pi(x) (J); +inf where x is inadmissible."""
        total = 0.0
        for term, c in self._scaled_terms(load_factor):
            e = term.energy(x)
            if not math.isfinite(e):
                return math.inf
            total += c * e
        return total

    def energy_roundoff(self) -> float:
        """Absolute round-off of Pi near the rest state (J).

        Energy differences below this carry no information (see
        ``ElasticPotential.energy_roundoff``); the dead loads are exact linear
        functions and add only ``eps |Pi|``, which Newton adds itself.
        """
        return self.body_potential.energy_roundoff()

    def gradient_roundoff(self) -> float:
        """Round-off floor of ||dPi/dx|| (N): the body's (``ElasticPotential.gradient_roundoff``)."""
        return self._gradient_roundoff

    @cached_property
    def _gradient_roundoff(self) -> float:
        return self.body_potential.gradient_roundoff()

    @cached_property
    def rigid_body_modes(self) -> np.ndarray:
        """``(ndofs, 6)`` rigid translations and rotations (read-only), the AMG near-null space."""
        B = self.space.rigid_body_modes()
        B.setflags(write=False)
        return B

    def gradient(self, x: np.ndarray, load_factor: float = 1.0) -> np.ndarray:
        """dPi/dx (N), ``(ndofs,)``; the force on the DOFs is its negative."""
        g = np.zeros(self.ndofs)
        for term, c in self._scaled_terms(load_factor):
            g += c * term.gradient(x)
        return g

    @property
    def quadratic(self) -> bool:
        """Whether Pi is quadratic in x (a linear elastic body under dead loads, no contact):
        its Hessian is then the same matrix at every state."""
        return all(p.quadratic for p in self.potentials)

    def linearize(self, x: np.ndarray, load_factor: float = 1.0, project: bool = True,
                  body: Potential | None = None) -> tuple[np.ndarray, sp.csr_matrix]:
        """Gradient (N) and Hessian (N/m, CSR) of Pi at x.

        ``project=True`` returns the per-point PSD projection of the tangent,
        which makes Newton's step a descent direction. Terms whose Hessian is
        zero (dead loads) return None and add nothing. ``body``, a Potential,
        stands in for the body's own (e.g. ``model.warped_stiffness``).

        The first call checks that the assembled tangent fits in memory (see
        :meth:`check_tangent_memory`; the linear solver's share is checked where a solve
        follows: static solves, implicit integrators, modal analysis).
        """
        self.check_tangent_memory("none")
        g = np.zeros(self.ndofs)
        H = None
        for term, c in self._scaled_terms(load_factor, body):
            gt, Ht = term.linearize(x, project=project)
            g += c * gt
            if Ht is not None:
                Ht = Ht if c == 1.0 else c * Ht  # keep the body's matrix (and its pattern) as is
                H = Ht if H is None else H + Ht
        return g, H

    def check_tangent_memory(self, solver: str = "auto") -> None:
        """:class:`fe.ResourceLimit` unless the tangent (and ``solver``'s share) fit in memory.

        The model's own share is checked when it is built; this checks the assembled
        tangent on top of it, and with ``solver`` ``"auto"``, ``"direct"`` or
        ``"iterative"`` the linear solver's share (:func:`fem_elastic.resources.model_memory`),
        ``"none"`` for none. Each kind is checked once per model (a solver's check
        covers the tangent alone).
        """
        done = self.__dict__.setdefault("_memory_checked", set())
        if solver in done or (solver == "none" and done):
            return
        nt = self.mesh.t.shape[1]
        what = f"the tangent of this model ({nt} tets, order {self.space.order})"
        if solver != "none":
            what += " with its linear solver"
        kernels = getattr(self.body_potential, "_fused", None)  # the fused path: registered materials only
        fused = kernels is not None and kernels() is not None
        check_memory(model_memory(nt, self.mesh.p.shape[1], self.space.order, solver, fused=fused), what)
        done.add(solver)

    # supports -----------------------------------------------------------------
    def _resolve_fixed(self, fixed, what: str = "fixed") -> np.ndarray:
        """Flat, sorted DOFs of a support given as ``fixed`` accepts it (see :mod:`.supports`)."""
        return resolve_fixed(self.space, fixed, what)[0]

    def boundary_nodes(self, where: Where) -> np.ndarray:
        """Scalar nodes (vertices and P2 edge nodes) of a boundary name, names, indices or mask."""
        return nodes_of(self.space, where, "boundary")

    def _check_pieces_reached(self, held: np.ndarray) -> None:
        """:class:`UnderConstrained` if a connected piece of the mesh holds no fixed or driven DOF.

        Not with contact (obstacles or ``contact=``): a piece may then rest on another, or on
        the ground, and be held by the contact force.
        """
        from scipy.sparse.csgraph import connected_components

        if self.contacts or getattr(self, "contact", None) is not None:
            return

        t = np.asarray(self.mesh.t)
        nv = self.mesh.p.shape[1]
        rows = np.repeat(t[:1], t.shape[0] - 1, axis=0).ravel()
        graph = sp.coo_matrix((np.ones(rows.size), (rows, t[1:].ravel())), shape=(nv, nv))
        n, label = connected_components(graph, directed=False)
        if n == 1:
            return
        is_held = np.zeros(self.ndofs, dtype=bool)
        is_held[held] = True
        piece = label[t[0]]  # of each element (its vertices share one label)
        reached = np.zeros(n, dtype=bool)
        reached[piece[is_held[self.space.element_dofs].any(axis=0)]] = True
        P = self.mesh.p
        if reached.all():  # each piece must hold its own six rigid modes
            dof_piece = np.empty(self.ndofs, dtype=np.int64)
            dof_piece[self.space.element_dofs] = piece[None, :]
            B = self.space.rigid_body_modes()
            B[:, 3:] /= np.ptp(self.X.reshape(-1, 3), axis=0).max()  # rotations in units of length
            for c in range(n):
                h = held[dof_piece[held] == c]
                s = np.linalg.svd(B[h], compute_uv=False) if h.size >= 6 else np.zeros(1)
                if int(np.sum(s > 1e-8 * s[0])) < 6:  # relative to the largest: round-off level
                    pts = P[:, label == c]
                    lo, hi = pts.min(axis=1), pts.max(axis=1)
                    raise UnderConstrained(
                        f"the mesh has {n} separate pieces, and the one of {pts.shape[1]} vertices in "
                        f"[{lo[0]:.4g}, {hi[0]:.4g}] x [{lo[1]:.4g}, {hi[1]:.4g}] x [{lo[2]:.4g}, "
                        f"{hi[2]:.4g}] m is held at too few DOFs to stop it moving as a rigid body "
                        f"({', '.join(describe_rigid_modes(self.X, h))}). Fix a face of that piece, or "
                        "connect the pieces (merge coincident vertices where they touch)."
                    )
            return
        lines = []
        for c in np.flatnonzero(~reached)[:3]:
            pts = P[:, label == c]
            lo, hi = pts.min(axis=1), pts.max(axis=1)
            lines.append(f"{pts.shape[1]} vertices in [{lo[0]:.4g}, {hi[0]:.4g}] x [{lo[1]:.4g}, "
                         f"{hi[1]:.4g}] x [{lo[2]:.4g}, {hi[2]:.4g}] m")
        more = f" (and {int((~reached).sum()) - 3} more)" if (~reached).sum() > 3 else ""
        raise UnderConstrained(
            f"the mesh has {n} separate pieces, {int((~reached).sum())} of which no support reaches (no "
            f"fixed or driven DOF): {'; '.join(lines)}{more}. Such a piece is free to move as a rigid body, so a static "
            "problem has no unique solution. Fix a boundary on each piece, connect the pieces (merge "
            "coincident vertices where they touch), or remove the loose piece from the mesh."
        )

    def check_supported(self) -> None:
        """Raise :class:`UnderConstrained` if the fixed DOFs leave rigid-body motion free.

        The six rigid-body modes restricted to the fixed DOFs must have rank
        6; otherwise some translation or rotation costs no energy and a
        static problem has no unique solution.
        """
        B = self.space.rigid_body_modes()
        size = np.ptp(self.X.reshape(-1, 3), axis=0).max()
        B[:, 3:] /= size  # rotations in the same units as translations
        held = np.flatnonzero(~self.free)
        if held.size == 0:
            raise UnderConstrained(
                "the model fixes nothing, so it can translate and rotate freely and a static "
                "problem has no unique solution. Fix a boundary, e.g. fe.Model(..., fixed='left'), "
                "or vertex indices, or simulate the dynamics instead."
            )
        self._check_pieces_reached(held)
        # svd returns min(n_fixed, 6) values: count the rank, not the small values
        s = np.linalg.svd(B[held], compute_uv=False)
        free_modes = 6 - int(np.sum(s > 1e-8 * s[0]))  # relative to the largest: round-off level
        if free_modes:
            names = describe_rigid_modes(self.X, held)
            raise UnderConstrained(
                f"the fixed DOFs leave {free_modes} rigid-body mode(s) free: "
                f"{'; '.join(names)}. A static problem then has no unique solution (fixing "
                "vertices on one line leaves the rotation about that line; rollers on one face "
                "leave the sliding along it). Fix a whole face (fixed='left') or at least three "
                "vertices that are not on one line, or add component-wise supports that hold "
                "the motions named, e.g. fixed={'left': 'x', 'front': 'y', 'bottom': 'z'}."
            )
