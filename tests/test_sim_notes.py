"""Validation notes for joints parked at a limit, and joints.png marking samples beyond range
with the joint_limits check's tolerance."""

from __future__ import annotations

import json

import numpy as np
import pytest

from motok_robot.robots.index import index_robot
from motok_robot.sim import synthetic as S
from motok_robot.sim.plots import _pyplot, plot_joints
from motok_robot.sim.testing import tiny_humanoid
from motok_robot.sim.trajectory import RobotTrajectory
from motok_robot.sim.validate import validate_trajectory


@pytest.fixture(scope="module")
def tiny():
    return index_robot(tiny_humanoid())


def _clip(index, changes):
    qpos = S.standing(index, seconds=2.0)
    for joint, frames, value in changes:
        qpos[frames, index.qpos_adr[index.joint_names.index(joint)]] = value
    return RobotTrajectory(qpos, 20.0, index.joint_names, index.name, source="clip.npz")


def test_a_joint_held_at_its_limit_gets_a_note(tiny, tmp_path):
    low = float(tiny.joint_range[tiny.joint_names.index("left_shoulder_roll")][0])
    frames = len(S.standing(tiny, seconds=2.0))
    held = slice(0, int(0.8 * frames))
    result = validate_trajectory(_clip(tiny, [("left_shoulder_roll", held, low - 0.004)]), tiny, physics=False,
                                 plots=False, out_dir=tmp_path)
    report = json.loads((tmp_path / "report.json").read_text())
    entry = report["per_joint"]["left_shoulder_roll"]
    assert entry["at_limit"] == "low" and entry["at_limit_rad"] == pytest.approx(low)
    assert entry["at_limit_ratio"] == pytest.approx(held.stop / frames)
    assert report["checks"]["joint_limits"]["passed"]  # within the check's tolerance: not a violation
    assert len(report["notes"]) == 1 and report["notes"][0].startswith("left_shoulder_roll is at its low limit")
    assert f"{held.stop / frames:.0%} of the frames" in report["notes"][0]
    assert "note: left_shoulder_roll is at its low limit" in result.summary()
    # held for less than half the clip: no note
    short = validate_trajectory(_clip(tiny, [("left_shoulder_roll", slice(0, frames // 3), low)]), tiny,
                                physics=False, plots=False)
    assert short.report["notes"] == [] and "note:" not in short.summary()


@pytest.mark.slow  # matplotlib draws an 18-panel figure: about 6 s on a busy core
def test_joints_png_marks_only_what_the_joint_limits_check_counts(tiny, tmp_path, monkeypatch):
    import matplotlib.axes

    high = float(tiny.joint_range[tiny.joint_names.index("right_elbow")][1])
    roll_low = float(tiny.joint_range[tiny.joint_names.index("left_shoulder_roll")][0])
    marked = []
    original = matplotlib.axes.Axes.scatter

    def record(self, x, y, *args, **kwargs):
        if kwargs.get("color") == "red":
            marked.append((self, len(np.atleast_1d(x))))  # titled after the scatter: named below
        return original(self, x, y, *args, **kwargs)

    monkeypatch.setattr(matplotlib.axes.Axes, "scatter", record)
    clip = _clip(tiny, [("left_shoulder_roll", slice(0, 30), roll_low - 0.005),  # inside the 0.01 rad tolerance
                        ("right_elbow", slice(10, 15), high + 0.05)])              # beyond it
    result = validate_trajectory(clip, tiny, physics=False, plots=False)
    plot_joints(result, tmp_path / "joints.png", _pyplot())
    assert result.report["checks"]["joint_limits"]["value"] == 5
    marked = [(ax.get_title().split(" ")[0], n) for ax, n in marked]
    assert ("right_elbow", 5) in marked and not any(name == "left_shoulder_roll" for name, _ in marked)
    assert (tmp_path / "joints.png").read_bytes()[:4] == b"\x89PNG"
