"""numba sweeps behind :mod:`fem_elastic.dynamics.position_based.constraints` (imported on first use).

Each kernel repeats the numpy projection of its constraint set
(:meth:`ConstraintSet.corrections`) for one constraint at a time, in the
order the set stores them:

- Gauss-Seidel (``jacobi`` False): each projection moves ``x`` at once, so the
  next one sees it. The sets store their constraints colour by colour, and
  within a colour they share no vertex, so this serial loop computes what the
  numpy path computes colour by colour.
- Jacobi (``jacobi`` True): every projection reads the unchanged ``x`` and
  adds its scaled correction into ``dx``; the caller adds ``dx`` to ``x``.

The loops are serial, like the fused force kernels
(:mod:`fem_elastic.discretization._fused_kernels`): one thread, results
independent of a thread count. Compiled with ``cache=True``.

Arguments: x, w ``(ndofs,)`` positions (m) and inverse masses (1/kg); nodes ``(n, k)``; at, lam ``(n, m)`` the compliances
over h^2 and the multipliers (lam updated in place); scale ``(n,)`` the factor
on each projection; dx ``(ndofs,)`` the Jacobi accumulator.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_jit = numba.njit(cache=True, error_model="numpy", nogil=True)


@_jit
def edge_sweep(x, w, nodes, rest, at, lam, scale, jacobi, dx):
    """Distance constraints ``|x_b - x_a| - l0``: one Gauss-Seidel or Jacobi sweep."""
    for e in range(nodes.shape[0]):
        a, b = 3 * nodes[e, 0], 3 * nodes[e, 1]
        d0, d1, d2 = x[b] - x[a], x[b + 1] - x[a + 1], x[b + 2] - x[a + 2]
        length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if length == 0.0:
            continue
        n0, n1, n2 = d0 / length, d1 / length, d2 / length
        den = (w[a] * n0 * n0 + w[a + 1] * n1 * n1 + w[a + 2] * n2 * n2
               + w[b] * n0 * n0 + w[b + 1] * n1 * n1 + w[b + 2] * n2 * n2) + at[e, 0]
        if den <= 0.0:
            continue
        dlam = (-(length - rest[e]) - at[e, 0] * lam[e, 0]) / den
        s = scale[e]
        lam[e, 0] += s * dlam
        q = s * dlam
        if jacobi:
            dx[a] -= q * w[a] * n0
            dx[a + 1] -= q * w[a + 1] * n1
            dx[a + 2] -= q * w[a + 2] * n2
            dx[b] += q * w[b] * n0
            dx[b + 1] += q * w[b + 1] * n1
            dx[b + 2] += q * w[b + 2] * n2
        else:
            x[a] -= q * w[a] * n0
            x[a + 1] -= q * w[a + 1] * n1
            x[a + 2] -= q * w[a + 2] * n2
            x[b] += q * w[b] * n0
            x[b + 1] += q * w[b + 1] * n1
            x[b + 2] += q * w[b + 2] * n2


@_jit
def _gradients(dCdF, d, g):
    """g[1..3, i] = sum_j dCdF[i, j] d[b, j]; g[0] = -(g[1] + g[2] + g[3]). dCdF a 9-tuple."""
    for i in range(3):
        c0, c1, c2 = dCdF[3 * i], dCdF[3 * i + 1], dCdF[3 * i + 2]
        s = 0.0
        for b in range(3):
            v = c0 * d[b, 0] + c1 * d[b, 1] + c2 * d[b, 2]
            g[b + 1, i] = v
            s += v
        g[0, i] = -s


@_jit
def tet_sweep(x, w, nodes, Dm_inv, kind, shift, at, lam, scale, jacobi, dx):
    """Tet constraints, one sweep: ``kind`` 0 volume (``J - 1``), 1 Neo-Hookean (``sqrt(I_C)``, ``J - gamma``).

    ``shift`` is ``gamma - 1 = mu / lam`` per tet (Neo-Hookean), unused for volume. F is
    formed from the vertex positions, ``H = Ds Dm^-1 - I``: x carries an absolute round-off
    of eps |x| whether it is differenced with X or with another vertex, so the reference
    positions (12 more scattered reads per tet, a third of the sweep's time on the
    153,600-tet beam) buy no precision here.
    """
    g1 = np.zeros((4, 3))
    g2 = np.zeros((4, 3))
    for e in range(nodes.shape[0]):
        k0, k1, k2, k3 = 3 * nodes[e, 0], 3 * nodes[e, 1], 3 * nodes[e, 2], 3 * nodes[e, 3]
        x00, x01, x02 = x[k0], x[k0 + 1], x[k0 + 2]
        a0, a1, a2 = x[k1] - x00, x[k1 + 1] - x01, x[k1 + 2] - x02
        b0, b1, b2 = x[k2] - x00, x[k2 + 1] - x01, x[k2 + 2] - x02
        c0, c1, c2 = x[k3] - x00, x[k3 + 1] - x01, x[k3 + 2] - x02
        d = Dm_inv[e]
        h00 = a0 * d[0, 0] + b0 * d[1, 0] + c0 * d[2, 0] - 1.0
        h01 = a0 * d[0, 1] + b0 * d[1, 1] + c0 * d[2, 1]
        h02 = a0 * d[0, 2] + b0 * d[1, 2] + c0 * d[2, 2]
        h10 = a1 * d[0, 0] + b1 * d[1, 0] + c1 * d[2, 0]
        h11 = a1 * d[0, 1] + b1 * d[1, 1] + c1 * d[2, 1] - 1.0
        h12 = a1 * d[0, 2] + b1 * d[1, 2] + c1 * d[2, 2]
        h20 = a2 * d[0, 0] + b2 * d[1, 0] + c2 * d[2, 0]
        h21 = a2 * d[0, 1] + b2 * d[1, 1] + c2 * d[2, 1]
        h22 = a2 * d[0, 2] + b2 * d[1, 2] + c2 * d[2, 2] - 1.0
        tr = h00 + h11 + h22
        i2 = h00 * h11 + h00 * h22 + h11 * h22 - h01 * h10 - h02 * h20 - h12 * h21
        deth = (h00 * (h11 * h22 - h12 * h21) - h01 * (h10 * h22 - h12 * h20)
                + h02 * (h10 * h21 - h11 * h20))
        jm1 = tr + i2 + deth
        f00, f01, f02 = h00 + 1.0, h01, h02
        f10, f11, f12 = h10, h11 + 1.0, h12
        f20, f21, f22 = h20, h21, h22 + 1.0
        cof = (f11 * f22 - f12 * f21, f12 * f20 - f10 * f22, f10 * f21 - f11 * f20,
               f21 * f02 - f22 * f01, f22 * f00 - f20 * f02, f20 * f01 - f21 * f00,
               f01 * f12 - f02 * f11, f02 * f10 - f00 * f12, f00 * f11 - f01 * f10)
        _gradients(cof, d, g2)
        wa = (w[k0], w[k0 + 1], w[k0 + 2], w[k1], w[k1 + 1], w[k1 + 2],
              w[k2], w[k2 + 1], w[k2 + 2], w[k3], w[k3 + 1], w[k3 + 2])
        cc = 0.0
        for v in range(4):
            for i in range(3):
                cc += wa[3 * v + i] * g2[v, i] * g2[v, i]
        s = scale[e]
        if kind == 0:
            den = cc + at[e, 0]
            if den <= 0.0:
                continue
            dl0 = (-jm1 - at[e, 0] * lam[e, 0]) / den
            dl1 = 0.0
            lam[e, 0] += s * dl0
            q0, q1 = 0.0, s * dl0
        else:
            ic = 3.0 + 2.0 * tr + (h00 * h00 + h01 * h01 + h02 * h02 + h10 * h10 + h11 * h11
                                   + h12 * h12 + h20 * h20 + h21 * h21 + h22 * h22)
            r = math.sqrt(ic) if ic > 0.0 else 0.0
            if r > 0.0:
                _gradients((f00 / r, f01 / r, f02 / r, f10 / r, f11 / r, f12 / r,
                            f20 / r, f21 / r, f22 / r), d, g1)
            else:  # a collapsed tet: the deviatoric gradient is undefined, leave it out
                for v in range(4):
                    for i in range(3):
                        g1[v, i] = 0.0
            aa = 0.0
            ab = 0.0
            for v in range(4):
                for i in range(3):
                    wg = wa[3 * v + i] * g1[v, i]
                    aa += wg * g1[v, i]
                    ab += wg * g2[v, i]
            at0, at1 = at[e, 0], at[e, 1]
            det = max(aa * cc - ab * ab, 0.0) + at0 * cc + at1 * aa + at0 * at1
            if det <= 0.0:
                continue
            r0 = -r - at0 * lam[e, 0]
            r1 = -(jm1 - shift[e]) - at1 * lam[e, 1]
            dl0 = ((cc + at1) * r0 - ab * r1) / det
            dl1 = ((aa + at0) * r1 - ab * r0) / det
            lam[e, 0] += s * dl0
            lam[e, 1] += s * dl1
            q0, q1 = s * dl0, s * dl1
        for v in range(4):
            kv = 3 * nodes[e, v]
            for i in range(3):
                step = wa[3 * v + i] * (q0 * g1[v, i] + q1 * g2[v, i])  # g1 = 0 for a volume
                if jacobi:
                    dx[kv + i] += step
                else:
                    x[kv + i] += step

