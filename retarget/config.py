"""Retargeting settings: every default lives here (dataclasses, no heavy imports)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class ContactConfig:
    """Foot-contact detection on the *human* motion (metres, seconds, before scaling).

    A foot is a candidate for contact in a frame when

    * its lowest point is near the floor: the toe joint (``left_foot`` / ``right_foot``) is at
      most ``toe_height`` above the floor, or the ankle at most ``ankle_height`` above it (the
      floor is the ``floor_percentile``-th percentile of the lowest foot joint over the clip),
    * and it is nearly still horizontally: the slower of ankle and toe moves slower than
      ``enter_speed`` (to enter a contact phase) / ``exit_speed`` (to stay in one; hysteresis).

    Phases shorter than ``min_contact_frames`` are dropped, swing gaps shorter than
    ``min_swing_frames`` between two contacts are filled.  Defaults suit walking mocap of an
    adult at 20 fps: a planted foot of a walking person moves < 0.1 m/s at the heel or toe,
    a swinging foot 1-4 m/s.

    ``support`` decides what the *robot* does in frames where neither human foot is planted
    (:func:`retarget.contacts.fill_support`): ``"off"`` keeps both feet in the air there (the
    robot floats); ``"near"`` plants the lower foot in such frames where a foot is near the
    floor (a sliding or shuffling foot becomes a planted one; a jump's flight stays a flight);
    ``"always"`` plants the lower foot in every such frame (a run becomes a fast walk).  A
    servo humanoid cannot glide on a sliding sole, and a robot with both soles 2 cm up fails
    ``motok-robot validate``'s floating check.
    """

    toe_height: float = 0.06
    ankle_height: float = 0.12
    enter_speed: float = 0.30
    exit_speed: float = 0.50
    min_contact_frames: int = 3
    min_swing_frames: int = 2
    floor_percentile: float = 2.0
    floor_height: float | None = None  # metres; None = estimate (floor_percentile) from the clip
    support: str = "near"  # "off" | "near" | "always": plant a foot in frames where none is planted
    #: at a hand-over from one foot to the other, keep the old foot planted until at least this many
    #: frames after the new one touches down (0 = as detected); see contacts.ensure_double_support
    min_double_support: int = 0
    #: a planted foot pivots about its sole site where the human's foot turns faster than
    #: ``pivot_speed_deg`` (degrees a second) within a contact phase that turns it more than
    #: ``pivot_min_turn_deg`` in all (the Bandai spinning kick turns its stance foot 307 degrees;
    #: the walks' largest turn within one step is 56 degrees, 173 where a walk turns round), by
    #: up to ``pivot_margin`` times the human foot's turn per frame (the kick's stance foot turns
    #: up to 33 degrees a frame at 20 fps; the base's own turn is bounded by
    #: ``SolverConfig.max_base_turn_speed_deg``); elsewhere it holds its yaw (a planted sole that
    #: could not turn snapped the kick's base 158 degrees in one frame)
    pivot_speed_deg: float = 120.0
    pivot_min_turn_deg: float = 120.0
    pivot_margin: float = 1.25


@dataclass(frozen=True)
class CostWeights:
    """Objective weights (dimensionless; positions are divided by the robot leg length first,
    angles are in radians, per frame and summed over the window).
    """

    keypoint: float = 100.0  # x keypoint weight from the robot description, per (error / leg length)^2
    heading: float = 1.0  # (base yaw - human heading)^2
    foot_yaw: float = 1.0  # |sole forward axis (xy) - human foot direction (xy)|^2, per foot
    velocity: float = 0.05  # |q[t+1] - q[t]|^2 (base position in leg lengths, angles in rad)
    acceleration: float = 5.0  # |q[t+1] - 2 q[t] + q[t-1]|^2
    nominal: float = 0.01  # |joints - nominal joints|^2
    base_tilt: float = 0.1  # (pitch^2 + roll^2) of the base: keeps the torso upright when unobserved
    com: float = 0.0  # soft: horizontal CoM distance to the support centre (leg lengths)^2, in contact frames
    zmp: float = 0.0  # soft: cart-table ZMP distance to the support centre (leg lengths)^2, in contact frames


@dataclass(frozen=True)
class SwingConfig:
    """Swing-foot clearance and gentle lift-off / touch-down (hard constraints; metres, m/s).

    Outside contact phases all four sole corners stay at least ``clearance(t)`` above the
    ground. ``clearance`` rises from ``lift`` in the swing frames next to a contact phase to
    ``height`` (smoothstep over ``ramp_seconds``), so the foot leaves and meets the ground
    without skimming it yet needs no large vertical jump (joint velocity limits still hold).
    Between a contact frame and its neighbouring swing frame the sole site moves at most
    ``transition_speed / fps`` per horizontal axis (the foot lifts and lands nearly vertically
    instead of sliding on or off), and in those swing frames the sole is held flat and low:
    its four corners between ``lift`` and ``lift + flat_tolerance`` (flat touch-down). A swing
    phase that touches no contact phase (the whole clip in the air) gets no clearance.
    ``height = 0`` turns all of this off (the behaviour before this term existed).

    Absolute lengths, not leg-length fractions: what the clearance must beat (servo position
    error and sag under load, floor unevenness, the 5 mm contact height of
    ``motok-robot validate``) does not shrink with the robot. A human clears the floor by
    ~2 cm; scaled to a 22 cm leg that is 5 mm, which physics sees as a foot scraping the floor.
    """

    height: float = 0.02  # m; mid-swing clearance of the lowest sole corner
    lift: float = 0.008  # m; clearance in the swing frames next to a contact phase
    ramp_seconds: float = 0.1  # s; rise time from ``lift`` to ``height``
    transition_speed: float = 0.04  # m/s; horizontal sole speed at lift-off / touch-down (per axis)
    flat_tolerance: float = 0.002  # m; corner height band in the lift-off / touch-down swing frames


@dataclass(frozen=True)
class CollisionConfig:
    """Self-collision avoidance (``retarget.collision``; metres).

    After a solve, geom pairs that overlap or come closer than ``detect_margin`` (MuJoCo's
    collision detection on the robot's own geoms; 0 = touching) get constraint rows that keep
    them at least ``margin`` apart, and the clip is solved again from that solution; repeated
    while new pairs touch, at most ``max_rounds`` times. A clip that needs it pays the build
    of a larger window problem (seconds, once per process and active set) and a second solve.
    ``enabled=False`` turns it off (the behaviour before this existed). ``margin`` leaves room
    for servo tracking error and for the 2 mm depth that ``motok-robot validate`` tolerates.
    """

    enabled: bool = True
    margin: float = 0.004
    detect_margin: float = 0.0
    max_rounds: int = 3


@dataclass(frozen=True)
class SolverConfig:
    """IPOPT settings (see https://coin-or.github.io/Ipopt/OPTIONS.html)."""

    tol: float = 1e-4  # IPOPT's scaled optimality error; the objective is ~1e3 per window
    acceptable_tol: float = 1e-4
    constr_viol_tol: float = 1e-6  # metres / radians: contact equalities hold to a micrometre
    max_iter: int = 500  # windows take 20-30 iterations; a self-collision re-solve of a hard window took 203
    max_cpu_time: float = 60.0  # s per window (windows take well under 1 s); a degenerate input cannot hang a run
    hessian: str = "exact"  # or "gauss-newton" (objective only + exact constraint curvature), "limited-memory"
    linear_solver: str = "mumps"
    mu_strategy: str = "adaptive"
    mu_init: float = 1e-2  # the primal start is close (previous window / previous frame)
    max_tilt: float = 1.0  # rad; bound on base pitch and roll (Euler singular at pi/2, see problem.py)
    max_yaw_offset: float = 1.2  # rad; bound on |base yaw - human heading| (no turning the wrong way round)
    #: deg/s; bound on the base's turn between frames (36 degrees a frame at 20 fps; the Bandai
    #: spinning kick's human turns at up to 660 deg/s, and a robot base that lagged it caught up
    #: by 53 degrees in one frame, which validation's base_continuity check fails above 45)
    max_base_turn_speed_deg: float = 720.0
    base_height_range: tuple = (0.3, 1.6)  # base z bounds as fractions of the nominal base height
    extra: tuple = ()  # further (name, value) IPOPT options, e.g. (("print_level", 5),)


@dataclass(frozen=True)
class RetargetConfig:
    """One retargeting run.

    ``window`` frames are optimised together; consecutive windows share ``overlap`` frames:
    the last ``overlap`` frames of a window are look-ahead only (they warm-start the next
    window, which re-solves them with more future context). ``mode="per-frame"`` solves one
    frame at a time with the same costs (the IK baseline). ``scale=False`` uses the human
    joints as robot targets unchanged (for motions that are already robot-sized).
    """

    window: int = 60
    overlap: int = 10
    mode: str = "trajectory"  # or "per-frame"
    scale: bool = True
    scaling: str = "segments"  # or "limbs" (retarget.targets)
    allow_partial: bool = False
    weights: CostWeights = field(default_factory=CostWeights)
    contacts: ContactConfig = field(default_factory=ContactConfig)
    swing: SwingConfig = field(default_factory=SwingConfig)
    collision: CollisionConfig = field(default_factory=CollisionConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)
    ground_height: float = 0.0  # metres, world z of the floor
    presolve_frames: int = 15  # the first window is warm-started by a sweep of windows this long (0 = off)
    # a presolved first window that fails, or leaves a keypoint farther than this many leg lengths
    # from its target, is solved again from the plain warm start; the lower objective is kept
    presolve_retry_per_leg: float = 0.5
    velocity_margin: float = 0.98  # use this fraction of each joint's velocity limit
    # the inner sole edges stay at least this far apart across the human heading (robot leg lengths;
    # None = off): scaled human feet pass closer than a robot's wide soles allow (op3_like: 4.4 mm gap)
    min_foot_gap: float | None = 0.02
