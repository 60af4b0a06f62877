"""Per-tet fields of a deformed body: von Mises stress and strain-energy density.

What a VTU frame colours a mesh by, one value per (vertex) tet of the mesh:

``von_mises`` (Pa)
    The von Mises equivalent stress ``sqrt(3/2 s:s)``, ``s = sigma - tr(sigma)/3 I``,
    of the Cauchy (true) stress ``sigma``.
``energy_density`` (J/m^3)
    Strain energy per unit REFERENCE volume, so that
    ``sum_t energy_density_t V_t`` (``V_t`` the reference tet volume) is the
    body's elastic energy.

FEM bodies (:class:`~fem_elastic.physics.elastic_body.ElasticPotential`, P1 or P2)
--------------------------------------------------------------------------
At each quadrature point, with ``P = dpsi_dF(F)`` the first Piola-Kirchhoff
stress and ``J = det F``,

    sigma = P F^T / J.

For a frame-indifferent material sigma is symmetric; for
:class:`~fem_elastic.materials.LinearElastic`, which is not, only its symmetric
part enters the von Mises stress (and a rigid rotation gives a spurious
stress of order ``E theta^2``, as the material itself does). The quadrature
values of von Mises and of ``psi`` are averaged over each tet with the
quadrature weights (``dx``, reference volume): for P1 tets there is one
point and this is the value there. A tet with ``J <= 0`` at any quadrature
point is inverted: its von Mises stress is NaN (a Cauchy stress does not
exist there), and its energy density is whatever the material gives
(``+inf`` for :class:`~fem_elastic.materials.NeoHookean`).

Mass-spring bodies (:class:`~fem_elastic.physics.springs.SpringPotential`)
------------------------------------------------------------------
A spring on edge ``e`` is shared by the tets around that edge; each tet
``t`` takes the share ``w_et = V_t / sum_{t' ∋ e} V_t'`` of it (by
reference volume). Then

    energy_density_t = (1 / V_t) sum_{e in t} w_et E_e,     E_e = 1/2 k_e (l_e - l0_e)^2,

so ``sum_t energy_density_t V_t`` is the springs' energy exactly, and the
stress is the network's virial (Cauchy) stress

    sigma_t = (1 / v_t) sum_{e in t} w_et f_e (x) l_e,

with ``l_e`` the current edge vector, ``f_e = k_e (l_e - l0_e) l_e / |l_e|``
the spring's tension force along it, and ``v_t`` the CURRENT tet volume. Summed
over the tets, ``sum_t v_t sigma_t = sum_e f_e (x) l_e``: the classical
virial of the network, whose volume average is the mean stress a
homogeneously deformed network carries across any section. A tet with
``v_t <= 0`` (inverted) gets NaN von Mises stress.
"""

from __future__ import annotations

import logging

from typing import TYPE_CHECKING, cast

import numpy as np

from .elastic_body import ElasticPotential
from ..errors import InvalidParameter
from ..materials.base import _det
from ..geometry.mesh import _signed_volumes
from .springs import SpringPotential

if TYPE_CHECKING:  # for annotations only (the model imports this module's neighbours)
    from .model import Model
    from .multibody import AnyModel, MultiBody

__all__ = ["CellFields", "cell_fields", "von_mises"]

log = logging.getLogger(__name__)

#: (i, j) index pairs of the six independent components of a symmetric 3x3 tensor.
_SYM = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))

#: The six local edges (pairs of local vertices) of a tet.
_TET_EDGES = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))


def _von_mises_sym(s00, s11, s22, s01, s12, s02):
    """von Mises stress from the six components of a symmetric stress (any unit, same out)."""
    return np.sqrt(
        0.5 * ((s00 - s11) ** 2 + (s11 - s22) ** 2 + (s22 - s00) ** 2)
        + 3.0 * (s01 ** 2 + s12 ** 2 + s02 ** 2)
    )


