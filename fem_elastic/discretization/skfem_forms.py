"""Plain scikit-fem forms of the elastic energy: the reference, not the fast path.

The elastic energy of a body, its gradient and its Hessian are written here
the way scikit-fem's documentation writes them: as a ``Functional``, a
``LinearForm`` and a ``BilinearForm`` of the displacement, with the
deformation gradient ``F = I + grad(u)`` built from :mod:`skfem.helpers`:

    E(u)      = int psi(F) dX,
    g(u; v)   = int P(F) : grad(v) dX,              P = dpsi/dF,
    K(u; w, v) = int (C(F) : grad(w)) : grad(v) dX,  C = d2psi/dF2.

scikit-fem evaluates a ``LinearForm`` once per local basis function (12 for
P1 tets, 30 for P2) and a ``BilinearForm`` once per pair (144 for P1, 900 for
P2), and these forms re-evaluate the material at every call. That is the
point: nothing is shared, cached or reordered, so this module is an
independent check of the vectorized kernel in :mod:`fem_elastic.physics.elastic_body`
(used by ``tests/test_elastic_body.py``) and the baseline that
``scripts/bench_assembly.py`` measures it against. It is far too slow for
simulation: use :class:`fem_elastic.ElasticPotential` there.

:func:`neohookean_forms_ex43` is scikit-fem's own hyperelastic example
(``docs/examples/ex43.py``): Neo-Hookean residual and tangent written inline
with ``grad, identity, ddot, det, transpose, inv, trace, mul``, without the
material classes of this package.

Examples
--------
>>> import numpy as np
>>> import fem_elastic as fe
>>> from fem_elastic.discretization import Discretization
>>> space = Discretization(fe.beam_mesh(cells=(2, 1, 1)), order=1)   # 12 vertices
>>> material = fe.NeoHookean(E=1.0e6, nu=0.3)
>>> energy, g, K = assemble_reference(space, material, space.X)   # rest state
>>> energy, float(np.abs(g).max()), K.shape
(0.0, 0.0, (36, 36))
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from skfem import BilinearForm, Functional, LinearForm
from skfem.helpers import ddot, det, grad, identity, inv, mul, trace, transpose

__all__ = [
    "deformation_gradient",
    "energy_form",
    "residual_form",
    "tangent_form",
    "assemble_reference",
    "neohookean_forms_ex43",
]


def deformation_gradient(w) -> np.ndarray:
    """``F = I + grad(u)`` at the quadrature points, ``(3, 3, nelems, nqp)``.

    Parameters
    ----------
    w : skfem.assembly.form.FormExtraParams
        The form's extra parameters; ``w["displacement"]`` must be the
        displacement interpolated on the basis (``basis.interpolate(u)``).

    Returns
    -------
    numpy.ndarray
        Deformation gradient (dimensionless).
    """
    dudX = grad(w["displacement"])
    return identity(dudX) + dudX


def _tangent(material, F: np.ndarray, project: bool) -> np.ndarray:
    return material.d2psi_dF2_psd(F) if project else material.d2psi_dF2(F)


def energy_form(material) -> Functional:
    """The elastic energy ``int psi(F) dX`` (J) as a scikit-fem Functional.

    Parameters
    ----------
    material : fem_elastic.Material
        Provides ``psi(F)`` (J/m^3).

    Returns
    -------
    skfem.Functional
        Assemble with ``energy_form(m).assemble(basis, displacement=basis.interpolate(u))``.
    """

    @Functional
    def energy(w):
        return material.psi(deformation_gradient(w))

    return energy


def residual_form(material) -> LinearForm:
    """The energy's gradient ``int P(F) : grad(v) dX`` (N) as a LinearForm.

    ``P = material.dpsi_dF(F)`` is re-evaluated for each of the element's
    test functions, as scikit-fem's generic assembly does.

    Parameters
    ----------
    material : fem_elastic.Material
        Provides ``dpsi_dF(F)`` (Pa).

    Returns
    -------
    skfem.LinearForm
        Assemble with ``displacement=basis.interpolate(u)``.
    """

    @LinearForm
    def residual(v, w):
        return ddot(material.dpsi_dF(deformation_gradient(w)), grad(v))

    return residual


def tangent_form(material, project: bool = False) -> BilinearForm:
    """The energy's Hessian ``int (C(F) : grad(u)) : grad(v) dX`` (N/m) as a BilinearForm.

    ``(C : grad u)_ij = C_ijkl du_k/dX_l``, with ``C = material.d2psi_dF2(F)``
    or, with ``project=True``, its PSD projection ``material.d2psi_dF2_psd(F)``.
    C is re-evaluated for each pair of local basis functions.

    Parameters
    ----------
    material : fem_elastic.Material
        Provides ``d2psi_dF2`` and ``d2psi_dF2_psd`` (Pa).
    project : bool
        Use the per-point PSD projection of the tangent.

    Returns
    -------
    skfem.BilinearForm
        Assemble with ``displacement=basis.interpolate(u)``.
    """

    @BilinearForm
    def tangent(u, v, w):
        C = _tangent(material, deformation_gradient(w), project)
        CdU = np.einsum("ijkl...,kl...->ij...", C, grad(u))
        return ddot(CdU, grad(v))

    return tangent


def assemble_reference(model_or_space, material, x: np.ndarray, project: bool = False):
    """Energy, gradient and Hessian at positions x, by plain scikit-fem form assembly.

    Uses the same basis and quadrature as the fast kernel (``space.basis`` of
    :class:`fem_elastic.discretization.Discretization`), so the two sum the
    same quadrature terms and agree to round-off.

    Parameters
    ----------
    model_or_space : fem_elastic.Model or fem_elastic.discretization.Discretization
        A model (its ``space`` is used) or a discretization.
    material : fem_elastic.Material
        The body's material.
    x : numpy.ndarray
        DOF positions ``(ndofs,)`` (m), scikit-fem's interleaved DOF order.
    project : bool
        Assemble the PSD-projected tangent.

    Returns
    -------
    energy : float
        J; ``nan`` or ``inf`` if an element is inadmissible (no special casing here).
    gradient : numpy.ndarray
        ``(ndofs,)`` (N).
    hessian : scipy.sparse.csr_matrix
        ``(ndofs, ndofs)`` (N/m).
    """
    space = getattr(model_or_space, "space", model_or_space)
    basis = space.basis
    u = basis.interpolate(np.asarray(x, dtype=float) - space.X)
    energy = float(energy_form(material).assemble(basis, displacement=u))
    gradient = np.asarray(residual_form(material).assemble(basis, displacement=u))
    hessian = sp.csr_matrix(tangent_form(material, project).assemble(basis, displacement=u))
    return energy, gradient, hessian


def neohookean_forms_ex43(mu: float, lam: float) -> tuple[LinearForm, BilinearForm]:
    """Neo-Hookean residual and tangent forms in scikit-fem's documented style (ex43).

    ``psi = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2``; the forms are
    scikit-fem's ``docs/examples/ex43.py`` (hyperelasticity), written inline
    with :mod:`skfem.helpers`:

        L(v)    = mu F : dF + (lam ln J - mu) F^-T : dF,
        a(u, v) = mu DF : dF - (lam ln J - mu) tr(DF F^-1 dF F^-1)
                  + lam tr(dF F^-1) tr(DF F^-1),

    with ``dF = grad(v)``, ``DF = grad(u)``. They equal
    ``residual_form(NeoHookean(...))`` and ``tangent_form(NeoHookean(...))``
    and serve as the generic-assembly baseline of ``scripts/bench_assembly.py``.

    Parameters
    ----------
    mu, lam : float
        Lame parameters (Pa), e.g. ``material.mu, material.lam``.

    Returns
    -------
    residual : skfem.LinearForm
    tangent : skfem.BilinearForm
        Assemble both with ``displacement=basis.interpolate(u)``.
    """

    def F_and_inverse(w):
        dudX = grad(w["displacement"])
        F = dudX + identity(dudX)
        return F, inv(F)

    @LinearForm
    def residual(v, w):
        F, iF = F_and_inverse(w)
        dF = grad(v)
        lnJ = np.log(det(F))
        return mu * ddot(F, dF) + (lam * lnJ - mu) * ddot(transpose(iF), dF)

    @BilinearForm
    def tangent(u, v, w):
        F, iF = F_and_inverse(w)
        DF = grad(u)
        dF = grad(v)
        dFiF = mul(dF, iF)
        DFiF = mul(DF, iF)
        tr_DFiF_dFiF = ddot(transpose(dFiF), DFiF)
        lnJ = np.log(det(F))
        return (
            mu * ddot(DF, dF)
            - (lam * lnJ - mu) * tr_DFiF_dFiF
            + lam * trace(dFiF) * trace(DFiF)
        )

    return residual, tangent
