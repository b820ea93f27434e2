"""Reconstruction quality of a tokenizer on a prepared dataset (``motok-robot eval reconstruct``).

Every clip of the split is padded to a multiple of ``frames_per_token``, encoded, decoded
(with ``steps`` DDIM steps and a fixed seed) and cropped back.  Joints are recovered from
the original and reconstructed features with the same function
(:func:`motok_robot.motion.features.joints_from_features`), so the comparison measures the
tokenizer alone.  Averages are over frames (a long clip weighs more than a short one).

Reported (JSON):

* ``mpjpe_cm``: mean per-joint position error, cm, in the world frame (root path included);
* ``mpjpe_root_aligned_cm``: the same after subtracting each frame's pelvis position;
* ``root_trajectory_error_cm``: mean planar (x, y) pelvis distance, cm; ``root_final_error_cm``
  the distance at each clip's last frame (mean over clips);
* ``foot_skating_ratio_reconstructed`` / ``_original``: fraction of frame steps with a
  skating foot (GMD protocol, :func:`motok_robot.motion.metrics.foot_skating_ratio`);
* ``codebook_usage``: fraction of the K codes used over the whole split; ``perplexity``;
* ``token_rate_hz``: tokens per second of motion (fps / downsample);
* ``tokens_per_second``: tokens encoded+decoded per second of wall time (throughput) and
  ``realtime_factor``: seconds of motion reconstructed per second of wall time.
"""

from __future__ import annotations

import platform
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from motok_robot.errors import InputError
from motok_robot.motion.features import joints_from_features
from motok_robot.motion.metrics import foot_skating_ratio, mpjpe, root_trajectory_error
from motok_robot.tokenizer.model import MoTok
from motok_robot.tokenizer.quantizer import code_statistics


@torch.no_grad()
def reconstruct_clips(
    tokenizer: MoTok,
    clips: list[tuple[str, np.ndarray]],
    steps: int | None = None,
    seed: int = 0,
    progress: bool | None = None,
) -> dict[str, Any]:
    """Reconstruct ``(id, features [T, 263])`` clips; return the metrics dict described above
    plus ``worst_clips`` (the five highest world-frame MPJPE, cm) and ``clip_errors`` (every
    clip's MPJPE, worst first)."""
    if not clips:
        raise InputError("reconstruct: no clips to evaluate")
    fps = tokenizer.config.fps
    sums = {"mpjpe": 0.0, "aligned": 0.0, "root": 0.0, "skate_rec": 0.0, "skate_orig": 0.0}
    frames_total, skate_steps, root_final, per_clip = 0, 0, [], []
    tokens_all: list[torch.Tensor] = []
    wall = 0.0
    for clip_id, feats in tqdm(clips, desc="reconstruct", unit="clip", disable=None if progress is None else not progress):
        feats = np.asarray(feats, dtype=np.float32)
        if feats.ndim != 2 or feats.shape[1] != tokenizer.config.feature_dim or feats.shape[0] < 2:
            raise InputError(f"clip {clip_id}: features must be [T >= 2, {tokenizer.config.feature_dim}] (got {feats.shape})")
        x = torch.from_numpy(feats)[None].to(tokenizer.device)
        if tokenizer.device.type == "cuda":
            torch.cuda.synchronize()
        start = time.perf_counter()
        padded, length = tokenizer.pad(x)
        tokens = tokenizer.encode(padded)
        y = tokenizer.decode(tokens, length=length, steps=steps, seed=seed)
        if tokenizer.device.type == "cuda":
            torch.cuda.synchronize()
        wall += time.perf_counter() - start
        tokens_all.append(tokens.reshape(-1).cpu())
        j_orig = joints_from_features(feats)
        j_rec = joints_from_features(y[0].cpu().numpy())
        t = feats.shape[0]
        err = mpjpe(j_rec, j_orig)
        sums["mpjpe"] += err * t
        sums["aligned"] += mpjpe(j_rec, j_orig, align_root=True) * t
        root = root_trajectory_error(j_rec, j_orig)
        sums["root"] += root["mean_m"] * t
        root_final.append(root["final_m"])
        sums["skate_rec"] += foot_skating_ratio(j_rec, fps) * (t - 1)
        sums["skate_orig"] += foot_skating_ratio(j_orig, fps) * (t - 1)
        frames_total += t
        skate_steps += t - 1
        per_clip.append((err * 100.0, clip_id))
    stats = code_statistics(torch.cat(tokens_all), tokenizer.config.codebook_size)
    n_tokens = int(sum(t.numel() for t in tokens_all))
    per_clip.sort(reverse=True)
    return {
        "clips": len(clips),
        "frames": frames_total,
        "seconds_of_motion": frames_total / fps,
        "mpjpe_cm": 100.0 * sums["mpjpe"] / frames_total,
        "mpjpe_root_aligned_cm": 100.0 * sums["aligned"] / frames_total,
        "root_trajectory_error_cm": 100.0 * sums["root"] / frames_total,
        "root_final_error_cm": 100.0 * float(np.mean(root_final)),
        "foot_skating_ratio_reconstructed": sums["skate_rec"] / max(skate_steps, 1),
        "foot_skating_ratio_original": sums["skate_orig"] / max(skate_steps, 1),
        "codebook_usage": float(stats["usage"]),
        "codes_used": int((stats["counts"] > 0).sum()),
        "codebook_size": tokenizer.config.codebook_size,
        "perplexity": float(stats["perplexity"]),
        "token_rate_hz": tokenizer.config.fps / tokenizer.frames_per_token,
        "tokens": n_tokens,
        "tokens_per_second": n_tokens / wall if wall > 0 else float("nan"),
        "realtime_factor": (frames_total / fps) / wall if wall > 0 else float("nan"),
        "wall_seconds": wall,
        "decoder": tokenizer.config.decoder,
        "steps": int(steps or tokenizer.config.sample_steps) if tokenizer.config.decoder == "diffusion" else 0,
        "seed": seed,
        "worst_clips": [{"id": cid, "mpjpe_cm": e} for e, cid in per_clip[:5]],
        "clip_errors": [{"id": cid, "mpjpe_cm": e} for e, cid in per_clip],  # all clips, worst first
    }


