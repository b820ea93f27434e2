"""Radians <-> ticks conversion and the per-tick safety limiter (no bus)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from motok_robot.errors import InputError
from motok_robot.robots.description import ServoSpec
from motok_robot.servo.convert import ServoMap, limit_command
from motok_robot.servo.testing import synthetic_specs


def test_xm430_convention_2048_is_zero_and_4096_per_turn():
    smap = ServoMap.from_specs([
        ServoSpec("a", 1, "XM430-W350", 1, 2048, 0, 4095),
        ServoSpec("b", 2, "XM430-W350", -1, 2100, 0, 4095),
    ])
    ticks = smap.to_ticks(np.array([[0.0, 0.0], [math.pi / 2, math.pi / 2]]))
    assert ticks.tolist() == [[2048, 2100], [3072, 2100 - 1024]]
    assert ticks.dtype == np.int64


def test_round_trip_within_half_a_tick():
    smap = ServoMap.from_specs(synthetic_specs(20))
    rng = np.random.default_rng(1)
    lo, hi = smap.to_rad(smap.min_ticks), smap.to_rad(smap.max_ticks)
    q = rng.uniform(np.minimum(lo, hi), np.maximum(lo, hi), size=(50, smap.n))
    back = smap.to_rad(smap.to_ticks(q))
    assert np.max(np.abs(back - q)) <= 0.5 * 2 * np.pi / 4096 + 1e-12
    ticks = rng.integers(smap.min_ticks, smap.max_ticks + 1, size=(50, smap.n))
    assert np.array_equal(smap.to_ticks(smap.to_rad(ticks)), ticks)


def test_to_ticks_clamps_and_rejects_non_finite_naming_the_servo():
    smap = ServoMap.from_specs(synthetic_specs(3))
    huge = smap.to_ticks(np.array([1e300, -1e300, 50.0]))
    assert np.all(huge >= smap.min_ticks) and np.all(huge <= smap.max_ticks)
    with pytest.raises(InputError, match=r"servo 2 \(joint_01\)"):
        smap.to_ticks(np.array([0.0, np.nan, 0.0]))


def test_step_limit_follows_velocity_limit():
    smap = ServoMap.from_specs(synthetic_specs(2))
    # 4.8 rad/s for 8 ms = 0.0384 rad = 25.03 ticks -> 25
    assert smap.step_limit_ticks(1 / 125).tolist() == [25, 25]
    assert smap.step_limit_ticks(1 / 125, margin=0.5).tolist() == [12, 12]


@pytest.mark.parametrize("bad, message", [
    (dict(id=1), "duplicate servo ID"),
    (dict(sign=2), "sign must be"),
    (dict(min_ticks=3000, max_ticks=1000), "must be below"),
    (dict(max_ticks=5000), "outside 0..4095"),
    (dict(velocity_limit=0.0), "velocity_limit"),
])
def test_bad_servo_map_entry_is_named(bad, message):
    fields = dict(joint="knee", id=2, model="XM430-W350", sign=1, zero_offset_ticks=2048, min_ticks=1000,
                  max_ticks=3000, ticks_per_rev=4096, velocity_limit=4.8)
    fields.update(bad)
    specs = [ServoSpec("hip", 1, "XM430-W350", 1, 2048, 0, 4095), ServoSpec(**fields)]
    with pytest.raises(InputError, match=message):
        ServoMap.from_specs(specs)


def test_empty_servo_map_is_an_input_error():
    with pytest.raises(InputError, match="no servo map"):
        ServoMap.from_specs([])


targets = hnp.arrays(
    np.float64, 6,
    elements=st.one_of(st.floats(-1e4, 1e4), st.sampled_from([np.nan, np.inf, -np.inf, 1e300, -1e300])),
)


@settings(max_examples=300, deadline=None)
@given(targets=targets, data=st.data())
def test_limit_command_never_leaves_limits_or_steps_too_far(targets, data):
    lo = np.array([0, 100, 1000, 2000, 2047, 10], dtype=np.int64)
    hi = np.array([4095, 200, 3000, 2100, 2049, 4000], dtype=np.int64)
    step = np.array(data.draw(st.lists(st.integers(0, 500), min_size=6, max_size=6)), dtype=np.int64)
    previous = np.array([data.draw(st.integers(int(a), int(b))) for a, b in zip(lo, hi)], dtype=np.int64)
    command, non_finite, limited = limit_command(targets, previous, lo, hi, step)
    assert command.dtype == np.int64
    assert np.all(command >= lo) and np.all(command <= hi)
    assert np.all(np.abs(command - previous) <= step)
    assert np.array_equal(non_finite, ~np.isfinite(targets))
    assert np.all(command[non_finite] == previous[non_finite])
    inside = np.isfinite(targets) & (targets >= np.maximum(lo, previous - step)) & (targets <= np.minimum(hi, previous + step))
    assert np.all(np.abs(command[inside] - targets[inside]) <= 0.5)
    assert not np.any(limited[inside])
