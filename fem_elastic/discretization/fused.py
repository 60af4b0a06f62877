"""Fused numba kernels for the elastic energy and force of linear (P1) tets.

Quadratic (P2) tets have their own kernels, in :mod:`._fused_p2_kernels` (energy,
force and tangent, per quadrature point); :func:`kernels_for` hands them out for a
space of order 2 under the same switches.

The numpy path of :class:`fem_elastic.physics.elastic_body.ElasticPotential` builds
the deformation gradient of every element, then the stress of every
element, then the element forces, each as a ``(3, 3, nelems)`` or
``(12, nelems)`` array: on 150k tets most of its time goes to writing and
re-reading those temporaries. Here one pass over the elements does it all
for P1 tets, whose shape-function gradients ``dN`` are constant per element:

    F_e = I + sum_a u_a (x) dN_a,      P_e = P(F_e),      g_{a i} += V_e P_e,ij dN_a,j

(``u = x - X``, ``V_e`` the element volume), accumulating the force straight
into the global vector, and the same loop sums ``V_e psi(F_e)`` for the
energy, returning ``+inf`` at the first inadmissible element (an inverted
Neo-Hookean tet) as the numpy path does.

The pointwise materials are re-written as numba functions that repeat the
numpy modules' formulas in the same order of operations, so both paths
agree to round-off; the numpy path stays the reference and the fallback.
:class:`~fem_elastic.materials.Corotated` is not fused: its stress needs
the polar decomposition (an SVD) of every F, which its numpy module does
batched; a per-element 3x3 SVD in numba would be a second implementation
of :mod:`fem_elastic.materials.svd` to keep in step with the first.

The gradient runs on numba's threads when it has several
(``NUMBA_NUM_THREADS``; see :func:`threaded`): the elements are cut into one
part per thread, the parts' interiors (no vertex shared with another part)
scattered in parallel without atomics, the thin seams between them after,
serially. With one thread, or ``FEM_ELASTIC_NUMBA_THREADS=0``, the serial
loop runs (results independent of the thread count). The energy (its
1024-element blocks) and the volume ratios are threaded too, with the same
bits as their serial loops; the warped stiffness is serial. On the 153,600-tet beam of ``scripts/bench_step.py`` the fused gradient
takes ~10 ms against ~70 ms on the numpy path.

numba is optional (the ``fast`` extra) and imported on first use only:
``import fem_elastic`` works without it. Set ``FEM_ELASTIC_NUMBA=0`` in the
environment to force the numpy path. The kernels are compiled with
``cache=True``: the first call on a machine compiles them (~3 s), later
processes load them from ``__pycache__`` (~0.4 s with the import of numba).

Examples
--------
>>> import numpy as np
>>> import fem_elastic as fe
>>> from fem_elastic.discretization import Discretization
>>> space = Discretization(fe.beam_mesh(cells=(2, 1, 1)), order=1)
>>> material = fe.NeoHookean(E=1e6, nu=0.45)
>>> kernels = kernels_for(material, space)
>>> kernels is None or kernels.energy(space.X) == 0.0   # None without numba
True
"""

from __future__ import annotations

import logging
import os
import threading
import weakref
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from .space import Discretization
from ..materials import LinearElastic, NeoHookean, StableNeoHookean, StVK
from ..materials.base import Material

if TYPE_CHECKING:  # imported on first use only (it imports numba)
    from ._fused_p2_kernels import FusedP2

__all__ = ["available", "threaded", "kernels_for", "registry", "FusedP1", "MaterialKernels", "warped_apply",
           "tet_volume_ratios"]

#: Environment variable that switches the fused kernels off when set to ``0``.
ENV = "FEM_ELASTIC_NUMBA"
#: Environment variable that selects the serial (one-thread) gradient kernel when set to ``0``.
THREADS_ENV = "FEM_ELASTIC_NUMBA_THREADS"
#: Fewer elements than this take the serial gradient kernel whatever the thread count: their
#: serial loop (~70 ns an element, < 1.5 ms) is not worth waking threads for, which costs
#: 10-50 us on an idle machine and up to a scheduler time slice (measured: 15 ms on a 720-tet
#: beam) where other processes keep the cores busy.
MIN_THREADED_ELEMENTS = 20_000


def _lame(m: Material) -> tuple[float, float, float]:
    return (float(m.mu), float(m.lam), 0.0)


def _stable_neohookean(m: StableNeoHookean) -> tuple[float, float, float]:
    return (float(m.mu_snh), float(m.lam_snh), float(m.alpha))


