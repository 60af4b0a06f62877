"""The numba update of a symplectic Euler step (imported by explicit.py on first use, with numba only).

One pass over the DOFs replaces the numpy path's six (negate, scale by the
inverse mass, zero the held DOFs, ``v + h a``, ``x + h v1``, then the two
finiteness scans of the next step's :func:`check_state`): on the
153,600-tet beam those are ~0.3 ms a step against a force kernel of 5-10 ms.
The operations and their order are the numpy path's, without FMA contraction
(numba does not contract without ``fastmath``), so the result is the same
bits: ``a = (-g) m^-1`` (negation is exact, so ``-(g m^-1)`` is the same
number), ``v1 = a h + v``, ``x1 = v1 h + x``, then the held DOFs set to their
prescription.
"""

from __future__ import annotations

import math

import numba

__all__ = ["symplectic_update"]


@numba.njit(cache=True, error_model="numpy", nogil=True)
def symplectic_update(f, negate, inv_mass, h, x, v, held, x_held, v_held, x1, v1):
    """x1, v1 of a symplectic Euler step from the force ``f`` (or ``-f``), and whether both are finite.

    Parameters
    ----------
    f : numpy.ndarray
        ``(ndofs,)``: the force (N), or dPi/dx when ``negate`` (then ``-f`` is the force).
    negate : bool
    inv_mass : numpy.ndarray
        ``(ndofs,)``, 1 / the lumped mass (1/kg).
    h : float
        The step (s).
    x, v : numpy.ndarray
        ``(ndofs,)`` positions (m) and velocities (m/s) at the step's start.
    held : numpy.ndarray
        int, the held DOFs; ``x_held``, ``v_held`` their positions (m) and velocities (m/s).
    x1, v1 : numpy.ndarray
        ``(ndofs,)``, overwritten with the step's end.

    Returns
    -------
    bool
        True if every entry of x1 and v1 is finite (the held ones included).
    """
    for i in range(x.shape[0]):
        a = f[i]
        if negate:
            a = -a
        a = a * inv_mass[i]
        vi = a * h + v[i]
        v1[i] = vi
        x1[i] = vi * h + x[i]
    for k in range(held.shape[0]):
        x1[held[k]] = x_held[k]
        v1[held[k]] = v_held[k]
    # a separate pass: a finiteness test inside the update loop would keep it from vectorizing
    for i in range(x1.shape[0]):
        if not (math.isfinite(x1[i]) and math.isfinite(v1[i])):
            return False
    return True
