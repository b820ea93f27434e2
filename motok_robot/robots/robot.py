"""The :class:`Robot`: a compiled MuJoCo model plus its checked description.

``load(name_or_path)`` finds ``models/mjcf/NAME.toml`` (or takes a path to a ``.toml``/``.xml``),
parses the description, compiles the MJCF and checks one against the other. Array conventions:
``nj`` actuated hinge joints in qpos order (the free base excluded); angles in rad, angular
velocities in rad/s, torques in N m; ``qpos`` vectors are MuJoCo's full ``[nq]`` (free base
position xyz in m and quaternion wxyz first).
"""

from __future__ import annotations

import hashlib
import os
import warnings
from pathlib import Path

import numpy as np

from motok_robot.paths import MODELS_ENV, robots_dir  # noqa: F401 (MODELS_ENV re-exported)
from motok_robot.errors import InputError
from motok_robot.robots import servo_models
from motok_robot.robots.description import (
    BusSpec,
    Keypoint,
    RobotDescription,
    ServoSpec,
    Sole,
    check_against_model,
    parse_description,
)

#: the robot used when a command is not told which one: the system-identified ROBOTIS OP3
DEFAULT_ROBOT = "op3"


def models_dir() -> Path:
    """The folder holding ``NAME.xml`` + ``NAME.toml``: ``$MOTOK_ROBOT_MODELS/mjcf`` or ``<repo>/models/mjcf``."""
    return robots_dir()


def list_robots() -> list[str]:
    """Names of the robots in :func:`models_dir` (a ``NAME.toml`` with its ``NAME.xml``), sorted."""
    folder = models_dir()
    if not folder.is_dir():
        return []
    return sorted(p.stem for p in folder.glob("*.toml") if p.with_suffix(".xml").is_file())


def _compile(mjcf: Path):
    import mujoco

    if not mjcf.is_file():
        raise InputError(f"robot model not found: {mjcf}")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            return mujoco.MjModel.from_xml_path(str(mjcf))
        except ValueError as exc:
            msg = " ".join(str(exc).split())
            raise InputError(f"{mjcf.name}: MuJoCo cannot compile it: {msg}") from None


