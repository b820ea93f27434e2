"""The pipeline's balance repair: a robot trajectory that loses balance is retargeted again with
the ZMP term, and the new one is kept only when it fails fewer checks (speed checks aside).

The unit tests fake the validation verdicts and the re-solve (a shifted copy of the first solve)
so that the keep / revert rule is checked exactly on the shipped demo motion; the last test runs
the real thing on a Bandai walk (``../shared``), which falls without the ZMP term.
"""

from __future__ import annotations

import hashlib
import json
import tarfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow  # balance re-solves of real clips: 13-55 s each, about 5 min for the module

pytest.importorskip("mujoco")
pytest.importorskip("casadi")

from motok_robot.errors import InputError  # noqa: E402
from motok_robot.pipeline import BALANCE_CHECKS, Pipeline, PipelineConfig  # noqa: E402
from retarget.config import RetargetConfig  # noqa: E402
from retarget.io import read_robot_npz  # noqa: E402

DEMO = Path(__file__).resolve().parents[1] / "examples" / "wave_demo.npz"
SHIFT = 0.01  # rad added to the first joint by the fake re-solve, to tell the trajectories apart


def _fake_validation(monkeypatch, verdicts: list[list[str]]) -> list[np.ndarray]:
    """Validation returns the real report with the i-th call's checks ``verdicts[i]`` failing
    (and every other check passing). Returns the list of validated ``qpos`` arrays."""
    import motok_robot.sim.validate as validate

    real = validate.validate_trajectory
    seen: list[np.ndarray] = []

    def fake(trajectory, *args, **kwargs):
        result = real(trajectory, *args, **kwargs)
        failing = verdicts[min(len(seen), len(verdicts) - 1)]
        seen.append(np.array(trajectory.qpos))
        report = result.report
        for name, check in report["checks"].items():
            check["passed"] = name not in failing
        report["failed_checks"] = [name for name in report["checks"] if name in failing]
        report["passed"] = not failing
        return result

    monkeypatch.setattr(validate, "validate_trajectory", fake)
    return seen


@pytest.fixture
def fake_resolve(monkeypatch):
    """The balance retargeter is the plain one with its result's first joint shifted by SHIFT;
    ``calls.window`` replaces the fields of its first solver window's report."""

    class Calls(list):
        window: dict = {}

    calls = Calls()

    class Shifted:
        def __init__(self, base):
            self.base = base

        def run(self, joints, fps, **kwargs):
            calls.append(len(joints))
            rt = self.base.run(joints, fps, **kwargs)
            rt.qpos = rt.qpos.copy()
            rt.qpos[:, 7] += SHIFT
            rt.windows[0] = replace(rt.windows[0], **calls.window)
            return rt

    monkeypatch.setattr(Pipeline, "_balance_retargeter", lambda self, entry: Shifted(entry["retargeter"]))
    return calls


def _run(tmp_path, name, **config):
    pipe = Pipeline(PipelineConfig(plots=False, max_retime=1.0, **config))
    return pipe.run(None, motion=DEMO, robot="op3_like", out_dir=tmp_path / name, render=False)


def _check_report_is_for_the_file(result):
    report = json.loads(result.files["report"].read_text())
    assert report["input"]["sha256"] == hashlib.sha256(result.files["robot"].read_bytes()).hexdigest()
    return report


def test_fewer_failing_checks_keep_the_rebalanced_trajectory(tmp_path, monkeypatch, fake_resolve):
    seen = _fake_validation(monkeypatch, [["zmp", "fall", "base_drift"], ["torque"]])
    result = _run(tmp_path, "kept")
    assert fake_resolve == [len(read_robot_npz(result.files["robot"]).qpos)]  # re-solved once
    assert len(seen) == 2 and np.allclose(seen[1][:, 7] - seen[0][:, 7], SHIFT)
    assert result.zmp_weight == PipelineConfig.balance_zmp_weight
    assert result.failed_checks == ["torque"] and "balance" in result.timings
    kept = read_robot_npz(result.files["robot"]).qpos
    assert np.array_equal(kept, seen[1])  # the file holds the re-solved trajectory ...
    assert _check_report_is_for_the_file(result)["failed_checks"] == ["torque"]  # ... and the report is its own
    assert any(n.startswith("balance:") and "kept" in n for n in result.notes)
    recorded = json.loads(result.files["result"].read_text())
    assert recorded["zmp_weight"] == PipelineConfig.balance_zmp_weight
    assert recorded["acceleration_weight"] == result.acceleration_weight == PipelineConfig.balance_acceleration_weight
    summary = result.files["summary"].read_text()
    assert "ZMP term (weight 1000, acceleration weight 50)" in summary and "| balance |" in summary


