# Size (452 lines): one file format: its dataclasses, parser and checks change together.
"""Robot description files (``models/mjcf/NAME.toml``): dataclasses, parsing and checks.

A description says, once for every later stage, which robot site stands for which human joint,
where the soles are, what the nominal standing pose is, and (for a servo-driven robot) which
Dynamixel servo drives which joint. The file format is documented in ``docs/robots.md``.

Two levels of checking:

* :func:`parse_description` checks the file on its own (fields present and of the right type,
  canonical joint names, servo IDs unique, ticks inside ``0..ticks_per_rev-1``);
* :func:`check_against_model` checks it against the compiled MJCF (sites, bodies and joints exist,
  each actuated joint has exactly one servo, the servo tick limits cover the joint range and lie
  inside it (to within :data:`TICK_TOLERANCE`), the nominal pose lies in the joint ranges).

Velocity limits must lie inside the servo model's datasheet range
(:mod:`motok_robot.robots.servo_models`; joints without a servo: positive, finite, at most
50 rad/s); the robot's torque limits are checked against the stall torque in :class:`Robot`.

Every error is an :class:`~motok_robot.errors.InputError` whose message names the file and the
entry (``op3_like.toml: [servos.l_knee] ...``).  No torch, no mujoco import at module level.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from motok_robot.errors import InputError
from motok_robot.motion.skeleton import JOINT_NAMES
from motok_robot.robots import servo_models

SIDES = ("left", "right")
LIMBS = ("legs", "arms", "torso", "head")


@dataclass(frozen=True)
class Keypoint:
    """A canonical human joint (``skeleton.JOINT_NAMES``) matched to a robot site, with a cost weight."""

    human_joint: str
    site: str
    weight: float = 1.0


@dataclass(frozen=True)
class Sole:
    """One foot sole.

    ``body``: the foot body; ``site``: sole centre site on the sole surface; ``corner_sites``: the
    4 corner sites on the sole surface (front-left, front-right, rear-right, rear-left in the foot
    frame); ``half_size``: (half length along the foot's x, half width along its y), metres.
    """

    body: str
    site: str
    corner_sites: tuple[str, str, str, str]
    half_size: tuple[float, float]


@dataclass(frozen=True)
class ServoSpec:
    """One Dynamixel servo driving one joint.

    ``angle = sign * (ticks - zero_offset_ticks) * 2*pi / ticks_per_rev`` (rad); ``min_ticks`` and
    ``max_ticks`` are the servo's own angle limits (ticks, inclusive); ``velocity_limit`` in rad/s.
    """

    joint: str
    id: int
    model: str
    sign: int
    zero_offset_ticks: int
    min_ticks: int
    max_ticks: int
    ticks_per_rev: int = 4096
    velocity_limit: float = 4.8

    @property
    def rad_per_tick(self) -> float:
        return 2.0 * math.pi / self.ticks_per_rev

    def angle_from_ticks(self, ticks):
        """Joint angle (rad) of a servo position (ticks); works on floats and numpy arrays."""
        return self.sign * (ticks - self.zero_offset_ticks) * self.rad_per_tick

    def ticks_from_angle(self, angle):
        """Servo position (ticks, not rounded) of a joint angle (rad); floats or numpy arrays."""
        return self.zero_offset_ticks + self.sign * angle / self.rad_per_tick

    @property
    def angle_range(self) -> tuple[float, float]:
        """(lowest, highest) joint angle (rad) that the tick limits allow."""
        a, b = self.angle_from_ticks(self.min_ticks), self.angle_from_ticks(self.max_ticks)
        return (min(a, b), max(a, b))


@dataclass(frozen=True)
class ImuSpec:
    """The torso IMU on the servo bus (``[bus.imu]``): a ROBOTIS OpenCR sub-controller at ``id``.

    ``axes`` says how the sensor is mounted: entry ``i`` names the sensor axis (``"x"``,
    ``"y"``, ``"z"``, with a leading ``-`` when it points the other way) that gives axis ``i``
    (x, y, z) of the robot's IMU frame (the MJCF's ``imu`` site, else the base body).  The
    ROBOTIS OP3 mounts it with x and y reversed: ``["-x", "-y", "z"]``.
    """

    id: int = 200
    axes: tuple[str, str, str] = ("-x", "-y", "z")


@dataclass(frozen=True)
class BusSpec:
    """The servo bus: Dynamixel protocol version, baud rate (bit/s), control cycle (Hz), and
    the IMU on it (None: the bus has no IMU)."""

    protocol: float = 2.0
    baud: int = 2_000_000
    control_hz: float = 125.0
    imu: ImuSpec | None = None


@dataclass
class RobotDescription:
    """A parsed ``NAME.toml`` (see the module docstring and ``docs/robots.md``)."""

    name: str
    path: Path  # the TOML file
    mjcf: Path  # the MJCF file (resolved next to the TOML)
    summary: str
    torso_body: str
    mass_range: tuple[float, float]  # kg, documented range of the total mass
    height_range: tuple[float, float]  # m, head top above the soles at the zero pose
    keypoints: list[Keypoint]
    limb_scale: dict[str, float]
    soles: dict[str, Sole]  # "left", "right"
    nominal_pose: dict[str, float]  # joint -> rad (joints not listed: 0)
    servos: list[ServoSpec] = field(default_factory=list)
    bus: BusSpec | None = None
    velocity_limits: dict[str, float] = field(default_factory=dict)  # joint (or "default") -> rad/s
    #: joint -> (low, high) rad: the range the retargeter may use, inside the MJCF joint range (a
    #: pose prior, e.g. an elbow that bends one way only); servo and validation limits stay the MJCF's
    retarget_ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    #: the feasibility stage's settings for this robot (the ``[feasibility]`` table: fields of
    #: ``FeasibilityConfig``, nested tables for ``gait``, ``balance``, ``refine_config``); they are
    #: checked where the stage reads them (``motok_robot.feasibility.config.robot_config``)
    feasibility: dict[str, Any] = field(default_factory=dict)

    def servo_for(self, joint: str) -> ServoSpec | None:
        """The servo driving ``joint``, or None."""
        for s in self.servos:
            if s.joint == joint:
                return s
        return None


# --------------------------------------------------------------------------------------------
# parsing


class _Reader:
    """Typed access to TOML tables with error messages naming the file and the entry."""

    def __init__(self, path: Path):
        self.path = path

    def fail(self, where: str, msg: str) -> InputError:
        loc = f"[{where}] " if where else ""
        return InputError(f"{self.path.name}: {loc}{msg}")

    def table(self, data: dict, key: str, where: str, required: bool = True) -> dict:
        if key not in data:
            if required:
                raise self.fail(where, f"missing table {key!r}")
            return {}
        value = data[key]
        if not isinstance(value, dict):
            raise self.fail(where, f"{key!r} must be a table, got {type(value).__name__}")
        return value

    def get(self, data: dict, key: str, kind, where: str, default: Any = ...):
        if key not in data:
            if default is ...:
                raise self.fail(where, f"missing field {key!r}")
            return default
        value = data[key]
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if kind is int and isinstance(value, float) and value.is_integer():
            value = int(value)
        if not isinstance(value, kind) or isinstance(value, bool) and kind is not bool:
            name = kind.__name__ if isinstance(kind, type) else "/".join(k.__name__ for k in kind)
            raise self.fail(where, f"field {key!r} must be {name}, got {value!r}")
        return value

    def numbers(self, data: dict, key: str, n: int, where: str, default: Any = ...) -> tuple[float, ...]:
        if key not in data and default is not ...:
            return default
        value = self.get(data, key, list, where)
        if len(value) != n or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            raise self.fail(where, f"field {key!r} must be a list of {n} numbers, got {value!r}")
        return tuple(float(v) for v in value)


def _parse_imu(r: _Reader, data) -> ImuSpec:
    """``[bus.imu]``: ``id`` (0..252) and ``axes`` (a signed permutation of x, y, z)."""
    if not isinstance(data, dict):
        raise r.fail("bus.imu", "must be a table {id, axes}")
    unknown = set(data) - {"id", "axes"}
    if unknown:
        raise r.fail("bus.imu", f"unknown field(s) {', '.join(sorted(unknown))}")
    default = ImuSpec()
    imu_id = r.get(data, "id", int, "bus.imu", default.id)
    if not 0 <= imu_id <= 252:
        raise r.fail("bus.imu", f"id {imu_id} outside 0..252")
    axes = r.get(data, "axes", list, "bus.imu", list(default.axes))
    if (len(axes) != 3 or not all(isinstance(a, str) and a.lstrip("-") in ("x", "y", "z") and a.count("-") <= 1
                                  for a in axes) or sorted(a.lstrip("-") for a in axes) != ["x", "y", "z"]):
        raise r.fail("bus.imu", f"axes must name each sensor axis once, e.g. [\"-x\", \"-y\", \"z\"], got {axes!r}")
    return ImuSpec(id=imu_id, axes=tuple(axes))


def parse_description(path: str | Path) -> RobotDescription:
    """Read and check ``NAME.toml`` on its own (not against the model: see :func:`check_against_model`)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"robot description not found: {path}")
    try:
        with path.open("rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path.name}: not valid TOML: {exc}") from None
    r = _Reader(path)

    name = r.get(data, "name", str, "")
    mjcf = path.parent / r.get(data, "mjcf", str, "", default=f"{path.stem}.xml")
    summary = r.get(data, "summary", str, "", default="")
    torso_body = r.get(data, "torso_body", str, "")
    mass_range = r.numbers(data, "mass_range", 2, "")
    height_range = r.numbers(data, "height_range", 2, "")
    for key, rng in (("mass_range", mass_range), ("height_range", height_range)):
        if not 0 < rng[0] <= rng[1]:
            raise r.fail("", f"{key!r} must be [low, high] with 0 < low <= high, got {list(rng)}")

    keypoints = []
    for human, entry in r.table(data, "keypoints", "").items():
        where = f"keypoints.{human}"
        if human not in JOINT_NAMES:
            raise r.fail(where, f"{human!r} is not a canonical human joint (one of {', '.join(JOINT_NAMES)})")
        if isinstance(entry, str):  # shorthand: human = "site"
            entry = {"site": entry}
        if not isinstance(entry, dict):
            raise r.fail(where, "must be a site name or a table {site, weight}")
        weight = r.get(entry, "weight", float, where, default=1.0)
        if not (weight >= 0 and math.isfinite(weight)):
            raise r.fail(where, f"weight must be >= 0, got {weight}")
        keypoints.append(Keypoint(human, r.get(entry, "site", str, where), weight))
    if not keypoints:
        raise r.fail("keypoints", "no keypoints")

    limb_scale = {}
    for limb, value in r.table(data, "limb_scale", "").items():
        where = f"limb_scale.{limb}"
        if limb not in LIMBS:
            raise r.fail(where, f"unknown limb {limb!r} (one of {', '.join(LIMBS)})")
        value = r.get({limb: value}, limb, float, "limb_scale")
        if not value > 0:
            raise r.fail(where, f"must be > 0, got {value}")
        limb_scale[limb] = value

    soles_table = r.table(data, "soles", "")
    soles = {}
    for side in SIDES:
        where = f"soles.{side}"
        entry = r.table(soles_table, side, "soles")
        corners = r.get(entry, "corner_sites", list, where)
        if len(corners) != 4 or not all(isinstance(c, str) for c in corners):
            raise r.fail(where, f"corner_sites must be 4 site names, got {corners!r}")
        half = r.numbers(entry, "half_size", 2, where)
        if not (half[0] > 0 and half[1] > 0):
            raise r.fail(where, f"half_size must be positive, got {list(half)}")
        soles[side] = Sole(r.get(entry, "body", str, where), r.get(entry, "site", str, where), tuple(corners), half)

    nominal = {}
    for joint, value in r.table(data, "nominal_pose", "").items():
        nominal[joint] = r.get({joint: value}, joint, float, "nominal_pose")

    velocity_limits = {}
    for joint, value in r.table(data, "velocity_limits", "", required=False).items():
        value = r.get({joint: value}, joint, float, "velocity_limits")
        problem = servo_models.generic_velocity_problem(value)
        if problem:
            raise r.fail(f"velocity_limits.{joint}", problem)
        velocity_limits[joint] = value

    retarget_ranges = {}
    ranges_table = r.table(data, "retarget_ranges", "", required=False)
    for joint in ranges_table:
        lo, hi = r.numbers(ranges_table, joint, 2, "retarget_ranges")
        if not lo < hi:
            raise r.fail(f"retarget_ranges.{joint}", f"needs low < high, got [{lo:g}, {hi:g}]")
        retarget_ranges[joint] = (lo, hi)

    bus = None
    if "bus" in data:
        b = r.table(data, "bus", "")
        bus = BusSpec(
            protocol=r.get(b, "protocol", float, "bus"),
            baud=r.get(b, "baud", int, "bus"),
            control_hz=r.get(b, "control_hz", float, "bus"),
            imu=_parse_imu(r, b["imu"]) if "imu" in b else None,
        )
        if bus.protocol not in (1.0, 2.0):
            raise r.fail("bus", f"protocol must be 1.0 or 2.0, got {bus.protocol}")
        if bus.baud <= 0 or bus.control_hz <= 0:
            raise r.fail("bus", "baud and control_hz must be positive")

    defaults = r.table(data, "servo_defaults", "", required=False)
    servos: list[ServoSpec] = []
    id_owner: dict[int, str] = {}
    for joint, entry in r.table(data, "servos", "", required=False).items():
        where = f"servos.{joint}"
        if not isinstance(entry, dict):
            raise r.fail(where, "must be a table {id, sign, zero_offset_ticks, min_ticks, max_ticks, ...}")
        e = {**defaults, **entry}
        spec = ServoSpec(
            joint=joint,
            id=r.get(e, "id", int, where),
            model=r.get(e, "model", str, where),
            sign=r.get(e, "sign", int, where),
            zero_offset_ticks=r.get(e, "zero_offset_ticks", int, where),
            min_ticks=r.get(e, "min_ticks", int, where),
            max_ticks=r.get(e, "max_ticks", int, where),
            ticks_per_rev=r.get(e, "ticks_per_rev", int, where),
            velocity_limit=r.get(e, "velocity_limit", float, where),
        )
        unknown = set(e) - {f for f in ServoSpec.__dataclass_fields__ if f != "joint"}
        if unknown:
            raise r.fail(where, f"unknown field(s) {', '.join(sorted(unknown))}")
        if not 0 <= spec.id <= 252:
            raise r.fail(where, f"servo id {spec.id} outside 0..252")
        if spec.id in id_owner:
            raise r.fail(where, f"duplicate servo id {spec.id}: already used by [servos.{id_owner[spec.id]}]")
        id_owner[spec.id] = joint
        if spec.sign not in (1, -1):
            raise r.fail(where, f"sign must be 1 or -1, got {spec.sign}")
        if spec.ticks_per_rev <= 0:
            raise r.fail(where, f"ticks_per_rev must be positive, got {spec.ticks_per_rev}")
        top = spec.ticks_per_rev - 1
        for key in ("zero_offset_ticks", "min_ticks", "max_ticks"):
            v = getattr(spec, key)
            if not 0 <= v <= top:
                raise r.fail(where, f"{key} {v} outside the servo's 0..{top} ticks")
        if spec.min_ticks >= spec.max_ticks:
            raise r.fail(where, f"min_ticks {spec.min_ticks} must be below max_ticks {spec.max_ticks}")
        if spec.model.upper() not in servo_models.DATASHEETS:
            raise r.fail(where, f"servo model {spec.model!r} has no datasheet entry (known: "
                                f"{', '.join(servo_models.DATASHEETS)}); its limits cannot be checked")
        problem = servo_models.velocity_problem(spec.model, spec.velocity_limit)
        if problem:
            raise r.fail(where, problem)
        servos.append(spec)
    if servos and bus is None:
        raise r.fail("", "servos are listed but there is no [bus] table")
    if bus is not None and bus.imu is not None and bus.imu.id in id_owner:
        raise r.fail("bus.imu", f"id {bus.imu.id} is already used by [servos.{id_owner[bus.imu.id]}]")

    return RobotDescription(
        name=name,
        path=path,
        mjcf=mjcf,
        summary=summary,
        torso_body=torso_body,
        mass_range=mass_range,
        height_range=height_range,
        keypoints=keypoints,
        limb_scale=limb_scale,
        soles=soles,
        nominal_pose=nominal,
        servos=servos,
        bus=bus,
        velocity_limits=velocity_limits,
        retarget_ranges=retarget_ranges,
        feasibility=r.table(data, "feasibility", "", required=False),
    )


