"""The energy projective dynamics minimises: corotated strain and volume constraints.

Projective dynamics (Bouaziz, Martin, Liu, Kavan and Pauly 2014) writes the
elastic energy as a sum of squared distances to constraint sets,

    E(x) = sum_i w_i / 2 ||A_i x - P_i(A_i x)||^2,

with ``A_i x`` the deformation gradient F of a tet (of a quadrature point)
and ``P_i`` the projection of F onto the set. Per unit reference volume this
is the energy density of this module's material,

    psi(F) = w_s / 2 ||F - R||^2 + w_v / 2 ||F - P_v(F)||^2,

with two constraints on the signed singular values ``s`` of
``F = U diag(s) V^T`` (:func:`.svd.signed_svd`; ``R = U V^T``):

- **strain**: F is a rotation, ``P_s(F) = R`` (the polar decomposition);
  ``||F - R||^2 = sum (s_i - 1)^2``;
- **volume**: the mean principal stretch ``m = (s_0 + s_1 + s_2) / 3`` lies
  in ``[sigma_min, sigma_max]``. The projection shifts the three singular
  values by the same ``delta = m - clip(m, sigma_min, sigma_max)``,
  ``P_v(F) = U diag(s - delta) V^T = F - delta R``, the nearest such matrix;
  ``||F - P_v(F)||^2 = 3 delta^2``. To first order ``3 (m - 1)`` is the
  volume change ``det F - 1``, so ``[1, 1]`` (the default) is volume
  preservation and a wider band lets the volume change freely inside it (the
  paper's ranges).

Weights from (E, nu): at small strain ``F = I + eps``, ``sum (s_i - 1)^2``
is ``|sym eps|^2`` and ``3 delta^2 = (tr eps)^2 / 3``, so ``w_s = 2 mu`` and
``w_v = 3 lam`` make psi linearize to linear elasticity with the Lamé
parameters of (E, nu): ``mu |sym eps|^2 + lam / 2 (tr eps)^2``. An element
carries ``w_i = (2 mu, 3 lam) x V_e``. Then

    psi = mu sum (s_i - 1)^2 + 9 lam / 2 delta^2,
    P   = 2 mu (F - R) + 3 lam delta R,

which with ``sigma_min = sigma_max = 1`` (``delta = (tr S - 3) / 3``) is the
fixed corotated energy :class:`.corotated.Corotated` to round-off: projective
dynamics on a corotated body minimises that body's own energy. The squared
distance ``1/2 ||F - P(F)||^2`` to each set has gradient ``F - P(F)`` (the
projection is the nearest point), which is why the local/global iteration
converges to the implicit-Euler step of this energy.

The tangent comes from the singular-value eigensystem
(:func:`.isotropic.isotropic_hessian`): ``H_ab = 2 mu d_ab + lam`` outside
the band (``2 mu d_ab`` inside), ``lam_flip = 2 mu``, ``lam_twist = (psi_i +
psi_j) / (s_i + s_j)`` with ``psi_i = 2 mu (s_i - 1) + 3 lam delta``, its
denominator clamped at :data:`.corotated.TWIST_EPS` as for the corotated
material. At the band's edges psi is once, not twice, differentiable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidParameter
from .base import _flat, _overflow_to_inf
from .corotated import Corotated
from .svd import signed_svd

__all__ = ["ProjectiveCorotated"]


@dataclass(frozen=True, init=False, repr=False)
class ProjectiveCorotated(Corotated):
    """Strain (``F -> R``) and volume (mean stretch in a band) constraints, as a material.

    ``psi = mu ||F - R||^2 + 3 lam / 2 ||F - P_v(F)||^2``: the energy of
    :class:`fe.ProjectiveDynamics`, weights ``2 mu`` and ``3 lam`` per unit
    volume (see the module notes for the derivation). With the default band
    ``[1, 1]`` it equals :class:`fe.Corotated`; ``fe.ImplicitEuler`` on a
    body of this material is the reference projective dynamics converges to.

    Parameters
    ----------
    E : float
        Young's modulus (Pa), > 0.
    nu : float
        Poisson's ratio, -1 < nu < 0.5 (projective dynamics needs nu >= 0, a
        non-negative volume weight). Or, as for every material, ``mu`` with
        ``lam`` or ``K`` (keywords) where the base class takes them.
    sigma_min, sigma_max : float
        Band of the mean principal stretch in which the volume term stores no
        energy, ``0 < sigma_min <= 1 <= sigma_max`` (keywords).

    Examples
    --------
    >>> import numpy as np
    >>> m = ProjectiveCorotated(E=1.0e6, nu=0.3)
    >>> F = np.array([[1.1, 0.2, 0.0], [0.0, 0.9, 0.1], [0.05, 0.0, 1.2]])
    >>> bool(np.isclose(m.psi(F), Corotated(E=1.0e6, nu=0.3).psi(F), rtol=1e-12))
    True
    >>> band = ProjectiveCorotated(E=1.0e6, nu=0.3, sigma_min=0.9, sigma_max=1.1)
    >>> bool(np.isclose(band.psi(1.05 * np.eye(3)), m.mu * 3 * 0.05 ** 2))   # no volume energy inside
    True
    >>> H, lt, lf = ProjectiveCorotated(E=1.0e6, nu=0.25, sigma_min=0.9, sigma_max=1.1
    ...                                 ).singular_value_hessian(np.ones((3, 1)))
    >>> round(float(H[0, 1, 0])), round(float(lf[0, 0]))    # inside the band: no lam
    (0, 800000)

    Stress and tangent are :class:`fe.Corotated`'s with its volume term
    ``lam (sum s - 3)`` replaced by ``3 lam delta``, and that term's stiffness
    ``lam`` by zero inside the band.
    """

    sigma_min: float = 1.0
    sigma_max: float = 1.0

    def __init__(self, E: float | None = None, nu: float | None = None, *,
                 mu: float | None = None, lam: float | None = None, K: float | None = None,
                 sigma_min: float = 1.0, sigma_max: float = 1.0) -> None:
        super().__init__(E, nu, mu=mu, lam=lam, K=K)
        for name, value in (("sigma_min", sigma_min), ("sigma_max", sigma_max)):
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) \
                    or not math.isfinite(value):
                raise InvalidParameter(f"{name} must be a finite number, got {value!r}.")
            object.__setattr__(self, name, float(value))
        if not 0.0 < self.sigma_min <= 1.0 <= self.sigma_max:
            raise InvalidParameter(
                "the volume band must hold the rest shape: 0 < sigma_min <= 1 <= sigma_max, got "
                f"sigma_min = {sigma_min!r}, sigma_max = {sigma_max!r} (e.g. 1.0, 1.0 for volume "
                "preservation, 0.95, 1.05 to let the volume change by about 15 % freely)."
            )

    def __repr__(self) -> str:
        text = super().__repr__()
        if (self.sigma_min, self.sigma_max) != (1.0, 1.0):
            text = f"{text[:-1]}, sigma_min={self.sigma_min!r}, sigma_max={self.sigma_max!r})"
        return text

    # the volume projection --------------------------------------------------------------
    def volume_shift(self, s: np.ndarray) -> np.ndarray:
        """``delta = m - clip(m, sigma_min, sigma_max)`` of signed singular values ``s`` (3, ...).

        The volume projection is ``P_v(F) = U diag(s - delta) V^T = F - delta R``.

        Examples
        --------
        >>> import numpy as np
        >>> round(float(ProjectiveCorotated(E=1.0, nu=0.3).volume_shift(np.array([1.3, 1.0, 1.0]))), 12)
        0.1
        """
        m = (s[0] + s[1] + s[2]) / 3.0
        return m - np.clip(m, self.sigma_min, self.sigma_max)

    def _volume_stress(self, s):
        """The volume term's ``dpsi/ds_i`` (the same for each i): ``3 lam delta`` (Pa)."""
        return 3.0 * self.lam * self.volume_shift(s)

    def _volume_stiffness(self, s):
        """The volume term's ``d2psi/ds_a ds_b``: ``lam`` where it is active, else 0 (Pa).

        Active where the mean stretch is not strictly inside the band: on a band's
        edge the second derivative from outside is taken; a band of zero width (the
        default) is active everywhere.
        """
        m = (s[0] + s[1] + s[2]) / 3.0
        return self.lam * (1.0 - ((m > self.sigma_min) & (m < self.sigma_max)).astype(float))

    # the four material methods ----------------------------------------------------------
    def psi(self, F: np.ndarray) -> np.ndarray:
        """Energy density ``mu sum (s_i - 1)^2 + 9 lam / 2 delta^2`` (J/m^3).

        Parameters
        ----------
        F : numpy.ndarray, shape (3, 3, ...)
            Deformation gradients.

        Returns
        -------
        psi : numpy.ndarray, shape F.shape[2:]
            Energy density (J/m^3).

        Examples
        --------
        >>> import numpy as np
        >>> float(ProjectiveCorotated(E=1.0, nu=0.0).psi(np.diag([2.0, 1.0, 1.0])))  # mu = 0.5
        0.5
        """
        F, batch = _flat(F)
        _, s, _ = signed_svd(F)
        d = s - 1.0
        delta = self.volume_shift(s)
        with np.errstate(invalid="ignore", over="ignore"):
            out = self.mu * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) + 4.5 * self.lam * delta * delta
        return _overflow_to_inf(out, F).reshape(batch)

    # what the local step of projective dynamics needs -----------------------------------
    def projections(self, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(R, delta)`` at each F (3, 3, N): the strain target R and volume shift delta.

        The volume target is ``F - delta R``; the combined weighted target of one
        point, ``2 mu R + 3 lam (F - delta R)``, is what the global step gathers.

        Examples
        --------
        >>> import numpy as np
        >>> R, delta = ProjectiveCorotated(E=1.0, nu=0.3).projections(1.2 * np.eye(3)[:, :, None])
        >>> bool(np.allclose(R[..., 0], np.eye(3))), round(float(delta[0]), 12)
        (True, 0.2)
        """
        U, s, V = signed_svd(F)
        return np.einsum("ian,jan->ijn", U, V), self.volume_shift(s)
