"""``motok-robot eval control``: the GMD / OmniControl protocol on held-out test clips.

For each test clip of a prepared dataset (cropped to what the planner can generate, at least
:attr:`ControlEvalConfig.min_frames` frames) the ground-truth joints (recovered from the clip's
features, so they start at the origin facing +x like every generated motion) give three tasks:

* ``trajectory``: the dense root path on the ground (x, y every frame);
* ``keyframes``: ``sparse_keyframes`` (5) positions of random joints among pelvis, feet, head
  and wrists, at random frames (3D);
* ``obstacles``: ``obstacle_scenes`` (20) scenes from clips whose root travels at least
  ``min_path_m``: five sparse root keyframes of the ground-truth path plus one obstacle
  (circle or box, alternating) beside the path, its edge ``obstacle_clearance_m`` from the
  pelvis path at mid-clip, on a random side. The ground-truth row shows how often the real
  motion itself would touch the obstacle.

Each task is generated under several settings with fixed seeds (``seed + clip index``):

* with a planner (``source="planner"``, the clip's first caption as text): ``none`` (no
  control; the constraints only measure), ``planner only`` / ``decoder only`` / ``both`` (the
  dual path, default mechanism), then ``both`` with each decoder mechanism (refinement, GMD,
  inpainting), and ``both`` with the default mechanism and the physics terms;
* without a planner (``source="tokens"``): the clip's own tokens (encoded ground truth) are
  decoded with each mechanism (and the default one with the physics terms), which isolates
  the decoder's part.

Metrics per row: :func:`motok_robot.control.metrics.control_table`.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from motok_robot.control.config import ControlConfig
from motok_robot.control.constraints import Constraints, Obstacle
from motok_robot.control.metrics import clip_metrics, control_table
from motok_robot.errors import InputError
from motok_robot.motion.skeleton import FPS, JOINT_INDEX

KEYFRAME_JOINTS = tuple(JOINT_INDEX[n] for n in ("pelvis", "left_foot", "right_foot", "head", "left_wrist", "right_wrist"))
TASKS = ("trajectory", "keyframes", "obstacles")
SOURCES = ("planner", "tokens")


@dataclass
class ControlEvalConfig:
    """What ``eval control`` runs (defaults in one place)."""

    clips: int = 32  #: test clips for the trajectory and keyframe tasks
    obstacle_scenes: int = 20
    sparse_keyframes: int = 5
    seed: int = 0
    min_frames: int = 40  #: shorter clips are left out (2 s)
    max_frames: int | None = None  #: crop (default: the planner's maximum, or 196 frames without one)
    min_path_m: float = 1.0  #: obstacle scenes need a root path at least this long
    obstacle_radius_m: float = 0.25  #: circle radius; boxes are 0.5 x 0.4 m
    obstacle_clearance_m: float = 0.2  #: gap between the pelvis path and the obstacle's edge
    mechanisms: tuple[str, ...] = ("motok", "gmd", "inpaint")
    decoder_steps: int | None = None
    #: add the physics terms (feet in contact do not slide or sink) to every controlled row
    #: (the ``+ physics`` row has them in any case)
    foot_physics: bool = False
    tasks: tuple[str, ...] = TASKS
    control: ControlConfig = field(default_factory=ControlConfig)

    def __post_init__(self) -> None:
        if self.clips < 1 or self.obstacle_scenes < 0 or self.sparse_keyframes < 1:
            raise InputError("eval control: clips and sparse keyframes must be >= 1, obstacle scenes >= 0")
        unknown = [t for t in self.tasks if t not in TASKS]
        if unknown:
            raise InputError(f"eval control: unknown task(s) {unknown} (choose from {', '.join(TASKS)})")


@dataclass
class TestClip:
    """One held-out clip: id, caption, ground-truth features ``[T, 263]`` and joints ``[T, 22, 3]``
    (metres, z up, from the features), and its seed."""

    clip_id: str
    text: str
    features: np.ndarray
    joints: np.ndarray
    seed: int


# ----------------------------------------------------------------------------- tasks


def trajectory_task(joints: np.ndarray) -> Constraints:
    """Dense root path (x, y every frame) of ``joints [T, 22, 3]``."""
    c = Constraints(len(joints))
    for f in range(len(joints)):
        c.set_joint(f, 0, joints[f, 0, :2])
    return c


def keyframe_task(joints: np.ndarray, count: int, rng: np.random.Generator) -> Constraints:
    """``count`` 3D keyframes of random joints (:data:`KEYFRAME_JOINTS`) at distinct random frames >= 1."""
    T = len(joints)
    c = Constraints(T)
    frames = np.sort(rng.choice(np.arange(1, T), size=min(count, T - 1), replace=False))
    for f in frames:
        j = int(rng.choice(KEYFRAME_JOINTS))
        c.set_joint(int(f), j, joints[f, j])
    return c


def path_length(joints: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(joints[:, 0, :2], axis=0), axis=-1).sum())


def obstacle_task(joints: np.ndarray, index: int, config: ControlEvalConfig, rng: np.random.Generator) -> Constraints:
    """Five sparse root keyframes of the path (the last frame among them) and one obstacle
    beside the path at mid-clip (circle for even ``index``, box for odd)."""
    T = len(joints)
    c = Constraints(T)
    for f in np.linspace(T / config.sparse_keyframes, T - 1, config.sparse_keyframes).round().astype(int):
        c.set_joint(int(f), 0, joints[f, 0, :2])
    root = joints[:, 0, :2]
    mid = T // 2
    lo, hi = max(0, mid - 5), min(T - 1, mid + 5)
    tangent = root[hi] - root[lo]
    tangent = tangent / max(np.linalg.norm(tangent), 1e-6)
    normal = np.array([-tangent[1], tangent[0]]) * (1 if rng.random() < 0.5 else -1)
    if index % 2 == 0:
        r = config.obstacle_radius_m
        center = root[mid] + normal * (r + config.obstacle_clearance_m)
        c.obstacles.append(Obstacle("circle", (float(center[0]), float(center[1])), radius=r))
    else:
        size = (0.5, 0.4)  # along the path, across it
        center = root[mid] + normal * (size[1] / 2 + config.obstacle_clearance_m)
        yaw = float(math.atan2(tangent[1], tangent[0]))
        c.obstacles.append(Obstacle("box", (float(center[0]), float(center[1])), size=size, yaw=yaw))
    return c


def without_obstacles(c: Constraints) -> Constraints:
    return replace(c, obstacles=[], joint_targets=c.joint_targets.copy(), joint_mask=c.joint_mask.copy(),
                   root_height_mask=c.root_height_mask.copy())


# ----------------------------------------------------------------------------- data


def load_test_clips(data: str | Path, count: int | None, max_frames: int, config: ControlEvalConfig,
                    need_text: bool, min_path_m: float = 0.0) -> list[TestClip]:
    """Up to ``count`` test-split clips (in split order) of at least ``min_frames`` frames, cropped
    to ``max_frames``, with a caption when ``need_text``, travelling ``min_path_m`` or more."""
    from motok_robot.data.dataset import PreparedDataset
    from motok_robot.motion.features import joints_from_features

    ds = PreparedDataset(data, "test")
    if len(ds) == 0:
        raise InputError(f"{data}: the test split is empty (splits/test.txt)")
    out: list[TestClip] = []
    for i, cid in enumerate(ds.clip_ids):
        if count is not None and len(out) >= count:
            break
        texts = ds.texts(cid)
        if need_text and not texts:
            continue
        feats = ds.features(cid)[:max_frames]
        if len(feats) < config.min_frames:
            continue
        joints = joints_from_features(feats).astype(np.float64)
        if min_path_m > 0 and path_length(joints) < min_path_m:
            continue
        out.append(TestClip(cid, texts[0] if texts else "", feats, joints, config.seed + i))
    if not out:
        raise InputError(f"{data}: no test clip of at least {config.min_frames} frames"
                         + (" with a caption" if need_text else "") + (f" and a root path >= {min_path_m:g} m" if min_path_m else ""))
    return out


# ----------------------------------------------------------------------------- generation


class _Runner:
    """Makes one clip's joints under one setting."""

    def __init__(self, source: str, config: ControlEvalConfig, generator=None, tokenizer=None):
        self.source, self.config, self.generator, self.tokenizer = source, config, generator, tokenizer
        self._tokens: dict[str, Any] = {}

    def control(self, mechanisms: tuple[str, ...]) -> ControlConfig:
        return replace(self.config.control, mechanisms=mechanisms)

    def run(self, clip: TestClip, constraints: Constraints | None, path: str, mechanisms: tuple[str, ...]) -> np.ndarray:
        import torch

        from motok_robot.motion.features import joints_from_features

        T = len(clip.features)
        if self.source == "planner":
            from motok_robot.control.generate import generate_motion

            motion = generate_motion(text=clip.text, constraints=constraints, control=self.control(mechanisms),
                                     control_path=path, seconds=T / FPS, seed=clip.seed, generator=self.generator,
                                     decoder_steps=self.config.decoder_steps)
            return motion.joints.astype(np.float64)
        from motok_robot.control.decode import decode_with_control

        tok = self.tokenizer
        if clip.clip_id not in self._tokens:
            padded, _ = tok.pad(torch.as_tensor(clip.features, dtype=torch.float32)[None].to(tok.device))
            self._tokens[clip.clip_id] = tok.encode(padded)
        with torch.no_grad():
            feats = decode_with_control(tok, self._tokens[clip.clip_id], T, constraints, self.control(mechanisms),
                                        steps=self.config.decoder_steps, seed=clip.seed)
        return joints_from_features(feats[0].detach().cpu().numpy().astype(np.float64))


