"""Materials from their energy alone: ``fe.material_from_energy(psi, **params)``.

The user writes the strain-energy density ``psi`` (J/m^3) as a Python function,
with :mod:`fe.math <fem_elastic.materials.energy_math>` for ``log``, ``exp``,
``sqrt``, ..., in one of two forms, told apart by the names of its first
arguments:

- ``psi(I1, I2, J, **params)``: an isotropic energy of the invariants of the
  right Cauchy-Green tensor ``C = F^T F``: ``I1 = tr C``,
  ``I2 = 1/2 ((tr C)^2 - tr C^2)``, ``J = det F`` (signed: ``J <= 0`` is an
  inverted element);
- ``psi(F, **params)``: any energy of the deformation gradient, ``F`` a 3x3
  matrix (``F[i, j]``, ``F.T @ F``, ``fe.math.det(F)``, ``fe.math.trace(...)``).

Its first and second derivatives are derived symbolically with sympy and
printed as straight-line numpy code (:mod:`.codegen`), vectorised over the
quadrature points. The result is an :class:`EnergyMaterial`, a
:class:`~fem_elastic.materials.Material` like the hand-written ones, usable in
``fe.ElasticBody``, ``fe.solve_static`` and every integrator (it takes the
numpy path: the fused numba kernels are registered for the built-in classes).

Stress and tangent of the invariant form, with the derivatives ``psi_1``,
``psi_2``, ``psi_J`` (and ``psi_ab``) generated from ``psi``:

    P = 2 psi_1 F + 2 psi_2 (I1 F - F C) + psi_J cof F,
    dP/dF = sum_ab psi_ab G_a (x) G_b + (2 psi_1 + 2 psi_2 I1) d_ik d_jl
            + 2 psi_2 (2 F (x) F - d_ik C_lj - F_il F_kj - B_ik d_jl) + psi_J d(cof F)/dF,

``G = (2 F, 2 (I1 F - F C), cof F)`` the gradients of the invariants, ``B = F F^T``.
Its PSD projection goes through the singular-value eigensystem of
:mod:`.isotropic` (clamping eigenvalues of a 3x3 block and six 2x2 blocks),
in closed form from the same derivatives: with ``s`` the signed singular
values and ``(i, j, k)`` a pair and its third index,
``lam_twist = 2 psi_1 + 2 psi_2 (s_k^2 + s_i s_j) + psi_J s_k`` and
``lam_flip = 2 psi_1 + 2 psi_2 (s_k^2 - s_i s_j) - psi_J s_k``.
An energy of F is differentiated entry by entry (9 + 45 expressions); its
projection eigen-decomposes the 9x9 tangent at each point that is not
already PSD (``numpy.linalg.eigh``, a few microseconds a point): the
invariant form is the faster one for isotropic energies.

Where the energy is undefined (an argument of ``log`` ``<= 0``, e.g. ``log(J)``
of an inverted element, or the base of a fractional power ``< 0``), or its
value leaves the float range, ``psi`` is ``+inf`` (a line search backs off)
and ``P`` and the tangents are NaN, as for
:class:`~fem_elastic.materials.NeoHookean`. Unlike the hand-written
Neo-Hookean, which rescales ``F`` where ``J`` itself over- or underflows
(``|F| ~ 1e110``), a generated energy is ``+inf`` there too.

References for the example energies (:mod:`.energies`): the Neo-Hookean of
Bonet and Wood (2008), the stable Neo-Hookean of Smith, de Goes and Kim
(2018, their eq. 14, log-free), and the compressible Neo-Hookean of deal.II's
step-44 tutorial (Pelteret and McBride) and its "Quasi-static finite-strain
compressible elasticity" Cook's-membrane code-gallery program,
``psi = mu/2 (J^(-2/3) I1 - 3) + kappa/4 (J^2 - 1 - 2 ln J)``.
"""

from __future__ import annotations

import inspect
import math
import warnings
import weakref
from dataclasses import dataclass
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Literal, overload

import numpy as np

from ..errors import InvalidParameter
from . import codegen
from .base import (
    Material,
    _add_cofactor_derivative,
    _add_identity_term,
    _add_outer,
    _check_real,
    _cofactor,
    _det,
    _flat,
    _right_cauchy_green,
    elastic_constants,
)
from .isotropic import PAIRS, project_psd, project_psd_9x9

