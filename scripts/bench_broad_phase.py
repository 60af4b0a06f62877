"""Benchmark: the bounding-sphere broad phase against the number of surface primitives.

For beam surfaces of growing resolution (a 1 x 0.2 x 0.2 m box meshed with tets, its
boundary triangles), times the vertex-triangle broad phase of ``fe.ImpulseContact``
(:class:`fem_elastic.physics.broad_phase.BoundingSpheres`: a k-d tree over the triangles'
bounding spheres, every surface vertex queried with the contact thickness) and prints

1. per size: primitives n (triangles + vertices), candidate pairs, median time;
2. the fitted exponent p of ``time = c n^p`` (least squares in log-log), and the fit of
   ``time = c n log n`` (its constant and the largest relative residual): a tree search is
   O(n log n), an all-pairs loop O(n^2) (p = 2);
3. on the small sizes, the candidates found against a brute-force all-pairs sphere test
   (the same set: the tree only prunes pairs that cannot overlap) and the brute force's time.

Usage::

    python scripts/bench_broad_phase.py            # sizes up to ~100k primitives, ~10 s
    python scripts/bench_broad_phase.py --quick    # up to ~4k primitives, ~1 s
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import fem_elastic as fe
from fem_elastic.physics.broad_phase import BoundingSpheres, triangle_spheres
from fem_elastic.physics.collision_surface import surface_triangles


def surface(k: int):
    """Boundary vertices (n, 3) and triangles of a 1 x 0.2 x 0.2 m beam of 5k x k x k cells."""
    mesh = fe.beam_mesh(length=1.0, width=0.2, height=0.2, cells=(5 * k, k, k))
    points = mesh.p.T
    faces = surface_triangles(mesh.t.T, points)
    verts, local = np.unique(faces, return_inverse=True)
    return points[verts], local.reshape(-1, 3)


def broad_phase(P, faces, thickness):
    centers, radii = triangle_spheres(P, faces)
    return BoundingSpheres(centers, radii).query(P, 0.0, thickness)


def brute_force(P, faces, thickness):
    centers, radii = triangle_spheres(P, faces)
    d = np.linalg.norm(P[:, None, :] - centers[None, :, :], axis=2)
    return np.nonzero(d < radii[None, :] + thickness)


def median_time(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes only")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    ks = [2, 3, 4, 6, 8] if args.quick else [2, 4, 6, 8, 12, 16, 24, 32, 40]
    n_fit = 200 if args.quick else 2000  # below this, fixed Python overhead dominates the timings
    rows = []
    print(f"{'cells':>12} {'n prims':>9} {'candidates':>11} {'tree (s)':>10} {'brute (s)':>10} same")
    for k in ks:
        P, faces = surface(k)
        thickness = 0.05 * 0.2 / k  # 5 % of the cell size
        n = len(P) + len(faces)
        t, (i, j) = median_time(lambda: broad_phase(P, faces, thickness), args.repeats)
        brute, same = "", ""
        if len(P) * len(faces) <= (2e6 if args.quick else 2e7):  # all pairs: memory and time n^2
            tb, (bi, bj) = median_time(lambda: brute_force(P, faces, thickness), 1)
            brute = f"{tb:10.4f}"
            same = str(set(zip(i.tolist(), j.tolist())) == set(zip(bi.tolist(), bj.tolist())))
        rows.append((n, t))
        print(f"{5 * k:>4}x{k:>3}x{k:>3} {n:>9} {len(i):>11} {t:10.4f} {brute:>10} {same}")
    n = np.array([r[0] for r in rows], dtype=float)
    t = np.array([r[1] for r in rows])
    big = n >= n_fit
    p = np.polyfit(np.log(n[big]), np.log(t[big]), 1)[0]
    c = float(np.sum(t[big] * n[big] * np.log(n[big])) / np.sum((n[big] * np.log(n[big])) ** 2))
    resid = np.abs(c * n[big] * np.log(n[big]) - t[big]) / t[big]
    print(f"fitted exponent p in time ~ n^p (n >= {n_fit}): {p:.2f}  (n log n over this range: "
          f"{np.polyfit(np.log(n[big]), np.log(n[big] * np.log(n[big])), 1)[0]:.2f}; all pairs: 2)")
    print(f"fit time = c n log n: c = {c:.3e} s, largest relative residual {resid.max():.0%}")


if __name__ == "__main__":
    main()
