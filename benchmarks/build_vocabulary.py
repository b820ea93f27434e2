"""Rebuild ``models/vocabulary.json`` from the training data and calibrate its warning threshold.

Run (the prepared dataset the shipped models were trained on: the bandai, cmu and deepmimic
archives, split by group, as ``models/train_default_models.sh`` prepares it)::

    motok-robot data prepare --source bandai=../shared/datasets/bandai-namco-bvh.tar.xz \\
        --source cmu=../shared/datasets/cmu-asf-amc.tar.xz --source deepmimic=../shared/datasets/deepmimic.tar.xz \\
        --out runs/prepared
    python benchmarks/build_vocabulary.py --data runs/prepared

What it does, in order:

1. reads every train-split clip's captions as the planners' training read them (whitespace
   collapsed, at most 32 per clip), writes each with the subject "a person" (the data draws
   "a person", "someone", "the person", "a human", "a figure" at random) and counts the train clips
   (mirrors included) that carry it;
2. sets apart the *partial* captions: a clip captioned from a CMU trial description that lists
   several actions ("Playground - climb, sit, dangle legs, descend") also gets one sentence per
   action ("Someone sits."), which names a part of the clip and not what the clip shows;
3. counts the actions (Bandai content labels, mirrored clips under their mirrored label; the CMU
   description or DeepMimic motion name otherwise) and Bandai styles of the train clips;
4. embeds the captions with MiniLM (one thread) and keeps a cover of them (every caption within
   cosine similarity ``--cover`` of a kept one, the shortest kept first), the captions a prompt
   is compared with at generation;
5. calibrates the threshold on held-out captions: the val and test captions that are not train
   captions, each against the kept captions; the threshold is the ``--false-warning-rate``
   quantile of their nearest similarities (rounded down to 0.01), i.e. at most that share of
   them is warned about. Reported beside it, never used to choose it: a list of prompts no
   training clip shows (detection rate), the eight benchmark prompts and a list of paraphrases
   of trained actions (false warnings), and prompts near trained motion for the record.

Writes ``--out`` (default ``models/vocabulary.json``, checked by the loader before it is written)
and ``--results`` (default ``benchmarks/results/vocabulary_calibration.json``).
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(ROOT))

from common import write_json  # noqa: E402

from motok_robot.data.sources import content_of  # noqa: E402
from motok_robot.data.texts import SUBJECTS  # noqa: E402
from motok_robot.errors import InputError  # noqa: E402

MAX_TEXTS_PER_CLIP = 32  # the planners' training reads at most this many sentences per clip
DEFAULT_COVER = 0.9
DEFAULT_FALSE_WARNING_RATE = 0.02

#: prompts whose motion no training clip shows (detection rate)
OUT_OF_VOCABULARY = (
    "a person sits down", "a person swims", "a person rides a bicycle", "a person lies down on the floor",
    "a person plays the guitar", "a person drinks from a cup", "a person types on a keyboard",
    "a person does push-ups", "a person lifts a heavy box", "a person kneels down", "a person squats",
    "a person skis down a slope", "a person plays tennis", "a person juggles three balls",
    "a person brushes their teeth", "a person opens a door", "a person drives a car", "a person rows a boat",
    "a person rides a skateboard", "a person sits on a chair and reads", "a person does yoga",
    "a person throws a ball", "a person picks up a box from the floor", "a person sweeps the floor with a broom",
    "a person plays the piano",
)
#: trained actions in other words than the captions' (false warnings on natural phrasing)
PARAPHRASES = (
    "a man is walking", "someone strolls forward slowly", "a woman jogs", "a person sprints",
    "a person waves hello", "a person greets someone with a bow", "a person lifts his arms up",
    "a person does a kick", "a person dances happily", "a tired man walks", "a person walks backwards",
    "a person turns right while walking", "a person raises the left arm", "someone waves goodbye",
    "a person does a cartwheel", "a person jumps", "a person crawls on the floor", "a person does a backflip",
    "an old man walks slowly", "a person walks angrily",
)
#: motion some training clip shows in part (climbing a playground frame, a crouch before a flip,
#: hand stand kicks, run and jump over): reported, in neither rate
NEAR_TRAINED = (
    "a person climbs a ladder", "a person crouches down", "a person does a handstand",
    "a person jumps over an obstacle",
)

_SUBJECT = re.compile(r"^((?:[^,]*, )?)(" + "|".join(re.escape(s) for s in SUBJECTS) + r")\b", re.IGNORECASE)


def canonical_caption(text: str) -> str:
    """The caption with whitespace collapsed and its subject written "a person" ("Happily, someone
    walks." -> "Happily, a person walks."); objects ("bows to someone") are left alone."""
    text = " ".join(str(text).split())
    text = _SUBJECT.sub(lambda m: m.group(1) + "a person", text, count=1)
    return text[:1].upper() + text[1:]


def from_description(record: dict) -> bool:
    """Whether a clip's captions come from a CMU trial description (CMU, DeepMimic's CMU trials)."""
    base = record["id"].removeprefix("mirror/")
    return record.get("source") == "cmu" or base.startswith("deepmimic/cmu/")


def description_of(texts: list[str]) -> str | None:
    """The trial description among a clip's captions: the one sentence without a subject."""
    bare = [t for t in texts if not _SUBJECT.match(" ".join(t.split()))]
    return bare[0].rstrip(".") if len(bare) == 1 else None


def partial_captions(texts: list[str], description: str | None) -> set[str]:
    """The captions that name one action of a description listing several ("Playground - climb, sit,
    dangle legs, descend" -> "Someone sits."): those without its last action."""
    if not description:
        return set()
    actions = [p.strip().lower() for p in re.split(r"[,;]", description.split(" - ")[-1]) if p.strip()]
    if len(actions) < 2:
        return set()
    return {t for t in texts if actions[-1] not in t.lower()}


def action_of(record: dict, texts: list[str]) -> tuple[str, str, str | None]:
    """``(source, action, style)`` of a clip: its ``action`` field, the Bandai content (mirrored for
    a mirror) and style, the CMU description or the DeepMimic motion name, else its first caption."""
    source = record.get("source") or record["id"].split("/", 1)[0]
    base = record["id"].removeprefix("mirror/")
    if isinstance(record.get("action"), str) and record["action"].strip():
        return source, record["action"].strip(), None
    if source == "bandai":
        parts = base.rsplit("/", 1)[-1].split("_")
        return source, content_of(record["id"]), parts[2] if len(parts) == 4 else None
    if from_description(record):
        desc = description_of(texts)
        if desc:
            return source, desc, None
    if source == "deepmimic":
        name = re.sub(r"^humanoid3d_", "", base.rsplit("/", 1)[-1])
        name = re.sub(r"_mirror$", "", name)
        return source, re.sub(r"\d+$", "", name).rstrip("_").replace("_", " "), None
    return source, canonical_caption(texts[0]) if texts else base, None


def read_split(data: Path, split: str) -> list[tuple[dict, list[str]]]:
    """``(record, captions)`` of every clip of a split, captions as the planners' training reads them."""
    from motok_robot.data.dataset import PreparedDataset

    ds = PreparedDataset(data, split)
    out = []
    for cid in ds.clip_ids:
        texts = [t for t in (" ".join(str(x).split()) for x in ds.texts(cid)) if t][:MAX_TEXTS_PER_CLIP]
        out.append((ds.record(cid), texts))
    return out


def collect(train: list[tuple[dict, list[str]]]) -> dict:
    """Captions (whole and partial, canonical, with train clip counts), actions and styles."""
    whole: Counter = Counter()
    partial: Counter = Counter()
    actions: dict[tuple[str, str], dict] = {}
    styles: Counter = Counter()
    for record, texts in train:
        parts = partial_captions(texts, description_of(texts)) if from_description(record) else set()
        whole.update({canonical_caption(t) for t in texts if t not in parts})
        partial.update({canonical_caption(t) for t in parts})
        source, action, style = action_of(record, texts)
        entry = actions.setdefault((source, action), {"source": source, "action": action, "clips": 0,
                                                      "seconds": 0.0, "styles": Counter()})
        entry["clips"] += 1
        entry["seconds"] += float(record.get("seconds") or 0.0)
        if style:
            entry["styles"][style] += 1
            styles[style] += 1
    for caption in list(partial):
        if caption in whole:  # a whole caption elsewhere: it supports prompts
            del partial[caption]
    action_rows = [{**a, "seconds": round(a["seconds"], 1), "styles": dict(sorted(a["styles"].items()))}
                   for a in sorted(actions.values(), key=lambda a: (a["source"], -a["clips"], a["action"]))]
    return {"whole": whole, "partial": partial, "actions": action_rows, "styles": dict(sorted(styles.items()))}


def select_cover(captions: list[str], emb: np.ndarray, cover: float) -> tuple[list[int], np.ndarray]:
    """Indices of kept captions (greedily, in the given order) such that every caption
    has cosine similarity >= ``cover`` to a kept one, and each caption's nearest kept index."""
    best = np.full(len(captions), -2.0)
    owner = np.zeros(len(captions), dtype=np.int64)
    kept: list[int] = []
    for i in range(len(captions)):
        if best[i] >= cover:
            continue
        kept.append(i)
        sims = emb @ emb[i]
        closer = sims > best
        best[closer] = sims[closer]
        owner[closer] = i
    return kept, owner


def threshold_for(similarities: np.ndarray, rate: float) -> float:
    """The threshold that warns about at most ``rate`` of ``similarities``: their ``rate`` quantile
    rounded down to 0.01 (a prompt is far when its similarity is below the threshold)."""
    if not len(similarities):
        raise InputError("no held-out captions to calibrate the threshold on")
    return float(np.floor(np.quantile(similarities, rate, method="lower") * 100) / 100)


def nearest_rows(texts, emb: np.ndarray, table: np.ndarray, names: list[str], threshold: float) -> list[dict]:
    rows = []
    for text, e in zip(texts, emb):
        sims = table @ e
        order = np.argsort(-sims)[:3]
        best = round(float(sims[order[0]]), 4)  # rounded as generation records it
        rows.append({"text": text, "similarity": best, "warned": best < threshold,
                     "nearest": [[names[i], round(float(sims[i]), 4)] for i in order]})
    return rows


def file_sha16(path: Path) -> str:
    from motok_robot.planner.data import file_digest

    return file_digest(path, 16)


def build(data: Path, models: Path, cover: float = DEFAULT_COVER, rate: float = DEFAULT_FALSE_WARNING_RATE,
          encoder=None, benchmark_prompts: list[str] | None = None, progress: bool = True) -> tuple[dict, dict]:
    """The vocabulary (as written to JSON) and the calibration results."""
    t0 = time.time()
    if encoder is None:
        import torch

        torch.set_num_threads(1)
        from motok_robot.text import load_text_encoder

        encoder = load_text_encoder("minilm")
    splits = {s: read_split(data, s) for s in ("train", "val", "test")}
    if not splits["train"]:
        raise InputError(f"{data}: the train split is empty")
    found = collect(splits["train"])
    # the cover keeps the shortest wording first (the captions a warning names read like prompts)
    train_captions = sorted(found["whole"], key=lambda c: (len(c), -found["whole"][c], c))
    known = set(found["whole"]) | set(found["partial"])
    held_counts: Counter = Counter()  # held-out caption -> the val/test clips that carry it
    for split in ("val", "test"):
        for _record, texts in splits[split]:
            held_counts.update({canonical_caption(t) for t in texts})
    held_all = sorted(held_counts)
    held_new = [c for c in held_all if c not in known]
    bench = list(benchmark_prompts if benchmark_prompts is not None else _benchmark_prompts())
    lists = {"out_of_vocabulary": list(OUT_OF_VOCABULARY), "benchmark": bench, "paraphrases": list(PARAPHRASES),
             "near_trained": list(NEAR_TRAINED)}
    everything = list(dict.fromkeys(train_captions + held_all + [p for v in lists.values() for p in v]))
    if progress:
        print(f"embedding {len(everything)} captions and prompts with {encoder.name} ...", file=sys.stderr)
    emb = _embed(encoder, everything)
    row = {t: i for i, t in enumerate(everything)}
    train_emb = emb[[row[t] for t in train_captions]]
    kept, owner = select_cover(train_captions, train_emb, cover)
    table = train_emb[kept]
    names = [train_captions[i] for i in kept]
    stands_for: dict[int, set] = defaultdict(set)  # kept caption -> the train clips of the captions it covers
    clip_captions = [{canonical_caption(t) for t in texts} for _r, texts in splits["train"]]
    index_of = {c: i for i, c in enumerate(train_captions)}
    for clip, caps in enumerate(clip_captions):
        for c in caps:
            if c in index_of:
                stands_for[int(owner[index_of[c]])].add(clip)

    held_sims = {c: float((table @ emb[row[c]]).max()) for c in held_all}
    threshold = threshold_for(np.array([held_sims[c] for c in held_new]), rate)
    per_list = {name: nearest_rows(v, emb[[row[t] for t in v]], table, names, threshold) if v else []
                for name, v in lists.items()}
    held_rows = nearest_rows(held_new, emb[[row[t] for t in held_new]], table, names, threshold) if held_new else []
    uses = sum(held_counts.values())
    warned_uses = sum(n for c, n in held_counts.items() if held_sims[c] < threshold)

    def rate_of(rows, at):
        return round(sum(r["similarity"] < at for r in rows) / len(rows), 4) if rows else None

    curve = []
    for at in np.round(np.arange(0.50, 0.905, 0.02), 2):
        curve.append({"threshold": float(at),
                      "false_warnings_heldout_new": rate_of(held_rows, at),
                      "detected_out_of_vocabulary": rate_of(per_list["out_of_vocabulary"], at),
                      "warned_benchmark": rate_of(per_list["benchmark"], at),
                      "warned_paraphrases": rate_of(per_list["paraphrases"], at)})
    summary = {
        "threshold": threshold,
        "rule": f"the {rate:g} quantile of the held-out captions' nearest similarities, rounded down to 0.01",
        "heldout_new_captions": len(held_new),
        "false_warning_rate_heldout_new": rate_of(held_rows, threshold),
        "heldout_caption_uses": uses,
        "false_warning_rate_heldout_all": round(warned_uses / max(1, uses), 4),
        "detection_rate_out_of_vocabulary": rate_of(per_list["out_of_vocabulary"], threshold),
        "warned_benchmark_prompts": sum(r["warned"] for r in per_list["benchmark"]),
        "benchmark_prompts": len(per_list["benchmark"]),
        "false_warning_rate_paraphrases": rate_of(per_list["paraphrases"], threshold),
    }
    sources = Counter(r.get("source") for r, _t in splits["train"])
    vocabulary = {
        "format": "motok-vocabulary",
        "version": 1,
        "text_encoder": {"spec": "minilm", "name": encoder.name},
        "threshold": threshold,
        "captions": [[names[k], len(stands_for[i])] for k, i in enumerate(kept)],
        "partial": [[c, n] for c, n in sorted(found["partial"].items(), key=lambda x: (-x[1], x[0]))],
        "actions": found["actions"],
        "styles": found["styles"],
        "planners": {name: file_sha16(models / name / "model.safetensors")
                     for name in ("planner_masked", "planner_ar") if (models / name / "model.safetensors").is_file()},
        "data": {
            "split": "train",
            "clips": {"train": len(splits["train"]), "val": len(splits["val"]), "test": len(splits["test"])},
            "train_clips_by_source": dict(sorted(sources.items())),
            "distinct_captions": len(found["whole"]),
            "distinct_partial_captions": len(found["partial"]),
            "cover": cover,
            "built_by": "python benchmarks/build_vocabulary.py --data PREPARED",
        },
        "calibration": {k: summary[k] for k in ("rule", "false_warning_rate_heldout_new",
                                                  "false_warning_rate_heldout_all",
                                                  "detection_rate_out_of_vocabulary")}
        | {"results": "benchmarks/results/vocabulary_calibration.json"},
    }
    results = {
        "summary": summary,
        "curve": curve,
        "heldout_warned": [r for r in held_rows if r["warned"]],
        "heldout_lowest": sorted(held_rows, key=lambda r: r["similarity"])[:25],
        **per_list,
        "vocabulary": {"captions_compared": len(kept), "distinct_train_captions": len(train_captions),
                       "partial_captions": len(found["partial"]), "cover": cover},
        "wall_time_s": round(time.time() - t0, 1),
    }
    return vocabulary, results


def _embed(encoder, texts: list[str]) -> np.ndarray:
    out = []
    for start in range(0, len(texts), 256):
        out.append(encoder.encode(texts[start:start + 256]).float().numpy())
    emb = np.concatenate(out) if out else np.zeros((0, encoder.dim), np.float32)
    return emb / np.maximum(np.linalg.norm(emb, axis=1, keepdims=True), 1e-12)


def _benchmark_prompts() -> list[str]:
    path = ROOT / "examples" / "prompts_eight.txt"
    return [ln.strip() for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")]


def write_vocabulary(vocabulary: dict, out: Path) -> Path:
    """Check ``vocabulary`` with the loader's rules, then write it (compact, one caption a line)."""
    import json

    from motok_robot.text.vocabulary import MAX_FILE_BYTES, vocabulary_from_dict

    vocabulary_from_dict(vocabulary, str(out))
    lines = ["{"]
    items = list(vocabulary.items())
    for n, (key, value) in enumerate(items):
        end = "," if n < len(items) - 1 else ""
        if isinstance(value, list) and value:
            body = ",\n".join("  " + json.dumps(v, ensure_ascii=False) for v in value)
            lines.append(f"{json.dumps(key)}: [\n{body}\n]{end}")
        else:
            lines.append(f"{json.dumps(key)}: {json.dumps(value, ensure_ascii=False)}{end}")
    text = "\n".join(lines) + "\n}\n"
    if len(text.encode()) > MAX_FILE_BYTES:
        raise InputError(f"{out}: the vocabulary would be {len(text.encode()):,} bytes (at most {MAX_FILE_BYTES:,})")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(out)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", required=True, type=Path, help="the prepared dataset the models were trained on")
    p.add_argument("--models", type=Path, default=ROOT / "models", help="models folder whose planners it describes")
    p.add_argument("--out", type=Path, default=None, help="vocabulary file (default MODELS/vocabulary.json)")
    p.add_argument("--results", type=Path, default=ROOT / "benchmarks" / "results" / "vocabulary_calibration.json")
    p.add_argument("--cover", type=float, default=DEFAULT_COVER,
                   help=f"similarity within which a kept caption stands for another (default {DEFAULT_COVER})")
    p.add_argument("--false-warning-rate", type=float, default=DEFAULT_FALSE_WARNING_RATE,
                   help="share of held-out captions the threshold may warn about "
                        f"(default {DEFAULT_FALSE_WARNING_RATE})")
    args = p.parse_args(argv)
    if not 0.0 < args.cover < 1.0 or not 0.0 < args.false_warning_rate < 0.5:
        p.error("--cover must lie in (0, 1) and --false-warning-rate in (0, 0.5)")
    try:
        vocabulary, results = build(args.data, args.models, args.cover, args.false_warning_rate)
        out = write_vocabulary(vocabulary, args.out or args.models / "vocabulary.json")
    except InputError as exc:
        print(f"build_vocabulary: error: {exc}", file=sys.stderr)
        return 2
    write_json(args.results, results, threads=1)
    s = results["summary"]
    print(f"wrote {out} ({out.stat().st_size:,} bytes, {len(vocabulary['captions'])} captions compared, "
          f"{len(vocabulary['partial'])} partial) and {args.results}")
    print(f"threshold {s['threshold']:.2f}: false warnings {s['false_warning_rate_heldout_new']:.1%} of "
          f"{s['heldout_new_captions']} held-out captions new to training ({s['false_warning_rate_heldout_all']:.1%} "
          f"of all held-out caption uses), out-of-vocabulary prompts detected "
          f"{s['detection_rate_out_of_vocabulary']:.0%}, benchmark prompts warned {s['warned_benchmark_prompts']} of "
          f"{s['benchmark_prompts']}, paraphrases warned {s['false_warning_rate_paraphrases']:.0%}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
