# Size (770 lines): one decision: the rules file, the commands it fixes, the files they write and the verdicts read the same field names.
"""Ship gate: measure a candidate tokenizer + planner beside the shipped models and say SHIP or DO NOT SHIP.

Run: python benchmarks/ship_gate.py --candidate-tokenizer RUN --candidate-planner RUN [--planner masked|ar]
       [--rules benchmarks/ship_gate_rules.toml] [--work runs/ship_gate] [--data runs/prepared]
       [--dry-run] [--publish shipped|candidate] [--out benchmarks/results/ship_gate.json]

The rules file (TOML, default ``benchmarks/ship_gate_rules.toml``) is written before the run: it
names what is measured (the robot prompts and seeds, the behaviour seeds, the generation repeats)
and every limit, each with a one-line reason. The gate runs, as child processes with one torch
thread each and in this order, for the shipped models (``models/``) and then the candidate:

* the robot benchmark, ``motok-robot run --prompts PROMPTS --seed S --no-render --no-plots --out
  WORK/<shipped|candidate>_s<S>`` for every seed of the rules (the candidate through ``run``'s
  ``--tokenizer`` / ``--planner-run`` / ``--planner``);
* the behaviour checks, ``python benchmarks/planner_behaviour.py --planner KIND --seeds 48
  --first-seed F --data DATA --threads 1 --out WORK/behaviour_<which>_s<F>-<L>.json`` per range of
  48 seeds (the candidate through ``$MOTOK_ROBOT_MODELS``, a folder of links in WORK);
* the generation metrics, ``motok-robot eval generation --data DATA --planner KIND --repeats R
  --mm-texts M --mm-repeats N --no-train-reference --json WORK/generation_<which>.json`` (the
  candidate with ``--model`` / ``--tokenizer``).

A part that finished (its ``WORK/.done/<part>.json`` records the same command and exit status 0)
is read, not rerun, so a stopped gate resumes. The rules' sha256 is recorded in ``WORK/start.json``
when the first part starts; a rules file that differs from it, weights that changed since, a part
that failed or any missing measurement give DO NOT SHIP, never a pass by default. The verdict of
every rule with both measured values is printed and written to ``--out`` with the rules' sha256.
``--publish`` then writes the README's sources (``robot_eight.json`` from seed 0 of the masked
planner, ``generation_<kind>.json``, the kind's rows of the two behaviour files) from one side's
measurements, so ``python benchmarks/readme_table.py --write README.md models/MODEL_CARD.md``
regenerates the tables from the gate; ``candidate`` only after SHIP and once its weights are the
ones in ``models/``. ``--dry-run`` prints the rules and the commands and runs nothing.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import os
import subprocess
import sys
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import readme_table as rt  # noqa: E402
from common import REPO_ROOT, RESULTS_DIR, write_json  # noqa: E402

from motok_robot.errors import InputError  # noqa: E402

DEFAULT_RULES = HERE / "ship_gate_rules.toml"
SHIPPED_MODELS = REPO_ROOT / "models"
SIDES = ("shipped", "candidate")
#: seeds per behaviour command (the README's behaviour files hold 48 each)
BEHAVIOUR_CHUNK = 48
#: generation metrics a rule may name
METRICS = ("fid", "r_precision_top1", "r_precision_top2", "r_precision_top3", "mm_dist", "diversity", "multimodality")
#: how a generation rule compares the candidate's mean with the shipped one's
DIRECTIONS = ("max_increase", "max_decrease", "max_change")
#: bounds on what the rules file decides
MAX_RULES_BYTES = 64 * 1024
MAX_ROBOT_SEEDS = 100
MAX_BEHAVIOUR_SEEDS = 10_000
MAX_REPEATS = 100
MAX_SUMMARY_BYTES = 16 * 1024 * 1024
#: seconds between the "still running" lines of a long child
HEARTBEAT_S = 300
SHIP, NO_SHIP = "SHIP", "DO NOT SHIP"


# -- rules --------------------------------------------------------------------------------------------
@dataclass
class Limit:
    """One limit of the rules: ``field`` as written in the file, the allowed amount, why."""

    field: str
    value: float
    reason: str


@dataclass
class Rules:
    path: Path
    sha256: str
    prompts: Path
    robot_seeds: list[int]
    robot_total: Limit
    robot_prompt: Limit
    behaviour_first_seed: int
    behaviour_seeds: int
    behaviour: Limit
    repeats: int
    mm_texts: int
    mm_repeats: int
    #: metric -> (direction, limit)
    generation: dict[str, tuple[str, Limit]] = field(default_factory=dict)

    def behaviour_ranges(self) -> list[tuple[int, int]]:
        """``[(first, count), ...]`` in chunks of :data:`BEHAVIOUR_CHUNK` seeds."""
        out, first, end = [], self.behaviour_first_seed, self.behaviour_first_seed + self.behaviour_seeds
        while first < end:
            out.append((first, min(BEHAVIOUR_CHUNK, end - first)))
            first += BEHAVIOUR_CHUNK
        return out

    def limits(self) -> list[tuple[str, Limit]]:
        """(what is compared, limit) for printing."""
        seeds = _span(self.robot_seeds)
        rows = [(f"robot: cells passing over {len(self.robot_seeds)} seeds ({seeds}), may drop by", self.robot_total),
                (f"robot: each prompt's passing seeds ({seeds}), may drop by", self.robot_prompt),
                (f"behaviour: each check's passing seeds ({self.behaviour_first_seed}-"
                 f"{self.behaviour_first_seed + self.behaviour_seeds - 1}), may drop by", self.behaviour)]
        words = {"max_increase": "may rise by", "max_decrease": "may fall by", "max_change": "may move by"}
        rows += [(f"generation: {m} mean {words[d]}", lim) for m, (d, lim) in self.generation.items()]
        return rows


def sha256_of(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _span(seeds: list[int]) -> str:
    if seeds and seeds == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"seeds {seeds[0]}-{seeds[-1]}" if len(seeds) > 1 else f"seed {seeds[0]}"
    return "seeds " + ", ".join(str(s) for s in seeds)


def _table(data: dict, name: str, where: str) -> dict:
    value = data.get(name)
    if not isinstance(value, dict):
        raise InputError(f"{where}: [{name}]: missing table")
    return value


def _known(table: dict, allowed: set[str], where: str, prefix: str) -> None:
    for key in table:
        if key not in allowed:
            raise InputError(f"{where}: {prefix}{key}: unknown field (known: {', '.join(sorted(allowed))})")


def _integer(table: dict, key: str, where: str, prefix: str, low: int, high: int) -> int:
    value = table.get(key)
    if value is None:
        raise InputError(f"{where}: {prefix}{key}: missing")
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise InputError(f"{where}: {prefix}{key}: expected a whole number {low}-{high}, got {value!r}")
    return value


def _number(table: dict, key: str, where: str, prefix: str) -> float:
    value = table.get(key)
    if value is None:
        raise InputError(f"{where}: {prefix}{key}: missing")
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < float("inf"):
        raise InputError(f"{where}: {prefix}{key}: expected a number >= 0, got {value!r}")
    return float(value)


def _reason(table: dict, key: str, where: str, prefix: str) -> str:
    value = table.get(key)
    if not isinstance(value, str) or not value.strip():
        raise InputError(f"{where}: {prefix}{key}: missing (every limit needs a one-line reason)")
    if "\n" in value.strip():
        raise InputError(f"{where}: {prefix}{key}: the reason must be one line")
    return value.strip()


def load_rules(path: str | Path) -> Rules:
    """Read and check a rules file; :class:`InputError` naming the file and the field otherwise."""
    path = Path(path)
    where = str(path)
    if not path.is_file():
        raise InputError(f"{where}: rules file not found (the default: {DEFAULT_RULES.relative_to(REPO_ROOT)})")
    size = path.stat().st_size
    if size > MAX_RULES_BYTES:
        raise InputError(f"{where}: {size:,} bytes, a rules file holds at most {MAX_RULES_BYTES:,}")
    raw = path.read_bytes()
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise InputError(f"{where}: not readable as TOML ({exc})") from None
    _known(data, {"robot", "behaviour", "generation"}, where, "")

    robot = _table(data, "robot", where)
    _known(robot, {"prompts", "seeds", "max_total_drop", "max_total_drop_reason", "max_prompt_drop",
                   "max_prompt_drop_reason"}, where, "robot.")
    prompts = robot.get("prompts")
    if not isinstance(prompts, str) or not prompts:
        raise InputError(f"{where}: robot.prompts: expected the path of a prompt file, got {prompts!r}")
    seeds = robot.get("seeds")
    if (not isinstance(seeds, list) or not 1 <= len(seeds) <= MAX_ROBOT_SEEDS
            or any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seeds) or len(set(seeds)) != len(seeds)):
        raise InputError(f"{where}: robot.seeds: expected 1-{MAX_ROBOT_SEEDS} distinct whole numbers >= 0, got {seeds!r}")

    behaviour = _table(data, "behaviour", where)
    _known(behaviour, {"first_seed", "seeds", "max_drop", "max_drop_reason"}, where, "behaviour.")

    generation = _table(data, "generation", where)
    _known(generation, {"repeats", "mm_texts", "mm_repeats", *METRICS}, where, "generation.")
    metrics: dict[str, tuple[str, Limit]] = {}
    for name in METRICS:
        if name not in generation:
            continue
        rule = generation[name]
        prefix = f"generation.{name}."
        if not isinstance(rule, dict):
            raise InputError(f"{where}: generation.{name}: expected a table ([generation.{name}])")
        _known(rule, {*DIRECTIONS, "reason"}, where, prefix)
        given = [d for d in DIRECTIONS if d in rule]
        if len(given) != 1:
            raise InputError(f"{where}: generation.{name}: give exactly one of {', '.join(DIRECTIONS)}")
        metrics[name] = (given[0], Limit(prefix + given[0], _number(rule, given[0], where, prefix),
                                         _reason(rule, "reason", where, prefix)))
    if not metrics:
        raise InputError(f"{where}: [generation]: no metric rule (e.g. [generation.fid] max_increase = 0.01)")

    def limit(table: dict, key: str, prefix: str) -> Limit:
        return Limit(prefix + key, _integer(table, key, where, prefix, 0, MAX_BEHAVIOUR_SEEDS),
                     _reason(table, key + "_reason", where, prefix))

    prompt_path = Path(prompts)
    return Rules(path=path, sha256=hashlib.sha256(raw).hexdigest(),
                 prompts=prompt_path if prompt_path.is_absolute() else REPO_ROOT / prompt_path,
                 robot_seeds=list(seeds), robot_total=limit(robot, "max_total_drop", "robot."),
                 robot_prompt=limit(robot, "max_prompt_drop", "robot."),
                 behaviour_first_seed=_integer(behaviour, "first_seed", where, "behaviour.", 0, 10**9),
                 behaviour_seeds=_integer(behaviour, "seeds", where, "behaviour.", 1, MAX_BEHAVIOUR_SEEDS),
                 behaviour=limit(behaviour, "max_drop", "behaviour."),
                 repeats=_integer(generation, "repeats", where, "generation.", 1, MAX_REPEATS),
                 mm_texts=_integer(generation, "mm_texts", where, "generation.", 0, 10_000),
                 mm_repeats=_integer(generation, "mm_repeats", where, "generation.", 1, MAX_REPEATS),
                 generation=metrics)


# -- the parts ----------------------------------------------------------------------------------------
@dataclass
class Part:
    """One child process: its name (also its ``.done`` file), what it is, the argument list, extra
    environment, and the file or folder it writes."""

    name: str
    what: str
    argv: list[str]
    env: dict[str, str]
    output: Path

    def shown(self) -> str:
        env = " ".join(f"{k}={v}" for k, v in self.env.items())
        return (env + " " if env else "") + " ".join(_quote(a) for a in self.argv)


def _quote(arg: str) -> str:
    return f"'{arg}'" if any(c in arg for c in " ;|&$\"") else arg


@dataclass
class Setup:
    rules: Rules
    work: Path
    kind: str
    data: Path
    candidate_tokenizer: Path
    candidate_planner: Path

    @property
    def candidate_models(self) -> Path:
        """A models folder of links: the candidate's tokenizer and planner, the shipped rest."""
        return self.work / "candidate_models"