__all__ = ["EnergyMaterial", "material_from_energy"]

_FORMS = "psi(F, <params>) (an energy of the deformation gradient) or psi(I1, I2, J, <params>) " \
    "(of the invariants of C = F^T F)"


def material_from_energy(psi: Callable[..., Any], **params: float) -> EnergyMaterial:
    """A material from its strain-energy density alone; its derivatives are generated.

    Parameters
    ----------
    psi : callable
        The energy density (J/m^3) as a Python function whose first arguments
        are named either ``F`` (the deformation gradient, a 3x3 matrix) or
        ``I1, I2, J`` (the invariants of ``C = F^T F``: ``tr C``,
        ``1/2 ((tr C)^2 - tr C^2)`` and ``det F``), and whose other arguments
        are its named parameters. Written with the operators ``+ - * / **``
        and ``fe.math`` (``fe.math.log``, ``fe.math.exp``, ``fe.math.sqrt``, ...;
        ``fe.math.det``, ``fe.math.trace`` of F), not ``math`` or ``numpy``
        functions. It should be zero and stress-free at ``F = I`` (a warning
        says when it is not stress-free).
    **params : float
        A value for every parameter of ``psi`` without a default (its units are
        the user's; Lame-like moduli in Pa for an energy in J/m^3).

    Returns
    -------
    EnergyMaterial
        A :class:`~fem_elastic.materials.Material`: ``psi``, ``dpsi_dF``,
        ``d2psi_dF2`` and ``d2psi_dF2_psd`` on ``(3, 3, ...)`` batches, and
        ``mu``, ``lam``, ``K``, ``E``, ``nu`` of its linearization at ``F = I``.

    Raises
    ------
    fem_elastic.InvalidParameter
        ``psi``'s arguments are not named as above, a parameter is missing or
        unknown or not a finite number, ``psi`` cannot be evaluated on symbols
        (a ``math``/``numpy`` function) or does not return one scalar, or its
        linearization at rest is not a stable solid (``mu <= 0`` or ``K <= 0``).
    fem_elastic.MissingDependency
        sympy is not installed (``pip install "fem_elastic[energy]"``).

    Examples
    --------
    The Neo-Hookean energy of :class:`fe.NeoHookean`, from its invariants:

    >>> import numpy as np
    >>> import fem_elastic as fe
    >>> m = fe.material_from_energy(
    ...     lambda I1, I2, J, mu, lam: mu/2*(I1 - 3) - mu*fe.math.log(J) + lam/2*fe.math.log(J)**2,
    ...     mu=1e6, lam=2e6)
    >>> F = np.diag([1.1, 0.95, 1.0])
    >>> ref = fe.NeoHookean(mu=1e6, lam=2e6)
    >>> bool(np.allclose(m.dpsi_dF(F), ref.dpsi_dF(F), rtol=1e-12, atol=1e-6))
    True
    >>> float(m.psi(np.diag([1.0, 1.0, -1.0])))          # log J of an inverted element
    inf
    >>> m.mu, m.lam                                        # its linearization at rest
    (1000000.0, 2000000.0)

    An energy of F, and the log-free stable Neo-Hookean of :mod:`fem_elastic.materials.energies`:

    >>> svk = fe.material_from_energy(
    ...     lambda F, mu, lam: mu*fe.math.trace((F.T@F - np.eye(3))**2)/4
    ...                        + lam/8*(fe.math.trace(F.T@F) - 3)**2, mu=1e6, lam=2e6)
    >>> bool(np.allclose(svk.dpsi_dF(F), fe.StVK(mu=1e6, lam=2e6).dpsi_dF(F)))
    True
    >>> snh = fe.material_from_energy(fe.energies.stable_neo_hookean, mu=1e6, lam=2e6)
    >>> bool(np.isfinite(snh.psi(np.diag([1.0, 1.0, -1.0]))))   # no log J: finite through inversion
    True
    """
    if not callable(psi):
        raise InvalidParameter(
            f"material_from_energy needs the energy as a function, {_FORMS}; got {psi!r}."
        )
    form, _, param_names, defaults = _signature(psi)
    values = _parameters(psi, param_names, defaults, params)
    return EnergyMaterial(psi, form, values)


def _name(psi) -> str:
    return getattr(psi, "__qualname__", None) or type(psi).__name__