#: Material class -> (prefix of its pointwise kernels ``<prefix>_psi`` and
#: ``<prefix>_P`` in :mod:`._fused_kernels`, the kernels' parameters of a
#: material). Exact classes only: a subclass may change psi.
_REGISTRY: dict[type, tuple[str, Callable[[Any], tuple[float, float, float]]]] = {
    LinearElastic: ("linear", _lame),
    StVK: ("stvk", _lame),
    NeoHookean: ("neohookean", _lame),
    StableNeoHookean: ("stable_neohookean", _stable_neohookean),
}

log = logging.getLogger(__name__)

_module = None  # the imported kernel module, once loaded
_import_error: ImportError | None = None


def _kernels():
    """The kernel module (imports numba on the first call), or None if numba is missing."""
    global _module, _import_error
    if _module is None and _import_error is None:
        try:
            from . import _fused_kernels
        except ImportError as err:  # numba (or llvmlite) not installed
            _import_error = err
            log.info("numba is not importable (%s): the elastic force and energy use numpy", err)
        else:
            _module = _fused_kernels
    return _module


def threaded() -> bool:
    """Whether the fused P1 gradient runs on numba's threads (``FEM_ELASTIC_NUMBA_THREADS`` not ``0``).

    With ``n = numba.get_num_threads() > 1`` (``NUMBA_NUM_THREADS``, or
    ``numba.set_num_threads``) and at least :data:`MIN_THREADED_ELEMENTS`
    elements, the elements are cut into n parts whose
    interiors are summed in parallel, then the seams between them serially;
    this differs from the serial kernel's result by round-off (the seam
    vertices sum their contributions in another order) and depends on n. With
    one thread, or the variable set to ``0``, the serial kernel runs: the
    same bits as earlier versions, at any thread count (for reproducibility).
    The energy and :func:`tet_volume_ratios` follow the same switch, with the
    same bits as their serial loops. Read at every call, like :data:`ENV`.

    Returns
    -------
    bool

    Examples
    --------
    >>> isinstance(threaded(), bool)
    True
    """
    return os.environ.get(THREADS_ENV, "1").strip().lower() not in ("0", "false", "no", "off")


def _threads(n_elements: int) -> int:
    """numba's thread count for a loop over n elements; 1 below :data:`MIN_THREADED_ELEMENTS`
    or where :func:`threaded` is false."""
    if n_elements < MIN_THREADED_ELEMENTS or not threaded():
        return 1
    return _kernels().numba.get_num_threads()


def available() -> bool:
    """Whether the fused kernels are used: numba imports and ``FEM_ELASTIC_NUMBA`` is not ``0``.

    The environment variable is read at every call, so it can be changed at
    run time (the tests do so to compare both paths).

    Returns
    -------
    bool

    Examples
    --------
    >>> isinstance(available(), bool)   # False without numba or with FEM_ELASTIC_NUMBA=0
    True
    """
    if os.environ.get(ENV, "1").strip().lower() in ("0", "false", "no", "off"):
        return False
    return _kernels() is not None


@dataclass(frozen=True)
class MaterialKernels:
    """The pointwise numba functions of one material class.

    Attributes
    ----------
    kind : int
        The branch of the element loops that evaluates this material.
    psi, P : numba functions
        ``psi(F, prm) -> float`` and ``P(F, prm) -> 9-tuple``, F a row-major 9-tuple.
    params : callable
        ``params(material) -> prm``, the 3-tuple of parameters (Pa or 1) the kernels take.
    """

    kind: int
    psi: object
    P: object
    params: Callable[[Material], tuple[float, float, float]]


def registry() -> dict[type, MaterialKernels]:
    """Material class -> its fused kernels (loads numba); empty without numba.

    Returns
    -------
    dict

    Examples
    --------
    >>> import fem_elastic as fe
    >>> fe.Corotated in registry()     # per-element SVD: stays on the numpy path
    False
    """
    k = _kernels()
    if k is None:
        return {}
    return {
        cls: MaterialKernels(getattr(k, name.upper()), getattr(k, f"{name}_psi"),
                             getattr(k, f"{name}_P"), params)
        for cls, (name, params) in _REGISTRY.items()
    }


