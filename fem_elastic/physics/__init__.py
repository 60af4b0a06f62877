"""Physics: every term of a model's energy, and the Model that adds them up.

Holds the :class:`~fem_elastic.physics.potential.Potential` protocol (energy,
gradient, Hessian of the nodal positions) and everything that is one or feeds
one: the elastic body (scikit-fem adapter), the mass-spring body, loads,
contact with obstacles and between bodies (IPC, impulses;
:class:`~fem_elastic.physics.multibody.MultiBody`), Rayleigh damping, stiffness warping, driven
boundaries, the :class:`~fem_elastic.physics.model.Model`, per-element fields
(stress, energy density) and the closed-form beam solutions the results are
checked against. It may import :mod:`fem_elastic.discretization`,
:mod:`fem_elastic.geometry`, :mod:`fem_elastic.materials` and the foundation
modules; solvers and integrators see it only through the Potential protocol.
"""

from .analytic import RectangularCantilever, elastica_tip
from .body import Body
from .broad_phase import BoundingSpheres
from .damping import Rayleigh
from .driven import Motion, Prescribed, Translate, Twist
from .elastic_body import ElasticBody, ElasticPotential
from .collision_surface import CollisionSurface, collision_surface
from .fields import CellFields, cell_fields, von_mises
from .impulse_contact import BoundImpulseContact, ImpulseContact, RestContactWarning, collide_particles
from .ipc_contact import BoundIPCContact, IPCContact
from .mixed_body import MixedPotential
from .model import Model
from .multibody import MultiBody
from .obstacles import Box, Ground, Obstacle, Sphere
from .potential import LinearPotential, Potential
from .springs import MassSpring, SpringPotential, lloyd_stiffness, van_gelder_stiffness
from .stiffness_warping import WarpedStiffness

__all__ = [
    "BoundIPCContact", "CollisionSurface", "IPCContact", "collision_surface",
    "Body", "MultiBody", "BoundImpulseContact", "BoundingSpheres", "ImpulseContact",
    "RestContactWarning", "collide_particles",
    "Box", "CellFields", "ElasticBody", "ElasticPotential", "Ground", "LinearPotential",
    "MassSpring", "MixedPotential", "Model", "Motion", "Obstacle", "Potential", "Prescribed", "Rayleigh",
    "RectangularCantilever", "Sphere", "SpringPotential", "Translate", "Twist", "WarpedStiffness",
    "cell_fields", "elastica_tip", "lloyd_stiffness", "van_gelder_stiffness", "von_mises",
]
