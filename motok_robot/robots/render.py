"""Headless pictures of a robot pose (EGL by default; set MUJOCO_GL to change the backend)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError


def render_pose(robot, qpos: np.ndarray, width: int = 640, height: int = 800, camera="track",
                scene_option=None) -> np.ndarray:
    """Draw ``robot`` at ``qpos[nq]`` from the model's camera ``camera``; returns RGB uint8 ``[height, width, 3]``.

    ``camera``: a camera name of the model, or a ``mujoco.MjvCamera`` (e.g. a free camera);
    ``scene_option``: an optional ``mujoco.MjvOption`` (site groups, labels, transparency).
    The model's offscreen buffer limits the size (``<visual><global offwidth offheight>``).
    """
    os.environ.setdefault("MUJOCO_GL", "egl")
    import mujoco

    m = robot.model
    if width > m.vis.global_.offwidth or height > m.vis.global_.offheight:
        raise InputError(
            f"render size {width}x{height} exceeds the model's offscreen buffer "
            f"{m.vis.global_.offwidth}x{m.vis.global_.offheight}"
        )
    if isinstance(camera, mujoco.MjvCamera):
        cam_id = camera
    else:
        cam_id = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if cam_id < 0:
            raise InputError(f"robot {robot.name!r} has no camera {camera!r}")
    d = mujoco.MjData(m)
    d.qpos[:] = np.asarray(qpos, dtype=np.float64).reshape(m.nq)
    mujoco.mj_forward(m, d)
    try:
        renderer = mujoco.Renderer(m, height=height, width=width)
    except Exception as exc:  # no GL context (no EGL / display)
        raise InputError(f"cannot render headless with MUJOCO_GL={os.environ.get('MUJOCO_GL')}: {exc}") from None
    try:
        renderer.update_scene(d, camera=cam_id, scene_option=scene_option)
        return renderer.render().copy()
    finally:
        renderer.close()


def save_png(image: np.ndarray, path: str | os.PathLike) -> Path:
    """Write an RGB uint8 image ``[H, W, 3]`` as PNG (creating the folder)."""
    import imageio.v3 as iio

    path = Path(path)
    if path.suffix.lower() != ".png":
        raise InputError(f"render file must end in .png, got {path.name}")
    path.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(path, image)
    return path
