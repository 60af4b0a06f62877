"""
A material from its energy
==========================

``fe.material_from_energy`` needs only the strain energy density, written with ``fe.math``
as a function of ``F`` or of the invariants ``I1, I2, J`` of ``C = F^T F``: its stress,
tangent and PSD projection are generated (sympy, the ``[energy]`` extra). First the
compressible Neo-Hookean energy, which must reproduce ``fe.NeoHookean`` to round-off; then a
Mooney-Rivlin energy that the library does not ship, on the same cantilever.
"""

import os

import matplotlib.pyplot as plt
import numpy as np

import fem_elastic as fe

QUICK = os.environ.get("FEM_ELASTIC_QUICK") == "1"

E, nu = 1e6, 0.45                                       # Pa, -
mu, lam = fe.lame_parameters(E, nu)
log = fe.math.log


def neo_hookean(I1, I2, J, mu, lam):
    """psi (J/m^3): fe.NeoHookean's energy, +inf where J <= 0."""
    return mu / 2 * (I1 - 3) - mu * log(J) + lam / 2 * log(J) ** 2


def mooney_rivlin(I1, I2, J, c1, c2, lam):
    """psi (J/m^3): compressible Mooney-Rivlin, with 2 (c1 + c2) = mu at small strain."""
    return c1 * (I1 - 3) + c2 * (I2 - 3) - 2 * (c1 + 2 * c2) * log(J) + lam / 2 * log(J) ** 2


materials = {
    "fe.NeoHookean": fe.NeoHookean(E=E, nu=nu),
    "Neo-Hookean from its energy": fe.material_from_energy(neo_hookean, mu=mu, lam=lam),
    "Mooney-Rivlin from its energy": fe.material_from_energy(mooney_rivlin, c1=0.3 * mu,
                                                             c2=0.2 * mu, lam=lam),
}
mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(6, 1, 1) if QUICK else (16, 2, 2))
tip = mesh.p[0] > 1.0 - 1e-9
results = {}
for name, material in materials.items():
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(material, order=2), fixed="left",
                     gravity=(0.0, 0.0, -9.81))
    results[name] = res = fe.solve_static(model, steps=4)
    print(f"{name:30s} tip {res.displacement[tip, 2].mean() * 1e3:9.4f} mm, "
          f"{res.wall_time:.2f} s")

u_hand = results["fe.NeoHookean"].displacement
u_gen = results["Neo-Hookean from its energy"].displacement
difference = np.abs(u_gen - u_hand).max() / np.abs(u_hand).max()
print(f"generated vs hand-written Neo-Hookean: {difference:.1e} (relative, max norm)")
# the same energy, so the same equilibrium: the same Newton iterates (49 on the quick mesh, 51
# on the full one, in both), equal to round-off, 1.1e-15 (quick) and 4.3e-16 (full). Were the
# two codes' round-off ever to send Newton one iteration further in one of them, that iteration
# would move u by under 1e-13 of max |u| (measured: one more Newton step from either converged
# state moves it by 8e-14 on the quick mesh, 3e-15 on the full one; Newton converges
# quadratically, so the iterate that passes rtol 1e-8 is already that close), so 1e-9 holds
# with four decades to spare; beyond it the two materials would truly differ
assert difference < 1e-9
# Mooney-Rivlin is another energy: a different deflection, of the same size (same mu)
tip_nh = results["fe.NeoHookean"].displacement[tip, 2].mean()
tip_mr = results["Mooney-Rivlin from its energy"].displacement[tip, 2].mean()
assert tip_mr != tip_nh and abs(tip_mr / tip_nh - 1.0) < 0.2

# %%
# The load path of both energies: the tip deflection against the load factor (the soft
# beam sags by a large fraction of its length, so the path is not a straight line).
fig, ax = plt.subplots(figsize=(6, 3.5))
for name in ("fe.NeoHookean", "Mooney-Rivlin from its energy"):
    path = results[name].path
    ax.plot([p.load_factor for p in path],
            [-p.displacement[tip, 2].mean() * 1e3 for p in path], "o-", label=name)
ax.set_xlabel("load factor (gravity)")
ax.set_ylabel("tip deflection (mm)")
ax.legend()
fig.tight_layout()