def _signature(psi):
    """``(form, variable names, parameter names, defaults)`` of psi, or InvalidParameter."""
    try:
        sig = inspect.signature(psi)
    except (TypeError, ValueError) as err:
        raise InvalidParameter(
            f"material_from_energy cannot read the arguments of {psi!r} ({err}): give a Python "
            f"function, {_FORMS}."
        ) from err
    names, defaults = [], {}
    for p in sig.parameters.values():
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            raise InvalidParameter(
                f"the energy {_name(psi)}{sig} takes *args or **kwargs: name every argument, "
                f"{_FORMS}."
            )
        names.append(p.name)
        if p.default is not p.empty:
            defaults[p.name] = p.default
    if names[:1] == ["F"]:
        form, variables = "F", names[:1]
    elif names[:3] == list(codegen.INVARIANTS):
        form, variables = "invariants", names[:3]
    else:
        raise InvalidParameter(
            f"the energy {_name(psi)}{sig} must be {_FORMS}: its first arguments are named "
            f"{tuple(names[:3])}. Rename them (e.g. lambda I1, I2, J, mu, lam: ...)."
        )
    params = names[len(variables):]
    for p in list(sig.parameters.values())[len(variables):]:
        if p.kind is p.POSITIONAL_ONLY:
            raise InvalidParameter(
                f"the parameter {p.name} of the energy {_name(psi)}{sig} is positional-only: "
                "parameters are passed by name, remove the '/'."
            )
    clash = [n for n in params if n in ("F", "I1", "I2", "J")]
    if clash:
        raise InvalidParameter(
            f"the energy {_name(psi)}{sig} mixes the two forms ({clash} among its parameters): "
            f"it is {_FORMS}, not both."
        )
    return form, variables, params, defaults


def _parameters(psi, names, defaults, given) -> dict:
    unknown = [n for n in given if n not in names]
    if unknown:
        raise InvalidParameter(
            f"the energy {_name(psi)} has no parameter {', '.join(unknown)}: its parameters are "
            f"{names}. Pass each of them by name, e.g. material_from_energy(psi, "
            + ", ".join(f"{n}=..." for n in names) + ")."
        )
    missing = [n for n in names if n not in given and n not in defaults]
    if missing:
        raise InvalidParameter(
            f"the energy {_name(psi)} needs a value for {', '.join(missing)}: pass "
            + ", ".join(f"{n}=..." for n in missing)
            + f" to material_from_energy (its parameters are {names})."
        )
    values = {}
    for n in names:
        v = given.get(n, defaults.get(n))
        _check_real(n, v)
        values[n] = float(v)
    return values


# -- the derivation, cached per energy function ----------------------------------------------
_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


class _Compiled:
    """The generated numpy functions of one energy (see :func:`_compile`)."""

    key: tuple  # (form, parameter names) it was compiled for
    derivation: Any  # the codegen.derive result
    psi: Any  # the generated functions (codegen.compile_functions)
    P: Any
    C: Any
    PC: Any
    d1: Any
    d2: Any
    zero1: list  # (invariant form) which first / second derivatives vanish identically
    zero2: list
    uses: dict[int, set[str]]  # the invariants each derivative order reads


def _compiled(psi, form, param_names):
    try:
        hit = _CACHE.get(psi)
    except TypeError:  # not weak-referenceable (a builtin, some callables)
        hit = None
    if hit is not None and hit.key == (form, tuple(param_names)):
        return hit
    compiled = _compile(psi, form, param_names)
    try:
        _CACHE[psi] = compiled
    except TypeError:
        pass
    return compiled


