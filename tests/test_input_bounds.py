"""Issue 46 item 3 (and 5): sizes taken from user numbers are bounded and refused up front.

Each case reproduces an input that used to allocate without bound (gigabytes to terabytes); now
it is one error line with the number and the limit, before any large allocation.  The bounds
come from :mod:`motok_robot.limits` and can be raised with an environment variable or
``motok-robot --limit NAME=VALUE``.
"""

import io
import json
import resource
import zipfile

import numpy as np
import pytest

from motok_robot.cli import main
from motok_robot.errors import InputError
from motok_robot.limits import LIMITS, limit
from motok_robot.npz_files import read_npz_fields
from motok_robot.robots import load
from motok_robot.servo.convert import ServoMap
from motok_robot.servo.streamer import load_trajectory


@pytest.fixture(scope="module")
def robot():
    return load("op3_like")


@pytest.fixture
def memory_cap():
    """Cap the address space (2 GiB above what is mapped) so a regression fails fast instead of
    eating the machine; restored afterwards."""
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    with open("/proc/self/statm") as f:
        mapped = int(f.read().split()[0]) * resource.getpagesize()
    cap = mapped + 2 * 2**30
    resource.setrlimit(resource.RLIMIT_AS, (cap if hard == resource.RLIM_INFINITY else min(cap, hard), hard))
    yield
    resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def one_line_error(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    errors = [line for line in err if line.startswith("motok-robot: error: ")]
    assert len(errors) == 1 and not any("Traceback" in line for line in err), err
    return errors[0]


def robot_npz(path, robot, frames=3, fps=20.0, drop_column=False):
    qpos = np.repeat(robot.nominal_qpos()[None], frames, axis=0)
    if drop_column:
        qpos = qpos[:, :-1]
    np.savez(path, qpos=qpos, joint_names=np.array(robot.joint_names), robot=robot.name, fps=fps)
    return path


def test_play_refuses_a_tiny_fps_up_front(tmp_path, robot, capsys, memory_cap):
    # before: fps 1e-6 made play grow to 20.9 GB until the kernel killed it
    npz = robot_npz(tmp_path / "robot.npz", robot, fps=1e-6)
    assert main(["play", str(npz), "--dry-run", "--force"]) == 2
    err = one_line_error(capsys)
    assert "robot.npz" in err and "field 'fps'" in err and "1e-06" in err and "MOTOK_MIN_RATE" in err


def test_validate_refuses_a_tiny_fps_up_front(tmp_path, robot, capsys, memory_cap):
    # before: validate asked for 35 GiB
    npz = robot_npz(tmp_path / "robot.npz", robot, fps=1e-6)
    assert main(["validate", str(npz), "--out", str(tmp_path / "val")]) == 2
    assert "field 'fps'" in one_line_error(capsys)
    assert not (tmp_path / "val" / "report.json").exists()


def test_long_durations_are_refused_with_the_number(tmp_path, robot):
    npz = robot_npz(tmp_path / "robot.npz", robot, frames=3, fps=1.0 / 400)  # 800 s at a legal rate
    with pytest.raises(InputError, match=r"field 'fps'"):
        load_trajectory(npz, ServoMap.from_specs(robot.servos))


def test_play_refuses_a_huge_ramp(tmp_path, robot, capsys, memory_cap):
    # before: --ramp 1e9 asked for 931 GiB
    npz = robot_npz(tmp_path / "robot.npz", robot)
    assert main(["play", str(npz), "--dry-run", "--force", "--ramp", "1e9"]) == 2
    err = one_line_error(capsys)
    assert "--ramp" in err and "1,000,000,000" in err and "MOTOK_MAX_SECONDS" in err
    assert main(["play", str(npz), "--dry-run", "--force", "--ramp", "nan"]) == 2
    assert "--ramp" in one_line_error(capsys)


def test_bvh_frame_time_is_bounded(tmp_path, memory_cap):
    from motok_robot.data.bvh import read_bvh

    # before: 'Frame Time: 1000000' resampled to 20 fps asked for 5.8 GiB
    text = ("HIERARCHY\nROOT hips\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n"
            " End Site\n {\n  OFFSET 0 1 0\n }\n}\nMOTION\nFrames: 2\nFrame Time: 1000000\n0 0 0\n0 0 0\n")
    (tmp_path / "slow.bvh").write_text(text)
    with pytest.raises(InputError, match=r"slow.bvh: the frame rate of 'Frame Time: 1000000' is 1e-06 Hz"):
        read_bvh(tmp_path / "slow.bvh")
    (tmp_path / "long.bvh").write_text(text.replace("Frames: 2", "Frames: 200000").replace("1000000", "0.01"))
    with pytest.raises(InputError, match=r"'Frames:' is 200,000 frames, above the limit of 100,000"):
        read_bvh(tmp_path / "long.bvh")


def test_bvh_joint_count_is_bounded(tmp_path, monkeypatch):
    from motok_robot.data.bvh import read_bvh

    monkeypatch.setenv("MOTOK_MAX_JOINTS", "10")
    body = "".join(f"JOINT j{k}\n{{\n OFFSET 0 1 0\n CHANNELS 1 Xrotation\n" for k in range(20)) + "}\n" * 20
    text = (f"HIERARCHY\nROOT hips\n{{\n OFFSET 0 0 0\n CHANNELS 1 Xrotation\n{body}}}\n"
            "MOTION\nFrames: 1\nFrame Time: 0.01\n" + " ".join(["0"] * 21) + "\n")
    (tmp_path / "wide.bvh").write_text(text)
    with pytest.raises(InputError, match=r"wide.bvh: the HIERARCHY's joints .* is 11 joints, above the limit of 10"):
        read_bvh(tmp_path / "wide.bvh")


def test_generate_seconds_is_bounded_before_any_model_loads(tmp_path, capsys, memory_cap):
    # before: generate --seconds 1e9 --keyframes asked for 4.8 TiB
    keyframes = tmp_path / "k.json"
    keyframes.write_text(json.dumps([{"frame": 0, "joint": "pelvis", "position": [0, 0, 0.9]}]))
    assert main(["generate", "a person walks", "--seconds", "1e9", "--keyframes", str(keyframes),
                 "--out", str(tmp_path / "m.npz")]) == 2
    err = one_line_error(capsys)
    assert "--seconds" in err and "1,000,000,000" in err
    assert main(["generate", "a person walks", "--seconds", "1e9", "--out", str(tmp_path / "m.npz")]) == 2
    assert "--seconds" in one_line_error(capsys)
    assert not (tmp_path / "m.npz").exists()


def zip_bomb(path, shape=(200_000_000,)):
    """An npz whose one array inflates to 1.6 GB from a few MB: written member by member."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": shape})
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        with archive.open("qpos.npy", "w", force_zip64=True) as member:
            member.write(header.getvalue())
            block = bytes(1 << 24)
            total = int(np.prod(shape)) * 8
            while total > 0:
                member.write(block[:min(total, len(block))])
                total -= len(block)
    return path


def test_an_npz_that_inflates_beyond_the_limit_is_refused_before_reading(tmp_path, monkeypatch, memory_cap):
    # before: a 1.3 MB npz inflating to 1.3 GB used 4.4 GB; a lower limit keeps this test small
    monkeypatch.setenv("MOTOK_MAX_INFLATED_BYTES", str(2**20))
    bomb = zip_bomb(tmp_path / "bomb.npz", shape=(1_000_000,))
    assert bomb.stat().st_size < 100_000
    with pytest.raises(InputError, match=r"bomb.npz: field 'qpos' inflates to 8,000,128 bytes, above the limit"):
        read_npz_fields(bomb)


def test_a_lying_npy_header_is_refused_before_allocating(tmp_path, memory_cap):
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (10**12,)})
    with zipfile.ZipFile(tmp_path / "liar.npz", "w") as archive:
        archive.writestr("qpos.npy", header.getvalue() + bytes(64))
    with pytest.raises(InputError, match=r"liar.npz: field 'qpos' .*1000000000000 float64.* above the limit"):
        read_npz_fields(tmp_path / "liar.npz")


def test_file_size_limit(tmp_path, monkeypatch):
    monkeypatch.setenv("MOTOK_MAX_FILE_BYTES", "100")
    np.savez(tmp_path / "big.npz", qpos=np.zeros(100))
    with pytest.raises(InputError, match=r"big.npz: the .npz file size is [\d,]+ bytes, above the limit of 100"):
        read_npz_fields(tmp_path / "big.npz")


def test_limits_can_be_raised_by_env_and_option(tmp_path, robot, monkeypatch, capsys):
    assert limit("frames") == LIMITS["frames"].default
    monkeypatch.setenv("MOTOK_MAX_FRAMES", "5")
    assert limit("frames") == 5
    npz = robot_npz(tmp_path / "robot.npz", robot, frames=8)
    with pytest.raises(InputError, match=r"field 'qpos' frames is 8 frames, above the limit of 5"):
        load_trajectory(npz, ServoMap.from_specs(robot.servos))
    assert main(["--limit", "frames=10", "play", str(npz), "--dry-run", "--force", "--joint-angles", "--ramp", "0.05",
                 "--log", str(tmp_path / "p.csv")]) == 0
    capsys.readouterr()
    assert main(["--limit", "bogus=1", "play", str(npz), "--dry-run"]) == 2
    assert "--limit 'bogus=1'" in one_line_error(capsys)
    monkeypatch.setenv("MOTOK_MAX_FRAMES", "lots")
    with pytest.raises(InputError, match="MOTOK_MAX_FRAMES='lots' is not a number"):
        limit("frames")


# ---------------------------------------------------------------------------------- item 5
def test_qpos_one_column_short_is_refused_even_with_force(tmp_path, robot, capsys):
    # before: --force played every joint shifted by one column
    npz = robot_npz(tmp_path / "robot.npz", robot, drop_column=True)
    with pytest.raises(InputError, match=r"field 'qpos' has 26 columns, but the free base \(7\) and the 20 joints"):
        load_trajectory(npz, ServoMap.from_specs(robot.servos))
    log = tmp_path / "p.csv"
    assert main(["play", str(npz), "--dry-run", "--force", "--log", str(log)]) == 2
    assert "field 'qpos' has 26 columns" in one_line_error(capsys)
    assert not log.exists()
