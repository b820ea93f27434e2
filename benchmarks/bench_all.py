"""Run every benchmark script in ``benchmarks/`` and write ``benchmarks/RESULTS.md``.

Run: python benchmarks/bench_all.py [--only NAME ...] [--skip NAME ...] [--data DIR]
       [--timeout 1800] [--report-only] [--markdown benchmarks/RESULTS.md]

Each script (every ``benchmarks/*.py`` except this one and ``common.py``) runs in its own
process with its default settings; its JSON goes to ``benchmarks/results/<name>.json`` (the
script's ``--out`` or ``--json`` option, found from its ``--help``). Scripts that take a
prepared dataset as a positional argument get ``--data DIR`` (they are skipped without it);
``bench_generate`` runs once per planner, with randomly initialised default-size models when
no trained models are in ``models/``. RESULTS.md then holds the machine description, and per
benchmark the command, its printed table and the rows of its JSON as markdown tables.
``--report-only`` rebuilds RESULTS.md from the JSON already in ``benchmarks/results/``.
Ablation scripts (``ablate_*.py``) train models; they run only when named with ``--only``.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import REPO_ROOT, RESULTS_DIR, machine_description, machine_summary, markdown_table  # noqa: E402

HERE = Path(__file__).resolve().parent
NOT_BENCHMARKS = {"bench_all", "common", "__init__", "readme_table", "ship_gate", "build_vocabulary"}  # tools, not benchmarks
EXPERIMENT_PREFIX = "ablate_"  # ablation studies train models: only run when named with --only


@dataclass
class Invocation:
    name: str  # result name: script stem, or stem_variant
    script: Path
    args: list[str] = field(default_factory=list)
    skip_reason: str | None = None


@dataclass
class Outcome:
    invocation: Invocation
    status: str  # "ok", "failed (exit N)", "timed out", "skipped: ..."
    seconds: float = 0.0
    stdout: str = ""
    stderr: str = ""
    json_path: Path | None = None


def discover() -> list[Path]:
    return sorted(p for p in HERE.glob("*.py") if p.stem not in NOT_BENCHMARKS and not p.stem.startswith("_"))


def script_options(script: Path) -> tuple[set[str], list[str]]:
    """(option flags, positional argument names) from ``script --help``."""
    try:
        out = subprocess.run([sys.executable, str(script), "--help"], capture_output=True, text=True, timeout=120,
                             cwd=REPO_ROOT).stdout
    except subprocess.TimeoutExpired:
        return set(), []
    flags = set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", out))
    positional: list[str] = []
    section = re.search(r"\npositional arguments:\n(.*?)(?:\n\n|\Z)", out, re.S)
    if section:
        positional = [ln.split()[0] for ln in section.group(1).splitlines() if ln.startswith("  ") and not ln.startswith("   ")]
    return flags, positional


def trained_models_present() -> bool:
    models = REPO_ROOT / "models"
    return all((models / d / "model.safetensors").is_file() for d in ("tokenizer", "planner_masked", "planner_ar"))


def plan(scripts: list[Path], results: Path, data: Path | None, explicit: bool = False) -> list[Invocation]:
    out: list[Invocation] = []
    for script in scripts:
        flags, positional = script_options(script)
        variants: list[tuple[str, list[str]]] = [(script.stem, [])]
        if script.stem == "bench_generate":
            extra = [] if trained_models_present() else ["--random-init"]
            variants = [(f"{script.stem}_{kind}", ["--planner", kind, *extra]) for kind in ("masked", "ar")]
        for name, args in variants:
            inv = Invocation(name, script, list(args))
            if script.stem.startswith(EXPERIMENT_PREFIX) and not explicit:
                inv.skip_reason = "an experiment (trains models), not a speed benchmark: run it with --only"
            if positional:
                if data is None:
                    inv.skip_reason = f"needs {' '.join(positional).upper()} (give bench_all.py --data DIR)"
                else:
                    inv.args = [str(data), *inv.args]
            flag = "--out" if "--out" in flags else "--json" if "--json" in flags else None
            if flag:
                inv.args += [flag, str(results / f"{name}.json")]
            out.append(inv)
    return out


def run(inv: Invocation, timeout: float) -> Outcome:
    if inv.skip_reason:
        return Outcome(inv, f"skipped: {inv.skip_reason}")
    cmd = [sys.executable, str(inv.script), *inv.args]
    print(f"== {inv.name}: {' '.join(cmd[1:])}", flush=True)
    start, started_at = time.perf_counter(), time.time() - 1.0
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=REPO_ROOT)
    except subprocess.TimeoutExpired as exc:
        return Outcome(inv, f"timed out after {timeout:g} s", time.perf_counter() - start,
                       (exc.stdout or b"").decode(errors="replace") if isinstance(exc.stdout, bytes) else exc.stdout or "")
    seconds = time.perf_counter() - start
    status = "ok" if done.returncode == 0 else f"failed (exit {done.returncode})"
    print(done.stdout[-4000:], end="" if done.stdout.endswith("\n") else "\n")
    if done.returncode != 0:
        print(done.stderr[-2000:], file=sys.stderr)
    return Outcome(inv, status, seconds, done.stdout, done.stderr, json_path_of(inv, newer_than=started_at))


def json_path_of(inv: Invocation, newer_than: float | None = None) -> Path | None:
    """The JSON the run wrote (a file left from an earlier run does not count)."""
    for flag in ("--out", "--json"):
        if flag in inv.args:
            path = Path(inv.args[inv.args.index(flag) + 1])
            fresh = path.is_file() and (newer_than is None or path.stat().st_mtime >= newer_than)
            return path if fresh else None
    return None


def row_tables(payload: dict) -> list[tuple[str, list[dict]]]:
    """Every top-level list of flat dicts in a benchmark's JSON (``rows``, ``results``, ``runs`` ...)."""
    tables = []
    for key, value in payload.items():
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            tables.append((key, value))
    return tables


