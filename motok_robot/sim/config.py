"""Every threshold of the validation stage, in one place.

:class:`ValidationConfig` holds the thresholds and model choices used by
:mod:`motok_robot.sim.kinematic`, :mod:`motok_robot.feasibility.dynamics`,
:mod:`motok_robot.sim.rollout` and the verdict in :mod:`motok_robot.sim.report`.
Each field's comment says what it measures, its unit and why its default is what it is.
From the command line any field can be changed with ``--set key=value`` (repeatable);
:func:`ValidationConfig.with_overrides` parses those strings and rejects unknown keys.

Units: metres, seconds, radians, newton metres.  Ratios are dimensionless.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields

from motok_robot.errors import InputError


@dataclass(frozen=True)
class ValidationConfig:
    """Thresholds of the validation checks (defaults tuned for 0.5-1.8 m humanoids).

    A check passes when its value is on the safe side of its threshold; see
    ``docs/validation.md`` for the table of checks.
    """

    # ---- foot contact and skating -------------------------------------------------------
    #: a foot is *in contact* at a frame when the lowest of its sole corner sites is below this
    #: height (m).  5 mm: above retargeting noise (soles held within 1 mm of the floor while
    #: planted), below any deliberate foot lift.
    contact_height_m: float = 0.005
    #: a foot in contact *skates* at a frame when its sole-centre horizontal speed exceeds this
    #: (m/s).  5 cm/s is 1/4 of a slow robot walk's foot speed and 10x the 5 mm drift per
    #: contact phase that retargeting allows spread over a 0.1 s phase.
    skate_speed_mps: float = 0.05
    #: fail when more than this fraction of a foot's contact frames skate.
    max_foot_skate_ratio: float = 0.10
    #: fail when a foot moves horizontally more than this in total while in contact (m),
    #: summed over the clip.
    max_foot_skate_distance_m: float = 0.03

    # ---- ground ------------------------------------------------------------------------
    #: fail when a sole corner goes deeper than this below the floor (m).  Retargeting keeps
    #: soles above -1 mm; 5 mm leaves room for the contact softness of the physics model.
    max_penetration_m: float = 0.005
    #: fail when the lowest sole point of the whole robot is higher than this above the floor
    #: (m): the robot floats.  1 cm: in a walk one sole is always on the floor; a servo humanoid
    #: does not jump, so a flight phase fails too (raise it for clips that mean to jump).
    max_float_m: float = 0.01

    # ---- self-collision ----------------------------------------------------------------
    #: two geoms of non-adjacent bodies overlapping deeper than this count as a self-collision
    #: (m); 2 mm ignores touching surfaces.
    self_collision_depth_m: float = 0.002
    #: fail when more than this many frames contain a self-collision.
    max_self_collision_frames: int = 0

    # ---- joint limits, speed, acceleration ---------------------------------------------
    #: a joint is beyond its limit when outside its range by more than this (rad).
    joint_limit_tolerance_rad: float = 0.01
    #: fail when more than this many (frame, joint) pairs are beyond their limits.
    max_joint_limit_violations: int = 0
    #: fail when |joint velocity| / servo velocity limit exceeds this anywhere.
    max_velocity_ratio: float = 1.0
    #: fail when |joint acceleration| exceeds this anywhere (rad/s^2); a jitter detector:
    #: human motion at 20 fps stays below ~100 rad/s^2 on the joints of a small humanoid.
    max_joint_acceleration_radps2: float = 200.0
    #: base_continuity: largest rotation of the base between two consecutive frames (degrees); a
    #: servo humanoid cannot turn its torso 45 degrees in one frame (a flip of the solution)
    max_base_rotation_step_deg: float = 45.0
    #: fail when |required torque| / actuator force limit exceeds this anywhere.
    max_torque_ratio: float = 1.0
    #: friction coefficient of the feet used to distribute the ground reaction in inverse
    #: dynamics (the linearised cone of :mod:`motok_robot.feasibility.dynamics`).
    friction_coefficient: float = 0.8

    # ---- balance -----------------------------------------------------------------------
    #: static balance is judged on quasi-static frames only: where the centre of mass moves
    #: horizontally slower than this (m/s).  In a walk the CoM legitimately leaves the stance
    #: foot while moving; a held lean does not move.
    static_com_speed_mps: float = 0.05
    #: fail when the signed CoM margin (m, positive inside the support polygon) of a
    #: quasi-static contact frame falls below this.
    min_balance_margin_m: float = 0.0
    #: ZMP model: "multibody" (centroidal: CoM acceleration + rate of angular momentum of the
    #: whole multibody) or "cart_table" (CoM acceleration only, linear inverted pendulum).
    zmp_model: str = "multibody"
    #: a ZMP counts as outside when it is outside the support polygon by more than this (m).
    zmp_tolerance_m: float = 0.005
    #: fail when more than this fraction of support frames have the ZMP outside.
    max_zmp_outside_ratio: float = 0.05
    #: centred moving-average window (frames) applied to positions before the second finite
    #: difference of the ZMP; 1 = none.  Smooths the 20 fps differentiation noise.
    zmp_smoothing_frames: int = 3

    # ---- physics rollout ---------------------------------------------------------------
    #: the robot has fallen when its root body is lower than this fraction of its frame-0
    #: height...
    fall_height_ratio: float = 0.6
    #: ...or its root body's up axis tilts more than this from vertical (rad; 1.0 rad = 57 deg).
    fall_tilt_rad: float = 1.0
    #: fail when the per-joint tracking RMSE averaged over joints exceeds this (rad).
    max_tracking_rmse_rad: float = 0.15
    #: fail when the root body ends farther than this (horizontally) from the reference (m)
    #: per metre of robot height -- the threshold scales with robot size.
    max_base_drift_per_height: float = 0.25
    #: fidelity (motok_robot.sim.fidelity): fail when the mean distance of the robot's bodies from
    #: their reference positions, each relative to its root's heading frame, exceeds this
    #: fraction of the robot's height (0.05: 2.6 cm on op3_like, about the retargeting's own
    #: keypoint error of real walks, 1.6-1.8 cm, plus servo compliance)
    max_pose_error_per_height: float = 0.05
    #: fidelity: fail when the root heading differs from the reference's by more than this (rad;
    #: 0.5 rad = 29 degrees, a turn of the robot the motion did not ask for)
    max_heading_error_rad: float = 0.5
    #: fidelity: fail when a foot's highest lift in the rollout stays lower than in the reference
    #: by more than this fraction of the robot's height (0.05: 2.7 cm on op3 and op3_like, a
    #: third of the feasibility stage's gait clearance; real walks re-planned by the stage lift
    #: their feet higher than the human did, a kick walked through without kicking does not)
    max_foot_lift_shortfall_per_height: float = 0.05
    #: fidelity: fail when the robot plays the motion more than this many times slower than the
    #: source (robot.npz ``retime_factor``: retargeting's ``--retime``, the pipeline's slow-down,
    #: the feasibility stage's time warp).  3.0 is the feasibility stage's own bound
    #: (``GaitConfig.max_time_warp``), 1.6x the Froude time scale of a 0.5 m robot copying a
    #: 1.7 m person (sqrt(1.7 / 0.5) = 1.8): slower than that is a different motion.
    max_time_warp: float = 3.0
    #: centre of pressure sampling rate in the rollout (Hz); contact forces are read there.
    #: 20 Hz = the frame rate of the trajectories.
    cop_rate_hz: float = 20.0
    #: fail when more than this fraction of CoP samples with contact lie outside the support
    #: polygon by more than ``zmp_tolerance_m``.
    max_cop_outside_ratio: float = 0.05
    #: physics timestep (s) of the rollout; 0 (the default) keeps the robot model's own
    #: ``opt.timestep`` (2 ms on every shipped robot), the step its contacts were made for: MuJoCo
    #: stiffens no contact beyond twice the step, so the system-identified OP3's 4 ms contact time
    #: constant becomes 8 ms at a 4 ms step, and loaded soles creep more (docs/validation.md).
    #: 0.004 halves the cost.
    physics_timestep_s: float = 0.0
    #: servo goals of the rollout (and of playback, which streams the validated goals):
    #: True = inverse-dynamics feedforward, goal = reference + (required torque + servo
    #: damping x velocity) / servo stiffness, clamped to the joint range and velocity limit
    #: (:mod:`motok_robot.feasibility.feedforward`); False = the reference joint angles themselves.
    #: A position servo only pushes once it lags, so plain reference goals make a compliant
    #: servo robot sag and trail (walks fall open loop; docs/validation.md).
    servo_feedforward: bool = True
    #: the servo goals change by at most this fraction of the velocity limit per frame (both
    #: modes).  Playback's per-tick step is the velocity limit floored to whole encoder ticks
    #: (XM430 at 125 Hz: 0.9988 of 4.8 rad/s) and its commands are rounded to ticks; 0.95
    #: keeps the goals clear of that clamp, so the servos get what the rollout tracked.
    servo_goal_velocity_fraction: float = 0.95
    #: proportional gain (N m / rad per N m of force limit) of the software PD used only for
    #: robots whose actuators are plain motors (position servos track their own targets).
    motor_kp_per_nm: float = 10.0
    #: derivative gain of that PD, as a fraction of the proportional gain (s).
    motor_kd_ratio: float = 0.05

    # ---- render ------------------------------------------------------------------------
    #: frames per second of the MP4.
    render_fps: float = 30.0
    #: width and height (pixels) of the MP4; both robots share one view.
    render_width: int = 640
    render_height: int = 360

    @classmethod
    def keys(cls) -> list[str]:
        """Names of all fields, in declaration order."""
        return [f.name for f in fields(cls)]

    def with_overrides(self, assignments: list[str] | dict | None) -> "ValidationConfig":
        """A copy with fields changed by ``["key=value", ...]`` strings or a ``{key: value}`` dict.

        Values are converted to the field's type; an unknown key or an unparsable value raises
        :class:`~motok_robot.errors.InputError` naming it.
        """
        if not assignments:
            return self
        if isinstance(assignments, dict):
            items = list(assignments.items())
        else:
            items = []
            for text in assignments:
                if "=" not in text:
                    raise InputError(f"--set {text!r}: expected key=value")
                key, value = text.split("=", 1)
                items.append((key.strip(), value.strip()))
        types = {f.name: f.type for f in fields(self)}
        changes = {}
        for key, value in items:
            if key not in types:
                raise InputError(f"--set {key}: unknown validation setting; known: {', '.join(types)}")
            kind = types[key]
            try:
                if kind in ("int", int):
                    changes[key] = int(value)
                elif kind in ("float", float):
                    changes[key] = float(value)
                else:
                    changes[key] = str(value)
            except ValueError:
                raise InputError(f"--set {key}={value}: not a valid {kind}") from None
        if "zmp_model" in changes and changes["zmp_model"] not in ("multibody", "cart_table"):
            raise InputError(f"--set zmp_model={changes['zmp_model']}: use multibody or cart_table")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)