def _compile(psi, form, param_names) -> _Compiled:
    sympy = codegen.require_sympy()
    d = codegen.derive(psi, form, list(param_names), f"the energy {_name(psi)}")
    c = _Compiled()
    c.key = (form, tuple(param_names))
    c.derivation = d
    make = codegen.compile_functions
    if form == "F":
        inputs = [(v, f"F[{k // 3}, {k % 3}]") for k, v in enumerate(d.variables)]
        P_out = [(f"out[{a // 3}, {a % 3}] = ", g) for a, g in enumerate(d.gradient)]
        C_out = [(f"outC[{a // 3}, {a % 3}, {b // 3}, {b % 3}] = ", d.hessian[(a, b)])
                 for a, b in codegen.PAIRS9]
        c.psi = make(sympy, "psi", ["F", "out"], inputs, d.params, [("out[...] = ", d.psi)], d.domain)
        c.P = make(sympy, "dpsi_dF", ["F", "out"], inputs, d.params, P_out, d.domain)
        c.C = make(sympy, "d2psi_dF2", ["F", "outC"], inputs, d.params, C_out, d.domain)
        c.PC = make(sympy, "stress_and_tangent", ["F", "out", "outC"], inputs, d.params,
                    P_out + C_out, d.domain)
    else:
        inputs = [(v, name) for v, name in zip(d.variables, codegen.INVARIANTS)]
        header = list(codegen.INVARIANTS)
        hess = [d.hessian[(a, b)] for a in range(3) for b in range(a, 3)]
        c.zero1 = [g == 0 for g in d.gradient]
        c.zero2 = [h == 0 for h in hess]
        c.psi = make(sympy, "psi", header, inputs, d.params, [("return", d.psi)], d.domain)
        c.d1 = make(sympy, "dpsi", header, inputs, d.params, [("return", g) for g in d.gradient],
                    d.domain)
        c.d2 = make(sympy, "d2psi", header, inputs, d.params,
                    [("return", g) for g in d.gradient] + [("return", h) for h in hess], d.domain)
        # the invariants each order reads (an order-1 term psi_a G_a needs invariant a's gradient)
        first = set().union(*(g.free_symbols for g in d.gradient))
        first |= {v for v, z in zip(d.variables, c.zero1) if not z}
        second = first | set().union(*(h.free_symbols for h in hess))
        c.uses = {k: {str(s) for s in v} for k, v in ((0, d.psi.free_symbols), (1, first), (2, second))}
    return c


#: index pairs (a, b), a <= b, of the invariants' 3x3 Hessian in the order of ``d2``'s outputs
_H3 = [(a, b) for a in range(3) for b in range(a, 3)]