class Robot:
    """A humanoid robot: MuJoCo model + description (see ``docs/CONTRACTS.md``, section Robots).

    Attributes (``nj`` = number of actuated hinge joints):

    * ``name``, ``mjcf_path``, ``description`` (:class:`RobotDescription`), ``model`` (``mujoco.MjModel``)
    * ``joint_names`` list[str] [nj], qpos order; ``qpos_adr`` / ``dof_adr`` int [nj]
    * ``joint_range`` [nj, 2] rad (the MJCF's); ``retarget_range`` [nj, 2] rad, inside it (the
      description's ``[retarget_ranges]``); ``velocity_limit`` [nj] rad/s; ``torque_limit`` [nj] N m
    * ``actuator_joint`` int [nu]: index into ``joint_names`` of the joint each actuator drives
    * ``keypoints``, ``soles``, ``limb_scale``, ``servos``, ``bus`` (from the description)
    """

    def __init__(self, description: RobotDescription, model=None):
        import mujoco

        self.description = description
        self.name = description.name
        self.mjcf_path = description.mjcf
        self.model = model if model is not None else _compile(description.mjcf)
        m = self.model
        if m.njnt == 0 or m.jnt_type[0] != mujoco.mjtJoint.mjJNT_FREE or m.jnt_qposadr[0] != 0:
            raise InputError(f"{self.mjcf_path.name}: the first joint must be the free base joint (qpos[0:7])")
        hinge = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
        others = [j for j in range(1, m.njnt) if m.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE]
        if others:
            bad = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, others[0])
            raise InputError(f"{self.mjcf_path.name}: joint {bad!r} is not a hinge (only a free base + hinges are supported)")
        hinge.sort(key=lambda j: m.jnt_qposadr[j])
        self._joint_ids = np.array(hinge, dtype=int)
        self.joint_names: list[str] = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in hinge]
        self.qpos_adr = m.jnt_qposadr[self._joint_ids].astype(int)
        self.dof_adr = m.jnt_dofadr[self._joint_ids].astype(int)
        for j, name in zip(hinge, self.joint_names):
            if not m.jnt_limited[j]:
                raise InputError(f"{self.mjcf_path.name}: joint {name!r} has no range")
        self.joint_range = m.jnt_range[self._joint_ids].astype(np.float64).copy()

        check_against_model(description, m, self.joint_names, self.joint_range)
        #: [nj, 2] rad: the joint range narrowed by the description's ``[retarget_ranges]`` (what the
        #: retargeter may use; limits everywhere else are ``joint_range``)
        self.retarget_range = self.joint_range.copy()
        for joint, bounds in description.retarget_ranges.items():
            self.retarget_range[self.joint_names.index(joint)] = bounds

        index = {n: i for i, n in enumerate(self.joint_names)}
        # actuators: one per joint, each on a joint transmission
        self.actuator_joint = np.full(m.nu, -1, dtype=int)
        driven: dict[int, int] = {}
        for a in range(m.nu):
            aname = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a) or f"#{a}"
            if m.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
                raise InputError(f"{self.mjcf_path.name}: actuator {aname!r} must drive a joint")
            jname = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, m.actuator_trnid[a, 0])
            if jname not in index:
                raise InputError(f"{self.mjcf_path.name}: actuator {aname!r} drives {jname!r}, not an actuated hinge")
            if index[jname] in driven:
                raise InputError(f"{self.mjcf_path.name}: joint {jname!r} has two actuators")
            driven[index[jname]] = a
            self.actuator_joint[a] = index[jname]
        undriven = [n for i, n in enumerate(self.joint_names) if i not in driven]
        if undriven:
            raise InputError(f"{self.mjcf_path.name}: joint(s) without an actuator: {', '.join(undriven)}")

        self.torque_limit = np.zeros(len(self.joint_names))
        for i, a in driven.items():
            gear = abs(m.actuator_gear[a, 0])
            limits = []
            if m.actuator_forcelimited[a]:
                limits.append(np.max(np.abs(m.actuator_forcerange[a])))
            if m.actuator_biastype[a] == 0 and m.actuator_ctrllimited[a]:  # plain motor: ctrl is torque
                limits.append(np.max(np.abs(m.actuator_ctrlrange[a])) * m.actuator_gainprm[a, 0] * gear)
            j = self._joint_ids[i]
            if m.jnt_actfrclimited[j]:
                limits.append(np.max(np.abs(m.jnt_actfrcrange[j])))
            if not limits:
                raise InputError(f"{self.mjcf_path.name}: the actuator of joint {self.joint_names[i]!r} has no torque limit")
            self.torque_limit[i] = float(min(limits))
            servo = description.servo_for(self.joint_names[i])
            problem = (servo_models.torque_problem(servo.model, self.torque_limit[i]) if servo is not None
                       else None if np.isfinite(self.torque_limit[i]) and self.torque_limit[i] > 0
                       else f"torque limit must be a positive finite number of N m, got {self.torque_limit[i]}")
            if problem:
                raise InputError(f"{self.mjcf_path.name}: actuator of joint {self.joint_names[i]!r}: {problem}")

        self.velocity_limit = np.zeros(len(self.joint_names))
        for i, n in enumerate(self.joint_names):
            servo = description.servo_for(n)
            if servo is not None:
                self.velocity_limit[i] = servo.velocity_limit
            else:
                self.velocity_limit[i] = description.velocity_limits.get(n, description.velocity_limits.get("default"))

    # -- description shortcuts ---------------------------------------------------------------
    @property
    def description_sha256(self) -> str:
        """Digest of this robot's description: sha256 over the TOML and the MJCF bytes
        (:func:`description_digest`); a validation report records it and playback checks it."""
        if getattr(self, "_description_sha256", None) is None:
            self._description_sha256 = description_digest(self.description.path, self.mjcf_path)
        return self._description_sha256

    @property
    def keypoints(self) -> list[Keypoint]:
        return self.description.keypoints

    @property
    def soles(self) -> dict[str, Sole]:
        return self.description.soles

    @property
    def limb_scale(self) -> dict[str, float]:
        return self.description.limb_scale

    @property
    def servos(self) -> list[ServoSpec]:
        return self.description.servos

    @property
    def bus(self) -> BusSpec | None:
        return self.description.bus

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    @property
    def nv(self) -> int:
        return int(self.model.nv)

    @property
    def nj(self) -> int:
        return len(self.joint_names)

    @property
    def torso_body(self) -> str:
        return self.description.torso_body

    def joint_index(self, name: str) -> int:
        """Index of joint ``name`` in ``joint_names``; InputError naming the known joints otherwise."""
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise InputError(f"robot {self.name!r} has no joint {name!r} (joints: {', '.join(self.joint_names)})") from None

    def total_mass(self) -> float:
        """Total mass of the robot, kg."""
        return float(self.model.body_subtreemass[0])

    # -- poses -------------------------------------------------------------------------------
    def nominal_joints(self) -> np.ndarray:
        """Nominal standing joint angles ``[nj]`` rad (joints not in the description: 0)."""
        q = np.zeros(self.nj)
        for n, v in self.description.nominal_pose.items():
            q[self.joint_index(n)] = v
        return q

    def qpos_from_joints(self, joints: np.ndarray, base_pos=(0.0, 0.0, 0.0), base_quat=(1.0, 0.0, 0.0, 0.0)) -> np.ndarray:
        """Full ``[nq]`` qpos from joint angles ``[nj]`` rad, base position (m) and quaternion (wxyz)."""
        q = self.model.qpos0.astype(np.float64).copy()
        q[0:3] = base_pos
        q[3:7] = base_quat
        q[self.qpos_adr] = np.asarray(joints, dtype=np.float64).reshape(self.nj)
        return q

    def lowest_sole_height(self, qpos: np.ndarray) -> float:
        """Lowest z (m) of all sole corner sites at ``qpos`` ``[nq]``."""
        import mujoco

        d = mujoco.MjData(self.model)
        d.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, d)
        ids = [self.model.site(s).id for sole in self.soles.values() for s in sole.corner_sites]
        return float(d.site_xpos[ids, 2].min())

    def standing_qpos(self, joints: np.ndarray) -> np.ndarray:
        """``[nq]`` qpos with joint angles ``[nj]``, base upright at x=y=0 and the lowest sole corner at z=0."""
        q = self.qpos_from_joints(joints)
        q[2] = -self.lowest_sole_height(q)
        return q

    def nominal_qpos(self) -> np.ndarray:
        """Nominal standing pose ``[nq]``: free base (pos m, quat wxyz) + joints, soles resting on the floor."""
        return self.standing_qpos(self.nominal_joints())

    def ctrl_from_qpos(self, qpos: np.ndarray) -> np.ndarray:
        """Position-actuator targets ``[..., nu]`` (rad) holding the joint angles of ``qpos[..., nq]``."""
        qpos = np.asarray(qpos)
        return qpos[..., self.qpos_adr[self.actuator_joint]]

    def height(self, qpos: np.ndarray | None = None) -> float:
        """Top of the highest geom above the lowest sole corner, m, at ``qpos`` (default: zero pose)."""
        import mujoco

        m = self.model
        q = self.qpos_from_joints(np.zeros(self.nj)) if qpos is None else np.asarray(qpos, dtype=np.float64)
        d = mujoco.MjData(m)
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        robot_geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] != 0]
        top = -np.inf
        for g in robot_geoms:
            centre = d.geom_xpos[g] + d.geom_xmat[g].reshape(3, 3) @ m.geom_aabb[g, :3]
            extent = np.abs(d.geom_xmat[g].reshape(3, 3)[2]) @ m.geom_aabb[g, 3:]
            top = max(top, centre[2] + extent)
        return float(top - self.lowest_sole_height(q))

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, nj={self.nj}, mass={self.total_mass():.2f} kg, servos={len(self.servos)})"