def reconstruct_dataset(
    tokenizer: MoTok,
    data_dir: str | Path,
    split: str = "test",
    steps: int | None = None,
    seed: int = 0,
    limit: int | None = None,
    progress: bool | None = None,
) -> dict[str, Any]:
    """:func:`reconstruct_clips` over a prepared dataset split (``train|val|test|all``);
    ``limit`` keeps the first clips only."""
    from motok_robot.data.dataset import PreparedDataset

    dataset = PreparedDataset(data_dir, split)
    ids = list(dataset.clip_ids)[: limit or None]
    if not ids:
        raise InputError(f"{data_dir}: split {split!r} has no clips")
    clips = [(i, dataset.features(i)) for i in ids]
    result = reconstruct_clips(tokenizer, clips, steps=steps, seed=seed, progress=progress)
    result.update({"data": str(data_dir), "split": split, "device": str(tokenizer.device), "machine": machine_description()})
    return result


def machine_description() -> dict[str, Any]:
    info = {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "torch_threads": torch.get_num_threads(),
    }
    try:
        import os

        info["cpus"] = len(os.sched_getaffinity(0))
        info["load_average_1min"] = os.getloadavg()[0]  # other work on the machine skews timings
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        pass
    if torch.cuda.is_available():
        info["cuda_device"] = torch.cuda.get_device_name(0)
    return info


@torch.no_grad()
def plot_reconstructions(
    tokenizer: MoTok, clips: list[tuple[str, np.ndarray]], path: str | Path, steps: int | None = None, seed: int = 0
) -> Path:
    """PNG with one row per clip: root path (x, y; m) of the original and the reconstruction,
    per-frame MPJPE (cm, world frame and root-aligned), and foot heights (m) over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    fps = tokenizer.config.fps
    fig, axes = plt.subplots(len(clips), 3, figsize=(15, 3.6 * len(clips)), squeeze=False)
    for row, (clip_id, feats) in zip(axes, clips):
        x = torch.from_numpy(np.asarray(feats, dtype=np.float32))[None].to(tokenizer.device)
        y = tokenizer.reconstruct(x, steps=steps, seed=seed)
        j_orig = joints_from_features(np.asarray(feats, dtype=np.float32))
        j_rec = joints_from_features(y[0].cpu().numpy())
        seconds = np.arange(len(j_orig)) / fps
        row[0].plot(j_orig[:, 0, 0], j_orig[:, 0, 1], "k-", label="original")
        row[0].plot(j_rec[:, 0, 0], j_rec[:, 0, 1], "r--", label="reconstruction")
        row[0].plot(j_orig[:1, 0, 0], j_orig[:1, 0, 1], "ko")
        row[0].set_aspect("equal", adjustable="datalim")
        row[0].set_title(f"{clip_id}: root path")
        row[0].set_xlabel("x (m)")
        row[0].set_ylabel("y (m)")
        row[0].legend(fontsize=8)
        world = np.linalg.norm(j_rec - j_orig, axis=-1).mean(-1) * 100
        aligned = np.linalg.norm((j_rec - j_rec[:, :1]) - (j_orig - j_orig[:, :1]), axis=-1).mean(-1) * 100
        row[1].plot(seconds, world, label=f"world (mean {world.mean():.1f})")
        row[1].plot(seconds, aligned, label=f"root-aligned (mean {aligned.mean():.1f})")
        row[1].set_title("MPJPE per frame")
        row[1].set_xlabel("time (s)")
        row[1].set_ylabel("cm")
        row[1].legend(fontsize=8)
        for joint, name, colour in ((10, "left foot", "tab:blue"), (11, "right foot", "tab:orange")):
            row[2].plot(seconds, j_orig[:, joint, 2], "-", color=colour, label=f"{name} original")
            row[2].plot(seconds, j_rec[:, joint, 2], "--", color=colour, label=f"{name} reconstruction")
        row[2].set_title("foot height")
        row[2].set_xlabel("time (s)")
        row[2].set_ylabel("z (m)")
        row[2].legend(fontsize=7)
    fig.suptitle(f"MoTok reconstruction ({tokenizer.config.decoder} decoder, {tokenizer.config.fps / tokenizer.frames_per_token:g} tokens/s)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
