"""A tiny 18-joint humanoid for the validation tests and examples.

:func:`tiny_humanoid` returns an object with the attributes of ``motok_robot.robots.Robot``
(docs/CONTRACTS.md) that validation reads, built from an MJCF string written here.  It lets
the validator be tested without the robot models of ``models/mjcf`` and proves the checks do
not depend on one robot.  About 0.45 m tall, 3.3 kg, position servos (kp 60 N m/rad, 3 N m
force limit, 4.8 rad/s velocity limit), 12 x 7 cm box soles with corner sites on their bottom
faces, floor friction 1.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

_LEG = """
      <body name="{s}_hip" pos="0 {y} -0.04">
        <joint name="{s}_hip_yaw" axis="0 0 1" range="-0.8 0.8"/>
        <joint name="{s}_hip_roll" axis="1 0 0" range="-0.6 0.6"/>
        <joint name="{s}_hip_pitch" axis="0 1 0" range="-1.6 1.0"/>
        <geom name="{s}_thigh" type="capsule" fromto="0 0 -0.01 0 0 -0.10" size="0.022" mass="0.3"/>
        <body name="{s}_shank" pos="0 0 -0.11">
          <joint name="{s}_knee" axis="0 1 0" range="0 2.3"/>
          <geom name="{s}_shank" type="capsule" fromto="0 0 -0.01 0 0 -0.10" size="0.02" mass="0.2"/>
          <body name="{s}_foot" pos="0 0 -0.11">
            <joint name="{s}_ankle_pitch" axis="0 1 0" range="-1.2 1.2"/>
            <joint name="{s}_ankle_roll" axis="1 0 0" range="-0.6 0.6"/>
            <geom name="{s}_sole" type="box" pos="0.01 0 -0.02" size="0.06 0.035 0.01" mass="0.15" friction="1 0.02 0.001"/>
            <site name="{s}_sole" pos="0.01 0 -0.03"/>
            <site name="{s}_sole_fl" pos="0.07 0.035 -0.03"/>
            <site name="{s}_sole_fr" pos="0.07 -0.035 -0.03"/>
            <site name="{s}_sole_bl" pos="-0.05 0.035 -0.03"/>
            <site name="{s}_sole_br" pos="-0.05 -0.035 -0.03"/>
          </body>
        </body>
      </body>"""

_ARM = """
      <body name="{s}_upper_arm" pos="0 {y} 0.18">
        <joint name="{s}_shoulder_pitch" axis="0 1 0" range="-3.0 3.0"/>
        <joint name="{s}_shoulder_roll" axis="1 0 0" range="{roll}"/>
        <geom name="{s}_upper_arm" type="capsule" fromto="0 {dy} 0 0 {dy} -0.08" size="0.018" mass="0.1"/>
        <body name="{s}_forearm" pos="0 {dy} -0.09">
          <joint name="{s}_elbow" axis="0 1 0" range="-2.0 0.2"/>
          <geom name="{s}_forearm" type="capsule" fromto="0 0 0 0 0 -0.08" size="0.016" mass="0.1"/>
        </body>
      </body>"""

_XML = """
<mujoco model="tiny_humanoid">
  <compiler angle="radian"/>
  <option timestep="0.004" integrator="implicitfast"/>
  <default>
    <joint damping="0.1" armature="0.01"/>
    <geom contype="1" conaffinity="0" friction="1 0.02 0.001" rgba="0.6 0.65 0.75 1"/>
    <position kp="60" kv="1.0" forcerange="-3 3" forcelimited="true"/>
    <site size="0.005" rgba="1 0 0 1"/>
  </default>
  <visual><global offwidth="1280" offheight="720"/></visual>
  <asset>
    <texture name="grid" type="2d" builtin="checker" rgb1=".25 .28 .32" rgb2=".35 .38 .42" width="256" height="256"/>
    <material name="grid" texture="grid" texrepeat="8 8"/>
  </asset>
  <worldbody>
    <light pos="0 0 3" dir="0 0 -1" directional="true"/>
    <geom name="floor" type="plane" size="0 0 0.05" material="grid" contype="1" conaffinity="1"/>
    <body name="pelvis" pos="0 0 0.3">
      <freejoint name="root"/>
      <camera name="track" mode="trackcom" pos="0.2 -1.4 0.5" xyaxes="1 0 0 0 0.3 1"/>
      <geom name="pelvis" type="box" size="0.04 0.07 0.03" mass="1.0"/>
      <geom name="torso" type="box" pos="0 0 0.12" size="0.045 0.065 0.08" mass="1.0"/>
      <geom name="head" type="sphere" pos="0 0 0.26" size="0.045" mass="0.2"/>
      {legs}
      {arms}
    </body>
  </worldbody>
  <actuator>
    {actuators}
  </actuator>
