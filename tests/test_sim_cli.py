"""`motok-robot validate` (single file, batch, overrides, errors), the video, the shipped robots."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

from motok_robot.cli import main
from motok_robot.robots import list_robots, load
from motok_robot.sim import synthetic as S
from motok_robot.sim.config import ValidationConfig
from motok_robot.robots.index import index_robot
from motok_robot.sim.testing import tiny_humanoid
from motok_robot.sim.trajectory import RobotTrajectory, save_robot_npz
from motok_robot.sim.validate import validate_trajectory

FPS = 20.0


@pytest.fixture(scope="module")
def op3():
    if "op3_like" not in list_robots():
        pytest.skip("models/mjcf/op3_like not present")
    return index_robot(load("op3_like"))


def _save(path, index, qpos):
    save_robot_npz(path, RobotTrajectory(qpos, FPS, index.joint_names, index.name))
    return path


def test_cli_single_file_pass_fail_and_override(op3, tmp_path, capsys):
    stand = _save(tmp_path / "stand.npz", op3, S.standing(op3, 1.0, FPS))
    sunk = _save(tmp_path / "sunk.npz", op3, S.sunk_feet(op3, 1.0, FPS))
    assert main(["validate", str(stand), "--out", str(tmp_path / "a"), "--no-render", "--no-plots"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("PASS stand.npz on op3_like")  # robot taken from the npz's 'robot' field
    report = json.loads((tmp_path / "a" / "report.json").read_text())
    assert report["passed"] and report["physics"] is True
    assert main(["validate", str(sunk), "--robot", "op3_like", "--out", str(tmp_path / "b"),
                 "--no-render", "--no-plots", "--no-physics"]) == 1
    out = capsys.readouterr().out
    assert "FAIL sunk.npz" in out and "FAILED penetration" in out
    assert json.loads((tmp_path / "b" / "report.json").read_text())["metrics"]["fell"] is None
    assert main(["validate", str(sunk), "--out", str(tmp_path / "c"), "--no-render", "--no-plots",
                 "--no-physics", "--set", "max_penetration_m=0.05"]) == 0
    assert json.loads((tmp_path / "c" / "report.json").read_text())["config"]["max_penetration_m"] == 0.05


def test_cli_errors_are_one_line_naming_the_field(op3, tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    np.savez(bad, qpos=np.zeros((10, 20)), fps=FPS, robot="op3_like")
    assert main(["validate", str(bad), "--out", str(tmp_path / "o"), "--no-render"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "field 'qpos' has 20 columns" in err and "nq=27" in err
    names = tmp_path / "names.npz"
    np.savez(names, qpos=S.standing(op3, 0.5, FPS), fps=FPS, joint_names=np.array(["a"] * op3.nj), robot="op3_like")
    assert main(["validate", str(names), "--out", str(tmp_path / "o"), "--no-render"]) == 2
    assert "field 'joint_names'" in capsys.readouterr().err
    assert main(["validate", str(bad), "--out", str(tmp_path / "o"), "--set", "nope=1"]) == 2
    assert "--set nope" in capsys.readouterr().err
    noname = tmp_path / "noname.npz"
    np.savez(noname, qpos=S.standing(op3, 0.5, FPS), fps=FPS)
    assert main(["validate", str(noname), "--out", str(tmp_path / "o"), "--no-render"]) == 2
    assert "pass --robot" in capsys.readouterr().err
    assert main(["validate", "--out", str(tmp_path / "o")]) == 2


def test_cli_batch_writes_summary_csv(op3, tmp_path, capsys):
    folder = tmp_path / "clips"
    folder.mkdir()
    _save(folder / "a_stand.npz", op3, S.standing(op3, 0.5, FPS))
    _save(folder / "b_sunk.npz", op3, S.sunk_feet(op3, 0.5, FPS))
    np.savez(folder / "c_bad.npz", qpos=np.zeros((10, 20)), fps=FPS, robot="op3_like")
    code = main(["validate", "--batch", str(folder), "--robot", "op3_like", "--out", str(tmp_path / "val"),
                 "--no-render", "--no-plots", "--no-physics"])
    assert code == 1
    out = capsys.readouterr().out
    assert "1/3 trajectories passed" in out and "FAIL  b_sunk.npz: penetration" in out and "ERROR c_bad.npz" in out
    with open(tmp_path / "val" / "summary.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["file"] for r in rows] == ["a_stand.npz", "b_sunk.npz", "c_bad.npz"]
    assert [r["passed"] for r in rows] == ["True", "False", "False"]
    assert rows[1]["failed_checks"] == "penetration" and float(rows[1]["max_penetration_m"]) == pytest.approx(0.02)
    assert "field 'qpos'" in rows[2]["error"]
    assert (tmp_path / "val" / "a_stand" / "report.json").exists()


def test_render_marks_failing_frames_in_red(tmp_path):
    import imageio.v2 as imageio

    tiny = index_robot(tiny_humanoid())
    qpos = S.sunk_feet(tiny, 0.5, FPS)  # every frame fails the penetration check
    config = ValidationConfig(render_width=192, render_height=144)
    trajectory = RobotTrajectory(qpos, FPS, tiny.joint_names, tiny.name, source="sunk.npz")
    try:
        result = validate_trajectory(trajectory, tiny, config=config, out_dir=tmp_path, plots=False, render=True)
    except Exception as exc:  # pragma: no cover - a machine without any EGL
        if "cannot render headless" in str(exc):
            pytest.skip(str(exc))
        raise
    video = tmp_path / "validation.mp4"
    assert result.report["outputs"]["video"] == str(video)
    frames = [f for f in imageio.get_reader(str(video))]
    assert len(frames) == int(0.5 * 30) + 1
    frame = frames[len(frames) // 2].astype(int)
    assert frame.shape == (144, 192, 3)
    border = frame[1:3, 20:170].reshape(-1, 3).mean(axis=0)
    assert border[0] > 150 and border[1] < 80 and border[2] < 80  # red border
    middle = frame[30:110, 20:80].reshape(-1, 3)
    assert middle.std(axis=0).max() > 10  # something (robot, floor) was drawn


def test_every_shipped_robot_stands_and_catches_a_sunk_foot():
    robots = list_robots()
    if not robots:
        pytest.skip("no robot models in models/mjcf")
    for name in robots:
        index = index_robot(load(name))
        stand = validate_trajectory(RobotTrajectory(S.standing(index, 1.0, FPS), FPS, index.joint_names, name),
                                    index)
        assert stand.passed, stand.summary()
        sunk = validate_trajectory(RobotTrajectory(S.sunk_feet(index, 0.5, FPS), FPS, index.joint_names, name),
                                   index, physics=False)
        assert sunk.report["failed_checks"] == ["penetration"], sunk.summary()


def test_validation_modules_do_not_import_torch():
    code = ("import sys; import motok_robot.sim.validate, motok_robot.sim.cli, motok_robot.sim.plots, "
            "motok_robot.sim.render, motok_robot.sim.synthetic; "
            "assert 'torch' not in sys.modules, 'torch imported'")
    subprocess.run([sys.executable, "-c", code], check=True)
