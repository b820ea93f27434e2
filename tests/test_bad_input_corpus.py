"""Issue 46: a corpus of malformed, hostile and huge inputs, generated here (small files), run
through the readers and the CLI commands.

Every case must: exit non-zero, print exactly one error line that names the file (or option)
and the field, print no traceback, and write nothing that looks like a finished output.
Items 7 (tracebacks) and 10 (misleading messages) of the issue are cases here.
"""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest

from motok_robot.cli import main
from motok_robot.robots import load

ROBOT = load("op3_like")


def robot_npz(path, **override):
    qpos = np.repeat(ROBOT.nominal_qpos()[None], 4, axis=0)
    fields = dict(qpos=qpos, joint_names=np.array(ROBOT.joint_names), robot="op3_like", fps=20.0)
    fields.update(override)
    np.savez(path, **fields)
    return path


def motion_npz(path, **override):
    from motok_robot.motion.synthetic import standing_clip

    fields = dict(joints=standing_clip(frames=10).astype(np.float32), fps=20.0)
    fields.update(override)
    np.savez(path, **fields)
    return path


def corrupt_header_npz(path):
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("qpos.npy", b"\x93NUMPY\x01\x00\x10\x00{'descr': garbage}\n" + bytes(32))
    return path


def object_npz(path):
    buffer = io.BytesIO()
    np.save(buffer, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("qpos.npy", buffer.getvalue())
        archive.writestr("fps.npy", _npy(np.array(20.0)))
    return path


def _npy(array):
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def bomb_npz(path):
    """A small npz whose qpos inflates to 8 MB (the test lowers the inflated limit to 1 MiB)."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("qpos.npy", _npy(np.zeros((1_000_000,))))
    return path


def bvh(path, frames="2", frame_time="0.01"):
    path.write_text("HIERARCHY\nROOT hips\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n"
                    f" End Site\n {{\n  OFFSET 0 1 0\n }}\n}}\nMOTION\nFrames: {frames}\nFrame Time: {frame_time}\n"
                    "0 0 0\n0 0 0\n")
    return path


def text(path, content: bytes | str):
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    return path


# (id, make input in tmp (returns the path), argv with {IN} and {OUT}, words the error must contain)
CASES = [
    ("play-empty-file", lambda d: text(d / "robot.npz", b""), ["play", "{IN}", "--dry-run", "--force"],
     ["robot.npz", "is empty"]),
    ("play-text-named-npz", lambda d: text(d / "robot.npz", "qpos,fps\n1,2\n"), ["play", "{IN}", "--dry-run", "--force"],
     ["robot.npz", "not a zip archive"]),
    ("play-corrupt-npy-header", lambda d: corrupt_header_npz(d / "robot.npz"), ["play", "{IN}", "--dry-run", "--force"],
     ["robot.npz", "field 'qpos'", "corrupt header"]),
    ("play-pickled-array", lambda d: object_npz(d / "robot.npz"), ["play", "{IN}", "--dry-run", "--force"],
     ["robot.npz", "field 'qpos'", "Python objects"]),
    ("play-array-fps", lambda d: robot_npz(d / "robot.npz", fps=np.array([20.0, 30.0])),
     ["play", "{IN}", "--dry-run", "--force"], ["robot.npz", "field 'fps'"]),
    ("play-tiny-fps", lambda d: robot_npz(d / "robot.npz", fps=1e-6), ["play", "{IN}", "--dry-run", "--force"],
     ["robot.npz", "field 'fps'", "1e-06"]),
    ("play-string-qpos", lambda d: robot_npz(d / "robot.npz", qpos=np.array([["a"] * 27] * 3)),
     ["play", "{IN}", "--dry-run", "--force"], ["robot.npz", "field 'qpos'"]),
    ("play-short-qpos", lambda d: robot_npz(d / "robot.npz", qpos=np.zeros((4, 26))),
     ["play", "{IN}", "--dry-run", "--force"], ["robot.npz", "field 'qpos'", "26 columns"]),
    ("play-robot-path", lambda d: robot_npz(d / "robot.npz", robot="/tmp/evil/op3_like.toml"),
     ["play", "{IN}", "--dry-run", "--force"], ["robot.npz", "field 'robot'", "is a path"]),
    ("play-bad-baud", lambda d: robot_npz(d / "robot.npz"), ["play", "{IN}", "--dry-run", "--force", "--baud", "12345"],
     ["--baud", "12345"]),
    ("play-huge-ramp", lambda d: robot_npz(d / "robot.npz"), ["play", "{IN}", "--dry-run", "--force", "--ramp", "1e9"],
     ["--ramp", "above the limit"]),
    ("play-npz-bomb", lambda d: bomb_npz(d / "robot.npz"), ["play", "{IN}", "--dry-run", "--force"],
     ["robot.npz", "field 'qpos'", "inflates"]),
    ("validate-empty-file", lambda d: text(d / "robot.npz", b""), ["validate", "{IN}", "--out", "{OUT}"],
     ["robot.npz", "is empty"]),
    ("validate-array-fps", lambda d: robot_npz(d / "robot.npz", fps=np.zeros((2, 2))), ["validate", "{IN}", "--out", "{OUT}"],
     ["robot.npz", "field 'fps'"]),
    ("validate-robot-path", lambda d: robot_npz(d / "robot.npz", robot="../x/op3_like.toml"),
     ["validate", "{IN}", "--out", "{OUT}"], ["robot.npz", "field 'robot'"]),
    ("retarget-0d-joints", lambda d: motion_npz(d / "motion.npz", joints=np.array(1.0)),
     ["retarget", "{IN}", "--robot", "op3_like", "--out", "{OUT}"], ["motion.npz", "field 'joints'"]),
    ("retarget-nan-joints", lambda d: motion_npz(d / "motion.npz", joints=np.full((10, 22, 3), np.nan, np.float32)),
     ["retarget", "{IN}", "--robot", "op3_like", "--out", "{OUT}"], ["motion.npz", "field 'joints'", "frame 0"]),
    ("retarget-complex-joints", lambda d: motion_npz(d / "motion.npz", joints=np.zeros((10, 22, 3), np.complex128)),
     ["retarget", "{IN}", "--robot", "op3_like", "--out", "{OUT}"], ["motion.npz", "field 'joints'", "complex128"]),
    ("validate-complex-qpos", lambda d: robot_npz(d / "robot.npz",
                                                  qpos=np.repeat(ROBOT.nominal_qpos()[None], 4, axis=0).astype(complex)),
     ["validate", "{IN}", "--out", "{OUT}"], ["robot.npz", "field 'qpos'", "complex"]),
    ("feasible-complex-qpos", lambda d: robot_npz(d / "robot.npz",
                                                  qpos=np.repeat(ROBOT.nominal_qpos()[None], 4, axis=0).astype(complex)),
     ["feasible", "{IN}", "--out", "{OUT}"], ["robot.npz", "complex"]),
    ("retarget-array-fps", lambda d: motion_npz(d / "motion.npz", fps=np.array([20.0, 20.0])),
     ["retarget", "{IN}", "--robot", "op3_like", "--out", "{OUT}"], ["motion.npz", "field 'fps'"]),
    ("retarget-bvh-frame-time", lambda d: bvh(d / "slow.bvh", frame_time="1000000"),
     ["retarget", "{IN}", "--robot", "op3_like", "--out", "{OUT}"], ["slow.bvh", "Frame Time"]),
    ("retarget-bvh-frames", lambda d: bvh(d / "long.bvh", frames="1000000000"),
     ["retarget", "{IN}", "--robot", "op3_like", "--out", "{OUT}"], ["long.bvh", "Frames:"]),
    ("run-motion-nan", lambda d: motion_npz(d / "motion.npz", joints=np.full((10, 22, 3), np.inf, np.float32),
                                             features=np.zeros((10, 263), np.float32)),
     ["run", "--motion", "{IN}", "--out", "{OUT}"], ["motion.npz", "field 'joints'", "not finite"]),
    ("generate-keyframe-frame-abc",
     lambda d: text(d / "k.json", json.dumps({"keyframes": [{"frame": "abc", "joint": "pelvis", "position": [0, 0, 1]}]})),
     ["generate", "a person walks", "--keyframes", "{IN}", "--out", "{OUT}"], ["k.json", "keyframes[0]", "'frame'"]),
    ("generate-trajectory-not-zip", lambda d: text(d / "x.npz", "root\n0,0\n"),
     ["generate", "a person walks", "--trajectory", "{IN}", "--out", "{OUT}"], ["x.npz", "not a zip archive"]),
    ("generate-seed-2-70", lambda d: text(d / "unused", ""),
     ["generate", "a person walks", "--seed", str(2**70), "--out", "{OUT}"], ["--seed", str(2**70)]),
    ("generate-huge-seconds", lambda d: text(d / "unused", ""),
     ["generate", "a person walks", "--seconds", "1e9", "--out", "{OUT}"], ["--seconds", "above the limit"]),
    ("run-prompts-non-utf8", lambda d: text(d / "p.txt", b"a person \xff\xfe walks\n"),
     ["run", "--prompts", "{IN}", "--out", "{OUT}"], ["p.txt"]),
]


@pytest.mark.parametrize("make, argv, words", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_gives_one_line_and_no_output(make, argv, words, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("MOTOK_MAX_INFLATED_BYTES", str(2**20))
    monkeypatch.chdir(tmp_path)
    source = make(tmp_path)
    out = tmp_path / "out" / ("robot.npz" if "retarget" in argv else "motion.npz" if "generate" in argv else "")
    args = [a.replace("{IN}", str(source)).replace("{OUT}", str(out)) for a in argv]
    log = source.with_name(source.stem + ".playback.csv")
    rc = main(args)
    captured = capsys.readouterr()
    lines = [line for line in captured.err.splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith("motok-robot: error: ")]
    assert rc != 0
    assert "Traceback" not in captured.err and "Traceback" not in captured.out
    assert len(errors) == 1, lines
    for word in words:
        assert word in errors[0], (word, errors[0])
    assert "allow_pickle" not in errors[0] and "models produced" not in errors[0]
    assert not out.exists() and not (tmp_path / "out" / "report.json").exists()
    assert not log.exists()
