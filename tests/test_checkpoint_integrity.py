"""Checkpoints are verified: altered, torn or re-encoded files are typed errors naming the file.

Every byte position of every appended file is open-ended input, so the flips
are drawn by hypothesis; each must be caught (CRC-32 detects every single-bit
and single-byte error), never resumed from.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fem_elastic as fe
from fem_elastic.dynamics.checkpoint import CHECKPOINT_NAME, CUTS_NAME, FRAMES_NAME, STEPS_NAME
from small_scene import small_scene


def _model():
    return fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1000.0,
                    body=fe.ElasticBody(fe.LinearElastic(E=1e5, nu=0.3)), fixed="left",
                    gravity=(0.0, 0.0, -9.81))


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """A checkpoint directory of a 6-step run (a checkpoint every 2 steps) and the run itself."""
    d = tmp_path_factory.mktemp("ck")
    traj = fe.simulate(_model(), fe.ImplicitEuler(), 0.01, steps=6, checkpoint_dir=d, checkpoint_every=2)
    return d, traj


def _copy(src, dst):
    shutil.copytree(src, dst, dirs_exist_ok=True)
    return dst


def test_an_intact_checkpoint_reads_back_with_its_checksums(written):
    d, traj = written
    ck = fe.load_checkpoint(d)
    meta_crc = set(ck.crc32)
    assert meta_crc == {FRAMES_NAME, STEPS_NAME, CUTS_NAME}
    np.testing.assert_array_equal(ck.trajectory().displacement, traj.displacement)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from([FRAMES_NAME, STEPS_NAME]), where=st.floats(0.0, 1.0, exclude_max=True),
       flip=st.integers(1, 255))
def test_any_changed_byte_of_a_record_file_is_caught(written, tmp_path, name, where, flip):
    d = _copy(written[0], tmp_path / "ck")
    path = d / name
    data = bytearray(path.read_bytes())
    i = int(where * len(data))
    data[i] ^= flip
    path.write_bytes(bytes(data))
    with pytest.raises(fe.InvalidParameter, match=f"{name}.*changed or damaged.*afresh"):
        fe.load_checkpoint(d)


def test_a_torn_frames_file_is_caught(written, tmp_path):
    d = _copy(written[0], tmp_path / "ck")
    path = d / FRAMES_NAME
    path.write_bytes(path.read_bytes()[:-100])  # the last record cut short
    with pytest.raises(fe.InvalidParameter, match=f"{FRAMES_NAME} holds .* records, the checkpoint counts"):
        fe.load_checkpoint(d)


def test_a_frames_file_swapped_for_another_runs_is_caught(written, tmp_path):
    d = _copy(written[0], tmp_path / "ck")
    other = tmp_path / "other"
    fe.simulate(_model(), fe.ImplicitEuler(), 0.005, steps=6, checkpoint_dir=other, checkpoint_every=2)
    shutil.copy(other / FRAMES_NAME, d / FRAMES_NAME)  # same size, other numbers
    with pytest.raises(fe.InvalidParameter, match=FRAMES_NAME):
        fe.load_checkpoint(d)


def test_a_damaged_checkpoint_npz_is_a_typed_error(written, tmp_path):
    d = _copy(written[0], tmp_path / "ck")
    path = d / CHECKPOINT_NAME
    data = bytearray(path.read_bytes())
    data[len(data) // 3] ^= 0xFF  # inside a member's compressed or stored bytes
    path.write_bytes(bytes(data))
    with pytest.raises(fe.InvalidParameter, match=f"{CHECKPOINT_NAME} cannot be read.*afresh"):
        fe.load_checkpoint(d)
    path.write_bytes(bytes(data[: len(data) // 2]))  # torn
    with pytest.raises(fe.InvalidParameter, match=f"{CHECKPOINT_NAME} cannot be read"):
        fe.load_checkpoint(d)


def test_a_cuts_file_in_another_encoding_is_a_typed_error(tmp_path):
    # a run whose steps are cut writes cuts.jsonl; re-encoding it (UTF-16, as an editor may) is caught
    model = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.NeoHookean(E=1e5, nu=0.3)), fixed="left",
                     gravity=(0.0, 0.0, -9.81))
    d = tmp_path / "ck"
    # two Newton iterations are too few for dt = 0.05 s at first: the steps are cut and recorded
    run = fe.simulate(model, fe.ImplicitEuler(max_iter=2), 0.05, steps=2, checkpoint_dir=d,
                      checkpoint_every=1)
    assert run.cuts
    cuts = d / CUTS_NAME
    cuts.write_bytes(cuts.read_text(encoding="utf-8").encode("utf-16"))
    with pytest.raises(fe.InvalidParameter, match=CUTS_NAME):
        fe.load_checkpoint(d)


SCENE = small_scene("ck", duration=0.04, output="checkpoint_every = 2")


def _run(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE, encoding="utf-8")
    out = tmp_path / "out"
    from fem_elastic.app import cli

    assert cli.main(["run", str(scene), "--out", str(out), "--quiet", "--no-render"]) == 0
    return out


def test_a_scene_edited_between_run_and_resume_is_refused(tmp_path, capsys):
    from fem_elastic.app import cli
    from fem_elastic.app.runner import read_resumable

    out = _run(tmp_path)
    assert "scene_sha256" in json.loads((out / "run.json").read_text())
    read_resumable(out)  # intact: fine
    copy = out / "scene.toml"
    copy.write_text(copy.read_text().replace("E = 1e5", "E = 2e5"), encoding="utf-8")
    with pytest.raises(fe.InvalidParameter, match="edited after the run started.*Undo the edit"):
        read_resumable(out)
    assert cli.main(["run", "--resume", str(out), "--quiet"]) == 2
    assert "scene.toml was edited" in capsys.readouterr().err


def test_a_scene_copy_in_another_encoding_is_refused(tmp_path):
    from fem_elastic.app.runner import read_resumable

    out = _run(tmp_path)
    copy = out / "scene.toml"
    copy.write_bytes(copy.read_text(encoding="utf-8").replace('"ck"', '"\u00e9t\u00e9"').encode("latin-1"))
    with pytest.raises(fe.InvalidParameter, match="scene.toml is not UTF-8.*Save it as UTF-8"):
        read_resumable(out)
