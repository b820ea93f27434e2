"""Shared test configuration: headless rendering, one thread, paths to optional shared data."""

from __future__ import annotations

import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
# no on-disk cache of compiled retargeting problems (and so no background gcc) unless a test
# builds its own ProblemCache: the suite must not leave compilers running behind it
os.environ.setdefault("MOTOK_ROBOT_CACHE", "off")

import pytest  # noqa: E402

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATASETS = REPO_ROOT.parent / "shared" / "datasets"


@pytest.fixture(scope="session")
def shared_datasets() -> Path:
    """The shared motion-capture folder; tests that use it skip when it is absent."""
    if not (SHARED_DATASETS / "README.md").exists():
        pytest.skip(f"shared datasets not found at {SHARED_DATASETS}")
    return SHARED_DATASETS


@pytest.fixture(scope="session")
def retargeted():
    """``retargeted(index, qpos, fps=20.0)``: a robot.npz-like trajectory of ``qpos`` [T, nq] as
    retargeting would write it (contacts from the soles, empty keypoints and source)."""
    import numpy as np

    from motok_robot.feasibility.stage import sole_contacts
    from retarget.io import RobotTrajectory

    def build(index, qpos, fps: float = 20.0) -> RobotTrajectory:
        T = qpos.shape[0]
        return RobotTrajectory(qpos=qpos, joint_names=list(index.joint_names), robot=index.name, fps=fps,
                               contacts=sole_contacts(index, qpos, 0.005), keypoint_error=np.zeros((T, 1)),
                               keypoint_names=["pelvis"], source=np.zeros((T, 22, 3), np.float32), solver_status=[])

    return build


def pytest_addoption(parser):
    parser.addoption("--run-slow", action="store_true", default=False,
                     help="also run the tests marked slow (what CI and the README's test command run)")


def pytest_collection_modifyitems(config, items):
    """Without --run-slow, tests marked ``slow`` are deselected: plain ``pytest`` is the fast suite."""
    if config.getoption("--run-slow") or config.option.markexpr:
        return  # an explicit -m expression decides by itself
    slow = [item for item in items if item.get_closest_marker("slow") is not None]
    if slow:
        config.hook.pytest_deselected(items=slow)
        items[:] = [item for item in items if item.get_closest_marker("slow") is None]
