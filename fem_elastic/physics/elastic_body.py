"""The scikit-fem adapter: an elastic body as a Potential of the nodal positions.

The total elastic energy of the body is

    E(x) = sum_e sum_q psi(F(x)_eq) dx_eq,

with ``F = I + grad u`` at each quadrature point, ``u = x - X`` the displacement
and ``dx`` the quadrature weight times the Jacobian (m^3). Its gradient (the
internal force with the sign flipped, N) and its Hessian (the tangent
stiffness, N/m) follow from ``P = dpsi_dF`` and ``C = d2psi_dF2``:

    g_ai = sum_q P_ij dN_a,j dx,          K_ai,bk = sum_q dN_a,j C_ijkl dN_b,l dx.

scikit-fem supplies the basis, quadrature and DOF maps (see
:mod:`fem_elastic.discretization`); the contraction above is done here by a
vectorized kernel over all elements at once, because scikit-fem's generic
``BilinearForm`` evaluates the form once per pair of local basis functions
(144 pairs for P1, 900 for P2), re-evaluating the material tangent each time.
:mod:`fem_elastic.discretization.skfem_forms` keeps that plain form assembly as the
reference the tests compare this kernel with.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..discretization.space import Discretization, check_order
from ..errors import InvalidParameter
from ..materials.base import Material
from .potential import Potential

__all__ = ["ElasticBody", "ElasticPotential", "FORMULATIONS"]

log = logging.getLogger(__name__)

#: The formulations an ElasticBody can use: the displacement element, and the
#: mixed element of :mod:`fem_elastic.physics.mixed_body` (no volumetric locking).
FORMULATIONS = ("displacement", "mixed")


@dataclass(frozen=True)
class ElasticBody:
    """A finite element body: a material on P1 or P2 tets.

    Parameters
    ----------
    material : Material
        e.g. ``fe.NeoHookean(E=1e6, nu=0.45)``.
    order : {1, 2}
        1 for linear tets (4 nodes), 2 for quadratic tets (10 nodes). Linear
        tets lock in bending: prefer order 2 for thin, bending-dominated parts.
    formulation : {"displacement", "mixed"}
        ``"displacement"`` (default): the energy integrated at every quadrature
        point. ``"mixed"``: an element-wise constant pressure and mean dilatation
        condensed out (:class:`~fem_elastic.physics.mixed_body.MixedPotential`),
        which does not lock as nu -> 0.5; needs ``order=2`` and a material with a
        volumetric split (``fe.LinearElastic``, ``fe.NeoHookean``,
        ``fe.StableNeoHookean``). The same energy under homogeneous deformation.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> body = fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.45), order=2)
    >>> body.order, body.formulation
    (2, 'displacement')
    >>> fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.4999), order=2, formulation="mixed").formulation
    'mixed'
    """

    material: Material
    order: int = 1
    formulation: str = "displacement"

    def __post_init__(self):
        if not isinstance(self.material, Material):
            raise InvalidParameter(
                f"ElasticBody needs a material such as fe.NeoHookean(E=..., nu=...), "
                f"got {self.material!r}."
            )
        check_order(self.order)
        if not isinstance(self.formulation, str) or self.formulation not in FORMULATIONS:
            raise InvalidParameter(
                f"formulation must be one of {', '.join(map(repr, FORMULATIONS))}, got "
                f"{self.formulation!r}: 'mixed' for nearly incompressible bodies (nu close to "
                "0.5), which lock in the displacement formulation."
            )
        if self.formulation == "mixed":
            from .mixed_body import check_mixed  # mixed_body builds on ElasticPotential below

            check_mixed(self.material, self.order)

    def build(self, space: Discretization) -> "ElasticPotential":
        """The body's energy on a discretization of matching order."""
        if self.formulation == "mixed":
            from .mixed_body import MixedPotential

            return MixedPotential(self.material, space)
        return ElasticPotential(self.material, space)


