"""`motok-robot run --motion FILE`: the robot half of the pipeline without generation models."""

from __future__ import annotations

import json

import numpy as np
import pytest

from motok_robot.cli import main
from motok_robot.motion.features import features_from_joints, joints_from_features
from motok_robot.motion.synthetic import standing_clip


@pytest.fixture(scope="module")
def stand_npz(tmp_path_factory):
    features = features_from_joints(standing_clip(frames=41))
    path = tmp_path_factory.mktemp("motion") / "stand.npz"
    np.savez(path, joints=joints_from_features(features).astype(np.float32), features=features, fps=20, text="stand")
    return path


def test_run_from_a_motion_file_writes_every_stage(stand_npz, tmp_path, capsys):
    out = tmp_path / "out"
    rc = main(["run", "--motion", str(stand_npz), "--out", str(out), "--no-render", "--no-plots"])
    printed = capsys.readouterr().out
    assert "stand" in printed
    for name in ("motion.npz", "robot.npz", "report.json", "summary.md", "playback.csv"):
        assert (out / name).is_file(), name
    report = json.loads((out / "report.json").read_text())
    assert rc == (0 if report["passed"] else 1)
    with np.load(out / "motion.npz") as m:
        assert m["joints"].shape == (40, 22, 3) and m["tokens"].shape == (0,)


def test_run_motion_errors_are_one_line(stand_npz, tmp_path, capsys):
    assert main(["run", "--motion", str(tmp_path / "missing.npz"), "--out", str(tmp_path / "o")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["run", "--motion", str(stand_npz), "--trajectory", "examples/trajectory.csv", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot be combined with --motion" in err[0]
    assert not (tmp_path / "o").exists()


def test_playback_none_skips_the_stage_and_a_motion_file_has_no_vocabulary_check(stand_npz, tmp_path):
    from motok_robot.pipeline import Pipeline

    result = Pipeline().run(None, motion=stand_npz, robot="op3_like", out_dir=tmp_path / "out", playback="none",
                            render=False, plots=False)
    assert result.playback.status == "skipped" and "playback_log" not in result.files
    assert not (tmp_path / "out" / "playback.csv").exists()
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["vocabulary"] is None  # motion files are not prompts


def test_a_far_prompt_becomes_a_note_of_run_and_its_report(stand_npz, tmp_path, monkeypatch):
    from motok_robot.pipeline import Pipeline, stages
    from motok_robot.text.vocabulary import VocabularyCheck

    check = VocabularyCheck(text="a person swims", similarity=0.41, threshold=0.72,
                            nearest=[("A person walks.", 0.41)], encoder="test", vocabulary="0" * 16)
    real = stages.generate

    def generate_far(*args, **kwargs):
        motion = real(*args, **kwargs)
        motion.vocabulary = check
        return motion

    monkeypatch.setattr(stages, "generate", generate_far)
    result = Pipeline().run(None, motion=stand_npz, robot="op3_like", out_dir=tmp_path / "out", playback="none",
                            render=False, plots=False)
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["vocabulary"]["far"] is True
    assert any(n.startswith("vocabulary:") and "A person walks." in n for n in report["notes"])
    assert any(n.startswith("vocabulary:") for n in result.notes)
    assert "vocabulary:" in (tmp_path / "out" / "summary.md").read_text()
