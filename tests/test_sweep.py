"""`motok-robot sweep` without Ray: the spec, the cells, resume, failing cells, interruption.

The cells are tiny: a 1 s standing clip (a motion file, so no trained model) on humanoid25, a
robot without servos (no playback), about half a second a cell once the robot is compiled.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from motok_robot.errors import InputError
from motok_robot.motion.features import features_from_joints, joints_from_features
from motok_robot.motion.synthetic import standing_clip

pytest.importorskip("pyarrow")

from motok_robot.sweep import results as R  # noqa: E402
from motok_robot.sweep.driver import run_sweep  # noqa: E402
from motok_robot.sweep.engine import SerialEngine  # noqa: E402
from motok_robot.sweep.spec import load_spec  # noqa: E402


def write_stand(path, frames=21):
    features = features_from_joints(standing_clip(frames=frames))
    np.savez(path, joints=joints_from_features(features).astype(np.float32), features=features, fps=20, text="stand")
    return path


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    root = tmp_path_factory.mktemp("sweep")
    write_stand(root / "stand.npz")
    return root


def spec_file(folder, text: str, name: str = "spec.toml"):
    path = folder / name
    path.write_text(text, encoding="utf-8")
    return path


TWO_VARIANTS = """
motions = ["stand.npz"]
robots = ["humanoid25"]
[run]
max-retime = 1.5
[variants.plain]
[variants.slow]
max-retime = 1.25
"""


# ----------------------------------------------------------------------------- the spec
@pytest.mark.parametrize("text, field, words", [
    ("motions = ['stand.npz']\ncolour = 1\n", "colour", "unknown field"),
    ("motions = ['stand.npz']\nrobots = ['op3_like', 'robot9000']\n", "robots[1]", "unknown robot 'robot9000'"),
    ("motions = ['stand.npz']\nseeds = [0, -3]\n", "seeds[1]", "non-negative integer"),
    ("motions = ['stand.npz', 'gone.npz']\n", "motions[1]", "does not exist"),
    ("prompts = ['  ']\n", "prompts[0]", "empty"),
    ("motions = ['stand.npz']\n[variants.fast]\nmax-retim = 2\n", "variants.fast.max-retim", "unknown `run` option"),
    ("motions = ['stand.npz']\n[variants.fast]\nmax-retime = 'quick'\n", "variants.fast.max-retime", "invalid float"),
    ("motions = ['stand.npz']\n[run]\nout = 'x'\n", "run.out", "not a sweep setting"),
    ("motions = ['stand.npz']\n[variants.a]\nmax-retime = 0.5\n", "variants.a", "max_retime"),
    ("motions = ['stand.npz']\n[variants.a]\nfeasible-retime = 2\n", "variants.a", "needs --feasible"),
    ("motions = ['stand.npz']\n[variants.a]\ntrajectory = 'path.csv'\n", "variants.a", "motion files"),
    ("[[cells]]\nmotion = 'stand.npz'\nvariant = 'b'\n", "cells[0].variant", "unknown variant 'b'"),
    ("[[cells]]\nmotion = 'stand.npz'\n[[cells]]\nmotion = 'stand.npz'\n", "cells[1]", "the same as cells[0]"),
    ("motions = ['stand.npz']\nseeds = [2, 3, 2]\n", "seeds[2]", "the same as seeds[0]"),
    ("seeds = [1]\n[[cells]]\nmotion = 'stand.npz'\n", "seeds", "not both"),
    ("motions = ['stand.npz']\ntime_budget_s = -1\n", "time_budget_s", "positive"),
])
def test_spec_errors_name_the_file_and_the_field(folder, text, field, words):
    path = spec_file(folder, text, "bad.toml")
    with pytest.raises(InputError) as info:
        load_spec(path)
    message = str(info.value)
    assert str(path) in message and f"field '{field}'" in message and words in message, message
    assert "\n" not in message


def test_spec_that_is_not_toml_names_the_line(folder):
    path = spec_file(folder, "motions = ['stand.npz']\nseeds = [0,,1]\n", "broken.toml")
    with pytest.raises(InputError, match=r"broken\.toml: not valid TOML: .*line"):
        load_spec(path)


def test_cartesian_product_and_explicit_list(folder):
    spec = load_spec(spec_file(folder, """
prompts = ["a person waves", "a person bows"]
motions = ["stand.npz"]
seeds = { start = 4, count = 3 }
robots = ["op3_like", "humanoid25"]
[variants.a]
[variants.b]
feasible = true
"""))
    assert len(spec.cells) == 3 * 3 * 2 * 2
    keys = {c.key for c in spec.cells}
    assert len(keys) == len(spec.cells) and len({c.cell_id for c in spec.cells}) == len(spec.cells)
    assert {c.seed for c in spec.cells} == {4, 5, 6}
    assert {c.input_label for c in spec.cells} == {"a person waves", "a person bows", "motion:stand.npz"}
    assert spec.variants["b"].argv == ("--feasible",) and spec.variants["a"].argv == ()

    listed = load_spec(spec_file(folder, """
