"""
Cost against mesh size
======================

How does the time of the basic operations grow with the number of tets? On cantilever
beams of growing size (Neo-Hookean, P1, held at one end), ``fe.study.measure_scaling``
times, on this machine:

- the assembly of the residual and the PSD-projected tangent (``model.linearize``);
- one implicit Euler step of dt = 1/60 s from rest under gravity (Newton on the projected
  tangent, AMG-CG linear solves);
- one symplectic Euler step;

and fits ``log t = a + p log n_tets`` to the medians. The work per element is the same on
every mesh, so assembly and an explicit step cost ``n`` times a constant (p = 1) up to
cache effects and fixed per-call costs; AMG-CG needs about the same number of iterations
on every mesh, so an implicit step is near-linear too. The full answer (5k-154k tets,
several minutes) is in ``docs/performance.md``; quick mode times 1k-20k tets in seconds.
"""

import os

import matplotlib.pyplot as plt
import numpy as np

import fem_elastic as fe

QUICK = os.environ.get("FEM_ELASTIC_QUICK") == "1"

scaling = fe.study.scaling
sizes = scaling.QUICK_SIZES if QUICK else scaling.FULL_SIZES
# medians of 5; in quick mode the implicit step's of 3 (it is most of the run's time). The
# clock is the process's CPU time: the docs build and the test suite share their cores with
# other jobs, whose share of the cores would otherwise land on whichever size ran beside
# them. Below 20k tets the kernels run on one thread, so it is the wall time of an idle machine.
result = fe.study.measure_scaling(sizes, repeats=5, implicit_repeats=3 if QUICK else 5,
                                  clock="process")
print(result.summary())   # a median per size and operation, and the fitted exponents
p = result.exponents

# %%
# What must hold, whatever the machine:
#
# - p near 1 for all three. The bounds are wide because the quick sizes are small: at 1k
#   tets fixed per-call costs (Python dispatch, numba launch, the AMG hierarchy's
#   per-level set-up) are a large part of a call and flatten the curve (p = 0.75 seen for
#   the implicit step, by the wall clock on a loaded 2-core machine), and one point can
#   move by 2x, which over a 20x range of sizes moves p by up to log 2 / log 20 = 0.23.
#   A cost that does not grow with the mesh (p near 0: a cached result timed) or that
#   grows as its square (p near 2: an all-pairs loop, a dense matrix) fails.
# - an implicit step costs more than one assembly at every size: each Newton iteration
#   assembles the tangent once and then solves with it;
# - an explicit step costs less than one assembly: it needs the gradient alone, which is
#   part of the assembly's work (20x less seen).
for op, exponent in p.items():
    assert 0.5 <= exponent <= 1.6, f"{op}: fitted exponent {exponent:.2f} outside [0.5, 1.6]"
seconds = result.seconds
assert np.all(seconds["implicit step"] > seconds["assembly"])
assert np.all(seconds["explicit step"] < seconds["assembly"])

# %%
# The log-log plot: the medians as markers, each fitted power law dashed. A slope of 1 is
# linear cost; the exponents are in the legend.
ax = result.plot()
ax.figure.tight_layout()
plt.show()
