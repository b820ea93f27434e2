# Size (421 lines): one command's whole pipeline: import, features, split, write, and its summary table.
"""``motok-robot data prepare``: import sources, compute features, split, write the dataset.

Output layout (docs/CONTRACTS.md, "Prepared dataset")::

    DIR/index.jsonl            one JSON object per clip (id, source, licence, fps, frames, seconds,
                               texts, split, file, mirror_of, derived_joints)
    DIR/features/NAME.npy      float32 [T-1, 263] HumanML3D features
    DIR/joints/NAME.npy        float32 [T, 22, 3] skeleton-normalised joints, metres, z up
    DIR/texts/NAME.txt         one sentence per line
    DIR/splits/{train,val,test}.txt
    DIR/mean.npy, DIR/std.npy  float32 [263] over the train split (std floored at STD_FLOOR)
    DIR/summary.json           clips/hours per source, skipped files with reasons, wall time

``NAME`` is the clip id with ``/`` replaced by ``__``.  Mirrored clips (left/right swapped,
texts with left/right words swapped) get the id ``mirror/<id>`` and the split of their
original.  The split is a hash of the clip's group (a Bandai content+style, otherwise the
clip itself) and the seed: ~85 % train, 5 % val, 10 % test.  ``split_by="clip"`` hashes each
clip on its own instead (HumanML3D's kind of split: other takes of a test clip's content and
style can be in train); a mirror still goes where its original goes.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import sys
import tempfile
import time
from collections import deque
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motok_robot.data import sources as S
from motok_robot.data.clip import Clip, stature
from motok_robot.data.texts import mirror_text
from motok_robot.errors import InputError

SPLIT_FRACTIONS = {"train": 0.85, "val": 0.05, "test": 0.10}
SPLIT_UNITS = ("group", "clip")  # what the split hashes: a clip's group, or the clip itself
STD_FLOOR = 1e-4
MIN_FRAMES = 4  # shorter clips (at 20 fps) are skipped: too short to learn from


@dataclass
class PrepareConfig:
    """Options of ``data prepare`` (defaults in one place)."""

    sources: list[tuple[str, str]]  # (kind, path)
    out: str
    texts: str | None = None  # user text index (CSV/JSON)
    joint_map: str | dict[str, str] | None = None  # joint-map JSON: one path (bvh and asf) or {kind: path}
    mirror: bool = True
    seed: int = 0
    split_by: str = "group"  # one of SPLIT_UNITS
    limit: int | None = None  # at most this many files per source
    workers: int = 2
    asf_fps: float = 120.0
    overwrite: bool = False
    progress: bool | None = None  # tqdm disable=None: quiet when not a TTY
    max_skip_share: float = 0.05  # more skipped files than this share of all files is an error ...
    allow_skips: bool = False  # ... unless this is set (``--allow-skips``)


def file_name(clip_id: str) -> str:
    """File stem of a clip id on disk (``bandai/x`` -> ``bandai__x``)."""
    return clip_id.replace("/", "__")


def split_of(group: str, seed: int = 0) -> str:
    """Deterministic split of a group key: sha256(seed:group) -> train / val / test."""
    h = int(hashlib.sha256(f"{seed}:{group}".encode()).hexdigest()[:12], 16) / float(16**12)
    if h < SPLIT_FRACTIONS["train"]:
        return "train"
    if h < SPLIT_FRACTIONS["train"] + SPLIT_FRACTIONS["val"]:
        return "val"
    return "test"


def split_key(record: dict, split_by: str) -> str:
    """What decides a clip's split: its group, or the clip (a mirror: its original)."""
    if split_by == "group":
        return record["group"]
    return record["mirror_of"] or record["id"]


# ----------------------------------------------------------------------------- worker

def process_job(job: S.Job, options: S.SourceOptions, mirror: bool) -> list[dict] | S.Skipped:
    """Load a job's clips and compute normalised joints + features (+ the mirror). Worker side."""
    from motok_robot.motion import features as F
    from motok_robot.motion.skeleton import mirror_joints

    try:
        clips = S.run_job(job, options)
        out = []
        for clip in clips:
            if clip.frames < MIN_FRAMES:
                raise InputError(f"{job.file}: only {clip.frames} frames at 20 fps (< {MIN_FRAMES})")
            out.append(_record(clip, F, None))
            if mirror and clip.source != "humanml3d" and not clip.labels.get("mirror_of"):
                m = clip.with_(
                    id=f"mirror/{clip.id}",
                    joints=mirror_joints(clip.joints).astype(np.float32),
                    texts=[mirror_text(t) for t in clip.texts],
                    labels={**clip.labels, "mirror_of": clip.id},
                )
                out.append(_record(m, F, clip.id))
        return out
    except InputError as exc:
        msg = str(exc)
        return S.Skipped(job.file, msg[len(job.file) + 2 :] if msg.startswith(job.file + ": ") else msg)
    except (ValueError, KeyError, IndexError, UnicodeError, OSError) as exc:  # unforeseen bad data
        return S.Skipped(job.file, f"{type(exc).__name__}: {exc}")


