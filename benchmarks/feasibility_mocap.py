"""Real mocap through the robot half: retarget, feasibility stage, physics validation, per clip.

Every clip is retargeted once per robot with the default options (as ``motok-robot retarget``;
the robot.npz is cached in the work folder under the clip and robot name, so a rerun skips
it) and then measured by the same validation call (``validate_file``, closed loop by default,
no plots or video) in up to three variants:

* ``A`` (baseline): the retargeted robot.npz validated as it is (today's path);
* ``B`` (feasible): ``make_feasible(..., robot_config(index))`` (the robot's own settings, from
  its description) + ``write_feasible``, then the stage's robot.npz validated (it replays the
  stage's goals and plan, judged against the reference);
* ``C`` (feasible, slowed): the same with ``retime`` 1.5;
* ``D`` (feasible, own steps): the same with ``gait.enabled``: a clip that travels is
  walked with the robot's own steps along its path (docs/feasibility.md, "Walking with the
  robot's own steps").

``--settings JSON`` applies more settings over every stage variant (to measure one change).

Clip set (from ``--datasets``, default ``../shared/datasets``; extracted into ``--work``):

* Bandai Namco ``walk_<style>_001`` of every style of dataset-1 and dataset-2; ``walk-left``,
  ``walk-right``, ``walk-back`` (style ``normal``), ``run`` (dataset-1, ``normal``), ``kick``,
  ``bow``, ``bye``, ``byebye`` (``normal``) and dataset-2's ``raise-up-*`` clips (``normal``);
* CMU ASF/AMC trials whose description (``cmu-descriptions.csv``) is only walk / run / jog;
* DeepMimic ``humanoid3d_walk`` and ``humanoid3d_run``.

Each clip is grouped as ``locomotion`` (walks and runs) or ``other``; the clips run round-robin over
the families (Bandai walks of each dataset, the other Bandai clips, CMU, DeepMimic), the
``normal`` walks first, so a partial run covers every source.  A crash in any stage is
recorded as that row's ``error`` and the run goes on.  The JSON is rewritten after every clip.

Usage::

    python benchmarks/feasibility_mocap.py [--robots op3_like] [--variants A B C] [--clips 'dataset-1_walk_*']
        [--groups locomotion] [--max-clips N] [--work /tmp/feasibility_mocap] [--settings JSON] [--out JSON]

Prints a progress line per row, the row table and pass counts per group x variant; writes
JSON with the machine description (default ``benchmarks/results/feasibility_mocap_<robots>.json``).
Skips with a message (exit 0) when the datasets folder is absent.  To measure one commit while
the working tree changes, put an extracted ``git archive COMMIT`` first on ``PYTHONPATH``: the
JSON's ``code`` records where ``motok_robot`` and ``retarget`` were imported from.
"""

from __future__ import annotations

import argparse
import csv
import fnmatch
import json
import os
import re
import subprocess
import sys
import time
import traceback
from collections import Counter
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO_ROOT, RESULTS_DIR, machine_description, markdown_table, write_json  # noqa: E402

VARIANTS = {"A": "baseline", "B": "feasible", "C": "feasible_retime1.5", "D": "feasible_own_steps"}
#: each stage variant's settings over the robot's own (``robot_config``)
VARIANT_SETTINGS = {"B": {}, "C": {"retime": 1.5}, "D": {"gait": {"enabled": True}}}
METRICS = ("fell", "fall_time_s", "base_drift_m", "tracking_rmse_rad", "pose_error_mean_m", "heading_error_max_rad",
           "zmp_outside_ratio", "max_torque_ratio")
#: Bandai contents besides the walks, first take of style "normal" (the first style present otherwise)
BANDAI_OTHER = {"walk-left": "locomotion", "walk-right": "locomotion", "walk-back": "locomotion",
                "run": "locomotion", "kick": "other", "bow": "other", "bye": "other", "byebye": "other"}
RAISE = re.compile(r"raise")  # raise-hands-like contents (dataset-2: raise-up-{left,right,both}-hand(s))
CMU_LOCOMOTION = re.compile(r"^\s*(walk|run|jog)(\s*/\s*(walk|run|jog))*\s*$", re.IGNORECASE)
DEEPMIMIC = ("humanoid3d_walk", "humanoid3d_run")