@pytest.mark.parametrize("after", [
    ["zmp", "fall", "base_drift"],                    # no better
    ["zmp", "self_collision"],                        # fixes two, breaks one that passed
])
def test_no_strict_improvement_keeps_the_first_trajectory(tmp_path, monkeypatch, fake_resolve, after):
    seen = _fake_validation(monkeypatch, [["zmp", "fall", "base_drift"], after])
    result = _run(tmp_path, "reverted")
    assert len(fake_resolve) == 1 and len(seen) == 2
    assert np.array_equal(read_robot_npz(result.files["robot"]).qpos, seen[0])  # the first solve, restored
    assert result.zmp_weight == 0.0 and result.acceleration_weight == RetargetConfig().weights.acceleration
    assert sorted(result.failed_checks) == ["base_drift", "fall", "zmp"]
    assert _check_report_is_for_the_file(result)["failed_checks"] == result.failed_checks
    assert any(n.startswith("balance:") and "first trajectory is kept" in n for n in result.notes)


def test_a_resolve_with_a_violated_constraint_is_not_kept(tmp_path, monkeypatch, fake_resolve):
    """Better checks do not buy a solver window whose hard constraints do not hold: the first solve stays."""
    fake_resolve.window = dict(success=False, status="Infeasible_Problem_Detected", violated="frame 3: no slip",
                               violation=0.01)
    seen = _fake_validation(monkeypatch, [["zmp", "fall"], []])
    result = _run(tmp_path, "infeasible")
    assert len(fake_resolve) == 1 and result.zmp_weight == 0.0
    assert np.array_equal(read_robot_npz(result.files["robot"]).qpos, seen[0])
    assert sorted(result.failed_checks) == ["fall", "zmp"]
    assert any(n.startswith("balance:") and "constraint violated" in n for n in result.notes)


def test_a_feasible_resolve_short_of_optimality_is_kept_and_noted(tmp_path, monkeypatch, fake_resolve):
    """IPOPT stopping before optimality with every constraint holding is a feasible trajectory:
    validation judges it, and the summary says the window did not converge."""
    fake_resolve.window = dict(success=False, status="Error_In_Step_Computation", violated=None, violation=0.0)
    _fake_validation(monkeypatch, [["zmp", "fall"], []])
    result = _run(tmp_path, "short")
    assert result.passed and result.zmp_weight == PipelineConfig.balance_zmp_weight
    assert any("did not converge" in n and "Error_In_Step_Computation" in n and "every constraint holds" in n
               for n in result.notes)


def test_both_feet_in_the_air_alone_calls_for_the_repair(tmp_path, monkeypatch, fake_resolve):
    """A flight phase (``floating``) cannot pass on a servo humanoid: the re-solve plants a foot."""
    _fake_validation(monkeypatch, [["floating"], []])
    result = _run(tmp_path, "floating")
    assert len(fake_resolve) == 1 and result.passed and result.zmp_weight == PipelineConfig.balance_zmp_weight


def test_a_speed_check_does_not_block_the_repair_but_balance_must_improve(tmp_path, monkeypatch, fake_resolve):
    """Speed checks are left to retiming: trading ``zmp`` for ``joint_velocity`` is kept."""
    _fake_validation(monkeypatch, [["zmp"], ["joint_velocity"]])
    assert _run(tmp_path, "speed").zmp_weight == PipelineConfig.balance_zmp_weight


@pytest.mark.parametrize("first, config", [
    (["self_collision"], {}),                                              # not a footing or balance check
    ([], {}),                                                              # passed
    (["zmp", "fall"], {"balance_zmp_weight": 0.0}),                        # repair off
    (["zmp", "fall"], {"retarget": replace(RetargetConfig(), weights=replace(RetargetConfig().weights, zmp=300.0))}),
])
def test_no_repair_when_balanced_off_or_already_with_the_zmp_term(tmp_path, monkeypatch, fake_resolve, first, config):
    seen = _fake_validation(monkeypatch, [first, []])
    result = _run(tmp_path, "plain", **config)
    assert fake_resolve == [] and len(seen) == 1 and "balance" not in result.timings
    assert not any(n.startswith("balance:") for n in result.notes)
    zmp = config["retarget"].weights.zmp if "retarget" in config else 0.0
    assert result.zmp_weight == zmp


def test_balance_retargeter_differs_only_in_the_zmp_and_acceleration_weights_and_contact_support():
    pipe = Pipeline(PipelineConfig(balance_zmp_weight=250.0, balance_acceleration_weight=40.0))
    entry = pipe.robot("op3_like")
    balanced = pipe._balance_retargeter(entry)
    weights = balanced.config.weights
    assert weights.zmp == 250.0 and weights.acceleration == 40.0 and balanced.config.contacts.support == "always"
    plain = entry["retargeter"].config
    assert replace(weights, zmp=plain.weights.zmp, acceleration=plain.weights.acceleration) == plain.weights
    assert replace(balanced.config, weights=plain.weights, contacts=plain.contacts) == plain
    assert pipe._balance_retargeter(entry) is balanced  # built once per robot and weights
    other = Pipeline(PipelineConfig(balance_zmp_weight=250.0, balance_acceleration_weight=5.0))
    assert other._balance_retargeter(entry) is not balanced
    assert BALANCE_CHECKS.isdisjoint({"torque", "joint_velocity", "joint_acceleration"})