# --------------------------------------------------------------------------------------------
# checks against the compiled model

#: how far (in ticks) the servo limits may fall inside the joint range (tick rounding)
TICK_TOLERANCE = 0.5
#: how far (in ticks) the servo limits may reach beyond the joint range: the range rounded
#: outward to whole ticks (at most 1 tick, 0.0015 rad for 4096 ticks per turn), never more
TICK_OUTSIDE_TOLERANCE = 1.0


def check_against_model(desc: RobotDescription, model, joint_names: list[str], joint_range) -> None:
    """Check that every name in ``desc`` exists in ``model`` and that the servo map fits the joints.

    ``joint_names``: the actuated hinge joints (free joint excluded); ``joint_range``: ``[nj, 2]`` rad.
    Raises :class:`InputError` naming the file and entry of the first problem.
    """
    import mujoco

    r = _Reader(desc.path)

    def names(obj) -> set[str]:
        count = {mujoco.mjtObj.mjOBJ_SITE: model.nsite, mujoco.mjtObj.mjOBJ_BODY: model.nbody}[obj]
        return {mujoco.mj_id2name(model, obj, i) for i in range(count)}

    sites, bodies = names(mujoco.mjtObj.mjOBJ_SITE), names(mujoco.mjtObj.mjOBJ_BODY)
    joints = set(joint_names)
    known = f"(model {desc.mjcf.name})"

    if desc.torso_body not in bodies:
        raise r.fail("", f"torso_body {desc.torso_body!r} is not a body {known}")
    for kp in desc.keypoints:
        if kp.site not in sites:
            raise r.fail(f"keypoints.{kp.human_joint}", f"unknown site {kp.site!r} {known}")
    for side, sole in desc.soles.items():
        where = f"soles.{side}"
        if sole.body not in bodies:
            raise r.fail(where, f"unknown body {sole.body!r} {known}")
        for s in (sole.site, *sole.corner_sites):
            if s not in sites:
                raise r.fail(where, f"unknown site {s!r} {known}")
    index = {j: i for i, j in enumerate(joint_names)}
    for joint, angle in desc.nominal_pose.items():
        if joint not in joints:
            raise r.fail(f"nominal_pose.{joint}", f"unknown joint {joint!r} {known}")
        lo, hi = joint_range[index[joint]]
        if not lo <= angle <= hi:
            raise r.fail(f"nominal_pose.{joint}", f"{angle} rad outside the joint range [{lo:.4g}, {hi:.4g}]")
    for joint in desc.velocity_limits:
        if joint != "default" and joint not in joints:
            raise r.fail(f"velocity_limits.{joint}", f"unknown joint {joint!r} {known}")
    for joint, (rlo, rhi) in desc.retarget_ranges.items():
        where = f"retarget_ranges.{joint}"
        if joint not in joints:
            raise r.fail(where, f"unknown joint {joint!r} {known}")
        lo, hi = joint_range[index[joint]]
        if rlo < lo or rhi > hi:
            raise r.fail(where, f"[{rlo:g}, {rhi:g}] rad reaches outside the joint range [{lo:.4g}, {hi:.4g}] "
                                f"of {desc.mjcf.name}")
        angle = desc.nominal_pose.get(joint, 0.0)
        if not rlo <= angle <= rhi:
            raise r.fail(where, f"[{rlo:g}, {rhi:g}] rad leaves out the nominal pose's {angle:g} rad")

    if desc.servos:
        for spec in desc.servos:
            where = f"servos.{spec.joint}"
            if spec.joint not in joints:
                raise r.fail(where, f"unknown joint {spec.joint!r} {known}")
            lo, hi = joint_range[index[spec.joint]]
            slo, shi = spec.angle_range
            tol = TICK_TOLERANCE * spec.rad_per_tick
            if slo > lo + tol or shi < hi - tol:
                raise r.fail(
                    where,
                    f"servo ticks {spec.min_ticks}..{spec.max_ticks} allow [{slo:.4f}, {shi:.4f}] rad, "
                    f"which does not cover the joint range [{lo:.4f}, {hi:.4f}] rad",
                )
            out = TICK_OUTSIDE_TOLERANCE * spec.rad_per_tick
            if slo < lo - out or shi > hi + out:
                raise r.fail(
                    where,
                    f"servo ticks {spec.min_ticks}..{spec.max_ticks} allow [{slo:.4f}, {shi:.4f}] rad, "
                    f"wider than the joint range [{lo:.4f}, {hi:.4f}] rad of {desc.mjcf.name} by more than "
                    f"{TICK_OUTSIDE_TOLERANCE:g} tick: servo limits must lie inside the joint range",
                )
        missing = [j for j in joint_names if desc.servo_for(j) is None]
        if missing:
            raise r.fail("servos", f"no servo for actuated joint(s) {', '.join(missing)}")
    else:
        missing = [j for j in joint_names if j not in desc.velocity_limits and "default" not in desc.velocity_limits]
        if missing:
            raise r.fail("velocity_limits", f"no velocity limit for joint(s) {', '.join(missing)} (add them or 'default')")
