"""Draft a robot description (``NAME.toml``) for an unknown humanoid from its MJCF alone.

``motok-robot robots add MJCF --out NAME.toml`` (see ``docs/robots.md``, "Adding a robot").
What is inferred, and how (all measured on the compiled model at its zero pose, in the frame of
the free base body, which must face +x with +y to its left and +z up):

* **free base**: the body carrying the free joint; it is the ``torso_body``.
* **feet**: the body with the lowest collision geom on each side (``y > 0`` left, ``y < 0``
  right); they must hang from two different chains. The legs are the paths from the feet's common
  ancestor (the pelvis) down to them; the arms end in the deepest (most hinges from the base)
  other body on each side, and the head is the highest remaining body.
* **joint groups**: along a chain, consecutive hinges whose axes (nearly) meet form one group
  (hip pitch, roll and yaw; shoulder pitch, roll and the upper-arm twist; ankle pitch and roll);
  a group's centre is the point nearest to all its axes. Hips, knees, ankles, shoulders, elbows
  and wrists are the centres of the 1st, 2nd and last groups of a leg, and of the 1st, 2nd and 3rd
  groups of an arm; the neck is the anchor of the first head joint, the head the centre of the
  head body's geoms, the pelvis the middle of the hips, the chest on the pelvis-neck line at the
  canonical human's ratio.
* **soles**: the lowest faces of each foot's collision geoms (box corners, sphere bottoms,
  cylinder rims, mesh vertices within 2 mm of the lowest point): their bounding rectangle gives
  the sole centre and 4 corner sites and ``half_size``; the toe keypoint sits 0.7 of the half
  length ahead of the sole centre.
* **limb scales**: robot chain length / canonical human length (``skeleton.rest_pose()``).
* **nominal pose**: a knee bend (``knee_bend`` rad, default 0.4) with hip and ankle pitch solved
  so the ankles stay under the hips and the soles flat; arms lowered to hang 0.15 rad from the
  body when the zero pose holds them out.
* **limits**: joint ranges and torque limits are the MJCF's (listed in the TOML's comments); the
  MJCF holds no joint speeds, so ``[velocity_limits]`` is a placeholder (or, for robots whose
  actuators look like Dynamixel position servos, the servo datasheet's no-load speed).

Sites the description needs and the MJCF lacks go into a copy of the MJCF (``NAME.xml`` beside
the TOML; the user's file is never written), together with what loading and rendering need
(a ``floor`` plane, a ``track`` camera, an offscreen buffer, joint ranges from the actuators'
``ctrlrange`` where a hinge has none). Everything the draft could not infer comes back as
:class:`Unsure` entries naming the file and line to edit. No torch; mujoco is imported lazily.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.robots.draft.body import GROUP_TOL, SOLE_TOL
from motok_robot.robots.draft.check_image import render_check_image
from motok_robot.robots.draft.drafter import Drafter
from motok_robot.robots.draft.mjcf_copy import parse_xml, write_copy
from motok_robot.robots.draft.model import MjcfModel
from motok_robot.robots.draft.pose import ARM_HANG, KNEE_BEND
from motok_robot.robots.draft.result import DraftResult, Unsure
from motok_robot.robots.draft.toml_text import VELOCITY_PLACEHOLDER, rename_sites, toml_text

__all__ = ["ARM_HANG", "GROUP_TOL", "KNEE_BEND", "SOLE_TOL", "VELOCITY_PLACEHOLDER", "DraftResult", "Unsure", "draft",
           "render_check_image"]


def _existing_site(M: MjcfModel, name: str):
    sid = M.mj.mj_name2id(M.m, M.mj.mjtObj.mjOBJ_SITE, name)
    return sid if sid >= 0 else None


def draft(mjcf: str | os.PathLike, out: str | os.PathLike, name: str | None = None, knee_bend: float = KNEE_BEND,
          render: str | os.PathLike | None = "", force: bool = False) -> DraftResult:
    """Draft ``out`` (NAME.toml) for the robot in ``mjcf``; see the module docstring.

    ``render``: the check image (default ``NAME.png`` beside the TOML; None: no image).
    Raises :class:`InputError` (one line naming the file) for an unusable MJCF.
    """
    src = Path(mjcf).expanduser()
    if not src.is_file():
        raise InputError(f"{src}: MJCF file not found")
    out = Path(out).expanduser()
    if out.suffix != ".toml":
        raise InputError(f"--out must name a .toml file, got {out.name}")
    name = name or out.stem
    out_xml = out.with_suffix(".xml")
    image = None if render is None else Path(render) if render else out.with_suffix(".png")
    if out_xml.resolve() == src.resolve():
        raise InputError(f"{out.name}: the MJCF copy would overwrite the input {src} itself; choose another --out name")
    if not force:
        for p in (out, out_xml, image):
            if p is not None and p.exists():
                raise InputError(f"{p}: exists; pass --force to overwrite the draft")
    parse_xml(src)  # XML errors first, as one line

    dr = Drafter(src, name, knee_bend)
    dr.analyse()
    dr.place_sites()
    rows = dr.joint_limits()
    dr.fill_missing_ranges(rows)
    M = dr.M

    # which sites the MJCF already has (same name, same place) and which the copy must add
    need = []
    for s in list(dr.sites.values()):
        sid = _existing_site(M, s.name)
        if sid is not None:
            if np.linalg.norm(M.d.site_xpos[sid] - s.pos) < 0.005 and (
                    M.m.site_bodyid[sid] in M.ancestors(s.body) or s.body in M.ancestors(M.m.site_bodyid[sid])):
                continue  # the model's own site, at the same place on the same chain
            s.name = f"mk_{s.name}"
        need.append(s)
    dr.renamed = {s.name[3:]: s.name for s in need if s.name.startswith("mk_")}
    floor = M.mj.mj_name2id(M.m, M.mj.mjtObj.mjOBJ_GEOM, "floor")
    add_floor = floor < 0
    add_camera = M.mj.mj_name2id(M.m, M.mj.mjtObj.mjOBJ_CAMERA, "track") < 0
    small_buffer = M.m.vis.global_.offwidth < 1280 or M.m.vis.global_.offheight < 960
    copied = bool(need or dr.added_ranges or add_floor or add_camera or small_buffer)

    nominal = dr.nominal_pose()
    scales = dr.limb_scales()
    servo = dr.servo_guess(rows)
    out.parent.mkdir(parents=True, exist_ok=True)
    if copied:
        added = write_copy(dr, out_xml, need, add_floor, add_camera)
        mjcf_ref = out_xml.name
    else:
        added = []
        mjcf_ref = Path(os.path.relpath(src.resolve(), out.parent.resolve())).as_posix()
    toml = toml_text(dr, mjcf_ref, nominal, rows, servo, scales)
    if dr.renamed:
        toml.lines = [rename_sites(line, dr.renamed) for line in toml.lines]
    out.write_text(toml.text())

    # what was inferred
    summary = [f"free base {M.body_name(M.base)!r} (torso_body); {len(M.hinges)} hinges; "
               f"{M.m.body_subtreemass[0]:.2f} kg; height {dr.height():.3f} m"]
    for side, (chain, groups) in dr.legs.items():
        summary.append(f"{side} leg: {' -> '.join(M.body_name(b) for b in chain)}; groups "
                       + " | ".join(",".join(M.joint_name(j) for j in g.joints) for g in groups))
    for side, (chain, groups) in dr.arms.items():
        summary.append(f"{side} arm: {' -> '.join(M.body_name(b) for b in chain)}; groups "
                       + " | ".join(",".join(M.joint_name(j) for j in g.joints) for g in groups))
    summary += dr.summary
    for side, (foot, half, z) in dr.soles.items():
        summary.append(f"{side} sole: {M.body_name(foot)}, {2 * half[0]:.3f} x {2 * half[1]:.3f} m ({dr.sole_kind})")
    summary.append("limb scale: " + ", ".join(f"{k} {v[0]:.3f}" for k, v in scales.items()))
    summary.append("nominal pose: " + (", ".join(f"{k} {v:g}" for k, v in nominal.items()) or "zero pose"))
    summary.append(f"servo map: {'draft, ' + servo[0].model + ' (VERIFY)' if servo else 'none (not Dynamixel-like)'}")
    if copied:
        summary.append(f"MJCF copy {out_xml.name}: added {', '.join(added)}")

    # what it could not infer
    unsure: list[Unsure] = []
    xml_lines = out_xml.read_text().splitlines() if copied else []

    def xml_line(marker: str):
        for i, line in enumerate(xml_lines, 1):
            if marker in line:
                return i, line
        return None, marker

    for s in dr.sites.values():
        if s.note:
            ln, text = xml_line(f'name="{s.name}"')
            unsure.append(Unsure(s.note, out_xml.name if copied else src.name, ln, text))
    for what, marker in dr.unsure_xml:
        ln, text = xml_line(marker)
        unsure.append(Unsure(what, out_xml.name, ln, text))
    for what, marker in dr.unsure_toml:
        ln = toml.line_of(marker)
        unsure.append(Unsure(what, out.name, ln, toml.lines[ln - 1] if ln else marker))
    for note in dr.nominal_notes:
        ln = toml.line_of("[nominal_pose]")
        unsure.append(Unsure(note + "; set the nominal angles by hand", out.name, ln, "[nominal_pose]"))
    for j, jname, lo, hi, tq, acts in rows:
        if tq is None:
            ln, text = xml_line(f'name="{jname}"') if copied else (None, f'<joint name="{jname}"')
            unsure.append(Unsure(f"joint {jname!r} has no torque limit: add actuatorfrcrange=\"-T T\" (N m) to it",
                                 out_xml.name if copied else src.name, ln, text))
        if not acts:
            unsure.append(Unsure(f"joint {jname!r} has no actuator: add one (<position joint=\"{jname}\" .../>)",
                                 out_xml.name if copied else src.name, None, f"<actuator> ... {jname}"))
    if servo is None:
        ln = toml.line_of("default = ")
        unsure.append(Unsure("joint speeds are not in the MJCF: a placeholder velocity limit (rad/s) for every joint; "
                             "put the motors' figures (per joint: JOINT = rad/s)", out.name, ln, toml.lines[ln - 1]))
    else:
        for key in ("baud = ", "[servos]"):
            ln = toml.line_of(key)
            what = ("the bus settings are guesses (protocol, baud, control rate)" if key.startswith("baud")
                    else "servo IDs, signs, zero offsets and the servo model are guesses: verify each on the robot")
            unsure.append(Unsure(what, out.name, ln, toml.lines[ln - 1]))

    result = DraftResult(out, out_xml if copied else src, copied, None, summary, unsure)
    # does it load?
    robot = None
    try:
        from motok_robot.robots import load

        robot = load(out)
    except InputError as exc:
        result.load_error = str(exc)
    if image is not None:
        try:
            result.image_path = render_check_image(dr, result, robot, image)
        except InputError as exc:  # no GL context: the draft is still written
            result.summary.append(f"no check image: {exc} (set MUJOCO_GL=egl before running motok-robot)")
    return result
