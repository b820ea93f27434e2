"""Behaviour of the configured (shipped) text-to-motion models, checked by measurable properties.

Runs against whatever models are configured (``models/`` at the repository root, or the folder in
``$MOTOK_ROBOT_MODELS``) with the default seed; each check skips, with the reason, when the
tokenizer or the planner is not there.
"""

from __future__ import annotations

import numpy as np
import pytest

from motok_robot.eval import behaviour as B
from motok_robot.motion.skeleton import FPS

PLANNERS = ["masked", "ar"]
TH = B.BehaviourThresholds()

#: Behaviours a shipped model is known to miss, keyed by the sha256 prefix of its weights. These
#: run as strict expected failures for exactly that file (a retrained model is checked normally,
#: and if the shipped one starts passing the test fails so the entry gets removed). The pass rates
#: over seeds 0-11 are in benchmarks/results/planner_behaviour.json (python
#: benchmarks/planner_behaviour.py) and the model card: seed 0 passing says little about a sampler.
KNOWN_MISSES = {
    "ba0682131936b6f1": {"bow": "the shipped AR planner's bows are mostly shallow; it bows and comes back "
                                "up in 1 of seeds 0-11, not with seed 0"},
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


def _generate(kind: str, text: str, seconds: float | None) -> np.ndarray:
    _models_or_skip(kind)
    import torch

    torch.set_num_threads(1)
    from motok_robot.planner.generate import generate

    return generate(text, seconds=seconds, seed=0, planner=kind).joints.astype(np.float64)


def _passes(result) -> None:
    assert result.passed, result.reason


@pytest.mark.parametrize("kind", PLANNERS)
def test_walk_forward_travels_with_alternating_feet(kind):
    _passes(B.check_walk(_generate(kind, B.WALK, TH.seconds)))


@pytest.mark.parametrize("kind", PLANNERS)
def test_walk_forward_keeps_a_foot_planted(kind, request):
    """A walk plants its feet: real Bandai walks have 0-2 % of frames (per style) with neither
    foot in contact (near the floor and nearly still), runs 9-69 %; without a planted foot a
    robot has nothing to stand on."""
    _expect_known_miss(request, kind, "walk_planted")
    _passes(B.check_walk_planted(_generate(kind, B.WALK, TH.seconds), FPS))


@pytest.mark.parametrize("kind", PLANNERS)
def test_run_is_faster_than_walk(kind):
    _passes(B.check_run_faster(_generate(kind, B.RUN, TH.seconds), _generate(kind, B.WALK, TH.seconds)))


@pytest.mark.parametrize("kind", PLANNERS)
def test_wave_the_right_hand(kind):
    _passes(B.check_wave_right_hand(_generate(kind, B.WAVE, TH.seconds)))


@pytest.mark.parametrize("kind", PLANNERS)
def test_raise_both_hands(kind, request):
    _expect_known_miss(request, kind, "raise_both_hands")
    _passes(B.check_raise_both_hands(_generate(kind, B.BOTH_HANDS, TH.action_seconds)))


@pytest.mark.parametrize("kind", PLANNERS)
def test_bow_pitches_forward_and_back(kind, request):
    _expect_known_miss(request, kind, "bow")
    _passes(B.check_bow(_generate(kind, B.BOW, TH.action_seconds), FPS))
