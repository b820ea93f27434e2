"""The shared benchmark helpers (benchmarks/common.py) and bench_all's planning and report."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))

import bench_all  # noqa: E402
import common  # noqa: E402


def test_machine_description_names_the_hardware_and_versions():
    m = common.machine_description(threads=2)
    for key in ("cpu", "logical_cores", "usable_cores", "ram_gb", "python", "versions", "commit", "date_utc"):
        assert key in m, key
    assert m["threads"] == 2 and m["logical_cores"] >= 1 and m["versions"]["numpy"] == np.__version__
    line = common.machine_summary(m)
    assert str(m["cpu"]) in line and "usable cores" in line


def test_time_median_runs_the_function_the_requested_number_of_times():
    calls = []

    def work():
        calls.append(1)
        time.sleep(0.002)

    t = common.time_median(work, repeat=5, warmup=2)
    assert len(calls) == 7 and len(t["runs_s"]) == 5
    assert t["min_s"] <= t["median_s"] <= t["max_s"] and t["median_s"] >= 0.002
    assert t["cpu_median_s"] < t["median_s"]  # sleeping costs no CPU
    with pytest.raises(ValueError):
        common.time_median(work, repeat=0)


def test_peak_memory_sees_a_large_allocation():
    def allocate():
        # 256 MB: glibc may keep up to 64 MB that earlier tests freed and hand it back without
        # the process growing (a 40 MB block grew it by 24 MB once in a full run)
        block = np.ones(256 * 2**20 // 8)
        time.sleep(0.3)  # long enough for the sampling thread on a loaded machine (0.05 s missed it once in CI)
        return float(block[-1])

    value, mem = common.measure_peak_memory(allocate, python_heap=True)
    assert value == 1.0
    assert mem["rss_increase_mb"] > 180 and mem["rss_peak_mb"] >= mem["rss_increase_mb"]
    assert mem["python_peak_mb"] > 250  # numpy buffers are traced by tracemalloc
    assert common.max_rss_mb() >= mem["rss_increase_mb"]


def test_markdown_table_and_cells():
    rows = [{"name": "a|b", "ms": 1234.5, "ratio": 0.123456, "tiny": 1.5e-6, "ok": True, "nested": {"x": 1}},
            {"name": "c", "ms": 2.0, "ratio": None, "tiny": 0.0, "ok": False}]
    table = common.markdown_table(rows)
    lines = table.splitlines()
    assert lines[0] == "| name | ms | ratio | tiny | ok |"  # nested dicts are left out
    assert lines[1] == "|---|---:|---:|---:|---|"
    assert lines[2] == "| a\\|b | 1,234 | 0.1235 | 1.5e-06 | yes |"
    assert lines[3] == "| c | 2.00 | - | 0 | no |"
    assert common.markdown_table([]) == "(no rows)"


def test_write_json_adds_the_machine(tmp_path):
    path = common.write_json(tmp_path / "sub" / "r.json", {"rows": [{"a": np.float32(1.5)}], "arr": np.arange(3)})
    data = json.loads(path.read_text())
    assert data["arr"] == [0, 1, 2] and data["rows"][0]["a"] == 1.5 and "cpu" in data["machine"]


def test_bench_all_plans_runs_and_reports(tmp_path, monkeypatch):
    scripts = tmp_path / "benchmarks"
    scripts.mkdir()
    (scripts / "fast.py").write_text(
        "import argparse, json\n"
        "p = argparse.ArgumentParser(); p.add_argument('--out'); a = p.parse_args()\n"
        "print('| what | ms |'); print('written', a.out)\n"
        "json.dump({'benchmark': 'fast', 'rows': [{'what': 'x', 'ms': 1.5}], 'machine': {'cpu': 'toy'}}, open(a.out, 'w'))\n")
    (scripts / "needs_data.py").write_text(
        "import argparse\np = argparse.ArgumentParser(); p.add_argument('dataset'); p.add_argument('--json')\np.parse_args()\n")
    (scripts / "broken.py").write_text("import sys\nprint('about to fail')\nsys.exit(3)\n")
    monkeypatch.setattr(bench_all, "REPO_ROOT", tmp_path)
    found = sorted(scripts.glob("*.py"))
    invocations = {i.name: i for i in bench_all.plan(found, tmp_path / "results", data=None)}
    assert invocations["fast"].args == ["--out", str(tmp_path / "results" / "fast.json")]
    assert invocations["needs_data"].skip_reason and "--data" in invocations["needs_data"].skip_reason
    assert invocations["broken"].args == []
    with_data = {i.name: i for i in bench_all.plan(found, tmp_path / "results", data=Path("/d"))}
    assert with_data["needs_data"].args == ["/d", "--json", str(tmp_path / "results" / "needs_data.json")]
    (tmp_path / "results").mkdir()
    outcomes = [bench_all.run(i, timeout=120) for i in invocations.values()]
    status = {o.invocation.name: o.status for o in outcomes}
    assert status["fast"] == "ok" and status["broken"] == "failed (exit 3)" and status["needs_data"].startswith("skipped")
    report = tmp_path / "RESULTS.md"
    bench_all.write_report(outcomes, report, tmp_path / "results", "python benchmarks/bench_all.py")
    text = report.read_text()
    assert "Measured on:" in text and "| fast | ok |" in text and "| broken | failed (exit 3) |" in text
    assert "| what | ms |\n|---|---:|\n| x | 1.50 |" in text and "Machine: toy" in text
    assert "about to fail" in text


def test_bench_all_ignores_stale_json_of_a_failed_run(tmp_path, monkeypatch):
    scripts = tmp_path / "benchmarks"
    scripts.mkdir()
    (scripts / "flaky.py").write_text(
        "import argparse, sys\np = argparse.ArgumentParser(); p.add_argument('--out'); p.parse_args()\nsys.exit(1)\n")
    monkeypatch.setattr(bench_all, "REPO_ROOT", tmp_path)
    results = tmp_path / "results"
    results.mkdir()
    (results / "flaky.json").write_text(json.dumps({"rows": [{"stale": 1.0}]}))
    (inv,) = bench_all.plan([scripts / "flaky.py"], results, data=None)
    time.sleep(1.1)
    outcome = bench_all.run(inv, timeout=60)
    assert outcome.status == "failed (exit 1)" and outcome.json_path is None
    bench_all.write_report([outcome], tmp_path / "R.md", results, "x")
    assert "stale" not in (tmp_path / "R.md").read_text()


def test_gait_quality_splits_unplanted_frames_into_airborne_and_sliding():
    import gait_quality

    from motok_robot.motion.skeleton import rest_pose

    T = 60
    j = np.tile(rest_pose(), (T, 1, 1)).astype(np.float64)
    assert gait_quality.unplanted_shares(j, 20.0) == {"unplanted": 0.0, "airborne": 0.0, "sliding": 0.0}
    j[10:20, :, 2] += 0.4  # the whole body in the air for 10 frames
    j[40:50, :, 0] += np.arange(10)[:, None] * 0.1  # 2 m/s across the floor, feet down: sliding
    shares = gait_quality.unplanted_shares(j, 20.0)
    assert shares["airborne"] == pytest.approx(10 / T)
    assert shares["sliding"] >= 8 / T and shares["sliding"] <= 12 / T  # central differences blur the ends
    assert shares["unplanted"] == pytest.approx(shares["airborne"] + shares["sliding"])


def test_planner_context_counts_every_usable_token_and_scores_an_oracle_at_one():
    """``planner_context.context_accuracy`` on in-memory clips: clips shorter than two tokens are
    skipped, longer ones cut to the planner's longest plan; planners that return the truth
    score 1 on all three measures (infill, text only, AR next token)."""
    import planner_context
    import torch

    K = 8
    truth_of = {}

    class Tokenizer:
        frames_per_token = 4

        def encode(self, feats):
            n = feats.shape[1] // 4
            tokens = torch.arange(n)[None] % K
            truth_of["tokens"] = tokens
            return tokens

    class Oracle:  # both planners: one-hot logits of the clip's true tokens at every position
        mask_id = K
        config = type("C", (), {"max_tokens": 5, "codebook_size": K})()

        def logits(self, tokens, *args):
            truth = truth_of["tokens"][0]
            rows = tokens.shape[0]
            return torch.nn.functional.one_hot(truth, K + 1).float()[None].expand(rows, -1, -1)

    class Texts:
        def encode(self, texts):
            return torch.zeros(len(texts), 3)

    class Dataset:
        frames = {"short": 7, "mid": 12, "long": 40}

        def features(self, clip_id):
            return np.zeros((self.frames[clip_id], 263), np.float32)

        def texts(self, clip_id):
            return ["a caption"]

    acc = planner_context.context_accuracy(Oracle(), Oracle(), Tokenizer(), Texts(), Dataset(), ["short", "mid", "long"])
    assert acc == {"tokens": 3 + 5, "infill": 1.0, "text_only": 1.0, "ar_next": 1.0}


def test_planner_behaviour_counts_passes_per_check_and_passes_the_lengths(monkeypatch):
    """``planner_behaviour.planner_rows`` with a stand-in generator: a walk for the walk prompt,
    standing for everything else; the lengths asked for are the checks' (6 s, and None for the
    single actions) and are recorded per seed."""
    import planner_behaviour

    import motok_robot.planner.generate as generate_module
    from motok_robot.eval import behaviour as B
    from motok_robot.motion.synthetic import standing_clip, walking_clip

    asked, asked_steps, asked_extra = [], set(), []

    class FakeGenerator:
        model_id = "fake"

        def __init__(self, kind):
            self.kind = kind

        def generate(self, text, seconds=None, seed=0, cfg_scale=None, steps=None, **extra):
            asked.append((text, seconds, seed, cfg_scale))
            asked_steps.add(steps)
            asked_extra.append(extra)
            frames = int(20 * (seconds or 2.0))
            joints = walking_clip(frames=frames) if text == B.WALK and seed == 0 else standing_clip(frames=frames)
            return type("Motion", (), {"joints": joints, "seconds": frames / 20})()

    monkeypatch.setattr(generate_module, "MotionGenerator", FakeGenerator)
    rows = planner_behaviour.planner_rows(["masked"], range(2), B.BehaviourThresholds(), cfg=1.5)
    row = rows[0]
    assert row["walk"] == "1/2" and row["walk_seeds"] == [0]
    assert row["bow"] == "0/2" and row["raise_both_hands"] == "0/2"
    assert row["run_faster"] == "0/2"  # standing never outruns the walk, nor a standing "walk"
    assert row["seeds"][1]["seconds"] == {B.WALK: 6.0, B.RUN: 6.0, B.WAVE: 6.0, B.BOTH_HANDS: 2.0, B.BOW: 2.0}
    assert {(t, s) for t, s, _, _ in asked} == {(B.WALK, 6.0), (B.RUN, 6.0), (B.WAVE, 6.0), (B.BOTH_HANDS, None),
                                               (B.BOW, None)}
    assert {c for *_, c in asked} == {1.5} and asked_steps == {None}

    asked.clear()  # a later seed range (--first-seed) counts over its own seeds
    asked_steps.clear()
    row = planner_behaviour.planner_rows(["masked"], range(1, 3), B.BehaviourThresholds(), cfg=None, steps=3)[0]
    assert row["walk"] == "0/2" and [s["seed"] for s in row["seeds"]] == [1, 2]
    assert asked_steps == {3}
    assert {seed for _, _, seed, _ in asked} == {1, 2}
    assert all(extra == {} for extra in asked_extra)  # the generator's own decoding by default
    asked_extra.clear()  # --temperature reaches every generation
    planner_behaviour.planner_rows(["ar"], range(1), B.BehaviourThresholds(), cfg=None, temperature=0.4)
    assert asked_extra and all(extra == {"temperature": 0.4} for extra in asked_extra)


def test_planner_behaviour_decoder_seed_decodes_every_seed_from_one_noise(monkeypatch):
    """``--decoder-seed K``: each seed's tokens are decoded from the noise of seed K, with
    ``--decoder-steps`` passed on; the planner still samples with the clip's own seed."""
    import planner_behaviour

    import motok_robot.planner.generate as generate_module
    from motok_robot.eval import behaviour as B
    from motok_robot.motion.synthetic import standing_clip

    decoded, planned = [], []

    class FakeGenerator:
        model_id = "fake"

        def __init__(self, kind):
            pass

        def generate(self, text, seconds=None, seed=0, cfg_scale=None, steps=None, decoder_steps=None,
                     decoder_seed=None):
            planned.append(seed)
            decoded.append((decoder_seed, decoder_steps))
            frames = int(20 * (seconds or 2.0))
            return type("Motion", (), {"joints": standing_clip(frames=frames), "seconds": frames / 20})()

    monkeypatch.setattr(generate_module, "MotionGenerator", FakeGenerator)
    planner_behaviour.planner_rows(["ar"], range(3, 5), B.BehaviourThresholds(), cfg=None, decoder_steps=7,
                                   decoder_seed=11)
    assert set(planned) == {3, 4}
    assert set(decoded) == {(11, 7)} and len(decoded) == len(planned) == 2 * 5


