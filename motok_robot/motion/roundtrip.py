"""Check the feature round trip on every clip of a prepared dataset (numpy only).

Usage::

    python -m motok_robot.motion.roundtrip DIR [--limit N] [--tolerance-mm 1.0] [--json OUT.json]

For each ``DIR/joints/ID.npy`` (``[T, 22, 3]`` float32, metres, z up, skeleton-normalised)
with its ``DIR/features/ID.npy`` (``[T-1, 263]``), it measures

* ``decode_mm``: max |``joints_from_features(features)`` - ``joints[:-1]``| (the stored
  features reproduce the stored joints);
* ``normalise_mm``: max |``normalise_joints(joints)`` - ``joints``| (the stored joints are
  already normalised, so recomputing features from them gives the same clip);
* ``recompute_mm``: max |``joints_from_features(features_from_joints(joints))`` - ``joints[:-1]``|.

It prints the worst clips and exits with status 1 when any value exceeds the tolerance.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.motion.features import features_from_joints, joints_from_features, normalise_joints


def check_clip(joints: np.ndarray, features: np.ndarray) -> dict[str, float]:
    """Round-trip errors (millimetres) of one stored clip; see the module docstring."""
    joints = np.asarray(joints, dtype=np.float64)
    features = np.asarray(features)
    if features.shape[0] != joints.shape[0] - 1:
        raise InputError(f"features have {features.shape[0]} frames but joints have {joints.shape[0]} (expected T-1)")
    decoded = joints_from_features(features.astype(np.float64))
    recomputed = joints_from_features(features_from_joints(joints).astype(np.float64))
    return {
        "decode_mm": float(np.abs(decoded - joints[:-1]).max() * 1000.0),
        "normalise_mm": float(np.abs(normalise_joints(joints) - joints).max() * 1000.0),
        "recompute_mm": float(np.abs(recomputed - joints[:-1]).max() * 1000.0),
    }


def check_dataset(root: Path, limit: int | None = None) -> tuple[dict[str, dict], dict[str, str]]:
    """``(results {clip id: errors}, failures {clip id: reason})`` over ``root/joints/*.npy``."""
    from tqdm import tqdm

    joint_files = sorted((root / "joints").glob("*.npy"))
    if not joint_files:
        raise InputError(f"{root}: no joints/*.npy files (is this a prepared dataset folder?)")
    if limit is not None:
        joint_files = joint_files[:limit]
    results: dict[str, dict] = {}
    failures: dict[str, str] = {}
    for path in tqdm(joint_files, desc="round trip", unit="clip", disable=None):
        clip_id = path.stem
        feat_path = root / "features" / path.name
        try:
            if not feat_path.exists():
                raise InputError(f"{feat_path} is missing")
            results[clip_id] = check_clip(np.load(path), np.load(feat_path))
        except (InputError, ValueError, OSError) as exc:
            failures[clip_id] = str(exc)
    return results, failures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m motok_robot.motion.roundtrip", description=__doc__.split("\n\n")[0])
    parser.add_argument("dataset", type=Path, help="prepared dataset folder (with joints/ and features/)")
    parser.add_argument("--limit", type=int, default=None, help="check only the first N clips")
    parser.add_argument("--tolerance-mm", type=float, default=1.0, help="fail above this error (default 1 mm)")
    parser.add_argument("--json", type=Path, default=None, help="write per-clip results to this JSON file")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    try:
        results, failures = check_dataset(args.dataset, args.limit)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    wall = time.perf_counter() - start
    keys = ("decode_mm", "normalise_mm", "recompute_mm")
    worst = {k: max((r[k] for r in results.values()), default=float("nan")) for k in keys}
    over = sorted(cid for cid, r in results.items() if max(r[k] for k in keys) > args.tolerance_mm)
    print(f"{len(results)} clips checked in {wall:.1f} s, {len(failures)} unreadable")
    print(f"{'metric':<14}{'max (mm)':>12}{'median (mm)':>14}")
    for k in keys:
        med = float(np.median([r[k] for r in results.values()])) if results else float("nan")
        print(f"{k:<14}{worst[k]:>12.4f}{med:>14.4f}")
    ranked = sorted(results.items(), key=lambda kv: -max(kv[1][k] for k in keys))[:5]
    for cid, r in ranked:
        print(f"  {cid}: " + ", ".join(f"{k} {r[k]:.4f}" for k in keys))
    for cid, reason in sorted(failures.items()):
        print(f"  unreadable {cid}: {reason}")
    if args.json is not None:
        args.json.write_text(json.dumps({"tolerance_mm": args.tolerance_mm, "wall_s": wall, "worst": worst,
                                         "over_tolerance": over, "failures": failures, "clips": results}, indent=1))
    if over:
        print(f"{len(over)} clip(s) above {args.tolerance_mm} mm: {', '.join(over[:10])}")
    return 1 if over or failures else 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
