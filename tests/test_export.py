"""`motok-robot export`: BVH of motion.npz (read back by the project's own BVH reader), CSV of
robot.npz and its validated servo goals, a LeRobot-style dataset of the passing run folders."""

from __future__ import annotations

import hashlib
import io
import json

import numpy as np
import pytest

from motok_robot.cli import main
from motok_robot.data.bvh import load_clip, read_bvh
from motok_robot.export.bvh import JOINT_MAP, euler_zxy_degrees, write_bvh
from motok_robot.export.lerobot import find_episodes, write_dataset
from motok_robot.export.progress import Progress
from motok_robot.export.robot_csv import read_robot_csv
from motok_robot.feasibility.feedforward import GOALS_FILE, goals_digest, save_servo_goals
from motok_robot.motion import skeleton, synthetic
from motok_robot.motion.rotations import quat_from_axis_angle, quat_to_matrix, rotation_about_axis

JOINTS = ["head_pan", "l_knee", "r_knee"]


def one_line_error(capsys):
    err = capsys.readouterr().err.strip()
    assert err.startswith("motok-robot: error: ") and "\n" not in err and "Traceback" not in err, err
    return err


def motion_npz(path, joints, fps=20.0, text="a person walks"):
    np.savez(path, joints=joints.astype(np.float32), fps=fps, text=text)
    return path


def robot_npz(path, frames=12, fps=20.0, robot="op3_like", seed=0):
    rng = np.random.default_rng(seed)
    qpos = np.zeros((frames, 7 + len(JOINTS)))
    qpos[:, :3] = [0.1, -0.2, 0.28] + 0.01 * rng.standard_normal((frames, 3))
    quat = quat_from_axis_angle(np.outer(np.linspace(0, 0.5, frames), [0, 0, 1.0]))
    qpos[:, 3:7] = quat
    qpos[:, 7:] = 0.3 * np.sin(np.linspace(0, 3, frames))[:, None] * [1.0, 2.0, -1.0]
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, qpos=qpos, joint_names=np.array(JOINTS), robot=robot, fps=fps)
    return path, qpos


def validated_run(folder, passed=True, goals=True, text="a person waves", frames=12, robot="op3_like", seed=0):
    """A run folder as `run` leaves it: robot.npz, report.json, servo_goals.npz, pipeline.json."""
    path, qpos = robot_npz(folder / "robot.npz", frames=frames, robot=robot, seed=seed)
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    servo = qpos[:, 7:] + 0.02  # feedforward goals differ from the joint angles
    record = None
    if goals:
        save_servo_goals(folder / GOALS_FILE, servo, JOINTS, 20.0, robot, "feedforward", digest)
        record = {"mode": "feedforward", "file": GOALS_FILE, "sha256": goals_digest(servo)}
    report = {"passed": passed, "failed_checks": [] if passed else ["zmp"], "robot": robot,
              "input": {"path": "robot.npz", "sha256": digest}, "servo_goals": record}
    (folder / "report.json").write_text(json.dumps(report))
    (folder / "pipeline.json").write_text(json.dumps({"text": text}))
    return qpos, servo


# ----------------------------------------------------------------------------- BVH
@pytest.mark.parametrize("clip", ["walk", "random"])
def test_bvh_round_trips_through_the_project_reader(tmp_path, clip, capsys):
    joints = synthetic.walking_clip(60) if clip == "walk" else synthetic.random_poses(20, seed=3)
    source = motion_npz(tmp_path / "motion.npz", joints)
    out = tmp_path / "motion.bvh"
    assert main(["export", str(source), "--bvh", str(out)]) == 0
    assert "centimetres, y up" in capsys.readouterr().out
    motion = read_bvh(out)
    named = [j for j in motion.skeleton.joints if not j.is_end_site]
    assert sorted(j.name for j in named) == sorted(skeleton.JOINT_NAMES)  # the canonical names, depth first
    for joint in named[1:]:  # the canonical tree
        parent = motion.skeleton.joints[joint.parent].name
        assert skeleton.PARENTS[skeleton.JOINT_INDEX[joint.name]] == skeleton.JOINT_INDEX[parent]
    assert motion.skeleton.joints[0].channels[:3] == ["Xposition", "Yposition", "Zposition"]
    assert motion.channels.shape == (len(joints), 6 + 21 * 3) and motion.fps == pytest.approx(20.0)
    back = load_clip(out, skeleton=JOINT_MAP).joints
    assert back.shape == joints.shape
    assert np.abs(back - joints).max() < 1e-5  # metres: the bones of a synthetic clip are exactly canonical
    # centimetres, y up: the pelvis height of frame 0 is the file's Yposition
    assert motion.channels[0, 1] == pytest.approx(joints[0, 0, 2] * 100, abs=1e-4)


