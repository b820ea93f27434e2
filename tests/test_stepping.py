"""Foothold tracking from leg odometry (feasibility/stepping.py) and the stage's torque slow-down.

The tracker is tested on a one-dimensional walk whose every step lands a few millimetres long
(as the identified OP3 does in physics): with tracking the error stays at one step's, without
it it adds up.  The stage tests use the shipped op3_like model and synthetic motions.
"""

from __future__ import annotations

import numpy as np
import pytest

from motok_robot.errors import InputError
from motok_robot.feasibility.config import BalanceConfig, FeasibilityConfig, GaitConfig
from motok_robot.feasibility.feedforward import load_servo_goals
from motok_robot.feasibility.stage import make_feasible, write_feasible
from motok_robot.feasibility.stepping import FootholdTracker, SteppingPlan, lift_off_events, swing_ramp
from motok_robot.robots import load
from motok_robot.robots.index import index_robot
from motok_robot.sim import synthetic as S

STAND, SWING = 4, 4  # frames standing at the start, frames of each swing


def _pattern(steps: int, end: int = 5) -> np.ndarray:
    """contacts [T, 2]: both down, then alternate swings (right first) with one frame of double
    support between them, both down at the end."""
    rows = [[True, True]] * STAND
    swing = 1
    for _ in range(steps):
        rows += [[swing == 1, swing == 0]] * SWING + [[True, True]]
        swing = 1 - swing
    return np.array(rows + [[True, True]] * end)


def test_lift_offs_and_swing_ramps_follow_the_contacts():
    contacts = _pattern(3)
    events = lift_off_events(contacts)
    # the first lift-off is from standing (nothing to measure); then each lift-off measures the
    # step of the foot that just landed
    assert events == [(STAND - 1, 1, -1), (STAND + SWING, 0, 1), (STAND + 2 * SWING + 1, 1, 0)]
    ramp = swing_ramp(contacts, lift_share=0.2)
    assert np.all(ramp[contacts] == 1.0)
    swing = ramp[STAND:STAND + SWING, 1]
    assert np.all(np.diff(swing) >= 0) and swing[0] < 0.2 and swing[-1] == pytest.approx(1.0)


def _toy_plan(steps: int, stride: float, gain: float) -> tuple[SteppingPlan, np.ndarray, np.ndarray]:
    """A 1-D walk: joint k is foot k's x relative to the base, the planned footholds advance by
    ``stride`` each step.  Returns (plan, contacts, planned foot x [T, 2])."""
    contacts = _pattern(steps)
    T, nj = contacts.shape[0], 2
    planned = np.zeros((T, 2))
    for t in range(1, T):
        planned[t] = planned[t - 1]
        landed = contacts[t] & ~contacts[t - 1]
        planned[t, landed] = planned[t - 1, 1 - np.flatnonzero(landed)] + stride
    # a swing foot's planned x is where it will land (what matters here is the landing)
    for k in range(2):
        for t in range(T - 2, -1, -1):
            if not contacts[t, k]:
                planned[t, k] = planned[t + 1, k]
    events = lift_off_events(contacts)
    measure = np.zeros((len(events), 2, nj))
    for e, (_, a, _) in enumerate(events):
        measure[e, 0, 1 - a], measure[e, 0, a] = 1.0, -1.0  # d(x_c - x_a)/dq
    correct = np.zeros((T, 2, nj, 2))
    correct[:, 0, 0, 0] = correct[:, 1, 1, 0] = 1.0
    ramp = swing_ramp(contacts, 0.2)
    for frame, a, _ in events:
        ramp[frame, a] = 0.0
    from motok_robot.feasibility.stepping import support_shares

    plan = SteppingPlan(ramp=ramp, support=support_shares(contacts, 1.0), correct=correct,
                        events=np.array(events).reshape(-1, 3), measure=measure,
                        joints=np.array([planned[f] for f, _, _ in events]), gain=gain, max_offset_m=0.05)
    return plan, contacts, planned


def _walk_toy(gain: float, bias: float = 0.004, steps: int = 12) -> np.ndarray:
    """Landing errors (actual - planned x, m) of the toy walk whose every step lands ``bias`` long."""
    plan, contacts, planned = _toy_plan(steps, 0.05, gain)
    tracker = FootholdTracker(plan, fps=1.0)
    x = planned[0].copy()
    errors = []
    offset = np.zeros(2)
    for t in range(contacts.shape[0]):
        if t:
            for k in np.flatnonzero(contacts[t] & ~contacts[t - 1]):  # lands with the last swing goals
                c = 1 - k
                x[k] = x[c] + (planned[t, k] - planned[t, c]) + (offset[k] - offset[c]) + bias
                errors.append(x[k] - planned[t, k])
        offset = tracker.offsets(float(t), x[None])[0]  # present: the feet as they are
    return np.array(errors)