def von_mises(sigma: np.ndarray) -> np.ndarray:
    """von Mises equivalent stress ``sqrt(3/2 s:s)`` of stresses in scikit-fem's layout.

    ``s`` is the deviator of the symmetric part of ``sigma``: for a symmetric
    stress this is the usual ``sqrt(((s1-s2)^2 + (s2-s3)^2 + (s3-s1)^2) / 2)``
    of the principal stresses; under uniaxial stress ``sigma_xx`` it is ``|sigma_xx|``.

    Parameters
    ----------
    sigma : array_like, shape (3, 3, ...)
        Stress tensors (Pa), the two tensor indices first.

    Returns
    -------
    numpy.ndarray, shape sigma.shape[2:]
        von Mises stress (Pa), >= 0; NaN where sigma has a NaN.

    Examples
    --------
    >>> import numpy as np
    >>> float(von_mises(np.diag([5.0, 0.0, 0.0])))          # uniaxial: |sigma_xx|
    5.0
    >>> float(von_mises(-2.0 * np.eye(3)))                  # pressure: no deviator
    0.0
    """
    sigma = np.asarray(sigma, dtype=float)
    if sigma.shape[:2] != (3, 3):
        raise InvalidParameter(
            f"von_mises needs stresses of shape (3, 3, ...), got {sigma.shape}; put the "
            "tensor indices first (scikit-fem's layout), e.g. np.moveaxis(s, (-2, -1), (0, 1))."
        )
    comps = [0.5 * (sigma[i, j] + sigma[j, i]) for i, j in _SYM]
    return _von_mises_sym(*comps)