# -- clips ------------------------------------------------------------------------------------------
def _extract(archive: Path, dest: Path, patterns: list[str]) -> None:
    """``tar -xJf archive -C dest --wildcards patterns`` once (a marker file records it)."""
    marker = dest / f".{archive.name}.extracted"
    if marker.exists():
        return
    dest.mkdir(parents=True, exist_ok=True)
    print(f"extracting {archive.name} ({', '.join(patterns)}) into {dest}", flush=True)
    subprocess.run(["tar", "-xJf", str(archive), "-C", str(dest), "--wildcards", *patterns], check=True)
    marker.write_text("ok\n")


def _bandai_name(path: Path) -> tuple[str, str, str, str]:
    """``dataset-1_walk-left_normal_001`` -> (dataset, content, style, take)."""
    dataset, rest = path.stem.split("_", 1)
    content, rest = rest.split("_", 1)
    style, take = rest.rsplit("_", 1)
    return dataset, content, style, take


def find_clips(datasets: Path, work: Path) -> tuple[list[dict], dict]:
    """The clip set as dicts (name, group, source, path, asf); and what was found (styles etc.)."""
    raw = work / "clips"
    clips: list[dict] = []
    found: dict = {}
    bandai = datasets / "bandai-namco-bvh.tar.xz"
    if bandai.is_file():
        _extract(bandai, raw / "bandai", ["*_001.bvh"])
        takes = {}
        for p in sorted((raw / "bandai").rglob("*_001.bvh")):
            dataset, content, style, _ = _bandai_name(p)
            takes.setdefault((dataset, content), {})[style] = p
        walk_styles = {}
        for (dataset, content), styles in sorted(takes.items()):
            if content == "walk":
                walk_styles[dataset] = sorted(styles)
                for style, p in sorted(styles.items()):
                    clips.append({"clip": p.stem, "group": "locomotion", "source": "bandai", "path": str(p), "asf": None})
        found["bandai_walk_styles"] = walk_styles
        others = [(d, c) for d, c in sorted(takes) if c in BANDAI_OTHER or RAISE.search(c)]
        wanted = set(BANDAI_OTHER)
        for dataset, content in others:
            if content in BANDAI_OTHER and content not in wanted:
                continue  # one dataset per content (dataset-1 first: 'run' is in both)
            wanted.discard(content)
            styles = takes[(dataset, content)]
            style = "normal" if "normal" in styles else sorted(styles)[0]
            p = styles[style]
            clips.append({"clip": p.stem, "group": BANDAI_OTHER.get(content, "other"), "source": "bandai",
                          "path": str(p), "asf": None})
        found["bandai_missing_contents"] = sorted(wanted)
    else:
        print(f"skip Bandai: {bandai} not found", file=sys.stderr)
    cmu, descriptions = datasets / "cmu-asf-amc.tar.xz", datasets / "cmu-descriptions.csv"
    if cmu.is_file() and descriptions.is_file():
        _extract(cmu, raw / "cmu", ["*.asf", "*.amc"])
        labels = {}
        with descriptions.open(newline="") as f:
            for row in csv.DictReader(f):
                try:
                    labels[f"{int(row['Subject']):02d}_{int(row['Trial #']):02d}"] = row["Motion Description"]
                except (KeyError, ValueError):
                    continue
        chosen = []
        for amc in sorted((raw / "cmu").rglob("*.amc")):
            label = labels.get(amc.stem, "")
            asf = amc.parent / f"{amc.stem.split('_')[0]}.asf"
            if CMU_LOCOMOTION.match(label) and asf.is_file():
                chosen.append(f"{amc.stem} ({label})")
                clips.append({"clip": f"cmu_{amc.stem}", "group": "locomotion", "source": "cmu", "path": str(amc),
                              "asf": str(asf), "label": label})
        found["cmu_trials"] = chosen
    else:
        print(f"skip CMU: {cmu} or {descriptions} not found", file=sys.stderr)
    deepmimic = datasets / "deepmimic.tar.xz"
    if deepmimic.is_file():
        _extract(deepmimic, raw / "deepmimic", [f"*/humanoid3d/{n}.txt" for n in DEEPMIMIC])
        for name in DEEPMIMIC:
            hits = sorted((raw / "deepmimic").rglob(f"humanoid3d/{name}.txt"))
            if hits:
                clips.append({"clip": f"deepmimic_{name}", "group": "locomotion", "source": "deepmimic",
                              "path": str(hits[0]), "asf": None})
            else:
                print(f"skip deepmimic {name}: not in {deepmimic}", file=sys.stderr)
    else:
        print(f"skip DeepMimic: {deepmimic} not found", file=sys.stderr)
    return interleave(clips), found


