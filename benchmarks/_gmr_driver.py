"""Run GMR (General Motion Retargeting) on one Bandai Namco BVH clip; for bench_gmr.py only.

Runs with the **GMR virtual environment's** python (mujoco, mink, daqp, numpy, scipy, rich), never
the project's, and imports nothing from the project. It imports GMR's retargeting class from an
extracted copy of its source (``--gmr-src``, the folder holding ``general_motion_retargeting/``)
without running that package's ``__init__`` (which pulls in the viewer). The leading underscore keeps ``bench_all.py``
from taking this helper for a benchmark.

What it does, as GMR's own ``scripts/bvh_to_robot.py`` does for LAFAN1 files, minus the viewer:

1. reads the BVH with GMR's reader (``utils/lafan_vendor``: ``read_bvh`` + ``quat_fk``) and
   converts every joint's global position and rotation to z-up metres with the matrix of GMR's
   ``utils/lafan1.load_lafan1_file`` (``(x, y, z) -> (x, -z, y)``, cm -> m);
2. **renames the Bandai joints to the LAFAN1 names** of GMR's ``ik_configs/bvh_to_*.json``
   (GMR's IK configs are used unchanged) and re-expresses each bone's rotation in the LAFAN1
   bone axes (below); ``LeftFootMod`` / ``RightFootMod`` = (foot position, toe rotation) as in
   GMR's loader;
3. builds ``GeneralMotionRetargeting(src_human="bvh", tgt_robot=..., actual_human_height=1.75)``
   (1.75 m: the value GMR's BVH loader passes for every file) and calls ``retarget(frame)`` for
   every frame at the file's 30 fps;
4. writes ``--out`` (.npz): ``qpos [T, nq]`` (GMR's robot model, MuJoCo order), ``joints`` (its
   hinge joints in qpos order), ``fps``, ``xml`` and CPU / wall seconds of loading the clip,
   building the retargeter and the per-frame solve loop; prints the same as one JSON line.

Bone axes. Both skeletons put a bone's local x axis along the bone, but they differ in the sign
on the right side and in the twist about the bone. In a standing pose (body facing +x, left
+y, up +z, arms hanging, legs straight) the local x, y, z axes point:

=================  =========================  =========================================
bone               Bandai (measured)          LAFAN1 (implied by GMR's offsets)
=================  =========================  =========================================
Hips               up, right, forward         up, forward, left
Chest -> Spine2    up, forward, left          up, forward, left
left leg bones     down, left, forward        down, forward, right
right leg bones    up, left, back             down, forward, right
left toes          forward, left, up          forward, up, right
right toes         back, left, down           forward, up, right
left arm bones     down, left, forward        down, back, left
right arm bones    up, left, back             down, back, left
=================  =========================  =========================================

The Bandai column was measured on the first frame of the standing clips
``dataset-1_respond_normal_001`` and ``dataset-1_bow_normal_001`` (each axis rounded to the
nearest body axis; hips, spine and legs within 17 degrees, arms and feet within 41 degrees,
the same on both clips). The LAFAN1 column is ``R_link(zero pose) * offset^-1`` of every entry
of GMR's ``bvh_to_g1.json``, ``bvh_to_t1.json`` and ``bvh_to_toddy.json`` on GMR's models at
the zero pose (all three agree; G1's zero pose holds the forearm forward and T1's holds the
arms out sideways, which are these axes turned with the limb). A Bandai rotation ``R_B`` is
passed to GMR as ``R_B @ C`` with ``C = M_B^T M_L`` (``M``: the table's axes as columns), the
LAFAN1-axes rotation of the same bone.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import types
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

ROBOTS = {"g1": "unitree_g1", "t1": "booster_t1", "toddlerbot": "stanford_toddy"}

# LAFAN1 name <- Bandai joint (positions); GMR's scale table uses these 14 plus the foot mods
RENAME = {
    "Hips": "Hips", "Spine2": "Chest", "Neck": "Neck", "Head": "Head",
    "LeftUpLeg": "UpperLeg_L", "LeftLeg": "LowerLeg_L", "LeftFoot": "Foot_L", "LeftToe": "Toes_L",
    "RightUpLeg": "UpperLeg_R", "RightLeg": "LowerLeg_R", "RightFoot": "Foot_R", "RightToe": "Toes_R",
    "LeftShoulder": "Shoulder_L", "LeftArm": "UpperArm_L", "LeftForeArm": "LowerArm_L", "LeftHand": "Hand_L",
    "RightShoulder": "Shoulder_R", "RightArm": "UpperArm_R", "RightForeArm": "LowerArm_R", "RightHand": "Hand_R",
}
_AXES = {"forward": (1, 0, 0), "back": (-1, 0, 0), "left": (0, 1, 0), "right": (0, -1, 0), "up": (0, 0, 1), "down": (0, 0, -1)}
# bone axes (local x, y, z) in the standing pose: Bandai, LAFAN1 (the table of the module doc)
_LEG = (("down", "left", "forward"), ("up", "left", "back"), ("down", "forward", "right"))
_ARM = (("down", "left", "forward"), ("up", "left", "back"), ("down", "back", "left"))
_TOE = (("forward", "left", "up"), ("back", "left", "down"), ("forward", "up", "right"))
AXES = {
    "Hips": (("up", "right", "forward"), ("up", "forward", "left")),
    "Spine2": (("up", "forward", "left"), ("up", "forward", "left")),
    **{f"{s}{b}": (_LEG[i], _LEG[2]) for i, s in enumerate(("Left", "Right")) for b in ("UpLeg", "Leg")},
    **{f"{s}{b}": (_ARM[i], _ARM[2]) for i, s in enumerate(("Left", "Right")) for b in ("Arm", "ForeArm", "Hand")},
    **{f"{s}Toe": (_TOE[i], _TOE[2]) for i, s in enumerate(("Left", "Right"))},
}
HUMAN_HEIGHT = 1.75  # what GMR's utils/lafan1.load_lafan1_file returns for every file


def axes_matrix(names) -> np.ndarray:
    return np.array([_AXES[n] for n in names], dtype=np.float64).T  # columns: local x, y, z


def conversion(bone: str) -> np.ndarray:
    """``C`` with ``R_lafan = R_bandai @ C`` for a LAFAN1 bone name (identity when not in AXES)."""
    if bone not in AXES:
        return np.eye(3)
    bandai, lafan = AXES[bone]
    return axes_matrix(bandai).T @ axes_matrix(lafan)


def import_gmr(src: Path):
    """GMR's ``GeneralMotionRetargeting`` class, its BVH reader and FK, from the extracted source."""
    src = Path(src).resolve()
    pkg = src / "general_motion_retargeting"
    if not pkg.is_dir():
        raise SystemExit(f"{pkg} not found (give --gmr-src, the folder holding general_motion_retargeting/)")
    for name, path in (("general_motion_retargeting", pkg), ("general_motion_retargeting.utils", pkg / "utils")):
        if name not in sys.modules:  # a bare package: skips __init__ (viewer, torch, smplx)
            mod = types.ModuleType(name)
            mod.__path__ = [str(path)]
            sys.modules[name] = mod
    from general_motion_retargeting.motion_retarget import GeneralMotionRetargeting
    from general_motion_retargeting.params import ROBOT_XML_DICT
    from general_motion_retargeting.utils.lafan_vendor import utils as lafan_utils
    from general_motion_retargeting.utils.lafan_vendor.extract import read_bvh

    return GeneralMotionRetargeting, ROBOT_XML_DICT, read_bvh, lafan_utils


