"""Off-screen rendering of run directories (fem_elastic.app.render)."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import fem_elastic as fe

pv = pytest.importorskip("pyvista")
iio = pytest.importorskip("imageio.v3")

from fem_elastic.app import render  # noqa: E402  (after the skip: pyvista is optional)
from fem_elastic.app.vtu import write_pvd
from fem_elastic.app.vtu import write_vtu_frame  # noqa: E402

SIZE = (160, 120)  # small pictures keep the tests fast; 160 x 120 still shows the beam


def _write_run(run_dir, mesh, times, displacement, von_mises, ground_z=-0.3, variant=None):
    """A run directory in the output format: frames/, series.pvd, summary.json."""
    (run_dir / "frames").mkdir(parents=True)
    entries = []
    for k, t in enumerate(times):
        name = f"frames/frame_{k:06d}.vtu"
        write_vtu_frame(run_dir / name, mesh.p.T + displacement[k], mesh.t.T,
                        {"displacement": displacement[k],
                         "velocity": np.zeros_like(displacement[k])},
                        {"von_mises": von_mises[k]})
        entries.append((t, name))
    write_pvd(run_dir / "series.pvd", entries)
    summary = {"variant": variant or run_dir.name, "status": "completed",
               "ground": None if ground_z is None else {"kind": "plane", "z": ground_z}}
    (run_dir / "summary.json").write_text(json.dumps(summary))
    return run_dir


def _bending(mesh, times, lift=0.0, uniform=False):
    """A cantilever bending down (w = -a(t) x^2) and rising by ``lift`` t (m/s).

    Returns the displacement (T, n, 3) m and a von Mises field (T, m) Pa that is
    largest at the clamp (x = 0) and vanishes at the tip, as in a bending beam
    (or equal in every tet with ``uniform``).
    """
    x = mesh.p[0]
    xc = mesh.p[0, mesh.t].mean(axis=0)
    a = 0.3 * times / times[-1]
    disp = np.zeros((len(times), mesh.p.shape[1], 3))
    disp[:, :, 2] = -a[:, None] * x[None] ** 2 + lift * times[:, None]
    shape = np.ones_like(xc) if uniform else 1.0 - xc
    vm = 1e5 * (a[:, None] + 0.01) * shape[None]
    return disp, vm


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """A soft cantilever falling under gravity, as FEM and as springs: fe.simulate + SeriesWriter.

    Five frames (t = 0, 0.1, ..., 0.4 s); the tip falls about 0.5 m, so the
    stress runs from 0 at the tip to its largest at the clamp.
    """
    from fem_elastic.app.output import SeriesWriter

    root = tmp_path_factory.mktemp("simulated")
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(4, 1, 1))
    dirs = {}
    for name, body in (("fem", fe.ElasticBody(fe.NeoHookean(E=2e5, nu=0.3))),
                       ("springs", fe.MassSpring(E=2e5, nu=0.25))):
        model = fe.Model(mesh, density=1000.0, body=body, fixed="left", gravity=(0, 0, -9.81),
                         ground=fe.Ground(z=-0.5))
        writer = SeriesWriter(model, root / name, every=2, n_steps=8, info={"variant": name})
        state = fe.State.rest(model)
        writer.write_state(state)
        run = fe.simulate(model, fe.ImplicitEuler(), dt=0.05, steps=8, state=state, record_every=2,
                          callback=writer.callback)
        writer.finish(run)
        dirs[name] = root / name
    return dirs


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Series with a motion and stress made to order, five frames each (t = 0 ... 0.4 s)."""
    root = tmp_path_factory.mktemp("runs")
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(4, 1, 1))
    times = np.linspace(0.0, 0.4, 5)
    d, vm = _bending(mesh, times)
    fem = _write_run(root / "fem", mesh, times, d, vm)
    springs = _write_run(root / "springs", mesh, times, 0.7 * d, 0.5 * vm)
    d, vm = _bending(mesh, times, lift=1.0)
    rising = _write_run(root / "rising", mesh, times, d, vm, ground_z=-0.2)
    d, vm = _bending(mesh, times, uniform=True)
    uniform = _write_run(root / "uniform", mesh, times, d, vm, ground_z=None)
    return {"fem": fem, "springs": springs, "rising": rising, "uniform": uniform, "times": times}


