"""numba kernels behind :mod:`fem_elastic.fused` (imported only by it, and only on first use).

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
    :data:`fem_elastic.fused._REGISTRY` (``(mu, lam, 0)``, or
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


@_jit
def gradient_p1(x, X, nodes, Dm_inv, V, kind, prm, out):
    """out = dE/dx: for each tet, g_ai += V P_ij dN_aj, scattered as it is computed.

    Parameters: x, X ``(ndofs,)``; nodes ``(ne, 4)`` vertex indices; Dm_inv
    ``(ne, 3, 3)``, ``Dm_inv[e, b, j] = dN_{b+1, j}`` (the gradients of the
    shape functions of nodes 1-3; node 0's is minus their sum); V ``(ne,)``
    volumes; out ``(ndofs,)``, overwritten.
    """
    out[:] = 0.0
    for e in range(nodes.shape[0]):
        F = _deformation_gradient(x, X, nodes, Dm_inv, e)
        p = P(kind, F, prm)
        v = V[e]
        d = Dm_inv[e]
        k0, k1, k2, k3 = 3 * nodes[e, 0], 3 * nodes[e, 1], 3 * nodes[e, 2], 3 * nodes[e, 3]
        for i in range(3):
            q0, q1, q2 = p[3 * i] * v, p[3 * i + 1] * v, p[3 * i + 2] * v
            f1 = q0 * d[0, 0] + q1 * d[0, 1] + q2 * d[0, 2]
            f2 = q0 * d[1, 0] + q1 * d[1, 1] + q2 * d[1, 2]
            f3 = q0 * d[2, 0] + q1 * d[2, 1] + q2 * d[2, 2]
            out[k1 + i] += f1
            out[k2 + i] += f2
            out[k3 + i] += f3
            out[k0 + i] -= f1 + f2 + f3


@_jit
def energy_p1(x, X, nodes, Dm_inv, V, kind, prm):
    """E = sum_e V_e psi(F_e); +inf as soon as one psi is not finite (inadmissible state).

    Summed in blocks of 1024 elements, so the round-off grows like that of
    numpy's pairwise sum rather than with the number of elements.
    """
    total = 0.0
    block = 0.0
    for e in range(nodes.shape[0]):
        F = _deformation_gradient(x, X, nodes, Dm_inv, e)
        w = psi(kind, F, prm)
        if not math.isfinite(w):
            return np.inf
        block += w * V[e]
        if (e & 1023) == 1023:
            total += block
            block = 0.0
    return total + block


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
