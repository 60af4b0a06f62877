"""Command polish (issue 20, item 5): --version, python -m fem_elastic, info on several meshes,
physical results of every run (printed and in summary.json), scene [probe] points over time."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.app import cli

ROOT = Path(__file__).resolve().parent.parent

SCENE = """\
[scene]
name = "probe"

[mesh]
kind = "beam"
length = 0.4
width = 0.1
height = 0.1
cells = [4, 1, 1]

[body]
material = "neo_hookean"
E = 1e5
nu = 0.3
density = 1000.0

[boundary]
fixed = ["left"]

[loads]
gravity = [0.0, 0.0, -9.81]

[integrator]
type = "implicit_euler"

[time]
dt = 0.01
duration = 0.05

[output]
render = []

[probe]
points = { tip = [0.4, 0.05, 0.1], near_tip = [0.39, 0.0, 0.0] }
"""


def test_version_and_python_dash_m():
    out = subprocess.run([sys.executable, "-m", "fem_elastic", "--version"], capture_output=True,
                         text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == f"fem-elastic {fe.__version__}"


def test_info_on_several_meshes(capsys):
    meshes = sorted(str(p) for p in (ROOT / "meshes").glob("*.vtu"))
    assert len(meshes) >= 2
    assert cli.main(["info", *meshes]) == 0
    text = capsys.readouterr().out
    for path in meshes:
        assert f"{path}\n" in text
    assert text.count("validation      ok") == len(meshes)


def test_run_prints_and_records_the_physical_result(tmp_path, capsys):
    scene = tmp_path / "probe.toml"
    scene.write_text(SCENE)
    assert cli.main(["run", str(scene), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert cli.main(["run", str(scene), "--out", str(tmp_path / "out2"), "--no-render"]) == 0
    text = capsys.readouterr().out
    assert "fem: max |u| = " in text and "min det F" in text and "energy 0 -> " in text
    assert "fem:   tip (vertex " in text and "reaction on left at the end" in text
    summary = json.loads((tmp_path / "out2" / "fem" / "summary.json").read_text())
    series = fe.read_series(tmp_path / "out2" / "fem")
    u = np.linalg.norm(series.displacement, axis=2)
    # the summary's norms are of the run's float64 displacements, the series' of those values as
    # written to and read back from the VTU frames: equal to round-off, well within 1e-12
    assert summary["max_displacement"] == pytest.approx(u.max(), rel=1e-12)
    assert summary["final_max_displacement"] == pytest.approx(u[-1].max(), rel=1e-12)
    tip = summary["probes"]["tip"]
    # (0.4, 0.05, 0.1) is not a vertex of a 4 x 1 x 1 beam: the nearest one, 0.05 m away
    assert tip["distance"] == pytest.approx(0.05, rel=1e-12)
    np.testing.assert_array_equal(tip["times"], series.times)
    # 1e-15 m: float64 round-off of the stored displacements (under 0.5 g t^2 = 1.2e-2 m at 0.05 s)
    np.testing.assert_allclose(tip["displacement"], series.displacement[:, tip["vertex"]],
                               rtol=0, atol=1e-15)
    assert tip["final"][2] < 0  # the free end sags
    near = summary["probes"]["near_tip"]
    assert near["vertex"] != tip["vertex"] and near["distance"] == pytest.approx(0.01, rel=1e-9)
    # the clamp's reaction is finite and points up against gravity's pull at the end
    assert summary["reactions"]["left"][2] > 0


def test_probe_must_be_points(tmp_path):
    bad = SCENE.replace("points = { tip = [0.4, 0.05, 0.1], near_tip = [0.39, 0.0, 0.0] }",
                        'points = { tip = "end" }')
    with pytest.raises(fe.SceneError, match="tip"):
        fe.parse_scene(bad)
