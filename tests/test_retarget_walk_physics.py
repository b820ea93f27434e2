"""A real walk, retargeted and checked in physics: the end-to-end claim of retargeting + validation.

Bandai ``dataset-1_walk_old_001`` (first 6 s) on op3_like with the soft ZMP term at weight 1000
passes every validation check, the physics rollout included (servos tracking the feedforward
goals, free base, contacts); with the ZMP term off the same clip fails (ZMP, and it falls or
leaves its path). Uses
``../shared/datasets`` and skips without it.
"""

from __future__ import annotations

import tarfile
from dataclasses import replace

import pytest

pytest.importorskip("mujoco")
pytest.importorskip("casadi")

from motok_robot.robots import load  # noqa: E402
from motok_robot.sim.validate import validate_file  # noqa: E402
from retarget.config import RetargetConfig  # noqa: E402
from retarget.io import read_input, write_robot_npz  # noqa: E402
from retarget.robot_model import RetargetRobot  # noqa: E402
from retarget.solve import Retargeter  # noqa: E402

pytestmark = pytest.mark.shared
CLIP = "dataset-1_walk_old_001.bvh"


@pytest.fixture(scope="module")
def walk_bvh(tmp_path_factory, shared_datasets):
    archive = shared_datasets / "bandai-namco-bvh.tar.xz"
    out = tmp_path_factory.mktemp("walk") / CLIP
    with tarfile.open(archive, "r|xz") as tar:  # streamed: the clip is near the start of the archive
        for member in tar:
            if member.name.endswith("/" + CLIP):
                out.write_bytes(tar.extractfile(member).read())
                return out
    pytest.fail(f"{CLIP} not found in {archive}")


def _validate_walk(path, tmp_path, zmp: float) -> dict:
    robot = load("op3_like")
    motion = read_input(path)
    frames = int(round(6.0 * motion.fps))
    d = RetargetConfig()
    result = Retargeter(RetargetRobot.from_robot(robot), replace(d, weights=replace(d.weights, zmp=zmp))).run(
        motion.joints[:frames], motion.fps, progress=False)
    assert result.success, result.solver_status()
    npz = write_robot_npz(tmp_path / f"zmp{zmp:g}" / "robot.npz", result)
    return validate_file(npz, robot, out_dir=npz.parent, render=False, plots=False).report


@pytest.mark.slow  # about 35 s
def test_retargeted_real_walk_passes_physics_with_the_zmp_term(walk_bvh, tmp_path):
    report = _validate_walk(walk_bvh, tmp_path, zmp=1000.0)
    m = report["metrics"]
    assert report["passed"], (report["failed_checks"], {k: m[k] for k in ("base_drift_m", "max_torque_ratio", "zmp_outside_ratio")})
    assert not m["fell"] and m["foot_skate_ratio"] == 0.0


def test_the_same_walk_without_the_zmp_term_fails(walk_bvh, tmp_path):
    """Its ZMP leaves the support, and the robot falls or leaves its path (at the 4 ms physics
    step of before it fell; at the model's own 2 ms it ends 0.52 m off the path, against 0.035 m
    with the term)."""
    report = _validate_walk(walk_bvh, tmp_path, zmp=0.0)
    failed = report["failed_checks"]
    assert not report["passed"] and "zmp" in failed and ("fall" in failed or "base_drift" in failed), failed