def _record(clip: Clip, F, mirror_of: str | None) -> dict:
    if clip.features is not None:  # HumanML3D: features as given, joints already normalised
        feats = clip.features.astype(np.float32)
        joints = clip.joints.astype(np.float32)
    else:
        joints = F.normalise_joints(clip.joints).astype(np.float32)
        feats = F.features_from_joints(clip.joints)
    if not np.isfinite(feats).all():
        raise InputError(f"{clip.file}: features of {clip.id} are not finite (degenerate skeleton?)")
    return {
        "id": clip.id,
        "source": clip.source,
        "licence": clip.licence,
        "fps": 20,
        "frames": int(joints.shape[0]),
        "seconds": round(joints.shape[0] / 20.0, 3),
        "texts": list(clip.texts),
        "file": clip.file,
        "mirror_of": mirror_of if mirror_of is not None else clip.labels.get("mirror_of"),
        "derived_joints": list(clip.derived_joints),
        "group": clip.labels.get("group", clip.id),
        "given_split": clip.labels.get("split"),
        "height_m": round(stature(clip.joints), 3) if clip.features is None else None,
        "digest": hashlib.sha1(np.round(clip.joints, 4).tobytes()).hexdigest(),
        "_joints": joints,
        "_features": feats,
    }


# ----------------------------------------------------------------------------- main

@dataclass
class _Stats:
    clips: int = 0
    mirrors: int = 0
    frames: int = 0
    frames_mirrors: int = 0
    files: int = 0
    skipped: int = 0
    duplicates: int = 0
    heights: list = field(default_factory=list)


