"""Behaviour checks: does a prompt produce the motion it names, by measurable properties.

Each check takes generated joints (``[T, 22, 3]``, metres, z up) and returns a
:class:`BehaviourResult` (passed, the measured values, a one-line reason).  The same checks run
in ``tests/test_planner_behaviour.py`` (the shipped models: seed 0, and floors over seeds 0-7)
and in ``benchmarks/planner_behaviour.py`` (pass rates over many seeds, the more honest number:
one seed passing says little about a sampler).  numpy only; the planted-foot check uses
:func:`retarget.contacts.detect_contacts`.

| check | prompt(s) | passes when |
|---|---|---|
| ``walk`` | "a person walks forward", 6 s (``seconds``) | the root travels >= 1.5 m and the feet swap the lead >= 4 times |
| ``walk_planted`` | same motion | no foot planted on <= 10 % of the frames |
| ``run_faster`` | "a person runs forward" vs the walk | the run travels farther |
| ``wave_right_hand`` | "a person waves the right hand" | right wrist above the shoulder >= 25 % of the frames, left <= 10 %, the raised wrist swings >= 2 times |
| ``raise_both_hands`` | "a person raises both hands", the generator's own length (``action_seconds``) | both wrists above the shoulders together >= 25 % of the frames |
| ``bow`` | "a person bows", the generator's own length | the torso pitches forward > 30 degrees, comes back below 15 degrees after the peak, and started below 15 degrees |
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np

from motok_robot.motion.features import planar_facing_yaw
from motok_robot.motion.skeleton import FPS, JOINT_INDEX

J = JOINT_INDEX
#: the prompts the checks generate, by role
WALK, RUN, WAVE, BOTH_HANDS, BOW = ("a person walks forward", "a person runs forward", "a person waves the right hand",
                                    "a person raises both hands", "a person bows")
#: every check's name, in report order
CHECKS = ("walk", "walk_planted", "run_faster", "wave_right_hand", "raise_both_hands", "bow")


@dataclass(frozen=True)
class BehaviourThresholds:
    """Pass thresholds of the checks (the acceptance of the planner issue)."""

    #: length of the walk, the run and the wave (repeated motions), seconds
    seconds: float | None = 6.0
    #: length of "raise both hands" and "bow" (one action each): None = the length the generator
    #: chooses, as ``generate`` without ``--seconds`` does (its length estimator).  Real
    #: Bandai raises last 1-5 s and bows 2.4-7.3 s: a 6 s request makes a planner hold or repeat
    #: the action, and a share-of-frames threshold then measures that, not the action.
    action_seconds: float | None = None
    walk_min_travel_m: float = 1.5
    walk_min_lead_swaps: int = 4
    lead_dead_band_m: float = 0.05  #: feet within this of each other along the facing do not count as a swap
    walk_max_unplanted: float = 0.1  #: real Bandai walks: 0-2 % per style, runs 9-69 %
    raised_min_share: float = 0.25
    other_hand_max_share: float = 0.1
    wave_min_swings: int = 2
    wave_dead_band_m: float = 0.02
    bow_min_pitch_deg: float = 30.0
    upright_max_pitch_deg: float = 15.0


@dataclass
class BehaviourResult:
    """Outcome of one check: ``passed``, the measured ``values`` and a one-line ``reason``."""

    passed: bool
    reason: str
    values: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)


def facing(joints: np.ndarray) -> np.ndarray:
    """Unit forward direction on the ground, ``[T, 2]`` (from hips and shoulders)."""
    yaw = planar_facing_yaw(joints)
    return np.stack([np.cos(yaw), np.sin(yaw)], axis=1)


def travel(joints: np.ndarray) -> float:
    """Ground distance of the root from the first to the last frame, metres."""
    return float(np.linalg.norm(joints[-1, 0, :2] - joints[0, 0, :2]))


def crossings(x: np.ndarray, dead: float) -> int:
    """Sign changes of ``x`` ignoring values within ``+-dead`` (hysteresis)."""
    sign, count = 0, 0
    for v in x:
        s = 1 if v > dead else -1 if v < -dead else 0
        if s and sign and s != sign:
            count += 1
        if s:
            sign = s
    return count


def torso_pitch_deg(joints: np.ndarray) -> np.ndarray:
    """Forward pitch of the pelvis-to-neck line from vertical, degrees per frame (forward > 0)."""
    torso = joints[:, J["neck"]] - joints[:, J["pelvis"]]
    return np.degrees(np.arctan2(np.einsum("td,td->t", torso[:, :2], facing(joints)), torso[:, 2]))


def _above(joints: np.ndarray, side: str) -> np.ndarray:
    return joints[:, J[f"{side}_wrist"], 2] > joints[:, J[f"{side}_shoulder"], 2]


def check_walk(joints: np.ndarray, th: BehaviourThresholds = BehaviourThresholds()) -> BehaviourResult:
    lead = np.einsum("td,td->t", joints[:, J["left_ankle"], :2] - joints[:, J["right_ankle"], :2], facing(joints))
    dist, swaps = travel(joints), crossings(lead, th.lead_dead_band_m)
    if dist < th.walk_min_travel_m:
        reason = f"walked only {dist:.2f} m"
    elif swaps < th.walk_min_lead_swaps:
        reason = f"feet swapped the lead only {swaps} times"
    else:
        reason = f"walked {dist:.2f} m, {swaps} lead swaps"
    return BehaviourResult(dist >= th.walk_min_travel_m and swaps >= th.walk_min_lead_swaps, reason,
                           {"travel_m": dist, "lead_swaps": swaps})


def check_walk_planted(joints: np.ndarray, fps: float = FPS,
                       th: BehaviourThresholds = BehaviourThresholds()) -> BehaviourResult:
    from retarget.contacts import detect_contacts

    unplanted = float((~detect_contacts(joints, float(fps)).any(axis=1)).mean())
    return BehaviourResult(unplanted <= th.walk_max_unplanted, f"no foot planted in {unplanted:.0%} of frames",
                           {"unplanted": unplanted})


def check_run_faster(run: np.ndarray, walk: np.ndarray) -> BehaviourResult:
    r, w = travel(run), travel(walk)
    return BehaviourResult(r > w, f"run {r:.2f} m vs walk {w:.2f} m", {"run_m": r, "walk_m": w})


def check_wave_right_hand(joints: np.ndarray, th: BehaviourThresholds = BehaviourThresholds()) -> BehaviourResult:
    right_up, left_up = _above(joints, "right"), _above(joints, "left")
    values = {"right_up": float(right_up.mean()), "left_up": float(left_up.mean()), "swings": 0}
    if right_up.mean() < th.raised_min_share:
        return BehaviourResult(False, f"right wrist above the shoulder on {right_up.mean():.0%} of frames", values)
    if left_up.mean() > th.other_hand_max_share:
        return BehaviourResult(False, f"left wrist above the shoulder on {left_up.mean():.0%} of frames", values)
    # repeatedly: the raised wrist swings side to side (relative to the shoulder, across the body)
    fwd = facing(joints)
    left_dir = np.stack([-fwd[:, 1], fwd[:, 0]], axis=1)
    side = np.einsum("td,td->t", joints[:, J["right_wrist"], :2] - joints[:, J["right_shoulder"], :2], left_dir)
    raised = side[right_up]
    values["swings"] = crossings(raised - np.median(raised), th.wave_dead_band_m)
    return BehaviourResult(values["swings"] >= th.wave_min_swings,
                           f"the raised right wrist changed direction {values['swings']} times", values)


def check_raise_both_hands(joints: np.ndarray, th: BehaviourThresholds = BehaviourThresholds()) -> BehaviourResult:
    both = float((_above(joints, "right") & _above(joints, "left")).mean())
    return BehaviourResult(both >= th.raised_min_share, f"both wrists above the shoulders on {both:.0%} of frames",
                           {"both_up": both})


def check_bow(joints: np.ndarray, fps: float = FPS, th: BehaviourThresholds = BehaviourThresholds()) -> BehaviourResult:
    pitch = torso_pitch_deg(joints)
    peak = int(np.argmax(pitch))
    after = float(pitch[peak:].min()) if peak < len(pitch) - 1 else float(pitch[peak])
    before = float(pitch[: max(peak, 1)].min())
    values = {"peak_deg": float(pitch[peak]), "peak_s": peak / float(fps), "min_after_deg": after, "min_before_deg": before}
    if pitch[peak] <= th.bow_min_pitch_deg:
        return BehaviourResult(False, f"torso pitched forward at most {pitch[peak]:.1f} deg", values)
    if peak >= len(pitch) - 1 or after >= th.upright_max_pitch_deg:
        return BehaviourResult(False, f"the torso did not come back up after the bow (at least {after:.1f} deg "
                                      f"after its {pitch[peak]:.1f} deg peak)", values)
    if before >= th.upright_max_pitch_deg and peak >= fps:
        return BehaviourResult(False, f"the clip did not start upright (at least {before:.1f} deg before the peak)", values)
    return BehaviourResult(True, f"bowed {pitch[peak]:.1f} deg and came back to {after:.1f} deg", values)


def check_all(generate: Callable[[str, float | None], np.ndarray], fps: float = FPS,
              th: BehaviourThresholds = BehaviourThresholds()) -> dict[str, BehaviourResult]:
    """Every check, generating each prompt once with ``generate(text, seconds) -> joints``
    (``seconds`` None: the generator's own length)."""
    walk = generate(WALK, th.seconds)
    return {
        "walk": check_walk(walk, th),
        "walk_planted": check_walk_planted(walk, fps, th),
        "run_faster": check_run_faster(generate(RUN, th.seconds), walk),
        "wave_right_hand": check_wave_right_hand(generate(WAVE, th.seconds), th),
        "raise_both_hands": check_raise_both_hands(generate(BOTH_HANDS, th.action_seconds), th),
        "bow": check_bow(generate(BOW, th.action_seconds), fps, th),
    }