def robot_folder(work: Path, side: str, seed: int) -> Path:
    return work / f"{side}_s{seed}"


def behaviour_file(work: Path, side: str, first: int, count: int) -> Path:
    return work / f"behaviour_{side}_s{first}-{first + count - 1}.json"


def generation_file(work: Path, side: str) -> Path:
    return work / f"generation_{side}.json"


def plan(setup: Setup) -> list[Part]:
    """Every child process of the gate, shipped side first (paths relative to the repository,
    where the children run, when they lie inside it)."""
    r, work, kind, data = setup.rules, setup.work, setup.kind, _rel(setup.data)
    tokenizer, planner = _rel(setup.candidate_tokenizer), _rel(setup.candidate_planner)
    parts = []
    for side in SIDES:
        models = [] if side == "shipped" else ["--tokenizer", tokenizer, "--planner-run", planner]
        for seed in r.robot_seeds:
            out = robot_folder(work, side, seed)
            parts.append(Part(f"robot_{side}_s{seed}", f"robot benchmark, {side}, seed {seed}",
                              ["motok-robot", "run", "--prompts", _rel(r.prompts), "--seed", str(seed), "--no-render",
                               "--no-plots", "--planner", kind, *models, "--out", _rel(out), "--overwrite"], {}, out))
    for side in SIDES:
        env = {} if side == "shipped" else {"MOTOK_ROBOT_MODELS": _rel(setup.candidate_models)}
        for first, count in r.behaviour_ranges():
            out = behaviour_file(work, side, first, count)
            parts.append(Part(f"behaviour_{side}_s{first}", f"behaviour checks, {side}, seeds {first}-{first + count - 1}",
                              ["python", "benchmarks/planner_behaviour.py", "--planner", kind, "--seeds", str(count),
                               "--first-seed", str(first), "--data", data, "--threads", "1", "--out", _rel(out)],
                              env, out))
    for side in SIDES:
        models = [] if side == "shipped" else ["--model", planner, "--tokenizer", tokenizer]
        out = generation_file(work, side)
        parts.append(Part(f"generation_{side}", f"generation metrics, {side}",
                          ["motok-robot", "eval", "generation", "--data", data, "--planner", kind, *models,
                           "--repeats", str(r.repeats), "--mm-texts", str(r.mm_texts), "--mm-repeats", str(r.mm_repeats),
                           "--no-train-reference", "--json", _rel(out)], {}, out))
    return parts


