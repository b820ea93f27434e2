"""Print the README's results table and the model card's tables from the JSON in ``benchmarks/results/``.

Run: python benchmarks/readme_table.py [TABLE ...]              # print tables (default: readme)
     python benchmarks/readme_table.py --check README.md models/MODEL_CARD.md
     python benchmarks/readme_table.py --write README.md models/MODEL_CARD.md
     python benchmarks/readme_table.py --import-batch OUT
         # after `motok-robot run --prompts examples/prompts_eight.txt --no-render --out OUT`:
         # writes benchmarks/results/robot_eight.json, the robot row's source

Tables: readme (the one results table), models, data, training, reconstruction, generation, behaviour, robot,
and sources (the command that writes each JSON the others read).
In a markdown file a generated table sits between ``<!-- table:NAME -->`` and ``<!-- /table -->``;
``--check`` exits 1 naming every table whose text differs from what the JSON give, ``--write``
replaces them. Every number comes from a file named in the table (``benchmarks/results/*.json``,
``models/*/metrics.csv``); a planner or tokenizer result measured on weights other than the ones in
``models/`` is refused with the file, the weights it measured and the shipped ones. Nothing heavy is
imported (no torch, no MuJoCo), so it runs in a second.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import re
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from common import REPO_ROOT, RESULTS_DIR, write_json  # noqa: E402

MODELS = REPO_ROOT / "models"
ROBOT_EIGHT = "robot_eight.json"
#: the same prompts over seeds 0-4 (optional: the row is left out without it)
ROBOT_SEEDS = "robot_eight_seeds0-4.json"
#: the same on robots other than the default, by robot (optional rows)
ROBOT_SEEDS_OTHER = {"op3_like": "robot_eight_seeds0-4_op3_like.json"}
GENERATION = {"masked": "generation_masked.json", "ar": "generation_ar.json"}
BEHAVIOUR = ("planner_behaviour.json", "planner_behaviour_seeds48-95.json")
RECONSTRUCTION = {"val split": "reconstruct_val.json", "test split": "reconstruct_test.json",
                  "acRNN (never seen)": "reconstruct_acrnn.json"}
DATA = {"training sources": "data_prepare.json", "acRNN": "data_prepare_acrnn.json"}
FEASIBILITY = {robot: f"feasibility_mocap_{robot}.json" for robot in ("op3", "op3_like")}
#: what each variant of the real-mocap benchmark adds (benchmarks/feasibility_mocap.py)
FEASIBILITY_VARIANTS = {"A": "retargeted", "B": "+ `feasible`", "C": "+ `feasible` 1.5x slower",
                        "D": "+ `feasible --own-steps`"}
GENERATE_SPEED = "bench_generate.json"
RETARGET = "retarget.json"
VALIDATE = "bench_validate.json"
PLAYBACK = {"SCHED_FIFO": "bench_playback_fifo.json", "normal priority": "bench_playback.json"}
WRITTEN_BY_SEEDS = ("motok-robot run --prompts examples/prompts_eight.txt --seed S --no-render --no-plots --out OUT_S "
                    "for S in 0-4, then readme_table.import_batches([OUT_0, ..., OUT_4], ...) (or ship_gate.py)")
#: the command that writes each source (printed by the ``sources`` table and named when one is missing)
WRITTEN_BY = {
    ROBOT_EIGHT: "motok-robot run --prompts examples/prompts_eight.txt --no-render --out OUT, then "
                 "python benchmarks/readme_table.py --import-batch OUT",
    ROBOT_SEEDS: WRITTEN_BY_SEEDS,
    **{name: f"motok-robot eval generation --data runs/prepared --planner {kind} --repeats 5 --mm-texts 20 "
             f"--mm-repeats 10 --no-train-reference --json benchmarks/results/{name}" for kind, name in GENERATION.items()},
    BEHAVIOUR[0]: "python benchmarks/planner_behaviour.py --seeds 48 --data runs/prepared",
    BEHAVIOUR[1]: f"python benchmarks/planner_behaviour.py --seeds 48 --first-seed 48 --data runs/prepared "
                  f"--out benchmarks/results/{BEHAVIOUR[1]}",
    RECONSTRUCTION["val split"]: "motok-robot eval reconstruct --data runs/prepared --split val --json benchmarks/results/"
                                 + RECONSTRUCTION["val split"],
    RECONSTRUCTION["test split"]: "motok-robot eval reconstruct --data runs/prepared --split test --json benchmarks/results/"
                                  + RECONSTRUCTION["test split"],
    RECONSTRUCTION["acRNN (never seen)"]: "motok-robot eval reconstruct --data runs/prepared_acrnn --split all --json "
                                          "benchmarks/results/" + RECONSTRUCTION["acRNN (never seen)"],
    DATA["training sources"]: "the summary.json of motok-robot data prepare --source bandai=... --source cmu=... "
                              "--source deepmimic=... --out runs/prepared",
    DATA["acRNN"]: "the summary.json of motok-robot data prepare --source acrnn=... --out runs/prepared_acrnn",
    **{name: f"python benchmarks/feasibility_mocap.py --robots {robot}" for robot, name in FEASIBILITY.items()},
    **{name: WRITTEN_BY_SEEDS.replace("--seed S", f"--seed S --robot {robot}") for robot, name in ROBOT_SEEDS_OTHER.items()},
    GENERATE_SPEED: "python benchmarks/bench_generate.py --planner masked",
    RETARGET: "python benchmarks/bench_retarget.py",
    VALIDATE: "python benchmarks/bench_validate.py --robot all --no-render",
    PLAYBACK["SCHED_FIFO"]: f"python benchmarks/bench_playback.py --fifo --out benchmarks/results/{PLAYBACK['SCHED_FIFO']}",
    PLAYBACK["normal priority"]: "python benchmarks/bench_playback.py",
}
#: the behaviour checks in the order the tables print them
CHECKS = ("walk", "walk_planted", "run_faster", "wave_right_hand", "raise_both_hands", "bow")
CHECK_HEADERS = ("walk", "foot planted", "run faster", "wave", "both hands", "bow and back")
PLANNER_NAMES = {"masked": "masked planner (default)", "ar": "AR planner"}
#: the shipped models' training runs: folder, what it is, the base run it was fine-tuned from
#: (its metrics.csv lives in git history at that commit), and how it ran
TRAINING = (
    ("tokenizer", "tokenizer", None, "2-core CPU, alone"),
    ("planner_masked", "masked planner", ("c9fed08", "2-core CPU"), "2-core CPU"),
    ("planner_ar", "AR planner", ("2ea1a80", "one H200 GPU shared by 4 runs"), "2-core CPU"),
    ("evaluator", "evaluator", None, "2-core CPU, beside the planners"),
)
MARK = re.compile(r"(<!-- table:(?P<name>[a-z]+) -->\n)(?P<body>.*?)(<!-- /table -->)", re.S)


class SourceError(Exception):
    """A source file is missing, unreadable or measured other weights than the shipped ones."""


# -- reading ------------------------------------------------------------------------------------------
def load(name: str, results: Path) -> dict:
    path = results / name
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SourceError(f"{path}: missing; written by: {WRITTEN_BY.get(name, 'see benchmarks/readme_table.py')}") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise SourceError(f"{path}: cannot read it as JSON ({exc})") from None


def shipped_digests(models: Path = MODELS) -> dict[str, str]:
    """``{run folder: first 12 hex digits of the sha256 of its model.safetensors}`` for the shipped models."""
    out = {}
    for folder in ("tokenizer", "planner_masked", "planner_ar"):
        weights = models / folder / "model.safetensors"
        if weights.is_file():
            h = hashlib.sha256()
            with open(weights, "rb") as fh:
                for chunk in iter(lambda: fh.read(1 << 20), b""):
                    h.update(chunk)
            out[folder] = h.hexdigest()[:12]
    return out


def model_digests(model_id: str) -> dict[str, str]:
    """``tokenizer=tokenizer@46bf...;planner=masked:planner_masked@1522...`` -> ``{"tokenizer": "46bf...",
    "planner": "1522..."}`` (the id ``generate`` and the benchmarks record)."""
    out = {}
    for part in str(model_id).split(";"):
        key, _, value = part.partition("=")
        if "@" in value:
            out[key.strip()] = value.rsplit("@", 1)[1].strip()
    return out


def require_shipped(model_id: str, kind: str, source: str, shipped: dict[str, str]) -> None:
    """Refuse a result whose model id names other tokenizer / planner weights than those in models/."""
    measured = model_digests(model_id)
    wanted = {"tokenizer": shipped.get("tokenizer"), "planner": shipped.get(f"planner_{kind}")}
    for key, digest in wanted.items():
        if digest is None or key not in measured:
            continue
        if not digest.startswith(measured[key][:12]) and not measured[key].startswith(digest):
            raise SourceError(f"{source}: measured {key} weights {measured[key]}, the shipped {kind} run has {digest}; "
                              f"re-measure: {WRITTEN_BY.get(source, 'see benchmarks/readme_table.py sources')}")


def load_average(data: dict) -> float | None:
    machine = data.get("machine") or {}
    load1 = machine.get("load_average_1_5_15") or [machine.get("load_average_1min")]
    return float(load1[0]) if load1[0] is not None else None


def measured_on(data: dict, with_load: bool = True) -> str:
    """``2026-12-01, load 0.3`` from a result's machine description (what is known of it); the load
    is left out where the machine was described after the work (an imported batch)."""
    machine = data.get("machine") or {}
    parts = []
    date = machine.get("date_utc")
    if date:
        parts.append(str(date)[:10])
    load1 = load_average(data) if with_load else None
    if load1 is not None:
        parts.append(f"load {load1:.1f}")
    return ", ".join(parts) or "-"


def fmt(value: float, digits: int = 3) -> str:
    return f"{value:.{digits}f}"


def metric(row: dict, name: str, digits: int = 3) -> str:
    m = row["metrics"].get(name)
    if not m or m.get("mean") is None:
        return "-"
    ci = m.get("ci95")
    return f"{m['mean']:.{digits}f} ± {ci:.{digits}f}" if ci is not None else f"{m['mean']:.{digits}f}"


def generation_rows(results: Path, shipped: dict[str, str]) -> tuple[dict, dict[str, dict]]:
    """(the reference rows of the masked file: ``{name: row}``, ``{kind: the planner's row}``)."""
    reference, planners = {}, {}
    for kind, name in GENERATION.items():
        data = load(name, results)
        for row in data["rows"]:
            if row.get("kind") in ("reference", "control") and kind == "masked":
                reference[row["name"]] = row
            elif row.get("kind") not in ("reference", "control"):
                require_shipped(data.get("models", {}).get(kind, ""), kind, name, shipped)
                planners[kind] = {**row, "_file": name, "_data": data}
    missing = [k for k in GENERATION if k not in planners]
    if missing:
        raise SourceError(f"{results}: no generation row for {', '.join(missing)}")
    return reference, planners


def behaviour_counts(results: Path, shipped: dict[str, str]) -> tuple[dict[str, dict], dict[str, str], str]:
    """``{kind: {check: passes}}`` summed over the seed ranges of :data:`BEHAVIOUR`, the real-clip
    rows (``{row name: "13/15 bows, 374/434 both hands"}``) and the seed range ``"0-95"``."""
    counts: dict[str, dict] = {}
    seeds: list[int] = []
    real: dict[str, str] = {}
    for name in BEHAVIOUR:
        data = load(name, results)
        first, n = int(data["first_seed"]), int(data["seeds"])
        seeds += list(range(first, first + n))
        for row in data["rows"]:
            kind = row.get("planner")
            if kind in PLANNER_NAMES and row.get("decoder_seed") is None:
                require_shipped(row.get("model", ""), kind, name, shipped)
                per = counts.setdefault(kind, {c: 0 for c in CHECKS} | {"seeds": 0})
                for seed in row["seeds"]:
                    per["seeds"] += 1
                    for check in CHECKS:
                        per[check] += bool(seed[check]["passed"])
            elif kind is None and "bow" in row:
                real[row["rows"]] = f"bows {row['bow']}, both hands {row['raise_both_hands']}"
    if sorted(seeds) != list(range(min(seeds), max(seeds) + 1)) or len(set(seeds)) != len(seeds):
        raise SourceError(f"{', '.join(BEHAVIOUR)}: the seed ranges overlap or leave a gap ({min(seeds)}-{max(seeds)})")
    return counts, real, f"{min(seeds)}-{max(seeds)}"


def robot_rows(results: Path) -> tuple[dict, list[dict]]:
    data = load(ROBOT_EIGHT, results)
    return data, data["rows"]


def truthy(value) -> bool:
    return str(value).strip().lower() in ("true", "1", "yes")


def failing(row: dict) -> list[str]:
    return [c for c in str(row.get("failed_checks") or "").replace(",", ";").split(";") if c]


# -- tables -------------------------------------------------------------------------------------------
def markdown(headers: tuple[str, ...], rows: list[tuple], align: str | None = None) -> str:
    """A markdown table; ``align`` is one character per column, ``l`` or ``r``."""
    align = align or "l" * len(headers)
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---:" if a == "r" else "---" for a in align) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def source(*names: str) -> str:
    return ", ".join(f"`{n}`" for n in names)


def robot_of(rows: list[dict]) -> str:
    """The robot of a prompt batch's rows (files written before rows named it: op3_like)."""
    robots = sorted({r.get("robot") or "op3_like" for r in rows})
    if len(robots) != 1:
        raise SourceError(f"the rows of one robot benchmark name several robots: {', '.join(robots)}")
    return robots[0]


def seeds_row(data: dict, name: str) -> tuple:
    """The row of the 8 prompts over several seeds on one robot."""
    cells = data["rows"]
    seeds = sorted({int(r["seed"]) for r in cells})
    per_prompt = {}
    for r in cells:
        per_prompt[r["text"]] = per_prompt.get(r["text"], 0) + truthy(r.get("passed"))
    worst = ", ".join(f"{_short(t)} {n}/{len(seeds)}" for t, n in per_prompt.items() if n < len(seeds))
    return (f"text → robot, `{robot_of(cells)}`", f"the same prompts over seeds {seeds[0]}-{seeds[-1]}, every default",
            f"**{sum(truthy(r.get('passed')) for r in cells)} of {len(cells)}**"
            + (f" (fewer than every seed: {worst})" if worst else ""),
            measured_on(data, with_load=False), source(name))


def feasibility_row(data: dict, robot: str, name: str) -> tuple:
    """The row of the real-mocap benchmark on one robot: passing (falls) per variant and group."""
    summary = {(r["group"], r["variant"][0]): r for r in data["summary"]}
    variants = [v for v in FEASIBILITY_VARIANTS if ("locomotion", v) in summary]
    loco = [summary[("locomotion", v)] for v in variants]
    other = [summary[("other", v)] for v in variants]
    return (f"real mocap → robot, `{robot}`", f"{loco[0]['clips']} locomotion / {other[0]['clips']} other clips "
            "passing (falls): " + " / ".join(FEASIBILITY_VARIANTS[v] for v in variants),
            " / ".join(f"{r['passed']} ({r['fell']})" for r in loco) + " and " + " / ".join(str(r["passed"]) for r in other),
            measured_on(newest_machine(data)), source(name))


def newest_machine(data: dict) -> dict:
    """``data`` with the latest of its machine descriptions as ``machine``: a file whose variants
    were measured at different times keeps each run's in ``machine_<VARIANT>``."""
    machines = [m for k, m in data.items() if (k == "machine" or k.startswith("machine_")) and isinstance(m, dict)]
    return {**data, "machine": max(machines, key=lambda m: str(m.get("date_utc", "")), default={})}


def table_readme(results: Path, shipped: dict[str, str]) -> str:
    rows = []
    robot_data, robot = robot_rows(results)
    passed = [r for r in robot if truthy(r.get("passed"))]
    fails = ", ".join(_short(r["text"]) for r in robot if not truthy(r.get("passed")))
    rows.append((f"text → robot, `{robot_of(robot)}`", f"the {len(robot)} prompts of `examples/prompts_eight.txt`, "
                 "seed 0, every default: clips passing every check",
                 f"**{len(passed)} of {len(robot)}**" + (f" (failing: {fails})" if fails else ""),
                 measured_on(robot_data, with_load=False), source(ROBOT_EIGHT)))
    for name in (ROBOT_SEEDS, *ROBOT_SEEDS_OTHER.values()):
        if (results / name).is_file():
            rows.append(seeds_row(load(name, results), name))
    reference, planners = generation_rows(results, shipped)
    real = reference.get("real (test)")
    for kind, row in planners.items():
        real_note = f" (real test motion: R-prec {metric(real, 'r_precision_top3')[:5]})" if real and kind == "masked" else ""
        rows.append((PLANNER_NAMES[kind], "test split, the project's evaluator: FID ↓ / R-precision top-3 ↑",
                     f"{metric(row, 'fid')} / {metric(row, 'r_precision_top3')}{real_note}",
                     measured_on(row["_data"]), source(row["_file"])))
    counts, _, span = behaviour_counts(results, shipped)
    when = measured_on(load(BEHAVIOUR[-1], results))
    for kind in PLANNER_NAMES:
        c = counts[kind]
        rows.append((PLANNER_NAMES[kind], f"behaviour checks passed over seeds {span}: " + " / ".join(CHECK_HEADERS),
                     " / ".join(str(c[k]) for k in CHECKS), when, source(*BEHAVIOUR)))
    recon = {label: load(name, results) for label, name in RECONSTRUCTION.items()}
    _require_tokenizer(recon, shipped)
    rows.append(("tokenizer", "whole-clip joint error after root alignment (MPJPE), val / test / acRNN (never seen)",
                 " / ".join(f"{d['mpjpe_root_aligned_cm']:.2f} cm" for d in recon.values()),
                 measured_on(recon["val split"]), source(*RECONSTRUCTION.values())))
    for robot, name in FEASIBILITY.items():
        if robot == "op3_like" or (results / name).is_file():
            rows.append(feasibility_row(load(name, results), robot, name))
    gen = load(GENERATE_SPEED, results)
    require_shipped(gen.get("model", ""), gen.get("planner", "masked"), GENERATE_SPEED, shipped)
    longest = max(gen["rows"], key=lambda r: r["seconds"])
    rows.append(("text → motion speed", f"a {longest['seconds']:g} s clip, median of {gen.get('repeat', '?')}, "
                 f"{(gen.get('machine') or {}).get('threads', '?')} threads",
                 f"{longest['total_ms'] / 1000:.2f} s", measured_on(gen), source(GENERATE_SPEED)))
    rt = load(RETARGET, results)
    speed = rt["speed_10s"]["op3_like"]
    load_after = speed.get("load_average_after")
    rows.append(("retargeting speed", f"{len(speed['clips'])} real 10 s walks onto `op3_like`, one process: "
                 "frames per second of wall time / of CPU time",
                 f"{speed['fps_wall']:.0f} / {speed['fps_cpu']:.0f} frames/s",
                 f"load {load_after[0]:.1f}" if load_after else "-", source(RETARGET)))
    val = load(VALIDATE, results)
    rtf = {r["robot"]: r["validate_no_render_rtf"] for r in val["results"]}
    rows.append(("validation speed", "10 s clip, closed-loop physics, no video: times real time",
                 ", ".join(f"{rtf[k]:.0f}x `{k}`" for k in sorted(rtf)), measured_on(val), source(VALIDATE)))
    jitter = {}
    for label, name in PLAYBACK.items():
        data = load(name, results)
        values = sorted(r["jitter_p99_ms"] for r in data["runs"])
        jitter[label] = (values[len(values) // 2], data)
    first = next(iter(jitter.values()))[1]
    rows.append(("playback", f"{first.get('servos', '?')} emulated servos at {first.get('rate_hz', '?'):g} Hz: p99 tick "
                 f"jitter (median of {len(first['runs'])} runs), " + " / ".join(jitter),
                 " / ".join(f"{j:.3f} ms" if j < 0.1 else f"{j:.1f} ms" for j, _ in jitter.values()),
                 measured_on(first), source(*PLAYBACK.values())))
    return markdown(("stage", "measure", "result", "measured", "from `benchmarks/results/`"), rows)


def _short(text: str) -> str:
    return re.sub(r"^a person ", "", str(text)).strip()


def _require_tokenizer(recon: dict[str, dict], shipped: dict[str, str]) -> None:
    """``eval reconstruct`` records the tokenizer folder, not its digest: it must be the shipped
    ``models/tokenizer`` (measured on another run, the file is refused)."""
    for label, data in recon.items():
        folder = Path(str(data.get("tokenizer", "")))
        if folder.parts[-2:] != ("models", "tokenizer"):
            raise SourceError(f"{RECONSTRUCTION[label]}: measured the tokenizer in {folder}, not the shipped models/tokenizer")


def table_reconstruction(results: Path, shipped: dict[str, str]) -> str:
    recon = {label: load(name, results) for label, name in RECONSTRUCTION.items()}
    _require_tokenizer(recon, shipped)
    rows = [(label, d["clips"], fmt(d["mpjpe_root_aligned_cm"], 2), fmt(d["mpjpe_cm"], 1),
             fmt(d["root_trajectory_error_cm"], 1),
             f"{d['foot_skating_ratio_reconstructed']:.3f} / {d['foot_skating_ratio_original']:.3f}",
             f"{100 * d['codebook_usage']:.1f} %") for label, d in recon.items()]
    return markdown(("data", "clips", "MPJPE aligned cm", "MPJPE world cm", "root path error cm",
                     "foot skating recon / real", "codebook usage"), rows, "lrrrrrr")


def table_generation(results: Path, shipped: dict[str, str]) -> str:
    reference, planners = generation_rows(results, shipped)
    names = ("fid", "r_precision_top1", "r_precision_top2", "r_precision_top3", "mm_dist", "diversity", "multimodality")
    rows = [(name, *(metric(row, n) for n in names)) for name, row in reference.items()]
    rows += [(kind, *(metric(row, n) for n in names)) for kind, row in planners.items()]
    return markdown(("", "FID ↓", "R-prec top-1 ↑", "top-2 ↑", "top-3 ↑", "MM-dist ↓", "Diversity →", "MModality ↑"),
                    rows, "lrrrrrrr")


def table_behaviour(results: Path, shipped: dict[str, str]) -> str:
    counts, real, span = behaviour_counts(results, shipped)
    rows = [(f"{PLANNER_NAMES[k]}, seeds {span}", *(counts[k][c] for c in CHECKS)) for k in PLANNER_NAMES]
    for name, text in real.items():
        bows = re.search(r"bows (\S+), both hands (\S+)", text)
        rows.append((name, "", "", "", "", bows.group(2).replace("/", " of "), bows.group(1).replace("/", " of ")))
    return markdown(("", *CHECK_HEADERS), rows, "lrrrrrr")


def table_robot(results: Path, shipped: dict[str, str]) -> str:
    data, robot = robot_rows(results)
    rows = []
    for r in robot:
        slower = r.get("retime_factor")
        rows.append((r["text"], r.get("seconds", "-"), "**yes**" if truthy(r.get("passed")) else "no",
                     ", ".join(failing(r)) or ("-" if truthy(r.get("passed")) else r.get("error") or "?"),
                     "yes" if r.get("balance_repair_kept") else "-",
                     f"{float(slower):.3g}x" if slower not in (None, "") else "1x",
                     _seconds(r, "retarget_s"), _seconds(r, "balance_s"), _seconds(r, "validate_s"), _seconds(r, "total_s")))
    return markdown(("prompt", "clip s", "passed", "failing checks", "balance repair kept", "played slower",
                     "retarget s", "balance s", "validate s", "total s"), rows, "lrlllrrrrr")


def _seconds(row: dict, key: str) -> str:
    value = row.get(key)
    return f"{float(value):.1f}" if value not in (None, "") else "-"


def table_training(results: Path, shipped: dict[str, str], models: Path = MODELS) -> str:
    rows, total = [], 0.0
    for folder, what, base, how in TRAINING:
        config = json.loads((models / folder / "config.json").read_text(encoding="utf-8"))
        train = config.get("train") or config.get("evaluator") or {}
        last = _last_row(models / folder / "metrics.csv")
        minutes = float(last["seconds"]) / 60
        steps = f"{int(float(last['step'])):,} x {train.get('batch_size', '?')}"
        time_text = f"{minutes:.1f} min ({how})"
        base_last = None
        if base is not None:
            commit, where = base
            base_last = _last_row_at(commit, f"models/{folder}/metrics.csv")
            if base_last is not None:
                steps = f"{int(float(base_last['step'])):,} x {train.get('batch_size', '?')}, then {steps} (fine-tune)"
                time_text = f"{float(base_last['seconds']) / 60:.1f} min ({where}) + {time_text}"
        rows.append((what, steps, time_text, _final(folder, last, train)))
        total += minutes + (float(base_last["seconds"]) / 60 if base is not None and base_last is not None else 0.0)
    rows.append(("**sum of the rows**", "", f"{total / 60:.1f} h", ""))
    return markdown(("model", "steps x batch", "wall time", "final validation"), rows)


def _final(folder: str, last: dict, train: dict) -> str:
    if folder == "tokenizer":
        return f"{float(last['val_mpjpe_cm']):.2f} cm MPJPE on {train.get('val_clips', '?')} fixed val windows"
    if folder == "evaluator":
        return f"R-precision top-1/2/3 {float(last['val_r1']):.2f} / {float(last['val_r2']):.2f} / {float(last['val_r3']):.2f}"
    return (f"val loss {float(last['val_loss']):.3f}, token accuracy {float(last['val_accuracy']):.3f}, "
            f"length within one token {float(last['val_length_within_1']):.2f}")


def _last_row(path: Path) -> dict:
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise SourceError(f"{path}: no rows")
    return rows[-1]


def _last_row_at(commit: str, path: str) -> dict | None:
    """The last row of ``path`` as committed at ``commit`` (None without git or that commit)."""
    try:
        text = subprocess.run(["git", "show", f"{commit}:{path}"], cwd=REPO_ROOT, capture_output=True, text=True,
                              timeout=30, check=True).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    rows = list(csv.DictReader(text.splitlines()))
    return rows[-1] if rows else None


def safetensors_parameters(path: Path) -> int:
    """Number of stored values in a ``.safetensors`` file, from its JSON header (no weights read)."""
    with open(path, "rb") as fh:
        size = int.from_bytes(fh.read(8), "little")
        if not 0 < size < 1 << 26:
            raise SourceError(f"{path}: not a safetensors file (header size {size})")
        header = json.loads(fh.read(size))
    total = 0
    for name, entry in header.items():
        if name == "__metadata__":
            continue
        count = 1
        for dim in entry["shape"]:
            count *= int(dim)
        total += count
    return total


#: what each shipped model folder holds and what needs it (the models table's text columns)
MODEL_FOLDERS = {
    "tokenizer": ("MoTok tokenizer: conv encoder (4x temporal downsampling, 5 tokens/s at 20 fps), one codebook "
                  "of 512 entries, conv conditioning decoder and conv diffusion denoiser (x0 prediction, cosine "
                  "schedule, DDIM, 20 steps)", "generation"),
    "planner_masked": ("masked discrete-diffusion planner (the default): bidirectional transformer after a 5-tap "
                       "convolution over the token embeddings, each token told its distance to the sequence end; "
                       "conditioned on the MiniLM sentence feature, action labels and local conditions", "generation"),
    "planner_ar": ("autoregressive planner: causal transformer, 6 layers, the same conditioning, the count of tokens "
                   "left given in the last 8", "`--planner ar`"),
    "evaluator": ("contrastive text-motion evaluator for FID and R-precision", "`eval generation` only"),
}


def table_models(results: Path, shipped: dict[str, str], models: Path = MODELS) -> str:
    rows = []
    for folder, (what, needed_for) in MODEL_FOLDERS.items():
        weights = models / folder / "model.safetensors"
        if not weights.is_file():
            raise SourceError(f"{weights}: missing")
        h = hashlib.sha256(weights.read_bytes()).hexdigest()[:16]
        rows.append((f"`{folder}/`", what, needed_for, f"{safetensors_parameters(weights) / 1e6:.2f} M",
                     f"{weights.stat().st_size / 1e6:.1f} MB", f"`{h}`"))
    return markdown(("folder", "model", "needed for", "values stored", "file size", "sha256 (first 16)"), rows, "lllrrl")


def table_data(results: Path, shipped: dict[str, str]) -> str:
    rows = []
    for label, name in DATA.items():
        data = load(name, results)
        for source_name, s in data["sources"].items():
            rows.append((source_name, f"{s['clips']:,} (+{s['mirrored_clips']:,})", f"{s['hours']:.2f}",
                         s["skipped_files"], "never trained on: the unseen set of the reconstruction table"
                         if label == "acRNN" else "train / val / test"))
        if label != "acRNN":
            split = data["splits"]
            rows.append(("**split** (clips incl. mirrors; a clip and its mirror share a split)",
                         " / ".join(f"{split[k]:,} {k}" for k in ("train", "val", "test")),
                         f"{data['total_hours']:.2f}", "", f"by {data.get('split_by', '?')}"))
    return markdown(("source", "clips (+ mirrors)", "hours without mirrors", "files skipped", "used for"), rows, "lrrrl")


def table_sources(results: Path, shipped: dict[str, str]) -> str:
    return markdown(("`benchmarks/results/`", "written by"), [(f"`{n}`", f"`{c}`") for n, c in WRITTEN_BY.items()])


TABLES = {"readme": table_readme, "sources": table_sources, "models": table_models, "data": table_data, "training": table_training, "reconstruction": table_reconstruction,
          "generation": table_generation, "behaviour": table_behaviour, "robot": table_robot}


def render(name: str, results: Path = RESULTS_DIR, shipped: dict[str, str] | None = None) -> str:
    if name not in TABLES:
        raise SourceError(f"unknown table {name!r}; tables: {', '.join(TABLES)}")
    return TABLES[name](results, shipped_digests() if shipped is None else shipped)


# -- markdown files -----------------------------------------------------------------------------------
def refresh(text: str, results: Path = RESULTS_DIR, shipped: dict[str, str] | None = None) -> tuple[str, list[str]]:
    """``text`` with every marked table regenerated, and the names of the tables that changed."""
    changed: list[str] = []
    cache: dict[str, str] = {}

    def one(match: re.Match) -> str:
        name = match.group("name")
        if name not in cache:
            cache[name] = render(name, results, shipped)
        if match.group("body") != cache[name]:
            changed.append(name)
        return match.group(1) + cache[name] + match.group(4)

    return MARK.sub(one, text), changed


# -- importing a batch run ----------------------------------------------------------------------------
STAGE_TIMES = ("generate", "retarget", "feasibility", "validate", "balance", "retime", "plots", "render", "playback", "total")


def import_batches(folders: list[Path], out: Path, code: str | None = None) -> Path:
    """The clips of ``run --prompts`` output folders (each clip's ``pipeline.json``, in folder order;
    several folders are joined, e.g. when a batch was stopped and its remaining prompts run again)
    -> the robot JSON. ``code``: the commit whose code ran the batch, when it is not this checkout's
    (``machine.commit`` records the checkout the import ran in)."""
    rows, models = [], set()
    for folder in folders:
        records = sorted(p for p in Path(folder).glob("*/pipeline.json") if not p.parent.name.startswith("."))
        if not records:
            raise SourceError(f"{folder}: no clip folder with a pipeline.json (a run --prompts --out folder?)")
        for record in records:
            result = json.loads(record.read_text(encoding="utf-8"))
            times = result.get("timings_s") or {}
            rows.append({"text": result["text"], "robot": result.get("robot"), "seconds": result.get("seconds"),
                         "seed": result.get("seed"),
                         "folder": f"{Path(folder).name}/{record.parent.name}", "passed": bool(result["passed"]),
                         "failed_checks": ";".join(result.get("failed_checks") or []),
                         "playback": (result.get("playback") or {}).get("status"),
                         **{f"{k}_s": times[k] for k in STAGE_TIMES if k in times},
                         "retime_factor": result.get("retime_factor"),
                         "balance_repair_kept": bool(result.get("zmp_weight")),  # the kept trajectory's ZMP weight (0: none)
                         "notes": result.get("notes", [])})
            if result.get("model"):
                models.add(str(result["model"]))
    payload = {"benchmark": "motok-robot run --prompts FILE --no-render --out OUT, every default; rows from "
                            "each clip's pipeline.json (" + ", ".join(str(f) for f in folders) + ")",
               "models": sorted(models), "code_commit": code, "rows": rows}
    return write_json(out, payload)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("tables", nargs="*", default=None, help=f"tables to print: {', '.join(TABLES)} (default readme)")
    parser.add_argument("--check", nargs="+", type=Path, metavar="FILE", help="fail when a marked table in FILE is stale")
    parser.add_argument("--write", nargs="+", type=Path, metavar="FILE", help="regenerate the marked tables in FILE")
    parser.add_argument("--import-batch", nargs="+", type=Path, metavar="OUT",
                        help=f"turn run --prompts output folders into benchmarks/results/{ROBOT_EIGHT}")
    parser.add_argument("--code", metavar="REV", help="with --import-batch: the commit whose code ran the batch")
    parser.add_argument("--results", type=Path, default=RESULTS_DIR, help="results folder (default benchmarks/results)")
    args = parser.parse_args(argv)
    try:
        if args.import_batch:
            print(f"wrote {import_batches(args.import_batch, args.results / ROBOT_EIGHT, args.code)}")
            return 0
        stale = []
        for path in args.check or args.write or []:
            text = path.read_text(encoding="utf-8")
            new, changed = refresh(text, args.results)
            if args.write and new != text:
                path.write_text(new, encoding="utf-8")
            stale += [f"{path}: table {name}" for name in changed]
        if args.check or args.write:
            verb = "rewrote" if args.write else "stale (python benchmarks/readme_table.py --write FILE)"
            for line in stale:
                print(f"{verb}: {line}", file=sys.stderr if args.check else sys.stdout)
            return 1 if stale and args.check else 0
        for name in args.tables or ["readme"]:
            print(render(name, args.results))
    except SourceError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
