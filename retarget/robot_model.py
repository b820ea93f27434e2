"""What retargeting needs to know about a robot, in one plain object.

:class:`RetargetRobot` is built from a :class:`motok_robot.robots.Robot` (``from_robot``) or
directly (tests, custom models). It holds the compiled MuJoCo model, the actuated joints,
their limits, the nominal pose, the keypoint map (human joint -> robot site, weight) and the
sole sites.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.motion.skeleton import JOINT_INDEX
from motok_robot.robots.description import Keypoint


@dataclass(frozen=True)
class SoleSites:
    """A sole: centre site on the sole surface, and its 4 corner sites (same plane)."""

    site: str
    corner_sites: tuple[str, ...]


@dataclass
class RetargetRobot:
    name: str
    model: object  # mujoco.MjModel (floating base: a free joint at qpos[0:7])
    joint_names: list[str]  # actuated joints, in qpos order
    qpos_adr: np.ndarray  # [nj] int, qpos address of each actuated joint
    joint_range: np.ndarray  # [nj, 2] rad (metres for slide joints): the range the solver may use (Robot.retarget_range)
    velocity_limit: np.ndarray  # [nj] rad/s
    nominal_qpos: np.ndarray  # [nq] standing pose, soles on the floor
    keypoints: list[Keypoint]  # human joint -> robot site, weight (the robots stage's type)
    soles: dict[str, SoleSites]  # "left", "right"
    limb_scale: dict[str, float] = field(default_factory=dict)  # legs, arms, torso, head

    def __post_init__(self) -> None:
        import mujoco

        m = self.model
        if m.njnt == 0 or m.jnt_type[0] != mujoco.mjtJoint.mjJNT_FREE or m.jnt_qposadr[0] != 0:
            raise InputError(f"robot {self.name!r}: the first joint must be a free joint (floating base) at qpos[0:7]")
        self.qpos_adr = np.asarray(self.qpos_adr, dtype=int)
        self.joint_range = np.asarray(self.joint_range, dtype=np.float64).reshape(-1, 2)
        self.velocity_limit = np.asarray(self.velocity_limit, dtype=np.float64).reshape(-1)
        self.nominal_qpos = np.asarray(self.nominal_qpos, dtype=np.float64).reshape(-1)
        nj = len(self.joint_names)
        for arr, what in ((self.qpos_adr, "qpos_adr"), (self.joint_range, "joint_range"), (self.velocity_limit, "velocity_limit")):
            if len(arr) != nj:
                raise InputError(f"robot {self.name!r}: {what} has {len(arr)} entries for {nj} joints")
        if self.nominal_qpos.shape != (m.nq,):
            raise InputError(f"robot {self.name!r}: nominal_qpos has {self.nominal_qpos.size} entries, model nq={m.nq}")
        site_names = {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, i) for i in range(m.nsite)}
        for kp in self.keypoints:
            if kp.human_joint not in JOINT_INDEX:
                raise InputError(f"robot {self.name!r}: keypoint human joint {kp.human_joint!r} is not a canonical joint")
            if kp.site not in site_names:
                raise InputError(f"robot {self.name!r}: keypoint site {kp.site!r} is not in the model")
        for side in ("left", "right"):
            if side not in self.soles:
                raise InputError(f"robot {self.name!r}: no {side} sole")
            for s in (self.soles[side].site, *self.soles[side].corner_sites):
                if s not in site_names:
                    raise InputError(f"robot {self.name!r}: {side} sole site {s!r} is not in the model")

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    @classmethod
    def from_robot(cls, robot) -> "RetargetRobot":
        """Adapter for :class:`motok_robot.robots.Robot` (see docs/CONTRACTS.md)."""
        return cls(
            name=robot.name,
            model=robot.model,
            joint_names=list(robot.joint_names),
            qpos_adr=np.asarray(robot.qpos_adr),
            joint_range=np.asarray(getattr(robot, "retarget_range", robot.joint_range)),
            velocity_limit=np.asarray(robot.velocity_limit),
            nominal_qpos=np.asarray(robot.nominal_qpos()),
            keypoints=list(robot.keypoints),
            soles={side: SoleSites(s.site, tuple(s.corner_sites)) for side, s in robot.soles.items()},
            limb_scale=dict(robot.limb_scale or {}),
        )


def load_robot(name_or_path: str | Path) -> RetargetRobot:
    """Load a robot by name or MJCF path through :func:`motok_robot.robots.load`."""
    from motok_robot.robots import load

    try:
        robot = load(name_or_path)
    except InputError:
        raise
    except (FileNotFoundError, KeyError, LookupError) as exc:
        raise InputError(f"unknown robot {name_or_path!r}: {exc}") from None
    return RetargetRobot.from_robot(robot)