@pytest.mark.parametrize("weight", [-1.0, float("nan")])
@pytest.mark.parametrize("name", ["balance_zmp_weight", "balance_acceleration_weight"])
def test_a_negative_balance_weight_is_refused(name, weight):
    with pytest.raises(InputError, match=name):
        Pipeline(**{name: weight})


@pytest.mark.parametrize("factor", [0.5, float("nan")])
def test_a_retime_ceiling_below_one_is_refused(factor):
    with pytest.raises(InputError, match="max_retime"):
        Pipeline(max_retime=factor)


def test_cli_balance_weight_reaches_the_pipeline_and_bad_values_are_one_line(tmp_path, monkeypatch, capsys):
    from motok_robot import pipeline
    from motok_robot.cli import main

    seen = {}

    class Stop(Exception):
        pass

    def capture(self, config=None, **overrides):
        seen["config"] = config
        raise Stop

    monkeypatch.chdir(tmp_path)
    np.savez(tmp_path / "m.npz", joints=np.zeros((4, 22, 3)), features=np.zeros((4, 263)))
    monkeypatch.setattr(pipeline.Pipeline, "__init__", capture)
    with pytest.raises(Stop):
        main(["run", "--motion", "m.npz", "--balance-zmp-weight", "300", "--balance-acceleration-weight", "30",
              "--out", str(tmp_path / "o")])
    assert seen["config"].balance_zmp_weight == 300.0 and seen["config"].balance_acceleration_weight == 30.0
    monkeypatch.undo()
    monkeypatch.chdir(tmp_path)
    for option in ("--balance-zmp-weight", "--balance-acceleration-weight"):
        assert main(["run", "--motion", "m.npz", option, "-5", "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and option in err[0]
        assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------- the real thing
CLIP = "dataset-1_walk_old_001.bvh"


@pytest.mark.shared
@pytest.mark.slow
def test_a_real_walk_that_falls_is_rebalanced_and_passes(shared_datasets, tmp_path):
    """Bandai ``walk_old_001`` (first 6 s, put on the canonical body at 20 fps as ``run
    --motion`` does) falls on op3_like when retargeted without the ZMP term; validated as
    retargeted (``walk_own_steps=False``), the pipeline re-solves it with the term and the robot
    then passes every check.  By default ``run`` walks it with the robot's own steps instead, and
    ``feasible --own-steps`` on the retargeted file gives the same robot.npz."""
    from motok_robot.pipeline import load_source_motion

    archive = shared_datasets / "bandai-namco-bvh.tar.xz"
    bvh = tmp_path / CLIP
    with tarfile.open(archive, "r|xz") as tar:  # streamed: the clip is near the start of the archive
        for member in tar:
            if member.name.endswith("/" + CLIP):
                bvh.write_bytes(tar.extractfile(member).read())
                break
    assert bvh.is_file(), f"{CLIP} not found in {archive}"
    source = load_source_motion(bvh)
    source.joints, source.features = source.joints[:120], source.features[:120]
    motion = source.save(tmp_path / "walk.npz")

    plain = Pipeline(plots=False, balance_zmp_weight=0.0, walk_own_steps=False).run(
        None, motion=motion, robot="op3_like", out_dir=tmp_path / "plain", render=False)
    assert "fall" in plain.failed_checks and plain.zmp_weight == 0.0
    result = Pipeline(plots=False, walk_own_steps=False).run(None, motion=motion, robot="op3_like",
                                                             out_dir=tmp_path / "balanced", render=False)
    assert result.passed, (result.failed_checks, result.notes)
    assert result.zmp_weight == PipelineConfig.balance_zmp_weight
    assert any(n.startswith("balance:") and "fall" in n for n in result.notes)
    # the stages one by one: retarget, then repair (run's repairs as a stage of their own)
    from motok_robot.cli import main

    robot = tmp_path / "stages" / "robot.npz"
    robot.parent.mkdir()
    assert main(["retarget", str(motion), "--robot", "op3_like", "--out", str(robot)]) == 0
    assert np.array_equal(read_robot_npz(robot).qpos, read_robot_npz(plain.files["robot"]).qpos)
    assert main(["repair", str(robot), "--motion", str(motion), "--out", str(tmp_path / "repaired")]) == 0
    assert np.array_equal(read_robot_npz(tmp_path / "repaired" / "robot.npz").qpos,
                          read_robot_npz(result.files["robot"]).qpos)
    # the default: the robot's own steps (the feasibility stage), no repair
    walked = Pipeline(plots=False).run(None, motion=motion, robot="op3_like", out_dir=tmp_path / "walked", render=False)
    assert walked.files.get("feasibility") is not None and not any(n.startswith("balance:") for n in walked.notes)
    assert any("steps of its own" in n for n in walked.notes)
    assert main(["feasible", str(robot), "--own-steps", "--out", str(tmp_path / "own")]) == 0
    assert np.array_equal(read_robot_npz(tmp_path / "own" / "robot.npz").qpos, read_robot_npz(walked.files["robot"]).qpos)