def test_foothold_tracking_keeps_the_step_error_from_adding_up():
    open_loop = _walk_toy(gain=0.0)
    tracked = _walk_toy(gain=1.0)
    assert open_loop[-1] == pytest.approx(len(open_loop) * 0.004)  # 12 steps, 4 mm each
    assert np.abs(tracked).max() <= 2 * 0.004 + 1e-9
    # without present positions nothing is measured, and the steps add up again
    plan, contacts, _ = _toy_plan(3, 0.05, 1.0)
    blind = FootholdTracker(plan, fps=1.0)
    for t in range(contacts.shape[0]):
        assert np.all(blind.offsets(float(t), None) == 0.0)
    assert blind.measured == 0


def test_a_stepping_plan_rejects_malformed_fields():
    plan, contacts, _ = _toy_plan(2, 0.05, 1.0)
    fields = plan.fields()
    assert SteppingPlan.from_fields(fields, contacts.shape[0], 2, "x.npz") is not None
    bad = {**fields, "step_events": fields["step_events"][::-1].copy()}
    with pytest.raises(InputError, match="step_events"):
        SteppingPlan.from_fields(bad, contacts.shape[0], 2, "x.npz")
    bad = {**fields, "step_correct": fields["step_correct"][:-1]}
    with pytest.raises(InputError, match="step_correct"):
        SteppingPlan.from_fields(bad, contacts.shape[0], 2, "x.npz")
    with pytest.raises(InputError, match="step_measure"):
        SteppingPlan.from_fields({k: v for k, v in fields.items() if k != "step_measure"}, contacts.shape[0], 2, "x.npz")


@pytest.fixture(scope="module")
def op3():
    return index_robot(load("op3_like"))


def test_a_walk_with_own_steps_travels_with_its_stepping_plan(op3, tmp_path, retargeted):
    qpos = S.walk(op3, steps=4, step_period_s=1.0, fps=20.0, double_support=0.2)
    result = make_feasible(retargeted(op3, qpos), op3, FeasibilityConfig(gait=GaitConfig(enabled=True)))
    stepping = result.plan.stepping
    assert stepping is not None and (stepping.events[:, 2] >= 0).sum() >= 3
    path = write_feasible(result, tmp_path, op3.name)
    loaded = load_servo_goals(path.parent / "servo_goals.npz")["plan"].stepping
    assert loaded is not None and np.array_equal(loaded.events, stepping.events)
    assert np.allclose(loaded.correct, stepping.correct)
    off = make_feasible(retargeted(op3, qpos), op3, FeasibilityConfig(
        gait=GaitConfig(enabled=True), balance=BalanceConfig(foothold_gain=0.0)))
    assert off.plan.stepping is None


def test_a_motion_that_needs_more_torque_than_the_servos_have_is_played_slower(op3, retargeted):
    qpos, joint = S.too_fast(op3, seconds=3.0, speed_ratio=0.9)
    result = make_feasible(retargeted(op3, qpos), op3, FeasibilityConfig())
    record = result.record["torque_retime"]
    assert record["torque_share_before"] > 0.9 >= record["torque_share_after"]
    assert record["factor"] > 1.0 and result.record["time_warp"] == pytest.approx(record["factor"])
    assert result.trajectory.qpos.shape[0] > qpos.shape[0]
    kept = make_feasible(retargeted(op3, qpos), op3, FeasibilityConfig(max_torque_share=1.0))
    assert kept.record["torque_retime"]["factor"] == 1.0 and kept.record["time_warp"] == 1.0
    with pytest.raises(InputError, match="max_torque_share"):
        FeasibilityConfig(max_torque_share=0.2)


def test_a_walk_on_its_retargeted_legs_keeps_its_timing(op3, retargeted):
    qpos = S.walk(op3, steps=6, step_period_s=1.0, fps=20.0, double_support=0.2)
    result = make_feasible(retargeted(op3, qpos), op3, FeasibilityConfig(max_torque_share=0.5))
    record = result.record["torque_retime"]
    assert record["travels"] and record["factor"] == 1.0 and result.record["time_warp"] == 1.0
