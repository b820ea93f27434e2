"""What validation needs to know about a robot, resolved once to MuJoCo ids.

:func:`index_robot` takes a :class:`motok_robot.robots.Robot` (docs/CONTRACTS.md: ``model``,
``name``, ``joint_names``, ``qpos_adr``, ``dof_adr``, ``joint_range``, ``velocity_limit``,
``torque_limit``, ``nominal_qpos()``, ``soles``) and returns a :class:`RobotIndex` with the
site / body / actuator ids used by the checks, plus three model copies:

* ``kin_model``: the robot with every constraint disabled (``mjDSBL_CONSTRAINT``), used for
  kinematic replay and for inverse dynamics *without* contacts (the ground reaction is then
  distributed over the soles by :mod:`motok_robot.feasibility.dynamics`);
* ``collision_model``: the robot with all its collision-capable geoms made to collide with
  each other and the floor removed, used to find self-collisions;
* the robot's own ``model`` (untouched) for the physics rollout.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from motok_robot.errors import InputError
from motok_robot.robots import collision

SIDES = ("left", "right")


@dataclass
class RobotIndex:
    """Ids and limits of one robot (arrays indexed by actuated joint j in ``joint_names`` order)."""

    name: str
    model: mujoco.MjModel
    kin_model: mujoco.MjModel
    collision_model: mujoco.MjModel
    joint_names: list[str]
    qpos_adr: np.ndarray        # int [nj]
    dof_adr: np.ndarray         # int [nj]
    joint_range: np.ndarray     # float [nj, 2] rad
    velocity_limit: np.ndarray  # float [nj] rad/s
    torque_limit: np.ndarray    # float [nj] N m
    root_body: int              # body carrying the free joint
    base_dof: np.ndarray        # int [6] qvel addresses of the free joint
    sole_site: np.ndarray       # int [2] (left, right) sole-centre sites
    corner_sites: np.ndarray    # int [2, 4] sole corner sites
    sole_body: np.ndarray       # int [2]
    actuator_joint: np.ndarray  # int [nu] index j driven by each actuator (-1: not a joint actuator)
    actuator_is_position: np.ndarray  # bool [nu] position servo (ctrl = target angle) vs motor
    nominal_qpos: np.ndarray    # float [nq]
    height_m: float             # standing height at the nominal pose (top of the highest geom)
    total_mass: float
    mjcf_path: object = None    # Path of the MJCF the model was compiled from (None: built in memory)
    description_sha256: str | None = None  # digest of the description (TOML + MJCF bytes), Robot.description_sha256
    ignored_body_pairs: set = field(default_factory=set)  # self-collision pairs touching at nominal
    feasibility_settings: dict = field(default_factory=dict)  # the description's [feasibility] table
    description_file: str = ""  # the description's file name, for messages ("op3.toml")

    @property
    def nj(self) -> int:
        return len(self.joint_names)


def _site_id(model, name: str, what: str) -> int:
    sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
    if sid < 0:
        raise InputError(f"robot: {what} site '{name}' is not in the MJCF")
    return sid


def index_robot(robot) -> RobotIndex:
    """Resolve ``robot`` (contract ``Robot``) into a :class:`RobotIndex`."""
    model = robot.model
    free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if not free:
        raise InputError(f"robot '{robot.name}': validation needs a free-floating base (no free joint found)")
    root_body = int(model.jnt_bodyid[free[0]])
    base_dof = np.arange(model.jnt_dofadr[free[0]], model.jnt_dofadr[free[0]] + 6)

    sole_site, corners, sole_body = [], [], []
    for side in SIDES:
        sole = robot.soles[side]
        sid = _site_id(model, sole.site, f"{side} sole")
        sole_site.append(sid)
        if len(sole.corner_sites) != 4:
            raise InputError(f"robot '{robot.name}': {side} sole needs 4 corner sites, has {len(sole.corner_sites)}")
        corners.append([_site_id(model, c, f"{side} sole corner") for c in sole.corner_sites])
        sole_body.append(int(model.site_bodyid[sid]))

    joint_ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in robot.joint_names]
    jindex = {jid: j for j, jid in enumerate(joint_ids)}
    actuator_joint = np.full(model.nu, -1, dtype=int)
    actuator_is_position = np.zeros(model.nu, dtype=bool)
    for a in range(model.nu):
        if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT:
            actuator_joint[a] = jindex.get(int(model.actuator_trnid[a, 0]), -1)
        # a position servo: force = kp*ctrl - kp*q - kv*qdot (affine bias with -kp on q)
        actuator_is_position[a] = (model.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE
                                   and model.actuator_biasprm[a, 1] < 0)

    kin_model = copy.deepcopy(model)
    kin_model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)

    collision_model = collision.self_collision_model(model)
    robot_geom = model.geom_bodyid != 0

    nominal = np.asarray(robot.nominal_qpos(), dtype=np.float64)
    data = mujoco.MjData(kin_model)
    data.qpos[:] = nominal
    mujoco.mj_forward(kin_model, data)
    top = data.geom_xpos[robot_geom, 2] + kin_model.geom_rbound[robot_geom]
    height = float(top.max()) if top.size else 1.0

    index = RobotIndex(
        name=robot.name, model=model, kin_model=kin_model, collision_model=collision_model,
        joint_names=list(robot.joint_names), qpos_adr=np.asarray(robot.qpos_adr, dtype=int),
        dof_adr=np.asarray(robot.dof_adr, dtype=int),
        joint_range=np.asarray(robot.joint_range, dtype=np.float64).reshape(-1, 2),
        velocity_limit=np.asarray(robot.velocity_limit, dtype=np.float64).reshape(-1),
        torque_limit=np.asarray(robot.torque_limit, dtype=np.float64).reshape(-1),
        root_body=root_body, base_dof=base_dof, sole_site=np.array(sole_site),
        corner_sites=np.array(corners), sole_body=np.array(sole_body),
        actuator_joint=actuator_joint, actuator_is_position=actuator_is_position,
        nominal_qpos=nominal, height_m=height, total_mass=float(kin_model.body_subtreemass[root_body]),
        mjcf_path=getattr(robot, "mjcf_path", None),
        description_sha256=getattr(robot, "description_sha256", None))
    description = getattr(robot, "description", None)
    if description is not None:
        index.feasibility_settings = dict(description.feasibility)
        index.description_file = Path(description.path).name
    index.ignored_body_pairs = collision.touching_body_pairs(collision_model, nominal)
    return index


def body_pairs_in_collision(index: RobotIndex, data: mujoco.MjData, min_depth: float) -> list[tuple[int, int, float]]:
    """Self-collisions at the pose in ``data`` (``collision_model``): (body1, body2, depth m).

    Pairs of a body and its direct parent, pairs touching at the nominal pose (structural
    overlaps of the model) and contacts shallower than ``min_depth`` are left out
    (:mod:`motok_robot.robots.collision`, which retargeting uses too).
    """
    return collision.body_pairs_in_collision(index.collision_model, data, min_depth, index.ignored_body_pairs)
