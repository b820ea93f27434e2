"""Behaviour of the configured (shipped) text-to-motion models, checked by measurable properties.

Runs against whatever models are configured (``models/`` at the repository root, or the folder in
``$MOTOK_ROBOT_MODELS``); each check skips, with the reason, when the tokenizer or the planner is
not there.  Two kinds of test: each check with the default seed (what ``motok-robot generate``
gives without ``--seed``), and every check over seeds 0-7 against a floor of passes
(:data:`MIN_PASSES`): one seed passing or failing says little about a sampler.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from motok_robot.eval import behaviour as B
from motok_robot.motion.skeleton import FPS

pytestmark = pytest.mark.slow  # generations over seeds: up to 70 s each, about 3 min for the module

PLANNERS = ["masked", "ar"]
TH = B.BehaviourThresholds()

#: Behaviours a shipped model is known to miss, keyed by the sha256 prefix of its weights. These
#: run as strict expected failures for exactly that file (a retrained model is checked normally,
#: and if the shipped one starts passing the test fails so the entry gets removed). The pass rates
#: over seeds 0-95 are in benchmarks/results/planner_behaviour*.json (python
#: benchmarks/planner_behaviour.py) and the model card: seed 0 passing says little about a sampler.
#: None at present: the AR planner shipped before 2026-11-28 (``5c9e80ceefcbd3ac``) bowed only
#: 22.6 degrees with seed 0, and the one shipped since passes.
KNOWN_MISSES: dict[str, dict[str, str]] = {}


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


def _generate(kind: str, text: str, seconds: float | None, seed: int = 0) -> np.ndarray:
    from motok_robot.planner.generate import default_run

    _models_or_skip(kind)
    # the run folders are part of the key: a changed $MOTOK_ROBOT_MODELS is never served from the cache
    runs = (str(default_run("tokenizer").resolve()), str(default_run(kind).resolve()))
    return _generated(runs, kind, text, seconds, seed).copy()


@lru_cache(maxsize=None)
def _generated(runs: tuple[str, str], kind: str, text: str, seconds: float | None, seed: int) -> np.ndarray:
    import torch

    torch.set_num_threads(1)
    from motok_robot.planner.generate import generate

    tokenizer_run, planner_run = runs
    return generate(text, seconds=seconds, seed=seed, planner=kind, tokenizer_run=tokenizer_run,
                    planner_run=planner_run).joints.astype(np.float64)


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


#: Seeds of the rate test.
RATE_SEEDS = range(8)
#: Fewest passes out of the 8 :data:`RATE_SEEDS`, per check: a regression floor for the configured
#: models.  The frequent labels of the data (walk, run, wave, raise both hands) must work with every
#: seed; the two weak behaviours less often: a planted foot on the walk in at least 4 of the 8,
#: the bow (15 takes in the data) in at least 2.  These are floors on fixed seeds, not rates: the
#: shipped models' rates over seeds 0-95 are in the model card (python
#: benchmarks/planner_behaviour.py --seeds 48 [--first-seed 48]).
MIN_PASSES = {"walk": 8, "walk_planted": 4, "run_faster": 8, "wave_right_hand": 8, "raise_both_hands": 8, "bow": 2}


@pytest.mark.parametrize("kind", PLANNERS)
def test_every_behaviour_over_eight_seeds_meets_its_floor(kind):
    """All six checks over seeds 0-7; a check below its floor is reported with its count and the
    reason of its first failing seed."""
    passes: dict[str, list[int]] = {name: [] for name in B.CHECKS}
    reasons: dict[str, str] = {}
    for seed in RATE_SEEDS:
        results = B.check_all(lambda text, seconds: _generate(kind, text, seconds, seed), FPS, TH)
        for name, result in results.items():
            if result.passed:
                passes[name].append(seed)
            else:
                reasons.setdefault(name, f"seed {seed}: {result.reason}")
    short = {name: f"{len(passes[name])}/{len(RATE_SEEDS)} (floor {MIN_PASSES[name]}; {reasons.get(name, 'all passed')})"
             for name in B.CHECKS if len(passes[name]) < MIN_PASSES[name]}
    assert not short, f"{kind} planner below its floor: {short}"