def interleave(clips: list[dict]) -> list[dict]:
    """Round-robin over families (Bandai walks per dataset, Bandai others, CMU, DeepMimic), each
    in its own order, so that a run cut short (or ``--max-clips``) still covers every source."""
    families: dict = {}
    for c in clips:
        key = (c["source"], Path(c["path"]).stem.split("_")[0] if "_walk_" in Path(c["path"]).name else "other")
        families.setdefault(key, []).append(c)
    queues = [sorted(f, key=lambda c: ("_walk_normal_" not in c["clip"], c["clip"])) for f in families.values()]
    out = []
    while any(queues):
        for q in queues:
            if q:
                out.append(q.pop(0))
    return out


# -- stages -----------------------------------------------------------------------------------------
def retarget_cached(clip: dict, robot_name: str, work: Path) -> tuple[Path, dict]:
    """The default-options retarget of ``clip`` onto ``robot_name`` (cached); (robot.npz, meta)."""
    folder = work / "retarget" / robot_name / clip["clip"]
    npz, meta_path = folder / "robot.npz", folder / "retarget.json"
    if npz.is_file() and meta_path.is_file():
        meta = json.loads(meta_path.read_text())
        return npz, {**meta, "cached": True}
    from motok_robot.errors import MotokError
    from retarget.config import RetargetConfig
    from retarget.io import read_input, write_robot_npz
    from retarget.robot_model import load_robot
    from retarget.solve import Retargeter

    t0 = time.perf_counter()
    motion = read_input(clip["path"], asf=clip["asf"])
    config = RetargetConfig()
    retargeter = Retargeter(load_robot(robot_name), config)
    retargeter.prepare(len(motion.joints))
    result = retargeter.run(motion.joints, motion.fps, progress=False, source=motion.name)
    failed = result.failed_windows()
    if failed and not config.allow_partial:  # as `motok-robot retarget` without --allow-partial
        raise MotokError(f"retarget: {len(failed)} of {len(result.windows)} windows did not converge (first: frames "
                         f"{failed[0].start}-{failed[0].stop - 1}, {failed[0].violated or failed[0].status})")
    folder.mkdir(parents=True, exist_ok=True)
    write_robot_npz(npz, result)
    meta = {"seconds": time.perf_counter() - t0, "frames": int(len(motion.joints)), "fps": float(motion.fps),
            "source": clip["path"]}
    meta_path.write_text(json.dumps(meta, indent=1) + "\n")
    return npz, {**meta, "cached": False}


def run_variant(variant: str, npz: Path, index, out: Path, settings: dict | None = None) -> dict:
    """Feasibility stage (B, C, D; the robot's settings, the variant's, then ``settings``) and
    validation of one variant; fields of the row."""
    from motok_robot.sim.validate import validate_file

    row: dict = {"stage_s": {}}
    if variant in ("B", "C", "D"):
        from motok_robot.feasibility.config import robot_config
        from motok_robot.feasibility.stage import make_feasible, write_feasible
        from retarget.io import read_robot_npz

        t0 = time.perf_counter()
        config = robot_config(index, VARIANT_SETTINGS[variant]).with_settings(settings or {}, "--settings")
        result = make_feasible(read_robot_npz(npz), index, config)
        npz = write_feasible(result, out / "feasible", index.name)
        row["stage_s"]["feasible"] = time.perf_counter() - t0
        shift = result.record.get("zmp_shift") or {}
        row["stage"] = {"fell": result.fell, "time_warp": result.record["time_warp"],
                        "base_drift_max_m": result.record["executed"]["base_drift_max_m"],
                        "com_shift_m_max": shift.get("com_shift_m_max"),
                        "zmp_outside_before": shift.get("zmp_outside_before"),
                        "zmp_outside_after": shift.get("zmp_outside_after"),
                        "own_steps": {k: v for k, v in result.record["gait"].items() if k != "footholds"}
                        if "gait" in result.record else None,
                        "timing_s": result.record["timing_s"]}
    t0 = time.perf_counter()
    report = validate_file(npz, index, out_dir=out / "validation", plots=False, render=False).report
    row["stage_s"]["validate"] = time.perf_counter() - t0
    m = report["metrics"]
    row.update(duration_s=report["input"]["duration_s"], passed=bool(report["passed"]),
               failed_checks=list(report["failed_checks"]), metrics={k: m.get(k) for k in METRICS},
               servo_goals_mode=(report.get("servo_goals") or {}).get("mode"))
    return row