def _rel(path: Path) -> str:
    try:
        return str(Path(path).resolve().relative_to(REPO_ROOT))
    except ValueError:
        return str(path)


def child_argv(argv: list[str]) -> list[str]:
    """The argument list to execute: ``motok-robot`` and ``python`` from this interpreter's environment."""
    if argv[0] == "python":
        return [sys.executable, *argv[1:]]
    if argv[0] == "motok-robot":
        exe = Path(sys.executable).parent / "motok-robot"
        return [str(exe), *argv[1:]] if exe.is_file() else [sys.executable, "-m", "motok_robot.cli", *argv[1:]]
    return list(argv)


def child_env(part: Part) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "MOTOK_ROBOT_MODELS"}
    env.update({"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}, **part.env)
    return env


def done_file(work: Path, part: Part) -> Path:
    return work / ".done" / f"{part.name}.json"


def finished(work: Path, part: Part) -> bool:
    """Whether ``part`` ran to exit status 0 with this very command and left its output."""
    try:
        record = json.loads(done_file(work, part).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return False
    return record.get("argv") == part.argv and record.get("env") == part.env and record.get("rc") == 0 and part.output.exists()


def run_part(work: Path, part: Part, index: int, total: int) -> int:
    """Run one child (its output to ``WORK/logs/<part>.log``) and record it in ``WORK/.done``."""
    logs = work / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    log = logs / f"{part.name}.log"
    print(f"[{index}/{total}] {part.what}: running, log {log}", flush=True)
    start = time.monotonic()
    with open(log, "w", encoding="utf-8") as fh:
        fh.write(part.shown() + "\n")
        fh.flush()
        child = subprocess.Popen(child_argv(part.argv), cwd=REPO_ROOT, env=child_env(part), stdout=fh,
                                 stderr=subprocess.STDOUT)
        try:
            while (rc := _wait(child, HEARTBEAT_S)) is None:
                print(f"[{index}/{total}] {part.what}: still running, {(time.monotonic() - start) / 60:.0f} min; "
                      f"log: {_last_line(log)}", flush=True)
        except BaseException:  # Ctrl-C or a kill of the gate: stop the child too; the part stays unfinished
            child.terminate()
            child.wait()
            raise
    seconds = time.monotonic() - start
    done = done_file(work, part)
    done.parent.mkdir(parents=True, exist_ok=True)
    done.write_text(json.dumps({"argv": part.argv, "env": part.env, "rc": rc, "seconds": round(seconds, 1),
                                "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}, indent=2) + "\n",
                    encoding="utf-8")
    print(f"[{index}/{total}] {part.what}: {'done' if rc == 0 else f'FAILED (exit {rc}, see {log})'} "
          f"in {seconds / 60:.1f} min", flush=True)
    return rc


def _wait(child: subprocess.Popen, seconds: float) -> int | None:
    try:
        return child.wait(timeout=seconds)
    except subprocess.TimeoutExpired:
        return None


def _last_line(log: Path, limit: int = 4096) -> str:
    """The last non-empty line of a log (progress bars end their updates with a carriage return)."""
    with open(log, "rb") as fh:
        fh.seek(max(0, log.stat().st_size - limit))
        tail = fh.read().decode("utf-8", "replace")
    lines = [ln.strip() for ln in tail.replace("\r", "\n").splitlines() if ln.strip()]
    return lines[-1][:160] if lines else "(empty)"


def link_candidate_models(setup: Setup) -> None:
    """``WORK/candidate_models``: links to the candidate's tokenizer and planner and to the shipped
    rest (evaluator, robots, vocabulary), for the commands that read ``$MOTOK_ROBOT_MODELS``."""
    folder = setup.candidate_models
    folder.mkdir(parents=True, exist_ok=True)
    wanted = {"tokenizer": setup.candidate_tokenizer.resolve(), f"planner_{setup.kind}": setup.candidate_planner.resolve()}
    for entry in SHIPPED_MODELS.iterdir():
        wanted.setdefault(entry.name, entry.resolve())
    for name, target in wanted.items():
        link = folder / name
        if link.is_symlink() or link.exists():
            if link.is_symlink() and link.resolve() == target:
                continue
            link.unlink()
        link.symlink_to(target)


# -- weights ------------------------------------------------------------------------------------------
def weights_digest(run: Path) -> str | None:
    path = Path(run) / "model.safetensors"
    if not path.is_file():
        return None
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def digests(setup: Setup) -> dict[str, dict[str, str | None]]:
    return {"shipped": {"tokenizer": weights_digest(SHIPPED_MODELS / "tokenizer"),
                        "planner": weights_digest(SHIPPED_MODELS / f"planner_{setup.kind}")},
            "candidate": {"tokenizer": weights_digest(setup.candidate_tokenizer),
                          "planner": weights_digest(setup.candidate_planner)}}


# -- reading the measurements -------------------------------------------------------------------------
def read_robot(folder: Path, prompts: list[str]) -> tuple[dict[str, bool] | None, str]:
    """``{prompt: passed}`` from a ``run --prompts`` folder's ``summary.csv`` (None and why when a
    prompt has no row); a prompt whose run raised counts as not passed."""
    path = folder / "summary.csv"
    if not path.is_file():
        return None, f"{path}: missing"
    if path.stat().st_size > MAX_SUMMARY_BYTES:
        return None, f"{path}: larger than {MAX_SUMMARY_BYTES:,} bytes"
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    cells = {}
    for row in rows:
        if row.get("text") in prompts:
            cells[row["text"]] = rt.truthy(row.get("passed"))
    missing = [p for p in prompts if p not in cells]
    if missing:
        return None, f"{path}: no row for {', '.join(repr(p) for p in missing)}"
    return cells, ""


def read_behaviour(files: list[Path], kind: str) -> tuple[dict[str, int] | None, str]:
    """``{check: passing seeds, "seeds": seeds}`` of ``kind``'s planner rows over ``files``."""
    counts = {c: 0 for c in rt.CHECKS} | {"seeds": 0}
    for path in files:
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            return None, f"{path}: cannot read it ({exc.__class__.__name__})"
        rows = [r for r in data.get("rows", []) if r.get("planner") == kind and r.get("decoder_seed") is None]
        if not rows:
            return None, f"{path}: no {kind} planner row"
        for seed in rows[0].get("seeds", []):
            counts["seeds"] += 1
            for check in rt.CHECKS:
                counts[check] += bool((seed.get(check) or {}).get("passed"))
    return counts, ""


def read_generation(path: Path) -> tuple[dict[str, float] | None, str]:
    """``{metric: mean}`` of the planner row of an ``eval generation --json`` file."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        return None, f"{path}: cannot read it ({exc.__class__.__name__})"
    rows = [r for r in data.get("rows", []) if r.get("kind") not in ("reference", "control")]
    if len(rows) != 1:
        return None, f"{path}: expected one planner row, found {len(rows)}"
    return {k: m["mean"] for k, m in rows[0].get("metrics", {}).items() if isinstance(m, dict) and m.get("mean") is not None}, ""


def measure(setup: Setup, failed: set[str]) -> dict:
    """The measurements of both sides as :func:`decide` reads them; a part that failed (its name in
    ``failed``) or wrote nothing readable leaves its entry None, with the reason in ``missing``."""
    from motok_robot.text.prompts import read_prompts

    r, work = setup.rules, setup.work
    prompts = [p.text for p in read_prompts(r.prompts)]
    out: dict = {"prompts": prompts, "robot": {}, "behaviour": {}, "generation": {}, "missing": []}
    for side in SIDES:
        out["robot"][side] = {}
        for seed in r.robot_seeds:
            cells, why = (None, "the run failed") if f"robot_{side}_s{seed}" in failed else \
                read_robot(robot_folder(work, side, seed), prompts)
            out["robot"][side][str(seed)] = cells
            if cells is None:
                out["missing"].append(f"robot {side} seed {seed}: {why}")
        names = [f"behaviour_{side}_s{first}" for first, _ in r.behaviour_ranges()]
        files = [behaviour_file(work, side, first, count) for first, count in r.behaviour_ranges()]
        counts, why = (None, "a range failed") if failed & set(names) else read_behaviour(files, setup.kind)
        if counts is not None and counts["seeds"] != r.behaviour_seeds:
            counts, why = None, f"{counts['seeds']} seeds measured, the rules ask {r.behaviour_seeds}"
        out["behaviour"][side] = counts
        if counts is None:
            out["missing"].append(f"behaviour {side}: {why}")
        metrics, why = (None, "the run failed") if f"generation_{side}" in failed else \
            read_generation(generation_file(work, side))
        out["generation"][side] = metrics
        if metrics is None:
            out["missing"].append(f"generation {side}: {why}")
    return out


# -- the decision -------------------------------------------------------------------------------------
def verdict(rule: str, limit: Limit, shipped, candidate, passed: bool, note: str = "") -> dict:
    return {"rule": rule, "field": limit.field, "limit": limit.value, "reason": limit.reason,
            "shipped": shipped, "candidate": candidate, "passed": bool(passed), "note": note}


def decide(rules: Rules, measured: dict, integrity: list[dict] = ()) -> tuple[str, list[dict]]:
    """(SHIP or DO NOT SHIP, the verdict of every rule). ``measured`` as :func:`measure` returns it;
    ``integrity``: verdicts on the rules file and weights (each must pass). Anything missing fails
    its rule; SHIP only when every rule passed."""
    verdicts = list(integrity)
    prompts = measured.get("prompts") or []
    robot = measured.get("robot") or {}
    seeds = [str(s) for s in rules.robot_seeds]

    def cells(side: str) -> dict[str, dict[str, bool]] | None:
        per_seed = robot.get(side) or {}
        if not prompts or any(not isinstance(per_seed.get(s), dict) or any(p not in per_seed[s] for p in prompts)
                              for s in seeds):
            return None
        return {s: {p: bool(per_seed[s][p]) for p in prompts} for s in seeds}

    ship_cells, cand_cells = cells("shipped"), cells("candidate")
    span = _span(rules.robot_seeds)
    if ship_cells is None or cand_cells is None:
        verdicts.append(verdict(f"robot: cells passing, {span}", rules.robot_total, None, None, False,
                                "missing: " + ", ".join(s for s, c in (("shipped", ship_cells), ("candidate", cand_cells))
                                                        if c is None)))
    else:
        ship_total = sum(v for per in ship_cells.values() for v in per.values())
        cand_total = sum(v for per in cand_cells.values() for v in per.values())
        lost = [f"{p!r} seed {s}" for s in seeds for p in prompts if ship_cells[s][p] and not cand_cells[s][p]]
        gained = sum(cand_cells[s][p] and not ship_cells[s][p] for s in seeds for p in prompts)
        note = f"{len(prompts) * len(seeds)} cells; lost {len(lost)}" + (f" ({'; '.join(lost)})" if lost else "") + \
            f", gained {gained}"
        verdicts.append(verdict(f"robot: cells passing, {span}", rules.robot_total, ship_total, cand_total,
                                ship_total - cand_total <= rules.robot_total.value, note))
        for p in prompts:
            a = sum(ship_cells[s][p] for s in seeds)
            b = sum(cand_cells[s][p] for s in seeds)
            verdicts.append(verdict(f"robot: {p!r}, seeds passing", rules.robot_prompt, a, b,
                                    a - b <= rules.robot_prompt.value))

    behaviour = measured.get("behaviour") or {}
    ship_b, cand_b = behaviour.get("shipped"), behaviour.get("candidate")
    for check in rt.CHECKS:
        a = None if not isinstance(ship_b, dict) else ship_b.get(check)
        b = None if not isinstance(cand_b, dict) else cand_b.get(check)
        ok = a is not None and b is not None and a - b <= rules.behaviour.value
        verdicts.append(verdict(f"behaviour: {check}, seeds passing", rules.behaviour, a, b, ok,
                                "" if a is not None and b is not None else "missing"))

    generation = measured.get("generation") or {}
    ship_g, cand_g = generation.get("shipped"), generation.get("candidate")
    for metric, (direction, limit) in rules.generation.items():
        a = None if not isinstance(ship_g, dict) else ship_g.get(metric)
        b = None if not isinstance(cand_g, dict) else cand_g.get(metric)
        if a is None or b is None:
            verdicts.append(verdict(f"generation: {metric}", limit, a, b, False, "missing"))
            continue
        delta = b - a
        ok = {"max_increase": delta <= limit.value + 1e-12, "max_decrease": -delta <= limit.value + 1e-12,
              "max_change": abs(delta) <= limit.value + 1e-12}[direction]
        verdicts.append(verdict(f"generation: {metric}", limit, a, b, ok, f"change {delta:+.4f}"))
    return (SHIP if verdicts and all(v["passed"] for v in verdicts) else NO_SHIP), verdicts


def integrity_verdicts(rules: Rules, start: dict, now_digests: dict) -> list[dict]:
    """The rules file is the one recorded when the run started, and no weights changed since."""
    current = sha256_of(rules.path) if rules.path.is_file() else None
    recorded = start.get("rules_sha256")
    out = [{"rule": "rules file unchanged since the run started", "field": "sha256", "limit": None,
            "reason": "the rules are fixed before the run", "shipped": None, "candidate": None,
            "passed": current is not None and current == recorded,
            "note": f"at start {(recorded or '?')[:16]}, now {(current or 'missing')[:16]}"}]
    for side in SIDES:
        for what in ("tokenizer", "planner"):
            before = (start.get("weights") or {}).get(side, {}).get(what)
            after = now_digests[side][what]
            out.append({"rule": f"{side} {what} weights unchanged since the run started", "field": "model.safetensors",
                        "limit": None, "reason": "the measurements must be of the weights judged", "shipped": None,
                        "candidate": None, "passed": before is not None and before == after,
                        "note": f"at start {(before or 'missing')[:12]}, now {(after or 'missing')[:12]}"})
    return out


def _show(value) -> str:
    if value is None:
        return "MISSING"
    if isinstance(value, float):
        return f"{value:.4f}"
    return str(value)


def print_decision(decision: str, verdicts: list[dict]) -> None:
    width = max(len(v["rule"]) for v in verdicts)
    for v in verdicts:
        measured = "" if v["limit"] is None else (f"  shipped {_show(v['shipped'])}  candidate {_show(v['candidate'])}"
                                                  f"  (limit {v['field']} = {v['limit']:g})")
        print(f"  {'pass' if v['passed'] else 'FAIL'}  {v['rule']:<{width}}{measured}"
              + (f"  {v['note']}" if v["note"] else ""))
    print(f"\n{decision}")


def print_rules(rules: Rules) -> None:
    print(f"rules: {rules.path} (sha256 {rules.sha256})")
    for what, limit in rules.limits():
        print(f"  {what} {limit.value:g}  [{limit.field}]: {limit.reason}")


# -- publishing ---------------------------------------------------------------------------------------
def read_json(path: Path, what: str) -> dict:
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: missing ({what})") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: cannot read it as JSON ({exc.__class__.__name__})") from None


def publish(setup: Setup, side: str, results: Path = RESULTS_DIR) -> list[Path]:
    """Write the README's sources from ``side``'s measurements in WORK (see the module docstring):
    only when the weights measured for ``side`` are the ones in ``models/`` now, and for the
    candidate only when the gate's decision (``WORK/decision.json``) was SHIP."""
    record = read_json(setup.work / "decision.json", "run the gate first")
    if side == "candidate" and record.get("decision") != SHIP:
        raise InputError(f"--publish candidate: the gate said {record.get('decision')} ({setup.work / 'decision.json'})")
    if record.get("planner") != setup.kind:
        raise InputError(f"--publish: the gate measured the {record.get('planner')} planner, not {setup.kind}")
    measured = (record.get("weights") or {}).get(side)
    if measured != digests(setup)["shipped"]:
        raise InputError(f"--publish {side}: the weights it measured are not the ones in models/ now (after SHIP, copy "
                         "the candidate's model.safetensors and config.json into models/ first)")
    written = []
    if setup.kind == "masked" and 0 in setup.rules.robot_seeds:
        written.append(rt.import_batches([robot_folder(setup.work, side, 0)], results / rt.ROBOT_EIGHT))
    gen = read_json(generation_file(setup.work, side), f"the {side} generation metrics")
    if side == "candidate":  # the row is named after the run folder; the README reads it as the kind's
        for row in gen["rows"]:
            if row.get("kind") not in ("reference", "control"):
                gen["models"] = {setup.kind: gen["models"].get(row["name"], "")}
                row["name"] = setup.kind
    written.append(write_json(results / rt.GENERATION[setup.kind], gen))
    ranges = setup.rules.behaviour_ranges()
    if ranges == [(0, 48), (48, 48)]:  # the seeds and files of the README's behaviour row
        for (first, count), name in zip(ranges, rt.BEHAVIOUR):
            new = read_json(behaviour_file(setup.work, side, first, count), f"the {side} behaviour checks")
            target = results / name
            old = read_json(target, "the README's behaviour source") if target.is_file() else {"rows": []}
            keep = [r for r in old.get("rows", []) if r.get("planner") not in (setup.kind, None)]
            new["rows"] = keep + [r for r in new["rows"] if r.get("planner") in (setup.kind, None)]
            written.append(write_json(target, new))
    return written


# -- main ---------------------------------------------------------------------------------------------
def check_run(path: Path, what: str) -> Path:
    if not (path / "model.safetensors").is_file() or not (path / "config.json").is_file():
        raise InputError(f"{what} {path}: not a trained run (config.json + model.safetensors)")
    return path


def gate(setup: Setup, out: Path) -> int:
    work = setup.work
    work.mkdir(parents=True, exist_ok=True)
    start_path = work / "start.json"
    now = digests(setup)
    if start_path.is_file():
        start = read_json(start_path, "this run's start record")
    else:
        start = {"rules": str(setup.rules.path), "rules_sha256": setup.rules.sha256, "weights": now,
                 "planner": setup.kind, "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        start_path.write_text(json.dumps(start, indent=2) + "\n", encoding="utf-8")
    print_rules(setup.rules)
    failed: set[str] = set()
    if start.get("rules_sha256") != setup.rules.sha256 or start.get("weights") != now:
        print(f"the rules file or the weights differ from what {start_path} recorded when this run started: "
              "nothing is run (start a new run with another --work)", flush=True)
    else:
        link_candidate_models(setup)
        parts = plan(setup)
        for i, part in enumerate(parts, 1):
            if finished(work, part):
                print(f"[{i}/{len(parts)}] {part.what}: finished before, read from {part.output}", flush=True)
            elif run_part(work, part, i, len(parts)) != 0:
                failed.add(part.name)
    measured = measure(setup, failed)
    decision, verdicts = decide(setup.rules, measured, integrity_verdicts(setup.rules, start, digests(setup)))
    print()
    print_decision(decision, verdicts)
    payload = {"benchmark": "ship_gate", "decision": decision, "planner": setup.kind,
               "rules": {"file": _rel(setup.rules.path), "sha256": setup.rules.sha256,
                         "sha256_at_start": start.get("rules_sha256")},
               "candidate": {"tokenizer": str(setup.candidate_tokenizer), "planner": str(setup.candidate_planner)},
               "weights": digests(setup), "work": str(work), "started_utc": start.get("started_utc"),
               "failed_parts": sorted(failed), "verdicts": verdicts, "measured": measured}
    write_json(work / "decision.json", payload, threads=1)
    print(f"wrote {write_json(out, payload, threads=1)}")
    return 0 if decision == SHIP else 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--candidate-tokenizer", type=Path, required=True, help="the candidate tokenizer run")
    parser.add_argument("--candidate-planner", type=Path, required=True, help="the candidate planner run")
    parser.add_argument("--planner", choices=("masked", "ar"), default="masked", help="planner kind (default masked)")
    parser.add_argument("--rules", type=Path, default=DEFAULT_RULES, help="rules file, written before the run "
                        "(default benchmarks/ship_gate_rules.toml)")
    parser.add_argument("--work", type=Path, default=REPO_ROOT / "runs" / "ship_gate",
                        help="work folder; a finished part in it is read, not rerun (default runs/ship_gate)")
    parser.add_argument("--data", type=Path, default=REPO_ROOT / "runs" / "prepared",
                        help="prepared dataset for the behaviour checks and the generation metrics (default runs/prepared)")
    parser.add_argument("--out", type=Path, default=RESULTS_DIR / "ship_gate.json", help="the decision JSON")
    parser.add_argument("--dry-run", action="store_true", help="print the rules and the commands; run nothing")
    parser.add_argument("--publish", choices=SIDES, default=None,
                        help="run nothing; write the README's result files from this side's measurements in --work "
                             "(candidate: only after SHIP, once its weights are in models/)")
    args = parser.parse_args(argv)
    try:
        rules = load_rules(args.rules)
        setup = Setup(rules, args.work.resolve(), args.planner, args.data.resolve(), args.candidate_tokenizer.resolve(),
                      args.candidate_planner.resolve())
        if args.publish:
            for path in publish(setup, args.publish):
                print(f"published {path}")
            return 0
        if args.dry_run:
            print_rules(rules)
            parts = plan(setup)
            print(f"commands ({len(parts)}, run from {REPO_ROOT}, each with OMP_NUM_THREADS=1; "
                  f"a part is skipped when WORK/.done/<part>.json records it):")
            for i, part in enumerate(parts, 1):
                state = "finished, would be read" if finished(setup.work, part) else "would run"
                print(f"  [{i}/{len(parts)}] {part.what} ({state}):\n      {part.shown()}")
            return 0
        check_run(setup.candidate_tokenizer, "--candidate-tokenizer")
        check_run(setup.candidate_planner, "--candidate-planner")
        if not rules.prompts.is_file():
            raise InputError(f"{rules.path}: robot.prompts: {rules.prompts} not found")
        if not (setup.data / "index.jsonl").is_file():
            raise InputError(f"--data {args.data}: no index.jsonl (make one with motok-robot data prepare)")
        return gate(setup, args.out)
    except (InputError, rt.SourceError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