def _overlays(shape, viewports=1):
    """Where the scalar bar (bottom right of the last viewport, under 30 % of its height
    at 120 px) and the time labels (bottom left of each viewport) are drawn."""
    h, w = shape[:2]
    mask = np.zeros((h, w), dtype=bool)
    mask[int(0.7 * h):, w - int(0.6 * w / viewports):] = True
    for v in range(viewports):
        mask[int(0.75 * h):, v * w // viewports: v * w // viewports + w // (2 * viewports)] = True
    return mask


def _chromatic(img, viewports=1):
    """Pixels of the coloured mesh: the background, ground and text are grey (r = g = b)."""
    rgb = img[..., :3].astype(int)
    return (rgb.max(axis=2) - rgb.min(axis=2) > 24) & ~_overlays(img.shape, viewports)


def test_png_has_the_size_and_colours_that_follow_the_stress(simulated, runs, tmp_path):
    path = render.render_frame(simulated["fem"], tmp_path / "a.png", size=SIZE)
    img = iio.imread(path)
    assert img.shape[:2] == (SIZE[1], SIZE[0])
    assert len(np.unique(img.reshape(-1, img.shape[2]), axis=0)) > 20
    body = img[_chromatic(img)][:, :3].astype(int)
    assert len(body) > 200  # the beam covers a good part of the picture
    # viridis runs from dark blue-purple (low stress, at the tip) to yellow (high, at the clamp)
    low = (body[:, 2] > body[:, 0] + 30).sum()
    high = ((body[:, 0] > 150) & (body[:, 1] > 150) & (body[:, 2] < 120)).sum()
    assert low > 10 and high > 3

    # the same picture with one stress in every tet: a single hue, shaded by the light only
    path = render.render_frame(runs["uniform"], tmp_path / "u.png", size=SIZE)
    img = iio.imread(path)
    body = img[_chromatic(img)][:, :3].astype(int)
    assert len(body) > 200
    assert (body[:, 2] > body[:, 0] + 30).sum() == 0


def test_camera_is_fixed_over_the_run(runs, tmp_path):
    size = (240, 180)  # the ground is a thin strip seen from the low camera: more pixels
    paths = render.render_runs(runs["rising"], tmp_path / "frames", format="png", size=size)
    assert [p.name for p in paths] == [f"frame_{k:04d}.png" for k in range(5)]
    first, last = iio.imread(paths[0]), iio.imread(paths[-1])
    # the body rose by 0.4 m: its pixels moved
    assert (_chromatic(first) != _chromatic(last)).sum() > 100
    # everything else (background, ground, scalar bar) stays put, pixel for pixel, but the
    # time label (bottom left)
    from scipy.ndimage import binary_dilation, binary_erosion

    rgb = first[..., :3].astype(int)
    coloured = [img[..., :3].max(axis=2) - img[..., :3].min(axis=2) > 24 for img in (first, last)]
    # the body's silhouette blends into the ground over a pixel: keep off it
    still = binary_erosion(~coloured[0] & ~coloured[1], iterations=2)
    still[int(0.85 * size[1]):, : int(0.35 * size[0])] = False
    white = (rgb == 255).all(axis=2)
    ground = still & (rgb.min(axis=2) > 120) & ~white
    # the ground and its border with the background are compared: a camera that moved
    # by a pixel would move that border
    assert ground.sum() > 300
    assert (ground & binary_dilation(still & white)).sum() > 30
    np.testing.assert_array_equal(first[still], last[still])


def test_gif_has_one_frame_per_recorded_frame(simulated, tmp_path):
    (path,) = render.render_runs(simulated["springs"], tmp_path / "m.gif", format="gif", size=SIZE,
                                 fps=10)
    frames = iio.imread(path, index=None)
    assert frames.shape[0] == 5 and frames.shape[1:3] == (SIZE[1], SIZE[0])
    (path,) = render.render_runs(simulated["springs"], tmp_path / "m2.gif", format="gif",
                                 size=SIZE, every=3)
    assert iio.imread(path, index=None).shape[0] == 3  # frames 0, 3 and the last one


def test_mp4_reads_back_with_its_frames_and_size(simulated, tmp_path):
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    (path,) = render.render_runs([simulated["fem"], simulated["springs"]], tmp_path / "m.mp4",
                                 size=SIZE)
    assert path.stat().st_size > 1000
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp file left
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = reader.__next__()
    assert tuple(meta["size"]) == SIZE
    assert sum(1 for _ in reader) == 5


def test_side_by_side_splits_the_width(simulated, tmp_path):
    size = (2 * SIZE[0], SIZE[1])
    path = render.render_frame([simulated["fem"], simulated["springs"]], tmp_path / "s.png",
                               size=size, frame=2)
    img = iio.imread(path)
    assert img.shape[:2] == (size[1], size[0])
    mesh = _chromatic(img, viewports=2)
    for half in (slice(0, SIZE[0]), slice(SIZE[0], None)):
        assert len(np.unique(img[:, half].reshape(-1, img.shape[2]), axis=0)) > 20
        assert mesh[:, half].sum() > 200


def test_rows_of_frames(runs, tmp_path):
    size = (2 * SIZE[0], 2 * SIZE[1])
    path = render.render_frame([runs["fem"], runs["springs"]], tmp_path / "g.png", size=size,
                               frame=(0, -1), color_by="displacement")
    img = iio.imread(path)
    mesh = _chromatic(img, viewports=2)
    top, bottom = mesh[: SIZE[1]], mesh[SIZE[1]:]
    assert top.sum() > 100 and bottom.sum() > 100
    # the beam bent between the first and the last frame
    assert (top != bottom).sum() > 50


def test_color_range_ignores_spikes_and_non_finite_values():
    values = np.concatenate([np.linspace(0.0, 1.0, 1000), [1e9, np.nan, np.inf]])
    lo, hi = render.color_range([values])
    assert lo == 0.0 and 0.98 < hi < 1.0
    assert render.color_range([[np.nan]]) == (0.0, 1.0)


@pytest.mark.parametrize("kwargs, match", [
    ({"format": "avi"}, "format"),
    ({"color_by": "pressure"}, "color_by"),
    ({"size": (161, 120)}, "even"),
    ({"every": 0}, "every"),
    ({"titles": ["a", "b"]}, "title"),
])
def test_bad_arguments_raise_invalid_parameter(runs, tmp_path, kwargs, match):
    with pytest.raises(fe.InvalidParameter, match=match):
        render.render_runs(runs["fem"], tmp_path / "x.mp4", **{"size": SIZE, **kwargs})
    assert not list(tmp_path.iterdir())


def test_a_directory_without_series_is_refused(simulated, tmp_path):
    with pytest.raises(fe.InvalidParameter, match="series.pvd"):
        render.render_runs(tmp_path, tmp_path / "x.gif", format="gif", size=SIZE)
    # a scene's output folder: the message names the run directories in it
    with pytest.raises(fe.InvalidParameter, match="its folders fem, springs do"):
        render.render_runs(simulated["fem"].parent, tmp_path / "x.gif", format="gif", size=SIZE)


def test_runs_with_different_frame_times_are_refused(runs, tmp_path):
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(4, 1, 1))
    times = np.linspace(0.0, 0.8, 5)  # same count, another clock
    d, vm = _bending(mesh, times)
    other = _write_run(tmp_path / "other", mesh, times, d, vm)
    with pytest.raises(fe.InvalidParameter, match="frame times differ"):
        render.render_runs([runs["fem"], other], tmp_path / "x.gif", format="gif", size=SIZE)