class ElasticPotential(Potential):
    """Elastic strain energy of a body (J) as a function of the DOF positions x (m).

    Parameters
    ----------
    material : Material
        Provides psi, dpsi_dF, d2psi_dF2 and d2psi_dF2_psd.
    space : Discretization
        Basis, quadrature and DOF maps.
    """

    def __init__(self, material: Material, space: Discretization) -> None:
        self.material = material
        self.space = space

    @property
    def quadratic(self) -> bool:  # type: ignore[override]
        """Whether the energy is quadratic in x: the material's psi is quadratic in F.

        Only a class that declares it itself counts (``LinearElastic``): a user's subclass of
        it that changes psi does not inherit the claim.
        """
        return bool(vars(type(self.material)).get("quadratic", False))

    def F(self, x: np.ndarray) -> np.ndarray:
        """Deformation gradient at the quadrature points, ``(3, 3, nelems, nqp)``."""
        return self.space.deformation_gradient(x - self.space.X)

    def energy_density(self, x: np.ndarray) -> np.ndarray:
        """psi at the quadrature points (J/m^3), ``(nelems, nqp)``."""
        return self.material.psi(self.F(x))

    def _fused(self):
        """The fused numba kernels of :mod:`fem_elastic.discretization.fused` (P1 or P2, registered
        materials, numba importable, ``FEM_ELASTIC_NUMBA`` not 0), or None: numpy path."""
        from ..discretization import fused  # numba itself is imported there, on first use only

        return fused.kernels_for(self.material, self.space)

    def energy(self, x: np.ndarray) -> float:
        kernels = self._fused()
        if kernels is not None:
            return kernels.energy(x)  # one pass over the elements, no temporaries
        with np.errstate(invalid="ignore", divide="ignore"):
            psi = self.energy_density(x)
        if not np.all(np.isfinite(psi)):
            return np.inf  # inadmissible (inverted elements of a barrier material)
        return float(np.sum(psi * self.space.dx))

    def energy_roundoff(self) -> float:
        """Absolute round-off of :meth:`energy` near the rest state (J).

        psi is evaluated from F, whose entries carry an absolute error of
        about eps, so each term of psi (of size ``~ (mu + lam) |F|^2``) carries
        ~ eps (mu + lam); the energy differences a line search compares fall
        below this long before the gradient does. Summed over the volume,
        with a factor 3 for the three diagonal entries of F.
        """
        m = self.material
        return (3.0 * np.finfo(float).eps * self._offset_factor() * (m.mu + abs(m.lam))
                * float(self.space.dx.sum()))

    def _offset_factor(self) -> float:
        """How much larger than the body's size its coordinates are (>= 1).

        Positions are stored absolutely, so u = x - X carries an absolute error
        of eps |X|: the estimates below assume coordinates of the order of the
        body's size (eps relative to it), and grow by max|X| / size for a body
        placed far from the origin (a steel beam 100 m away otherwise never met
        Newton's floor).
        """
        X = self.space.X.reshape(-1, 3)
        size = float(np.ptp(X, axis=0).max())
        return max(1.0, float(np.abs(X).max()) / size) if size > 0 else 1.0

    def gradient_roundoff(self) -> float:
        """Norm of the round-off in :meth:`gradient` (N): the floor under ||g||.

        The stress is evaluated from F = I + grad u, whose entries carry an
        absolute error of about eps; the material subtracts I again (in
        eps = sym F - I, in F - F^-T, ...), so each stress component carries
        ~ eps (2 mu + lam) whatever the load. Through the force contraction
        this gives ``eps (2 mu + lam) sum_q |dN_a| dx`` per DOF (times
        :meth:`_offset_factor` for a body far from the origin). For a stiff
        material under a small load this floor lies above rtol ||f_ext||, and
        no iterate can do better: Newton stops when it reaches it.
        """
        m = self.material
        s = self.space
        w = np.einsum("ajeq,eq->ae", np.abs(s.dN), s.dx)  # sum_j |dN_a,j| dx per element node
        per_node = np.bincount(s.element_dofs[0::3].ravel() // 3, weights=w.ravel(),
                               minlength=s.ndofs // 3)
        eps = np.finfo(float).eps * self._offset_factor()
        return float(eps * (2.0 * m.mu + abs(m.lam)) * np.sqrt(3.0) * np.linalg.norm(per_node))

    def gradient(self, x: np.ndarray) -> np.ndarray:
        kernels = self._fused()
        if kernels is not None:
            return kernels.gradient(x)  # gather, F, P and scatter fused per element
        return self._force(self.material.dpsi_dF(self.F(x)))

    def hessian(self, x: np.ndarray, project: bool = False) -> sp.csr_matrix:
        kernels = self._fused()
        if kernels is not None:  # tangent per element, scattered straight into the CSR data
            return kernels.hessian(x, self.space.pattern, project)
        F = self.F(x)
        C = self.material.d2psi_dF2_psd(F) if project else self.material.d2psi_dF2(F)
        return self.space.pattern.assemble(self.element_stiffness(C))

    def linearize(self, x: np.ndarray,
                  project: bool = False) -> tuple[np.ndarray, sp.spmatrix | None]:
        kernels = self._fused()
        if kernels is not None:
            return kernels.gradient(x), kernels.hessian(x, self.space.pattern, project)
        P, C = self.material.stress_and_tangent(self.F(x), project=project)
        return self._force(P), self.space.pattern.assemble(self.element_stiffness(C))

    # kernels -----------------------------------------------------------------
    def _force(self, P: np.ndarray) -> np.ndarray:
        """Assemble g_ai = sum_q P_ij dN_a,j dx."""
        s = self.space
        f_e = np.einsum("ijeq,ajeq,eq->aie", P, s.dN, s.dx, optimize=True)
        return s.scatter(f_e)

    def element_stiffness(self, C: np.ndarray) -> np.ndarray:
        """Element matrices ``(3 nloc, 3 nloc, nelems)`` from C at the quadrature points.

        K[a i, b k, e] = sum_q sum_jl dN[a, j] C[i, j, k, l] dN[b, l] dx, done
        as two contractions, T = C . dN_b then K_ab = dN_a . T_b, so the work
        is 3^4 nloc + 3^3 nloc^2 products per point instead of 3^4 nloc^2;
        only the blocks b >= a are computed and the others mirrored, since C
        has major symmetry (C_ijkl = C_klij, so K_ba = K_ab^T). Each numpy
        call works on whole slabs over all elements, written in place: this
        measured 3x faster than ``np.einsum`` on the same contractions.
        """
        s = self.space
        nl = s.nloc
        ne, nq = s.dx.shape
        T = np.empty((3, 3, 3, nl, ne))  # T[i, j, k, b]
        tmp3 = np.empty((3, 3, 3, ne))
        K = np.empty((nl, 3, nl, 3, ne))  # K[a, i, b, k]
        for q in range(nq):
            Cq = np.multiply(C[..., q], s.dx[:, q], order="C")  # fold the weight in once
            dN = s.dN[..., q]  # (nloc, 3, ne)
            for b in range(nl):
                np.multiply(Cq[:, :, :, 0], dN[b, 0], out=T[:, :, :, b])
                for l in (1, 2):
                    np.multiply(Cq[:, :, :, l], dN[b, l], out=tmp3)
                    T[:, :, :, b] += tmp3
            for a in range(nl):
                S = T[:, 0, :, a:] * dN[a, 0]  # S[i, k, b - a]
                S += T[:, 1, :, a:] * dN[a, 1]
                S += T[:, 2, :, a:] * dN[a, 2]
                if q == 0:
                    K[a, :, a:] = S.transpose(0, 2, 1, 3)
                else:
                    K[a, :, a:] += S.transpose(0, 2, 1, 3)
        for a in range(nl - 1):  # K[b, k, a, i] = K[a, i, b, k] for b > a
            K[a + 1 :, :, a] = K[a, :, a + 1 :].transpose(1, 2, 0, 3)
        return K.reshape(3 * nl, 3 * nl, ne)