def prepare(cfg: PrepareConfig) -> dict:
    """Run the whole preparation; returns the summary dict (also written to summary.json)."""
    from tqdm import tqdm

    t0 = time.time()
    if not cfg.sources:
        raise InputError("no --source given (use --source KIND=PATH)")
    if cfg.split_by not in SPLIT_UNITS:
        raise InputError(f"split_by {cfg.split_by!r}: use one of {', '.join(SPLIT_UNITS)}")
    out = Path(cfg.out)
    _prepare_out_dir(out, cfg.overwrite)
    options_base = S.SourceOptions(asf_fps=cfg.asf_fps)
    maps: dict[str, dict] = {}
    if cfg.joint_map:
        from motok_robot.data.clip import load_joint_map

        spec = cfg.joint_map if isinstance(cfg.joint_map, dict) else {"bvh": cfg.joint_map, "asf": cfg.joint_map}
        for k, p in spec.items():
            if k not in ("bvh", "asf"):
                raise InputError(f"--map {k}={p}: a joint map applies to the 'bvh' and 'asf' kinds only")
            maps[k] = load_joint_map(p)
    if cfg.texts:
        from motok_robot.data.texts import load_text_index

        options_base.text_index = load_text_index(cfg.texts)
    for kind, path in cfg.sources:
        if kind not in S.KINDS:
            raise InputError(f"unknown source kind {kind!r}; use one of {', '.join(S.KINDS)}")
        if not Path(path).exists():
            raise FileNotFoundError(f"{path}: no such file or folder (source {kind})")
        if kind == "bvh" and "bvh" not in maps:
            raise InputError("source kind 'bvh' needs --map FILE (a joint-map JSON, see docs/data.md)")

    for sub in ("features", "joints", "texts", "splits"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    index_f = (out / "index.jsonl").open("w")
    splits: dict[str, list[str]] = {"train": [], "val": [], "test": []}
    stats: dict[str, _Stats] = {}
    skipped: list[dict] = []
    duplicates: list[dict] = []
    seen_digest: dict[str, str] = {}
    sums = np.zeros(263)  # over the train split
    sumsq = np.zeros(263)
    count = 0
    all_sums, all_sumsq, all_count = np.zeros(263), np.zeros(263), 0  # fallback: every clip
    warnings: list[str] = []
    all_humanml = all(k == "humanml3d" for k, _ in cfg.sources)
    given_mean_std = None

    def handle(result, st: _Stats):
        nonlocal sums, sumsq, count, all_sums, all_sumsq, all_count
        if isinstance(result, S.Skipped):
            st.skipped += 1
            skipped.append({"file": result.file, "reason": result.reason})
            tqdm.write(f"warning: skipped {result.file}: {result.reason}", file=sys.stderr)
            return
        st.files += 1
        dropped = set()
        for r in result:
            if r["id"].startswith("mirror/"):
                continue
            if r["digest"] in seen_digest:
                st.duplicates += 1
                duplicates.append({"file": r["file"], "id": r["id"], "duplicate_of": seen_digest[r["digest"]]})
                dropped.add(r["id"])
            else:
                seen_digest[r["digest"]] = r["id"]
        for r in result:
            if r["id"] in dropped or (r["id"].startswith("mirror/") and r["mirror_of"] in dropped):
                continue
            split = r["given_split"] or split_of(split_key(r, cfg.split_by), cfg.seed)
            r["split"] = split
            name = file_name(r["id"])
            feats = r.pop("_features")
            np.save(out / "features" / f"{name}.npy", feats)
            np.save(out / "joints" / f"{name}.npy", r.pop("_joints"))
            (out / "texts" / f"{name}.txt").write_text("".join(t.replace("\n", " ") + "\n" for t in r["texts"]))
            f64 = feats.astype(np.float64)
            all_sums += f64.sum(0)
            all_sumsq += (f64 * f64).sum(0)
            all_count += f64.shape[0]
            if split == "train":
                sums += f64.sum(0)
                sumsq += (f64 * f64).sum(0)
                count += f64.shape[0]
            splits[split].append(r["id"])
            is_mirror = r["id"].startswith("mirror/")
            if is_mirror:
                st.mirrors += 1
                st.frames_mirrors += r["frames"]
            else:
                st.clips += 1
                st.frames += r["frames"]
                if r["height_m"] is not None:
                    st.heights.append(r["height_m"])
                    if not 1.2 <= r["height_m"] <= 2.3:
                        msg = f"{r['file']}: the body is {r['height_m']:.2f} m tall; check the units / joint map"
                        warnings.append(msg)
                        tqdm.write(f"warning: {msg}", file=sys.stderr)
            rec = {k: r[k] for k in ("id", "source", "licence", "fps", "frames", "seconds", "texts", "split", "file",
                                       "mirror_of", "derived_joints")}
            index_f.write(json.dumps(rec) + "\n")

    pool = ProcessPoolExecutor(max_workers=cfg.workers) if cfg.workers > 1 else None
    workdir = tempfile.TemporaryDirectory(prefix="motok-prepare-")  # HumanML3D archives only
    try:
        for i, (kind, path) in enumerate(cfg.sources):
            options = S.SourceOptions(
                joint_map=maps.get(kind),
                text_index=options_base.text_index,
                asf_fps=cfg.asf_fps,
            )
            if kind in ("cmu", "deepmimic"):
                csv_path = S.find_cmu_descriptions(path)
                if csv_path is not None:
                    from motok_robot.data.texts import load_cmu_descriptions

                    options.cmu_descriptions = load_cmu_descriptions(csv_path)
                elif kind == "cmu":
                    warnings.append(f"{path}: no cmu-descriptions.csv found next to it; CMU clips get no texts")
            if kind == "humanml3d":
                from motok_robot.data import humanml3d

                path = str(S.humanml3d_root(path, Path(workdir.name) / f"source{i}"))
                if all_humanml:
                    given_mean_std = humanml3d.load_mean_std(path)
            st = stats.setdefault(kind, _Stats())
            bar = tqdm(desc=f"{kind}: {Path(path).name}", unit="file", disable=True if cfg.progress is False else None)
            n_jobs = 0
            pending: deque = deque()  # results are handled in file order: deterministic output
            mirror = cfg.mirror
            jobs = S.iter_jobs(kind, path, options)
            for job in jobs:
                if cfg.limit is not None and n_jobs >= cfg.limit:
                    break
                n_jobs += 1
                if isinstance(job, S.Skipped):
                    handle(job, st)
                    bar.update(1)
                    continue
                if pool is None:
                    handle(process_job(job, options, mirror), st)
                    bar.update(1)
                    continue
                pending.append(pool.submit(process_job, job, options, mirror))
                while len(pending) >= 4 * cfg.workers:
                    handle(pending.popleft().result(), st)
                    bar.update(1)
            while pending:
                handle(pending.popleft().result(), st)
                bar.update(1)
            bar.close()
    finally:
        index_f.close()
        if pool is not None:
            pool.shutdown(cancel_futures=True)
        workdir.cleanup()

    total = sum(s.clips for s in stats.values())
    if total == 0:
        reasons = "; ".join(f"{s['file']}: {s['reason']}" for s in skipped[:5])
        raise InputError(f"nothing usable: 0 clips prepared from {len(cfg.sources)} source(s); " + (reasons or "no motion files found"))

    seen_files = sum(s.files + s.skipped for s in stats.values())
    if skipped and not cfg.allow_skips and len(skipped) > cfg.max_skip_share * seen_files:
        reasons = "; ".join(f"{s['file']}: {s['reason']}" for s in skipped[:3])
        raise InputError(f"{len(skipped)} of {seen_files} files skipped ({len(skipped) / seen_files:.0%}, more than "
                         f"{cfg.max_skip_share:.0%}); the dataset in {out} is left unfinished (no summary.json). First: "
                         f"{reasons}. Each skipped file was listed above; pass --allow-skips to accept them")
    for split, ids in splits.items():
        (out / "splits" / f"{split}.txt").write_text("".join(i + "\n" for i in ids))
    if given_mean_std is not None:
        mean, std = given_mean_std
        stats_from = "HumanML3D Mean.npy/Std.npy"
    else:
        stats_from = f"train split ({count} frames)"
        if count == 0:
            sums, sumsq, count = all_sums, all_sumsq, all_count
            stats_from = f"all clips ({count} frames): the train split is empty"
            warnings.append("the train split is empty (too few clips); mean/std are over all clips")
        mean = sums / count
        std = np.sqrt(np.maximum(sumsq / count - mean * mean, 0.0))
        std = np.maximum(std, STD_FLOOR)
    np.save(out / "mean.npy", mean.astype(np.float32))
    np.save(out / "std.npy", std.astype(np.float32))

    wall = time.time() - t0
    summary = {
        "out": str(out),
        "sources": {
            k: {
                "clips": s.clips,
                "mirrored_clips": s.mirrors,
                "files_read": s.files,
                "hours": round(s.frames / 20.0 / 3600.0, 4),
                "hours_with_mirrors": round((s.frames + s.frames_mirrors) / 20.0 / 3600.0, 4),
                "skipped_files": s.skipped,
                "duplicate_clips": s.duplicates,
                "stature_m_median": round(float(np.median(s.heights)), 3) if s.heights else None,
            }
            for k, s in stats.items()
        },
        "total_clips": total,
        "total_clips_with_mirrors": total + sum(s.mirrors for s in stats.values()),
        "total_hours": round(sum(s.frames for s in stats.values()) / 20.0 / 3600.0, 4),
        "splits": {k: len(v) for k, v in splits.items()},
        # the unit the split actually held out: HumanML3D brings its own split
        "split_by": "given" if all_humanml else cfg.split_by,
        "mean_std_from": stats_from,
        "skipped": skipped,
        "duplicates": duplicates,
        "warnings": warnings,
        "wall_time_s": round(wall, 2),
        "command": {"sources": [f"{k}={p}" for k, p in cfg.sources], "mirror": cfg.mirror, "seed": cfg.seed,
                    "split_by": cfg.split_by, "limit": cfg.limit, "texts": cfg.texts, "map": cfg.joint_map},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def _prepare_out_dir(out: Path, overwrite: bool) -> None:
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")
    if out.is_dir() and any(out.iterdir()):
        if not (out / "index.jsonl").exists() and not (out / "summary.json").exists():
            raise InputError(f"{out}: folder is not empty and is not a prepared dataset; choose another --out")
        if not overwrite:
            raise InputError(f"{out}: already holds a prepared dataset; pass --overwrite to replace it")
        for sub in ("features", "joints", "texts", "splits"):
            shutil.rmtree(out / sub, ignore_errors=True)
        for f in ("index.jsonl", "mean.npy", "std.npy", "summary.json"):
            (out / f).unlink(missing_ok=True)


def format_summary(summary: dict) -> str:
    """Human-readable table of a summary dict."""
    lines = [f"{'source':<11} {'clips':>7} {'mirrors':>8} {'hours':>8} {'skipped':>8} {'dupes':>6} {'stature m':>10}"]
    for k, s in summary["sources"].items():
        h = s["stature_m_median"]
        lines.append(
            f"{k:<11} {s['clips']:>7} {s['mirrored_clips']:>8} {s['hours']:>8.3f} {s['skipped_files']:>8} "
            f"{s['duplicate_clips']:>6} {('%.2f' % h) if h else '-':>10}"
        )
    lines.append(
        f"{'total':<11} {summary['total_clips']:>7} {summary['total_clips_with_mirrors'] - summary['total_clips']:>8} "
        f"{summary['total_hours']:>8.3f} {len(summary['skipped']):>8} {len(summary['duplicates']):>6}"
    )
    by = summary.get("split_by", "group")
    lines.append(f"splits (by {by}): {summary['splits']}  wall time: {summary['wall_time_s']:.1f} s  -> {summary['out']}")
    if summary["skipped"]:
        lines.append(f"skipped {len(summary['skipped'])} file(s):")
        lines += [f"  {s['file']}: {s['reason']}" for s in summary["skipped"]]
    if summary["duplicates"]:
        lines.append(f"{len(summary['duplicates'])} duplicate file(s) not written (same motion as an earlier clip):")
        lines += [f"  {d['file']} = {d['duplicate_of']}" for d in summary["duplicates"]]
    for w in summary["warnings"]:
        lines.append(f"warning: {w}")
    return "\n".join(lines)