def test_a_run_that_stopped_early_holds_its_last_frame(runs, tmp_path):
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(4, 1, 1))
    times = runs["times"][:3]
    d, vm = _bending(mesh, times)
    short = _write_run(tmp_path / "short", mesh, times, d, vm)
    summary = json.loads((short / "summary.json").read_text())
    (short / "summary.json").write_text(json.dumps({**summary, "status": "diverged"}))
    paths = render.render_runs([runs["fem"], short], tmp_path / "f", format="png",
                               size=(2 * SIZE[0], SIZE[1]))
    assert len(paths) == 5
    body = [_chromatic(iio.imread(p), viewports=2)[:, SIZE[0]:] for p in paths]
    np.testing.assert_array_equal(body[2], body[4])  # held after its last frame
    assert (body[0] != body[2]).any()


def test_a_failed_run_says_where_and_why_on_every_frame(tmp_path):
    """A run that blew up: its frames say "diverged at step N: reason" under the title."""
    from fem_elastic.app.output import SeriesWriter
    from fem_elastic.app.render_scene import _run_from_series, failure_line, failure_text, time_stamp
    from fem_elastic.app.vtu import read_series

    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(2, 1, 1))
    model = fe.Model(mesh, density=1000.0, body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)),
                     fixed="left", gravity=(0.0, 0.0, -9.81))
    # 20 times the stable step of symplectic Euler: the stiffest mode grows by orders of
    # magnitude a step, so the blow-up watch stops the run within a few steps
    dt = 20.0 * fe.critical_time_step(model, fe.SymplecticEuler())
    run_dir = tmp_path / "blown"
    writer = SeriesWriter(model, run_dir, info={"variant": "blown"})
    writer.write_state(fe.State.rest(model))
    with pytest.raises(fe.Diverged) as err:
        fe.simulate(model, fe.SymplecticEuler(), dt=dt, steps=40, check_stability=False,
                    observers=[writer])
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "diverged" and summary["failed_step"] == err.value.step
    run = _run_from_series(read_series(run_dir), "blown", "displacement")
    head = f"diverged at step {err.value.step}: "
    assert run.failure.startswith(head) and len(run.failure) <= len(head) + 60
    last = len(run.times) - 1
    for j, t in enumerate(run.times):
        assert time_stamp(run, j) == f"t = {t:.3f} s" + (" (last good state)" if j == last else "")
    # wrapped to the panel, two lines at most (the first 100-pixel line holds 20 characters)
    lines = failure_text(run.failure, width=100.0, font=8).split("\n")
    assert len(lines) == 2 and lines[0].startswith(head[:16]) and max(map(len, lines)) <= 20
    # a trajectory saved with .save() records the failure in its message only
    assert failure_line({"status": "failed", "message": "failed at step 4: the solver\ngave up"}) \
        == "failed at step 4: the solver gave up"
    assert failure_line({"status": "completed", "failed_step": 3}) == ""

    # on the picture: the same frame of the run marked completed has its title alone at the
    # top, so the failed one has more dark (text) pixels there, above the body
    done = tmp_path / "done"
    shutil.copytree(run_dir, done)
    (done / "summary.json").write_text(json.dumps({**summary, "status": "completed"}))
    dark = []
    for d in (run_dir, done):
        png = render.render_frame([d], tmp_path / f"{d.name}.png", frame=0, size=SIZE,
                                  color_by="displacement", warp=1.0)
        img = iio.imread(png)[..., :3].astype(int)
        top = img[: int(0.3 * SIZE[1])]
        dark.append(int((top.max(axis=2) < 100).sum()))
    assert dark[0] > dark[1] > 0, dark


