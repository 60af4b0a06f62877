"""numba kernels behind :mod:`fem_elastic.discretization.fused` (imported only by it, and only on first use).

Everything here is compiled with ``cache=True``: the compile (a few seconds)
is paid once per machine and later processes load the object code from
``__pycache__``. The kernels live in their own module, at module level,
because numba can cache only such functions: a kernel defined inside a
function that refers to other kernels through its closure misses the cache
on every new process.

Conventions
-----------
F, P : 9-tuples of floats, a 3x3 matrix row by row (``F[3 i + j] = F_ij``),
    so the pointwise material code stays in registers (no array per point).
prm : 3-tuple of floats, the material's parameters, see
    :data:`fem_elastic.discretization.fused._REGISTRY` (``(mu, lam, 0)``, or
    ``(mu', lam', alpha)`` for the stable Neo-Hookean).
kind : which material the element loops evaluate, one of the constants
    below. One loop serves the four materials: the branch is the same for
    every element, and measured no slower than a loop per material.
nodes, Dm_inv, V : the P1 geometry, ``(ne, 4)`` vertex indices, ``(ne, 3, 3)``
    with ``Dm_inv[e, b, j] = dN_{b+1, j}`` (scikit-fem's shape-function
    gradients of nodes 1-3: the rows of Dm^-1, for ``F = I + Ds Dm^-1``),
    and ``(ne,)`` volumes (m^3).

The pointwise formulas repeat the numpy material modules term by term and in
the same order of operations (numba does not reassociate or contract to FMA
without ``fastmath``; measured, FMA contraction bought nothing here), so the
two paths agree to round-off. Two deliberate departures, each of a few ulps:
F is formed from the edge vectors (``Ds Dm^-1``, node 0's gradient implied
as minus the others') and the Neo-Hookean stress divides once by J. Both
paths see ``u = x - X``, never x, so F - I keeps its relative precision.
"""

from __future__ import annotations

import math

import numba
import numpy as np

LINEAR, STVK, NEOHOOKEAN, STABLE_NEOHOOKEAN = 0, 1, 2, 3

_jit = numba.njit(cache=True, error_model="numpy", nogil=True)
#: Element functions inlined into their loops at numba's IR level (an element function called
#: per element from the gradient loop measured 16.6 ms on the 153,600-tet beam against 11.1 ms
#: for the body written out in the loop, in the same run).
_jit_inline = numba.njit(cache=True, error_model="numpy", nogil=True, inline="always")
#: The threaded loops: prange over independent pieces, one parallel region per call.
_pjit = numba.njit(cache=True, error_model="numpy", nogil=True, parallel=True)


def drop_stale_caches(module_file: str, *dependencies: str) -> bool:
    """Delete numba's cache files of ``module_file`` if a module its kernels call has changed.

    numba's ``cache=True`` checks only the source file of the cached function itself: a
    kernel that inlines code from another module (the material laws of this one) keeps its
    old machine code when only that other module is edited. The kernel modules call this
    at import with the files they depend on; a digest of those files is kept beside the
    cache (``__pycache__/<module>.deps``) and, when it differs, the module's ``*.nbi`` and
    ``*.nbc`` files are removed, so numba compiles anew. Best effort: a ``__pycache__``
    that cannot be written (an installed package; numba then caches elsewhere, and the
    sources do not change there) is left alone.

    Returns
    -------
    bool
        Whether cache files were removed.
    """
    import hashlib
    from pathlib import Path

    here = Path(module_file)
    cache = here.parent / "__pycache__"
    stamp = cache / f"{here.stem}.deps"
    digest = hashlib.sha256(b"".join(Path(d).read_bytes() for d in dependencies)).hexdigest()
    try:
        if stamp.read_text() == digest:
            return False
    except OSError:
        pass
    removed = False
    try:
        for f in cache.glob(f"{here.stem}.*.nb[ic]"):
            f.unlink(missing_ok=True)
            removed = True
        cache.mkdir(exist_ok=True)
        stamp.write_text(digest)
    except OSError:
        pass
    return removed


# pointwise materials ----------------------------------------------------------------
@_jit
def _det(F):
    f00, f01, f02, f10, f11, f12, f20, f21, f22 = F
    # the expansion of materials.base._det(F) (without the cofactor)
    return (
        f00 * (f11 * f22 - f12 * f21)
        - f01 * (f10 * f22 - f12 * f20)
        + f02 * (f10 * f21 - f11 * f20)
    )


