"""Stick-figure videos and summary plots of joint motions (matplotlib + imageio, no torch).

Input joints are ``[T, 22, 3]`` metres, z up, SMPL joint order, floor at ``z = 0``.
Rendering is headless (matplotlib's Agg canvas): the figure, axes and line artists are made
once and only their data change per frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.motion import skeleton

#: colours of the kinematic chains (right leg, left leg, spine, right arm, left arm):
#: right side red, left side blue, spine black
CHAIN_COLOURS = ("#d62728", "#1f77b4", "#222222", "#ff7f0e", "#17becf")
_PANEL_PX = 480  # panel size in pixels (a multiple of 16, as video encoders like)
_DPI = 100


def _as_motion(x, name: str) -> np.ndarray:
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a numeric array of shape [T, 22, 3]: {exc}") from None
    if arr.ndim != 3 or arr.shape[1:] != (skeleton.NUM_JOINTS, 3):
        raise InputError(f"{name} must have shape [T, {skeleton.NUM_JOINTS}, 3] (frames, joints, xyz metres); got shape {list(arr.shape)}")
    if arr.shape[0] < 1:
        raise InputError(f"{name} has 0 frames")
    bad = ~np.isfinite(arr)
    if bad.any():
        t, j, _ = np.argwhere(bad)[0]
        raise InputError(f"{name} contain NaN or inf at frame {t}, joint {j} ({skeleton.JOINT_NAMES[j]})")
    return arr


def _motions(joints) -> list[np.ndarray]:
    if isinstance(joints, np.ndarray) and joints.ndim == 3:
        return [_as_motion(joints, "joints")]
    if isinstance(joints, (list, tuple)):
        if not joints:
            raise InputError("joints: an empty list of motions was given")
        return [_as_motion(m, f"joints[{i}]") for i, m in enumerate(joints)]
    return [_as_motion(joints, "joints")]


def _output_path(out_path, allowed: tuple[str, ...]) -> Path:
    path = Path(out_path)
    if path.suffix.lower() not in allowed:
        raise InputError(f"{path}: the output must end in {' or '.join(allowed)}")
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    return path


def _figure(width_px: int, height_px: int):
    # an Agg canvas on a bare Figure: headless, and leaves pyplot's global backend alone
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_px / _DPI, height_px / _DPI), dpi=_DPI)
    FigureCanvasAgg(fig)
    return fig


def _view_half_size(motion: np.ndarray) -> float:
    """Half the side (m) of the cubic view that follows the body: fits the tallest pose."""
    height = float((motion[..., 2].max(axis=1) - np.minimum(motion[..., 2].min(axis=1), 0.0)).max())
    spread = float(np.abs(motion[..., :2] - motion[:, :1, :2]).max())
    return max(0.5 * height + 0.15, spread + 0.15, 0.9)


class _FloorGrid:
    """Grid lines on the floor (z = 0) of the current view, ``step`` metres apart; the line
    artists are made once and moved with the view."""

    def __init__(self, ax, half: float, step: float):
        self.step = float(step)
        self.half = half
        count = int(np.ceil(2 * half / self.step)) + 2
        style = dict(color="#c8c8c8", lw=0.6, zorder=0)
        self.x_lines = [ax.plot([], [], [], **style)[0] for _ in range(count)]
        self.y_lines = [ax.plot([], [], [], **style)[0] for _ in range(count)]

    def update(self, cx: float, cy: float) -> None:
        x0, x1, y0, y1 = cx - self.half, cx + self.half, cy - self.half, cy + self.half
        xs = np.arange(np.ceil(x0 / self.step) * self.step, x1 + 1e-9, self.step)
        ys = np.arange(np.ceil(y0 / self.step) * self.step, y1 + 1e-9, self.step)
        for i, line in enumerate(self.x_lines):
            if i < len(xs):
                line.set_data_3d([xs[i], xs[i]], [y0, y1], [0.0, 0.0])
            else:
                line.set_data_3d([], [], [])
        for i, line in enumerate(self.y_lines):
            if i < len(ys):
                line.set_data_3d([x0, x1], [ys[i], ys[i]], [0.0, 0.0])
            else:
                line.set_data_3d([], [], [])


def render_stick_figure(joints, out_path, fps: float = skeleton.FPS, title: str | None = None,
                        labels: Sequence[str] | None = None, trail: bool = True, floor: bool = True,
                        elevation: float = 20.0, azimuth: float = -60.0, grid_step: float = 0.5) -> Path:
    """Write a 3D stick-figure video of one motion or several side by side.

    Args:
        joints: ``[T, 22, 3]`` metres (z up), or a list of such motions (different lengths are
            fine: a shorter motion holds its last pose).
        out_path: ``.mp4`` (H.264 through imageio-ffmpeg) or ``.gif``.
        fps: playback rate, frames per second.
        title: text above the panels (the frame time is appended).
        labels: one caption per motion.
        trail: draw the root's ground path up to the current frame.
        floor: draw a grid on the floor (lines every ``grid_step`` metres, parallel to x and y).
        elevation, azimuth: camera angles in degrees (matplotlib's ``view_init``); the view
            follows the root horizontally and always shows the floor at ``z = 0``.
        grid_step: floor grid spacing, metres.

    Returns:
        the written path. The file has ``max(T)`` frames.
    """
    import imageio.v2 as imageio

    motions = _motions(joints)
    path = _output_path(out_path, (".mp4", ".gif"))
    if not np.isfinite(fps) or fps <= 0:
        raise InputError(f"fps must be positive; got {fps}")
    if labels is not None and len(labels) != len(motions):
        raise InputError(f"labels: {len(labels)} given for {len(motions)} motion(s)")
    n = len(motions)
    frames = max(len(m) for m in motions)
    fig = _figure(_PANEL_PX * n, _PANEL_PX)
    heading = fig.suptitle(title or "", fontsize=10)
    panels = []
    for i, motion in enumerate(motions):
        ax = fig.add_subplot(1, n, i + 1, projection="3d")
        ax.view_init(elev=elevation, azim=azimuth)
        half = _view_half_size(motion)
        ax.set_box_aspect((1, 1, 1))
        ax.set_axis_off()
        grid = _FloorGrid(ax, half, grid_step) if floor else None
        if labels is not None:
            ax.set_title(labels[i], fontsize=9)
        lines = [ax.plot([], [], [], color=CHAIN_COLOURS[c % len(CHAIN_COLOURS)], lw=2.5, marker="o", ms=2.5)[0]
                 for c in range(len(skeleton.KINEMATIC_CHAINS))]
        path_line = ax.plot([], [], [], color="#2ca02c", lw=1.2, axlim_clip=True)[0] if trail else None
        panels.append((ax, motion, half, grid, lines, path_line))
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=0.92, wspace=0.0)

    def draw(t: int) -> np.ndarray:
        for ax, motion, half, grid, lines, path_line in panels:
            k = min(t, len(motion) - 1)
            pose = motion[k]
            cx, cy = pose[0, :2]
            ax.set_xlim(cx - half, cx + half)
            ax.set_ylim(cy - half, cy + half)
            ax.set_zlim(0.0, 2.0 * half)
            if grid is not None:
                grid.update(cx, cy)
            for line, chain in zip(lines, skeleton.KINEMATIC_CHAINS):
                pts = pose[list(chain)]
                line.set_data_3d(pts[:, 0], pts[:, 1], pts[:, 2])
            if path_line is not None:
                root = motion[: k + 1, 0]
                path_line.set_data_3d(root[:, 0], root[:, 1], np.zeros(len(root)))
        heading.set_text(f"{title + '  ' if title else ''}t = {t / fps:5.2f} s  ({t + 1}/{frames})")
        fig.canvas.draw()
        return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()

    if path.suffix.lower() == ".mp4":
        writer = imageio.get_writer(path, format="FFMPEG", mode="I", fps=fps, codec="libx264",
                                    pixelformat="yuv420p", quality=7, macro_block_size=16)
    else:
        writer = imageio.get_writer(path, format="GIF", mode="I", duration=1000.0 / fps, loop=0)
    try:
        for t in range(frames):
            writer.append_data(draw(t))
    finally:
        writer.close()
    return path


def plot_motion_summary(joints, png_path, fps: float = skeleton.FPS, title: str | None = None,
                        contact_height: float = 0.05) -> Path:
    """Write a PNG with the top view of the root path and the foot heights over time.

    Left: root (pelvis) ground path (x, y in metres) with start and end marked and the facing
    direction every second. Right: heights (m) of the ankles and feet against time (s), with
    the ``contact_height`` line (the foot-skating protocol's contact threshold).
    """
    motion = _as_motion(joints, "joints")
    path = _output_path(png_path, (".png",))
    fig = _figure(1000, 420)
    ax_top, ax_feet = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    root = motion[:, 0]
    ax_top.plot(root[:, 0], root[:, 1], color="#2ca02c", lw=1.5, label="root path")
    ax_top.plot(*root[0, :2], "o", color="black", label="start")
    ax_top.plot(*root[-1, :2], "s", color="#d62728", label="end")
    step = max(int(round(fps)), 1)
    across = (motion[:, 2] - motion[:, 1]) + (motion[:, 17] - motion[:, 16])
    forward = np.stack([-across[:, 1], across[:, 0]], axis=-1)
    forward /= np.maximum(np.linalg.norm(forward, axis=-1, keepdims=True), 1e-9)
    idx = np.arange(0, len(motion), step)
    ax_top.quiver(root[idx, 0], root[idx, 1], forward[idx, 0], forward[idx, 1], angles="xy", scale_units="xy",
                  scale=4.0, width=0.004, color="#555555", label="facing (every 1 s)")
    ax_top.set_aspect("equal", adjustable="datalim")
    ax_top.set_xlabel("x (m)")
    ax_top.set_ylabel("y (m)")
    ax_top.set_title("root path, top view")
    ax_top.grid(alpha=0.3)
    ax_top.legend(fontsize=7, loc="best")
    time = np.arange(len(motion)) / fps
    for name, colour in (("left_ankle", "#1f77b4"), ("left_foot", "#17becf"), ("right_ankle", "#d62728"), ("right_foot", "#ff7f0e")):
        ax_feet.plot(time, motion[:, skeleton.JOINT_INDEX[name], 2], color=colour, lw=1.2, label=name)
    ax_feet.axhline(contact_height, color="#777777", ls="--", lw=1, label=f"{contact_height * 100:g} cm")
    ax_feet.axhline(0.0, color="black", lw=0.8)
    ax_feet.set_xlabel("time (s)")
    ax_feet.set_ylabel("height (m)")
    ax_feet.set_title("foot joint heights")
    ax_feet.grid(alpha=0.3)
    ax_feet.legend(fontsize=7, loc="upper right")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    return path
