"""Files in and out of retargeting.

Input: ``motion.npz`` from generation (``joints`` float32 ``[T, 22, 3]`` metres z-up, ``fps``),
or a mocap file imported with :mod:`motok_robot.data` (BVH, ASF+AMC, DeepMimic JSON in a
``.json`` or ``.txt`` file).

Output: ``robot.npz`` exactly as in docs/CONTRACTS.md::

    qpos            float64 [T, nq]   MuJoCo order: free base pos (m), quat w x y z, joints (rad)
    joint_names     str [nj]          actuated joints, qpos order
    robot           str               robot name
    fps             float             frames per second
    contacts        bool [T, 2]       foot contact (left, right) detected on the human motion
    keypoint_error  float64 [T, K]    metres between robot keypoint site and scaled human joint
    keypoint_names  str [K]           the human joint of each keypoint
    source          float32 [T, 22, 3] human joints as given (metres, z up)
    solver_status   str (JSON)        per window: start, stop, status, success, iterations,
                                      violated (constraint or null), violation, seconds
    retime_factor   float             how many times slower than the human motion the
                                      trajectory plays (1.0 as retargeted; retarget.retime)
    collision_pairs str [n]           "geom1|geom2" pairs that came close and were kept apart
                                      by self-collision rows (retarget.collision; absent = none)

Written by the feasibility stage (``motok_robot.feasibility``; absent in retargeting's output)::

    reference_qpos  float64 [T, nq]   the kinematic trajectory the robot was asked to perform;
                                      ``qpos`` is then what it executed in physics
    initial_qvel    float64 [nv]      the velocity the executed rollout started from
    task_qpos       float64 [T, nq]   what the stage commanded the servos to follow: the
                                      reference with the stage's changes (its CoM path, or its
                                      own steps for a walk); validation's ``tracking`` uses it
    feasibility     str (JSON)        what the stage changed (docs/feasibility.md)
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.limits import check_frames, check_rate, check_seconds
from motok_robot.npz_files import check_npz_sizes, read_npz_fields, reject_complex, scalar_field

MOCAP_SUFFIXES = (".bvh", ".amc", ".json", ".txt")


@dataclass
class HumanMotion:
    """A human motion to retarget: ``joints[T, 22, 3]`` (m, z up) at ``fps``; ``name`` for messages."""

    joints: np.ndarray
    fps: float
    name: str


def read_motion_npz(path: str | Path) -> HumanMotion:
    """Read ``joints`` and ``fps`` from a generation ``motion.npz``."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: file not found")
    data = read_npz_fields(path, "motion file")
    if "joints" not in data:
        raise InputError(f"{path}: no 'joints' array (fields: {', '.join(data) or 'none'})")
    joints = np.asarray(data["joints"])
    if joints.ndim != 3 or joints.shape[1:] != (22, 3) or joints.shape[0] < 1 or joints.dtype.kind not in "fiu":
        raise InputError(f"{path}: field 'joints' must be a number array [T, 22, 3] (metres, z up), got shape "
                         f"{joints.shape} ({joints.dtype})")
    bad = ~np.isfinite(joints)
    if bad.any():
        from motok_robot.motion.skeleton import JOINT_NAMES

        frame, joint, _ = np.argwhere(bad)[0]
        raise InputError(f"{path}: field 'joints' is not finite (NaN or inf) at frame {frame}, joint "
                         f"{JOINT_NAMES[joint]}: fix the file")
    fps = scalar_field(data, "fps", path) if "fps" in data else 20.0
    check_rate(fps, str(path), "field 'fps'")
    check_frames(joints.shape[0], str(path), "field 'joints' frames")
    check_seconds((joints.shape[0] - 1) / fps, str(path), "the duration (joints frames / fps)")
    return HumanMotion(joints=joints, fps=fps, name=str(path))


