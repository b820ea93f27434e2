"""A one-page PNG of a retargeting result (matplotlib, headless).

Panels: side view (x-z) of the scaled human targets and the robot keypoint sites at a few
frames; sole heights over time with the detected contact phases shaded; keypoint error over
time; two joint trajectories (the knees), optionally against the per-frame baseline.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from retarget.contacts import contact_phases
from retarget.metrics import sole_points


def plot_result(path: str | Path, kin, result, baseline=None, title: str | None = None) -> Path:
    """Write the PNG; ``result`` / ``baseline``: :class:`retarget.solve.RetargetResult`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    T = len(result.x)
    t = np.arange(T) / result.fps
    K = len(result.keypoint_names)
    kp = np.array(kin.frame.map(T)(result.x.T)[0]).reshape(3, K, T, order="F").transpose(2, 1, 0)
    idx = list(range(K))
    from motok_robot.motion.skeleton import JOINT_INDEX

    tgt = result.targets.joints[:, [JOINT_INDEX[n] for n in result.keypoint_names]]
    site, corners = sole_points(kin, result.x)

    fig, axes = plt.subplots(2, 2, figsize=(13, 8))
    ax = axes[0, 0]
    for f in np.linspace(0, T - 1, min(6, T)).astype(int):
        ax.scatter(tgt[f, idx, 0], tgt[f, idx, 2], s=12, c="tab:orange", alpha=0.8)
        ax.scatter(kp[f, idx, 0], kp[f, idx, 2], s=12, c="tab:blue", alpha=0.8)
        for a, b in zip(tgt[f], kp[f]):
            ax.plot([a[0], b[0]], [a[2], b[2]], c="0.6", lw=0.5)
    ax.scatter([], [], c="tab:orange", label="scaled human targets")
    ax.scatter([], [], c="tab:blue", label="robot keypoint sites")
    ax.axhline(0.0, c="k", lw=0.8)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_title("side view, 6 frames")
    ax.legend(loc="upper left", fontsize=8)

    ax = axes[0, 1]
    for s, (side, col) in enumerate((("left", "tab:red"), ("right", "tab:green"))):
        ax.plot(t, corners[:, s, :, 2].min(axis=1) * 1000, c=col, label=f"{side} sole, lowest corner")
        for a, b in contact_phases(result.contacts[:, s]):
            ax.axvspan(t[a], t[b - 1], color=col, alpha=0.12)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("height (mm)")
    ax.set_title("sole height (shaded: detected contact phases)")
    ax.legend(fontsize=8)

    ax = axes[1, 0]
    ax.plot(t, result.keypoint_error.mean(axis=1) * 100, label=f"trajectory ({result.keypoint_error.mean() * 100:.2f} cm)")
    if baseline is not None:
        ax.plot(t, baseline.keypoint_error.mean(axis=1) * 100, label=f"per-frame ({baseline.keypoint_error.mean() * 100:.2f} cm)", alpha=0.8)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("mean keypoint error (cm)")
    ax.legend(fontsize=8)

    ax = axes[1, 1]
    names = [n for n in result.joint_names if "knee" in n][:2] or result.joint_names[:2]
    for n in names:
        j = result.joint_names.index(n)
        line = ax.plot(t, result.x[:, 6 + j], label=f"{n} trajectory")[0]
        if baseline is not None:
            ax.plot(t, baseline.x[:, 6 + j], ls="--", c=line.get_color(), alpha=0.7, label=f"{n} per-frame")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("angle (rad)")
    ax.legend(fontsize=8)
    fig.suptitle(title or f"{result.robot}: {T} frames at {result.fps:g} fps")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
