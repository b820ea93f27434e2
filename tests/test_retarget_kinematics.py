"""CasADi forward kinematics (retarget.kinematics) against MuJoCo's mj_kinematics."""

from __future__ import annotations

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from motok_robot.errors import InputError  # noqa: E402
from retarget.kinematics import UnsupportedJointError, kinematics_function  # noqa: E402

NESTED_XML = """
<mujoco>
  <worldbody>
    <body name="base" pos="0.1 0.2 0.5" quat="0.9 0.1 0.2 0.3">
      <freejoint name="root"/>
      <geom type="box" size="0.1 0.1 0.1" mass="2"/>
      <site name="s_base" pos="0.01 0.02 0.03" quat="0.5 0.5 0.5 0.5"/>
      <body name="a" pos="0.1 0 -0.1" quat="0.7 0 0.7 0.1">
        <joint name="j1" type="hinge" axis="0.3 0.5 0.8" pos="0.02 0.01 0.0" ref="0.3"/>
        <joint name="j2" type="slide" axis="1 0 1" ref="0.05"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.2" size="0.03" mass="0.5"/>
        <body name="b" pos="0 0.05 -0.2" euler="10 20 30">
          <joint name="j3" type="hinge" axis="0 1 0" pos="0 0 0.03"/>
          <joint name="j4" type="hinge" axis="1 0 0"/>
          <geom type="sphere" size="0.04" pos="0.01 0 -0.05" mass="0.3"/>
          <site name="tip" pos="0.03 -0.02 -0.1" euler="5 0 40"/>
          <body name="fixed" pos="0.02 0.0 -0.07" quat="0.2 0.9 0.1 0.3">
            <geom type="sphere" size="0.01" mass="0.05"/>
            <site name="fixed_site" pos="0.01 0.01 0.01"/>
          </body>
        </body>
      </body>
      <body name="c" pos="-0.1 0 0.1">
        <joint name="j5" type="hinge" axis="0 0 1"/>
        <geom type="box" size="0.02 0.03 0.04" pos="0 0.1 0" mass="0.2"/>
        <site name="c_site" pos="0 0.2 0"/>
      </body>
    </body>
    <body name="arm" pos="1 0 0.3">
      <joint name="s1" type="slide" axis="0 0 1"/>
      <joint name="h1" type="hinge" axis="0 1 0" pos="0 0 0.1"/>
      <geom type="box" size="0.05 0.05 0.05" mass="1"/>
      <site name="arm_site" pos="0.1 0 0"/>
    </body>
  </worldbody>
</mujoco>
"""


def _compare(model, rng, trials=40, scale=1.5):
    data = mujoco.MjData(model)
    fk = kinematics_function(model)
    worst = 0.0
    for _ in range(trials):
        q = model.qpos0 + rng.normal(scale=scale, size=model.nq)
        for j in range(model.njnt):
            if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
                a = model.jnt_qposadr[j]
                q[a + 3 : a + 7] = rng.normal(size=4)  # any non-zero quaternion: both normalise it
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        site_pos, site_rot, body_pos, body_rot, com = (np.array(v) for v in fk(q))
        worst = max(
            worst,
            np.abs(site_pos - data.site_xpos.T).max() if model.nsite else 0.0,
            np.abs(site_rot - np.hstack([data.site_xmat[i].reshape(3, 3) for i in range(model.nsite)])).max() if model.nsite else 0.0,
            np.abs(body_pos - data.xpos[1:].T).max(),
            np.abs(body_rot - np.hstack([data.xmat[i].reshape(3, 3) for i in range(1, model.nbody)])).max(),
            np.abs(com.ravel() - data.subtree_com[1]).max(),
        )
    return worst


def test_fk_matches_mujoco_on_nested_model():
    model = mujoco.MjModel.from_xml_string(NESTED_XML)
    assert _compare(model, np.random.default_rng(0)) < 1e-9


@pytest.mark.parametrize("name", ["op3_like", "humanoid25"])
def test_fk_matches_mujoco_on_project_robots(name):
    robots = pytest.importorskip("motok_robot.robots")
    try:
        available = robots.list_robots()
    except Exception as exc:  # the robots stage is broken or absent
        pytest.skip(f"robots not available: {exc}")
    if name not in available:
        pytest.skip(f"{name} not present")
    model = robots.load(name).model
    assert _compare(model, np.random.default_rng(1), trials=20, scale=0.7) < 1e-9


def test_ball_joint_is_rejected_with_its_name():
    xml = """<mujoco><worldbody><body name="b"><freejoint/><geom size="0.1"/>
      <body name="c" pos="0 0 -0.2"><joint name="shoulder_ball" type="ball"/><geom size="0.05"/></body>
      </body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    with pytest.raises(UnsupportedJointError, match="shoulder_ball"):
        kinematics_function(model)


def test_unknown_site_is_named():
    model = mujoco.MjModel.from_xml_string(NESTED_XML)
    with pytest.raises(InputError, match="no_such_site"):
        kinematics_function(model, sites=["no_such_site"])