def read_mocap(path: str | Path, skeleton: str = "bandai", asf: str | Path | None = None, amc_fps: float = 120.0) -> HumanMotion:
    """Import a mocap file onto the canonical body (20 fps) with :mod:`motok_robot.data`.

    ``.bvh``: ``skeleton`` is ``bandai``, ``acrnn`` or a joint-map JSON path; ``.amc``: the
    skeleton file is ``asf`` or the only ``.asf`` next to it; ``.json`` / ``.txt``: DeepMimic motion.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: file not found")
    suffix = path.suffix.lower()
    try:
        if suffix == ".bvh":
            from motok_robot.data.bvh import load_clip

            clip = load_clip(path, skeleton=skeleton)
        elif suffix == ".amc":
            from motok_robot.data.asf_amc import load_clip

            if asf is None:
                from motok_robot.data.sources import skeleton_for

                candidates = {p.stem: p for p in sorted(path.parent.glob("*.asf"))}
                stem = skeleton_for(path.stem, candidates)
                if stem is None:
                    raise InputError(f"{path}: give the skeleton file with --asf ({len(candidates)} .asf files next to "
                                     "it, none whose name is a prefix of its own)")
                asf = candidates[stem]
            clip = load_clip(asf, path, fps=amc_fps)
        elif suffix in (".json", ".txt"):
            from motok_robot.data.deepmimic import load_clip

            clip = load_clip(path)
        else:
            raise InputError(f"{path}: unknown input type {suffix!r} (motion.npz, .bvh, .amc, DeepMimic .json/.txt)")
    except InputError:
        raise
    except (OSError, UnicodeDecodeError, ValueError, KeyError, IndexError) as exc:
        raise InputError(f"{path}: cannot import ({type(exc).__name__}: {exc})") from None
    return HumanMotion(joints=np.asarray(clip.joints), fps=float(clip.fps), name=str(path))


def read_input(path: str | Path, skeleton: str = "bandai", asf: str | Path | None = None) -> HumanMotion:
    """``motion.npz`` or a mocap file, by suffix."""
    p = Path(path)
    if p.suffix.lower() == ".npz":
        return read_motion_npz(p)
    return read_mocap(p, skeleton=skeleton, asf=asf)


def write_robot_npz(path: str | Path, result) -> Path:
    """Write a :class:`retarget.solve.RetargetResult` or a :class:`RobotTrajectory` as
    ``robot.npz`` (see module doc)."""
    path = Path(path)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    status = result.solver_status() if callable(result.solver_status) else result.solver_status
    np.savez(
        path,
        qpos=np.asarray(result.qpos, dtype=np.float64),
        joint_names=np.array(result.joint_names, dtype=str),
        robot=np.array(result.robot),
        fps=np.array(float(result.fps)),
        contacts=np.asarray(result.contacts, dtype=bool),
        keypoint_error=np.asarray(result.keypoint_error, dtype=np.float64),
        keypoint_names=np.array(result.keypoint_names, dtype=str),
        source=np.asarray(result.source, dtype=np.float32),
        solver_status=np.array(json.dumps(status)),
        retime_factor=np.array(float(getattr(result, "retime_factor", 1.0))),
        collision_pairs=np.array(list(result.collision_pairs), dtype=str).reshape(-1),
        **_feasibility_fields(result),
    )
    return path


def _feasibility_fields(result) -> dict:
    """The feasibility stage's optional fields of ``result`` (empty for a retargeting result)."""
    out = {}
    if getattr(result, "reference_qpos", None) is not None:
        out["reference_qpos"] = np.asarray(result.reference_qpos, dtype=np.float64)
    if getattr(result, "initial_qvel", None) is not None:
        out["initial_qvel"] = np.asarray(result.initial_qvel, dtype=np.float64)
    if getattr(result, "task_qpos", None) is not None:
        out["task_qpos"] = np.asarray(result.task_qpos, dtype=np.float64)
    if getattr(result, "feasibility", None) is not None:
        out["feasibility"] = np.array(json.dumps(result.feasibility))
    return out