[[cells]]
prompt = "a person bows"
seed = 7
robot = "op3_like"
[[cells]]
motion = "stand.npz"
"""))
    assert [(c.prompt, c.motion_label, c.seed, c.robot, c.variant) for c in listed.cells] == [
        ("a person bows", None, 7, "op3_like", "default"), (None, "stand.npz", 0, "op3", "default")]
    assert listed.cells[1].motion == (folder / "stand.npz").resolve()


def test_variant_options_map_to_the_pipeline_config(folder):
    from motok_robot.sweep.run_options import parse, pipeline_config, run_arguments

    spec = load_spec(spec_file(folder, """
motions = ["stand.npz"]
[run]
max-retime = 1.5
zmp_weight = 500
[variants.closed]
feasible = true
feasible-retime = 2
sim = true
"""))
    args = parse(spec.variants["closed"].argv)
    config = pipeline_config(args)
    assert config.max_retime == 1.5 and config.retarget.weights.zmp == 500
    # the feasibility settings asked for, applied later over the robot's own (robot_config)
    assert config.feasibility is not None and config.feasibility["retime"] == 2 and config.plots is False
    kwargs = run_arguments(args)
    assert kwargs["playback"] == "sim" and kwargs["render"] is False and kwargs["constraints"] is None


# ----------------------------------------------------------------------------- running cells
def rows_of(out):
    return {r["cell_id"]: r for r in R.read_table(out)}


def test_serial_sweep_writes_rows_folders_summary_and_resumes(folder, tmp_path):
    spec = spec_file(folder, TWO_VARIANTS, "two.toml")
    out = tmp_path / "sweep"
    first = run_sweep(spec, out, workers=1, progress=False)
    assert first.ran == 2 and first.skipped == 0 and sum(first.counts.values()) == 2
    rows = rows_of(out)
    assert {r["variant"] for r in rows.values()} == {"plain", "slow"}
    for cell_id, row in rows.items():
        assert row["status"] in ("passed", "failed") and row["error"] == ""
        assert (out / "cells" / cell_id / "robot.npz").is_file()
        report = json.loads((out / "cells" / cell_id / "report.json").read_text())
        assert row["passed"] == report["passed"] and row["metric_max_torque_ratio"] == report["metrics"]["max_torque_ratio"]
        assert row["time_retarget_s"] > 0 and row["cell_s"] > 0 and row["worker"]
    with open(out / "results.csv", encoding="utf-8") as handle:
        assert len(handle.read().strip().splitlines()) == 3
    summary = (out / "summary.md").read_text()
    assert "Pass rate by input and robot" in summary and "motion:stand.npz" in summary
    assert (out / "heatmap_input_robot.png").stat().st_size > 1000 and (out / "heatmap_input_seed.png").is_file()

    with pytest.raises(InputError, match="pass --resume"):
        run_sweep(spec, out, workers=1, progress=False)
    again = run_sweep(spec, out, workers=1, resume=True, progress=False)
    assert again.ran == 0 and again.skipped == 2
    assert rows_of(out) == rows  # nothing rerun: the same rows, run ids included

    spec.write_text(TWO_VARIANTS.replace("max-retime = 1.25", "max-retime = 1.75"), encoding="utf-8")
    changed = run_sweep(spec, out, workers=1, resume=True, progress=False)
    assert changed.ran == 1 and changed.skipped == 1
    after = rows_of(out)
    for cell_id, row in after.items():
        if row["variant"] == "slow":
            assert row["run_id"] != rows[cell_id]["run_id"] and row["inputs_hash"] != rows[cell_id]["inputs_hash"]
            assert row["report_sha"] == rows[cell_id]["report_sha"]  # deterministic: the same result
            assert row["qpos_sha"] == rows[cell_id]["qpos_sha"]
        else:
            assert row == rows[cell_id]


def test_a_raising_cell_is_recorded_and_the_sweep_goes_on(folder, tmp_path):
    np.savez(folder / "broken.npz", joints=np.zeros((10, 5, 3), np.float32), fps=20)
    spec = spec_file(folder, 'motions = ["broken.npz", "stand.npz"]\nrobots = ["humanoid25"]\n', "raising.toml")
    out = tmp_path / "sweep"
    outcome = run_sweep(spec, out, workers=1, progress=False)
    rows = {r["motion"]: r for r in R.read_table(out)}
    assert outcome.counts.get("error") == 1 and not outcome.all_passed
    broken = rows["broken.npz"]
    assert broken["status"] == "error" and broken["passed"] is False and "\n" not in broken["error"]
    assert "generate stage failed" in broken["error"] and "22" in broken["error"]
    assert (out / "cells" / broken["cell_id"] / "FAILED.txt").is_file()
    assert rows["stand.npz"]["status"] in ("passed", "failed") and rows["stand.npz"]["error"] == ""
    assert "Errors and time-outs (1)" in (out / "summary.md").read_text()


def test_a_cell_over_its_time_budget_is_cancelled_and_recorded(folder, tmp_path):
    spec = spec_file(folder, 'motions = ["stand.npz"]\nrobots = ["humanoid25"]\ntime_budget_s = 0.01\n', "budget.toml")
    out = tmp_path / "sweep"
    run_sweep(spec, out, workers=1, progress=False)
    (row,) = R.read_table(out)
    assert row["status"] == "timeout" and "time budget of 0.01 s" in row["error"]


class InterruptedEngine(SerialEngine):
    """Runs ``after`` cells, then Ctrl-C."""

    def __init__(self, after: int) -> None:
        super().__init__()
        self.after = after

    def run(self, jobs, blobs, done, running):
        for i, job in enumerate(jobs):
            if i == self.after:
                raise KeyboardInterrupt
            job.attempts += 1
            done(job, self.runner.run_cell(job.task, *blobs(job)))


def test_an_interrupted_sweep_leaves_a_readable_table_and_resumes(folder, tmp_path):
    spec = spec_file(folder, TWO_VARIANTS, "two.toml")
    out = tmp_path / "sweep"
    with pytest.raises(KeyboardInterrupt):
        run_sweep(spec, out, engine=InterruptedEngine(after=1), progress=False)
    rows = rows_of(out)
    assert len(rows) == 1 and all(r["status"] in ("passed", "failed") for r in rows.values())
    assert len((out / "results.csv").read_text().strip().splitlines()) == 2
    assert not (out / "summary.md").exists()
    with open(out / R.JOURNAL, "a", encoding="utf-8") as handle:  # a line cut short by a killed driver
        handle.write('{"cell_id": "stand_humanoid25_s0_sl')
    resumed = run_sweep(spec, out, workers=1, resume=True, progress=False)
    assert resumed.ran == 1 and resumed.skipped == 1
    final = rows_of(out)
    assert len(final) == 2 and all(final[k] == rows[k] for k in rows)
    assert len((out / R.JOURNAL).read_text().strip().splitlines()) == 2
    assert sorted(p.name for p in (out / "cells").iterdir()) == sorted(final)


def test_cli_one_line_errors(folder, tmp_path, capsys):
    from motok_robot.cli import main

    spec = spec_file(folder, "motions = ['stand.npz']\nrobots = ['robot9000']\n", "cli.toml")
    assert main(["sweep", str(spec), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "field 'robots[0]'" in err[0] and "robot9000" in err[0]
    assert main(["sweep", str(spec), "--out", str(tmp_path / "o"), "--rerun-errors"]) == 2
    assert "--rerun-errors needs --resume" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("module, workers", [("pyarrow", 1), ("ray", 2)])
def test_without_the_extra_the_command_says_how_to_get_it(folder, tmp_path, capsys, monkeypatch, module, workers):
    from motok_robot.cli import main

    monkeypatch.setitem(__import__("sys").modules, module, None)  # as if not installed
    spec = spec_file(folder, "motions = ['stand.npz']\n", "extra.toml")
    assert main(["sweep", str(spec), "--out", str(tmp_path / "o"), "--workers", str(workers)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"needs {module}" in err[0] and 'pip install -e ".[sweep]"' in err[0]


def test_the_example_spec_parses():
    from pathlib import Path

    spec = load_spec(Path(__file__).resolve().parents[1] / "examples" / "sweep_small.toml")
    assert len(spec.cells) == 24 and set(spec.variants) == {"plain", "feasible"}
    assert spec.variants["feasible"].argv == ("--seconds", "3", "--feasible") and spec.time_budget_s == 300


def test_the_sweep_benchmarks_cell_specs_are_valid_specs_of_the_asked_size(tmp_path):
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_sweep import GESTURES, write_inputs

    from motok_robot.sweep.spec import load_spec

    for kind, cells in (("prompt", 200), ("stand", 40)):
        folder = tmp_path / kind
        folder.mkdir()
        spec = load_spec(write_inputs(folder, cells, kind))
        assert len(spec.cells) == cells
    assert {c.prompt for c in load_spec(tmp_path / "prompt" / "bench.toml").cells} == set(GESTURES)