def description_digest(toml_path: str | os.PathLike, mjcf_path: str | os.PathLike) -> str:
    """sha256 over the bytes of a robot description: ``len(toml) toml len(mjcf) mjcf`` (lengths
    as 8-byte big-endian integers, so no two pairs of files give the same stream)."""
    digest = hashlib.sha256()
    for path in (toml_path, mjcf_path):
        data = Path(path).read_bytes()
        digest.update(len(data).to_bytes(8, "big"))
        digest.update(data)
    return digest.hexdigest()


def installed_robot_name(value: str, where: str) -> str:
    """``value`` (a robot named inside a data file, e.g. the ``robot`` field of robot.npz) when it
    names an installed robot (:func:`list_robots`); otherwise InputError naming ``where``.

    A data file may only NAME a robot: a path to a description in a data file would let the file
    choose its own limits. A description path is accepted only from the user (``--robot PATH``)."""
    text = str(value).strip()
    installed = list_robots()
    if text in installed:
        return text
    looks_like_path = any(c in text for c in "/\\") or text.endswith((".toml", ".xml"))
    why = "is a path, and a data file may only name an installed robot" if looks_like_path else "is not an installed robot"
    raise InputError(f"{where}: field 'robot' {text!r} {why} (installed: {', '.join(installed) or 'none'}, "
                     f"in {models_dir()}); pass --robot NAME or --robot PATH/TO/NAME.toml to choose one")


def load(name_or_path: str | os.PathLike) -> Robot:
    """Load a robot by name (``list_robots()``) or from a ``NAME.toml`` / ``NAME.xml`` path.

    Raises :class:`InputError` for an unknown robot (listing the known ones) or a bad description.
    """
    text = str(name_or_path)
    p = Path(text).expanduser()
    if p.suffix in (".toml", ".xml") or os.sep in text or p.is_file():
        toml = p.with_suffix(".toml")
        if not toml.is_file():
            raise InputError(f"robot description not found: {toml} (a robot is NAME.xml + NAME.toml)")
    else:
        toml = models_dir() / f"{text}.toml"
        if not toml.is_file():
            known = ", ".join(list_robots()) or "none"
            raise InputError(f"unknown robot {text!r}; known robots: {known} (in {models_dir()})")
    return Robot(parse_description(toml))
