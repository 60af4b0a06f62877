"""
A scene file run from Python
============================

``scenes/springs_vs_fem.toml`` describes a cantilever under a sudden tip load: corotated FEM on
P2 tets beside two mass-spring networks calibrated from the same E. The command line runs it
with ``fem-elastic run scenes/springs_vs_fem.toml --out out``; from Python, ``fe.load_scene``
reads and checks it, and ``scene.build()`` gives one ready-to-run :class:`fem_elastic.BuiltRun`
per variant (model, integrator, dt, steps, initial state).
"""

import os
from pathlib import Path

import matplotlib.pyplot as plt

import fem_elastic as fe

QUICK = os.environ.get("FEM_ELASTIC_QUICK") == "1"
ROOT = Path(fe.__file__).resolve().parent.parent     # the checkout (an editable install)

path = ROOT / "scenes" / "springs_vs_fem.toml"
if QUICK:  # quick mode: the same scene on a coarser mesh, parsed from its edited text
    text = path.read_text().replace("cells = [20, 2, 2]", "cells = [8, 1, 1]")
    scene = fe.parse_scene(text, source=str(path), base_dir=path.parent)
else:
    scene = fe.load_scene(path)
print(f"scene {scene.name!r}: variants {scene.variants}")
runs = {built.name: built for built in scene.build()}

# %%
# Each variant's model also has a static answer, the rest state the damping settles to.
beam = fe.RectangularCantilever(length=1.0, width=0.1, height=0.1, E=1e7, nu=0.25)  # the scene's
P = 1.0e3 * beam.area                                # N: the 1 kPa traction on the end face
euler_bernoulli = beam.tip_load_euler_bernoulli(P)   # P L^3 / (3 E I), m
steps = 15 if QUICK else None                        # quick: the first 0.3 s of the 2 s
trajectories, statics = {}, {}
for name, built in runs.items():
    tip = built.model.mesh.p[0] > beam.length - 1e-9
    statics[name] = -fe.solve_static(built.model).displacement[tip, 2].mean()
    traj = built.simulate(steps=steps) if steps else built.simulate()
    trajectories[name] = (traj.times, -traj.displacement[:, tip, 2].mean(axis=1))
    print(f"{name:20s} static {statics[name] * 100:6.3f} cm "
          f"({statics[name] / euler_bernoulli:5.3f} x Euler-Bernoulli), "
          f"{len(traj.times) - 1} steps in {traj.wall_time:.2f} s")

# corotated P2 FEM bends like the beam (the 3-D solid is within 3 % of Euler-Bernoulli here:
# shear and the clamp add a little, the coarse quick mesh takes a little), the springs do not
assert abs(statics["fem_p2"] / euler_bernoulli - 1.0) < 0.03
assert all(abs(statics[n] / euler_bernoulli - 1.0) > 0.1 for n in statics if n != "fem_p2")

# %%
# The tip deflection over time, each variant against its own static answer.
fig, ax = plt.subplots(figsize=(7, 3.5))
for (name, (t, w)), colour in zip(trajectories.items(), ["C0", "C1", "C2"]):
    ax.plot(t, w * 100, color=colour, label=name)
    ax.axhline(statics[name] * 100, color=colour, ls=":")
ax.axhline(euler_bernoulli * 100, color="k", ls="--", label="Euler-Bernoulli")
ax.set_xlabel("t (s)")
ax.set_ylabel("tip deflection (cm)")
ax.legend(fontsize=8)
fig.tight_layout()