class _P1Geometry:
    """What the P1 kernels need of a Discretization, contiguous and element-major.

    Every array is a read-only copy, and :meth:`FusedP1._x` hands x over
    read-only too: numba compiles one specialization per combination of
    array flags, so fixing them keeps it to one compile (and one cache entry).
    """

    def __init__(self, space: Discretization):
        nodes = space.element_dofs[0::3] // 3  # (4, ne) vertex of each local node
        # dN is constant on a P1 tet (every quadrature point holds the same values),
        # and sum_a dN_a = 0: the rows of nodes 1-3 are Dm^-1, F = I + Ds Dm^-1.
        dx = space.dx
        self.nodes = _frozen(nodes.T, np.int64)  # (ne, 4)
        self.Dm_inv = _frozen(space.dN[1:, :, :, 0].transpose(2, 0, 1), float)  # (ne, 3, 3)
        self.V = _frozen(dx[:, 0] if dx.shape[1] == 1 else dx.sum(axis=1), float)  # (ne,)
        self.X = _frozen(space.X, float)  # (ndofs,)
        self.ndofs = space.ndofs
        self._parts: dict[int, _PartitionedP1] = {}

    @cached_property
    def blocks(self) -> np.ndarray:
        """Dm^-1 and V in the force loop's block layout (:func:`._fused_gradient_kernels.blocks`;
        built on first use, 80 bytes per element)."""
        from . import _fused_gradient_kernels as kb

        return _frozen(kb.blocks(self.Dm_inv, self.V, [0, self.nodes.shape[0]])[0], float)

    def parts(self, n_parts: int) -> "_PartitionedP1":
        """The elements split into ``n_parts`` parts, for the threaded gradient (built on first use)."""
        if n_parts not in self._parts:
            self._parts[n_parts] = _PartitionedP1(self, n_parts)
        return self._parts[n_parts]


class _PartitionedP1:
    """The P1 geometry regrouped for :func:`._fused_gradient_kernels.gradient_p1_parts`.

    The elements are cut into ``n_parts`` slabs of equal element counts
    across the longest side of the body's bounding box (by the rank of their
    centroids along it); an element with a vertex that an element of another
    slab also has is a *seam* element. ``nodes``, ``Dm_inv`` and ``V`` are :class:`_P1Geometry`'s
    permuted by ``order``: the interior of part 0, of part 1, ..., then the
    seams, each in element order; ``part_start`` (``n_parts + 2``) delimits
    them. On the 153,600-tet beam cut in 2, the seam is 2 % of the
    elements (3,072: the layer of cells on each side of the cut). A body whose slabs meet in
    many places (a ring, a coil) gets a large seam, summed serially: correct
    results, less parallel. ``DB, first_block`` hold Dm^-1 and V of each group
    in the force loop's block layout. Costs a second copy of the geometry (112
    bytes per element).
    """

    def __init__(self, geo: _P1Geometry, n_parts: int):
        nodes = geo.nodes
        ne, nv = nodes.shape[0], geo.ndofs // 3
        Xv = geo.X.reshape(-1, 3)
        axis = int(np.argmax(np.ptp(Xv, axis=0))) if nv else 0
        centroid = Xv[nodes, axis].sum(axis=1)
        rank = np.empty(ne, dtype=np.int64)
        rank[np.argsort(centroid, kind="stable")] = np.arange(ne, dtype=np.int64)
        part = (rank * n_parts) // max(ne, 1)
        lo = np.full(nv, n_parts, dtype=np.int64)
        hi = np.full(nv, -1, dtype=np.int64)
        owner = np.repeat(part, nodes.shape[1])
        np.minimum.at(lo, nodes.ravel(), owner)
        np.maximum.at(hi, nodes.ravel(), owner)
        seam = (lo != hi)[nodes].any(axis=1)
        group = np.where(seam, n_parts, part)
        self.order = np.argsort(group, kind="stable")
        self.part_start = _frozen(
            np.concatenate(([0], np.cumsum(np.bincount(group, minlength=n_parts + 1)))), np.int64)
        self.nodes = _frozen(nodes[self.order], np.int64)
        from . import _fused_gradient_kernels as kb

        DB, first_block = kb.blocks(geo.Dm_inv[self.order], geo.V[self.order], self.part_start)
        self.DB = _frozen(DB, float)
        self.first_block = _frozen(first_block, np.int64)


def _frozen(a: np.ndarray, dtype) -> np.ndarray:
    """A C-contiguous, read-only copy."""
    out = np.array(a, dtype=dtype, order="C", copy=True)
    out.setflags(write=False)
    return out