def test_planner_behaviour_noise_summary_counts_plans_passing_under_every_some_no_noise():
    """``noise_summary``: per planner measured under several decoder noises, the seeds whose plan
    passes under every noise, some, none, and the pass rate; rows without a decoder seed and a
    planner under one noise only are left out."""
    import planner_behaviour

    from motok_robot.eval import behaviour as B

    def row(kind, noise, bow_seeds):
        r = {"rows": f"{kind} planner" + ("" if noise is None else f", decoder noise {noise}"), "planner": kind,
             "decoder_seed": noise, "seeds": [{"seed": s} for s in range(4)]}
        for name in B.CHECKS:
            r[f"{name}_seeds"] = list(range(4)) if name != "bow" else bow_seeds
        return r

    rows = [row("ar", None, [0]), row("ar", 0, [0, 1]), row("ar", 5, [1, 2]), row("masked", 3, [0])]
    summary = planner_behaviour.noise_summary(rows)
    assert [s["rows"] for s in summary] == ["ar planner over 2 decoder noises"]
    assert summary[0]["decoder_seeds"] == [0, 5]
    assert summary[0]["bow_counts"] == {"every": 1, "some": 2, "none": 1, "rate": 0.5}
    assert summary[0]["bow"] == "1 / 2 / 1 (50 %)"
    assert summary[0]["walk_counts"]["every"] == 4