@_jit
def _cofactor(F):
    """K = dJ/dF = J F^-T, as materials.base._cofactor(F)."""
    f00, f01, f02, f10, f11, f12, f20, f21, f22 = F
    return (
        f11 * f22 - f12 * f21, f12 * f20 - f10 * f22, f10 * f21 - f11 * f20,
        f21 * f02 - f22 * f01, f22 * f00 - f20 * f02, f20 * f01 - f21 * f00,
        f01 * f12 - f02 * f11, f02 * f10 - f00 * f12, f00 * f11 - f01 * f10,
    )


@_jit
def _frobenius2(F):
    s = 0.0
    for k in range(9):
        s += F[k] * F[k]
    return s


@_jit
def linear_psi(F, prm):
    """psi = mu eps:eps + lam/2 tr(eps)^2, eps = sym F - I (materials.linear)."""
    mu, lam = prm[0], prm[1]
    f00, f01, f02, f10, f11, f12, f20, f21, f22 = F
    e00, e11, e22 = f00 - 1.0, f11 - 1.0, f22 - 1.0
    e01, e02, e12 = f01 + f10, f02 + f20, f12 + f21  # 2 eps_ij
    tr = e00 + e11 + e22
    epseps = e00 * e00 + e11 * e11 + e22 * e22 + 0.5 * (e01 * e01 + e02 * e02 + e12 * e12)
    return mu * epseps + 0.5 * lam * tr * tr


@_jit
def linear_P(F, prm):
    """P = 2 mu eps + lam tr(eps) I (materials.linear)."""
    mu, lam = prm[0], prm[1]
    f00, f01, f02, f10, f11, f12, f20, f21, f22 = F
    d = lam * (f00 + f11 + f22 - 3.0) - 2.0 * mu
    s01, s02, s12 = mu * (f01 + f10), mu * (f02 + f20), mu * (f12 + f21)
    return (
        mu * (f00 + f00) + d, s01, s02,
        s01, mu * (f11 + f11) + d, s12,
        s02, s12, mu * (f22 + f22) + d,
    )


@_jit
def _right_cauchy_green(F):
    """The upper triangle (a00, a01, a02, a11, a12, a22) of F^T F."""
    f00, f01, f02, f10, f11, f12, f20, f21, f22 = F
    return (
        f00 * f00 + f10 * f10 + f20 * f20,
        f00 * f01 + f10 * f11 + f20 * f21,
        f00 * f02 + f10 * f12 + f20 * f22,
        f01 * f01 + f11 * f11 + f21 * f21,
        f01 * f02 + f11 * f12 + f21 * f22,
        f02 * f02 + f12 * f12 + f22 * f22,
    )


@_jit
def stvk_psi(F, prm):
    """psi = mu E:E + lam/2 tr(E)^2, E = (F^T F - I)/2 (materials.stvk)."""
    mu, lam = prm[0], prm[1]
    a00, a01, a02, a11, a12, a22 = _right_cauchy_green(F)
    e00, e11, e22 = 0.5 * (a00 - 1.0), 0.5 * (a11 - 1.0), 0.5 * (a22 - 1.0)
    tr = e00 + e11 + e22
    EE = e00 * e00 + e11 * e11 + e22 * e22 + 0.5 * (a01 * a01 + a02 * a02 + a12 * a12)
    return mu * EE + 0.5 * lam * tr * tr


@_jit
def stvk_P(F, prm):
    """P = F S, S = 2 mu E + lam tr(E) I (materials.stvk)."""
    mu, lam = prm[0], prm[1]
    f00, f01, f02, f10, f11, f12, f20, f21, f22 = F
    a00, a01, a02, a11, a12, a22 = _right_cauchy_green(F)
    trE = 0.5 * (a00 + a11 + a22 - 3.0)
    d = lam * trE - mu
    s00, s11, s22 = mu * a00 + d, mu * a11 + d, mu * a22 + d
    s01, s02, s12 = mu * a01, mu * a02, mu * a12
    return (
        f00 * s00 + f01 * s01 + f02 * s02,
        f00 * s01 + f01 * s11 + f02 * s12,
        f00 * s02 + f01 * s12 + f02 * s22,
        f10 * s00 + f11 * s01 + f12 * s02,
        f10 * s01 + f11 * s11 + f12 * s12,
        f10 * s02 + f11 * s12 + f12 * s22,
        f20 * s00 + f21 * s01 + f22 * s02,
        f20 * s01 + f21 * s11 + f22 * s12,
        f20 * s02 + f21 * s12 + f22 * s22,
    )


@_jit
def neohookean_psi(F, prm):
    """psi = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2; +inf where J <= 0 (materials.neohookean)."""
    mu, lam = prm[0], prm[1]
    J = _det(F)
    if not J > 0.0:
        return np.inf
    I1 = _frobenius2(F)
    lnJ = math.log(J)
    return 0.5 * mu * (I1 - 3.0) - mu * lnJ + 0.5 * lam * lnJ * lnJ


