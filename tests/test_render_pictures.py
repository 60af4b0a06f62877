"""Renders compared with stored pictures (issue 20, item 3): what the renderer draws stays drawn.

Each case simulates a small run, saves it (``traj.save``), draws one frame
with :func:`fe.render_frame` at 240 x 150 pixels and compares it with
``tests/images/<case>.png`` through VTK's image difference
(:func:`pyvista.compare_images`). The references are small (a few KB).

To regenerate them after a deliberate change of the pictures (look at them
first!)::

    FEM_ELASTIC_REGENERATE_IMAGES=1 .venv/bin/python -m pytest -q tests/test_render_pictures.py

The checks that do not depend on pixels (the magnification chosen, the ground
in frame, the colour bar's band) are asserted on the scene itself.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

import fem_elastic as fe

pv = pytest.importorskip("pyvista")
pytest.importorskip("imageio")

IMAGES = Path(__file__).parent / "images"
REGENERATE = os.environ.get("FEM_ELASTIC_REGENERATE_IMAGES") == "1"
SIZE = (240, 150)

#: vtkImageDifference's thresholded error summed over the picture (pyvista's own image tests
#: fail above 500 and warn above 200): the anti-aliasing and font hinting of another OpenGL
#: (llvmpipe, EGL, a GPU driver) move edge pixels by a few levels, a changed picture (a lost
#: outline, a moved colour bar, a different magnification) costs thousands.
MAX_ERROR = 500.0


def _cantilever(tmp_path):
    """A stiff cantilever under gravity: a deflection far under 5 % of its length."""
    model = fe.Model(fe.beam_mesh(cells=(6, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.LinearElastic(E=1e9, nu=0.3)), fixed="left",
                     gravity=(0.0, 0.0, -9.81), damping=fe.Rayleigh(50.0, 0.0))
    traj = fe.simulate(model, fe.ImplicitEuler(), dt=0.02, steps=4)
    return traj.save(tmp_path / "stiff")


def _drop(tmp_path):
    """A soft block falling onto the ground: drawn as it is, ground whole in the picture."""
    model = fe.Model(fe.beam_mesh(length=0.3, width=0.3, height=0.1, cells=(2, 2, 1)),
                     density=1000.0, body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)),
                     gravity=(0.0, 0.0, -9.81), ground=fe.Ground(z=-0.05))
    # 8 steps: the block lands (after ~0.1 s), so the colours show contact stresses; in free fall
    # the stress is round-off (1e-11 Pa), whose pattern any change of linear solver redraws.
    traj = fe.simulate(model, fe.ImplicitEuler(), dt=0.02, steps=8)
    return traj.save(tmp_path / "drop")


CASES = {"cantilever_warped": _cantilever, "drop_on_ground": _drop}


@pytest.mark.parametrize("case", sorted(CASES))
def test_render_matches_the_reference_picture(tmp_path, case):
    run_dir = CASES[case](tmp_path)
    out = fe.render_frame(run_dir, tmp_path / f"{case}.png", size=SIZE)
    reference = IMAGES / f"{case}.png"
    if REGENERATE:
        IMAGES.mkdir(exist_ok=True)
        shutil.copyfile(out, reference)
    if not reference.is_file():
        pytest.fail(f"no reference picture {reference}; regenerate (see the module docstring)")
    error = pv.compare_images(pv.read(out), pv.read(reference))
    assert error <= MAX_ERROR, (
        f"{case}: the render differs from {reference} (error {error:.0f} > {MAX_ERROR}); look at "
        f"{out} and regenerate the reference if the change is deliberate"
    )


def test_scene_layout(tmp_path):
    """Magnification, outline, ground in frame and the colour bar's band, on the scene."""
    from fem_elastic.app.render import _load_runs
    from fem_elastic.app.render_scene import BAR_BAND, _Scene, warp_factor

    stiff = _load_runs([_cantilever(tmp_path)], None, "von_mises", 1)
    u = max(float(np.linalg.norm(r.displacement, axis=2).max()) for r in stiff)
    factor = warp_factor(stiff)
    assert u < 0.05 * 1.0 and factor > 1  # under 5 % of the 1 m beam: magnified ...
    # ... to 15 % of it rounded down to 1-2-5 steps (the widest step, 2 -> 5, divides by under
    # 2.5): between 6 and 15 %, 1e-12 for the round-off of the product
    assert 0.15 / 2.5 < factor * u <= 0.15 + 1e-12
    assert warp_factor(stiff, 1.0) == 1.0
    with pytest.raises(fe.InvalidParameter, match="warp"):
        warp_factor(stiff, -2)
    drop = _load_runs([_drop(tmp_path)], None, "von_mises", 1)
    assert warp_factor(drop) == 1.0  # a run with a ground is never magnified
    scene = _Scene(pv, drop, "von_mises", SIZE)
    try:
        scene.draw(0)
        renderer = scene.plotter.renderers[0]
        # every corner of the ground plane projects inside the picture
        ground = [a for a in renderer.actors.values()
                  if getattr(a, "mapper", None) is not None and a.mapper.dataset is not None
                  and a.mapper.dataset.n_cells == 1]
        assert ground, "no ground plane drawn"
        for x, y, z in ground[0].mapper.dataset.points:
            renderer.SetWorldPoint(float(x), float(y), float(z), 1.0)
            renderer.WorldToDisplay()
            px, py, _ = renderer.GetDisplayPoint()
            assert 0 <= px <= SIZE[0] and BAR_BAND * SIZE[1] * 0.5 <= py <= SIZE[1]
        # the undeformed outline: an actor of lines only, on the reference positions
        datasets = [a.mapper.dataset for a in renderer.actors.values()
                    if getattr(a, "mapper", None) is not None and a.mapper.dataset is not None]
        lines = [d for d in datasets if d.n_cells and d.n_lines == d.n_cells]
        assert lines, "no undeformed outline drawn"
        reference = {tuple(x) for x in drop[0].points_ref}
        assert all(tuple(x) in reference for x in np.asarray(lines[0].points))
    finally:
        scene.close()
