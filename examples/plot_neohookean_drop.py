"""
A Neo-Hookean cube dropped on the ground
========================================

A soft rubber cube (10 cm, E = 100 kPa) falls 5 cm onto a penalty ground plane under gravity
and is integrated by implicit Euler. Implicit Euler is dissipative: the bounce dies out and
the total energy never grows. The body comes to rest no deeper in the ground than the
penalty's allowed penetration.
"""

import os

import matplotlib.pyplot as plt
import numpy as np

import fem_elastic as fe

QUICK = os.environ.get("FEM_ELASTIC_QUICK") == "1"

cube = fe.beam_mesh(length=0.1, width=0.1, height=0.1,
                    cells=(2, 2, 2) if QUICK else (4, 4, 4)).translated((0, 0, 0.05))
model = fe.Model(cube, density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
                 gravity=(0.0, 0.0, -9.81), ground=fe.Ground(z=0.0))
run = fe.simulate(model, fe.ImplicitEuler(), dt=1 / 100, t_end=0.4 if QUICK else 1.0)

z = cube.p[2][None, :] + run.displacement[:, :, 2]         # (T, n_vertices) heights, m
lowest = z.min(axis=1)
print(f"{len(run.times)} frames in {run.wall_time:.2f} s of wall time")
print(f"first contact at t = {run.times[np.argmax(lowest < 1e-3)]:.2f} s; "
      f"deepest point {lowest.min() * 1e3:.2f} mm, at the end {lowest[-1] * 1e3:.2f} mm")
print(f"total energy: {run.total[0]:.4f} J at rest up there, {run.total[-1]:.4f} J at the end")
# the penalty ground is stiff enough that no node *rests* deeper than its penetration
# (1 mm by default, plus 10 % for the bounce not yet settled); on impact it goes a little deeper
assert lowest[-1] > -1.1e-3 and lowest.min() > -5e-3
# implicit Euler only dissipates: the total energy (kinetic + gravity + elastic + contact)
# never rises beyond the Newton tolerance's noise (1e-6 J on a 0.5 J budget)
assert np.all(np.diff(run.total) < 1e-6)

# %%
# Heights and energies over time.
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.5))
ax1.plot(run.times, lowest * 1e3, label="lowest point")
ax1.plot(run.times, z.mean(axis=1) * 1e3, label="mean height")
ax1.axhline(0.0, color="k", lw=0.8)
ax1.set_xlabel("t (s)")
ax1.set_ylabel("height (mm)")
ax1.legend()
ax2.plot(run.times, run.kinetic, label="kinetic")
ax2.plot(run.times, run.potential - run.potential[-1], label="potential - final")
ax2.plot(run.times, run.total - run.total[-1], "k--", label="total - final")
ax2.set_xlabel("t (s)")
ax2.set_ylabel("energy (J)")
ax2.legend()
fig.tight_layout()

# %%
# The cube at the frame of its deepest squash, on the ground, coloured by its von Mises stress.
import pyvista as pv  # noqa: E402

k = int(np.argmin(lowest))
plotter = run.plot(k, off_screen=True, show=False)   # over its outline at the start
plotter.add_mesh(pv.Plane(center=(0.05, 0.05, 0.0), i_size=0.3, j_size=0.3), color="lightgrey")
plotter.camera.zoom(0.8)  # the contact clear of the colour bar
plotter.show()
