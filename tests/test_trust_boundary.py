"""Issue 46 items 1 and 2: limits come only from the installed robot models and the MJCF.

* ``play`` never takes a description path from a data file (the ``robot`` field may only name an
  installed robot); a report binds the description digest (TOML + MJCF bytes) and play checks it.
* Servo tick ranges must lie inside the joint range (1 tick tolerance); velocity and torque limits
  inside the servo model's datasheet range.
"""

import hashlib
import json
import re
import shutil

import numpy as np
import pytest

from motok_robot.cli import main
from motok_robot.errors import InputError
from motok_robot.robots import ServoSpec, load, models_dir
from motok_robot.robots.robot import description_digest, installed_robot_name
from motok_robot.servo.convert import ServoMap
from motok_robot.servo.playback_log import read_log
from motok_robot.servo.streamer import check_validation_report


@pytest.fixture(scope="module")
def robot():
    return load("op3_like")


def copy_robot(folder, toml_edit=None, xml_edit=None):
    """op3_like.toml + op3_like.xml copied into ``folder``, edited by the two (old, new) lists."""
    folder.mkdir(parents=True, exist_ok=True)
    toml = folder / "op3_like.toml"
    xml = folder / "op3_like.xml"
    shutil.copy(models_dir() / "op3_like.xml", xml)
    text = (models_dir() / "op3_like.toml").read_text()
    for old, new in toml_edit or []:
        assert old in text, old
        text = text.replace(old, new)
    toml.write_text(text)
    if xml_edit:
        body = xml.read_text()
        for old, new in xml_edit:
            assert old in body, old
            body = body.replace(old, new)
        xml.write_text(body)
    return toml


WIDE_KNEE = [("l_knee = { id = 14, sign = 1, zero_offset_ticks = 2048, min_ticks = 2048, max_ticks = 3613 }",
              "l_knee = { id = 14, sign = 1, zero_offset_ticks = 2048, min_ticks = 2048, max_ticks = 4004 }")]


def knee_clip(folder, robot, robot_field, amplitude=2.5):
    """A 1 s clip bending l_knee far beyond its joint range (so only the limits keep it in)."""
    nominal = robot.nominal_qpos()
    t = np.arange(21) / 20
    qpos = np.repeat(nominal[None], len(t), axis=0)
    qpos[:, robot.qpos_adr[robot.joint_names.index("l_knee")]] = amplitude * np.minimum(t * 4, 1.0)
    path = folder / "robot.npz"
    np.savez(path, qpos=qpos, joint_names=np.array(robot.joint_names), robot=robot_field, fps=20.0)
    return path


def hand_written_report(folder, npz, robot_name="op3_like", description_sha256=None):
    report = {"passed": True, "robot": robot_name,
              "input": {"path": str(npz), "sha256": hashlib.sha256(npz.read_bytes()).hexdigest()}}
    if description_sha256 is not None:
        report["robot_description"] = {"name": robot_name, "sha256": description_sha256}
    (folder / "report.json").write_text(json.dumps(report))
    return folder / "report.json"


def one_line_error(capsys):
    err = capsys.readouterr().err.strip()
    assert err.startswith("motok-robot: error: ") and "\n" not in err and "Traceback" not in err, err
    return err


# ---------------------------------------------------------------------------------- item 1
def test_play_refuses_a_description_path_in_the_robot_field(tmp_path, robot, capsys):
    """The reproduced attack: a widened op3_like.toml named by the file plus a hand-written
    passing report; before the fix ``play --dry-run`` commanded l_knee to 4004 ticks."""
    toml = copy_robot(tmp_path / "evil", WIDE_KNEE)
    npz = knee_clip(tmp_path, robot, str(toml))
    hand_written_report(tmp_path, npz, description_sha256=description_digest(toml, toml.with_suffix(".xml")))
    log = tmp_path / "play.csv"
    rc = main(["play", str(npz), "--dry-run", "--ramp", "0.1", "--log", str(log)])
    assert rc == 2
    err = one_line_error(capsys)
    assert "field 'robot'" in err and "is a path" in err and str(npz) in err
    assert not log.exists()


def test_robot_field_may_only_name_an_installed_robot(tmp_path):
    assert installed_robot_name("op3_like", "x.npz") == "op3_like"
    for value in ("../evil/op3_like.toml", "op3_like.toml", "no_such_robot", "/abs/op3_like"):
        with pytest.raises(InputError, match=r"x\.npz: field 'robot'"):
            installed_robot_name(value, "x.npz")


def test_report_must_bind_the_description_digest(tmp_path, robot, capsys):
    npz = knee_clip(tmp_path, robot, "op3_like", amplitude=0.3)
    hand_written_report(tmp_path, npz)  # no robot_description: an old or hand-written report
    assert main(["play", str(npz), "--dry-run", "--ramp", "0.1"]) == 2
    assert "records no robot description digest" in one_line_error(capsys)
    hand_written_report(tmp_path, npz, description_sha256="0" * 64)
    assert main(["play", str(npz), "--dry-run", "--ramp", "0.1"]) == 2
    assert "another robot description" in one_line_error(capsys)
    hand_written_report(tmp_path, npz, description_sha256=robot.description_sha256)
    assert main(["play", str(npz), "--dry-run", "--ramp", "0.1", "--joint-angles"]) == 0  # it records no goals
    capsys.readouterr()
    # an explicit description path on the command line is the user's choice, and is checked
    # against the report too: a calibrated copy is a different description
    toml = copy_robot(tmp_path / "copy", [("zero_offset_ticks = 2048, min_ticks = 1024, max_ticks = 3072",
                                           "zero_offset_ticks = 2049, min_ticks = 1025, max_ticks = 3073")])
    assert main(["play", str(npz), "--robot", str(toml), "--dry-run", "--ramp", "0.1"]) == 2
    assert "another robot description" in one_line_error(capsys)


