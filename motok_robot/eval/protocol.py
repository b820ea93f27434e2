# Size (434 lines): one evaluation protocol: its inputs, metrics and repetitions, reviewed together.
"""The generation-evaluation protocol (HumanML3D style), independent of any model or CLI.

Inputs:

* ``clips``: the real test clips (:class:`EvalClip`: raw 263-d features ``[T, 263]`` and captions);
* an :class:`Embedder`: a text-motion evaluator (``embed_text(captions) -> [N, D]``,
  ``embed_motion(list of raw features [T_i, 263]) -> [N, D]``, ``min_frames``, ``max_frames``);
* ``generators``: ``{row name: GenerateFn}`` where ``GenerateFn(texts, lengths, seed)`` returns
  one raw feature array ``[lengths[i], 263]`` per text (``lengths`` in frames at 20 fps);
* optionally ``reference_clips`` (train-split clips, as many as test clips:
  :func:`sample_clips`) for the reference row's FID.

Each of ``cfg.repeats`` repeats draws, with its own seed, one caption and one window of
``min(T, max_frames)`` frames per test clip (clips shorter than ``min_frames`` or without a
caption are left out, as HumanML3D does), shuffles the order, and computes:

* ``real (test)`` (reference row): real windows with their captions. Its FID is between the
  test windows and windows of ``reference_clips`` (the train split): the FID two sets of real
  motions reach; without ``reference_clips`` it is left empty.
* ``shuffled texts`` (control row): the same real windows with the captions permuted so that
  no clip keeps its own caption. R-precision falls to chance (top-1 = 1/32) when the evaluator
  really matches text and motion.
* one row per generator: motions generated for the same captions and lengths; FID against the
  real test windows of the same repeat; R-precision, MM-dist against the captions; diversity of
  the generated set; multimodality over ``cfg.mm_texts`` captions generated ``cfg.mm_repeats``
  times each. Every generator gets the same sampling seed in a repeat, so a row's numbers do
  not depend on which other rows are evaluated with it.

Every metric is reported as mean and 95 % confidence half-width over the repeats
(:func:`motok_robot.eval.metrics.confidence_interval`). Numpy only: no torch here.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from motok_robot.errors import InputError
from motok_robot.eval import metrics
from motok_robot.eval.config import GenerationEvalConfig

FEATURE_DIM = 263
METRICS = ("fid", "r_precision_top1", "r_precision_top2", "r_precision_top3", "mm_dist", "diversity", "multimodality")
METRIC_TITLES = {
    "fid": "FID ↓",
    "r_precision_top1": "R-prec top-1 ↑",
    "r_precision_top2": "top-2 ↑",
    "r_precision_top3": "top-3 ↑",
    "mm_dist": "MM-dist ↓",
    "diversity": "Diversity →",
    "multimodality": "MModality ↑",
}
REFERENCE_ROW = "real (test)"
CONTROL_ROW = "shuffled texts"

#: ``(texts, lengths in frames, seed) -> [raw features [lengths[i], 263] per text]``
GenerateFn = Callable[[list[str], list[int], int], list[np.ndarray]]


class Embedder(Protocol):
    """A text-motion evaluator as the protocol sees it (see :mod:`motok_robot.eval.embedders`)."""

    min_frames: int
    max_frames: int

    def embed_text(self, captions: list[str]) -> np.ndarray:
        """Captions -> ``[N, D]`` embeddings."""

    def embed_motion(self, features: list[np.ndarray]) -> np.ndarray:
        """Raw (unnormalised) features, one ``[T_i, 263]`` array per motion -> ``[N, D]``."""


@dataclass
class EvalClip:
    """One real clip: ``features`` float32 ``[T, 263]`` (raw HumanML3D features) and its captions."""

    clip_id: str
    features: np.ndarray
    captions: list[str]


@dataclass
class MetricValue:
    """A metric over the repeats: ``mean``, 95 % ``ci95`` half-width and the per-repeat ``values``."""

    mean: float
    ci95: float
    values: list[float]

    def to_dict(self) -> dict:
        return {"mean": self.mean, "ci95": self.ci95, "values": self.values}


@dataclass
class Row:
    """One table row: ``kind`` is ``"reference"``, ``"control"`` or ``"model"``; metrics it does
    not apply to are absent (the table shows ``-``)."""

    name: str
    kind: str
    metrics: dict[str, MetricValue] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"name": self.name, "kind": self.kind, "metrics": {k: v.to_dict() for k, v in self.metrics.items()}}


@dataclass
class EvalResult:
    rows: list[Row]
    n_clips: int
    repeats: int
    diversity_times: int
    settings: dict

    def row(self, name: str) -> Row:
        for r in self.rows:
            if r.name == name:
                return r
        raise KeyError(name)

    def to_dict(self) -> dict:
        return {
            "n_clips": self.n_clips,
            "repeats": self.repeats,
            "diversity_times": self.diversity_times,
            "chance_r_precision_top1": 1.0 / self.settings.get("r_precision_batch", metrics.R_PRECISION_BATCH),
            "settings": self.settings,
            "rows": [r.to_dict() for r in self.rows],
        }


def clips_from_dataset(dataset, min_frames: int, max_clips: int | None = None) -> list[EvalClip]:
    """Clips of a split (anything with ``clip_ids``, ``features(id)``, ``texts(id)``, e.g.
    :class:`motok_robot.data.dataset.PreparedDataset`) that have a caption and at least
    ``min_frames`` frames, in split order (the first ``max_clips`` of them when given)."""
    out: list[EvalClip] = []
    for clip_id in dataset.clip_ids:
        captions = [" ".join(t.split()) for t in dataset.texts(clip_id) if t.strip()]
        feats = dataset.features(clip_id)
        if not captions or len(feats) < min_frames:
            continue
        feats = np.asarray(feats, np.float32)
        if feats.ndim != 2 or feats.shape[1] != FEATURE_DIM:
            raise InputError(f"clip {clip_id}: features must be [T, {FEATURE_DIM}], got {feats.shape}")
        out.append(EvalClip(clip_id, feats, captions))
        if max_clips is not None and len(out) >= max_clips:
            break
    return out


def sample_clips(dataset, min_frames: int, n: int, seed: int = 0) -> list[EvalClip]:
    """``n`` usable clips of a split in a seeded random order (fewer when the split has fewer):
    the reference set for the FID floor, as large as the test set so both FIDs have the same
    sample-size bias. Reads only the clips it keeps."""

    class _Shuffled:
        clip_ids = [dataset.clip_ids[i] for i in np.random.default_rng(seed).permutation(len(dataset.clip_ids))]
        features = staticmethod(dataset.features)
        texts = staticmethod(dataset.texts)

    return clips_from_dataset(_Shuffled(), min_frames, max_clips=n)


def content_matched_clips(test: Sequence[EvalClip], dataset, min_frames: int, seed: int = 0) -> list[EvalClip]:
    """Clips of ``dataset`` (a train split) with the content mix of ``test``: for each test clip
    in order, an unused clip of the same content (:func:`motok_robot.data.sources.content_of`)
    with at least ``min_frames`` frames, drawn in a seeded order; a content used up starts
    over (reuse), a content the split lacks draws from all its clips.  A split held out by
    content and style groups has a content mix unlike the train split's, and FID compares
    whole distributions: this reference asks whether real motions *of the same kinds* are
    close, which a random split (HumanML3D's) gives by construction."""
    from collections import defaultdict

    from motok_robot.data.sources import content_of

    rng = np.random.default_rng([seed, 11])
    pools: dict[str, list[str]] = defaultdict(list)
    for clip_id in dataset.clip_ids:
        pools[content_of(clip_id)].append(clip_id)
    everything = list(dataset.clip_ids)
    for pool in (*pools.values(), everything):
        rng.shuffle(pool)
    cursor: dict[str, int] = defaultdict(int)
    loaded: dict[str, EvalClip | None] = {}

    class _One:  # one clip of the split, read through clips_from_dataset's checks
        def __init__(self, clip_id: str):
            self.clip_ids = [clip_id]
            self.features, self.texts = dataset.features, dataset.texts

    def usable(clip_id: str) -> EvalClip | None:
        if clip_id not in loaded:
            found = clips_from_dataset(_One(clip_id), min_frames)
            loaded[clip_id] = found[0] if found else None
        return loaded[clip_id]

    out: list[EvalClip] = []
    for clip in test:
        key = content_of(clip.clip_id)
        pool = pools.get(key) or everything
        for _ in range(len(pool)):
            candidate = usable(pool[cursor[key] % len(pool)])
            cursor[key] += 1
            if candidate is not None:
                out.append(candidate)
                break
    return out


@dataclass
class Draw:
    """One repeat's sample of the test clips: order, captions and windows."""

    order: np.ndarray  # [N] clip indices
    captions: list[str]
    starts: np.ndarray  # [N] first frame of each window
    lengths: np.ndarray  # [N] frames

    def windows(self, clips: Sequence[EvalClip]) -> list[np.ndarray]:
        return [clips[i].features[s : s + n] for i, s, n in zip(self.order, self.starts, self.lengths)]


def draw(clips: Sequence[EvalClip], rng: np.random.Generator, max_frames: int) -> Draw:
    """Shuffle the clips, pick one caption and one window of ``min(T, max_frames)`` frames each."""
    order = rng.permutation(len(clips))
    captions, starts, lengths = [], [], []
    for i in order:
        clip = clips[i]
        n = min(len(clip.features), max_frames)
        starts.append(int(rng.integers(0, len(clip.features) - n + 1)))
        lengths.append(n)
        captions.append(clip.captions[int(rng.integers(len(clip.captions)))])
    return Draw(order, captions, np.asarray(starts), np.asarray(lengths))


def derangement(n: int, rng: np.random.Generator) -> np.ndarray:
    """A permutation of ``0..n-1`` with no fixed point (shuffle, then shift by one)."""
    if n < 2:
        raise ValueError("a derangement needs at least 2 elements")
    perm = rng.permutation(n)
    out = np.empty(n, np.int64)
    out[perm] = np.roll(perm, -1)
    return out


def derange_captions(captions: Sequence[str], rng: np.random.Generator) -> list[str]:
    """Captions permuted so that, wherever possible, no position keeps a caption equal to its own.

    A plain derangement of positions can still hand a clip the same caption text (mirrored
    clips and repeated descriptions); those positions are swapped with others where that
    makes both differ.
    """
    n = len(captions)
    perm = derangement(n, rng)
    out = [captions[j] for j in perm]
    for i in range(n):
        if out[i] != captions[i]:
            continue
        for j in rng.permutation(n):
            if out[j] != captions[i] and out[i] != captions[j]:
                out[i], out[j] = out[j], out[i]
                break
    return out


def generate_checked(
    name: str, fn: GenerateFn, texts: list[str], lengths: Sequence[int], seed: int, batch_size: int, progress=None
) -> list[np.ndarray]:
    """Call ``fn`` in chunks of ``batch_size`` (sorted by length so a batch holds similar lengths),
    check every output is finite ``[length, 263]``, return the motions in the input order."""
    lengths = [int(n) for n in lengths]
    order = np.argsort(lengths, kind="stable")
    out: list[np.ndarray | None] = [None] * len(texts)
    for chunk_no, start in enumerate(range(0, len(order), batch_size)):
        idx = order[start : start + batch_size]
        motions = fn([texts[i] for i in idx], [lengths[i] for i in idx], seed * 100_003 + chunk_no)
        if len(motions) != len(idx):
            raise InputError(f"generator {name!r} returned {len(motions)} motions for {len(idx)} texts")
        for i, motion in zip(idx, motions):
            motion = np.asarray(motion, np.float32)
            if motion.shape != (lengths[i], FEATURE_DIM):
                raise InputError(f"generator {name!r}: motion for text {texts[i]!r} has shape {motion.shape}, "
                                 f"expected ({lengths[i]}, {FEATURE_DIM})")
            if not np.isfinite(motion).all():
                raise InputError(f"generator {name!r}: motion for text {texts[i]!r} contains NaN or inf")
            out[i] = motion
        if progress is not None:
            progress.update(len(idx))
    return out  # type: ignore[return-value]


def _r_precision_dict(text_z: np.ndarray, motion_z: np.ndarray, batch: int) -> dict[str, float]:
    r = metrics.r_precision(text_z, motion_z, top_k=3, batch_size=batch)
    return {f"r_precision_top{k + 1}": float(r[k]) for k in range(3)}


def check_setup(clips: Sequence[EvalClip], cfg: GenerationEvalConfig) -> None:
    if cfg.repeats < 1:
        raise InputError(f"repeats must be >= 1, got {cfg.repeats}")
    if len(clips) < cfg.r_precision_batch:
        raise InputError(f"the test split has {len(clips)} usable clips (a caption and enough frames); "
                         f"R-precision needs at least {cfg.r_precision_batch}")
    if cfg.mm_repeats and cfg.mm_repeats < cfg.mm_times:
        raise InputError(f"mm_repeats ({cfg.mm_repeats}) must be >= mm_times ({cfg.mm_times}), or 0 to skip multimodality")


def run_protocol(
    clips: Sequence[EvalClip],
    embedder: Embedder,
    generators: dict[str, GenerateFn] | None = None,
    cfg: GenerationEvalConfig | None = None,
    reference_clips: Sequence[EvalClip] | None = None,
    progress: bool | None = None,
) -> EvalResult:
    """Run the protocol (see the module docstring) and return every row's metrics over the repeats."""
    from tqdm import tqdm

    cfg = cfg or GenerationEvalConfig()
    generators = dict(generators or {})
    clips = list(clips)
    check_setup(clips, cfg)
    for name in generators:
        if name in (REFERENCE_ROW, CONTROL_ROW):
            raise InputError(f"generator name {name!r} is reserved")
    n = len(clips)
    div_times = min(cfg.diversity_times, n)
    mm_texts = min(cfg.mm_texts, n) if cfg.mm_repeats and generators else 0
    values: dict[str, dict[str, list[float]]] = {REFERENCE_ROW: {}, CONTROL_ROW: {}, **{g: {} for g in generators}}

    def put(row: str, scores: dict[str, float]) -> None:
        for key, value in scores.items():
            values[row].setdefault(key, []).append(float(value))

    ref_z = None
    if reference_clips:
        ref_draw = draw(reference_clips, np.random.default_rng([cfg.seed, 999_983]), embedder.max_frames)
        ref_z = embedder.embed_motion(ref_draw.windows(reference_clips))
        if len(ref_z) < 2:
            ref_z = None

    per_repeat = len(generators) * (n + mm_texts * cfg.mm_repeats)
    bar = tqdm(total=cfg.repeats * per_repeat, desc="generating", unit="motion", disable=None if progress is None else not progress) if per_repeat else None
    for rep in range(cfg.repeats):
        rng = np.random.default_rng([cfg.seed, rep])
        sample = draw(clips, rng, embedder.max_frames)
        text_z = embedder.embed_text(sample.captions)
        real_z = embedder.embed_motion(sample.windows(clips))
        scores = _r_precision_dict(text_z, real_z, cfg.r_precision_batch)
        scores["mm_dist"] = metrics.matching_score(text_z, real_z)
        scores["diversity"] = metrics.diversity(real_z, div_times, np.random.default_rng([cfg.seed, rep, 1]))
        if ref_z is not None:
            scores["fid"] = metrics.fid(ref_z, real_z)
        put(REFERENCE_ROW, scores)

        shuffled = derange_captions(sample.captions, np.random.default_rng([cfg.seed, rep, 2]))
        shuffled_z = embedder.embed_text(shuffled)
        scores = _r_precision_dict(shuffled_z, real_z, cfg.r_precision_batch)
        scores["mm_dist"] = metrics.matching_score(shuffled_z, real_z)
        put(CONTROL_ROW, scores)

        mm_pick = np.random.default_rng([cfg.seed, rep, 3]).choice(n, mm_texts, replace=False) if mm_texts else []
        # one sampling seed per repeat for every generator (until 2026-11-27 each row's position
        # was part of it, so a model's numbers moved with the rows evaluated before it: the AR
        # planner's R-precision top-3 by 0.02); ``0`` keeps the first row's seeds as they were
        gen_seed = int(np.random.default_rng([cfg.seed, rep, 4, 0]).integers(2**31 - 1))
        for name, fn in generators.items():
            motions = generate_checked(name, fn, sample.captions, sample.lengths, gen_seed, cfg.batch_size, bar)
            gen_z = embedder.embed_motion(motions)
            scores = _r_precision_dict(text_z, gen_z, cfg.r_precision_batch)
            scores["fid"] = metrics.fid(real_z, gen_z)
            scores["mm_dist"] = metrics.matching_score(text_z, gen_z)
            scores["diversity"] = metrics.diversity(gen_z, div_times, np.random.default_rng([cfg.seed, rep, 5]))
            if mm_texts:
                texts = [sample.captions[i] for i in mm_pick for _ in range(cfg.mm_repeats)]
                lengths = [int(sample.lengths[i]) for i in mm_pick for _ in range(cfg.mm_repeats)]
                mm_motions = generate_checked(name, fn, texts, lengths, gen_seed + 1, cfg.batch_size, bar)
                mm_z = embedder.embed_motion(mm_motions).reshape(mm_texts, cfg.mm_repeats, -1)
                scores["multimodality"] = metrics.multimodality(mm_z, cfg.mm_times, np.random.default_rng([cfg.seed, rep, 6]))
            put(name, scores)
    if bar is not None:
        bar.close()

    rows = []
    for name, kind in [(REFERENCE_ROW, "reference"), (CONTROL_ROW, "control")] + [(g, "model") for g in generators]:
        row = Row(name, kind)
        for key in METRICS:
            if key in values[name]:
                vals = values[name][key]
                mean, half = metrics.confidence_interval(np.asarray(vals))
                row.metrics[key] = MetricValue(float(mean), float(half), vals)
        rows.append(row)
    settings = {
        "repeats": cfg.repeats, "r_precision_batch": cfg.r_precision_batch, "diversity_times": div_times,
        "mm_texts": mm_texts, "mm_repeats": cfg.mm_repeats if mm_texts else 0, "mm_times": cfg.mm_times,
        "seed": cfg.seed, "min_frames": embedder.min_frames, "max_frames": embedder.max_frames,
        "reference_fid": "test vs reference split" if ref_z is not None else None,
    }
    return EvalResult(rows, n, cfg.repeats, div_times, settings)


def format_value(value: MetricValue | None, digits: int = 3) -> str:
    if value is None:
        return "-"
    if not math.isfinite(value.mean):
        return "nan"
    return f"{value.mean:.{digits}f} ± {value.ci95:.{digits}f}"


def format_table(result: EvalResult, title: str | None = None) -> str:
    """A markdown table: one row per :class:`Row`, ``mean ± 95 % CI`` per metric."""
    header = ["", *(METRIC_TITLES[m] for m in METRICS)]
    lines = []
    if title:
        lines += [title, ""]
    lines.append("| " + " | ".join(header) + " |")
    lines.append("|" + "|".join(["---"] + ["---:"] * len(METRICS)) + "|")
    for row in result.rows:
        lines.append("| " + " | ".join([row.name, *(format_value(row.metrics.get(m)) for m in METRICS)]) + " |")
    s = result.settings
    lines.append("")
    lines.append(
        f"{result.n_clips} test clips, {result.repeats} repeat(s), mean ± 95 % CI; R-precision in batches of "
        f"{s['r_precision_batch']} (chance top-1 = {1 / s['r_precision_batch']:.3f}); diversity over "
        f"{result.diversity_times} pairs"
        + (f"; multimodality over {s['mm_texts']} texts x {s['mm_repeats']} generations" if s["mm_texts"] else "")
        + ("; reference FID = test vs train windows" if s.get("reference_fid") else "")
        + "."
    )
    return "\n".join(lines)
