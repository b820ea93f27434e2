"""Retargeting side by side with GMR (General Motion Retargeting) on the same BVH clips and robots.

Issues 44 and 45. For each robot (G1, T1, ToddlerBot) and Bandai Namco clip (default: a walk,
a kick and a dance), this project's retargeting (``retarget.solve.Retargeter`` with the
default ``RetargetConfig``: windowed trajectory optimisation, contacts and self-collision on;
what ``motok-robot retarget`` runs) and GMR (per-frame differential IK with mink + daqp, its
``bvh_to_*.json`` IK configs) run **alternately in one process tree**, each repetition in a
fresh process per method, and their outputs are measured by **the same code**
(``benchmarks/_gmr_quality.py``, whose docstring defines every measure):

* speed: seconds of motion per CPU second, both *solve only* (CPU time of the solve loop,
  reported by the worker: ``Retargeter.run`` for ours; the ``retarget(frame)`` loop for GMR;
  problem construction / model loading excluded) and *fresh process* (user + system CPU of the
  whole worker process: interpreter start, imports, clip reading, construction, solve, writing);
  the median over ``--repeat`` alternating repetitions (odd ones run GMR first), and the ratio
  GMR / ours as the median of the per-repetition ratios (only ratios mean much on a loaded
  machine);
* quality: frames with any geom > 1 cm below the floor, foot slip while in contact (summed and
  worst frame), joint-limit violation frames, self-collision frames, keypoint error, largest base
  turn between consecutive frames.

**Models.** G1 and T1: GMR's qpos is copied onto this project's MJCF (``models/mjcf/g1.xml``,
``t1.xml``) by joint name (every GMR joint exists there under the same name; T1's two head
joints, absent from GMR's model, stay at 0), so both outputs are measured on one model and
against one set of joint ranges; the JSON's ``mapping_residual_m`` is the largest distance
between same-named bodies posed by GMR on its own model and by the copy on ours. ToddlerBot:
GMR's ``toddy_mocap.xml`` is another revision (other joint names, 22 instead of 30 joints,
other link lengths), so each output is measured **on its own model** (GMR's joint ranges for
GMR). Keypoints are joint anchors (hip roll, knee, ankle pitch, shoulder roll, elbow of each
side) on every model.

**Human joints for GMR.** GMR reads LAFAN1-named BVH files; ``_gmr_driver.py`` renames the
Bandai joints to those names and converts the bone axes (its docstring has the table), and
uses GMR's IK configs unchanged (``"gmr_joint_map"`` in the JSON). GMR runs at the file's
30 fps, ours at the project's 20 fps (the same seconds of motion; per-frame measures are
per each method's own frames, turns also per second).

Setup (once; GMR is never a dependency of the project)::

    python3 -m venv ../gmr_venv
    ../gmr_venv/bin/pip install mujoco mink daqp numpy scipy loop_rate_limiters rich

Usage::

    python benchmarks/bench_gmr.py [--robots g1 t1 toddlerbot] [--clips 'dataset-1_walk_normal_001' ...]
                                   [--max-seconds S] [--repeat 3] [--gmr-python ../gmr_venv/bin/python]
                                   [--out benchmarks/results/bench_gmr.json]

Reads ``../shared/datasets/bandai-namco-bvh.tar.xz`` and ``../shared/peers/gmr.tar.xz``
(extracted to a scratch folder under the system temp dir, never into the repository); skips
with one line (exit 0) when either or the GMR environment is missing. Single-threaded.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import os
import resource
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
import traceback
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))
SHARED = REPO.parent / "shared"
BANDAI = SHARED / "datasets" / "bandai-namco-bvh.tar.xz"
GMR_ARCHIVE = SHARED / "peers" / "gmr.tar.xz"
GMR_VENV_PYTHON = REPO.parent / "gmr_venv" / "bin" / "python"
SCRATCH = Path(tempfile.gettempdir()) / "motok_bench_gmr"
DEFAULT_CLIPS = ["dataset-1_walk_normal_001", "dataset-1_kick_normal_001", "dataset-1_dance-short_normal_001"]
DEFAULT_ROBOTS = ["g1", "t1", "toddlerbot"]
GMR_NAMES = {"g1": "unitree_g1", "t1": "booster_t1", "toddlerbot": "stanford_toddy"}
GMR_XML = {"g1": "assets/unitree_g1/g1_mocap_29dof.xml", "t1": "assets/booster_t1/t1_mocap.xml",
           "toddlerbot": "assets/stanford_toddy/toddy_mocap.xml"}
SETUP = "python3 -m venv ../gmr_venv && ../gmr_venv/bin/pip install mujoco mink daqp numpy scipy loop_rate_limiters rich"

# per robot and model: (feet bodies, keypoint joints as (human joint, joint name)); "ours" = models/mjcf
_SIDES = ("left", "right")


def _kp(fmt: dict) -> list[tuple[str, str]]:
    out = []
    for part in ("hip", "knee", "ankle", "shoulder", "elbow"):
        for side in _SIDES:
            out.append((f"{side}_{part}", fmt[part].format(side=side, Side=side.capitalize())))
    return out


MEASURE = {
    ("g1", "ours"): ({"left": "left_ankle_roll_link", "right": "right_ankle_roll_link"},
                     _kp({"hip": "{side}_hip_roll_joint", "knee": "{side}_knee_joint", "ankle": "{side}_ankle_pitch_joint",
                          "shoulder": "{side}_shoulder_roll_joint", "elbow": "{side}_elbow_joint"})),
    ("t1", "ours"): ({"left": "left_foot_link", "right": "right_foot_link"},
                     _kp({"hip": "{Side}_Hip_Roll", "knee": "{Side}_Knee_Pitch", "ankle": "{Side}_Ankle_Pitch",
                          "shoulder": "{Side}_Shoulder_Roll", "elbow": "{Side}_Elbow_Pitch"})),
    ("toddlerbot", "ours"): ({"left": "left_ankle_roll_link", "right": "right_ankle_roll_link"},
                             _kp({"hip": "{side}_hip_roll", "knee": "{side}_knee", "ankle": "{side}_ankle_pitch",
                                  "shoulder": "{side}_shoulder_roll", "elbow": "{side}_elbow_roll"})),
    ("toddlerbot", "gmr"): ({"left": "ank_roll_link", "right": "ank_roll_link_2"},
                            _kp({"hip": "{side}_hip_roll", "knee": "{side}_knee", "ankle": "{side}_ank_pitch",
                                 "shoulder": "{side}_sho_roll", "elbow": "{side}_elbow_roll"})),
}
OWN_MODEL = {"toddlerbot"}  # GMR's output measured on GMR's model (see the module doc)


def say(msg: str) -> None:
    print(msg, flush=True)


# -- inputs -----------------------------------------------------------------------------------------------
def extract_gmr(scratch: Path) -> Path:
    """GMR's source folder (``gmr/``) under ``scratch``, extracted from the archive when absent."""
    root = scratch / "gmr_src"
    src = root / "gmr"
    if not (src / "general_motion_retargeting" / "motion_retarget.py").exists():
        root.mkdir(parents=True, exist_ok=True)
        say(f"extracting {GMR_ARCHIVE.name} to {root}")
        with tarfile.open(GMR_ARCHIVE) as tar:
            tar.extractall(root, filter="data")
    return src


