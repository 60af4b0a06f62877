"""Discretization: the finite element space of a body and the kernels that integrate over it.

Holds the scikit-fem adapter (:mod:`~fem_elastic.discretization.space`: bases,
DOF maps, quadrature data, the fixed CSR pattern), the reference assembly
through scikit-fem forms (:mod:`~fem_elastic.discretization.skfem_forms`), the
fused numba kernels (:mod:`~fem_elastic.discretization.fused`) and the mass
matrices (:mod:`~fem_elastic.discretization.mass`). It turns a material's
pointwise ``psi(F)`` into element sums, and knows nothing of loads, contact or
time. It may import :mod:`fem_elastic.geometry`, :mod:`fem_elastic.materials`
and the foundation modules, never a layer above it.
"""

from .mass import consistent_mass, lumped_mass
from .space import Discretization, SparsityPattern, check_order

__all__ = ["Discretization", "SparsityPattern", "check_order", "consistent_mass", "lumped_mass"]
