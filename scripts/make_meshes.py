"""Regenerate the shipped meshes ``meshes/beam.vtu`` and ``meshes/blob.vtu``.

Run from anywhere: ``python scripts/make_meshes.py``. Both meshes are
deterministic (no random numbers), so rerunning reproduces the same files.

- beam.vtu: ``fem_elastic.beam_mesh()`` with its defaults, 1 m x 0.1 m x 0.1 m,
  20 x 2 x 2 cells (480 tets), boundaries left/right/front/back/bottom/top.
- blob.vtu: a lumpy, bunny-like body about 0.2 m long: skfem's ball (4096 tets)
  stretched into an ellipsoid, given smooth lobes (head, two ears, haunch,
  tail), its underside flattened, and set down on z = 0. Boundary "bottom" is
  the flattened underside, so the blob can be fixed to or rest on the ground.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from skfem import MeshTet

from fem_elastic.geometry.mesh_io import save_mesh
from fem_elastic.geometry.mesh import beam_mesh, mesh_quality, reorient, validate_mesh

MESHES = Path(__file__).resolve().parent.parent / "meshes"

# (direction, amplitude, angular width): smooth radial bumps on the unit ball.
LOBES = [
    ((1.0, 0.0, 0.45), 0.35, 0.35),  # head, forward and up
    ((0.55, 0.35, 1.0), 0.45, 0.18),  # left ear
    ((0.55, -0.35, 1.0), 0.45, 0.18),  # right ear
    ((-0.6, 0.0, 0.3), 0.20, 0.50),  # haunch
    ((-1.0, 0.0, 0.1), 0.15, 0.20),  # tail
]
SIZE = 0.1  # m, radius of the ball before shaping
FLAT_BELOW = -0.6  # underside (unit-ball z) compressed into a thin, almost flat layer
BOTTOM_BAND = 0.05  # boundary facets lower than this fraction of the height are "bottom"


def blob_mesh() -> MeshTet:
    """The bunny-like blob, reoriented, with boundary "bottom"."""
    ball = MeshTet.init_ball(nrefs=3)
    x = ball.p.copy()
    r = np.linalg.norm(x, axis=0)
    direction = x / np.maximum(r, 1e-12)
    bump = np.zeros_like(r)
    for c, amplitude, width in LOBES:
        c = np.asarray(c) / np.linalg.norm(c)
        bump += amplitude * np.exp((c @ direction - 1.0) / width**2)
    # r**2 fades the bumps out towards the centre, keeping inner tets unstretched.
    x = x * (1.0 + r**2 * bump)
    x *= np.array([1.3, 0.9, 1.0])[:, None]  # body longer than wide
    # Piecewise-linear, increasing map in z flattens the underside without
    # folding tets over.
    x[2] = np.where(x[2] < FLAT_BELOW, FLAT_BELOW + 0.25 * (x[2] - FLAT_BELOW), x[2])
    x[2] -= x[2].min()
    mesh = reorient(MeshTet(SIZE * x, ball.t))
    height = mesh.p[2].max()
    mesh = mesh.with_boundaries({"bottom": lambda m: m[2] < BOTTOM_BAND * height})
    # with_boundaries tests facet midpoints; require every vertex below the band.
    bottom = mesh.boundaries["bottom"]
    keep = np.all(mesh.p[2, mesh.facets[:, bottom]] < BOTTOM_BAND * height, axis=0)
    return validate_mesh(mesh.with_boundaries({"bottom": bottom[keep]}))


def main() -> None:
    MESHES.mkdir(exist_ok=True)
    for name, mesh in (("beam", validate_mesh(beam_mesh())), ("blob", blob_mesh())):
        path = save_mesh(mesh, MESHES / f"{name}.vtu")
        q = mesh_quality(mesh)
        print(
            f"{path}: {q['n_vertices']} vertices, {q['n_elements']} tets, "
            f"min quality {q['min_quality']:.3f}, boundaries {q['boundaries']}, "
            f"{path.stat().st_size / 1024:.0f} KiB"
        )


if __name__ == "__main__":
    main()