def extract_clips(patterns: list[str], scratch: Path) -> list[Path]:
    """BVH files whose stem matches any glob in ``patterns``, extracted to ``scratch/clips``."""
    out_dir = scratch / "clips"
    out_dir.mkdir(parents=True, exist_ok=True)
    have = {p.stem: p for p in out_dir.glob("*.bvh")}
    wanted = [p for p in patterns if not any(ch in p for ch in "*?[")]
    if wanted and all(w in have for w in wanted) and len(wanted) == len(patterns):
        return [have[w] for w in wanted]
    found = []
    with tarfile.open(BANDAI) as tar:
        for m in tar:
            stem = Path(m.name).stem
            if m.isfile() and m.name.endswith(".bvh") and any(fnmatch.fnmatch(stem, p) for p in patterns):
                dst = out_dir / Path(m.name).name
                if not dst.exists():
                    dst.write_bytes(tar.extractfile(m).read())
                found.append(dst)
    order = {p: i for i, p in enumerate(patterns)}
    return sorted(found, key=lambda p: (min(order.get(q, 99) for q in patterns if fnmatch.fnmatch(p.stem, q)), p.name))


def human_joints(bvh: Path) -> dict:
    """Canonical joints of a Bandai clip: ``{"ours": [T20, 22, 3]`` in the project frame at 20 fps
    (what ``read_input`` gives the retargeter), ``"gmr": [T30, 22, 3]`` in GMR's z-up frame at the
    file's rate, ``"fps_file"``}."""
    import numpy as np

    from motok_robot.data.bvh import BANDAI_MAP, BANDAI_UNITS_TO_M, BANDAI_UP, forward_kinematics, read_bvh
    from motok_robot.data.clip import apply_joint_map, snap_fps, to_project_frame, zup_rotation
    from motok_robot.motion.features import resample

    motion = read_bvh(bvh)
    joints, _ = apply_joint_map(forward_kinematics(motion), BANDAI_MAP, str(bvh))
    ours = resample(to_project_frame(joints, BANDAI_UNITS_TO_M, zup_rotation(BANDAI_UP)), snap_fps(motion.fps))
    gmr = to_project_frame(joints, 0.01, np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]))
    return {"ours": ours, "gmr": gmr, "fps_file": snap_fps(motion.fps)}


