"""benchmarks/ship_gate.py: the rules file, the decision on synthetic measurements, resuming, --dry-run."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

import ship_gate as sg  # noqa: E402

from motok_robot.errors import InputError  # noqa: E402

PROMPTS = [line.strip() for line in (REPO / "examples" / "prompts_eight.txt").read_text().splitlines() if line.strip()]
CHECKS = sg.rt.CHECKS


def _rules(tmp_path: Path, text: str | None = None) -> sg.Rules:
    path = tmp_path / "rules.toml"
    path.write_text(sg.DEFAULT_RULES.read_text() if text is None else text)
    return sg.load_rules(path)


def _measured(rules: sg.Rules, robot_fails: dict | None = None, behaviour: dict | None = None,
              generation: dict | None = None) -> dict:
    """Both sides equal (every cell passes but the kick, 90 of 96 seeds per check, FID 0.19, top-3 0.58),
    with the candidate changed by ``robot_fails`` ({(prompt index, seed): passed}), ``behaviour``
    ({check: count}) and ``generation`` ({metric: mean})."""
    def robot(changes: dict) -> dict:
        return {str(s): {p: (i != 6) if (i, s) not in changes else changes[(i, s)] for i, p in enumerate(PROMPTS)}
                for s in rules.robot_seeds}

    base_b = {c: 90 for c in CHECKS} | {"seeds": 96}
    base_g = {"fid": 0.19, "r_precision_top1": 0.26, "r_precision_top3": 0.58}
    return {"prompts": PROMPTS, "robot": {"shipped": robot({}), "candidate": robot(robot_fails or {})},
            "behaviour": {"shipped": base_b, "candidate": base_b | (behaviour or {})},
            "generation": {"shipped": base_g, "candidate": base_g | (generation or {})}, "missing": []}


def _failing(verdicts: list[dict]) -> list[str]:
    return [v["rule"] for v in verdicts if not v["passed"]]


# -- rules --------------------------------------------------------------------------------------------
def test_default_rules_state_the_project_rules():
    rules = sg.load_rules(sg.DEFAULT_RULES)
    assert rules.robot_seeds == [0, 1, 2, 3, 4]
    assert rules.prompts == REPO / "examples" / "prompts_eight.txt"
    assert rules.robot_total.value == rules.robot_prompt.value == rules.behaviour.value == 0
    assert rules.behaviour_ranges() == [(0, 48), (48, 48)]
    assert {"fid", "r_precision_top3"} <= set(rules.generation)
    for _, limit in rules.limits():
        assert limit.reason and "\n" not in limit.reason
    assert len(rules.sha256) == 64


@pytest.mark.parametrize("edit, field", [
    (lambda t: t.replace("max_total_drop_reason", "# max_total_drop_reason"), "robot.max_total_drop_reason"),
    (lambda t: t.replace("max_drop = 0", "max_dorp = 0"), "behaviour.max_dorp"),
    (lambda t: t.replace("seeds = [0, 1, 2, 3, 4]", 'seeds = "0-4"'), "robot.seeds"),
    (lambda t: t.replace("seeds = [0, 1, 2, 3, 4]", "seeds = [0, 1, 1]"), "robot.seeds"),
    (lambda t: t.replace("max_prompt_drop = 0", "max_prompt_drop = -1"), "robot.max_prompt_drop"),
    (lambda t: t.replace("max_increase = 0.01", "max_increase = 0.01\nmax_decrease = 0.01"), "generation.fid"),
    (lambda t: t.replace("max_increase = 0.01", 'max_increase = "small"'), "generation.fid.max_increase"),
    (lambda t: t.replace("repeats = 5", "repeats = 0"), "generation.repeats"),
    (lambda t: t.replace("[behaviour]", "[behavior]"), "behavior"),
    (lambda t: t.replace("[robot]", "[robot"), "not readable as TOML"),
])
def test_a_bad_rules_file_is_one_line_naming_the_file_and_field(tmp_path, edit, field):
    path = tmp_path / "rules.toml"
    path.write_text(edit(sg.DEFAULT_RULES.read_text()))
    with pytest.raises(InputError) as err:
        sg.load_rules(path)
    message = str(err.value)
    assert message.startswith(str(path)) and field in message and "\n" not in message


def test_a_missing_rules_file_is_named(tmp_path):
    with pytest.raises(InputError, match="rules file not found"):
        sg.load_rules(tmp_path / "none.toml")


# -- the decision -------------------------------------------------------------------------------------
def test_equal_measurements_ship(tmp_path):
    rules = _rules(tmp_path)
    decision, verdicts = sg.decide(rules, _measured(rules))
    assert decision == sg.SHIP and not _failing(verdicts)
    total = verdicts[0]
    assert total["shipped"] == total["candidate"] == 35  # 7 passing prompts x 5 seeds
    assert len(verdicts) == 1 + len(PROMPTS) + len(CHECKS) + len(rules.generation)


def test_better_measurements_ship(tmp_path):
    rules = _rules(tmp_path)
    better = _measured(rules, robot_fails={(6, 2): True}, behaviour={"bow": 95}, generation={"fid": 0.15})
    decision, verdicts = sg.decide(rules, better)
    assert decision == sg.SHIP
    assert verdicts[0]["candidate"] == 36 and "gained 1" in verdicts[0]["note"]


def test_one_prompt_seed_cell_regressed_does_not_ship(tmp_path):
    rules = _rules(tmp_path)
    decision, verdicts = sg.decide(rules, _measured(rules, robot_fails={(5, 3): False}))
    assert decision == sg.NO_SHIP
    assert _failing(verdicts) == ["robot: cells passing, seeds 0-4", f"robot: {PROMPTS[5]!r}, seeds passing"]
    assert f"{PROMPTS[5]!r} seed 3" in verdicts[0]["note"]


def test_a_loss_on_one_prompt_is_not_paid_for_by_a_gain_on_another(tmp_path):
    rules = _rules(tmp_path)
    decision, verdicts = sg.decide(rules, _measured(rules, robot_fails={(0, 1): False, (6, 1): True}))
    assert decision == sg.NO_SHIP and _failing(verdicts) == [f"robot: {PROMPTS[0]!r}, seeds passing"]
    # one prompt passing on another seed than before keeps its count: no regression
    swap = _measured(rules)
    swap["robot"]["shipped"]["0"][PROMPTS[6]] = True
    swap["robot"]["candidate"]["1"][PROMPTS[6]] = True
    assert sg.decide(rules, swap)[0] == sg.SHIP


def test_a_behaviour_or_generation_regression_does_not_ship(tmp_path):
    rules = _rules(tmp_path)
    decision, verdicts = sg.decide(rules, _measured(rules, behaviour={"walk_planted": 89}))
    assert decision == sg.NO_SHIP and _failing(verdicts) == ["behaviour: walk_planted, seeds passing"]
    assert sg.decide(rules, _measured(rules, generation={"fid": 0.19 + 0.009}))[0] == sg.SHIP
    decision, verdicts = sg.decide(rules, _measured(rules, generation={"fid": 0.19 + 0.011}))
    assert decision == sg.NO_SHIP and _failing(verdicts) == ["generation: fid"]
    decision, verdicts = sg.decide(rules, _measured(rules, generation={"r_precision_top3": 0.55}))
    assert _failing(verdicts) == ["generation: r_precision_top3"]


@pytest.mark.parametrize("drop", [
    lambda m: m["robot"]["candidate"].pop("4"),
    lambda m: m["robot"]["candidate"]["2"].pop(PROMPTS[3]),
    lambda m: m["robot"]["shipped"].clear(),
    lambda m: m["behaviour"].update(candidate=None),
    lambda m: m["behaviour"]["shipped"].pop("bow"),
    lambda m: m["generation"].update(shipped=None),
    lambda m: m["generation"]["candidate"].pop("r_precision_top1"),
    lambda m: m.update(prompts=[]),
])
def test_a_missing_measurement_does_not_ship(tmp_path, drop):
    rules = _rules(tmp_path)
    measured = _measured(rules)
    drop(measured)
    decision, verdicts = sg.decide(rules, measured)
    assert decision == sg.NO_SHIP
    assert any("missing" in v["note"] for v in verdicts if not v["passed"])


def test_rules_changed_after_the_start_do_not_ship(tmp_path):
    rules = _rules(tmp_path)
    weights = {side: {"tokenizer": "a" * 64, "planner": "b" * 64} for side in sg.SIDES}
    start = {"rules_sha256": rules.sha256, "weights": weights}
    good = sg.integrity_verdicts(rules, start, weights)
    assert all(v["passed"] for v in good)
    assert sg.decide(rules, _measured(rules), good)[0] == sg.SHIP
    rules.path.write_text(rules.path.read_text().replace("max_drop = 0", "max_drop = 5"))
    changed = sg.integrity_verdicts(rules, start, weights)
    assert [v["rule"] for v in changed if not v["passed"]] == ["rules file unchanged since the run started"]
    assert sg.decide(rules, _measured(rules), changed)[0] == sg.NO_SHIP
    moved = {**weights, "candidate": {"tokenizer": "a" * 64, "planner": "c" * 64}}
    rules.path.write_text(sg.DEFAULT_RULES.read_text())
    assert [v["rule"] for v in sg.integrity_verdicts(rules, start, moved) if not v["passed"]] == [
        "candidate planner weights unchanged since the run started"]


# -- running: resume, the start record, --dry-run -----------------------------------------------------
def _run(folder: Path, name: str, content: bytes) -> Path:
    folder = folder / name
    folder.mkdir(parents=True)
    (folder / "config.json").write_text("{}")
    (folder / "model.safetensors").write_bytes(content)
    return folder


@pytest.fixture
def setup(tmp_path, monkeypatch):
    shipped = tmp_path / "models"
    _run(shipped, "tokenizer", b"shipped tokenizer")
    _run(shipped, "planner_masked", b"shipped planner")
    monkeypatch.setattr(sg, "SHIPPED_MODELS", shipped)
    candidate = tmp_path / "cand"
    rules = _rules(tmp_path)
    return sg.Setup(rules, tmp_path / "work", "masked", tmp_path / "prepared",
                    _run(candidate, "tok", b"candidate tokenizer"), _run(candidate, "plan", b"candidate planner"))


def _finish(setup: sg.Setup, part: sg.Part, bow: int, robot_pass: bool = True) -> None:
    """Write what ``part`` would have written, and its .done record."""
    if part.name.startswith("robot_"):
        part.output.mkdir(parents=True)
        with open(part.output / "summary.csv", "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=["index", "text", "passed"])
            writer.writeheader()
            for i, text in enumerate(PROMPTS):
                writer.writerow({"index": i, "text": text, "passed": robot_pass or i != 0})
                clip = part.output / f"{i:03d}_clip"
                clip.mkdir()
                (clip / "pipeline.json").write_text(json.dumps({"text": text, "passed": robot_pass or i != 0,
                                                                "failed_checks": [], "seed": 0}))
    elif part.name.startswith("behaviour_"):
        count = int(part.argv[part.argv.index("--seeds") + 1])
        first = int(part.argv[part.argv.index("--first-seed") + 1])
        seeds = [{"seed": first + k, **{c: {"passed": c != "bow" or k < bow} for c in CHECKS}} for k in range(count)]
        part.output.write_text(json.dumps({"seeds": count, "first_seed": first,
                                           "rows": [{"planner": "masked", "decoder_seed": None, "seeds": seeds},
                                                    {"rows": "real Bandai clips", "bow": "13/15",
                                                     "raise_both_hands": "374/434"}]}))
    else:
        rows = [{"name": "real (test)", "kind": "reference", "metrics": {}},
                {"name": "masked", "kind": "model", "metrics": {m: {"mean": v, "ci95": 0.01} for m, v in
                                                                 {"fid": 0.19, "r_precision_top1": 0.26,
                                                                  "r_precision_top3": 0.58}.items()}}]
        part.output.write_text(json.dumps({"models": {"masked": "x"}, "rows": rows}))
    done = sg.done_file(setup.work, part)
    done.parent.mkdir(parents=True, exist_ok=True)
    done.write_text(json.dumps({"argv": part.argv, "env": part.env, "rc": 0}))


def _no_children(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("a finished part was run again")

    monkeypatch.setattr(sg, "run_part", refuse)


def test_a_finished_gate_is_read_not_rerun(setup, tmp_path, monkeypatch, capsys):
    _no_children(monkeypatch)
    setup.work.mkdir()
    start = {"rules_sha256": setup.rules.sha256, "weights": sg.digests(setup), "planner": "masked"}
    (setup.work / "start.json").write_text(json.dumps(start))
    for part in sg.plan(setup):
        shipped = "_shipped" in part.name
        _finish(setup, part, bow=30 if shipped else 31, robot_pass=shipped or part.name != "robot_candidate_s2")
    out = tmp_path / "ship_gate.json"
    assert sg.gate(setup, out) == 1  # the walk failed on seed 2 for the candidate
    result = json.loads(out.read_text())
    assert result["decision"] == sg.NO_SHIP and result["rules"]["sha256"] == setup.rules.sha256
    failing = [v["rule"] for v in result["verdicts"] if not v["passed"]]
    assert failing == ["robot: cells passing, seeds 0-4", f"robot: {PROMPTS[0]!r}, seeds passing"]
    bow = next(v for v in result["verdicts"] if v["rule"] == "behaviour: bow, seeds passing")
    assert (bow["shipped"], bow["candidate"]) == (60, 62)
    text = capsys.readouterr().out
    assert "finished before" in text and "DO NOT SHIP" in text
    # the candidate's models folder links its own tokenizer and planner
    assert (setup.candidate_models / "planner_masked").resolve() == setup.candidate_planner


def test_a_gate_whose_rules_changed_since_its_start_runs_nothing(setup, tmp_path, monkeypatch, capsys):
    _no_children(monkeypatch)
    setup.work.mkdir()
    (setup.work / "start.json").write_text(json.dumps({"rules_sha256": "0" * 64, "weights": sg.digests(setup)}))
    out = tmp_path / "ship_gate.json"
    assert sg.gate(setup, out) == 1
    result = json.loads(out.read_text())
    assert result["decision"] == sg.NO_SHIP and result["rules"]["sha256_at_start"] == "0" * 64
    assert "nothing is run" in capsys.readouterr().out


def test_a_failed_part_is_a_missing_measurement(setup, tmp_path, monkeypatch):
    parts = sg.plan(setup)
    for part in parts:
        if part.name != "generation_candidate":
            _finish(setup, part, bow=30)
    monkeypatch.setattr(sg, "run_part", lambda work, part, i, n: 3)
    setup.work.mkdir(exist_ok=True)
    (setup.work / "start.json").write_text(json.dumps({"rules_sha256": setup.rules.sha256,
                                                       "weights": sg.digests(setup)}))
    assert sg.gate(setup, tmp_path / "g.json") == 1
    result = json.loads((tmp_path / "g.json").read_text())
    assert result["failed_parts"] == ["generation_candidate"]
    assert "generation candidate: the run failed" in result["measured"]["missing"]


def test_dry_run_lists_the_commands_and_runs_nothing(tmp_path, monkeypatch, capsys):
    _no_children(monkeypatch)
    work = tmp_path / "work"
    code = sg.main(["--candidate-tokenizer", "runs/tok", "--candidate-planner", "runs/plan", "--planner", "ar",
                    "--work", str(work), "--dry-run"])
    assert code == 0 and not work.exists()
    text = capsys.readouterr().out
    assert "max_total_drop" in text and "sha256" in text
    runs = [line.strip() for line in text.splitlines() if line.strip().startswith("motok-robot run")]
    assert len(runs) == 10
    assert all("--prompts examples/prompts_eight.txt" in r and "--no-render --no-plots --planner ar" in r for r in runs)
    assert sum("--tokenizer runs/tok --planner-run runs/plan" in r for r in runs) == 5
    assert [r.split("--seed ")[1].split()[0] for r in runs] == ["0", "1", "2", "3", "4"] * 2
    behaviour = [line for line in text.splitlines() if "benchmarks/planner_behaviour.py" in line]
    assert len(behaviour) == 4 and sum("MOTOK_ROBOT_MODELS=" in b for b in behaviour) == 2
    generation = [line for line in text.splitlines() if "motok-robot eval generation" in line]
    assert len(generation) == 2 and all("--repeats 5 --mm-texts 20 --mm-repeats 10" in g for g in generation)


def test_publishing_a_candidate_needs_a_ship(setup):
    setup.work.mkdir()
    (setup.work / "decision.json").write_text(json.dumps({"decision": sg.NO_SHIP, "planner": "masked"}))
    with pytest.raises(InputError, match="the gate said DO NOT SHIP"):
        sg.publish(setup, "candidate")
    (setup.work / "decision.json").write_text(json.dumps({"decision": sg.SHIP, "planner": "masked",
                                                          "weights": sg.digests(setup)}))
    with pytest.raises(InputError, match="not the ones in models/"):
        sg.publish(setup, "candidate")


def test_publishing_the_shipped_side_feeds_the_readme_tables(setup, tmp_path, monkeypatch):
    _no_children(monkeypatch)
    setup.work.mkdir()
    (setup.work / "start.json").write_text(json.dumps({"rules_sha256": setup.rules.sha256,
                                                       "weights": sg.digests(setup)}))
    for part in sg.plan(setup):
        _finish(setup, part, bow=40)
    assert sg.gate(setup, tmp_path / "g.json") == 0
    results = tmp_path / "results"
    results.mkdir()
    ar_row = {"planner": "ar", "decoder_seed": None, "seeds": [{c: {"passed": True} for c in CHECKS}] * 48}
    for name in sg.rt.BEHAVIOUR:
        (results / name).write_text(json.dumps({"rows": [ar_row, {"planner": "masked", "decoder_seed": None,
                                                                  "seeds": []}]}))
    written = sg.publish(setup, "shipped", results)
    assert {p.name for p in written} == {sg.rt.ROBOT_EIGHT, "generation_masked.json", *sg.rt.BEHAVIOUR}
    counts, _, span = sg.rt.behaviour_counts(results, {})
    assert span == "0-95" and counts["masked"]["bow"] == 80 and counts["ar"]["bow"] == 96
    robot = json.loads((results / sg.rt.ROBOT_EIGHT).read_text())
    assert [r["text"] for r in robot["rows"]] == PROMPTS


def test_a_child_runs_logs_and_is_recorded_only_when_it_succeeds(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sg, "HEARTBEAT_S", 0.05)
    work = tmp_path / "work"
    out = tmp_path / "made.txt"
    ok = sg.Part("ok", "a child", ["python", "-c", f"import os, time; time.sleep(0.3); print(os.environ['OMP_NUM_THREADS']); "
                                   f"open({str(out)!r}, 'w').write('x')"], {}, out)
    assert sg.run_part(work, ok, 1, 2) == 0 and sg.finished(work, ok)
    assert (work / "logs" / "ok.log").read_text().splitlines()[-1] == "1"  # one thread
    assert "still running" in capsys.readouterr().out
    bad = sg.Part("bad", "a failing child", ["python", "-c", "raise SystemExit(3)"], {}, tmp_path)
    assert sg.run_part(work, bad, 2, 2) == 3 and not sg.finished(work, bad)
    changed = sg.Part("ok", "a child", [*ok.argv[:-1], "print(1)"], {}, out)
    assert not sg.finished(work, changed)  # another command is not the finished part
