"""Zero-offset calibration: read the servos in the robot's zero pose, write a calibrated description.

The servo map convention (``ServoSpec``) is ``angle = sign * (ticks - zero_offset_ticks) * 2 pi /
ticks_per_rev``, so the present position of each servo with the robot held in its zero pose
(every joint angle 0) *is* its ``zero_offset_ticks``.  The tick limits describe the joint range
around that zero, so they move by the same amount.  The copy keeps everything else of the
original file (comments included) and points ``mjcf`` at the original MJCF.
"""

from __future__ import annotations

import re
from pathlib import Path


from motok_robot.errors import HardwareError, InputError
from motok_robot.servo.bus import ServoBus, ServoError
from motok_robot.servo.convert import ServoMap


def prepare(bus: ServoBus, servo_map: ServoMap) -> None:
    """Ping every servo (naming the silent ones) and switch torque off so the joints move by hand."""
    names = servo_map.names_by_id
    silent = []
    for servo_id in servo_map.ids:
        try:
            bus.ping(int(servo_id))
        except ServoError as exc:
            silent.append(exc.describe(names))
    if silent:
        raise HardwareError("calibration: " + "; ".join(silent))
    bus.set_torque([int(i) for i in servo_map.ids], False)


def read_zero_pose(bus: ServoBus, servo_map: ServoMap) -> dict[str, int]:
    """Present position (ticks) of every servo, by joint name."""
    ids = [int(i) for i in servo_map.ids]
    try:
        ticks = bus.read_present_positions_each(ids)
    except ServoError as exc:
        raise HardwareError("calibration: " + exc.describe(servo_map.names_by_id)) from None
    return {joint: int(t) for joint, t in zip(servo_map.joints, ticks)}


def calibrated_description(robot, zero_ticks: dict[str, int], out: str | Path) -> Path:
    """Write a copy of ``robot``'s description with measured zero offsets; returns its path.

    Raises InputError naming the servo when the shifted tick limits leave ``0..ticks_per_rev-1``
    or when the file's servo entry is not a one-line inline table.
    """
    source = Path(robot.description.path)
    text = source.read_text(encoding="utf-8")
    lines = text.splitlines(keepends=True)
    section = None
    done = set()
    specs = {s.joint: s for s in robot.servos}
    for k, line in enumerate(lines):
        stripped = line.strip()
        header = re.match(r"^\[([^\]]+)\]", stripped)
        if header:
            section = header.group(1).strip()
            continue
        if section == "mjcf" or (section is None and re.match(r"^mjcf\s*=", stripped)):
            lines[k] = f'mjcf = "{Path(robot.mjcf_path).resolve().as_posix()}"\n'
            continue
        if section != "servos":
            continue
        match = re.match(r"^([A-Za-z0-9_]+)\s*=\s*\{", stripped)
        if not match or match.group(1) not in zero_ticks:
            continue
        joint = match.group(1)
        spec = specs[joint]
        zero = int(zero_ticks[joint])
        delta = zero - int(spec.zero_offset_ticks)
        lo, hi = int(spec.min_ticks) + delta, int(spec.max_ticks) + delta
        if lo < 0 or hi > int(spec.ticks_per_rev) - 1:
            raise InputError(f"servo {spec.id} ({joint}): zero pose at {zero} ticks moves the joint range to "
                             f"[{lo}, {hi}], outside 0..{int(spec.ticks_per_rev) - 1}; re-seat the servo horn")
        new = line
        for key, value in (("zero_offset_ticks", zero), ("min_ticks", lo), ("max_ticks", hi)):
            if re.search(rf"\b{key}\s*=\s*-?\d+", new):
                new = re.sub(rf"\b{key}\s*=\s*-?\d+", f"{key} = {value}", new)
            else:
                new = new.replace("{", f"{{ {key} = {value},", 1)
        lines[k] = new
        done.add(joint)
    missing = [j for j in zero_ticks if j not in done]
    if missing:
        raise InputError(f"{source}: no one-line [servos] entry for {', '.join(missing)}; "
                         "set zero_offset_ticks by hand: " + ", ".join(f"{j}={zero_ticks[j]}" for j in missing))
    out = Path(out)
    if out.suffix != ".toml":
        raise InputError(f"{out}: the calibrated description must be a .toml file")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("".join(lines), encoding="utf-8")
    from motok_robot.robots import load

    load(out)  # the copy must load and pass the robot checks
    return out