@_jit
def neohookean_P(F, prm):
    """P = mu F + (lam ln J - mu) F^-T; NaN where J <= 0, as in materials.neohookean."""
    mu, lam = prm[0], prm[1]
    K = _cofactor(F)
    J = F[0] * K[0] + F[1] * K[1] + F[2] * K[2]
    lnJ = np.log(J)  # NaN for J < 0, -inf for J = 0 (no exception: numpy semantics)
    c = (lam * lnJ - mu) / J  # one division, where numpy divides K by J (1 ulp apart)
    return (
        mu * F[0] + c * K[0], mu * F[1] + c * K[1], mu * F[2] + c * K[2],
        mu * F[3] + c * K[3], mu * F[4] + c * K[4], mu * F[5] + c * K[5],
        mu * F[6] + c * K[6], mu * F[7] + c * K[7], mu * F[8] + c * K[8],
    )


@_jit
def stable_neohookean_psi(F, prm):
    """Smith, de Goes and Kim (2018), shifted so that psi(I) = 0 (materials.stable_neohookean)."""
    mu_, lam_, alpha = prm
    IC = _frobenius2(F)
    dJ = _det(F) - alpha
    d0 = 1.0 - alpha
    return (
        0.5 * mu_ * (IC - 3.0)
        + 0.5 * lam_ * (dJ - d0) * (dJ + d0)
        - 0.5 * mu_ * math.log1p((IC - 3.0) / 4.0)
    )


@_jit
def stable_neohookean_P(F, prm):
    """P = mu' (1 - 1/(I_C + 1)) F + lam' (J - alpha) cof F (materials.stable_neohookean)."""
    mu_, lam_, alpha = prm
    IC = _frobenius2(F)
    K = _cofactor(F)
    J = F[0] * K[0] + F[1] * K[1] + F[2] * K[2]
    a = mu_ * (1.0 - 1.0 / (IC + 1.0))
    b = lam_ * (J - alpha)
    return (
        a * F[0] + b * K[0], a * F[1] + b * K[1], a * F[2] + b * K[2],
        a * F[3] + b * K[3], a * F[4] + b * K[4], a * F[5] + b * K[5],
        a * F[6] + b * K[6], a * F[7] + b * K[7], a * F[8] + b * K[8],
    )


@_jit
def psi(kind, F, prm):
    """psi(F) of the material ``kind``."""
    if kind == LINEAR:
        return linear_psi(F, prm)
    if kind == STVK:
        return stvk_psi(F, prm)
    if kind == NEOHOOKEAN:
        return neohookean_psi(F, prm)
    return stable_neohookean_psi(F, prm)


@_jit
def P(kind, F, prm):
    """P = dpsi_dF(F) of the material ``kind``."""
    if kind == LINEAR:
        return linear_P(F, prm)
    if kind == STVK:
        return stvk_P(F, prm)
    if kind == NEOHOOKEAN:
        return neohookean_P(F, prm)
    return stable_neohookean_P(F, prm)


# element loops ------------------------------------------------------------------------
@_jit
def _displacements(x, X, nodes, e):
    """u_0 and the edges Ds = (u_1 - u_0, u_2 - u_0, u_3 - u_0) of element e, u = x - X.

    The displacement, not the position, is differenced: x is O(the body
    size) while u is O(the deformation), so F - I keeps its relative precision.
    """
    k0, k1, k2, k3 = 3 * nodes[e, 0], 3 * nodes[e, 1], 3 * nodes[e, 2], 3 * nodes[e, 3]
    u0, u1, u2 = x[k0] - X[k0], x[k0 + 1] - X[k0 + 1], x[k0 + 2] - X[k0 + 2]
    a0, a1, a2 = x[k1] - X[k1] - u0, x[k1 + 1] - X[k1 + 1] - u1, x[k1 + 2] - X[k1 + 2] - u2
    b0, b1, b2 = x[k2] - X[k2] - u0, x[k2 + 1] - X[k2 + 1] - u1, x[k2 + 2] - X[k2 + 2] - u2
    c0, c1, c2 = x[k3] - X[k3] - u0, x[k3 + 1] - X[k3 + 1] - u1, x[k3 + 2] - X[k3 + 2] - u2
    return (a0, a1, a2, b0, b1, b2, c0, c1, c2)


