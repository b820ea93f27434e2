"""Self-collision avoidance in retargeting (``retarget.collision``).

The clearance rows are checked against MuJoCo's own geom distance on random poses, and a
motion whose arms sweep into the torso is retargeted with and without the avoidance: without
it the robot's forearms enter the torso, with it MuJoCo finds no overlap, and ``robot.npz``
names the pairs that were kept apart. The robot is the small test humanoid of
``tests/test_retarget.py``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")
pytest.importorskip("casadi")

from motok_robot.robots.collision import body_pairs_in_collision, self_collision_model, touching_body_pairs  # noqa: E402
from retarget.collision import CollisionMonitor, pair_geometry  # noqa: E402
from retarget.config import CollisionConfig, ContactConfig  # noqa: E402
from retarget.io import read_robot_npz, write_robot_npz  # noqa: E402
from retarget.problem import RobotKinematics  # noqa: E402
from retarget.solve import Retargeter  # noqa: E402
from test_retarget import SMALL, sites_to_human, toy_robot  # noqa: E402


@pytest.fixture(scope="module")
def robot():
    return toy_robot()


def _geom_of(model, body: str, kind: int) -> int:
    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
    found = [g for g in range(model.ngeom) if model.geom_bodyid[g] == b and model.geom_type[g] == kind]
    assert len(found) == 1, (body, found)
    return found[0]


def _random_x(robot, kin, rng) -> np.ndarray:
    x = kin.nominal_x.copy()
    lo, hi = robot.joint_range[:, 0], robot.joint_range[:, 1]
    x[6:] = rng.uniform(lo, hi)
    x[3:6] = rng.uniform(-0.5, 0.5, size=3)  # yaw, pitch, roll of the base
    return x


def _mujoco_distance(robot, kin, x: np.ndarray, g1: int, g2: int) -> float:
    data = mujoco.MjData(robot.model)
    data.qpos[:] = kin.qpos_from_x(x[None])[0]
    mujoco.mj_kinematics(robot.model, data)
    return float(mujoco.mj_geomDistance(robot.model, data, g1, g2, 1.0, None))


@pytest.mark.parametrize("pair", [("r_forearm", "torso"), ("r_forearm", "r_thigh"), ("l_forearm", "r_forearm")])
def test_clearance_rows_agree_with_mujoco_distance(robot, pair):
    """Clear rows mean the geoms really are apart by the margin (up to the capsule bulge
    between covering spheres), and for capsule pairs the rows measure the real distance."""
    kin = RobotKinematics.build(robot)
    m = robot.model
    capsule = _geom_of(m, pair[0], mujoco.mjtGeom.mjGEOM_CAPSULE)
    other_kind = mujoco.mjtGeom.mjGEOM_BOX if pair[1] == "torso" else mujoco.mjtGeom.mjGEOM_CAPSULE
    other = _geom_of(m, pair[1], other_kind)
    margin = 0.004
    geometry = pair_geometry(m, capsule, other)
    fn, names = kin.clearance_function((geometry,), margin)
    assert len(names) == len(geometry.spheres.radii) and all("self-collision" in n for n in names)
    bulge = float(geometry.spheres.radii.max()) * (1 - np.sqrt(0.75))  # spheres at most one radius apart
    rng = np.random.default_rng(0)
    clear, checked = 0, 0
    for _ in range(300):
        x = _random_x(robot, kin, rng)
        rows = np.array(fn(x)).ravel()
        dist = _mujoco_distance(robot, kin, x, capsule, other)
        if dist > 0.2:
            continue
        checked += 1
        if rows.min() >= 0:
            clear += 1
            assert dist >= margin - bulge - 1e-6, (rows.min(), dist)
        if other_kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            # sphere-vs-segment rows are exact distances minus the margin, short by at most the bulge
            assert rows.min() + margin == pytest.approx(dist, abs=bulge + 1e-6)
        else:
            # the rounded box is conservative: never more clearance than there is (but for the bulge)
            assert rows.min() + margin <= dist + bulge + 1e-6
    assert checked >= 30 and clear >= 5, (checked, clear)


def _arms_into_torso(robot, T: int = 40) -> np.ndarray:
    """Robot qpos [T, nq]: standing, both shoulder rolls sweep the arms inwards to their range
    limit (forearms through the torso) and back, elbows bent."""
    q = np.tile(robot.nominal_qpos, (T, 1))
    adr = dict(zip(robot.joint_names, robot.qpos_adr))
    s = np.sin(np.linspace(0, np.pi, T)) ** 2
    q[:, adr["r_sho_roll"]] = -0.1 + 0.4 * s  # range -1.6..0.3: +0.3 is towards the torso
    q[:, adr["l_sho_roll"]] = 0.1 - 0.4 * s
    q[:, adr["r_el"]] = -0.3 - 0.5 * s
    q[:, adr["l_el"]] = -0.3 - 0.5 * s
    return q


def _deepest_self_collision(robot, qpos: np.ndarray) -> float:
    model = self_collision_model(robot.model)
    ignored = touching_body_pairs(model, robot.nominal_qpos)
    data = mujoco.MjData(model)
    deepest = 0.0
    for q in qpos:
        data.qpos[:] = q
        for _, _, depth in body_pairs_in_collision(model, data, 1e-9, ignored):  # (the toy's feet touch side by side)
            deepest = max(deepest, depth)
    return deepest


def test_arms_sweeping_into_torso_are_kept_apart(robot, tmp_path):
    human = sites_to_human(robot, _arms_into_torso(robot))
    base = replace(SMALL, scale=False, contacts=ContactConfig(floor_height=0.0), min_foot_gap=None)

    off = Retargeter(robot, replace(base, collision=CollisionConfig(enabled=False))).run(human, 20.0, progress=False)
    assert off.success and off.collision_rounds == 0 and off.collision_pairs == []
    assert _deepest_self_collision(robot, off.qpos) > 0.005  # the human motion really drives the arms in

    on = Retargeter(robot, base).run(human, 20.0, progress=False)
    assert on.success, on.solver_status()
    assert on.collision_rounds >= 1
    assert on.collision_pairs, "the pairs kept apart are reported"
    assert _deepest_self_collision(robot, on.qpos) == 0.0  # no overlap at all
    # the robot still follows the motion where it can: legs and head are untouched by the avoidance
    legs = [i for i, n in enumerate(on.keypoint_names) if any(k in n for k in ("hip", "knee", "ankle", "head"))]
    assert on.keypoint_error[:, legs].max() < 0.01
    # only the frames that needed it moved: the first and last frames (arms out) match the free solve
    assert np.abs(on.qpos[:3] - off.qpos[:3]).max() < 1e-3

    path = write_robot_npz(tmp_path / "robot.npz", on)
    assert read_robot_npz(path).collision_pairs == on.collision_pairs


def test_monitor_ignores_pairs_close_by_design(robot):
    """Bodies that touch at the nominal pose (structural overlaps) are never reported."""
    monitor = CollisionMonitor(robot.model, robot.nominal_qpos, near=0.006)
    assert monitor.close_pairs(robot.nominal_qpos[None]) == {}
    # and a pose with the forearm in the torso is reported, with a positive depth
    q = _arms_into_torso(robot, T=21)[10]
    found = monitor.close_pairs(q[None])
    assert found and max(found.values()) > 0.0


def test_collision_config_off_is_the_old_behaviour(robot):
    human = sites_to_human(robot, _arms_into_torso(robot, T=25))
    cfg = replace(SMALL, scale=False, contacts=ContactConfig(floor_height=0.0), min_foot_gap=None,
                  collision=CollisionConfig(enabled=False))
    rt = Retargeter(robot, cfg)
    rt.run(human, 20.0, progress=False)
    assert all(pairs == () for _, pairs, _ in rt._problems)  # no problem with collision rows was ever built


def test_an_unnamed_geom_is_labelled_by_its_body_and_number():
    from retarget.solve import geom_label

    model = mujoco.MjModel.from_xml_string("""<mujoco><worldbody><body name="arm"><geom name="hand" size="0.1"/>
      <geom size="0.05" pos="0 0 0.2"/></body></worldbody></mujoco>""")
    assert [geom_label(model, g) for g in range(model.ngeom)] == ["hand", "arm/1"]
