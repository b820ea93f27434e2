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