def test_missing_von_mises_names_the_fields_there_are(tmp_path):
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(4, 1, 1))
    run = tmp_path / "run"
    (run / "frames").mkdir(parents=True)
    zero = np.zeros((mesh.p.shape[1], 3))
    write_vtu_frame(run / "frames/f.vtu", mesh.p.T, mesh.t.T,
                    {"displacement": zero, "velocity": zero})
    write_pvd(run / "series.pvd", [(0.0, "frames/f.vtu")])
    with pytest.raises(fe.InvalidParameter, match="displacement"):
        render.render_frame(run, tmp_path / "a.png", size=SIZE)
    path = render.render_frame(run, tmp_path / "a.png", size=SIZE, color_by="displacement")
    assert path.is_file()


def test_missing_pyvista_says_what_to_install(runs, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyvista", None)  # import pyvista now fails
    install = r'pip install "fem_elastic\[render\]"'
    with pytest.raises(render.MissingDependency, match=install) as err:
        render.render_frame(runs["fem"], tmp_path / "a.png", size=SIZE)
    assert isinstance(err.value, ModuleNotFoundError) and isinstance(err.value, fe.FemElasticError)


def test_readme_script_renders_a_demo_output_headless_and_quietly(simulated, tmp_path):
    """scripts/render_readme.py on finished runs, with no display: a PNG, no VTK warning."""
    script = Path(__file__).resolve().parent.parent / "scripts" / "render_readme.py"
    env = {k: v for k, v in os.environ.items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY", "VTK_DEFAULT_OPENGL_WINDOW")}
    out = tmp_path / "docs" / "demo.png"
    r = subprocess.run(
        [sys.executable, str(script), "--runs", str(simulated["fem"].parent), "--out", str(out),
         "--size", "320", "240"],
        capture_output=True, text=True, env=env, timeout=300,
    )
    assert r.returncode == 0, r.stderr
    assert f"wrote {out}" in r.stdout and "fem | springs, frames 2 and 4 of 5" in r.stdout
    assert iio.imread(out).shape[:2] == (240, 320)
    if sys.platform.startswith("linux"):
        # VTK tries X first and logs "bad X server connection" unless render.py hides it
        assert "X server" not in r.stderr and "WARN" not in r.stderr, r.stderr