# -- output -----------------------------------------------------------------------------------------
def summary_rows(rows: list[dict]) -> list[dict]:
    out = []
    keys = sorted({(r["robot"], r["group"], r["variant"]) for r in rows})
    for robot, group, variant in keys:
        sel = [r for r in rows if (r["robot"], r["group"], r["variant"]) == (robot, group, variant)]
        ok = [r for r in sel if r.get("error") is None]
        out.append({"robot": robot, "group": group, "variant": f"{variant} ({VARIANTS[variant]})", "clips": len(sel),
                    "passed": sum(r["passed"] for r in ok), "fell": sum(bool(r["metrics"]["fell"]) for r in ok),
                    "errors": len(sel) - len(ok)})
    return out


def failing_checks(rows: list[dict]) -> dict:
    """{robot: {variant: [(check, count), ...]}}, most common first."""
    out: dict = {}
    for r in rows:
        if r.get("error") is None:
            out.setdefault(r["robot"], {}).setdefault(r["variant"], Counter()).update(r["failed_checks"])
    return {robot: {v: c.most_common() for v, c in sorted(per.items())} for robot, per in out.items()}


def table_rows(rows: list[dict]) -> list[dict]:
    out = []
    for r in rows:
        m = r.get("metrics") or {}
        fall = "-" if m.get("fell") is None else (f"{m['fall_time_s']:.2f} s" if m["fell"] else "no")
        out.append({"clip": r["clip"], "group": r["group"], "v": r["variant"], "robot": r["robot"],
                    "dur s": r.get("duration_s"), "fall": fall, "drift m": m.get("base_drift_m"),
                    "track rad": m.get("tracking_rmse_rad"), "pose m": m.get("pose_error_mean_m"),
                    "head rad": m.get("heading_error_max_rad"), "zmp out": m.get("zmp_outside_ratio"),
                    "torque": m.get("max_torque_ratio"),
                    "result": ("ERROR " + r["error"].splitlines()[0][:60]) if r.get("error") else
                              ("PASS" if r["passed"] else ", ".join(r["failed_checks"]))})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", nargs="+", default=["op3_like"])
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--clips", nargs="+", default=None, metavar="GLOB", help="keep clips whose name matches one glob")
    ap.add_argument("--groups", nargs="+", default=None, choices=("locomotion", "other"))
    ap.add_argument("--max-clips", type=int, default=None, metavar="N", help="the first N clips (after the filters)")
    ap.add_argument("--datasets", type=Path, default=REPO_ROOT.parent / "shared" / "datasets")
    ap.add_argument("--work", type=Path, default=Path("/tmp/feasibility_mocap"),
                    help="extracted clips, cached retargets and the per-variant outputs")
    ap.add_argument("--out", type=Path, default=None,
                    help="JSON (default benchmarks/results/feasibility_mocap_<robots>.json)")
    ap.add_argument("--settings", type=json.loads, default={}, metavar="JSON",
                    help="feasibility settings applied over each variant's, e.g. "
                         "'{\"gait\": {\"damping_speed_share\": 0}}' (recorded in the JSON)")
    args = ap.parse_args(argv)
    out = args.out or RESULTS_DIR / f"feasibility_mocap_{'+'.join(args.robots)}.json"

    if not args.datasets.is_dir():
        print(f"skip: datasets folder {args.datasets} not found (the clips come from ../shared/datasets)", file=sys.stderr)
        return 0
    clips, found = find_clips(args.datasets, args.work)
    if args.clips:
        clips = [c for c in clips if any(fnmatch.fnmatch(c["clip"], g) for g in args.clips)]
    if args.groups:
        clips = [c for c in clips if c["group"] in args.groups]
    if args.max_clips is not None:
        clips = clips[:args.max_clips]
    if not clips:
        print("no clips found; nothing to do", file=sys.stderr)
        return 0
    for key, value in found.items():
        print(f"{key}: {value}", flush=True)
    print(f"{len(clips)} clips ({sum(c['group'] == 'locomotion' for c in clips)} locomotion), robots {args.robots}, "
          f"variants {args.variants}", flush=True)

    from motok_robot.robots import load
    from motok_robot.robots.index import index_robot

    started = time.perf_counter()
    rows: list[dict] = []
    meta = {"variants": {v: VARIANTS[v] for v in args.variants}, "settings": args.settings,
            "found": found, "datasets": str(args.datasets),
            "clips": [{k: c[k] for k in ("clip", "group", "source") if k in c} | {"label": c.get("label")} for c in clips]}
    machine = machine_description()
    import motok_robot
    import retarget

    meta["code"] = {"motok_robot": str(Path(motok_robot.__file__).parent), "retarget": str(Path(retarget.__file__).parent),
                    "pythonpath": os.environ.get("PYTHONPATH"), "retarget_cache": os.environ.get("MOTOK_ROBOT_CACHE")}
    n_total = len(args.robots) * len(clips) * len(args.variants)
    for robot_name in args.robots:
        index = index_robot(load(robot_name))
        for clip in clips:
            base = {"clip": clip["clip"], "group": clip["group"], "robot": robot_name}
            try:
                npz, rmeta = retarget_cached(clip, robot_name, args.work)
                retarget_error = None
            except Exception as exc:  # recorded, the run goes on
                rmeta, retarget_error = {"seconds": None, "cached": False}, f"{type(exc).__name__}: {exc}"
                retarget_traceback = traceback.format_exc(limit=6)
            for variant in args.variants:
                row = {**base, "variant": variant, "duration_s": None, "passed": False, "failed_checks": [],
                       "metrics": {k: None for k in METRICS}, "error": None}
                stage_s = {"retarget": rmeta.get("seconds"), "retarget_cached": rmeta.get("cached"),
                           "feasible": None, "validate": None}
                if retarget_error is not None:
                    row["error"], row["traceback"] = retarget_error, retarget_traceback
                else:
                    try:
                        part = run_variant(variant, npz, index, args.work / "runs" / robot_name / clip["clip"] / variant,
                                           args.settings)
                        stage_s.update(part.pop("stage_s"))
                        row.update(part)
                    except Exception as exc:
                        row["error"] = f"{type(exc).__name__}: {exc}"
                        row["traceback"] = traceback.format_exc(limit=6)
                row["stage_s"] = stage_s
                rows.append(row)
                m = row["metrics"]
                verdict = ("ERROR " + row["error"].splitlines()[0][:200]) if row["error"] else \
                    ("PASS" if row["passed"] else "FAIL " + ", ".join(row["failed_checks"]))
                fall = "" if m["fell"] is None else (f", fell at {m['fall_time_s']:.2f} s" if m["fell"] else ", stayed up")
                times = ", ".join(f"{k} {v:.1f} s" for k, v in stage_s.items()
                                  if isinstance(v, float) and k != "retarget_cached")
                print(f"[{len(rows)}/{n_total}] {robot_name} {clip['clip']} {variant}: {verdict}{fall} ({times}; "
                      f"{time.perf_counter() - started:.0f} s so far)", flush=True)
            write_json(out, {**meta, "machine": machine, "wall_s": time.perf_counter() - started,
                             "summary": summary_rows(rows), "failing_checks": failing_checks(rows), "rows": rows})
    wall = time.perf_counter() - started
    print()
    print(markdown_table(table_rows(rows)))
    print("\npass counts per group x variant:")
    print(markdown_table(summary_rows(rows)))
    print("\nmost common failing checks:")
    for robot, per in failing_checks(rows).items():
        for variant, counts in per.items():
            print(f"  {robot} {variant}: " + (", ".join(f"{k} {n}" for k, n in counts) or "none"))
    machine["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    write_json(out, {**meta, "machine": machine, "wall_s": wall, "summary": summary_rows(rows),
                     "failing_checks": failing_checks(rows), "rows": rows})
    print(f"\n{len(rows)} rows in {wall:.0f} s; wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