def scalar_facts(payload: dict) -> list[str]:
    skip = {"machine", "date", "date_utc"}
    return [f"{k}: {v}" for k, v in payload.items() if k not in skip and isinstance(v, (str, int, float, bool)) and v is not None]


def clean_stdout(text: str) -> str:
    lines = [ln for ln in text.rstrip().splitlines() if not re.match(r"^(wrote|written)\s", ln)]
    return "\n".join(lines[-60:])


def write_report(outcomes: list[Outcome], path: Path, results: Path, command: str, report_only: bool = False) -> None:
    machine = machine_description()
    where = ("Report assembled from earlier JSON (each section names the machine it was measured on) on"
             if report_only else "Measured on")
    lines = ["# Benchmark results", "",
             f"Regenerate with `{command}` (writes this file and `benchmarks/results/*.json`).", "",
             f"{where}: {machine_summary(machine)}; {machine['date_utc']}.", "",
             "| benchmark | status | wall s |", "|---|---|---:|"]
    for o in outcomes:
        lines.append(f"| {o.invocation.name} | {o.status} | {f'{o.seconds:.1f}' if o.seconds else '-'} |")
    for o in outcomes:
        lines += ["", f"## {o.invocation.name}", ""]
        rel = o.invocation.script.relative_to(REPO_ROOT)
        lines.append(f"`python {rel} {' '.join(o.invocation.args)}`".replace(str(REPO_ROOT) + "/", "") + f" - {o.status}")
        if o.stdout.strip():
            lines += ["", "<details><summary>printed output</summary>", "", "```text", clean_stdout(o.stdout), "```",
                      "", "</details>"]
        if o.status != "ok" and o.stderr.strip():
            lines += ["", "```text", "\n".join(o.stderr.strip().splitlines()[-15:]), "```"]
        payload = None
        jp = o.json_path or (results / f"{o.invocation.name}.json")
        if jp.is_file() and (o.json_path is not None or o.status == "from existing JSON"):
            try:
                payload = json.loads(jp.read_text())
            except json.JSONDecodeError:
                payload = None
        if isinstance(payload, dict):
            facts = scalar_facts(payload)
            if facts:
                lines += ["", "; ".join(facts)]
            m = payload.get("machine")
            if isinstance(m, dict) and m.get("cpu"):
                lines += ["", f"Machine: {machine_summary(m)}"]
            elif isinstance(m, dict):
                lines += ["", "Machine: " + ", ".join(f"{k} {v}" for k, v in m.items())]
            for key, rows in row_tables(payload):
                lines += ["", f"`{key}` ({jp.relative_to(REPO_ROOT) if jp.is_relative_to(REPO_ROOT) else jp}):", "",
                          markdown_table(rows)]
    path.write_text("\n".join(lines) + "\n")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", nargs="+", default=None, help="script names to run (stems)")
    parser.add_argument("--skip", nargs="+", default=[], help="script names to leave out")
    parser.add_argument("--data", type=Path, default=None, help="prepared dataset for scripts that need one")
    parser.add_argument("--timeout", type=float, default=1800, help="seconds per script")
    parser.add_argument("--results", type=Path, default=RESULTS_DIR, help="JSON folder")
    parser.add_argument("--markdown", type=Path, default=HERE / "RESULTS.md")
    parser.add_argument("--report-only", action="store_true", help="rebuild RESULTS.md from existing JSON")
    parser.add_argument("--list", action="store_true", help="list the benchmark runs and exit")
    args = parser.parse_args()
    scripts = discover()
    known = {s.stem for s in scripts}
    for name in (args.only or []) + args.skip:
        if name not in known:
            parser.error(f"unknown benchmark {name!r}; known: {sorted(known)}")
    scripts = [s for s in scripts if (args.only is None or s.stem in args.only) and s.stem not in args.skip]
    args.results.mkdir(parents=True, exist_ok=True)
    invocations = plan(scripts, args.results.resolve(), args.data, explicit=args.only is not None)
    if args.list:
        for inv in invocations:
            print(f"{inv.name}: {inv.script.name} {' '.join(inv.args)}" + (f"  [skipped: {inv.skip_reason}]" if inv.skip_reason else ""))
        return 0
    if args.report_only:
        outcomes = [Outcome(inv, "from existing JSON" if (args.results / f"{inv.name}.json").is_file() else "no JSON",
                            json_path=args.results / f"{inv.name}.json") for inv in invocations]
    else:
        outcomes = [run(inv, args.timeout) for inv in invocations]
    command = "python benchmarks/bench_all.py" + (f" --data {args.data}" if args.data else "")
    write_report(outcomes, args.markdown, args.results.resolve(), command, report_only=args.report_only)
    print(f"written {args.markdown}")
    failed = [o.invocation.name for o in outcomes if o.status.startswith(("failed", "timed out"))]
    if failed:
        print(f"failed: {failed}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
