"""``motok-robot robots list|show [--render]``."""

from __future__ import annotations

import numpy as np
import pytest

from motok_robot.cli import main


def test_robots_list(capsys):
    assert main(["robots", "list"]) == 0
    out = capsys.readouterr().out
    assert "op3_like" in out and "humanoid25" in out
    row = next(line for line in out.splitlines() if line.startswith("op3_like"))
    assert row.split()[1:3] == ["20", "3.39"]


def test_robots_show_prints_joints_limits_and_servo_map(capsys):
    assert main(["robots", "show", "op3_like"]) == 0
    out = capsys.readouterr().out
    assert "XM430-W350" in out and "2000000 baud" in out and "125 Hz" in out
    row = next(line for line in out.splitlines() if line.split()[:1] == ["l_knee"])
    fields = row.split()
    # joint, min rad, max rad, min deg, max deg, vel, torque, nominal, id, model, sign, zero, min tk, max tk
    assert fields[1:3] == ["0.000", "2.400"] and fields[5:7] == ["4.80", "4.10"]
    assert fields[8:] == ["14", "XM430-W350", "+1", "2048", "2048", "3613"]


def test_robots_show_second_robot_has_no_servo_columns(capsys):
    assert main(["robots", "show", "humanoid25"]) == 0
    out = capsys.readouterr().out
    assert "waist_pitch" in out and "bus:" not in out and "XM430" not in out


def test_unknown_robot_is_one_line_error(capsys):
    assert main(["robots", "show", "asimo"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("motok-robot: error: unknown robot 'asimo'; known robots:") and err.count("\n") == 1


def test_render_nominal_pose(tmp_path, capsys):
    import imageio.v3 as iio

    out = tmp_path / "pics" / "op3.png"
    try:
        code = main(["robots", "show", "op3_like", "--render", str(out), "--size", "160x200"])
    except Exception as exc:  # pragma: no cover - machines without any GL backend
        pytest.skip(f"no headless GL: {exc}")
    if code != 0:
        err = capsys.readouterr().err
        if "cannot render headless" in err:
            pytest.skip(err.strip())
    assert code == 0
    image = iio.imread(out)
    assert image.shape == (200, 160, 3) and image.dtype == np.uint8
    # the robot is in the middle of the picture: the centre differs from the sky at the top
    centre = image[60:140, 50:110].reshape(-1, 3).astype(int)
    sky = image[:10].reshape(-1, 3).astype(int).mean(axis=0)
    assert np.abs(centre - sky).sum(axis=1).max() > 100


def test_render_rejects_bad_size(tmp_path, capsys):
    assert main(["robots", "show", "op3_like", "--render", str(tmp_path / "x.png"), "--size", "big"]) == 2
    assert "--size must be WIDTHxHEIGHT" in capsys.readouterr().err