def test_planner_behaviour_reference_only_loads_no_planner(tmp_path, monkeypatch, capsys):
    """``--reference-only``: the real clips and their round trip under each decoder noise, no
    planner row (so a candidate tokenizer can be compared alone), and per bow clip the noises its
    round trip passes under; without ``--data`` it is refused."""
    import planner_behaviour

    monkeypatch.setattr(planner_behaviour, "planner_rows", lambda *a, **k: pytest.fail("a planner was run"))
    seen = {}

    def clips(*passed):
        return [{"clip": f"bow_{k}", "label": "bow", "passed": p} for k, p in enumerate(passed)]

    def reference_rows(data, noises, decoder_steps):
        seen.update(data=data, noises=list(noises), steps=decoder_steps)
        return [{"rows": "real Bandai clips", "model": str(data), "bow": "2/3", "clips": clips(True, True, False)},
                {"rows": "the same clips through the tokenizer, decoder noise 0", "model": "tok", "bow": "2/3",
                 "clips": clips(True, False, True)},
                {"rows": "the same clips through the tokenizer, decoder noise 3", "model": "tok", "bow": "1/3",
                 "clips": clips(True, False, False)}]

    monkeypatch.setattr(planner_behaviour, "reference_rows", reference_rows)
    (tmp_path / "index.jsonl").write_text("")
    out = tmp_path / "ref.json"
    argv = ["planner_behaviour.py", "--reference-only", "--data", str(tmp_path), "--decoder-seed", "0", "3",
            "--threads", "1", "--out", str(out)]
    monkeypatch.setattr(sys, "argv", argv)
    assert planner_behaviour.main() == 0
    assert seen == {"data": tmp_path, "noises": [0, 3], "steps": None}
    result = json.loads(out.read_text())
    assert result["seeds"] == 0 and result["noise_summary"] == [] and [r["bow"] for r in result["rows"]] == ["2/3", "2/3", "1/3"]
    assert [(c["rows"], c["real"], c["round trip"]) for c in result["clip_round_trips"]] == [
        ("bow_0", "pass", "2/2"), ("bow_1", "pass", "0/2"), ("bow_2", "MISS", "1/2")]
    printed = capsys.readouterr().out
    assert "Real clips and their tokenizer round trip" in printed and "bow_1" in printed
    monkeypatch.setattr(sys, "argv", ["planner_behaviour.py", "--reference-only"])
    with pytest.raises(SystemExit) as stop:
        planner_behaviour.main()
    assert stop.value.code == 2 and "--reference-only needs --data" in capsys.readouterr().err