@_jit
def _deformation_gradient(x, X, nodes, Dm_inv, e):
    """F = I + Ds Dm^-1 of element e (= I + sum_a u_a (x) dN_a, since sum_a dN_a = 0)."""
    a0, a1, a2, b0, b1, b2, c0, c1, c2 = _displacements(x, X, nodes, e)
    d = Dm_inv[e]
    return (
        a0 * d[0, 0] + b0 * d[1, 0] + c0 * d[2, 0] + 1.0,
        a0 * d[0, 1] + b0 * d[1, 1] + c0 * d[2, 1],
        a0 * d[0, 2] + b0 * d[1, 2] + c0 * d[2, 2],
        a1 * d[0, 0] + b1 * d[1, 0] + c1 * d[2, 0],
        a1 * d[0, 1] + b1 * d[1, 1] + c1 * d[2, 1] + 1.0,
        a1 * d[0, 2] + b1 * d[1, 2] + c1 * d[2, 2],
        a2 * d[0, 0] + b2 * d[1, 0] + c2 * d[2, 0],
        a2 * d[0, 1] + b2 * d[1, 1] + c2 * d[2, 1],
        a2 * d[0, 2] + b2 * d[1, 2] + c2 * d[2, 2] + 1.0,
    )


@_jit_inline
def _deformation_gradient9(x, X, nodes, D, e):
    """:func:`_deformation_gradient` with ``D = Dm_inv.reshape(ne, 9)``: the same operations
    (the same bits), Dm^-1 read as nine scalars rather than through a 3x3 view per element
    (inlined into the energy loop; the force loop is :mod:`._fused_gradient_kernels`)."""
    k0, k1, k2, k3 = 3 * nodes[e, 0], 3 * nodes[e, 1], 3 * nodes[e, 2], 3 * nodes[e, 3]
    u0, u1, u2 = x[k0] - X[k0], x[k0 + 1] - X[k0 + 1], x[k0 + 2] - X[k0 + 2]  # as _displacements
    a0, a1, a2 = x[k1] - X[k1] - u0, x[k1 + 1] - X[k1 + 1] - u1, x[k1 + 2] - X[k1 + 2] - u2
    b0, b1, b2 = x[k2] - X[k2] - u0, x[k2 + 1] - X[k2 + 1] - u1, x[k2 + 2] - X[k2 + 2] - u2
    c0, c1, c2 = x[k3] - X[k3] - u0, x[k3 + 1] - X[k3 + 1] - u1, x[k3 + 2] - X[k3 + 2] - u2
    d00, d01, d02 = D[e, 0], D[e, 1], D[e, 2]
    d10, d11, d12 = D[e, 3], D[e, 4], D[e, 5]
    d20, d21, d22 = D[e, 6], D[e, 7], D[e, 8]
    return (
        a0 * d00 + b0 * d10 + c0 * d20 + 1.0,
        a0 * d01 + b0 * d11 + c0 * d21,
        a0 * d02 + b0 * d12 + c0 * d22,
        a1 * d00 + b1 * d10 + c1 * d20,
        a1 * d01 + b1 * d11 + c1 * d21 + 1.0,
        a1 * d02 + b1 * d12 + c1 * d22,
        a2 * d00 + b2 * d10 + c2 * d20,
        a2 * d01 + b2 * d11 + c2 * d21,
        a2 * d02 + b2 * d12 + c2 * d22 + 1.0,
    )


@_jit
def _energy_range(x, X, nodes, D, V, kind, prm, start, stop):
    """sum V_e psi(F_e) over the elements start:stop, in order; +inf as soon as one psi is not finite."""
    block = 0.0
    for e in range(start, stop):
        w = psi(kind, _deformation_gradient9(x, X, nodes, D, e), prm)
        if not math.isfinite(w):
            return np.inf
        block += w * V[e]
    return block


@_jit
def energy_p1(x, X, nodes, Dm_inv, V, kind, prm):
    """E = sum_e V_e psi(F_e); +inf as soon as one psi is not finite (inadmissible state).

    Summed in blocks of 1024 elements, so the round-off grows like that of
    numpy's pairwise sum rather than with the number of elements.
    """
    ne = nodes.shape[0]
    D = Dm_inv.reshape((ne, 9))  # a view (Dm_inv is C-contiguous)
    total = 0.0
    for start in range(0, ne, 1024):
        block = _energy_range(x, X, nodes, D, V, kind, prm, start, min(ne, start + 1024))
        if block == np.inf:
            return np.inf
        total += block
    return total