@dataclass
class RobotTrajectory:
    """Contents of a ``robot.npz`` (see module doc for axes and units)."""

    qpos: np.ndarray
    joint_names: list[str]
    robot: str
    fps: float
    contacts: np.ndarray
    keypoint_error: np.ndarray
    keypoint_names: list[str]
    source: np.ndarray
    solver_status: list[dict]
    retime_factor: float = 1.0
    collision_pairs: list[str] = field(default_factory=list)  # geom pairs retargeting kept apart
    reference_qpos: np.ndarray | None = None  # [T, nq] the kinematic trajectory (feasibility output only)
    initial_qvel: np.ndarray | None = None    # [nv] start velocity of the executed rollout
    task_qpos: np.ndarray | None = None       # [T, nq] what the servos were commanded to follow (feasibility output only)
    feasibility: dict | None = None           # what the feasibility stage changed


ROBOT_NPZ_FIELDS = ("qpos", "joint_names", "robot", "fps", "contacts", "keypoint_error", "keypoint_names", "source", "solver_status")


def read_robot_npz(path: str | Path) -> RobotTrajectory:
    """Read and check a ``robot.npz``."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: file not found")
    check_npz_sizes(path, "robot.npz")
    try:
        with np.load(path, allow_pickle=False) as d:
            missing = [f for f in ROBOT_NPZ_FIELDS if f not in d.files]
            if missing:
                raise InputError(f"{path}: not a robot.npz, missing {', '.join(missing)}")
            reject_complex({f: d[f] for f in ("qpos", "keypoint_error", "source")}, path)
            out = RobotTrajectory(
                qpos=np.asarray(d["qpos"], dtype=np.float64),
                joint_names=[str(n) for n in d["joint_names"]],
                robot=str(d["robot"]),
                fps=float(d["fps"]),
                contacts=np.asarray(d["contacts"], dtype=bool),
                keypoint_error=np.asarray(d["keypoint_error"]),
                keypoint_names=[str(n) for n in d["keypoint_names"]],
                source=np.asarray(d["source"]),
                solver_status=json.loads(str(d["solver_status"])),
                retime_factor=float(d["retime_factor"]) if "retime_factor" in d.files else 1.0,
                collision_pairs=[str(n) for n in d["collision_pairs"]] if "collision_pairs" in d.files else [],
                reference_qpos=np.asarray(d["reference_qpos"], dtype=np.float64) if "reference_qpos" in d.files else None,
                initial_qvel=np.asarray(d["initial_qvel"], dtype=np.float64) if "initial_qvel" in d.files else None,
                task_qpos=np.asarray(d["task_qpos"], dtype=np.float64) if "task_qpos" in d.files else None,
                feasibility=json.loads(str(d["feasibility"])) if "feasibility" in d.files else None,
            )
    except InputError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise InputError(f"{path}: cannot read as .npz ({exc})") from None
    T = out.qpos.shape[0]
    if out.qpos.ndim != 2 or out.contacts.shape != (T, 2) or out.keypoint_error.shape[0] != T:
        raise InputError(f"{path}: inconsistent shapes qpos {out.qpos.shape}, contacts {out.contacts.shape}, keypoint_error {out.keypoint_error.shape}")
    for name in ("reference_qpos", "task_qpos"):
        value = getattr(out, name)
        if value is not None and value.shape != out.qpos.shape:
            raise InputError(f"{path}: field '{name}' has shape {value.shape}, 'qpos' {out.qpos.shape}")
    check_retime_factor(out.retime_factor, path)
    return out


def check_retime_factor(value: float, where) -> float:
    """``value`` (robot.npz ``retime_factor``) when it is a positive number; InputError naming
    ``where`` (the file) and the field otherwise."""
    if not (np.isfinite(value) and value > 0):
        raise InputError(f"{where}: field 'retime_factor' must be a positive number (times slower than the source), "
                         f"got {value!r}")
    return float(value)
