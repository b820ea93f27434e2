"""Settings of the feasibility stage: the balance controller and the physics refinement.

Units: radians, seconds, hertz.  Gains are dimensionless (rad of joint goal per rad of torso
tilt error) or seconds (rad of joint goal per rad/s of torso rate error).  The per-robot
defaults are documented in docs/feasibility.md with the measurements behind them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from motok_robot.errors import InputError

#: the leg joints the balance controller moves, by role (inferred from the kinematic chain
#: from each sole up to the base: the first pitch joint is the ankle, the last the hip, pitch
#: joints between them are knees; the first roll joint is the ankle's, the last the hip's; a
#: joint turning about the vertical is a hip yaw, which acts on the torso's yaw only)
ROLES = ("ankle_pitch", "ankle_roll", "knee", "hip_pitch", "hip_roll", "hip_yaw")


def _check_ranges(what: str, config, ranges) -> None:
    """InputError naming ``what`` and the field when a field of ``config`` lies outside its
    ``(name, low, high)`` range."""
    for name, low, high in ranges:
        value = float(getattr(config, name))
        if not low <= value <= high:
            raise InputError(f"{what} {name} = {value}: must lie in [{low}, {high}]")


def _default_tilt_gain() -> dict:
    # no attitude (P) feedback by default: on op3_like every tilt gain tried (ankle +-1 and 2,
    # hip +-1 rad/rad) lowered the push a standing robot survives, with or without gyro damping
    # (docs/feasibility.md, "Gains"); the accelerometer-corrected estimate stays for users who set one
    return {"ankle_pitch": 0.0, "ankle_roll": 0.0, "knee": 0.0, "hip_pitch": 0.0, "hip_roll": 0.0, "hip_yaw": 0.0}


def _default_rate_gain() -> dict:
    # gyro damping on the stance ankles (s), as the ROBOTIS OP3 walk's gyro feedback; 0.1 s on
    # op3_like raised the backward push a standing robot survives from 11 to 13 N (0.1 s push)
    # and kept a ZMP-shifted slow Bandai walk up for its 17.9 s (it fell at 5.0 s open loop);
    # hip and knee damping did not help there
    return {"ankle_pitch": 0.1, "ankle_roll": 0.1, "knee": 0.0, "hip_pitch": 0.0, "hip_roll": 0.0, "hip_yaw": 0.0}


@dataclass(frozen=True)
class BalanceConfig:
    """The closed-loop balance controller (:mod:`motok_robot.feasibility.balance`)."""

    #: run the controller (False: the servo goals are streamed open loop, as before)
    enabled: bool = True
    #: controller rate (Hz): one IMU + present-position read and one goal write per tick; the
    #: OP3's bus cycle is 8 ms
    rate_hz: float = 125.0
    #: goal offset per rad of torso tilt error (estimated minus reference), per joint role
    tilt_gain: dict = field(default_factory=_default_tilt_gain)
    #: goal offset per rad/s of torso rate error (gyro minus reference), per joint role
    rate_gain: dict = field(default_factory=_default_rate_gain)
    #: share of the correction a leg gets while it is not in support (1 = as a stance leg)
    swing_share: float = 0.0
    #: per-tick weight of the accelerometer in the tilt estimate (complementary filter; 0.02
    #: at 125 Hz is a 0.4 s time constant: the gyro carries the fast part)
    accel_weight: float = 0.02
    #: first-order low-pass of the gyro (weight of the new sample; the ROBOTIS driver uses 0.4)
    gyro_filter: float = 0.5
    #: the correction of one joint is clamped to this (rad)
    max_offset_rad: float = 0.35
    #: foothold tracking on walks with the robot's own steps (:mod:`.stepping`): the share of
    #: each step's error, measured from the servo present positions, that the next step
    #: corrects (1: all of it; 0: off), and the largest correction of a foot per leg length
    foothold_gain: float = 1.0
    max_foothold_offset_per_leg: float = 0.1

    def __post_init__(self):
        for name in ("tilt_gain", "rate_gain"):
            gains = getattr(self, name)
            unknown = sorted(set(gains) - set(ROLES))
            if unknown:
                raise InputError(f"balance {name}: unknown joint role(s) {', '.join(unknown)}; known: {', '.join(ROLES)}")
            for role, value in gains.items():
                if not (isinstance(value, (int, float)) and abs(float(value)) < 10):
                    raise InputError(f"balance {name}.{role} = {value!r}: expected a number of magnitude < 10")
        _check_ranges("balance", self, (("rate_hz", 1.0, 2000.0), ("swing_share", 0.0, 1.0),
                                        ("accel_weight", 0.0, 1.0), ("gyro_filter", 1e-3, 1.0),
                                        ("max_offset_rad", 0.0, 1.0), ("foothold_gain", 0.0, 1.0),
                                        ("max_foothold_offset_per_leg", 0.0, 0.5)))

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, values: dict) -> "BalanceConfig":
        """The defaults with ``values`` merged in (the gains per joint role), as a robot's
        ``[feasibility.balance]`` table is."""
        return _with_settings(cls(), values, "balance settings", "balance")


@dataclass(frozen=True)
class RefineConfig:
    """The receding-horizon predictive-sampling refinement (:mod:`motok_robot.feasibility.refine`)."""

    #: candidate rollouts per planning step (the first is the current plan unchanged)
    samples: int = 16
    #: planning horizon (s); MuJoCo MPC's OP3 task plans over 0.35 s
    horizon_s: float = 0.4
    #: re-plan interval (s): the best candidate's first part is executed for this long
    replan_s: float = 0.1
    #: spacing of the spline knots of the goal offsets (s); offsets are linear between knots
    knot_s: float = 0.1
    #: standard deviation of the knot perturbations (rad)
    noise_rad: float = 0.1
    #: largest offset the refinement may add to a goal (rad)
    max_offset_rad: float = 0.4
    #: which joints get offsets: "legs" (the balance controller's leg joints and hip yaws) or "all"
    joints: str = "legs"
    #: cost weights (per second of motion): torso attitude (rad^2), base height (m^2, per
    #: robot height^2), base position (m^2 per height^2), soles (m^2 per height^2), joint
    #: angles (rad^2, mean over joints), offsets (rad^2, mean)
    w_tilt: float = 20.0
    w_height: float = 200.0
    w_base: float = 20.0
    w_feet: float = 100.0
    w_joints: float = 1.0
    w_effort: float = 0.5
    #: torso tilt from the reference beyond which a candidate is counted as falling (rad)
    fall_tilt_rad: float = 0.7
    #: cost added per second spent fallen
    fall_cost: float = 1000.0
    #: seed of the perturbations (the result is deterministic for a given seed)
    seed: int = 0

    def __post_init__(self):
        if not 1 <= int(self.samples) <= 4096:
            raise InputError(f"refine samples = {self.samples}: must lie in [1, 4096]")
        _check_ranges("refine", self, (("horizon_s", 0.01, 5.0), ("replan_s", 0.008, 5.0), ("knot_s", 0.01, 2.0),
                                       ("noise_rad", 0.0, 1.0), ("max_offset_rad", 0.0, 1.5)))
        if self.joints not in ("legs", "all"):
            raise InputError(f"refine joints = {self.joints!r}: use legs or all")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class GaitConfig:
    """Walking with the robot's own steps (:mod:`.footsteps`, :mod:`.gait`)."""

    #: replace the legs of a motion that travels by a walk planned for the robot along its path
    #: (False: the retargeted legs are tracked, with the ZMP shift)
    enabled: bool = False
    #: one step every this many seconds, ``double_support`` of it on both feet (at least one
    #: frame; 0.1 = one frame at 20 fps): in physics the landed foot takes the load at
    #: touchdown, and a trailing foot left on the floor unloaded is dragged along it
    step_period_s: float = 0.5
    double_support: float = 0.1
    #: the ZMP reference reaches the landed foot after this share of each double support
    zmp_transfer_share: float = 0.5
    #: the longest step (how far a foot lands ahead of the other), per leg length; 0.27 on
    #: op3_like = 6.8 cm, about half a foot length: the synthetic walk that stays up at 0.5 s a step
    advance_per_leg: float = 0.27
    #: a motion that travels faster than those steps follow at ``max_time_warp`` is walked with
    #: longer steps, up to this (0.4 on op3_like = 10 cm): on op3_like, 0.4 took the angry Bandai
    #: walk's distance from its path from 0.51 m to 0.08 m; walks slow enough keep ``advance_per_leg``
    max_advance_per_leg: float = 0.4
    #: ... and then with quicker steps, down to one every this many seconds (the ROBOTIS OP3
    #: framework's own walk steps every 0.3 s: ``period_time`` 600 ms for a left and a right
    #: step); ``step_period_s``: off
    min_step_period_s: float = 0.5
    #: time the walk on the path's forward and sideways speed in its heading frame, against the
    #: steps the robot can take each way (sideways 0.375 of a step length per step); False: its
    #: speed against forward steps.  Off by default: on op3_like it kept a generated kick that
    #: drifted sideways on its path (0.19 -> 0.11 m) but the musical Bandai walk, slowed to the
    #: 3x bound and walked with longer steps, then failed `torque` (1.02) and `foot_skate_distance`
    sideways_timing: bool = False
    #: the largest turn of a foot per step (rad)
    turn_per_step_rad: float = 0.3
    #: how high the swing foot lifts at mid-swing, per leg length (0.15 on op3_like = 3.8 cm)
    clearance_per_leg: float = 0.15
    #: a swing rises as high as the reference's same foot did near it, up to this per leg length
    #: (0.3 on the OP3 = 7.2 cm; a run or a kick lifts its feet higher than a walk, and
    #: `fidelity_foot_lift` fails a rollout whose feet stay 5 % of the robot's height lower);
    #: ``clearance_per_leg``: off
    max_clearance_per_leg: float = 0.3
    #: the swing foot rises and lands vertically over this share of the swing at each end (0.05:
    #: until it is 6 mm up on op3_like); the shorter it is, the slower the swing moves across
    #: (its joints' damping, a servo's back-EMF, takes most of the identified OP3's torque at
    #: the peak: 0.15 failed `torque` on every real walk there)
    vertical_share: float = 0.05
    #: > 0: the walk's joints move no faster than where their damping (a servo's back-EMF)
    #: takes this share of the torque limit (the identified OP3 at 0.75: 4.1 / 1.084 x 0.75 =
    #: 2.8 rad/s); 0: off.  Measured at 0.75: real walks passing on the OP3 2 -> 10 of 31,
    #: on op3_like 19 -> 10 (the bounded legs miss their footholds), so it is off by default
    #: and set per robot (op3.toml's ``[feasibility.gait]``)
    damping_speed_share: float = 0.0
    #: the base height is the reference's smoothed over this many seconds of the source (a Hann
    #: window; the time warp stretches it): a human pelvis bobs with each of the human's own
    #: steps, out of phase with the robot's, and a stance knee lifting the OP3 by that bob at
    #: 2.3 rad/s spent the servo's whole torque; 0: the reference's height as it is
    height_smoothing_s: float = 1.0
    #: the arms are moved (by their own joints) where they come closer than this (per robot
    #: height; 0.02 = 1.1 cm on the OP3) to the legs the walk planned (:mod:`.clearance`); 0: off
    arm_clearance_per_height: float = 0.02
    #: the ZMP target of a stance foot lies this far (per leg length) outward of its sole centre
    #: (0.04 on op3_like = 1 cm): the CoM then stands over the stance foot where its sway turns
    zmp_outward_per_leg: float = 0.04
    #: standing on both feet before the first step and after the reference ends (s): a robot
    #: starts from rest, and the last steps bring the feet together
    lead_in_s: float = 0.6
    lead_out_s: float = 1.0
    #: where the reference moves faster than the robot can step, the motion is played slower,
    #: by at most this factor
    max_time_warp: float = 3.0
    #: a motion is walked when both feet travel farther than this per leg length and neither
    #: rises above ``max_lift_per_leg`` (a wave on the spot, a kick or a jump keeps its
    #: retargeted legs)
    min_travel_per_leg: float = 0.5
    max_lift_per_leg: float = 0.3
    #: ... but a motion whose base ends farther than this (per leg length) from where it started
    #: is walked however high its feet rise (a run: the runs tried end 2.4-9.5 leg lengths from
    #: their start; the Bandai kick 0.45); 1000: off
    min_run_travel_per_leg: float = 2.0

    def __post_init__(self):
        _check_ranges("gait", self, (("step_period_s", 0.2, 2.0), ("min_step_period_s", 0.2, 2.0),
                                     ("double_support", 0.05, 0.8),
                                     ("zmp_transfer_share", 0.1, 1.0),
                                     ("advance_per_leg", 0.02, 1.0), ("max_advance_per_leg", 0.02, 1.0),
                                     ("turn_per_step_rad", 0.0, 1.0),
                                     ("clearance_per_leg", 0.0, 0.5), ("max_clearance_per_leg", 0.0, 0.5),
                                     ("vertical_share", 0.0, 0.45),
                                     ("damping_speed_share", 0.0, 1.0), ("arm_clearance_per_height", 0.0, 0.1),
                                     ("height_smoothing_s", 0.0, 5.0),
                                     ("zmp_outward_per_leg", 0.0, 0.2), ("lead_in_s", 0.0, 5.0),
                                     ("lead_out_s", 0.0, 5.0), ("max_time_warp", 1.0, 4.0),
                                     ("min_travel_per_leg", 0.0, 10.0), ("max_lift_per_leg", 0.0, 2.0),
                                     ("min_run_travel_per_leg", 0.0, 1000.0)))

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class SpotStepConfig:
    """The steps of a motion on the spot that lifts a foot (:mod:`.spot_steps`)."""

    #: plan the reference's own lift-offs with the weight moved onto the stance foot first
    #: (False: a motion on the spot keeps its retargeted legs, with the ZMP shift).  Off by
    #: default: the real Bandai kick, the one real clip it changes, still falls on both OP3
    #: models with it (later: op3 5.3 -> 8.9 s, op3_like 5.4 -> 5.8 s of 36-46 s;
    #: docs/experiments/2026-12-06-spinning-kick-pivot-and-collision-resolve.md)
    enabled: bool = False
    #: a foot that moves faster than this along the floor (leg lengths a second; 0.2 on the OP3
    #: = 4.8 cm/s) is not down: the robot steps where the human shuffled it
    slide_speed_per_leg: float = 0.2
    #: the shortest swing (a shorter lift-off is lengthened: a shuffle becomes a step) and the
    #: shortest stance between two swings (a shorter one joins them), in seconds
    min_swing_s: float = 0.3
    min_stance_s: float = 0.15
    #: a swing starts at least this long after the other foot's touchdown (s): the ZMP moves
    #: across in that time (a human lands a kick while its stance foot already slides on)
    min_double_support_s: float = 0.25
    #: a swing foot rises at least this high at mid-swing, per leg length (0.06 on the OP3 = 1.4 cm)
    clearance_per_leg: float = 0.06
    #: the ZMP moves onto the stance foot over this long before a lift-off, and back between
    #: the feet over as long after the touchdown (s)
    transfer_s: float = 0.4
    #: a double support lasts long enough for the ZMP to move onto the next stance foot at this
    #: speed (leg lengths a second; 0.5 on the OP3 = 12 cm/s): the reference pauses where not
    zmp_speed_per_leg: float = 0.5
    #: a foothold lies at most this far ahead of or behind the other foot's (per leg length;
    #: 0.25 on the OP3 = 6 cm)
    max_stagger_per_leg: float = 0.25
    #: a motion with both feet higher than this (per leg length; 0.05 on the OP3 = 1.2 cm) in
    #: one frame hops: it has no spot steps
    hop_height_per_leg: float = 0.05

    def __post_init__(self):
        _check_ranges("spot_steps", self, (("slide_speed_per_leg", 0.01, 5.0), ("min_swing_s", 0.0, 2.0),
                                           ("min_stance_s", 0.0, 2.0), ("min_double_support_s", 0.0, 2.0),
                                           ("clearance_per_leg", 0.0, 0.5),
                                           ("transfer_s", 0.02, 2.0), ("hop_height_per_leg", 0.0, 1.0),
                                           ("zmp_speed_per_leg", 0.05, 10.0), ("max_stagger_per_leg", 0.0, 2.0)))

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class FeasibilityConfig:
    """The whole stage (:mod:`motok_robot.feasibility.stage`)."""

    #: play the motion this many times slower (1 = human timing); recorded as the time warp
    retime: float = 1.0
    #: a motion on the spot (it does not travel) that needs more than this share of a servo's
    #: torque limit (inverse dynamics of the task, joint damping included: a servo's back-EMF)
    #: is played slower until it needs less, up to ``gait.max_time_warp`` in all (1: never slowed)
    max_torque_share: float = 0.9
    #: move the CoM so the cart-table ZMP stays on the planned feet (:mod:`.zmp_shift`)
    zmp_shift: bool = True
    #: how far inside the support polygon the shifted ZMP is kept (m)
    zmp_margin_m: float = 0.01
    #: "lateral": the CoM only moves across the walking direction; "both": also along it
    zmp_axes: str = "lateral"
    #: run the predictive-sampling refinement of the goals (:mod:`.refine`)
    refine: bool = False
    #: physics timestep (s); 0: the robot model's own, as the validation rollout
    #: (ValidationConfig.physics_timestep_s) and the simulated rig
    timestep_s: float = 0.0
    #: servo goals change by at most this fraction of the velocity limit per frame
    goal_velocity_fraction: float = 0.95
    #: contact height (m) and friction of the inverse dynamics behind the feedforward goals
    contact_height_m: float = 0.005
    friction: float = 0.8
    balance: BalanceConfig = field(default_factory=BalanceConfig)
    refine_config: RefineConfig = field(default_factory=RefineConfig)
    gait: GaitConfig = field(default_factory=GaitConfig)
    spot_steps: SpotStepConfig = field(default_factory=SpotStepConfig)

    def __post_init__(self):
        if not 1.0 <= float(self.retime) <= 4.0:
            raise InputError(f"feasibility retime = {self.retime}: must lie in [1, 4] (times slower)")
        if not 0.5 <= float(self.max_torque_share) <= 1.0:
            raise InputError(f"feasibility max_torque_share = {self.max_torque_share}: must lie in [0.5, 1]")
        if self.zmp_axes not in ("lateral", "both"):
            raise InputError(f"feasibility zmp_axes = {self.zmp_axes!r}: use lateral or both")
        if not 0.0 <= float(self.zmp_margin_m) <= 0.05:
            raise InputError(f"feasibility zmp_margin_m = {self.zmp_margin_m}: must lie in [0, 0.05] m")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def with_settings(self, settings: dict, source: str) -> "FeasibilityConfig":
        """This config with ``settings`` applied: a dict of field names (``gait``, ``balance`` and
        ``refine_config`` as nested dicts, the balance gains merged per joint role), the layout
        of a robot description's ``[feasibility]`` table.  ``source`` names where they come from
        in messages (``"op3.toml"``)."""
        return _with_settings(self, settings, source, "feasibility")