@_pjit
def energy_p1_blocks(x, X, nodes, Dm_inv, V, kind, prm, blocks):
    """:func:`energy_p1` on numba's threads, the same bits: its 1024-element blocks in parallel.

    ``blocks`` ``(ceil(ne / 1024),)`` receives each block's sum, computed as
    the serial loop computes it (+inf if one psi is not finite); the blocks
    are then added in order, as the serial loop adds them. So the result
    does not depend on the number of threads, and equals :func:`energy_p1`'s.
    """
    ne = nodes.shape[0]
    D = Dm_inv.reshape((ne, 9))
    for b in numba.prange(blocks.shape[0]):
        blocks[b] = _energy_range(x, X, nodes, D, V, kind, prm, b * 1024, min(ne, (b + 1) * 1024))
    total = 0.0
    for b in range(blocks.shape[0]):
        if blocks[b] == np.inf:
            return np.inf
        total += blocks[b]
    return total


@_jit
def psi_points(kind, F, prm, out):
    """psi at each of N points, F given as ``(9, N)`` (tests compare with the materials)."""
    for n in range(F.shape[1]):
        out[n] = psi(kind, (F[0, n], F[1, n], F[2, n], F[3, n], F[4, n], F[5, n],
                            F[6, n], F[7, n], F[8, n]), prm)


@_jit
def P_points(kind, F, prm, out):
    """P at each of N points, F and out ``(9, N)``."""
    for n in range(F.shape[1]):
        p = P(kind, (F[0, n], F[1, n], F[2, n], F[3, n], F[4, n], F[5, n],
                     F[6, n], F[7, n], F[8, n]), prm)
        for k in range(9):
            out[k, n] = p[k]


# stiffness warping ----------------------------------------------------------------------
# The polar rotation of F. Unlike the material kernels above it does not repeat the numpy
# path's algorithm (materials.svd: Jacobi on F^T F, then Gram-Schmidt): it computes the
# same rotation by iterations that converge to round-off, so the two agree to a few ulps
# times the conditioning of R (1 / (s_2 + s_3), s the signed singular values).

#: ``|F^T F - I|_F^2`` below which the inverse-free cubic iteration is used. Its
#: eigenvalues s^2 then lie in (0.5, 1.5), where the iteration converges (its other fixed
#: point, s^2 = 7/3, is far) and its first step already brings every s within 5 % of 1.
_CUBIC_DEFECT2 = 0.25
#: The cubic iteration stops after a step (Frobenius) below sqrt of this, 3.2e-6: its
#: error is then ~2.5 step^3 < 1e-16.
_CUBIC_TOL2 = 1e-11
#: Newton's iteration stops after a step below this: it converges quadratically (error
#: ~ step^2 / 2).
_NEWTON_TOL = 1e-8
#: Higham's scaling is applied while Newton's steps are larger than this (far from R).
_NEWTON_SCALE_ABOVE = 1e-2
#: More iterations than either needs for any F they are used on (scaled Newton: < 15
#: up to condition numbers of 1e16); past them the SVD decides.
_POLAR_MAX_ITER = 40

# FMA contraction shortens the dependency chain of the cubic step, which is latency-bound
# (measured: -15 % of warped_apply_p1); nothing compares it bit for bit with numpy.
_jit_fma = numba.njit(cache=True, error_model="numpy", nogil=True, fastmath={"contract"})


@_jit_fma
def _gram(X):
    """The upper triangle (a00, a01, a02, a11, a12, a22) of X^T X (contracted to FMA)."""
    x00, x01, x02, x10, x11, x12, x20, x21, x22 = X
    return (
        x00 * x00 + x10 * x10 + x20 * x20,
        x00 * x01 + x10 * x11 + x20 * x21,
        x00 * x02 + x10 * x12 + x20 * x22,
        x01 * x01 + x11 * x11 + x21 * x21,
        x01 * x02 + x11 * x12 + x21 * x22,
        x02 * x02 + x12 * x12 + x22 * x22,
    )


