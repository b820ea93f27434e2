"""PNG plots of a validation (matplotlib, Agg backend, no display needed).

:func:`save_plots` writes into a folder:

* ``balance_topview.png``: top view (x, y in m) of the support polygons (shaded, darker where
  feet stay longer), the CoM ground projection and the ZMP paths, ZMP samples outside the
  polygon in red, and the simulated centre of pressure when physics ran;
* ``feet.png``: per foot, lowest sole height (m) and horizontal sole speed (m/s) over time,
  contact frames shaded, skating frames in red, thresholds dashed;
* ``joints.png``: every joint's angle (rad) against its range (grey band = allowed), the
  simulated angle when physics ran, samples beyond the range by more than the ``joint_limits``
  check's tolerance in red (what that check counts), joints parked at a limit (the report's
  notes) titled in orange;
* ``torques.png``: every joint's required torque (N m) against +-its actuator force limit.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from motok_robot.sim.notes import PARKED_FRACTION


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[(start, end_exclusive)] of the True runs of a 1-D bool array."""
    padded = np.concatenate([[False], mask.astype(bool), [False]])
    edges = np.flatnonzero(np.diff(padded.astype(int)))
    return list(zip(edges[::2], edges[1::2]))


def save_plots(result, out_dir: str | Path) -> list[Path]:
    """Write the four PNGs of ``result`` (:class:`~motok_robot.sim.validate.ValidationResult`)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    plt = _pyplot()
    paths = [plot_balance(result, out_dir / "balance_topview.png", plt),
             plot_feet(result, out_dir / "feet.png", plt),
             plot_joints(result, out_dir / "joints.png", plt),
             plot_torques(result, out_dir / "torques.png", plt)]
    return paths


def _title(result, what: str) -> str:
    report = result.report
    status = "PASS" if report["passed"] else "FAIL: " + ", ".join(report["failed_checks"])
    return f"{Path(report['input']['path']).name} on {report['robot']} - {what}\n{status}"


def plot_balance(result, path: Path, plt) -> Path:
    kin, roll = result.kinematic, result.rollout
    cfg = result.report["config"]
    fig, ax = plt.subplots(figsize=(8, 7))
    from matplotlib.patches import Polygon

    seen = set()
    for hull in kin.support:  # each distinct support polygon once (a planted stance repeats)
        if len(hull) < 3:
            continue
        key = tuple(np.round(hull, 3).ravel())
        if key in seen:
            continue
        seen.add(key)
        ax.add_patch(Polygon(hull, closed=True, facecolor="tab:green", edgecolor="darkgreen", lw=0.5, alpha=0.12))
    ax.plot(kin.com[:, 0], kin.com[:, 1], color="tab:blue", lw=1.8, label="CoM ground projection")
    ax.plot(kin.zmp[:, 0], kin.zmp[:, 1], color="tab:orange", lw=1.0, alpha=0.9, label=f"ZMP ({cfg['zmp_model']})")
    outside = np.isfinite(kin.zmp_margin) & (kin.zmp_margin < -cfg["zmp_tolerance_m"])
    if outside.any():
        ax.scatter(kin.zmp[outside, 0], kin.zmp[outside, 1], s=14, color="red", zorder=5, label="ZMP outside support")
    static_bad = np.isfinite(kin.balance_margin) & kin.quasi_static & (kin.balance_margin < cfg["min_balance_margin_m"])
    if static_bad.any():
        ax.scatter(kin.com[static_bad, 0], kin.com[static_bad, 1], s=18, marker="x", color="darkred", zorder=6,
                   label="CoM outside (quasi-static)")
    if roll is not None:
        keep = np.isfinite(roll.cop).all(axis=1)
        if roll.fell:
            keep &= roll.cop_time < roll.fall_time_s
        if keep.any():
            ax.plot(roll.cop[keep, 0], roll.cop[keep, 1], ".", ms=3, color="tab:purple", alpha=0.7,
                    label="CoP (physics, before any fall)")
    ax.plot([], [], color="tab:green", lw=6, alpha=0.3, label=f"support polygons ({len(seen)} distinct)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(_title(result, "balance (top view)"), fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_feet(result, path: Path, plt) -> Path:
    kin = result.kinematic
    cfg = result.report["config"]
    fig, axes = plt.subplots(2, 2, figsize=(12, 6), sharex=True)
    for s, side in enumerate(("left", "right")):
        for row, (values, label, threshold) in enumerate((
                (kin.sole_height[:, s] * 100, "lowest sole point (cm)", cfg["contact_height_m"] * 100),
                (kin.sole_speed[:, s], "horizontal sole speed (m/s)", cfg["skate_speed_mps"]))):
            ax = axes[row, s]
            for a, b in _runs(kin.contact[:, s]):
                ax.axvspan(kin.time[a] - 0.5 / kin.fps, kin.time[b - 1] + 0.5 / kin.fps, color="tab:green", alpha=0.15, lw=0)
            ax.plot(kin.time, values, color="black", lw=1.2)
            skating = kin.skating[:, s]
            if skating.any():
                ax.scatter(kin.time[skating], values[skating], color="red", s=12, zorder=5, label="skating")
                ax.legend(fontsize=8, loc="upper right")
            ax.axhline(threshold, color="tab:red", ls="--", lw=0.8)
            if row == 0:
                ax.axhline(0.0, color="grey", lw=0.8)
                ax.axhline(-cfg["max_penetration_m"] * 100, color="tab:red", ls=":", lw=0.8)
                ax.set_title(f"{side} foot (green: contact)", fontsize=9)
            ax.set_ylabel(label, fontsize=8)
            ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("time (s)")
    fig.suptitle(_title(result, "feet"), fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _joint_grid(n: int, plt):
    cols = 5 if n > 16 else 4
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 1.9 * rows + 0.8), sharex=True, squeeze=False)
    for k in range(n, rows * cols):
        axes.flat[k].axis("off")
    return fig, axes


def plot_joints(result, path: Path, plt) -> Path:
    kin, roll, index = result.kinematic, result.rollout, result.index
    tolerance = float(result.report["config"]["joint_limit_tolerance_rad"])
    fig, axes = _joint_grid(index.nj, plt)
    for j, name in enumerate(index.joint_names):
        ax = axes.flat[j]
        low, high = index.joint_range[j]
        ax.axhspan(low, high, color="grey", alpha=0.15, lw=0)
        ax.axhline(low, color="grey", lw=0.6)
        ax.axhline(high, color="grey", lw=0.6)
        ax.plot(kin.time, kin.joint_pos[:, j], color="tab:blue", lw=1.2, label="reference")
        if roll is not None:
            ax.plot(kin.time, roll.qpos[:, index.qpos_adr[j]], color="tab:orange", lw=1.0, label="physics")
        # beyond the range by more than the joint_limits check's tolerance: what that check counts
        bad = (kin.joint_pos[:, j] < low - tolerance) | (kin.joint_pos[:, j] > high + tolerance)
        if bad.any():
            ax.scatter(kin.time[bad], kin.joint_pos[bad, j], s=8, color="red", zorder=5)
        vel_bad = np.abs(kin.joint_vel[:, j]) > index.velocity_limit[j]
        if vel_bad.any():
            ax.scatter(kin.time[vel_bad], kin.joint_pos[vel_bad, j], s=8, marker="^", color="magenta", zorder=5)
        entry = result.report.get("per_joint", {}).get(name, {})
        at_limit = entry.get("at_limit_ratio") or 0.0
        parked = at_limit > PARKED_FRACTION
        ax.set_title(name + (f" (at {entry['at_limit']} limit {at_limit:.0%})" if parked else ""), fontsize=8,
                     color="darkorange" if parked else "black")
        ax.tick_params(labelsize=7)
    axes.flat[0].legend(fontsize=6, loc="best")
    fig.suptitle(_title(result, f"joint angles (rad) vs range; red: beyond range by more than {tolerance:g} rad "
                                "(the joint_limits check), magenta: over velocity limit, orange title: parked at a "
                                "limit"), fontsize=9)
    fig.subplots_adjust(left=0.05, right=0.99, bottom=0.06, top=0.9, hspace=0.45, wspace=0.25)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_torques(result, path: Path, plt) -> Path:
    kin, index = result.kinematic, result.index
    fig, axes = _joint_grid(index.nj, plt)
    for j, name in enumerate(index.joint_names):
        ax = axes.flat[j]
        limit = index.torque_limit[j]
        ax.axhspan(-limit, limit, color="grey", alpha=0.15, lw=0)
        ax.axhline(limit, color="tab:red", ls="--", lw=0.7)
        ax.axhline(-limit, color="tab:red", ls="--", lw=0.7)
        ax.plot(kin.time, kin.torque[:, j], color="black", lw=1.0)
        bad = np.abs(kin.torque[:, j]) > limit
        if bad.any():
            ax.scatter(kin.time[bad], kin.torque[bad, j], s=8, color="red", zorder=5)
        ax.set_title(f"{name} (limit {limit:g} N m)", fontsize=8)
        ax.tick_params(labelsize=7)
    fig.suptitle(_title(result, "required torque (N m, inverse dynamics) vs actuator limit"), fontsize=9)
    fig.subplots_adjust(left=0.05, right=0.99, bottom=0.06, top=0.9, hspace=0.45, wspace=0.25)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
