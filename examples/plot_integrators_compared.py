"""
Time integrators compared
=========================

A cantilever is bent by gravity and let go: every integrator runs the same model from the
same state. Explicit schemes (symplectic Euler, velocity Verlet, RK4) must stay below their
critical time step, which ``fe.critical_time_step`` predicts from the highest natural
frequency; implicit ones (implicit Euler, Newmark, the trapezoid rule) take a step 10-100 x
larger. Implicit Euler damps the swing numerically, Newmark and the trapezoid rule keep its
energy, and the cost of each is its wall time.
"""

import os
import time

import matplotlib.pyplot as plt
import numpy as np

import fem_elastic as fe

QUICK = os.environ.get("FEM_ELASTIC_QUICK") == "1"

L = 1.0                                                   # m
mesh = fe.beam_mesh(length=L, width=0.1, height=0.1, cells=(6, 1, 1) if QUICK else (12, 2, 2))
model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)),
                 fixed="left")
# start from the static sag under gravity, released with gravity switched off: a free swing
sagged = fe.solve_static(fe.Model(mesh, density=1000.0,
                                  body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)),
                                  fixed="left", gravity=(0.0, 0.0, -9.81)))
start = fe.State.rest(model, displacement=sagged.displacement)
f1 = fe.natural_frequencies(model, 1)[0]
t_end = 1.0 / f1 if QUICK else 3.0 / f1                  # one (three) periods of the first mode
print(f"first bending frequency {f1:.3f} Hz: simulate {t_end:.2f} s")

dt_implicit = 1.0 / (40 * f1)                             # 40 steps a period
integrators = {
    "symplectic Euler": fe.SymplecticEuler(),
    "velocity Verlet": fe.VelocityVerlet(),
    "RK4": fe.RK4(),
    "implicit Euler": fe.ImplicitEuler(),
    "Newmark": fe.Newmark(),
    "trapezoid": fe.Trapezoid(),
}
tip = mesh.p[0] > L - 1e-9
runs = {}
for name, integrator in integrators.items():
    dt_crit = fe.critical_time_step(model, integrator)
    dt = dt_implicit if np.isinf(dt_crit) else 0.9 * dt_crit   # 10 % under the limit
    steps = int(np.ceil(t_end / dt))
    t0 = time.perf_counter()
    runs[name] = run = fe.simulate(model, integrator, dt=dt, steps=steps, state=start,
                                   record_every=max(1, steps // 200))
    seconds = time.perf_counter() - t0
    drift = run.total[-1] / run.total[0] - 1.0
    print(f"{name:17s} dt = {dt:.2e} s ({steps:5d} steps) {seconds:6.2f} s wall, "
          f"energy {drift * 100:+7.2f} %")

# implicit Euler loses energy every period (first order, numerical damping, 40 steps a period)
assert runs["implicit Euler"].total[-1] < 0.9 * runs["implicit Euler"].total[0]
# Newmark and the trapezoid rule conserve the energy of a linear body up to the Newton
# tolerance; symplectic schemes keep it within a few % (their energy oscillates with h omega)
for name in ("Newmark", "trapezoid"):
    assert abs(runs[name].total[-1] / runs[name].total[0] - 1.0) < 1e-3
for name in ("symplectic Euler", "velocity Verlet", "RK4"):
    assert abs(runs[name].total[-1] / runs[name].total[0] - 1.0) < 0.05

# %%
# The tip's vertical displacement: the implicit Euler swing decays, the others keep it.
fig, ax = plt.subplots(figsize=(7, 3.5))
for name, run in runs.items():
    ax.plot(run.times, run.displacement[:, tip, 2].mean(axis=1) * 1e3, label=name)
ax.set_xlabel("t (s)")
ax.set_ylabel("tip displacement (mm)")
ax.legend(ncol=2, fontsize=8)
fig.tight_layout()