def bandai_frames(path: Path, read_bvh, lafan_utils, max_frames: int | None = None,
                  convert_axes: bool = True) -> tuple[list[dict], float]:
    """GMR's per-frame human data ``{LAFAN1 name: (pos [3], quat wxyz [4])}`` from a Bandai BVH
    (``convert_axes=False``: renamed only, Bandai bone axes as they are; a diagnostic)."""
    from scipy.spatial.transform import Rotation as R

    anim = read_bvh(str(path))
    quats, pos = anim.quats, anim.pos
    if max_frames:
        quats, pos = quats[:max_frames], pos[:max_frames]
    grot, gpos = lafan_utils.quat_fk(quats, pos, anim.parents)
    M = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=np.float64)  # GMR's y-up -> z-up
    index = {b: i for i, b in enumerate(anim.bones)}
    missing = [b for b in RENAME.values() if b not in index]
    if missing:
        raise SystemExit(f"{path}: not a Bandai skeleton, joints missing: {missing}")
    T = len(gpos)
    frames = [dict() for _ in range(T)]
    for lafan, bandai in RENAME.items():
        i = index[bandai]
        p = gpos[:, i] @ M.T / 100.0
        C = conversion(lafan) if convert_axes else np.eye(3)
        rot = R.from_matrix(M) * R.from_quat(grot[:, i], scalar_first=True) * R.from_matrix(C)
        q = rot.as_quat(scalar_first=True)
        for t in range(T):
            frames[t][lafan] = (p[t], q[t])
    for t in range(T):
        for side in ("Left", "Right"):
            frames[t][f"{side}FootMod"] = (frames[t][f"{side}Foot"][0], frames[t][f"{side}Toe"][1])
    # frame time from the header (GMR's script assumes 30 fps; Bandai files are 30 fps)
    fps = 30.0
    with open(path, errors="replace") as f:
        for line in f:
            if line.strip().startswith("Frame Time:"):
                fps = round(1.0 / float(line.split(":", 1)[1]), 3)
                break
    return frames, fps


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="GMR on one Bandai BVH clip -> robot qpos per frame (.npz)")
    ap.add_argument("--gmr-src", type=Path, required=True, help="folder holding general_motion_retargeting/ (extracted archive)")
    ap.add_argument("--robot", required=True, help=f"GMR robot name or one of {sorted(ROBOTS)}")
    ap.add_argument("--bvh", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--max-seconds", type=float, default=None, help="use only the first seconds of the clip")
    ap.add_argument("--no-axis-conversion", action="store_true", help="rename the joints only (diagnostic)")
    args = ap.parse_args(argv)

    w0, c0 = time.perf_counter(), time.process_time()
    GMR, xml_dict, read_bvh, lafan_utils = import_gmr(args.gmr_src)
    import_wall, import_cpu = time.perf_counter() - w0, time.process_time() - c0

    robot = ROBOTS.get(args.robot, args.robot)
    w0, c0 = time.perf_counter(), time.process_time()
    frames, fps = bandai_frames(args.bvh, read_bvh, lafan_utils, convert_axes=not args.no_axis_conversion)
    if args.max_seconds:
        frames = frames[: max(2, int(round(args.max_seconds * fps)))]
    load_wall, load_cpu = time.perf_counter() - w0, time.process_time() - c0

    w0, c0 = time.perf_counter(), time.process_time()
    retargeter = GMR(src_human="bvh", tgt_robot=robot, actual_human_height=HUMAN_HEIGHT)
    init_wall, init_cpu = time.perf_counter() - w0, time.process_time() - c0

    w0, c0 = time.perf_counter(), time.process_time()
    qpos = np.stack([retargeter.retarget(f) for f in frames])
    solve_wall, solve_cpu = time.perf_counter() - w0, time.process_time() - c0

    model = retargeter.model
    joints = [model.joint(j).name for j in range(model.njnt) if model.jnt_type[j] != 0]
    summary = {
        "robot": robot, "frames": len(qpos), "fps": fps, "seconds": len(qpos) / fps, "xml": str(retargeter.xml_file),
        "import_wall_s": import_wall, "import_cpu_s": import_cpu, "load_wall_s": load_wall, "load_cpu_s": load_cpu,
        "init_wall_s": init_wall, "init_cpu_s": init_cpu, "solve_wall_s": solve_wall, "solve_cpu_s": solve_cpu,
        "human_height": HUMAN_HEIGHT,
        "joint_map": "Bandai joints renamed to LAFAN1 names, " + ("bone axes converted" if not args.no_axis_conversion else
                                                                  "bone axes NOT converted (diagnostic)") + "; GMR's bvh IK config unchanged",
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    np.savez(args.out, qpos=qpos, joints=np.array(joints), fps=fps, summary=json.dumps(summary))
    print(json.dumps(summary), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
