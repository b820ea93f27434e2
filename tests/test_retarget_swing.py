"""Swing-foot clearance and the soft ZMP balance term of retargeting (toy robot of test_retarget)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("mujoco")
pytest.importorskip("casadi")

from motok_robot.motion.skeleton import JOINT_INDEX  # noqa: E402
from retarget.config import SwingConfig  # noqa: E402
from retarget.metrics import sole_points  # noqa: E402
from retarget.solve import Retargeter  # noqa: E402
from retarget.swing import swing_clearance, transition_frames  # noqa: E402
from test_retarget import SMALL, synthetic_walk, toy_robot  # noqa: E402


def test_clearance_profile_ramps_between_contacts():
    c = np.zeros((20, 2), dtype=bool)
    c[:5, 0] = c[15:, 0] = True  # left: swing 5..14 between two contacts
    c[:, 1] = True  # right planted throughout
    cfg = SwingConfig(height=0.2, lift=0.04, ramp_seconds=0.1)  # ramp: 2 frames at 20 fps
    h = swing_clearance(c, 20.0, cfg)
    assert (h[c] == 0).all()
    np.testing.assert_allclose(h[[5, 14], 0], 0.04)  # next to contact: lift
    np.testing.assert_allclose(h[7:13, 0], 0.20)  # mid-swing: full height
    assert 0.04 < h[6, 0] < 0.20 and h[6, 0] == pytest.approx(h[13, 0])  # symmetric smooth ramp
    assert (np.diff(h[5:10, 0]) >= 0).all()
    tf = transition_frames(c)
    assert tf[:, 0].nonzero()[0].tolist() == [5, 14] and not tf[:, 1].any()
    assert not swing_clearance(c, 20.0, replace(cfg, height=0.0)).any()  # off


def test_clearance_profile_clip_edges():
    c = np.zeros((10, 2), dtype=bool)
    c[6:, 0] = True  # left starts in swing: no lift-off ramp at the clip start
    h = swing_clearance(c, 20.0, SwingConfig(height=0.1, lift=0.05, ramp_seconds=0.1))
    assert h[0, 0] == pytest.approx(0.1) and h[5, 0] == pytest.approx(0.05)
    # right never touches the ground while left does (a one-legged stance): held up throughout,
    # so it cannot drag along the floor
    np.testing.assert_allclose(h[:, 1], 0.1)
    # neither foot ever touches: nothing to clear
    assert not swing_clearance(np.zeros((10, 2), dtype=bool), 20.0, SwingConfig(height=0.1)).any()


def skimming_walk(T: int = 50) -> np.ndarray:
    """The synthetic walk with its swing feet flattened to the stance height (a foot that skims the floor)."""
    j = synthetic_walk(T=T)
    for side in ("left", "right"):
        for name in (f"{side}_ankle", f"{side}_foot"):
            k = JOINT_INDEX[name]
            j[:, k, 2] = j[:, k, 2].min()  # the planted height all the time
    return j


@pytest.fixture(scope="module")
def robot():
    return toy_robot()


def test_swing_feet_clear_the_floor_and_land_flat(robot):
    human = skimming_walk()
    off = Retargeter(robot, replace(SMALL, swing=SwingConfig(height=0.0))).run(human, 20.0, progress=False)
    rt = Retargeter(robot, SMALL)
    on = rt.run(human, 20.0, progress=False)
    assert on.success, on.solver_status()
    np.testing.assert_array_equal(on.contacts, off.contacts)
    swing = ~on.contacts
    assert swing.any() and on.contacts.any()
    cfg = SMALL.swing
    site, corners = sole_points(rt.kin, on.x)
    low = corners[..., 2].min(axis=2)  # [T, 2]
    need = swing_clearance(on.contacts, 20.0, cfg)
    assert (low[swing] >= need[swing] - 1e-5).all()
    assert low[swing].max() >= cfg.height - 1e-5  # mid-swing reaches the full clearance
    # without the term the skimming swing foot stays below the clearance somewhere
    _, corners_off = sole_points(rt.kin, off.x)
    assert (corners_off[..., 2].min(axis=2)[swing] < need[swing] - 1e-3).any()
    # lift-off / touch-down frames: flat and low, and the sole moves at most the transition step
    tf = transition_frames(on.contacts)
    spread = corners[..., 2].max(axis=2) - corners[..., 2].min(axis=2)
    assert tf.any() and (spread[tf] <= cfg.flat_tolerance + 1e-5).all()
    step = np.abs(np.diff(site[:, :, :2], axis=0)).max(axis=-1)  # [T-1, 2] largest of the x, y moves
    change = on.contacts[1:] != on.contacts[:-1]
    assert change.any() and (step[change] <= cfg.transition_speed / 20.0 + 1e-5).all()
    # contacts still hold: planted soles at the ground
    assert np.abs(low[on.contacts]).max() < 1e-4


@pytest.mark.slow  # about 20 s
def test_soft_zmp_term_pulls_zmp_over_support(robot):
    human = synthetic_walk(T=40)
    base = Retargeter(robot, SMALL)
    with_zmp = Retargeter(robot, replace(SMALL, weights=replace(SMALL.weights, zmp=30.0)))

    def zmp_offset(rt, res, fps=20.0):
        out = rt.kin.frame.map(len(res.x))(res.x.T)
        com = np.array(out[4]).T
        soles = np.array(out[1]).reshape(3, 2, -1, order="F").transpose(2, 1, 0)[..., :2]
        acc = (com[2:] - 2 * com[1:-1] + com[:-2]) * fps**2
        zmp = com[1:-1, :2] - com[1:-1, 2:3] * acc[:, :2] / (9.81 + acc[:, 2:3])
        m = res.contacts[1:-1].astype(float)
        keep = m.sum(1) > 0
        centre = (m[:, :, None] * soles[1:-1]).sum(1)[keep] / m.sum(1)[keep, None]
        return np.linalg.norm(zmp[keep] - centre, axis=1).mean()

    a = base.run(human, 20.0, progress=False)
    b = with_zmp.run(human, 20.0, progress=False)
    assert b.success, b.solver_status()
    assert zmp_offset(with_zmp, b) < 0.7 * zmp_offset(base, a)


def test_feet_keep_a_gap_when_the_human_feet_pass_close(robot):
    human = synthetic_walk(T=40)
    for name in ("left_ankle", "left_foot", "right_ankle", "right_foot"):
        human[:, JOINT_INDEX[name], 1] = 0.0  # a walk on a line: the feet pass through each other
    rt = Retargeter(robot, SMALL)
    res = rt.run(human, 20.0, progress=False)
    assert res.success, res.solver_status()
    site, _ = sole_points(rt.kin, res.x)
    h = res.targets.heading
    lateral = -np.sin(h) * (site[:, 0, 0] - site[:, 1, 0]) + np.cos(h) * (site[:, 0, 1] - site[:, 1, 1])
    need = rt._sole_width() + SMALL.min_foot_gap * rt.kin.leg_length
    assert lateral.min() >= need - 1e-5
    free = Retargeter(robot, replace(SMALL, min_foot_gap=None)).run(human, 20.0, progress=False)
    site_f, _ = sole_points(rt.kin, free.x)
    lateral_f = -np.sin(h) * (site_f[:, 0, 0] - site_f[:, 1, 0]) + np.cos(h) * (site_f[:, 0, 1] - site_f[:, 1, 1])
    assert lateral_f.min() < need - 1e-3  # without the constraint the soles come closer than that


def test_cli_rejects_negative_swing_height(tmp_path, capsys):
    from motok_robot.cli import main

    motion = tmp_path / "motion.npz"
    np.savez(motion, joints=synthetic_walk(T=10).astype(np.float32), fps=20)
    out = tmp_path / "robot.npz"
    assert main(["retarget", str(motion), "--robot", "op3_like", "--out", str(out), "--swing-height", "-0.01"]) == 2
    assert "--swing-height must be >= 0" in capsys.readouterr().err and not out.exists()