@_jit_fma
def _cubic_step(X, A):
    """``X (15 I - 10 A + 3 A^2) / 8`` with ``A = X^T X``: the inverse-free Pade iteration
    (Kenney and Laub 1991; Higham, *Functions of Matrices*, 2008, sec. 8.5) for the polar
    factor. A singular value s goes to ``s (15 - 10 s^2 + 3 s^4) / 8 = 1 + 2.5 (s - 1)^3
    + ...``: cubic convergence without a division.
    """
    a00, a01, a02, a11, a12, a22 = A
    b00 = a00 * a00 + a01 * a01 + a02 * a02  # B = A^2 (symmetric)
    b01 = a00 * a01 + a01 * a11 + a02 * a12
    b02 = a00 * a02 + a01 * a12 + a02 * a22
    b11 = a01 * a01 + a11 * a11 + a12 * a12
    b12 = a01 * a02 + a11 * a12 + a12 * a22
    b22 = a02 * a02 + a12 * a12 + a22 * a22
    m00 = 1.875 - 1.25 * a00 + 0.375 * b00
    m11 = 1.875 - 1.25 * a11 + 0.375 * b11
    m22 = 1.875 - 1.25 * a22 + 0.375 * b22
    m01 = 0.375 * b01 - 1.25 * a01
    m02 = 0.375 * b02 - 1.25 * a02
    m12 = 0.375 * b12 - 1.25 * a12
    x00, x01, x02, x10, x11, x12, x20, x21, x22 = X
    return (
        x00 * m00 + x01 * m01 + x02 * m02, x00 * m01 + x01 * m11 + x02 * m12,
        x00 * m02 + x01 * m12 + x02 * m22,
        x10 * m00 + x11 * m01 + x12 * m02, x10 * m01 + x11 * m11 + x12 * m12,
        x10 * m02 + x11 * m12 + x12 * m22,
        x20 * m00 + x21 * m01 + x22 * m02, x20 * m01 + x21 * m11 + x22 * m12,
        x20 * m02 + x21 * m12 + x22 * m22,
    )


@_jit
def _distance2(X, Y):
    """|X - Y|_F^2, summed as a tree (a short dependency chain)."""
    d0, d1, d2 = Y[0] - X[0], Y[1] - X[1], Y[2] - X[2]
    d3, d4, d5 = Y[3] - X[3], Y[4] - X[4], Y[5] - X[5]
    d6, d7, d8 = Y[6] - X[6], Y[7] - X[7], Y[8] - X[8]
    return (((d0 * d0 + d1 * d1) + (d2 * d2 + d3 * d3))
            + ((d4 * d4 + d5 * d5) + (d6 * d6 + d7 * d7)) + d8 * d8)


@_jit
def _polar_newton(F):
    """(R, converged): the polar factor of F by scaled Newton, ``X <- (g X + X^-T / g) / 2``.

    For ``det F > 0`` (the iteration keeps det X > 0 and converges to the
    proper polar rotation, the ``U V^T`` of the signed SVD). g is Higham's
    Frobenius scaling ``(|X^-1|_F / |X|_F)^(1/2)`` while the steps are
    large, then 1 (plain Newton, quadratic). ``converged`` is False if the
    iteration met a non-positive or non-finite determinant or did not
    converge; the caller then takes the SVD.
    """
    X = F
    scale = True
    for _ in range(_POLAR_MAX_ITER):
        K = _cofactor(X)  # det(X) X^-T
        J = X[0] * K[0] + X[1] * K[1] + X[2] * K[2]
        if not (J > 0.0 and J < np.inf):
            return X, False
        if scale:
            g = math.sqrt(math.sqrt(_frobenius2(K) / _frobenius2(X)) / J)
            a, b = 0.5 * g, 0.5 / (g * J)
        else:
            a, b = 0.5, 0.5 / J
        Y = (
            a * X[0] + b * K[0], a * X[1] + b * K[1], a * X[2] + b * K[2],
            a * X[3] + b * K[3], a * X[4] + b * K[4], a * X[5] + b * K[5],
            a * X[6] + b * K[6], a * X[7] + b * K[7], a * X[8] + b * K[8],
        )
        step2 = _distance2(X, Y)
        X = Y
        if step2 < _NEWTON_TOL * _NEWTON_TOL:
            return X, True
        if not step2 < np.inf:
            return X, False
        scale = step2 > _NEWTON_SCALE_ABOVE * _NEWTON_SCALE_ABOVE
    return X, False


@_jit
def _polar_svd(F):
    """The rotation ``U V^T`` of the signed SVD of F (materials.svd), through LAPACK.

    LAPACK gives ``F = U diag(s) V^T``; the signed SVD flips the last column
    of U where ``det U < 0`` and that of V where ``det V < 0``, so its
    rotation is ``U diag(1, 1, det U det V) V^T``. NaN if F is not finite.
    """
    for k in range(9):
        if not math.isfinite(F[k]):
            n = np.nan
            return (n, n, n, n, n, n, n, n, n)
    A = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            A[i, j] = F[3 * i + j]
    U, _, Vt = np.linalg.svd(A)
    c = 1.0 if np.linalg.det(U) * np.linalg.det(Vt) > 0.0 else -1.0
    R = np.empty(9)
    for i in range(3):
        for j in range(3):
            R[3 * i + j] = U[i, 0] * Vt[0, j] + U[i, 1] * Vt[1, j] + c * U[i, 2] * Vt[2, j]
    return (R[0], R[1], R[2], R[3], R[4], R[5], R[6], R[7], R[8])