def settings_for(source: str, task: str, mechanisms: tuple[str, ...], default: tuple[str, ...]) -> list[tuple[str, str, tuple[str, ...], bool, bool]]:
    """Rows of one task: ``(name, control_path, mechanisms, with_obstacles, foot_physics)``."""
    rows: list[tuple[str, str, tuple[str, ...], bool, bool]] = []
    d = "+".join(default)
    if task == "obstacles":
        rows.append(("ground truth", "", (), True, False))
    if source == "planner":
        rows.append(("none", "both", ("none",), True, False))
        if task == "trajectory":
            rows += [("planner only", "planner", default, True, False), ("decoder only", "decoder", default, True, False)]
        if task == "obstacles":
            rows.append((f"both {d}, no obstacle term", "both", default, False, False))
        rows.append((f"both {d}", "both", default, True, False))
        if task == "trajectory":
            rows += [(f"both {m}", "both", (m,), True, False) for m in mechanisms if (m,) != default]
        rows.append((f"both {d} + physics", "both", default, True, True))
    else:
        rows.append(("none", "decoder", ("none",), True, False))
        if task == "obstacles":
            rows.append((f"{d}, no obstacle term", "decoder", default, False, False))
            rows.append((d, "decoder", default, True, False))
        else:
            rows += [(m, "decoder", (m,), True, False) for m in mechanisms]
            if default not in [(m,) for m in mechanisms]:
                rows.append((d, "decoder", default, True, False))
        rows.append((f"{d} + physics", "decoder", default, True, True))
    return rows


