"""One mode of a small linear cantilever, in closed form: shared by the integrator order tests.

A linear cantilever (4 P1 hexahedra, 10 x 15 cm: no repeated frequency) and one of its
lumped-mass modes (dense eigh: exact to round-off). With mass-proportional damping alpha the
mode stays decoupled, zeta = alpha / (2 omega): a single damped oscillator in closed form.
"""

import math

import numpy as np
import scipy.linalg as sl

import fem_elastic as fe


def one_mode(alpha=0.0, mode=0):
    """(model, omega in rad/s, mass-normalised mode on the free DOFs)."""
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.15, cells=(4, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)),
                     fixed="left", damping=fe.Rayleigh(alpha=alpha) if alpha else None)
    free = model.free
    K = model.rest_stiffness.toarray()[np.ix_(free, free)]
    w2, Q = sl.eigh(K, np.diag(model.lumped_mass[free]))
    return model, math.sqrt(w2[mode]), Q[:, mode]


def modal(model, phi, s):
    """(q, v) of the State ``s`` in the mass-normalised mode phi."""
    free, m = model.free, model.lumped_mass[model.free]
    return phi @ (m * (s.x[free] - model.X[free])), phi @ (m * s.v[free])


def in_mode(model, phi, q0, v0):
    """The State with modal displacement q0 (m) and velocity v0 (m/s) in the mode phi."""
    x, v = model.X.copy(), np.zeros(model.ndofs)
    x[model.free] += q0 * phi
    v[model.free] = v0 * phi
    return fe.State(x, v)