def test_bvh_of_a_motion_whose_bones_stretch(tmp_path, capsys):
    joints = synthetic.walking_clip(40).astype(np.float64)
    knee, ankle = skeleton.JOINT_INDEX["left_knee"], skeleton.JOINT_INDEX["left_ankle"]
    stretch = 1.0 + 0.1 * np.sin(np.linspace(0, 6, len(joints)))[:, None]  # the shin grows and shrinks 10 %
    moved = knee_to_ankle = (joints[:, ankle] - joints[:, knee]) * (stretch - 1.0)
    for j in (ankle, skeleton.JOINT_INDEX["left_foot"]):  # the foot follows the ankle
        joints[:, j] += moved
    source = motion_npz(tmp_path / "motion.npz", joints)
    result = write_bvh(joints, 20.0, tmp_path / "fixed.bvh")
    back = load_clip(tmp_path / "fixed.bvh", skeleton=JOINT_MAP).joints
    error = float(np.linalg.norm(back - joints, axis=-1).max())
    assert 0.01 < error == pytest.approx(result.max_position_error_m, abs=1e-5)  # it says what it changed
    assert result.max_bone_length_change_m == pytest.approx(np.linalg.norm(knee_to_ankle, axis=-1).max(), rel=0.3)
    assert main(["export", str(source), "--bvh", str(tmp_path / "exact.bvh"), "--bone-positions"]) == 0
    assert "position channels on every joint" in capsys.readouterr().out
    exact = load_clip(tmp_path / "exact.bvh", skeleton=JOINT_MAP).joints
    assert np.abs(exact - joints).max() < 1e-5


def test_euler_zxy_recomposes_the_rotation():
    rng = np.random.default_rng(1)
    m = quat_to_matrix(quat_from_axis_angle(rng.normal(size=(200, 3))))
    lock = rotation_about_axis(np.array([0.3]), 2) @ rotation_about_axis(np.array([np.pi / 2]), 0)
    m = np.concatenate([m, lock])
    z, x, y = np.radians(euler_zxy_degrees(m)).T
    again = rotation_about_axis(z, 2) @ rotation_about_axis(x, 0) @ rotation_about_axis(y, 1)
    assert np.abs(again - m).max() < 1e-9


# ----------------------------------------------------------------------------- CSV
def test_csv_has_units_in_the_header_and_the_trajectory_in_the_rows(tmp_path, capsys):
    path, qpos = robot_npz(tmp_path / "robot.npz")
    out = tmp_path / "robot.csv"
    assert main(["export", str(path), "--csv", str(out)]) == 0
    header = out.read_text().splitlines()[0].split(",")
    assert header == ["time_s", "root_x_m", "root_y_m", "root_z_m", "root_qw", "root_qx", "root_qy", "root_qz",
                      "head_pan_rad", "l_knee_rad", "r_knee_rad"]
    table = read_robot_csv(out)
    assert np.allclose(table["time_s"], np.arange(len(qpos)) / 20.0)
    got = np.stack([table[name] for name in header[1:]], axis=1)
    assert np.abs(got - qpos).max() < 1e-8
    capsys.readouterr()
    assert main(["export", str(path), "--csv", str(out)]) == 2
    assert "exists" in one_line_error(capsys) and out.is_file()


