"""The check image of a draft: front and side views of the nominal pose with every site labelled."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from motok_robot.robots.draft.drafter import Drafter
from motok_robot.robots.draft.result import DraftResult


def render_check_image(dr: Drafter, result: DraftResult, robot, path: Path, width: int = 640, height: int = 800) -> Path:
    """Front and side views of the nominal pose, robot see-through, every keypoint and sole site labelled."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    import mujoco

    from motok_robot.robots.render import render_pose, save_png

    if robot is not None:
        model = robot.model
        qpos = robot.nominal_qpos()
        target = robot
    else:  # the draft does not load yet: draw the copy at the zero pose
        model = mujoco.MjModel.from_xml_path(str(result.mjcf_path))
        qpos = model.qpos0.copy()
        qpos[2] = -min(z for _, _, z in dr.soles.values())

        class _Shim:
            name = dr.name

        target = _Shim()
        target.model = model
    mine = {s.name for s in dr.sites.values()}
    for s in range(model.nsite):
        n = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, s)
        model.site_group[s] = 4 if n in mine else 5
    width = min(width, model.vis.global_.offwidth)
    height = min(height, model.vis.global_.offheight)
    opt = mujoco.MjvOption()
    opt.sitegroup[:] = 0
    opt.sitegroup[4] = 1
    opt.label = mujoco.mjtLabel.mjLABEL_SITE
    opt.flags[mujoco.mjtVisFlag.mjVIS_TRANSPARENT] = 1
    d = mujoco.MjData(model)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(model, d)
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, n) for n in mine]
    pts = d.site_xpos[[i for i in ids if i >= 0]]
    centre = (pts.min(axis=0) + pts.max(axis=0)) / 2
    extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    views = []
    for azimuth in (180.0, 90.0):  # from the front (looking along -x), from the robot's right (along +y)
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = centre
        cam.distance = 1.25 * extent / math.tan(math.radians(model.vis.global_.fovy / 2)) / 2 + 0.1 * extent
        cam.azimuth = azimuth
        cam.elevation = -5.0
        views.append(render_pose(target, qpos, width=width, height=height, camera=cam, scene_option=opt))
    save_png(np.concatenate(views, axis=1), path)
    return path
