"""Headless MP4 of a validation: the reference motion and the physics rollout side by side.

Left half: the trajectory as given (kinematic replay); right half: the physics rollout (or
the reference again, greyed label, when physics did not run).  Each half has its own camera
following its robot's root from the front-left.  A frame belongs to reference frame
``round(t * fps)``; when a check failed at that frame the picture gets a red border and a
red banner naming the failing checks; after a fall the physics half says so.

Rendering uses ``mujoco.Renderer`` with ``MUJOCO_GL=egl`` (set here unless already set) and
no shadows, reflections or multisampling (software EGL renders them slowly); frames go to ``libx264``
through imageio-ffmpeg.
"""

from __future__ import annotations

import copy
import os
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError


def _interp_qpos(qpos: np.ndarray, fps: float, t: float) -> np.ndarray:
    """qpos [nq] at time ``t`` from frames ``qpos`` [T, nq] (linear; quaternion normalised)."""
    x = min(max(t * fps, 0.0), qpos.shape[0] - 1)
    a = int(np.floor(x))
    b = min(a + 1, qpos.shape[0] - 1)
    w = x - a
    q = (1 - w) * qpos[a] + w * qpos[b]
    q[3:7] /= np.linalg.norm(q[3:7])
    return q


def failing_checks_per_frame(report: dict, num_frames: int) -> list[list[str]]:
    """For each reference frame, the names of the failed checks that list it."""
    names: list[list[str]] = [[] for _ in range(num_frames)]
    for name, check in report["checks"].items():
        if check["passed"]:
            continue
        for f in check["frames"]:
            if 0 <= f < num_frames:
                names[f].append(name)
    return names


def _font(size: int):
    from PIL import ImageFont

    try:
        return ImageFont.truetype("DejaVuSans.ttf", size)
    except OSError:
        return ImageFont.load_default()


def render_video(result, trajectory, path: str | Path, config=None) -> Path:
    """Write ``path`` (MP4) for ``result`` (:class:`~motok_robot.sim.validate.ValidationResult`)."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    import imageio.v2 as imageio
    import mujoco
    from PIL import Image, ImageDraw
    from tqdm import tqdm

    from motok_robot.sim.config import ValidationConfig

    config = config or ValidationConfig()
    index, roll, report = result.index, result.rollout, result.report
    width, height = int(config.render_width), int(config.render_height)
    half = width // 2
    model = copy.deepcopy(index.model)
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, half)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    model.vis.quality.offsamples = 0  # no multisampling: halves the cost of software EGL
    try:
        renderer = mujoco.Renderer(model, height=height, width=half)
    except Exception as exc:  # no GL context
        raise InputError(f"cannot render headless with MUJOCO_GL={os.environ.get('MUJOCO_GL')}: {exc} "
                         f"(use --no-render)") from None
    renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
    renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
    data = mujoco.MjData(model)
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    camera.distance = 2.4 * index.height_m
    camera.azimuth = 150.0
    camera.elevation = -12.0

    fps_ref = trajectory.fps
    duration = trajectory.duration_s
    n_out = int(np.floor(duration * config.render_fps)) + 1
    failing = failing_checks_per_frame(report, trajectory.num_frames)
    font, small = _font(max(12, height // 22)), _font(max(10, height // 28))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    writer = imageio.get_writer(str(path), fps=config.render_fps, codec="libx264", quality=6,
                                macro_block_size=8, ffmpeg_log_level="error")
    lookat = {}
    try:
        for k in tqdm(range(n_out), desc="render", unit="frame", disable=None, leave=False):
            t = k / config.render_fps
            frame = min(int(round(t * fps_ref)), trajectory.num_frames - 1)
            views = []
            sources = [("reference", _interp_qpos(trajectory.qpos, fps_ref, t))]
            if roll is not None:
                step = min(int(round(t / roll.timestep)), roll.step_qpos.shape[0] - 1)
                sources.append(("physics", roll.step_qpos[step]))
            else:
                sources.append(("reference (no physics)", sources[0][1]))
            for label, qpos in sources:
                data.qpos[:] = qpos
                mujoco.mj_kinematics(model, data)
                target = np.array([qpos[0], qpos[1], 0.5 * index.height_m])
                prev = lookat.get(label)
                lookat[label] = target if prev is None else prev + 0.2 * (target - prev)
                camera.lookat[:] = lookat[label]
                renderer.update_scene(data, camera)
                views.append(renderer.render())
            image = Image.fromarray(np.concatenate(views, axis=1))
            draw = ImageDraw.Draw(image)
            draw.text((8, 6), f"reference   t = {t:5.2f} s   frame {frame}", fill=(255, 255, 255), font=font)
            right = "physics rollout" if roll is not None else sources[1][0]
            if roll is not None and roll.fell and t >= roll.fall_time_s:
                right += f"  FELL at {roll.fall_time_s:.2f} s"
            draw.text((half + 8, 6), right, fill=(255, 120, 120) if "FELL" in right else (255, 255, 255), font=font)
            draw.line([(half, 0), (half, height)], fill=(0, 0, 0), width=2)
            if failing[frame]:
                border = 6
                draw.rectangle([0, 0, width - 1, height - 1], outline=(230, 20, 20), width=border)
                banner_h = max(18, height // 14)
                draw.rectangle([0, height - banner_h, width, height], fill=(200, 20, 20))
                draw.text((10, height - banner_h + 2), "FAIL: " + ", ".join(failing[frame]),
                          fill=(255, 255, 255), font=small)
            writer.append_data(np.asarray(image))
    finally:
        writer.close()
        renderer.close()
    return path
