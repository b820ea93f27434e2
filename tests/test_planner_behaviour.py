"""Behaviour of the configured (shipped) text-to-motion models, checked by measurable properties.

Runs against whatever models are configured (``models/`` at the repository root, or the folder in
``$MOTOK_ROBOT_MODELS``) with the default seed; each check skips, with the reason, when the
tokenizer or the planner is not there.
"""

from __future__ import annotations

import numpy as np
import pytest

from motok_robot.motion.skeleton import FPS, JOINT_INDEX

J = JOINT_INDEX
PLANNERS = ["masked", "ar"]

#: Behaviours a shipped model is known to miss, keyed by the sha256 prefix of its weights. These
#: run as strict expected failures for exactly that file (a retrained model is checked normally,
#: and if the shipped one starts passing the test fails so the entry gets removed). Measured over
#: seeds 0-5 for the AR planner shipped on 2026-11-22: bow > 30 deg in 2 of 6, both hands up in
#: 3 of 6; see the note of the planner issue. (The masked planner shipped before 2026-11-25
#: slid and hopped where it should walk; the one shipped since plants its feet.)
KNOWN_MISSES = {
    "ba0682131936b6f1": {"bow": "the shipped AR planner bows in 2 of 6 seeds, not with seed 0",
                         "raise_both_hands": "the shipped AR planner raises both hands in 3 of 6 seeds, not with seed 0"},
}


def _expect_known_miss(request, kind: str, behaviour: str) -> None:
    from motok_robot.planner.data import file_digest
    from motok_robot.planner.generate import default_run

    weights = default_run(kind) / "model.safetensors"
    if not weights.is_file():
        return
    reason = KNOWN_MISSES.get(file_digest(weights), {}).get(behaviour)
    if reason:
        request.applymarker(pytest.mark.xfail(strict=True, reason=reason))


def _models_or_skip(kind: str):
    from motok_robot.planner.generate import default_run

    for what in ("tokenizer", kind):
        run = default_run(what)
        if not (run / "model.safetensors").is_file():
            pytest.skip(f"no trained {what} model in {run} (the shipped models land with the end-to-end issue)")


def _generate(kind: str, text: str, seconds: float) -> np.ndarray:
    _models_or_skip(kind)
    import torch

    torch.set_num_threads(1)
    from motok_robot.planner.generate import generate

    return generate(text, seconds=seconds, seed=0, planner=kind).joints.astype(np.float64)


def _facing(joints: np.ndarray) -> np.ndarray:
    """Unit forward direction on the ground, ``[T, 2]`` (hips and shoulders across-vector, rotated)."""
    across = (joints[:, J["left_hip"]] - joints[:, J["right_hip"]]) + (
        joints[:, J["left_shoulder"]] - joints[:, J["right_shoulder"]])
    fwd = np.stack([across[:, 1], -across[:, 0]], axis=1)  # across x z, projected on the ground
    return fwd / np.maximum(np.linalg.norm(fwd, axis=1, keepdims=True), 1e-9)


def _travel(joints: np.ndarray) -> float:
    return float(np.linalg.norm(joints[-1, 0, :2] - joints[0, 0, :2]))


def _crossings(x: np.ndarray, dead: float) -> int:
    """Sign changes of ``x`` ignoring values within ``+-dead`` (hysteresis)."""
    sign, count = 0, 0
    for v in x:
        s = 1 if v > dead else -1 if v < -dead else 0
        if s and sign and s != sign:
            count += 1
        if s:
            sign = s
    return count


@pytest.mark.parametrize("kind", PLANNERS)
def test_walk_forward_travels_with_alternating_feet(kind):
    j = _generate(kind, "a person walks forward", 6.0)
    assert _travel(j) >= 1.5, f"walked only {_travel(j):.2f} m in 6 s"
    fwd = _facing(j)
    lead = np.einsum("td,td->t", j[:, J["left_ankle"], :2] - j[:, J["right_ankle"], :2], fwd)
    steps = _crossings(lead, dead=0.05)
    assert steps >= 4, f"feet swapped the lead only {steps} times in 6 s"


@pytest.mark.parametrize("kind", PLANNERS)
def test_walk_forward_keeps_a_foot_planted(kind, request):
    """A walk plants its feet: real Bandai walks have 0-2 % of frames (per style) with neither
    foot in contact (near the floor and nearly still), runs 9-69 %; without a planted foot a
    robot has nothing to stand on."""
    _expect_known_miss(request, kind, "walk_planted")
    from retarget.contacts import detect_contacts

    j = _generate(kind, "a person walks forward", 6.0)
    flight = float((~detect_contacts(j, float(FPS)).any(axis=1)).mean())
    assert flight <= 0.1, f"no foot planted in {flight:.0%} of frames"


@pytest.mark.parametrize("kind", PLANNERS)
def test_run_is_faster_than_walk(kind):
    walk = _generate(kind, "a person walks forward", 6.0)
    run = _generate(kind, "a person runs forward", 6.0)
    assert _travel(run) > _travel(walk), f"run {_travel(run):.2f} m vs walk {_travel(walk):.2f} m in 6 s"


@pytest.mark.parametrize("kind", PLANNERS)
def test_wave_the_right_hand(kind):
    j = _generate(kind, "a person waves the right hand", 6.0)
    right_up = j[:, J["right_wrist"], 2] > j[:, J["right_shoulder"], 2]
    left_up = j[:, J["left_wrist"], 2] > j[:, J["left_shoulder"], 2]
    assert right_up.mean() >= 0.25, f"right wrist above the shoulder on {right_up.mean():.0%} of frames"
    assert left_up.mean() <= 0.1, f"left wrist above the shoulder on {left_up.mean():.0%} of frames"
    # repeatedly: the raised wrist swings side to side (relative to the shoulder, across the body)
    fwd = _facing(j)
    left_dir = np.stack([-fwd[:, 1], fwd[:, 0]], axis=1)
    side = np.einsum("td,td->t", j[:, J["right_wrist"], :2] - j[:, J["right_shoulder"], :2], left_dir)
    raised = side[right_up]
    swings = _crossings(raised - np.median(raised), dead=0.02)
    assert swings >= 2, f"the raised right wrist changed direction {swings} times"


@pytest.mark.parametrize("kind", PLANNERS)
def test_raise_both_hands(kind, request):
    _expect_known_miss(request, kind, "raise_both_hands")
    j = _generate(kind, "a person raises both hands", 6.0)
    both = (j[:, J["right_wrist"], 2] > j[:, J["right_shoulder"], 2]) & (
        j[:, J["left_wrist"], 2] > j[:, J["left_shoulder"], 2])
    assert both.mean() >= 0.25, f"both wrists above the shoulders on {both.mean():.0%} of frames"


@pytest.mark.parametrize("kind", PLANNERS)
def test_bow_pitches_forward_and_back(kind, request):
    _expect_known_miss(request, kind, "bow")
    j = _generate(kind, "a person bows", 6.0)
    torso = j[:, J["neck"]] - j[:, J["pelvis"]]
    fwd = _facing(j)
    pitch = np.degrees(np.arctan2(np.einsum("td,td->t", torso[:, :2], fwd), torso[:, 2]))
    peak = int(np.argmax(pitch))
    assert pitch[peak] > 30.0, f"torso pitched forward at most {pitch[peak]:.1f} deg"
    assert peak < len(pitch) - 1 and pitch[peak:].min() < 15.0, "the torso did not come back up after the bow"
    assert pitch[: max(peak, 1)].min() < 15.0 or peak < FPS, "the clip did not start upright"
