"""The drafted ``NAME.toml`` (schema: docs/robots.md), line by line, with a comment on how each
value was measured."""

from __future__ import annotations

import math

from motok_robot.robots.draft.drafter import Drafter

#: the velocity limit written when the MJCF says nothing about joint speeds, rad/s (a placeholder)
VELOCITY_PLACEHOLDER = 10.0


class TomlLines:
    def __init__(self):
        self.lines: list[str] = []

    def add(self, *lines: str) -> None:
        self.lines.extend(lines)

    def line_of(self, marker: str) -> int | None:
        for i, line in enumerate(self.lines, 1):
            if line.startswith(marker) or marker in line and not line.startswith("#"):
                return i
        return None

    def text(self) -> str:
        return "\n".join(self.lines) + "\n"


def _fnum(v: float, nd: int = 4) -> str:
    s = f"{v:.{nd}f}".rstrip("0")
    return s + "0" if s.endswith(".") else s


def toml_text(dr: Drafter, mjcf_ref: str, nominal: dict[str, float], rows, servo, scales) -> TomlLines:
    M = dr.M
    t = TomlLines()
    mass = float(M.m.body_subtreemass[0])
    height = dr.height()
    nj = len(M.hinges)
    t.add(f"# {dr.name} robot description, DRAFTED by `motok-robot robots add {dr.src.name}` (schema: docs/robots.md).",
          f"# Measured on {dr.src.name} at its zero pose; check the image and the list the command printed.",
          "# Angles in radians, lengths in metres, masses in kilograms.",
          "",
          f'name = "{dr.name}"',
          f'mjcf = "{mjcf_ref}"',
          f'summary = "{dr.name}: {nj} joints, {height:.2f} m, {mass:.1f} kg (drafted from {dr.src.name})"',
          f'torso_body = "{M.body_name(M.base)}"',
          f"# measured on the model: {mass:.3f} kg; zero-pose height (highest geom above the soles) {height:.3f} m",
          f"mass_range = [{_fnum(mass * 0.97, 3)}, {_fnum(mass * 1.03, 3)}]",
          f"height_range = [{_fnum(height * 0.97, 3)}, {_fnum(height * 1.03, 3)}]",
          "")
    t.add("# canonical human joint (motok_robot.motion.skeleton.JOINT_NAMES) -> robot site, cost weight.",
          "# Sites: hip / knee / ankle / shoulder / elbow / wrist at the centres of the leg's and arm's joint groups",
          "# (where their axes meet), pelvis between the hips, neck at the first head joint, head at the head's centre.",
          "[keypoints]")
    for human, site, w in dr.keypoints:
        t.add(f'{human} = {{ site = "{site}", weight = {w} }}')
    t.add("")
    t.add("# robot length / canonical human length (skeleton.rest_pose()) per limb, measured between the sites at")
    names = {"legs": "hip -> knee -> ankle", "arms": "shoulder -> elbow -> wrist", "torso": "pelvis -> neck",
             "head": "neck -> head"}
    t.add("# the zero pose: " + "; ".join(f"{k}: {names[k]} {r:.3f} / {h:.3f}" for k, (_, r, h) in scales.items()))
    t.add("[limb_scale]")
    for k, (s, _, _) in scales.items():
        t.add(f"{k} = {s:.3f}")
    t.add("")
    foot_desc = dr.sole_kind
    t.add(f"# soles: the lowest faces of each foot's collision geoms ({foot_desc}) at the zero pose; the centre and",
          "# corner sites lie on that plane, the corners bound the contact points (front-left, front-right,",
          "# rear-right, rear-left)")
    for side in ("left", "right"):
        foot, half, _ = dr.soles[side]
        s = side[0]
        t.add(f"[soles.{side}]",
              f'body = "{M.body_name(foot)}"',
              f'site = "{s}_sole"',
              f'corner_sites = ["{s}_sole_fl", "{s}_sole_fr", "{s}_sole_rr", "{s}_sole_rl"]',
              f"half_size = [{_fnum(half[0])}, {_fnum(half[1])}]",
              "")
    t.add(f"# nominal standing pose: knees bent {dr.knee_bend} rad, hip and ankle pitch solved for flat soles with the",
          "# ankles under the hips; arms lowered when the zero pose holds them out; joints not listed are 0")
    t.add("[nominal_pose]")
    for j, v in nominal.items():
        t.add(f"{j} = {v}")
    t.add("")
    t.add("# joint limits from the MJCF (range rad, torque N m):")
    for j, name, lo, hi, tq, _ in rows:
        lo, hi = dr.joint_range(j)
        t.add(f"#   {name}: [{lo:.3f}, {hi:.3f}], {'%.3g' % tq if tq is not None else 'NO TORQUE LIMIT'}"
              + ("  (range added in the copy)" if j in dr.added_ranges else ""))
    if servo is None:
        t.add("# rad/s. The MJCF gives no joint speeds: PLACEHOLDER, replace with the motors' figures",
              "[velocity_limits]",
              f"default = {VELOCITY_PLACEHOLDER}")
    else:
        sheet, top = servo
        t.add("", "# VERIFY: the actuators look like Dynamixel position servos, so this is a DRAFT servo map:",
              f"# model {sheet.model} = the smallest datasheet servo whose stall torque covers the MJCF's",
              f"# {top:.3g} N m; IDs in actuator order, sign +1, zero offset 2048: check every entry on the robot",
              "# (`motok-robot servo scan`, `motok-robot servo calibrate`) before playback.",
              "[bus]", "protocol = 2.0", "baud = 1000000   # VERIFY", "control_hz = 100   # VERIFY", "",
              "[servo_defaults]", f'model = "{sheet.model}"', "ticks_per_rev = 4096",
              f"velocity_limit = {math.floor(sheet.no_load_speed * 100) / 100}   # rad/s, datasheet no-load speed", "",
              "[servos]")
        rad = 2 * math.pi / 4096
        act_order = sorted(rows, key=lambda r: r[5][0])
        for i, (j, name, _, _, _, _) in enumerate(act_order, 1):
            lo, hi = dr.joint_range(j)
            tlo = max(0, math.floor(2048 + lo / rad + 1e-9))
            thi = min(4095, math.ceil(2048 + hi / rad - 1e-9))
            t.add(f"{name} = {{ id = {i}, sign = 1, zero_offset_ticks = 2048, min_ticks = {tlo}, max_ticks = {thi} }}")
    return t


def rename_sites(line: str, renamed: dict[str, str]) -> str:
    for old, new in renamed.items():
        line = line.replace(f'"{old}"', f'"{new}"')
    return line