# -- our worker (a fresh process per run, like the GMR driver) -------------------------------------------
def worker_ours(robot_name: str, bvh: Path, out: Path, max_seconds: float | None) -> int:
    import numpy as np

    w0, c0 = time.perf_counter(), time.process_time()
    from retarget.config import RetargetConfig
    from retarget.io import read_input
    from retarget.robot_model import load_robot
    from retarget.solve import Retargeter

    import_wall, import_cpu = time.perf_counter() - w0, time.process_time() - c0
    w0, c0 = time.perf_counter(), time.process_time()
    motion = read_input(str(bvh), skeleton="bandai")
    joints = np.asarray(motion.joints, dtype=np.float64)
    if max_seconds:
        joints = joints[: max(2, int(round(max_seconds * motion.fps)))]
    load_wall, load_cpu = time.perf_counter() - w0, time.process_time() - c0
    w0, c0 = time.perf_counter(), time.process_time()
    robot = load_robot(robot_name)
    rt = Retargeter(robot, RetargetConfig())
    rt.prepare(len(joints))
    cache = [p.cache_status for p in rt._problems.values()]
    init_wall, init_cpu = time.perf_counter() - w0, time.process_time() - c0
    w0, c0 = time.perf_counter(), time.process_time()
    res = rt.run(joints, motion.fps, progress=False)
    solve_wall, solve_cpu = time.perf_counter() - w0, time.process_time() - c0
    summary = {
        "robot": robot_name, "frames": len(joints), "fps": float(motion.fps), "seconds": len(joints) / float(motion.fps),
        "import_wall_s": import_wall, "import_cpu_s": import_cpu, "load_wall_s": load_wall, "load_cpu_s": load_cpu,
        "init_wall_s": init_wall, "init_cpu_s": init_cpu, "solve_wall_s": solve_wall, "solve_cpu_s": solve_cpu,
        "windows": len(res.windows), "failed_windows": len(res.failed_windows()), "collision_rounds": res.collision_rounds,
        "collision_pairs": res.collision_pairs, "cache": cache,
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    names = [robot.model.joint(j).name for j in range(robot.model.njnt) if robot.model.jnt_type[j] != 0]
    np.savez(out, qpos=res.qpos, joints=np.array(names), fps=float(motion.fps), summary=json.dumps(summary))
    print(json.dumps(summary), flush=True)
    return 0


# -- running --------------------------------------------------------------------------------------------
def run_process(cmd: list[str], timeout: float) -> dict:
    """Run ``cmd``; wall seconds, user + system CPU of the process tree, the JSON line it printed."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    w0 = time.perf_counter()
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=REPO)
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout:g} s"}
    wall = time.perf_counter() - w0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if done.returncode != 0:
        tail = (done.stderr or done.stdout).strip().splitlines()[-6:]
        return {"error": f"exit {done.returncode}: " + " | ".join(tail), "process_wall_s": wall, "process_cpu_s": cpu}
    line = [ln for ln in done.stdout.splitlines() if ln.startswith("{")]
    info = json.loads(line[-1]) if line else {}
    return info | {"process_wall_s": wall, "process_cpu_s": cpu}


def wait_for_compiles(limit: float = 900.0) -> float:
    """Wait while the retargeting cache's background compiler holds its lock; seconds waited."""
    from retarget.cache import COMPILE_LOCK, ProblemCache

    cache = ProblemCache.from_env()
    if cache is None:
        return 0.0
    lock = Path(cache.folder) / COMPILE_LOCK
    t0 = time.perf_counter()
    while lock.exists() and time.perf_counter() - t0 < limit:
        time.sleep(2.0)
    return time.perf_counter() - t0


# -- measuring ------------------------------------------------------------------------------------------
def measure_spec(robot: str, which: str):
    from _gmr_quality import Keypoint, MeasureSpec

    from motok_robot.motion.skeleton import JOINT_NAMES

    feet, kps = MEASURE[(robot, which)]
    keypoints = [Keypoint(JOINT_NAMES.index(h), "joint", j) for h, j in kps]
    names = [h for h, _ in kps]
    idx = {h: i for i, h in enumerate(names)}
    legs = tuple((idx[f"{s}_hip"], idx[f"{s}_knee"], idx[f"{s}_ankle"]) for s in _SIDES)
    return MeasureSpec(feet=feet, keypoints=keypoints, hips=(idx["left_hip"], idx["right_hip"]), legs=legs)


def load_models(robot: str, gmr_src: Path) -> dict:
    import mujoco

    from motok_robot.robots import load

    ours = load(robot).model
    gmr = mujoco.MjModel.from_xml_path(str(gmr_src / GMR_XML[robot]))
    return {"ours": ours, "gmr": gmr}


def gmr_on_ours(robot: str, npz: dict, models: dict) -> tuple:
    """GMR's qpos copied onto our model by joint name; (qpos, joints left at 0, residual m)."""
    import mujoco
    import numpy as np

    from _gmr_quality import map_qpos

    qpos = np.asarray(npz["qpos"])
    mapped, missing = map_qpos(qpos, [str(j) for j in npz["joints"]], models["ours"])
    a, b = models["gmr"], models["ours"]
    shared = [(i, mujoco.mj_name2id(b, mujoco.mjtObj.mjOBJ_BODY, a.body(i).name)) for i in range(1, a.nbody)]
    da, db = mujoco.MjData(a), mujoco.MjData(b)
    # compare the same-named bodies that coincide at the zero pose (T1's hand bodies do not: GMR's
    # model extends the forearm with three more bodies)
    da.qpos[:], db.qpos[:] = 0.0, 0.0
    da.qpos[3] = db.qpos[3] = 1.0
    mujoco.mj_kinematics(a, da)
    mujoco.mj_kinematics(b, db)
    shared = [(i, j) for i, j in shared if j > 0 and np.linalg.norm(da.xpos[i] - db.xpos[j]) < 1e-3]
    worst = 0.0
    for t in range(0, len(qpos), max(1, len(qpos) // 50)):
        da.qpos[:], db.qpos[:] = qpos[t], mapped[t]
        mujoco.mj_kinematics(a, da)
        mujoco.mj_kinematics(b, db)
        worst = max(worst, max(float(np.linalg.norm(da.xpos[i] - db.xpos[j])) for i, j in shared))
    return mapped, missing, worst, len(shared)


def quality(robot: str, method: str, npz: dict, human: dict, models: dict) -> dict:
    import numpy as np

    from _gmr_quality import leg_scale, measure

    qpos = np.asarray(npz["qpos"])
    fps = float(npz["fps"])
    extra = {}
    if method == "gmr" and robot not in OWN_MODEL:
        qpos, missing, residual, nshared = gmr_on_ours(robot, npz, models)
        which, model = "ours", models["ours"]
        extra = {"measured_on": f"models/mjcf/{robot}.xml (GMR qpos mapped by joint name)", "joints_not_in_gmr": missing,
                 "mapping_residual_m": residual, "mapping_bodies_compared": nshared,
                 "joint_limit_frames_gmr_model": limit_frames(models["gmr"], np.asarray(npz["qpos"]))}
    elif method == "gmr":
        which, model = "gmr", models["gmr"]
        extra = {"measured_on": f"GMR's {GMR_XML[robot]} (own model)"}
    else:
        which, model = "ours", models["ours"]
        extra = {"measured_on": f"models/mjcf/{robot}.xml"}
    full = human["gmr" if method == "gmr" else "ours"]
    h = full[: len(qpos)]
    spec = measure_spec(robot, which)
    # one scale factor per clip and model: from the clip's full human motion
    s = leg_scale(model, spec, full)
    return measure(model, qpos, fps, spec, human=h, scale=s, stance=human_stance(h, fps)) | extra


def limit_frames(model, qpos, tol: float = 1e-3) -> int:
    """Frames with a limited hinge / slide joint of ``model`` outside its range by more than ``tol``."""
    import numpy as np

    js = [j for j in range(model.njnt) if model.jnt_type[j] in (2, 3) and model.jnt_limited[j]]
    q = np.asarray(qpos)[:, [model.jnt_qposadr[j] for j in js]]
    r = np.array([model.jnt_range[j] for j in js])
    return int(((q < r[:, 0] - tol) | (q > r[:, 1] + tol)).any(axis=1).sum())


def human_stance(joints, fps: float):
    """The human's planted feet ``[T, 2]`` (left, right): the project's contact detector
    (``retarget.contacts.detect_contacts``, thresholds scaled by leg length), the same for both methods."""
    import numpy as np

    from retarget.config import ContactConfig
    from retarget.contacts import detect_contacts
    from retarget.solve import scaled_contact_config

    j = np.asarray(joints, dtype=np.float64)
    return np.asarray(detect_contacts(j, fps, scaled_contact_config(j, ContactConfig())), dtype=bool)


# -- main -----------------------------------------------------------------------------------------------
def median(xs):
    xs = [x for x in xs if x is not None]
    return statistics.median(xs) if xs else None


def summarise_speed(runs: list[dict]) -> dict:
    ok = [r for r in runs if "error" not in r]
    if not ok:
        return {"error": runs[-1].get("error") if runs else "no runs"}
    sec = ok[0]["seconds"]
    return {
        "repeats": len(ok), "motion_seconds": sec,
        "solve_cpu_s_median": median([r["solve_cpu_s"] for r in ok]),
        "process_cpu_s_median": median([r["process_cpu_s"] for r in ok]),
        "process_wall_s_median": median([r["process_wall_s"] for r in ok]),
        "speed_solve": median([sec / r["solve_cpu_s"] for r in ok]),
        "speed_process": median([sec / r["process_cpu_s"] for r in ok]),
        "fps_solve_cpu": median([r["frames"] / r["solve_cpu_s"] for r in ok]),
        "runs": ok,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", nargs="+", default=DEFAULT_ROBOTS, choices=DEFAULT_ROBOTS)
    ap.add_argument("--clips", nargs="+", default=DEFAULT_CLIPS, help="BVH file stems or globs (default: walk, kick, dance)")
    ap.add_argument("--max-seconds", type=float, default=None, help="cut every clip to its first S seconds")
    ap.add_argument("--repeat", type=int, default=3, help="alternating timed repetitions per clip and robot (default 3)")
    ap.add_argument("--gmr-python", type=Path, default=GMR_VENV_PYTHON, help="python of the GMR environment")
    ap.add_argument("--scratch", type=Path, default=SCRATCH, help="where the archives are extracted")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per worker process")
    ap.add_argument("--out", type=Path, default=HERE / "results" / "bench_gmr.json")
    ap.add_argument("--worker-ours", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--robot", help=argparse.SUPPRESS)
    ap.add_argument("--bvh", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--npz", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args.worker_ours:
        sys.path.insert(0, str(REPO))
        return worker_ours(args.robot, args.bvh, args.npz, args.max_seconds)

    if not BANDAI.exists() or not GMR_ARCHIVE.exists():
        say(f"bench_gmr: skipped: {BANDAI if not BANDAI.exists() else GMR_ARCHIVE} not found (../shared)")
        return 0
    gmr_python = Path(os.path.abspath(args.gmr_python))  # not resolved: a venv's python is a symlink
    probe = subprocess.run([str(gmr_python), "-c", "import mink, daqp, mujoco, scipy, rich"], capture_output=True, text=True) \
        if gmr_python.exists() else None
    if probe is None or probe.returncode != 0:
        say(f"bench_gmr: skipped: no GMR environment at {gmr_python} (create it: {SETUP})")
        return 0

    import numpy as np

    from common import machine_description, markdown_table, write_json

    t_start = time.perf_counter()
    gmr_src = extract_gmr(args.scratch)
    clips = extract_clips(args.clips, args.scratch)
    if not clips:
        say(f"bench_gmr: no clip in {BANDAI.name} matches {args.clips}")
        return 1
    say(f"bench_gmr: {len(clips)} clip(s) ({', '.join(c.stem for c in clips)}), robots {', '.join(args.robots)}, "
        f"{args.repeat} alternating repetitions; GMR from {gmr_src}")
    humans = {c.stem: human_joints(c) for c in clips}
    runs_dir = args.scratch / "runs"
    cut = ["--max-seconds", str(args.max_seconds)] if args.max_seconds else []

    def cmd(method: str, robot: str, clip: Path, out: Path) -> list[str]:
        if method == "ours":
            return [sys.executable, str(HERE / "bench_gmr.py"), "--worker-ours", "--robot", robot, "--bvh", str(clip),
                    "--npz", str(out), *cut]
        return [str(gmr_python), str(HERE / "_gmr_driver.py"), "--gmr-src", str(gmr_src), "--robot", GMR_NAMES[robot],
                "--bvh", str(clip), "--out", str(out), *cut]

    rows, report_rows = [], []
    for robot in args.robots:
        try:
            models = load_models(robot, gmr_src)
        except Exception as exc:  # noqa: BLE001 - recorded in the row
            for clip in clips:
                report_rows.append({"robot": robot, "clip": clip.stem, "error": f"models: {exc}"})
            continue
        for clip in clips:
            entry = {"robot": robot, "clip": clip.stem, "ours": {}, "gmr": {}}
            outs = {m: runs_dir / f"{robot}_{clip.stem}_{m}.npz" for m in ("ours", "gmr")}
            # warm-up (untimed): fills our compiled-problem cache and the OS file cache; its outputs are measured
            for method in ("ours", "gmr"):
                say(f"[{time.perf_counter() - t_start:6.0f} s] {robot} {clip.stem}: {method} warm-up run")
                r = run_process(cmd(method, robot, clip, outs[method]), args.timeout)
                entry[method]["warmup"] = r
                if "error" in r:
                    say(f"    {method} failed: {r['error']}")
            waited = wait_for_compiles()
            if waited > 1:
                say(f"    waited {waited:.0f} s for the background compiler")
            # quality of the warm-up outputs
            for method in ("ours", "gmr"):
                if "error" in entry[method]["warmup"]:
                    entry[method]["quality"] = {"error": entry[method]["warmup"]["error"]}
                    continue
                try:
                    with np.load(outs[method]) as z:
                        npz = {k: z[k] for k in z.files}
                    entry[method]["quality"] = quality(robot, method, npz, humans[clip.stem], models)
                except Exception as exc:  # noqa: BLE001
                    entry[method]["quality"] = {"error": f"{type(exc).__name__}: {exc}"}
                    traceback.print_exc()
            # timed, alternating
            timed = {"ours": [], "gmr": []}
            for rep in range(args.repeat):
                order = ("ours", "gmr") if rep % 2 == 0 else ("gmr", "ours")
                for method in order:
                    r = run_process(cmd(method, robot, clip, runs_dir / f"timed_{method}.npz"), args.timeout)
                    timed[method].append(r)
                msg = "  ".join(f"{m} {r['seconds'] / r['solve_cpu_s']:.2f} motion-s/CPU-s (process {r['seconds'] / r['process_cpu_s']:.2f})"
                                if "error" not in r else f"{m} failed" for m in ("ours", "gmr") for r in [timed[m][-1]])
                say(f"[{time.perf_counter() - t_start:6.0f} s] {robot} {clip.stem} rep {rep + 1}/{args.repeat}: {msg}")
            ratios_solve, ratios_proc = [], []
            for a, b in zip(timed["ours"], timed["gmr"]):
                if "error" not in a and "error" not in b:
                    ratios_solve.append((b["seconds"] / b["solve_cpu_s"]) / (a["seconds"] / a["solve_cpu_s"]))
                    ratios_proc.append((b["seconds"] / b["process_cpu_s"]) / (a["seconds"] / a["process_cpu_s"]))
            for method in ("ours", "gmr"):
                entry[method]["speed"] = summarise_speed(timed[method])
            entry["ratio_gmr_over_ours_solve"] = median(ratios_solve)
            entry["ratio_gmr_over_ours_process"] = median(ratios_proc)
            report_rows.append(entry)
            for method in ("ours", "gmr"):
                q, s = entry[method].get("quality", {}), entry[method].get("speed", {})
                row = {"robot": robot, "clip": clip.stem.replace("dataset-1_", ""), "method": method}
                err = q.get("error") or s.get("error")
                if err:
                    row["error"] = err
                row |= {
                    "frames": q.get("frames"), "fps": q.get("fps"),
                    "motion s / CPU s (solve)": s.get("speed_solve"), "(process)": s.get("speed_process"),
                    "GMR/ours (solve)": entry["ratio_gmr_over_ours_solve"] if method == "gmr" else None,
                    "(process) ": entry["ratio_gmr_over_ours_process"] if method == "gmr" else None,
                    "below floor fr": q.get("below_floor_frames"),
                    "lowest mm": None if q.get("lowest_point_m") is None else q["lowest_point_m"] * 1000,
                    "contact %": None if q.get("foot_contact_fraction") is None else q["foot_contact_fraction"] * 100,
                    "slip cm": None if q.get("foot_slip_total_m") is None else q["foot_slip_total_m"] * 100,
                    "worst slip mm": None if q.get("foot_slip_worst_frame_m") is None else q["foot_slip_worst_frame_m"] * 1000,
                    "limit fr": q.get("joint_limit_frames"), "self-coll fr": q.get("self_collision_frames"),
                    "stance slip cm": None if q.get("stance_slip_total_m") is None else q["stance_slip_total_m"] * 100,
                    "stance foot mm": None if q.get("stance_foot_height_median_m") is None else q["stance_foot_height_median_m"] * 1000,
                    "kp err cm": None if q.get("keypoint_error_mean_m") is None else q["keypoint_error_mean_m"] * 100,
                    "kp centred cm": None if q.get("keypoint_error_centred_m") is None else q["keypoint_error_centred_m"] * 100,
                    "max turn deg": q.get("base_turn_max_deg"), "turn deg/s": q.get("base_turn_max_deg_s"),
                }
                rows.append(row)
                say(f"    {method:4s} " + ", ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}"
                                                 for k, v in row.items() if k not in ("robot", "clip", "method") and v is not None))

    table = markdown_table(rows)
    say("\n" + table)
    elapsed = time.perf_counter() - t_start
    payload = {
        "benchmark": "bench_gmr",
        "command": "python benchmarks/bench_gmr.py " + " ".join(sys.argv[1:]),
        "clips": [c.stem for c in clips], "robots": args.robots, "repeat": args.repeat, "max_seconds": args.max_seconds,
        "seconds": elapsed,
        "gmr": {"source": "../shared/peers/gmr.tar.xz (YanjieZe/GMR commit 4f9e8b7, MIT), extracted to " + str(gmr_src),
                "python": str(gmr_python), "versions": _gmr_versions(gmr_python),
                "gmr_joint_map": "Bandai joints renamed to LAFAN1 names with bone axes converted (_gmr_driver.py); "
                                 "GMR's ik_configs/bvh_to_*.json unchanged; actual_human_height 1.75 as GMR's BVH loader",
                "rate": "file rate (30 fps)"},
        "ours": {"config": "RetargetConfig() defaults (trajectory mode, window 60 / overlap 10, contacts, swing, "
                           "self-collision on), compiled-problem cache on (warmed by the untimed first run)",
                 "rate": "20 fps (project rate)"},
        "definitions": "benchmarks/_gmr_quality.py docstring; speed = seconds of motion / CPU seconds; 'solve' = the solve "
                       "loop only, 'process' = the whole worker process (fresh interpreter)",
        "models": {r: ("each method on its own model (GMR: " + GMR_XML[r] + ")" if r in OWN_MODEL
                       else f"both on models/mjcf/{r}.xml (GMR qpos mapped by joint name)") for r in args.robots},
        "table": rows,
        "results": report_rows,
        "machine": machine_description(threads=1),
    }
    path = write_json(args.out, payload)
    say(f"wrote {path} ({elapsed / 60:.1f} min)")
    return 0


def _gmr_versions(python: Path) -> dict:
    code = ("import json; from importlib import metadata as m; "
            "print(json.dumps({p: m.version(p) for p in ('mujoco', 'mink', 'daqp', 'numpy', 'scipy')}))")
    try:
        return json.loads(subprocess.run([str(python), "-c", code], capture_output=True, text=True, timeout=60).stdout)
    except (OSError, ValueError, subprocess.SubprocessError):
        return {}


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    sys.exit(main())