def test_planner_text_reliance_scores_captioned_clips_in_each_condition():
    """``planner_text_reliance.token_nll`` with a stand-in AR planner that records what it is
    given: only clips with a caption count (every motion token, no [END]); "other caption" gives
    each clip the previous clip's text, "none" drops the text, "unknown" clears the ends; uniform
    logits score log(K + 1) nats per token."""
    import planner_text_reliance
    import torch

    from motok_robot.planner.data import PlannerData, TokenisedClip

    K = 6
    seen = []

    class Recorder:
        pad_id = K + 1

        def logits(self, tokens, cond, n, drop, lengths, ends):
            seen.append({"text": cond.text_embedding.clone(), "drop": drop.clone(), "ends": ends.clone(),
                         "lengths": lengths.clone()})
            return torch.zeros(tokens.shape[0], n + 1, K + 1)

    table = torch.eye(3)  # caption rows 0, 1, 2
    clips = [TokenisedClip("a", np.arange(5) % K, np.zeros((20, 263), np.float16), [0], -1),
             TokenisedClip("b", np.arange(3) % K, np.zeros((12, 263), np.float16), [], 0),  # action label only
             TokenisedClip("c", np.arange(4) % K, np.zeros((16, 263), np.float16), [1], -1),
             TokenisedClip("d", np.arange(7) % K, np.zeros((28, 263), np.float16), [2], -1)]
    data = PlannerData(clips, table, downsample=4, max_tokens=6)
    nll, count = planner_text_reliance.token_nll(Recorder(), data, "caption", "known", batch_size=8)
    assert count == 5 + 4 + 6 and nll == pytest.approx(np.log(K + 1))
    assert torch.equal(seen[-1]["text"], table) and not seen[-1]["drop"].any()
    assert seen[-1]["lengths"].tolist() == [5, 4, 6] and seen[-1]["ends"].tolist() == [True, True, False]
    planner_text_reliance.token_nll(Recorder(), data, "other caption", "unknown", batch_size=8)
    assert torch.equal(seen[-1]["text"], table[[2, 0, 1]]) and not seen[-1]["ends"].any()
    planner_text_reliance.token_nll(Recorder(), data, "none", "known", batch_size=8)
    assert seen[-1]["drop"].all()