#: Discretization -> (its geometry, {material: FusedP1}); dropped with the Discretization.
_cache: "weakref.WeakKeyDictionary[Discretization, tuple[_P1Geometry, dict]]" = (
    weakref.WeakKeyDictionary()
)
#: P2 Discretization -> {material: FusedP2}; dropped with the Discretization.
_p2_cache: "weakref.WeakKeyDictionary[Discretization, dict]" = weakref.WeakKeyDictionary()


class FusedP1:
    """Energy and gradient of one material on one P1 discretization, by the fused kernels.

    Build it with :func:`kernels_for`, which returns None where the numpy
    path must be used.

    Parameters
    ----------
    material : Material
        One of the classes of :func:`registry`.
    space : Discretization
        Of order 1.
    """

    def __init__(self, material: Material, space: Discretization):
        if space.order != 1:
            raise ValueError(f"the fused kernels are for P1 tets, got order {space.order}")
        name, params = _REGISTRY[type(material)]
        self._k = _kernels()
        from . import _fused_gradient_kernels  # numba is importable: _kernels() loaded it

        self._g = _fused_gradient_kernels
        # u = x - X for the force loop: one buffer per calling thread (a FusedP1 may be shared by
        # Python threads, e.g. solve_static in a pool), made on its first call
        self._scratch = threading.local()
        self.kind = getattr(self._k, name.upper())
        self.prm = params(material)
        entry = _cache.get(space)
        self.geo = entry[0] if entry is not None else _P1Geometry(space)

    def _x(self, x) -> np.ndarray:
        """x as a read-only, C-contiguous float view (a copy only if it is not one already)."""
        return _readonly(x, self.geo.ndofs, "x")

    def energy(self, x: np.ndarray) -> float:
        """Elastic energy (J); +inf if any element is inadmissible."""
        g = self.geo
        if _threads(g.nodes.shape[0]) > 1:  # the same bits as the serial loop
            blocks = np.empty(-(-g.nodes.shape[0] // 1024))
            e = self._k.energy_p1_blocks(self._x(x), g.X, g.nodes, g.Dm_inv, g.V, self.kind,
                                         self.prm, blocks)
        else:
            e = self._k.energy_p1(self._x(x), g.X, g.nodes, g.Dm_inv, g.V, self.kind, self.prm)
        return float(e)

    def gradient(self, x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """dE/dx (N), ``(ndofs,)``: into ``out`` if given (C-contiguous float), else a new array.

        On numba's threads (parts of the mesh in parallel, then their seams)
        when :func:`threaded` is true and numba has more than one thread;
        else by the serial loop. The two agree to round-off (the seam entries
        sum their element contributions in another order).
        """
        g = self.geo
        out = _out_array(out, g.ndofs)
        n_threads = _threads(g.nodes.shape[0])
        u = getattr(self._scratch, "u", None)
        if u is None:
            u = self._scratch.u = np.empty(g.ndofs)
        if n_threads > 1:
            c = g.parts(n_threads)
            self._g.gradient_p1_parts(self._x(x), g.X, u, c.nodes, c.DB, c.first_block, self.kind,
                                      self.prm, c.part_start, out)
        else:
            self._g.gradient_p1(self._x(x), g.X, u, g.nodes, g.blocks, self.kind, self.prm, out)
        return out

    def hessian(self, x: np.ndarray, pattern, project: bool = False):
        """d2E/dx2 (N/m) on the space's CSR ``pattern``, one pass over the elements.

        See :mod:`._fused_tangent_kernels` (imported here, on first use): the
        element matrices are scattered straight into the CSR data array, and
        ``project`` makes each element's dP/dF PSD as ``Material.d2psi_dF2_psd`` does.
        """
        from . import _fused_tangent_kernels

        return _fused_tangent_kernels.hessian(self, x, pattern, project)


def kernels_for(material: Material, space: Discretization) -> "FusedP1 | FusedP2 | None":
    """The fused kernels for a material on a discretization, or None for the numpy path.

    None unless the material's exact class is registered (see :func:`registry`)
    and :func:`available` is true. A P1 space gets a :class:`FusedP1`, a P2 space a
    :class:`~fem_elastic.discretization._fused_p2_kernels.FusedP2` (energy, gradient
    and tangent with the same methods; imported here, on first use).

    Parameters
    ----------
    material : Material
    space : Discretization

    Returns
    -------
    FusedP1, FusedP2 or None
    """
    if space.order not in (1, 2) or type(material) not in _REGISTRY or not available():
        return None
    if space.order == 2:
        from . import _fused_p2_kernels

        by_material = _p2_cache.setdefault(space, {})
        p2 = by_material.get(material)
        if p2 is None:
            p2 = by_material[material] = _fused_p2_kernels.FusedP2(material, space)
        return p2
    entry = _cache.get(space)
    if entry is None:
        entry = _cache[space] = (_P1Geometry(space), {})
    fused = entry[1].get(material)
    if fused is None:
        fused = entry[1][material] = FusedP1(material, space)
    return fused


# stiffness warping ----------------------------------------------------------------------
def _geometry(space: Discretization) -> _P1Geometry:
    """The cached P1 geometry of a space (built on first use, shared with :class:`FusedP1`)."""
    entry = _cache.get(space)
    if entry is None:
        entry = _cache[space] = (_P1Geometry(space), {})
    return entry[0]


def _readonly(a, n: int, name: str) -> np.ndarray:
    """a as a read-only, C-contiguous float ``(n,)`` view (a copy only if it is not one already)."""
    a = np.ascontiguousarray(a, dtype=float)
    if a.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {a.shape}")
    if a.flags.writeable:
        a = a.view()
        a.setflags(write=False)
    return a


def _out_array(out: np.ndarray | None, n: int) -> np.ndarray:
    """``out`` checked as a kernel's result array (C-contiguous float64 ``(n,)``), or a new one."""
    if out is None:
        return np.empty(n)
    if out.shape != (n,) or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous float64 array of shape ({n},)")
    return out


def warped_apply(warped, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``K(x) v`` of a P1 :class:`~fem_elastic.physics.stiffness_warping.WarpedStiffness`, in one pass.

    Per element: F, its polar rotation R (an inverse-free cubic iteration
    for moderate strains, scaled Newton for large ones, LAPACK's SVD for
    inverted or degenerate elements: the rotation of the signed SVD, as
    :func:`fem_elastic.materials.svd.polar_rotation`), then ``R K_e R^T
    v_e`` scattered into the result, with ``K_e w`` evaluated as the linear
    elastic force ``V sigma_lin(grad w) dN`` (the K_e of a P1 tet, never
    read from memory). Agrees with the numpy path of
    :meth:`WarpedStiffness.apply` to round-off. Call only where
    :func:`available` is true.

    Parameters
    ----------
    warped : WarpedStiffness
        On a P1 space; its material's ``mu`` and ``lam`` (Pa) define K_e.
    x : numpy.ndarray, shape (ndofs,)
        DOF positions (m).
    v : numpy.ndarray, shape (ndofs,)
        Any DOF vector (e.g. velocities, m/s).

    Returns
    -------
    numpy.ndarray, shape (ndofs,)
        ``sum_e R_e K_e R_e^T v_e`` (N/m times v's unit), a new array.
    """
    space = warped.space
    if space.order != 1:
        raise ValueError(f"the fused warped stiffness is for P1 tets, got order {space.order}")
    g = _geometry(space)
    prm = (float(warped.material.mu), float(warped.material.lam), 0.0)
    out = np.empty(g.ndofs)
    _kernels().warped_apply_p1(_readonly(x, g.ndofs, "x"), g.X, _readonly(v, g.ndofs, "v"),
                               g.nodes, g.Dm_inv, g.V, prm, out)
    return out


def tet_volume_ratios(p: np.ndarray, tets: np.ndarray, ref_det: np.ndarray):
    """``det(Ds) / det(Dm)`` of every tet by the fused kernel, or None without it.

    Parameters
    ----------
    p : numpy.ndarray
        ``(n_vertices, 3)`` vertex positions (m).
    tets : numpy.ndarray
        ``(4, n_tets)`` int64 vertex indices.
    ref_det : numpy.ndarray
        ``(n_tets,)`` determinants of the reference edge matrices (m^3).

    Returns
    -------
    numpy.ndarray or None
        ``(n_tets,)`` volume ratios (det F of a P1 tet); None when the fused kernels are
        not available (the caller takes its numpy path, which gives the same bits).

    Examples
    --------
    >>> import numpy as np
    >>> p = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 2]])
    >>> r = tet_volume_ratios(p, np.arange(4).reshape(4, 1), np.array([1.0]))
    >>> r is None or float(r[0]) == 2.0
    True
    """
    if not available():
        return None
    out = np.empty(tets.shape[1])
    k = _kernels()
    kernel = k.tet_volume_ratios_threaded if _threads(tets.shape[1]) > 1 else k.tet_volume_ratios
    kernel(np.ascontiguousarray(p, dtype=float), tets, ref_det, out)
    return out
