"""HumanML3D folder reader, so a user who has HumanML3D can train on it unchanged.

Expected layout (HumanML3D's own)::

    ROOT/new_joint_vecs/ID.npy   float32 [T-1, 263] features (used as they are)
    ROOT/new_joints/ID.npy       float32 [T, 22, 3] joints, metres, y up (x left, z forward)
    ROOT/texts/ID.txt            lines "caption#tokens#from#to" (from/to in seconds; 0 = whole clip)
    ROOT/Mean.npy, ROOT/Std.npy  float32 [263]
    ROOT/train.txt, val.txt, test.txt (optional; also all.txt) clip ids

Joints are converted to the project frame (z up, x forward, y left) with
:func:`motok_robot.motion.skeleton.zup_from_yup`.  A caption with a time range ``from..to``
becomes its own sub-clip ``ID_from_to`` cut from the features (and joints) at 20 fps, as
HumanML3D's loaders do.  Ids starting with ``M`` are HumanML3D's own mirrors of the id
without the ``M``; they are marked ``mirror_of`` so prepare adds no second mirror.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import numpy as np

from motok_robot.data.clip import Clip
from motok_robot.errors import InputError
from motok_robot.motion.skeleton import FPS, zup_from_yup

LICENCE = "HumanML3D / AMASS licences (see the HumanML3D and AMASS terms)"


def read_split_files(root: Path) -> dict[str, str]:
    """``{clip id: split}`` from ROOT/{train,val,test}.txt (missing files are fine)."""
    out = {}
    for split in ("train", "val", "test"):
        f = root / f"{split}.txt"
        if f.is_file():
            for line in f.read_text().split():
                out[line.strip()] = split
    return out


def parse_text_file(path: Path) -> list[tuple[str, float, float]]:
    """``[(caption, from_s, to_s)]`` from a HumanML3D ``texts/ID.txt`` (NaN ranges -> 0)."""
    out = []
    for lineno, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
        if not line.strip():
            continue
        parts = line.strip().split("#")
        caption = parts[0].strip()
        try:
            f0 = float(parts[2]) if len(parts) > 2 and parts[2] else 0.0
            f1 = float(parts[3]) if len(parts) > 3 and parts[3] else 0.0
        except ValueError:
            raise InputError(f"{path}: line {lineno}: bad time range {parts[2:4]}") from None
        f0 = 0.0 if not np.isfinite(f0) else f0
        f1 = 0.0 if not np.isfinite(f1) else f1
        if caption:
            out.append((caption, f0, f1))
    return out


def list_ids(root: str | Path) -> list[str]:
    root = Path(root)
    vec = root / "new_joint_vecs"
    if not vec.is_dir():
        raise InputError(f"{root}: not a HumanML3D folder (no new_joint_vecs/)")
    return sorted(p.stem for p in vec.glob("*.npy"))


def load_clips(root: str | Path, clip_id: str) -> list[Clip]:
    """The clip(s) of one HumanML3D id (one per distinct caption time range)."""
    root = Path(root)
    fvec = root / "new_joint_vecs" / f"{clip_id}.npy"
    fjoint = root / "new_joints" / f"{clip_id}.npy"
    ftext = root / "texts" / f"{clip_id}.txt"
    for f in (fvec, fjoint):
        if not f.is_file():
            raise InputError(f"{f}: missing (HumanML3D id {clip_id})")
    try:
        feats = np.load(fvec).astype(np.float32)
        joints = np.load(fjoint).astype(np.float32)
    except (OSError, ValueError) as exc:
        raise InputError(f"{fvec}: cannot read .npy ({exc})") from None
    if feats.ndim != 2 or feats.shape[1] != 263:
        raise InputError(f"{fvec}: expected [T-1, 263] features, got {list(feats.shape)}")
    if joints.ndim != 3 or joints.shape[1:] != (22, 3):
        raise InputError(f"{fjoint}: expected [T, 22, 3] joints, got {list(joints.shape)}")
    if feats.shape[0] == 0:
        raise InputError(f"{fvec}: zero frames")
    if not np.isfinite(feats).all() or not np.isfinite(joints).all():
        raise InputError(f"{fvec}: NaN or infinite values")
    joints = zup_from_yup(joints).astype(np.float32)
    T = min(joints.shape[0], feats.shape[0] + 1)
    joints, feats = joints[:T], feats[: T - 1]
    captions = parse_text_file(ftext) if ftext.is_file() else []
    groups: dict[tuple[float, float], list[str]] = {}
    for cap, f0, f1 in captions:
        groups.setdefault((f0, f1), []).append(cap)
    if not groups:
        groups[(0.0, 0.0)] = []
    splits = read_split_files(root)
    mirror_of = f"humanml3d/{clip_id[1:]}" if clip_id.startswith("M") else None
    clips = []
    for (f0, f1), caps in sorted(groups.items()):
        cid, j, fe = f"humanml3d/{clip_id}", joints, feats
        if (f0, f1) != (0.0, 0.0):
            a, b = int(f0 * FPS), int(f1 * FPS)
            if b - a < 2 or b > joints.shape[0]:
                continue
            cid = f"humanml3d/{clip_id}_{a}_{b}"
            j, fe = joints[a:b], feats[a : b - 1]
        labels = {"split": splits.get(clip_id), "mirror_of": None}
        if mirror_of:
            labels["mirror_of"] = mirror_of + cid[len(f"humanml3d/{clip_id}") :]
        clips.append(
            Clip(
                id=cid,
                source="humanml3d",
                licence=LICENCE,
                joints=j,
                texts=list(caps),
                file=str(fvec),
                labels=labels,
                features=fe,
            )
        )
    return clips


def iter_clips(root: str | Path) -> Iterator[tuple[str, list[Clip] | Exception]]:
    """``(file, clips or the InputError)`` for every id in the folder."""
    root = Path(root)
    for cid in list_ids(root):
        try:
            yield str(root / "new_joint_vecs" / f"{cid}.npy"), load_clips(root, cid)
        except InputError as exc:
            yield str(root / "new_joint_vecs" / f"{cid}.npy"), exc


def load_mean_std(root: str | Path) -> tuple[np.ndarray, np.ndarray] | None:
    root = Path(root)
    if (root / "Mean.npy").is_file() and (root / "Std.npy").is_file():
        return np.load(root / "Mean.npy").astype(np.float32), np.load(root / "Std.npy").astype(np.float32)
    return None