def test_csv_goals_are_the_validated_ones(tmp_path, capsys, monkeypatch):
    qpos, servo = validated_run(tmp_path / "val")
    out = tmp_path / "goals.csv"
    assert main(["export", str(tmp_path / "val" / "robot.npz"), "--csv", str(out), "--goals"]) == 0
    table = read_robot_csv(out)
    assert np.abs(np.stack([table[f"{j}_goal_rad"] for j in JOINTS], axis=1) - servo).max() < 1e-8
    assert np.abs(table["root_z_m"] - qpos[:, 2]).max() < 1e-8
    capsys.readouterr()
    # goals computed from other content are refused, naming the field
    other, _ = robot_npz(tmp_path / "other" / "robot.npz", seed=5)
    assert main(["export", str(other), "--csv", str(tmp_path / "x.csv"),
                 "--goals", str(tmp_path / "val" / GOALS_FILE)]) == 2
    assert "field 'source_sha256'" in one_line_error(capsys)
    monkeypatch.chdir(tmp_path / "other")
    assert main(["export", str(other), "--csv", str(tmp_path / "y.csv"), "--goals"]) == 2
    assert "--goals: no validation report" in one_line_error(capsys)
    assert not (tmp_path / "x.csv").exists() and not (tmp_path / "y.csv").exists()


@pytest.mark.parametrize("argv, expected", [
    (["--csv", "{OUT}.csv", "--bone-positions"], "--bone-positions: not an option of export --csv"),
    (["--bvh", "{OUT}.bvh"], "robot.npz: no 'joints' array"),
    (["--lerobot", "{OUT}"], "not a folder"),
])
def test_bad_export_input_is_one_line(tmp_path, capsys, argv, expected):
    path, _ = robot_npz(tmp_path / "robot.npz")
    argv = [a.replace("{OUT}", str(tmp_path / "out")) for a in argv]
    assert main(["export", str(path), *argv]) == 2
    assert expected in one_line_error(capsys)


def test_csv_names_the_joint_of_a_non_finite_angle(tmp_path, capsys):
    path, qpos = robot_npz(tmp_path / "robot.npz")
    qpos[4, 8] = np.nan
    np.savez(path, qpos=qpos, joint_names=np.array(JOINTS), robot="op3_like", fps=20.0)
    assert main(["export", str(path), "--csv", str(tmp_path / "r.csv")]) == 2
    assert "field 'qpos' is not finite at frame 4 (joint l_knee)" in one_line_error(capsys)


# ----------------------------------------------------------------------------- LeRobot
def _runs(tmp_path):
    runs = tmp_path / "batch"
    good = {"000_wave": validated_run(runs / "000_wave", text="a person waves", frames=12, seed=1),
            "003_bow": validated_run(runs / "cells" / "003_bow", text="a person bows", frames=9, seed=2)}
    validated_run(runs / "001_fall", passed=False, text="a person runs")
    validated_run(runs / "002_nophys", goals=False, text="a person sits")
    validated_run(runs / "004_changed", text="a person jumps", seed=4)
    robot_npz(runs / "004_changed" / "robot.npz", seed=9)  # changed after validation
    validated_run(runs / ".005_a.partial-1", text="unfinished")  # a run still being written
    return runs, good