@_jit
def polar_rotation(F):
    """The proper rotation R of ``F = R S``, as ``materials.svd.polar_rotation`` (signed SVD).

    ``det F > 0`` and F within ``|F^T F - I|_F < 0.5`` of a rotation (every
    element of a moderately strained body): the cubic iteration, two steps
    from F for strains up to ~1e-2. Other ``det F > 0``: scaled Newton.
    Inverted or degenerate F (``det F <= 0``), or an iteration that fails:
    LAPACK's SVD with the signed SVD's convention (``det R = +1``).
    """
    A = _gram(F)
    a00, a01, a02, a11, a12, a22 = A
    defect2 = (((a00 - 1.0) * (a00 - 1.0) + (a11 - 1.0) * (a11 - 1.0))
               + ((a22 - 1.0) * (a22 - 1.0) + 2.0 * ((a01 * a01 + a02 * a02) + a12 * a12)))
    J = _det(F)
    if J > 0.0 and defect2 < _CUBIC_DEFECT2:
        X1 = _cubic_step(F, A)
        X = _cubic_step(X1, _gram(X1))
        if _distance2(X1, X) < _CUBIC_TOL2:
            return X
        for _ in range(_POLAR_MAX_ITER):
            Y = _cubic_step(X, _gram(X))
            step2 = _distance2(X, Y)
            X = Y
            if step2 < _CUBIC_TOL2:
                return X
    if J > 0.0:
        R, ok = _polar_newton(F)
        if ok:
            return R
    return _polar_svd(F)


@_jit
def polar_points(F, out):
    """R at each of N points, F and out ``(9, N)`` (tests compare with materials.svd)."""
    for n in range(F.shape[1]):
        r = polar_rotation((F[0, n], F[1, n], F[2, n], F[3, n], F[4, n], F[5, n],
                            F[6, n], F[7, n], F[8, n]))
        for k in range(9):
            out[k, n] = r[k]


@_jit
def _vector_gradient(v, nodes, Dm_inv, e):
    """L = sum_a v_a (x) dN_a of element e (= Ds(v) Dm^-1), a 9-tuple."""
    k0, k1, k2, k3 = 3 * nodes[e, 0], 3 * nodes[e, 1], 3 * nodes[e, 2], 3 * nodes[e, 3]
    u0, u1, u2 = v[k0], v[k0 + 1], v[k0 + 2]
    a0, a1, a2 = v[k1] - u0, v[k1 + 1] - u1, v[k1 + 2] - u2
    b0, b1, b2 = v[k2] - u0, v[k2 + 1] - u1, v[k2 + 2] - u2
    c0, c1, c2 = v[k3] - u0, v[k3 + 1] - u1, v[k3 + 2] - u2
    d = Dm_inv[e]
    return (
        a0 * d[0, 0] + b0 * d[1, 0] + c0 * d[2, 0],
        a0 * d[0, 1] + b0 * d[1, 1] + c0 * d[2, 1],
        a0 * d[0, 2] + b0 * d[1, 2] + c0 * d[2, 2],
        a1 * d[0, 0] + b1 * d[1, 0] + c1 * d[2, 0],
        a1 * d[0, 1] + b1 * d[1, 1] + c1 * d[2, 1],
        a1 * d[0, 2] + b1 * d[1, 2] + c1 * d[2, 2],
        a2 * d[0, 0] + b2 * d[1, 0] + c2 * d[2, 0],
        a2 * d[0, 1] + b2 * d[1, 1] + c2 * d[2, 1],
        a2 * d[0, 2] + b2 * d[1, 2] + c2 * d[2, 2],
    )