def evaluate_control(
    data: str | Path,
    source: str = "planner",
    planner: str = "masked",
    tokenizer_run=None,
    planner_run=None,
    device: str = "cpu",
    config: ControlEvalConfig | None = None,
    progress: bool | None = None,
) -> dict[str, Any]:
    """Run the protocol; returns ``{"tasks": {task: {row: metrics}}, "clips": ..., ...}`` (JSON-ready)."""
    from tqdm import tqdm

    config = config or ControlEvalConfig()
    if source not in SOURCES:
        raise InputError(f"source must be one of {SOURCES}, got {source!r}")
    generator = tokenizer = None
    if source == "planner":
        from motok_robot.planner.generate import load_generator

        generator = load_generator(planner, tokenizer_run, planner_run, device)
        max_frames = generator.frames_for(generator.max_seconds)
        model = generator.model_id
    else:
        from motok_robot.tokenizer import load_tokenizer

        if tokenizer_run is None:
            from motok_robot.planner.generate import _require_run, default_run

            tokenizer_run = default_run("tokenizer")
            _require_run(Path(tokenizer_run), "tokenizer")
        tokenizer = load_tokenizer(tokenizer_run, device=device)
        max_frames = 196
        model = f"tokenizer={tokenizer_run}"
    if config.max_frames is not None:
        max_frames = min(max_frames, config.max_frames)
    runner = _Runner(source, config, generator, tokenizer)
    default = tuple(config.control.mechanisms)
    need_text = source == "planner"

    jobs: list[tuple[str, list[TestClip], list[Constraints]]] = []
    rng = np.random.default_rng(config.seed)
    if "trajectory" in config.tasks or "keyframes" in config.tasks:
        clips = load_test_clips(data, config.clips, max_frames, config, need_text)
        if "trajectory" in config.tasks:
            jobs.append(("trajectory", clips, [trajectory_task(c.joints) for c in clips]))
        if "keyframes" in config.tasks:
            jobs.append(("keyframes", clips, [keyframe_task(c.joints, config.sparse_keyframes, rng) for c in clips]))
    if "obstacles" in config.tasks and config.obstacle_scenes > 0:
        scenes = load_test_clips(data, config.obstacle_scenes, max_frames, config, need_text, config.min_path_m)
        jobs.append(("obstacles", scenes, [obstacle_task(c.joints, i, config, rng) for i, c in enumerate(scenes)]))

    plan = [(task, clips, cons, row) for task, clips, cons in jobs for row in settings_for(source, task, config.mechanisms, default)]
    total = sum(len(clips) for _, clips, _, row in plan if row[0] != "ground truth")
    bar = tqdm(total=total, desc="eval control", unit="motion", disable=None if progress is None else not progress)
    tasks: dict[str, dict[str, Any]] = {}
    started = time.perf_counter()
    for task, clips, cons, (name, path, mechanisms, with_obstacles, physics) in plan:
        per_clip = []
        t0 = time.perf_counter()
        for clip, c in zip(clips, cons):
            if name == "ground truth":
                joints = clip.joints
            else:
                guide = c if with_obstacles else without_obstacles(c)
                if (physics or config.foot_physics) and guide is not None:
                    guide = replace(guide, foot_physics=True)
                joints = runner.run(clip, None if mechanisms == ("none",) else guide, path, mechanisms)
                bar.update(1)
            per_clip.append(clip_metrics(joints, c))
        row = control_table(per_clip)
        row["seconds_per_motion"] = (time.perf_counter() - t0) / len(clips) if name != "ground truth" else 0.0
        tasks.setdefault(task, {})[name] = row
    bar.close()
    return {
        "source": source,
        "model": model,
        "data": str(data),
        "config": {k: (asdict(v) if hasattr(v, "__dataclass_fields__") else v) for k, v in vars(config).items()},
        "clips": {task: [c.clip_id for c in clips] for task, clips, _ in jobs},
        "tasks": tasks,
        "seconds": time.perf_counter() - started,
    }