</mujoco>
"""

JOINTS = [f"{s}_{j}" for s in ("left", "right") for j in
          ("hip_yaw", "hip_roll", "hip_pitch", "knee", "ankle_pitch", "ankle_roll")]
JOINTS += [f"{s}_{j}" for s in ("left", "right") for j in ("shoulder_pitch", "shoulder_roll", "elbow")]


def tiny_humanoid_xml(actuator: str = "position") -> str:
    """The MJCF text; ``actuator`` "position" (servos) or "motor" (torque motors, gear 1)."""
    legs = "".join(_LEG.format(s=s, y=y) for s, y in (("left", 0.045), ("right", -0.045)))
    arms = "".join(_ARM.format(s=s, y=y, dy=dy, roll=roll) for s, y, dy, roll in
                   (("left", 0.075, 0.02, "-0.2 1.6"), ("right", -0.075, -0.02, "-1.6 0.2")))
    if actuator == "position":
        lines = [f'<position name="{j}" joint="{j}" ctrlrange="-3.2 3.2"/>' for j in JOINTS]
    elif actuator == "motor":
        lines = [f'<motor name="{j}" joint="{j}" ctrlrange="-3 3" ctrllimited="true"/>' for j in JOINTS]
    else:
        raise ValueError(f"actuator must be 'position' or 'motor', got {actuator!r}")
    return _XML.format(legs=legs, arms=arms, actuators="\n    ".join(lines))


@dataclass
class Sole:
    body: str
    site: str
    corner_sites: list
    half_size: tuple


@dataclass
class TinyHumanoid:
    """Contract-shaped robot (the subset validation reads)."""

    name: str
    model: mujoco.MjModel
    joint_names: list
    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    joint_range: np.ndarray
    velocity_limit: np.ndarray
    torque_limit: np.ndarray
    soles: dict
    _nominal: np.ndarray = field(repr=False, default=None)
    mjcf_path: object = None

    def nominal_qpos(self) -> np.ndarray:
        return self._nominal.copy()


def tiny_humanoid(torque_limit: float = 3.0, actuator: str = "position") -> TinyHumanoid:
    """Build the tiny humanoid; knees bent 0.6 rad, soles flat on the floor at the nominal pose.

    ``actuator="motor"`` gives torque motors limited to +-3 N m (the rollout then wraps them
    in a PD servo law)."""
    model = mujoco.MjModel.from_xml_string(tiny_humanoid_xml(actuator))
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in JOINTS]
    qpos_adr = model.jnt_qposadr[ids].copy()
    dof_adr = model.jnt_dofadr[ids].copy()
    if torque_limit != 3.0:
        model.actuator_forcerange[:] = [-torque_limit, torque_limit]
    soles = {s: Sole(body=f"{s}_foot", site=f"{s}_sole",
                     corner_sites=[f"{s}_sole_{c}" for c in ("fl", "fr", "bl", "br")], half_size=(0.06, 0.035))
             for s in ("left", "right")}
    nominal = model.qpos0.copy()
    bend = {"hip_pitch": -0.3, "knee": 0.6, "ankle_pitch": -0.3}
    for j, name in enumerate(JOINTS):
        for key, value in bend.items():
            if name.endswith(key):
                nominal[qpos_adr[j]] = value
    data = mujoco.MjData(model)
    data.qpos[:] = nominal
    mujoco.mj_kinematics(model, data)
    corner_ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, c) for s in soles.values() for c in s.corner_sites]
    nominal[2] -= data.site_xpos[corner_ids, 2].min()
    return TinyHumanoid(
        name="tiny_humanoid", model=model, joint_names=list(JOINTS), qpos_adr=qpos_adr, dof_adr=dof_adr,
        joint_range=model.jnt_range[ids].copy(), velocity_limit=np.full(len(JOINTS), 4.8),
        torque_limit=np.abs(model.actuator_forcerange[:, 1]).copy(), soles=soles, _nominal=nominal)
