"""Benchmark: the generated Neo-Hookean of ``fe.material_from_energy`` against the hand-written one.

Times ``psi``, the stress ``P = dpsi_dF``, the tangent ``d2psi_dF2`` and its PSD
projection ``d2psi_dF2_psd`` on the same batch of deformation gradients (default
150,000 elements x 4 quadrature points = 600,000 points, scikit-fem's
``(3, 3, nelems, nqp)`` layout), for

- ``fe.NeoHookean`` (hand-written numpy, the reference),
- the same energy generated from its invariants,
  ``psi(I1, I2, J) = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2``
  (``fe.energies.neo_hookean``),
- the same energy generated from F, ``mu/2 (tr F^T F - 3) - mu ln det F + ...``
  (its projection eigen-decomposes 9x9 matrices: timed on a smaller batch unless
  ``--f-projection``),

and prints the ratio generated / hand-written of the medians (the goal: within 2x).
It also checks that the three agree to round-off on the batch. The batch is a random
mix of stretches, shears and compressions (all ``det F > 0``) in which about a third of
the points have an indefinite tangent, so the projection has work to do.

BLAS/OpenMP threads are pinned to 1 with threadpoolctl where it is installed.

Usage::

    python scripts/bench_material_from_energy.py            # 150k x 4 points, ~1 min
    python scripts/bench_material_from_energy.py --quick    # 2k x 4 points, seconds
    python scripts/bench_material_from_energy.py --elements 50000 --repeats 7
"""

from __future__ import annotations

import argparse
import contextlib
import platform
import statistics
import time

import numpy as np


def timed(fn, repeats):
    """(median seconds, last result) of ``repeats`` calls."""
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def sample_F(nelems: int, nqp: int, seed: int = 0) -> np.ndarray:
    """Random deformation gradients ``(3, 3, nelems, nqp)`` with ``det F > 0.1``."""
    rng = np.random.default_rng(seed)
    n = nelems * nqp
    F = np.eye(3)[:, :, None] + 0.25 * rng.standard_normal((3, 3, n))
    J = np.linalg.det(np.moveaxis(F, -1, 0))
    bad = J < 0.1
    F[..., bad] = np.eye(3)[:, :, None] * np.linspace(0.6, 1.4, int(bad.sum()))  # pure dilations
    return F.reshape(3, 3, nelems, nqp)


def neo_hookean_of_F(F, mu, lam):
    import fem_elastic as fe

    J = fe.math.det(F)
    return mu / 2 * (fe.math.trace(F.T @ F) - 3) - mu * fe.math.log(J) + lam / 2 * fe.math.log(J) ** 2


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--elements", type=int, default=150_000, help="number of elements (default 150000)")
    parser.add_argument("--qp", type=int, default=4, help="quadrature points per element (default 4)")
    parser.add_argument("--quick", action="store_true", help="2000 elements (seconds)")
    parser.add_argument("--repeats", type=int, default=5, help="repeats of each timing (median)")
    parser.add_argument("--f-projection", action="store_true",
                        help="time the F-form's 9x9 projection on the full batch too (slow)")
    args = parser.parse_args(argv)
    nelems = 2000 if args.quick else args.elements
    try:
        from threadpoolctl import threadpool_limits
        limit = threadpool_limits(limits=1)
    except ImportError:  # not a dependency of the library
        limit = contextlib.nullcontext()
    with limit:
        run(nelems, args.qp, args.repeats, args.f_projection)


def run(nelems, nqp, repeats, f_projection):
    import fem_elastic as fe

    mu, lam = 3.4e5, 3.1e6
    F = sample_F(nelems, nqp)
    n = F[0, 0].size
    print(f"fe.material_from_energy vs fe.NeoHookean: {nelems} elements x {nqp} qp = {n} points, "
          f"numpy {np.__version__}, {platform.processor() or platform.machine()}")
    t0 = time.perf_counter()
    inv = fe.material_from_energy(fe.energies.neo_hookean, mu=mu, lam=lam)
    t_inv = time.perf_counter() - t0
    t0 = time.perf_counter()
    of_F = fe.material_from_energy(neo_hookean_of_F, mu=mu, lam=lam)
    t_F = time.perf_counter() - t0
    print(f"derivation + code generation: invariants {t_inv:.2f} s (sympy import included), "
          f"F {t_F:.2f} s")
    hand = fe.NeoHookean(mu=mu, lam=lam)
    small = F[:, :, : max(1, min(nelems, 5000))]
    methods = [("psi", "psi"), ("P", "dpsi_dF"), ("tangent", "d2psi_dF2"),
               ("projected tangent", "d2psi_dF2_psd")]
    print(f"{'':20s}{'hand-written':>14s}{'invariants':>14s}{'ratio':>8s}{'of F':>14s}{'ratio':>8s}")
    ratios, worst = {}, 0.0
    for label, method in methods:
        reps = repeats if method != "d2psi_dF2_psd" else max(1, min(repeats, 3))  # ~10 s each
        t_hand, ref = timed(lambda f=getattr(hand, method): f(F), reps)
        t_i, out_i = timed(lambda f=getattr(inv, method): f(F), reps)
        scale = np.abs(ref).max()
        worst = max(worst, float(np.abs(out_i - ref).max() / scale))
        del out_i
        if method == "d2psi_dF2_psd" and not f_projection:
            t_hs, _ = timed(lambda: hand.d2psi_dF2_psd(small), repeats)
            t_f, out_f = timed(lambda: of_F.d2psi_dF2_psd(small), max(1, repeats // 2))
            ratio_f, note = t_f / t_hs, f" ({small[0, 0].size} points)"
        else:
            t_f, out_f = timed(lambda f=getattr(of_F, method): f(F), reps)
            ratio_f, note = t_f / t_hand, ""
            worst = max(worst, float(np.abs(out_f - ref).max() / scale))
        del out_f, ref
        ratios[label] = t_i / t_hand
        print(f"{label:20s}{t_hand * 1e3:11.1f} ms{t_i * 1e3:11.1f} ms{t_i / t_hand:7.2f}x"
              f"{t_f * 1e3:11.1f} ms{ratio_f:7.2f}x{note}")
    print("generated / hand-written (medians, invariant form): "
          + ", ".join(f"{k} {v:.2f}x" for k, v in ratios.items()))
    verdict = "within" if max(ratios.values()) <= 2.0 else "NOT within"
    print(f"goal <= 2x: {verdict} (worst {max(ratios.values()):.2f}x)")
    print(f"max rel. difference to fe.NeoHookean: {worst:.2e}")


if __name__ == "__main__":
    main()