@_jit
def warped_apply_p1(x, X, v, nodes, Dm_inv, V, prm, out):
    """out = K(x) v = sum_e R_e K_e R_e^T v_e, the warped stiffness times v (P1, matrix-free).

    K_e, the rest stiffness of a linear tet, is not read: it is the linear
    elastic force of a field, ``(K_e w)_a = V sigma_lin(grad w) dN_a`` with
    ``sigma_lin(G) = mu (G + G^T) + lam tr(G) I``, and for ``w_a = R^T v_a``
    ``grad w = R^T L``, ``L = grad v``. So per element: R the polar rotation
    of F (:func:`polar_rotation`), ``P = R sigma_lin(R^T L)`` and
    ``out_a += V P dN_a``, scattered as :func:`._fused_gradient_kernels.gradient_p1` does. (The 12x12
    K_e would be 1.2 kB per element to stream from memory: measured, that
    path took ~1.6x as long.)

    Parameters: x, X, v ``(ndofs,)``; nodes, Dm_inv, V the P1 geometry; prm
    ``(mu, lam, 0)`` (Pa); out ``(ndofs,)``, overwritten.
    """
    mu, lam = prm[0], prm[1]
    out[:] = 0.0
    for e in range(nodes.shape[0]):
        R = polar_rotation(_deformation_gradient(x, X, nodes, Dm_inv, e))
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
        L = _vector_gradient(v, nodes, Dm_inv, e)
        # G = R^T L
        g00 = r00 * L[0] + r10 * L[3] + r20 * L[6]
        g01 = r00 * L[1] + r10 * L[4] + r20 * L[7]
        g02 = r00 * L[2] + r10 * L[5] + r20 * L[8]
        g10 = r01 * L[0] + r11 * L[3] + r21 * L[6]
        g11 = r01 * L[1] + r11 * L[4] + r21 * L[7]
        g12 = r01 * L[2] + r11 * L[5] + r21 * L[8]
        g20 = r02 * L[0] + r12 * L[3] + r22 * L[6]
        g21 = r02 * L[1] + r12 * L[4] + r22 * L[7]
        g22 = r02 * L[2] + r12 * L[5] + r22 * L[8]
        vol = V[e]
        t = lam * (g00 + g11 + g22)
        # V sigma_lin(G), symmetric
        s00 = (mu * (g00 + g00) + t) * vol
        s11 = (mu * (g11 + g11) + t) * vol
        s22 = (mu * (g22 + g22) + t) * vol
        s01, s02, s12 = mu * (g01 + g10) * vol, mu * (g02 + g20) * vol, mu * (g12 + g21) * vol
        d = Dm_inv[e]
        k0, k1, k2, k3 = 3 * nodes[e, 0], 3 * nodes[e, 1], 3 * nodes[e, 2], 3 * nodes[e, 3]
        for i in range(3):
            ri0, ri1, ri2 = R[3 * i], R[3 * i + 1], R[3 * i + 2]
            q0 = ri0 * s00 + ri1 * s01 + ri2 * s02  # (V R sigma)_ij, row i
            q1 = ri0 * s01 + ri1 * s11 + ri2 * s12
            q2 = ri0 * s02 + ri1 * s12 + ri2 * s22
            f1 = q0 * d[0, 0] + q1 * d[0, 1] + q2 * d[0, 2]
            f2 = q0 * d[1, 0] + q1 * d[1, 1] + q2 * d[1, 2]
            f3 = q0 * d[2, 0] + q1 * d[2, 1] + q2 * d[2, 2]
            out[k1 + i] += f1
            out[k2 + i] += f2
            out[k3 + i] += f3
            out[k0 + i] -= f1 + f2 + f3


# det F of the vertex tets -----------------------------------------------------------
@_jit_inline
def _tet_volume_ratio(p, tets, ref_det, e):
    """``det(Ds) / det(Dm)`` of tet e (the body of both loops below, inlined into them)."""
    i0, i1, i2, i3 = tets[0, e], tets[1, e], tets[2, e], tets[3, e]
    a00 = p[i1, 0] - p[i0, 0]
    a10 = p[i1, 1] - p[i0, 1]
    a20 = p[i1, 2] - p[i0, 2]
    a01 = p[i2, 0] - p[i0, 0]
    a11 = p[i2, 1] - p[i0, 1]
    a21 = p[i2, 2] - p[i0, 2]
    a02 = p[i3, 0] - p[i0, 0]
    a12 = p[i3, 1] - p[i0, 1]
    a22 = p[i3, 2] - p[i0, 2]
    det = (a00 * (a11 * a22 - a12 * a21)
           - a01 * (a10 * a22 - a12 * a20)
           + a02 * (a10 * a21 - a11 * a20))
    return det / ref_det[e]


@_jit
def tet_volume_ratios(p, tets, ref_det, out):
    """``out[e] = det(Ds) / det(Dm)`` of each tet, from vertex positions ``p`` ``(n, 3)``.

    ``Ds``'s columns are the edges from vertex 0, in the order of operations of
    :func:`fem_elastic.physics.inversion.det3` (the numpy path), so the two agree
    to the last bit; one pass, no temporaries (the numpy path's gathers made the
    per-step inversion watch cost more than a fused explicit step).
    """
    for e in range(tets.shape[1]):
        out[e] = _tet_volume_ratio(p, tets, ref_det, e)


@_pjit
def tet_volume_ratios_threaded(p, tets, ref_det, out):
    """:func:`tet_volume_ratios` on numba's threads (the same bits: each tet is independent)."""
    for e in numba.prange(tets.shape[1]):
        out[e] = _tet_volume_ratio(p, tets, ref_det, e)