def _with_settings(config, settings, source: str, table: str):
    """``config`` (a config dataclass) with ``settings`` merged in; InputError naming ``source``,
    the ``table`` and the key for an unknown key or a value of the wrong kind."""
    where = f"{source}: [{table}]"
    if not isinstance(settings, dict):
        raise InputError(f"{where} expected a table of settings, got {type(settings).__name__}")
    fields = {f.name for f in dataclasses.fields(config)}
    unknown = sorted(set(settings) - fields)
    if unknown:
        raise InputError(f"{where} unknown setting(s) {', '.join(unknown)}; known: {', '.join(sorted(fields))}")
    changes = {}
    for key, value in settings.items():
        current = getattr(config, key)
        if dataclasses.is_dataclass(current):
            changes[key] = _with_settings(current, value, source, f"{table}.{key}")
        elif isinstance(current, dict):
            if not isinstance(value, dict):
                raise InputError(f"{where} {key}: expected a table, got {type(value).__name__}")
            changes[key] = {**current, **value}
        elif isinstance(current, bool) or isinstance(value, bool):
            if not (isinstance(current, bool) and isinstance(value, bool)):
                raise InputError(f"{where} {key} = {value!r}: expected {type(current).__name__}")
            changes[key] = value
        elif isinstance(current, (int, float)):
            if not isinstance(value, (int, float)):
                raise InputError(f"{where} {key} = {value!r}: expected a number")
            if isinstance(current, int) and not float(value).is_integer():
                raise InputError(f"{where} {key} = {value!r}: expected a whole number")
            changes[key] = type(current)(value)
        elif not isinstance(value, type(current)):
            raise InputError(f"{where} {key} = {value!r}: expected {type(current).__name__}")
        else:
            changes[key] = value
    try:
        return dataclasses.replace(config, **changes)
    except InputError as exc:
        raise InputError(f"{where} {exc}") from None


def robot_config(index, settings: dict | None = None) -> FeasibilityConfig:
    """The stage's settings for robot ``index`` (a RobotIndex): the defaults, then the robot
    description's ``[feasibility]`` table, then ``settings`` (what a user asked for, the same
    layout)."""
    config = FeasibilityConfig()
    own = getattr(index, "feasibility_settings", None) or {}
    if own:
        config = config.with_settings(own, getattr(index, "description_file", "") or f"robot {index.name}")
    return config.with_settings(settings, "feasibility settings") if settings else config
