"""
Natural frequencies and mode shapes
===================================

``fe.natural_frequencies`` solves ``K phi = omega^2 M phi`` for the lowest modes. A steel
cantilever 1 m x 5 cm x 5 cm on quadratic tets: its bending modes come in pairs (about y and
about z, the section is square) and sit on Euler-Bernoulli's
``f_n = (beta_n L)^2 / (2 pi L^2) sqrt(E I / (rho A))``, a little above it, as a finite
element model with a consistent mass does (Rayleigh-Ritz gives upper bounds of the 3-D
continuum's frequencies); shear and rotary inertia, which the beam theory leaves out, pull
the second pair back towards it.
"""

import os

import matplotlib.pyplot as plt
import numpy as np

import fem_elastic as fe

QUICK = os.environ.get("FEM_ELASTIC_QUICK") == "1"

L, a, E, nu, rho = 1.0, 0.05, 2e11, 0.3, 7850.0        # m, m, Pa, -, kg/m^3
mesh = fe.beam_mesh(L, a, a, cells=(10, 1, 1) if QUICK else (20, 1, 1))
model = fe.Model(mesh, density=rho, body=fe.ElasticBody(fe.LinearElastic(E=E, nu=nu), order=2),
                 fixed="left")
f, modes = fe.natural_frequencies(model, 6, return_modes=True)

I, A = a**4 / 12, a * a
beta_L = np.array([1.8751, 4.6941])                       # clamped-free roots of cos cosh = -1
f_eb = beta_L**2 / (2 * np.pi * L**2) * np.sqrt(E * I / (rho * A))
for k, fk in enumerate(f):
    beam = f"{fk / f_eb[k // 2]:6.3f} x Euler-Bernoulli" if k < 4 else "(torsion, axial, ...)"
    print(f"mode {k + 1}: {fk:8.2f} Hz {beam}")
# the first pair within 2 % above the beam (the P2 model is stiffer than the continuum by
# its discretization: 1.2-1.4 % on the quick 10-cell mesh, 0.6 % on 20 cells), the second
# within 3 % (shear and rotary inertia soften it, the mesh stiffens it)
assert np.all((f[:2] / f_eb[0] > 1.0) & (f[:2] / f_eb[0] < 1.02))
assert np.all(abs(f[2:4] / f_eb[1] - 1.0) < 0.03)

# %%
# The shapes of the first and third modes along the axis (the vertical component of the
# vertices, normalised), against the Euler-Bernoulli mode shapes.
n_vertices = mesh.p.shape[1]
x = mesh.p[0]
order = np.argsort(x)
fig, ax = plt.subplots(figsize=(7, 3.5))
s = np.linspace(0.0, L, 200)
for k, bl in zip((0, 2), beta_L):
    u = modes[: 3 * n_vertices, k].reshape(-1, 3)        # the vertex DOFs come first
    w = u[:, np.argmax(np.abs(u).max(axis=0))]          # the bending direction of this mode
    w = w / w[np.argmax(np.abs(w))]
    b = bl / L
    sigma = (np.cosh(bl) + np.cos(bl)) / (np.sinh(bl) + np.sin(bl))
    phi = np.cosh(b * s) - np.cos(b * s) - sigma * (np.sinh(b * s) - np.sin(b * s))
    phi = phi / phi[np.argmax(np.abs(phi))]
    ax.plot(x[order], w[order], ".", label=f"FEM mode {k + 1}, {f[k]:.1f} Hz")
    ax.plot(s, phi, "k-", lw=0.8)
ax.set_xlabel("x (m)")
ax.set_ylabel("normalised deflection")
ax.legend(title="lines: Euler-Bernoulli", fontsize=8)
fig.tight_layout()
