"""benchmarks/readme_table.py: tables from result JSON, stale-table checks, the weights guard."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

import readme_table as rt  # noqa: E402

SHIPPED = {"tokenizer": "aaaaaaaaaaaa", "planner_masked": "bbbbbbbbbbbb", "planner_ar": "cccccccccccc"}


def _model_id(kind: str, planner: str, tokenizer: str = "aaaaaaaaaaaa") -> str:
    return f"tokenizer=tokenizer@{tokenizer};planner={kind}:planner_{kind}@{planner};text=minilm:x"


def _metric(mean: float, ci: float = 0.01) -> dict:
    return {"mean": mean, "ci95": ci, "values": [mean]}


def _generation(results: Path, kind: str, planner: str, fid: float) -> None:
    rows = [{"name": "real (test)", "kind": "reference", "metrics": {"r_precision_top3": _metric(0.64)}},
            {"name": kind, "kind": "generated", "metrics": {"fid": _metric(fid), "r_precision_top3": _metric(0.5)}}]
    (results / rt.GENERATION[kind]).write_text(json.dumps({"models": {kind: _model_id(kind, planner)}, "rows": rows}))


def _behaviour(results: Path, name: str, first: int, n: int, bows: int) -> None:
    rows = []
    for kind, planner in (("masked", "bbbbbbbbbbbb"), ("ar", "cccccccccccc")):
        seeds = [{c: {"passed": c != "bow" or s < bows} for c in rt.CHECKS} for s in range(n)]
        rows.append({"rows": kind, "planner": kind, "model": _model_id(kind, planner), "decoder_seed": None, "seeds": seeds})
    rows.append({"rows": "real clips", "model": "x", "bow": "13/15", "raise_both_hands": "374/434", "clips": []})
    (results / name).write_text(json.dumps({"seeds": n, "first_seed": first, "rows": rows}))


def test_model_digests_reads_the_ids_generate_records():
    assert rt.model_digests(_model_id("masked", "1522579cf9aa")) == {"tokenizer": "aaaaaaaaaaaa", "planner": "1522579cf9aa"}
    assert rt.model_digests("no digests here") == {}


def test_a_result_measured_on_other_weights_is_refused_naming_the_file(tmp_path):
    _generation(tmp_path, "masked", "bbbbbbbbbbbb", 0.19)
    _generation(tmp_path, "ar", "dddddddddddd", 0.20)  # not the shipped AR planner
    with pytest.raises(rt.SourceError, match=r"generation_ar\.json: measured planner weights dddddddddddd.*cccccccccccc"):
        rt.render("generation", tmp_path, SHIPPED)


def test_generation_table_prints_each_metric_with_its_interval(tmp_path):
    _generation(tmp_path, "masked", "bbbbbbbbbbbb", 0.191)
    _generation(tmp_path, "ar", "cccccccccccc", 0.202)
    table = rt.render("generation", tmp_path, SHIPPED)
    lines = table.splitlines()
    assert lines[0].startswith("|  | FID")
    assert "| masked | 0.191 ± 0.010 |" in table and "| ar | 0.202 ± 0.010 |" in table
    assert "| real (test) | - |" in table  # no FID recorded for the real row: a dash, not a number


def test_behaviour_counts_add_the_seed_ranges_and_refuse_overlaps(tmp_path):
    _behaviour(tmp_path, rt.BEHAVIOUR[0], 0, 4, bows=3)
    _behaviour(tmp_path, rt.BEHAVIOUR[1], 4, 4, bows=1)
    counts, real, span = rt.behaviour_counts(tmp_path, SHIPPED)
    assert span == "0-7" and counts["masked"]["bow"] == 4 and counts["ar"]["walk"] == 8
    assert real == {"real clips": "bows 13/15, both hands 374/434"}
    _behaviour(tmp_path, rt.BEHAVIOUR[1], 2, 4, bows=1)  # seeds 2-5 overlap 0-3
    with pytest.raises(rt.SourceError, match="overlap"):
        rt.behaviour_counts(tmp_path, SHIPPED)


def test_a_missing_source_names_the_file(tmp_path):
    with pytest.raises(rt.SourceError, match=r"robot_eight\.json: missing"):
        rt.render("robot", tmp_path, SHIPPED)


def _clip(batch: Path, folder: str, text: str, passed: bool, failed: list[str], retime: float, zmp) -> None:
    (batch / folder).mkdir(parents=True)
    (batch / folder / "pipeline.json").write_text(json.dumps(
        {"text": text, "seconds": 1.8, "seed": 0, "passed": passed, "failed_checks": failed,
         "timings_s": {"retarget": 1.5, "validate": 0.2, "total": 9.0}, "playback": {"status": "completed"},
         "retime_factor": retime, "zmp_weight": zmp, "model": _model_id("masked", "bbbbbbbbbbbb"), "notes": ["n"]}))


def test_import_batches_then_robot_table(tmp_path):
    first, rest = tmp_path / "eight", tmp_path / "rest"
    _clip(first, "000_a_person_waves", "a person waves the right hand", True, [], 1.0, 0.0)
    (first / ".001_a_person_kicks.partial-1").mkdir()  # a clip the batch did not finish: ignored
    _clip(rest, "000_a_person_kicks", "a person kicks with the right leg", False, ["torque", "zmp"], 2.0, 1000.0)
    results = tmp_path / "results"
    rt.import_batches([first, rest], results / rt.ROBOT_EIGHT)
    data = json.loads((results / rt.ROBOT_EIGHT).read_text())
    assert data["models"] == [_model_id("masked", "bbbbbbbbbbbb")] and "machine" in data
    assert [r["folder"] for r in data["rows"]] == ["eight/000_a_person_waves", "rest/000_a_person_kicks"]
    table = rt.render("robot", results, SHIPPED)
    assert "| a person waves the right hand | 1.8 | **yes** | - | - | 1x | 1.5 | - | 0.2 | 9.0 |" in table
    assert "| a person kicks with the right leg | 1.8 | no | torque, zmp | yes | 2x |" in table
    with pytest.raises(rt.SourceError, match="no clip folder"):
        rt.import_batches([tmp_path / "results"], results / rt.ROBOT_EIGHT)


def test_refresh_rewrites_marked_tables_and_check_fails_on_a_stale_one(tmp_path):
    _generation(tmp_path, "masked", "bbbbbbbbbbbb", 0.191)
    _generation(tmp_path, "ar", "cccccccccccc", 0.202)
    doc = tmp_path / "doc.md"
    doc.write_text("intro\n<!-- table:generation -->\n| old |\n<!-- /table -->\nend\n")
    new, changed = rt.refresh(doc.read_text(), tmp_path, SHIPPED)
    assert changed == ["generation"] and "| masked | 0.191 ± 0.010 |" in new and new.endswith("<!-- /table -->\nend\n")
    assert rt.refresh(new, tmp_path, SHIPPED) == (new, [])
    doc.write_text(new)
    _generation(tmp_path, "masked", "bbbbbbbbbbbb", 0.150)  # a new measurement: the doc is now stale
    assert rt.refresh(doc.read_text(), tmp_path, SHIPPED)[1] == ["generation"]


def test_safetensors_parameters_reads_the_header_only(tmp_path):
    header = json.dumps({"__metadata__": {"a": "b"}, "w": {"dtype": "F32", "shape": [3, 4], "data_offsets": [0, 48]},
                         "b": {"dtype": "F32", "shape": [4], "data_offsets": [48, 64]}}).encode()
    path = tmp_path / "model.safetensors"
    path.write_bytes(len(header).to_bytes(8, "little") + header + bytes(64))
    assert rt.safetensors_parameters(path) == 16
    path.write_bytes(b"\xff" * 16)
    with pytest.raises(rt.SourceError, match="not a safetensors file"):
        rt.safetensors_parameters(path)


def test_the_readme_and_model_card_tables_are_current():
    """Every number in the README's and the model card's generated tables is what the JSON in
    benchmarks/results (and models/) give today: re-measure, then `readme_table.py --write`."""
    if not all((REPO / "models" / d / "model.safetensors").is_file() for d in ("tokenizer", "planner_masked", "planner_ar")):
        pytest.skip("trained models are not in models/")
    bases = [(folder, base[0]) for folder, _, base, _ in rt.TRAINING if base is not None]
    if any(rt._last_row_at(commit, f"models/{folder}/metrics.csv") is None for folder, commit in bases):
        pytest.skip("the base runs' commits are not in this clone's git history (a shallow clone?)")
    assert rt.main(["--check", str(REPO / "README.md"), str(REPO / "models" / "MODEL_CARD.md")]) == 0