class CellFields:
    """The per-tet fields of one model, with what depends only on the mesh computed once.

    Call it on a position vector for each frame; :func:`cell_fields` is the
    one-shot form. See the module notes for the definitions.

    Parameters
    ----------
    model : Model
        Its ``body_potential`` is an ElasticPotential (``fe.ElasticBody``, P1
        or P2) or a SpringPotential (``fe.MassSpring``).

    Raises
    ------
    InvalidParameter
        Another kind of body, or a spring that lies on no tet edge (its
        energy cannot be given to a tet).

    Examples
    --------
    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1e3,
    ...                  body=fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3)))
    >>> fields = CellFields(model)
    >>> out = fields(model.X)                                  # the rest state
    >>> sorted(out), float(out["von_mises"].max()), float(out["energy_density"].max())
    (['energy_density', 'von_mises'], 0.0, 0.0)
    """

    def __init__(self, model: AnyModel) -> None:
        self.model = model
        parts = getattr(model, "models", None)
        if parts is not None:  # a fe.MultiBody: each body's fields, the bodies' tets stacked
            self._parts = [CellFields(m) for m in parts]
            self.potential = model.body_potential
            self.volume: np.ndarray = np.concatenate([f.volume for f in self._parts])
            self._evaluate = self._stacked
            return
        space = cast("Model", model).space  # a Model here (a MultiBody returned above)
        self.potential = pot = model.body_potential
        #: ``(n_tets,)`` reference volume of each tet (m^3).
        self.volume = np.asarray(space.dx, dtype=float).sum(axis=1)
        if isinstance(pot, ElasticPotential):
            self._evaluate = self._fem
        elif isinstance(pot, SpringPotential):
            self._evaluate = self._springs
            self._spring_setup(space)
        else:
            raise InvalidParameter(
                f"cell fields are defined for fe.ElasticBody and fe.MassSpring bodies, got a "
                f"body potential of type {type(pot).__name__}."
            )

    def _check(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.shape != (self.model.space.ndofs,):
            raise InvalidParameter(
                f"x must be a flat vector of the model's {self.model.space.ndofs} DOF positions "
                f"(state.x), got shape {x.shape}."
            )
        return x

    def __call__(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Fields at the flat DOF positions ``x`` (m).

        Parameters
        ----------
        x : numpy.ndarray
            ``(ndofs,)`` flat DOF positions (m), e.g. ``state.x``.

        Returns
        -------
        dict
            ``"von_mises"`` (Pa; NaN on inverted tets) and ``"energy_density"``
            (J/m^3 of reference volume), each ``(n_tets,)``.
        """
        x = self._check(x)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            return self._evaluate(x)

    def stress(self, x: np.ndarray) -> np.ndarray:
        """Per-tet Cauchy stress ``(3, 3, n_tets)`` (Pa), symmetric; NaN on inverted tets.

        FEM bodies: the symmetric part of ``P F^T / J`` averaged over the
        tet's quadrature points with their weights (the value itself on P1
        tets). Spring bodies: the network's virial stress (module notes).
        ``von_mises`` of :meth:`__call__` is the quadrature average of the
        pointwise von Mises stress, which on P2 tets is not the von Mises
        stress of this average.

        Parameters
        ----------
        x : numpy.ndarray
            ``(ndofs,)`` flat DOF positions (m).

        Returns
        -------
        numpy.ndarray
            ``(3, 3, n_tets)`` stress (Pa).
        """
        x = self._check(x)
        if getattr(self, "_parts", None) is not None:
            return np.concatenate([f.stress(xb) for f, (_, xb) in zip(self._parts, cast("MultiBody", self.model)._split(x))], axis=2)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            if isinstance(self.potential, ElasticPotential):
                sig, J, _ = self._fem_parts(x)
                dx = self.potential.space.dx
                comps = [np.einsum("eq,eq->e", c, dx) / self.volume for c in sig]
                bad = ~np.all(J > 0.0, axis=1)
            else:
                comps, v, _ = self._spring_parts(x)
                bad = ~(v > 0.0)
        out = np.empty((3, 3, self.volume.size))
        for c, (i, j) in zip(comps, _SYM):
            out[i, j] = out[j, i] = c
        out[:, :, bad] = np.nan
        return out

    def _stacked(self, x):
        """A MultiBody's fields: each body's, concatenated in the order of its tets, and ``body``.

        ``body`` (float, for VTU cell data) is the index of each tet's body in
        ``model.bodies``, which lets ParaView and the renderer tell the bodies apart.
        """
        parts = [f._evaluate(xb) for f, (_, xb) in zip(self._parts, cast("MultiBody", self.model)._split(x))]
        out = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
        out["body"] = self.model.body_of_tet.astype(float)
        return out

    # FEM ---------------------------------------------------------------------------
    def _fem_parts(self, x):
        """Cauchy stress (six ``(ne, nq)`` components), J and psi at the quadrature points."""
        pot = self.potential
        F = pot.F(x)  # (3, 3, ne, nq)
        psi = pot.material.psi(F)
        P = pot.material.dpsi_dF(F)
        J = _det(F)
        tau = np.einsum("ikeq,jkeq->ijeq", P, F)  # Kirchhoff stress J sigma = P F^T
        sigma = [0.5 * (tau[i, j] + tau[j, i]) / J for i, j in _SYM]  # its symmetric part / J
        return sigma, J, psi

    def _fem(self, x):
        dx = self.potential.space.dx  # (ne, nq), reference volume weights (m^3)
        sigma, J, psi = self._fem_parts(x)
        vm_q = _von_mises_sym(*sigma)
        inverted = ~np.all(J > 0.0, axis=1)  # NaN J counts as inverted too
        if dx.shape[1] == 1:
            vm, energy = vm_q[:, 0], psi[:, 0].copy()
        else:
            vm = np.einsum("eq,eq->e", vm_q, dx) / self.volume
            energy = np.einsum("eq,eq->e", psi, dx) / self.volume
        vm[inverted] = np.nan
        return {"von_mises": vm, "energy_density": energy}

    # springs -----------------------------------------------------------------------
    def _spring_setup(self, space):
        pot = self.potential
        nodes = (space.element_dofs[0:12:3] // 3).astype(np.int64)  # (4, ne) vertex nodes
        self._tets = nodes.T  # (ne, 4)
        nn = space.ndofs // 3
        ns = pot.edges.shape[1]
        a = np.array([e[0] for e in _TET_EDGES])
        b = np.array([e[1] for e in _TET_EDGES])
        ta, tb = nodes[a], nodes[b]  # (6, ne)
        tet_keys = np.minimum(ta, tb) * nn + np.maximum(ta, tb)
        i, j = pot.edges
        spring_keys = np.minimum(i, j) * nn + np.maximum(i, j)
        if np.unique(spring_keys).size != ns:
            raise InvalidParameter(
                "two springs join the same pair of nodes; cell fields need at most one spring "
                "per tet edge (fe.MassSpring builds exactly that)."
            )
        order = np.argsort(spring_keys)
        sorted_keys = np.append(spring_keys[order], -1)  # sentinel: never a key
        pos = np.minimum(np.searchsorted(sorted_keys[:-1], tet_keys), ns)
        on_edge = sorted_keys[pos] == tet_keys
        # (6, ne) spring on each local edge; ns (a zero row appended per frame) where the
        # tet edge carries no spring
        self._spring_of = np.where(on_edge, np.append(order, ns)[pos], ns)
        W = np.bincount(self._spring_of.ravel(),
                        weights=np.broadcast_to(self.volume, tet_keys.shape).ravel(),
                        minlength=ns + 1)[:ns]
        orphans = np.flatnonzero(W <= 0.0)
        if orphans.size:
            raise InvalidParameter(
                f"{orphans.size} springs (e.g. {orphans[:5].tolist()}) lie on no tet edge of "
                "the mesh, so their energy and stress belong to no tet; put springs on mesh "
                "edges only (fe.MassSpring does)."
            )
        #: ``(n_springs,)`` reference volume of the tets around each spring (m^3).
        self.spring_volume = W

    def _spring_parts(self, x):
        """Virial stress (six ``(ne,)`` components), current volumes v and energy density."""
        pot = self.potential
        xp = x.reshape(-1, 3)
        i, j = pot.edges
        d = np.take(xp, j, axis=0) - np.take(xp, i, axis=0)  # (ns, 3) current edge vectors
        l = np.sqrt(np.einsum("si,si->s", d, d))
        stretch = l - pot.rest_length
        # per spring, divided by W_e: its energy, and f (x) l = k (l - l0) / l d d^T
        per = np.empty((d.shape[0] + 1, 7))
        per[-1] = 0.0  # the row of tet edges without a spring
        per[:-1, 6] = 0.5 * pot.stiffness * stretch ** 2 / self.spring_volume
        c = pot.stiffness * stretch / (np.where(l > 0.0, l, 1.0) * self.spring_volume)
        for col, (a, b) in enumerate(_SYM):
            per[:-1, col] = c * d[:, a] * d[:, b]
        # sum_e w_et q_e / V_t = sum_e q_e / W_e over the tet's six edges
        tet = np.take(per, self._spring_of, axis=0).sum(axis=0)  # (ne, 7)
        v = _signed_volumes(xp, self._tets)  # current volume (m^3)
        # sigma_t = (1 / v_t) sum_e w_et (f (x) l)_e = (V_t / v_t) sum_e (f (x) l)_e / W_e
        scale = self.volume / v
        sigma = [tet[:, k] * scale for k in range(6)]
        return sigma, v, tet[:, 6].copy()

    def _springs(self, x):
        sigma, v, energy = self._spring_parts(x)
        vm = _von_mises_sym(*sigma)
        vm[~(v > 0.0)] = np.nan
        return {"von_mises": vm, "energy_density": energy}


def cell_fields(model: AnyModel, x: np.ndarray) -> dict[str, np.ndarray]:
    """Per-tet von Mises stress and strain-energy density at positions ``x``.

    See the module notes for the definitions (Cauchy stress ``P F^T / J``
    for FEM bodies, the virial stress for spring networks). To evaluate many
    frames of one model, build a :class:`CellFields` once and call it.

    Parameters
    ----------
    model : Model
        A model with an ``fe.ElasticBody`` (P1 or P2) or ``fe.MassSpring`` body.
    x : numpy.ndarray
        ``(ndofs,)`` flat DOF positions (m), e.g. ``state.x``.

    Returns
    -------
    dict of str to numpy.ndarray
        ``"von_mises"`` (Pa; NaN on inverted tets) and ``"energy_density"``
        (J/m^3 of reference volume), each ``(n_tets,)`` in ``model.mesh.t`` order.

    Examples
    --------
    A 1 % stretch along x of a linear-elastic bar, contracting laterally by nu eps:
    the Cauchy stress is uniaxial, ``E eps (1 + eps) / J = E eps / (1 - nu eps)^2``.

    >>> import numpy as np
    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1e3,
    ...                  body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.25)))
    >>> X = model.X.reshape(-1, 3)
    >>> x = (X * [1.01, 1 - 0.25 * 0.01, 1 - 0.25 * 0.01]).ravel()
    >>> out = cell_fields(model, x)
    >>> np.round(out["von_mises"][:2] / 1e4, 4)   # E eps / (1 - nu eps)^2, E eps = 1e4 Pa
    array([1.005, 1.005])
    """
    return CellFields(model)(x)