def test_lerobot_dataset_of_the_passing_runs(tmp_path, capsys):
    pq = pytest.importorskip("pyarrow.parquet")
    runs, good = _runs(tmp_path)
    out = tmp_path / "dataset"
    assert main(["export", str(runs), "--lerobot", str(out)]) == 0
    text = capsys.readouterr().out
    assert "2 episodes, 21 frames" in text and "skipped 3 run folder(s)" in text
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["codebase_version"] == "v2.1" and info["robot_type"] == "op3_like" and info["fps"] == 20.0
    assert (info["total_episodes"], info["total_frames"], info["total_tasks"]) == (2, 21, 2)
    assert info["features"]["observation.state"]["names"] == JOINTS
    assert info["features"]["action"]["shape"] == [3]
    episodes = [json.loads(line) for line in (out / "meta" / "episodes.jsonl").read_text().splitlines()]
    assert episodes == [{"episode_index": 0, "tasks": ["a person waves"], "length": 12},
                        {"episode_index": 1, "tasks": ["a person bows"], "length": 9}]
    skipped = {s["folder"].rsplit("/", 1)[-1]: s["reason"]
               for s in json.loads((out / "meta" / "motok_export.json").read_text())["skipped"]}
    assert skipped["001_fall"] == "validation failed (zmp)"
    assert "records no servo goals" in skipped["002_nophys"] and "did not validate" in skipped["004_changed"]
    index = 0
    for e, name in enumerate(("000_wave", "003_bow")):
        qpos, servo = good[name]
        table = pq.read_table(out / info["data_path"].format(episode_chunk=0, episode_index=e)).to_pydict()
        assert np.allclose(np.array(table["observation.state"]), qpos[:, 7:], atol=1e-6)
        assert np.allclose(np.array(table["action"]), servo, atol=1e-6)
        assert np.allclose(np.array(table["observation.base_pose"]), qpos[:, :7], atol=1e-6)
        assert table["frame_index"] == list(range(len(qpos))) and set(table["episode_index"]) == {e}
        assert table["index"] == list(range(index, index + len(qpos)))
        assert np.allclose(table["timestamp"], np.arange(len(qpos)) / 20.0)
        index += len(qpos)
    stats = json.loads((out / "meta" / "episodes_stats.jsonl").read_text().splitlines()[0])["stats"]
    assert stats["action"]["max"] == pytest.approx(good["000_wave"][1].max(axis=0).tolist(), abs=1e-6)


def test_lerobot_without_pyarrow_writes_npz(tmp_path, capsys, monkeypatch):
    import motok_robot.export.lerobot as lerobot

    runs, good = _runs(tmp_path)
    out = tmp_path / "dataset"
    monkeypatch.setattr(lerobot, "parquet_available", lambda: False)
    assert main(["export", str(runs), "--lerobot", str(out)]) == 0
    assert "(npz: pyarrow is not installed)" in capsys.readouterr().out
    assert "pyarrow is not installed" in json.loads((out / "meta" / "motok_export.json").read_text())["note"]
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["data_path"].endswith(".npz")
    with np.load(out / "data" / "chunk-000" / "episode_000001.npz") as episode:
        assert np.allclose(episode["action"], good["003_bow"][1], atol=1e-6)
        assert episode["observation.state"].dtype == np.float32
    assert main(["export", str(runs), "--lerobot", str(out), "--npz"]) == 2
    assert "not empty" in one_line_error(capsys)
    assert main(["export", str(runs), "--lerobot", str(out), "--npz", "--overwrite"]) == 0


def test_lerobot_refuses_mixed_robots_and_empty_trees(tmp_path, capsys):
    validated_run(tmp_path / "a", robot="op3_like")
    validated_run(tmp_path / "b", robot="op3")
    scan = find_episodes(tmp_path)
    assert len(scan.episodes) == 2
    with pytest.raises(Exception, match="different robots"):
        write_dataset(scan.episodes, tmp_path / "ds", source=str(tmp_path))
    assert main(["export", str(tmp_path), "--lerobot", str(tmp_path / "ds1"), "--robot", "op3"]) == 0
    assert "1 episode," in capsys.readouterr().out  # the progress lines went to stderr
    (tmp_path / "empty").mkdir()
    assert main(["export", str(tmp_path / "empty"), "--lerobot", str(tmp_path / "ds2")]) == 2
    assert "no passing trajectory" in one_line_error(capsys)
    # a failed re-export leaves the previous dataset alone
    capsys.readouterr()
    assert main(["export", str(tmp_path), "--lerobot", str(tmp_path / "ds1"), "--overwrite"]) == 2
    assert "different robots" in capsys.readouterr().err
    assert (tmp_path / "ds1" / "meta" / "info.json").is_file()


def test_progress_prints_lines_off_a_terminal():
    stream = io.StringIO()
    times = iter([0.0, 1.0, 6.0, 7.0])
    progress = Progress("write", "episodes", stream=stream, interval_s=5.0, clock=lambda: next(times))
    for done in range(1, 5):
        progress(done, 4)
    assert stream.getvalue().splitlines() == ["write: 1/4 episodes", "write: 3/4 episodes", "write: 4/4 episodes"]