COLUMNS = (
    ("traj_fail_50cm", "traj>50cm"),
    ("traj_fail_20cm", "traj>20cm"),
    ("location_fail_50cm", "loc>50cm"),
    ("avg_error_m", "avg err m"),
    ("avg_error_cm", "avg err cm"),
    ("max_error_cm", "max err cm"),
    ("foot_skating_ratio", "skating"),
    ("penetration_mm", "pen mm"),
    ("floating_mm", "float mm"),
    ("obstacle_hit_fraction", "obst hit"),
    ("obstacle_depth_max_cm", "obst cm"),
    ("bone_change_cm", "bone cm"),
)


def format_table(result: dict[str, Any]) -> str:
    """The metric table as aligned text, one block per task."""
    lines = [f"control protocol ({result['source']}; {result['model']})"]
    header = ["task", "setting"] + [label for _, label in COLUMNS]
    rows = [header]
    for task, table in result["tasks"].items():
        for name, m in table.items():
            cells = [task, name]
            for key, _ in COLUMNS:
                v = m.get(key)
                cells.append("-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.3f}" if abs(v) < 10 else f"{v:.1f}")
            rows.append(cells)
    widths = [max(len(r[i]) for r in rows) for i in range(len(header))]
    for r in rows:
        lines.append("  ".join(cell.ljust(w) if i < 2 else cell.rjust(w) for i, (cell, w) in enumerate(zip(r, widths))))
    return "\n".join(lines)
