"""Stiffness warping: corotated linear FEM with element stiffness precomputed once.

The scheme of Mueller and Gross (2004), as in the SIGGRAPH 2008 course notes
(``seeds/002_942bade499ba35f4.txt``, "Co-Rotated Finite Elements"): each
element keeps its *linear* stiffness matrix K_e (N/m), computed once at the
reference configuration, and measures its deformation in a frame that turns
with it. With R_e the rotation of the polar decomposition ``F = R S`` of the
element's deformation gradient and B_e = blockdiag(R_e, ..., R_e) acting on
the element's node blocks,

    E(x) = 1/2 sum_e d_e^T K_e d_e,        d_e = B_e^T x_e - X_e   (m),
    g(x) = sum_e B_e K_e d_e               (N; the force is -g),
    K(x) = sum_e B_e K_e B_e^T             (N/m).

Only R_e changes with x: no material tangent is evaluated, and a step of an
implicit integrator is a single linear solve (no Newton iterations).

Symbols: x, X the current and reference DOF positions (m, flat, DOF
``3 * node + component``); x_e, X_e their element blocks; F the deformation
gradient; R a proper rotation (``det R = +1``); S = R^T F the stretch;
mu, lam the Lame parameters (Pa); ``sigma_lin(G) = 2 mu sym(G - I) + lam
tr(G - I) I`` the linear-elastic stress of a gradient G.

What the scheme computes exactly, and what it does not
------------------------------------------------------
*Linear tets (P1): the force is the exact corotated force.* F is constant
in the element, so K_e d_e is the linear-elastic force of the rotated-back
configuration R^T x, whose gradient is R^T F = S:
``(K_e d_e)_a = V sigma_lin(S) dN_a``. The signed SVD gives
``F = U diag(s) V^T``, ``R = U V^T``, so ``S = V diag(s) V^T`` is symmetric
and ``sym(S - I) = S - I``. Then

    R sigma_lin(S) = 2 mu (R S - R) + lam tr(S - I) R
                   = 2 mu (F - R) + lam tr(R^T F - I) R,

which is the first Piola stress P of :class:`fem_elastic.Corotated`, so
``B_e K_e d_e = V P dN_a``: g equals the gradient of
``ElasticPotential(Corotated(E, nu), space)`` to round-off, and E(x) equals
its energy (``psi_lin(S) = mu ||S - I||^2 + lam/2 tr(S - I)^2 = mu sum (s_i -
1)^2 + lam/2 (sum s_i - 3)^2``). That g is the exact gradient of E although
dR/dx is ignored is no accident: the ignored term is ``sigma_lin(S) : (dR^T
F)``, ``dR^T F = W S`` with ``W = dR^T R`` skew, and ``S sigma_lin(S)`` is
symmetric (the two commute), so the term vanishes.

*Quadratic tets (P2): an approximation.* F varies (linearly) inside the
element and one R_e serves all its quadrature points, taken from the
element's mean deformation gradient (see :meth:`WarpedStiffness.rotations`).
``R^T F`` is then not symmetric at the quadrature points, g is not the exact
gradient of E (the dR/dx term no longer vanishes), and neither is the
corotated force; it still vanishes under any rigid motion.

*The matrix K is never the exact Hessian* (of E or of the corotated energy):
it drops every dR/dx term. That is the scheme: K is symmetric, positive
semi-definite (a congruence of the PSD K_e) and costs no material tangent.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.sparse as sp

from ..discretization.space import Discretization
from .elastic_body import ElasticPotential
from ..errors import InvalidParameter
from ..materials.base import Material
from ..materials.svd import polar_rotation
from .potential import Potential

__all__ = ["WarpedStiffness"]

log = logging.getLogger(__name__)


def _linear_tangent(mu: float, lam: float) -> np.ndarray:
    """C_ijkl = mu (d_ik d_jl + d_il d_jk) + lam d_ij d_kl (Pa), shape (3, 3, 3, 3)."""
    d = np.eye(3)
    return (mu * (np.einsum("ik,jl->ijkl", d, d) + np.einsum("il,jk->ijkl", d, d))
            + lam * np.einsum("ij,kl->ijkl", d, d))


class WarpedStiffness(Potential):
    """Stiffness-warped (corotated) linear elasticity on P1 or P2 tets.

    Parameters
    ----------
    space : Discretization
        The P1 or P2 space of the body.
    material : Material
        Any material: only its Lame parameters ``mu`` and ``lam`` (Pa) are
        used, through the linear-elastic tangent at the rest state (which is
        the same for every material in this package).

    Attributes
    ----------
    element_matrices : numpy.ndarray, shape (nelems, 3 nloc, 3 nloc)
        The linear-elastic element stiffness matrices K_e at the reference
        configuration (N/m), in the element's local DOF order ``3 a + i``;
        read-only.

    Notes
    -----
    A :class:`Potential`, so it has ``energy``, ``gradient``, ``hessian`` and
    ``linearize``; ``project`` is accepted and ignored (K is PSD already).
    See the module docstring for what is exact: for P1 the gradient is the
    exact corotated force; the matrix drops the dR/dx terms (that is the
    scheme). The stored K_e take ``8 (3 nloc)^2`` bytes per element: 1.2 kB
    for P1, 7.2 kB for P2.

    Examples
    --------
    A rigid rotation and translation of the body costs nothing:

    >>> import numpy as np
    >>> import fem_elastic as fe
    >>> from fem_elastic.discretization import Discretization
    >>> space = Discretization(fe.beam_mesh(cells=(4, 1, 1)), order=1)
    >>> warped = WarpedStiffness(space, fe.Corotated(E=1e6, nu=0.3))
    >>> c, s = np.cos(1.0), np.sin(1.0)
    >>> Q = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    >>> x = (space.X.reshape(-1, 3) @ Q.T + [0.3, -0.2, 0.5]).ravel()
    >>> g, K = warped.linearize(x)
    >>> bool(np.abs(g).max() < 1e-9 * np.abs(K).max()), space.pattern.owns(K)
    (True, True)
    """

    def __init__(self, space: Discretization, material: Material) -> None:
        if not isinstance(space, Discretization):
            raise InvalidParameter(
                f"space must be a fem_elastic Discretization (P1 or P2 tets), got {type(space).__name__}."
            )
        try:
            mu, lam = float(material.mu), float(material.lam)
        except AttributeError:
            raise InvalidParameter(
                f"material must provide Lame parameters mu and lam (Pa), e.g. "
                f"fe.Corotated(E=1e6, nu=0.3); got {material!r}."
            ) from None
        self.space = space
        self.material = material
        s = space
        ne, nq = s.dx.shape
        nl = s.nloc
        C = np.broadcast_to(_linear_tangent(mu, lam)[..., None, None], (3, 3, 3, 3, ne, nq))
        # element_stiffness uses only the space and C (not the potential's material)
        Ke = ElasticPotential(material, space).element_stiffness(C)  # (3 nl, 3 nl, ne)
        # Elements first: the per-element products below are batched matmuls.
        self.element_matrices = np.ascontiguousarray(np.moveaxis(Ke, -1, 0))
        # Mean shape-function gradient per element (1/m): F_mean = I + sum_a u_a dNbar_a^T.
        vol = s.dx.sum(axis=1)
        self._dN_mean = np.einsum("ajeq,eq->aje", s.dN, s.dx) / vol  # (nl, 3, ne)
        self._dofs = np.ascontiguousarray(s.element_dofs.T)  # (ne, 3 nl)
        Xe = s.X[self._dofs].reshape(ne, nl, 3)
        # Element node positions relative to the element's mean node: K_e annihilates
        # translations, so dropping them changes nothing but keeps round-off at eps h
        # instead of eps |X| for a body far from the origin.
        self._Xc = Xe - Xe.mean(axis=1, keepdims=True)
        # The space's scatter map, reordered to the elements-first layout of the
        # products below, so they are summed into the pattern's CSR data without
        # first transposing them (that copy cost more than the sum itself).
        m = 3 * nl
        self._scatter = np.ascontiguousarray(
            s.pattern.scatter.reshape(m, m, ne).transpose(2, 0, 1)).ravel()
        for arr in (self.element_matrices, self._dN_mean, self._dofs, self._Xc, self._scatter):
            arr.setflags(write=False)
        log.debug("warped stiffness: %d elements of %d DOFs", ne, 3 * nl)

    # rotations -------------------------------------------------------------------
    def mean_deformation_gradient(self, x: np.ndarray) -> np.ndarray:
        """Volume average of F over each element, shape ``(3, 3, nelems)``.

        P1: F itself (it is constant). P2: F is affine in a straight-sided
        tet, so its volume average is also its value at the centroid; the
        quadrature (degree 2) integrates it exactly.
        """
        s = self.space
        ue = s.gather(np.asarray(x, dtype=float) - s.X)  # (nl, 3, ne)
        F = np.einsum("aie,aje->ije", ue, self._dN_mean)
        for i in range(3):
            F[i, i] += 1.0
        return F

    def rotations(self, x: np.ndarray) -> np.ndarray:
        """Per-element rotation R_e, shape ``(3, 3, nelems)`` (dimensionless).

        The rotation of the polar decomposition ``F = R S`` of the element's
        mean deformation gradient (:meth:`mean_deformation_gradient`: F
        itself for P1, F at the centroid for P2), from the signed SVD
        (:func:`fem_elastic.materials.svd.polar_rotation`): ``det R = +1``
        even for an inverted element, whose inversion then shows as a
        negative eigenvalue of S, so the element pushes back towards its
        rest shape instead of settling in a mirrored one.

        Parameters
        ----------
        x : numpy.ndarray, shape (ndofs,)
            DOF positions (m).

        Returns
        -------
        R : numpy.ndarray, shape (3, 3, nelems)
            Proper rotations.

        Examples
        --------
        >>> import numpy as np
        >>> import fem_elastic as fe
        >>> from fem_elastic.discretization import Discretization
        >>> space = Discretization(fe.beam_mesh(cells=(2, 1, 1)), order=2)
        >>> R = WarpedStiffness(space, fe.LinearElastic(E=1e6, nu=0.3)).rotations(space.X)
        >>> R.shape, bool(np.allclose(R, np.eye(3)[:, :, None]))
        ((3, 3, 12), True)
        """
        return polar_rotation(self.mean_deformation_gradient(x))

    # the scheme --------------------------------------------------------------------
    def _local(self, x: np.ndarray):
        """(R as (ne, 3, 3), d_e = R^T x_e - X_e up to a translation, as (ne, nl, 3))."""
        s = self.space
        x = np.asarray(x, dtype=float)
        R = np.ascontiguousarray(np.moveaxis(self.rotations(x), -1, 0))  # (ne, 3, 3)
        ue = (x - s.X)[self._dofs].reshape(self._Xc.shape)
        xc = self._Xc + (ue - ue.mean(axis=1, keepdims=True))  # x_e minus its mean node
        # row vectors: (R^T p)^T = p^T R
        d = xc @ R - self._Xc
        return R, d

    def _forces(self, R, d) -> np.ndarray:
        """g = sum_e B_e K_e d_e, assembled (N)."""
        ne, nl, _ = d.shape
        Kd = (self.element_matrices @ d.reshape(ne, 3 * nl, 1)).reshape(ne, nl, 3)
        ge = Kd @ R.transpose(0, 2, 1)  # (R Kd_a)^T = Kd_a^T R^T
        return np.bincount(self._dofs.ravel(), weights=ge.ravel(), minlength=self.space.ndofs)

    def _matrix(self, R) -> sp.csr_matrix:
        """K = sum_e B_e K_e B_e^T on the space's CSR pattern (N/m)."""
        ne, m, _ = self.element_matrices.shape
        nl = m // 3
        # rows: R acting on the row index i of every (a i, b l) entry
        T = R[:, None] @ self.element_matrices.reshape(ne, nl, 3, m)  # (ne, nl, 3, m)
        # columns: multiply the trailing (b, l) blocks by R^T from the right
        Kr = T.reshape(ne, m * nl, 3) @ R.transpose(0, 2, 1)  # (ne, m, m) as (ne, m nl, 3)
        # What ``space.pattern.assemble(np.moveaxis(Kr, 0, -1))`` computes, without the
        # transposed copy: the same CSR structure arrays, so ``pattern.owns(K)`` holds.
        pat = self.space.pattern
        data = np.bincount(self._scatter, weights=Kr.ravel(), minlength=pat.nnz)
        return sp.csr_matrix((data, pat.indices, pat.indptr), shape=pat.shape, copy=False)

    def energy(self, x: np.ndarray) -> float:
        """Warped energy ``1/2 sum_e d_e^T K_e d_e`` (J).

        For P1 it equals the corotated energy and :meth:`gradient` is its
        exact gradient; for P2 the gradient is the scheme's force, not the
        exact derivative of this energy (see the module docstring).

        Parameters
        ----------
        x : numpy.ndarray, shape (ndofs,)
            DOF positions (m).

        Returns
        -------
        float
            Energy (J), >= 0.

        Examples
        --------
        >>> import fem_elastic as fe
        >>> from fem_elastic.discretization import Discretization
        >>> space = Discretization(fe.beam_mesh(cells=(2, 1, 1)), order=1)
        >>> WarpedStiffness(space, fe.Corotated(E=1e6, nu=0.3)).energy(space.X)
        0.0
        """
        R, d = self._local(x)
        ne = d.shape[0]
        dv = d.reshape(ne, -1, 1)
        return float(0.5 * np.sum(dv * (self.element_matrices @ dv)))

    def gradient(self, x: np.ndarray) -> np.ndarray:
        """``g = sum_e B_e K_e (B_e^T x_e - X_e)`` (N), ``(ndofs,)``; the force is -g.

        Examples
        --------
        >>> import numpy as np
        >>> import fem_elastic as fe
        >>> from fem_elastic.discretization import Discretization
        >>> space = Discretization(fe.beam_mesh(cells=(2, 1, 1)), order=1)
        >>> g = WarpedStiffness(space, fe.Corotated(E=1e6, nu=0.3)).gradient(1.01 * space.X)
        >>> g.shape, bool(abs(g.sum()) < 1e-6)      # internal forces balance
        ((36,), True)
        """
        return self._forces(*self._local(x))

    def apply(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``K(x) v`` without assembling K: ``sum_e B_e K_e B_e^T v_e`` (N/m times v's unit).

        The warped stiffness annihilates rigid motions of a rotated element,
        ``K (omega x (x - c)) = 0``, so stiffness-proportional damping built on
        it does not brake a spinning body (the rest stiffness K_0 does).

        Examples
        --------
        >>> import numpy as np
        >>> import fem_elastic as fe
        >>> from fem_elastic.discretization import Discretization
        >>> space = Discretization(fe.beam_mesh(cells=(2, 1, 1)), order=1)
        >>> w = WarpedStiffness(space, fe.LinearElastic(E=1e6, nu=0.3))
        >>> c, s = np.cos(1.0), np.sin(1.0)
        >>> Q = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
        >>> x = (space.X.reshape(-1, 3) @ Q.T).ravel()               # rotated by 1 rad about z
        >>> spin = np.cross([0, 0, 1.0], x.reshape(-1, 3)).ravel()   # its rigid spin velocity
        >>> bool(np.abs(w.apply(x, spin)).max() < 1e-6)
        True

        For P1 with numba (:func:`fem_elastic.discretization.fused.available`) one fused pass
        over the elements computes it (:func:`fem_elastic.discretization.fused.warped_apply`);
        otherwise, and for P2, batched numpy products do (the reference).
        """
        if self.space.order == 1:
            from ..discretization import fused

            if fused.available():
                return fused.warped_apply(self, x, v)
        R = np.ascontiguousarray(np.moveaxis(self.rotations(x), -1, 0))  # (ne, 3, 3)
        ne, m, _ = self.element_matrices.shape
        ve = np.asarray(v, dtype=float)[self._dofs].reshape(ne, m // 3, 3)
        local = ve @ R  # rows: (R^T v_a)^T = v_a^T R
        Kv = (self.element_matrices @ local.reshape(ne, m, 1)).reshape(ne, m // 3, 3)
        fe_ = Kv @ R.transpose(0, 2, 1)
        return np.bincount(self._dofs.ravel(), weights=fe_.ravel(), minlength=self.space.ndofs)

    def hessian(self, x: np.ndarray, project: bool = False) -> sp.csr_matrix:
        """``K = sum_e B_e K_e B_e^T`` (N/m), CSR on ``space.pattern``.

        ``project`` is ignored: K is symmetric positive semi-definite already.
        """
        R, _ = self._local(x)
        return self._matrix(R)

    def linearize(self, x: np.ndarray,
                  project: bool = False) -> tuple[np.ndarray, sp.spmatrix | None]:
        """Force and stiffness of the scheme at x, sharing the rotations.

        Parameters
        ----------
        x : numpy.ndarray, shape (ndofs,)
            DOF positions (m).
        project : bool
            Ignored (K is PSD); accepted for the Potential protocol.

        Returns
        -------
        g : numpy.ndarray, shape (ndofs,)
            ``sum_e B_e K_e (B_e^T x_e - X_e)`` (N); the force is ``-g``.
        K : scipy.sparse.csr_matrix, shape (ndofs, ndofs)
            ``sum_e B_e K_e B_e^T`` (N/m), on ``space.pattern``
            (``space.pattern.owns(K)`` holds), symmetric PSD.

        Examples
        --------
        At the rest state K is the linear-elastic stiffness:

        >>> import numpy as np
        >>> import fem_elastic as fe
        >>> from fem_elastic.discretization import Discretization
        >>> from fem_elastic.physics.elastic_body import ElasticPotential
        >>> space = Discretization(fe.beam_mesh(cells=(2, 1, 1)), order=1)
        >>> g, K = WarpedStiffness(space, fe.Corotated(E=1e6, nu=0.3)).linearize(space.X)
        >>> K_lin = ElasticPotential(fe.LinearElastic(E=1e6, nu=0.3), space).hessian(space.X)
        >>> bool(abs(K - K_lin).max() < 1e-9 * abs(K_lin).max()), float(np.abs(g).max())
        (True, 0.0)
        """
        R, d = self._local(x)
        return self._forces(R, d), self._matrix(R)