def test_gate_function_checks_the_digest(tmp_path, robot):
    npz = knee_clip(tmp_path, robot, "op3_like", amplitude=0.3)
    hand_written_report(tmp_path, npz, description_sha256="ab" * 32)
    assert check_validation_report(npz, robot_name="op3_like")["passed"] is True  # no digest asked
    with pytest.raises(InputError, match="another robot description"):
        check_validation_report(npz, robot_name="op3_like", robot_sha256=robot.description_sha256)


def test_validation_report_records_the_description_digest(tmp_path, robot):
    from motok_robot.sim.validate import validate_file

    npz = knee_clip(tmp_path, robot, "op3_like", amplitude=0.0)
    result = validate_file(npz, robot, out_dir=tmp_path / "val", physics=False, plots=False)
    on_disk = json.loads((tmp_path / "val" / "report.json").read_text())
    assert result.report["robot_description"]["sha256"] == robot.description_sha256
    assert on_disk["robot_description"] == {"name": "op3_like", "sha256": robot.description_sha256}
    assert re.fullmatch(r"[0-9a-f]{64}", robot.description_sha256)
    # the digest covers both files
    toml = copy_robot(tmp_path / "c", xml_edit=[("<mujoco", "<!-- x -->\n<mujoco")])
    assert description_digest(toml, toml.with_suffix(".xml")) != robot.description_sha256


def test_forced_play_of_the_widened_setup_stays_in_the_installed_limits(tmp_path, robot, capsys):
    """With ``--force`` the file still cannot choose limits: the installed robot's apply."""
    npz = knee_clip(tmp_path, robot, "op3_like")
    log = tmp_path / "play.csv"
    assert main(["play", str(npz), "--dry-run", "--force", "--joint-angles", "--ramp", "0.1", "--log", str(log)]) == 0
    assert read_log(log)["cmd_l_knee_ticks"].max() <= 3613


# ---------------------------------------------------------------------------------- item 2
def test_servo_ticks_wider_than_the_joint_range_are_refused(tmp_path):
    with pytest.raises(InputError, match=r"op3_like.toml: \[servos.l_knee\] .*wider than the joint range"):
        load(copy_robot(tmp_path, WIDE_KNEE))


@pytest.mark.parametrize("value", ["1e-9", "1e6", "1e30", "inf", "-1.0", "0.0", "nan", "5.5"])
def test_velocity_limit_outside_the_datasheet_is_refused(tmp_path, value):
    toml = copy_robot(tmp_path, [("velocity_limit = 4.8   # rad/s", f"velocity_limit = {value}   # rad/s")])
    with pytest.raises(InputError, match=r"op3_like.toml: \[servos\.\w+\] velocity_limit"):
        load(toml)


def test_velocity_limit_of_one_servo_is_checked(tmp_path):
    toml = copy_robot(tmp_path, [("min_ticks = 2048, max_ticks = 3613 }",
                                  "min_ticks = 2048, max_ticks = 3613, velocity_limit = 1e6 }")])
    with pytest.raises(InputError, match=r"\[servos.l_knee\] velocity_limit 1e\+06 rad/s outside the XM430-W350"):
        load(toml)


def test_unknown_servo_model_is_refused(tmp_path):
    toml = copy_robot(tmp_path, [('model = "XM430-W350"', 'model = "XM999-FAST"')])
    with pytest.raises(InputError, match="no datasheet entry"):
        load(toml)


def test_torque_limit_above_the_stall_torque_is_refused(tmp_path):
    toml = copy_robot(tmp_path, xml_edit=[('forcerange="-4.1 4.1"', 'forcerange="-41 41"')])
    with pytest.raises(InputError, match="above the XM430-W350 stall torque 4.1 N m"):
        load(toml)


def test_generic_velocity_limits_are_bounded(tmp_path):
    folder = tmp_path / "h"
    folder.mkdir()
    shutil.copy(models_dir() / "humanoid25.xml", folder / "humanoid25.xml")
    text = (models_dir() / "humanoid25.toml").read_text().replace("default = 8.0", "default = 1e30", 1)
    (folder / "humanoid25.toml").write_text(text)
    with pytest.raises(InputError, match=r"\[velocity_limits.default\] 1e\+30 rad/s is above"):
        load(folder / "humanoid25.toml")


@pytest.mark.parametrize("velocity", [1e-9, 1e6, float("inf")])
def test_servo_map_refuses_velocity_limits_outside_the_datasheet(velocity):
    spec = ServoSpec("knee", 1, "XM430-W350", 1, 2048, 1000, 3000, 4096, velocity)
    with pytest.raises(InputError, match="servo 1 \\(knee\\)"):
        ServoMap.from_specs([spec])


def test_installed_robots_pass_the_checks():
    load("op3_like")
    load("humanoid25")