@dataclass(frozen=True, init=False, repr=False, eq=False)
class EnergyMaterial(Material):
    """A material generated from its energy by :func:`material_from_energy`.

    Attributes
    ----------
    energy : callable
        The user's ``psi``.
    form : str
        ``"invariants"`` (``psi(I1, I2, J, ...)``) or ``"F"`` (``psi(F, ...)``).
    params : dict
        The parameters' values, by name.
    E, nu : float
        Young's modulus (Pa) and Poisson's ratio of the linearization at
        ``F = I`` (as ``mu``, ``lam`` and ``K``, in Pa): what the library's
        round-off and stiffness estimates use. For an energy of F that is not
        isotropic they average its moduli over directions.

    Examples
    --------
    >>> import fem_elastic as fe
    >>> m = fe.material_from_energy(fe.energies.cook_membrane, mu=80.194e6, kappa=1e9)
    >>> m
    EnergyMaterial(cook_membrane, mu=80194000.0, kappa=1000000000.0)
    >>> round(m.K / 1e9, 6)                                          # kappa
    1.0
    """

    energy: object
    form: str
    params: dict
    if TYPE_CHECKING:  # set in __init__ by object.__setattr__; not a dataclass field
        _code: _Compiled

    def __init__(self, energy, form: str, params: dict):
        object.__setattr__(self, "energy", energy)
        object.__setattr__(self, "form", form)
        object.__setattr__(self, "params", dict(params))
        object.__setattr__(self, "_code", _compiled(energy, form, list(params)))
        object.__setattr__(self, "_args", tuple(params.values()))
        self._linearize()

    def _linearize(self) -> None:
        """E, nu, mu, lam, K of the tangent at rest; checks it is a stable solid."""
        I = np.eye(3)[:, :, None]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            psi0 = float(self.psi(I)[0])
            P0 = self.dpsi_dF(I)[..., 0]
            C0 = self.d2psi_dF2(I)[..., 0]
        name = f"the energy {_name(self.energy)}"
        if not (math.isfinite(psi0) and np.isfinite(P0).all() and np.isfinite(C0).all()):
            raise InvalidParameter(
                f"{name} is not defined at rest (F = I: psi = {psi0!r}): an energy must be finite "
                "at the undeformed state, e.g. use log(J), not log(J - 1)."
            )
        off = [(i, j) for i in range(3) for j in range(3) if i != j]
        mu = float(np.mean([(C0[i, j, i, j] + C0[i, j, j, i]) / 2.0 for i, j in off]))
        lam = float(np.mean([C0[i, i, j, j] for i, j in off]))
        if not (mu > 0 and lam + 2.0 * mu / 3.0 > 0):
            raise InvalidParameter(
                f"{name} with {self.params} is not a stable solid at rest: its linearization at "
                f"F = I has shear modulus mu = {mu:.6g} Pa and bulk modulus K = {lam + 2 * mu / 3:.6g} "
                "Pa, both must be > 0. Check the signs and values of the parameters."
            )
        c = elastic_constants(mu=mu, lam=lam, who=name)
        object.__setattr__(self, "E", c.E)
        object.__setattr__(self, "nu", c.nu)
        self._set_constants(c)
        scale = 2.0 * mu + abs(lam)
        if np.abs(P0).max() > 1e-8 * scale:
            warnings.warn(
                f"{name} is not stress-free at rest: P(I) has entries up to "
                f"{np.abs(P0).max():.3g} Pa, so a body of it deforms under no load. A "
                "compressible energy needs a term that balances the stress of its I1 term at "
                "J = 1, e.g. - mu log(J) with mu/2 (I1 - 3).",
                UserWarning, stacklevel=4,
            )

    # identity, printing, pickling -------------------------------------------------------------
    def __repr__(self) -> str:
        inner = ", ".join([_name(self.energy)] + [f"{k}={v!r}" for k, v in self.params.items()])
        return f"{type(self).__qualname__}({inner})"

    def __eq__(self, other):
        if type(other) is not type(self):
            return NotImplemented
        return self.energy is other.energy and self.params == other.params

    def __hash__(self):
        return hash((type(self), id(self.energy), tuple(self.params.items())))

    def __reduce__(self):
        # the generated code is rebuilt from the energy (a module-level function pickles)
        return (_rebuild, (self.energy, dict(self.params)))

    @property
    def source(self) -> dict:
        """The generated numpy source of each function, by name (for reading, and debugging).

        Examples
        --------
        >>> import fem_elastic as fe
        >>> m = fe.material_from_energy(fe.energies.neo_hookean, mu=1.0, lam=1.0)
        >>> sorted(m.source)
        ['d2psi', 'dpsi', 'psi']
        """
        c = self._code
        names = ("psi", "P", "C", "PC") if self.form == "F" else ("psi", "d1", "d2")
        return {getattr(c, n).__name__: getattr(c, n).source for n in names}

    # the invariants -------------------------------------------------------------------------
    def _invariants(self, F, order):
        """I1, I2, J (None where psi's derivatives of this order do not read them), C = F^T F, cof F."""
        uses = self._code.uses[order]
        with np.errstate(over="ignore", invalid="ignore"):
            I1 = np.einsum("ijn,ijn->n", F, F) if (order > 0 or "I1" in uses or "I2" in uses) else None
            Cg = _right_cauchy_green(F) if ("I2" in uses or (order > 0 and not self._code.zero1[1])) else None
            I2 = 0.5 * (I1 * I1 - np.einsum("ijn,ijn->n", Cg, Cg)) if Cg is not None else None
            need_J = "J" in uses or (order > 0 and not self._code.zero1[2])
            K = _cofactor(F) if need_J and order > 0 else None
            J = _det(F, K) if need_J else None
        return I1, I2, J, Cg, K

    def _call(self, f, *args):
        with np.errstate(all="ignore"):
            return f(*args, *self._args)

    # the four material methods ----------------------------------------------------------------
    def psi(self, F: np.ndarray) -> np.ndarray:
        """Strain-energy density (J/m^3); ``+inf`` outside the energy's domain or the float range.

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
        >>> import fem_elastic as fe
        >>> m = fe.material_from_energy(fe.energies.neo_hookean, mu=1e6, lam=2e6)
        >>> m.psi(np.stack([np.eye(3), np.diag([1.0, 1.0, -1.0])], axis=-1))
        array([ 0., inf])
        """
        F, batch = _flat(F)
        n = F.shape[-1]
        if self.form == "F":
            out = np.empty(n)
            _, ok = self._call(self._code.psi, F, out)
        else:
            I1, I2, J, _, _ = self._invariants(F, 0)
            (value,), ok = self._call(self._code.psi, I1, I2, J)
            out = np.empty(n)
            out[...] = value
        with np.errstate(invalid="ignore"):
            total = out.sum()
        if not math.isfinite(total):  # NaN or -inf at finite F: undefined or beyond the float range
            bad = ~np.isfinite(out)
            bad &= np.isfinite(F).all(axis=(0, 1))
            out[bad] = np.inf
        if ok is not None:
            bad = ~np.asarray(ok, dtype=bool)
            if bad.any():  # outside the domain (NaN F stays NaN: garbage in)
                out[bad & np.isfinite(F).all(axis=(0, 1))] = np.inf
        return out.reshape(batch)

    def dpsi_dF(self, F: np.ndarray) -> np.ndarray:
        """First Piola-Kirchhoff stress ``P = dpsi/dF`` (Pa); NaN outside the energy's domain.

        Parameters
        ----------
        F : numpy.ndarray, shape (3, 3, ...)
            Deformation gradients.

        Returns
        -------
        P : numpy.ndarray, shape F.shape
            Stress (Pa).

        Examples
        --------
        >>> import numpy as np
        >>> import fem_elastic as fe
        >>> m = fe.material_from_energy(fe.energies.neo_hookean, mu=0.5, lam=0.0)
        >>> float(m.dpsi_dF(2.0 * np.eye(3))[0, 0])        # mu (2 - 1/2), as fe.NeoHookean
        0.75
        """
        F, batch = _flat(F)
        if self.form == "F":
            P = np.empty_like(F)
            _, ok = self._call(self._code.P, F, P)
        else:
            I1, I2, J, Cg, K = self._invariants(F, 1)
            d1, ok = self._call(self._code.d1, I1, I2, J)
            P = self._stress(F, I1, Cg, K, d1)
        _mask(P, ok)
        return P.reshape((3, 3) + batch)

    def d2psi_dF2(self, F: np.ndarray) -> np.ndarray:
        """Tangent ``dP/dF`` (Pa); NaN outside the energy's domain.

        Parameters
        ----------
        F : numpy.ndarray, shape (3, 3, ...)
            Deformation gradients.

        Returns
        -------
        C : numpy.ndarray, shape (3, 3, 3, 3) + F.shape[2:]
            ``C[i, j, k, l] = dP_ij / dF_kl`` (Pa).

        Examples
        --------
        >>> import numpy as np
        >>> import fem_elastic as fe
        >>> C = fe.material_from_energy(fe.energies.neo_hookean, mu=4e5, lam=4e5).d2psi_dF2(np.eye(3))
        >>> round(float(C[0, 0, 0, 0])), round(float(C[0, 1, 1, 0]))   # 2 mu + lam, mu
        (1200000, 400000)
        """
        return self.stress_and_tangent(F, project=False, stress=False)[1]

    def d2psi_dF2_psd(self, F: np.ndarray) -> np.ndarray:
        """Tangent projected to positive semi-definite (negative eigenvalues set to 0), Pa.

        Invariant form: through the singular-value eigensystem
        (:func:`.isotropic.project_psd`), equal to :meth:`d2psi_dF2` where that
        is already PSD. Energy of F: eigen-decomposition of the 9x9 tangent at
        the points that have a negative eigenvalue (:func:`project_psd_9x9`).

        Parameters
        ----------
        F : numpy.ndarray, shape (3, 3, ...)
            Deformation gradients.

        Returns
        -------
        C : numpy.ndarray, shape (3, 3, 3, 3) + F.shape[2:]
            Projected tangent (Pa).

        Examples
        --------
        >>> import numpy as np
        >>> import fem_elastic as fe
        >>> m = fe.material_from_energy(fe.energies.neo_hookean, mu=1.0, lam=1.0)
        >>> C = m.d2psi_dF2_psd(np.diag([0.5, 0.6, 0.7]))      # compressed: twist modes < 0
        >>> bool(np.linalg.eigvalsh(C.reshape(9, 9)).min() >= -1e-12)
        True
        """
        return self.stress_and_tangent(F, project=True, stress=False)[1]

    @overload
    def stress_and_tangent(self, F: np.ndarray, project: bool = False,
                           stress: Literal[True] = True) -> tuple[np.ndarray, np.ndarray]: ...

    @overload
    def stress_and_tangent(self, F: np.ndarray, project: bool,
                           stress: Literal[False]) -> tuple[None, np.ndarray]: ...

    @overload
    def stress_and_tangent(self, F: np.ndarray, project: bool = False, *,
                           stress: Literal[False]) -> tuple[None, np.ndarray]: ...

    def stress_and_tangent(self, F: np.ndarray, project: bool = False,
                           stress: bool = True) -> tuple[np.ndarray | None, np.ndarray]:
        """``(P, C)`` from one evaluation of the generated derivatives: what Newton needs.

        Parameters
        ----------
        F : numpy.ndarray, shape (3, 3, ...)
            Deformation gradients.
        project : bool
            Project C to positive semi-definite (as :meth:`d2psi_dF2_psd`).
        stress : bool
            Compute P too (False: ``P`` is None, the tangent alone).

        Returns
        -------
        P : numpy.ndarray, shape F.shape, or None
            Stress (Pa).
        C : numpy.ndarray, shape (3, 3, 3, 3) + F.shape[2:]
            Tangent (Pa).

        Examples
        --------
        >>> import numpy as np
        >>> import fem_elastic as fe
        >>> m = fe.material_from_energy(fe.energies.neo_hookean, mu=1.0, lam=1.0)
        >>> P, C = m.stress_and_tangent(np.eye(3)[:, :, None], project=True)
        >>> P.shape, C.shape
        ((3, 3, 1), (3, 3, 3, 3, 1))
        """
        F, batch = _flat(F)
        n = F.shape[-1]
        if self.form == "F":
            C = np.empty((3, 3, 3, 3, n))
            if stress:
                P = np.empty_like(F)
                _, ok = self._call(self._code.PC, F, P, C)
                _mask(P, ok)
            else:
                P = None
                _, ok = self._call(self._code.C, F, C)
            for a, b in codegen.PAIRS9:
                if a != b:
                    C[b // 3, b % 3, a // 3, a % 3] = C[a // 3, a % 3, b // 3, b % 3]
            _mask(C, ok)
            if project:
                C = project_psd_9x9(C)
        else:
            I1, I2, J, Cg, K = self._invariants(F, 2)
            d, ok = self._call(self._code.d2, I1, I2, J)
            P = None
            if stress:
                P = self._stress(F, I1, Cg, K, d[:3])
                _mask(P, ok)
            if project:
                C = project_psd(F, self.singular_value_hessian,
                                lambda G: self._tangent(G, I1, Cg, K, d, ok))
            else:
                C = self._tangent(F, I1, Cg, K, d, ok)
        return (None if P is None else P.reshape((3, 3) + batch)), C.reshape((3, 3, 3, 3) + batch)

    # the chain rule of the invariant form -------------------------------------------------------
    def _stress(self, F, I1, Cg, K, d1):
        z = self._code.zero1
        P = np.zeros_like(F)
        with np.errstate(all="ignore"):
            if not z[0]:
                P += (2.0 * d1[0]) * F
            if not z[1]:
                FC = np.einsum("ikn,kjn->ijn", F, Cg)
                P += (2.0 * d1[1]) * (I1 * F - FC)
            if not z[2]:
                P += d1[2] * K
        return P

    def _tangent(self, F, I1, Cg, K, d, ok):
        """dP/dF of the invariant form (see the module docstring)."""
        z1, z2 = self._code.zero1, self._code.zero2
        d1, d2 = d[:3], d[3:]
        n = F.shape[-1]
        C = np.zeros((3, 3, 3, 3, n))
        with np.errstate(all="ignore"):
            # the gradients of the invariants that a non-zero second derivative multiplies
            needed = {a for r, ab in enumerate(_H3) if not z2[r] for a in ab}
            G = [2.0 * F if 0 in needed else None,
                 2.0 * (I1 * F - np.einsum("ikn,kjn->ijn", F, Cg)) if 1 in needed else None,
                 K]
            for r, (a, b) in enumerate(_H3):
                if z2[r]:
                    continue
                if a == b:
                    _add_outer(C, G[a], G[a], d2[r])
                else:
                    _add_outer(C, G[a], G[b], d2[r])
                    _add_outer(C, G[b], G[a], d2[r])
            identity = 0.0
            if not z1[0]:
                identity = identity + 2.0 * d1[0]
            if not z1[1]:
                s = 2.0 * d1[1]
                identity = identity + s * I1
                _add_outer(C, F, F, 2.0 * s)
                B = np.einsum("ikn,jkn->ijn", F, F)
                Ft = F.transpose(1, 0, 2)
                for i in range(3):
                    for j in range(3):
                        C[i, j] -= (s * Ft[j])[:, None] * F[i][None, :]  # F_il F_kj as (k, l)
                        for q in range(3):
                            C[i, j, i, q] -= s * Cg[q, j]
                            C[i, j, q, j] -= s * B[i, q]
            if not z1[2]:
                _add_cofactor_derivative(C, F, np.broadcast_to(d1[2], (n,)))
            if not (isinstance(identity, float) and identity == 0.0):
                _add_identity_term(C, identity)
        _mask(C, ok)
        return C

    def singular_value_hessian(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Eigensystem of the Hessian of an invariant-form energy from its signed singular values.

        ``H_ab = sum_pq psi_pq g_pa g_qb + 2 psi_1 d_ab + psi_2 h2_ab + psi_J hJ_ab`` with
        ``g = (2 s_a, 2 s_a (I1 - s_a^2), J / s_a)``, ``h2_aa = 2 (I1 - s_a^2)``,
        ``h2_ab = 4 s_a s_b``, ``hJ_ab = s_k`` (``a != b``, ``k`` the third index), and
        the twist and flip eigenvalues of the module docstring. No division by s.

        Parameters
        ----------
        s : numpy.ndarray, shape (3, N)
            Signed singular values.

        Returns
        -------
        d2psi_ds2 : numpy.ndarray, shape (3, 3, N)
        lam_twist, lam_flip : numpy.ndarray, shape (3, N)
            Pa, rows for the pairs (0, 1), (0, 2), (1, 2).

        Examples
        --------
        >>> import numpy as np
        >>> import fem_elastic as fe
        >>> m = fe.material_from_energy(fe.energies.neo_hookean, mu=1e6, lam=4e5)
        >>> H, lt, lf = m.singular_value_hessian(np.ones((3, 1)))
        >>> round(float(lt[0, 0])), round(float(lf[0, 0]))          # 0 and 2 mu at rest
        (0, 2000000)
        """
        if self.form != "invariants":
            raise InvalidParameter(
                "singular_value_hessian needs an energy of the invariants I1, I2, J; an energy of "
                "F has no closed-form eigensystem (its projection eigen-decomposes the 9x9 tangent)."
            )
        n = s.shape[-1]
        with np.errstate(all="ignore"):
            s2 = s * s
            I1 = s2[0] + s2[1] + s2[2]
            I2 = s2[0] * s2[1] + s2[0] * s2[2] + s2[1] * s2[2]
            J = s[0] * s[1] * s[2]
            d, ok = self._call(self._code.d2, I1, I2, J)
            d1 = [np.broadcast_to(np.asarray(v, dtype=float), (n,)) for v in d[:3]]
            d2 = [np.broadcast_to(np.asarray(v, dtype=float), (n,)) for v in d[3:]]
            Js = np.array([s[1] * s[2], s[0] * s[2], s[0] * s[1]])  # J / s_a
            g = [2.0 * s, 2.0 * s * (I1 - s2), Js]
            H = np.zeros((3, 3, n))
            for r, (p, q) in enumerate(_H3):
                if self._code.zero2[r]:
                    continue
                term = d2[r] * g[p][:, None] * g[q][None, :]
                H += term if p == q else term + term.transpose(1, 0, 2)
            for a in range(3):
                H[a, a] += 2.0 * d1[0] + 2.0 * d1[1] * (I1 - s2[a])
            lt, lf = np.empty_like(s), np.empty_like(s)
            for row, (i, j, k) in enumerate(PAIRS):
                H[i, j] += 4.0 * d1[1] * s[i] * s[j] + d1[2] * s[k]
                H[j, i] = H[i, j]
                base = 2.0 * d1[0] + 2.0 * d1[1] * s2[k]
                mixed = 2.0 * d1[1] * s[i] * s[j]
                lt[row] = base + mixed + d1[2] * s[k]
                lf[row] = base - mixed - d1[2] * s[k]
        for A in (H, lt, lf):
            _mask(A, ok)
        return H, lt, lf


def _mask(A: np.ndarray, ok) -> None:
    """NaN at the points outside the energy's domain (``ok`` False), in place."""
    if ok is not None:
        bad = ~np.asarray(ok, dtype=bool)
        if bad.any():
            A[..., bad] = np.nan


def _rebuild(energy, params):
    return material_from_energy(energy, **params)
