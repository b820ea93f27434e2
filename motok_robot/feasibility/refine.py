"""Physics refinement of the servo goals: receding-horizon predictive sampling over rollouts.

The kinematic reference of a human walk is not dynamically consistent for a small robot: its
ZMP leaves the support polygon and the robot tips over within a second or two, with or
without the balance controller.  This module searches, as MuJoCo MPC's predictive sampling
does, for offsets to the servo goals that keep the robot on its feet while it does the motion.

Decision variables: offsets of the leg joints' goals at spline knots every ``knot_s``
(linear between knots), added to the warm start (the inverse-dynamics feedforward goals).
Every ``replan_s`` the planner rolls ``samples`` candidates out over ``horizon_s`` from the
current simulated state, with the balance controller in the loop (one batched controller for
all candidates): candidate 0 is the current plan, the others perturb the knots ahead of now
by Gaussian noise.  The cheapest candidate becomes the plan and its first ``replan_s`` is
executed on the main rollout; the goal frames that execution used are frozen.  At the end
every frame is frozen, so a rollout of the returned goals from the start (validation's)
reproduces the executed motion exactly (same physics, same controller, same ticks).

The search is greedy over a short horizon, so its plan can end costlier over the whole clip
than the warm start (on the robot's own walk of ``cmu_02_01``, with 0.02 rad of noise, it fell
where the warm start does not).  The warm start is rolled out over the same ticks; when it costs less, it is
returned unchanged and the record says ``"kept": "warm start"``.

Cost per tick, relative to the reference at that time (lengths divided by the robot's height):
torso attitude, base height, base position, sole positions (contact and foot placement),
joint angles, offset size, and a fixed cost per second fallen.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import mujoco
import numpy as np

from motok_robot.feasibility.balance import BalanceController, BalancePlan, leg_roles
from motok_robot.feasibility.config import RefineConfig
from motok_robot.feasibility.physics import ServoPhysics, execute


@dataclass
class Reference:
    """Per-frame reference quantities the cost compares with (frames at ``fps``)."""

    fps: float
    base: np.ndarray    # [T, 3] m
    up: np.ndarray      # [T, 3] torso up axis (world)
    soles: np.ndarray   # [T, 2, 3] m sole-centre sites
    joints: np.ndarray  # [T, nj] rad


def reference_of(index, qpos: np.ndarray, fps: float) -> Reference:
    model = index.kin_model
    data = mujoco.MjData(model)
    T = qpos.shape[0]
    up = np.zeros((T, 3))
    soles = np.zeros((T, 2, 3))
    for t in range(T):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        up[t] = data.xmat[index.root_body].reshape(3, 3)[:, 2]
        soles[t] = data.site_xpos[index.sole_site]
    return Reference(fps=float(fps), base=qpos[:, :3].copy(), up=up, soles=soles,
                     joints=qpos[:, index.qpos_adr].copy())


@dataclass
class RefineResult:
    goals: np.ndarray                 # [T, nj] refined servo goals
    offsets: np.ndarray               # [T, nj] refined minus warm-start goals (rad)
    executed_qpos: np.ndarray         # [T, nq] the main rollout at the frame times
    fell: bool                        # the main rollout fell (torso tilt beyond fall_tilt_rad)
    cost: float                       # total cost of the main rollout
    cost_start: float                 # cost of the warm start alone (same rollout length)
    planning_steps: int
    rollouts: int                     # candidate rollouts simulated
    wall_s: float
    config: RefineConfig = field(default_factory=RefineConfig)
    kept: str = "refined"             # "refined", or "warm start" when the search ended costlier
    cost_searched: float = float("nan")  # total cost of the searched plan, kept or not

    def record(self) -> dict:
        """What the stage changed, for report.json and summary.md."""
        moved = np.abs(self.offsets)
        return {"method": "predictive sampling", "kept": self.kept, "fell": self.fell, "cost": self.cost,
                "cost_searched": self.cost_searched, "cost_warm_start": self.cost_start,
                "planning_steps": self.planning_steps, "rollouts": self.rollouts, "wall_s": self.wall_s,
                "offset_rad_mean": float(moved.mean()), "offset_rad_max": float(moved.max()),
                "config": self.config.to_dict()}


class _Cost:
    """Accumulates the cost of B rollouts tick by tick (see the module docstring)."""

    def __init__(self, index, ref: Reference, config: RefineConfig, tick_s: float, height: float, batch: int):
        self.index, self.ref, self.config, self.tick_s = index, ref, config, tick_s
        self.scale = 1.0 / max(height, 1e-3) ** 2
        self.total = np.zeros(batch)
        self.fallen = np.zeros(batch, dtype=bool)

    def __call__(self, tick: int, datas: list) -> None:
        ref, cfg, idx = self.ref, self.config, self.index
        i = int(min(round((tick + 1) * self.tick_s * ref.fps), ref.base.shape[0] - 1))
        for b, data in enumerate(datas):
            up = data.xmat[idx.root_body].reshape(3, 3)[:, 2]
            tilt = float(np.arccos(np.clip(up @ ref.up[i], -1.0, 1.0)))
            base = data.qpos[:3]
            soles = data.site_xpos[idx.sole_site]
            q = data.qpos[idx.qpos_adr]
            c = (cfg.w_tilt * tilt ** 2
                 + self.scale * (cfg.w_height * (base[2] - ref.base[i, 2]) ** 2
                                 + cfg.w_base * float(((base[:2] - ref.base[i, :2]) ** 2).sum())
                                 + cfg.w_feet * float(((soles - ref.soles[i]) ** 2).sum()))
                 + cfg.w_joints * float(((q - ref.joints[i]) ** 2).mean()))
            if tilt > cfg.fall_tilt_rad:
                self.fallen[b] = True
            if self.fallen[b]:
                c += cfg.fall_cost
            self.total[b] += c * self.tick_s


def refine_goals(index, qpos: np.ndarray, fps: float, goals: np.ndarray, plan: BalancePlan | None,
                 config: RefineConfig | None = None, timestep_s: float = 0.0, initial_qvel: np.ndarray | None = None,
                 progress=None) -> RefineResult:
    """Refined servo goals [T, nj] for the reference ``qpos`` [T, nq] at ``fps``, warm-started
    from ``goals`` [T, nj], with the balance controller of ``plan`` in the loop (None: open loop).
    ``progress(done_s, total_s)`` is called after each planning step."""
    start = time.perf_counter()
    config = config or RefineConfig()
    rng = np.random.default_rng(config.seed)
    qpos = np.asarray(qpos, dtype=np.float64)
    goals = np.asarray(goals, dtype=np.float64)
    T, nj = goals.shape
    physics = ServoPhysics(index, timestep_s=timestep_s, rate_hz=plan.config.rate_hz if plan else 125.0)
    ref = reference_of(index, qpos, fps)
    duration = (T - 1) / fps
    nticks = max(1, int(round(duration / physics.tick_s)))
    replan = max(1, int(round(config.replan_s / physics.tick_s)))
    horizon = max(replan, int(round(config.horizon_s / physics.tick_s)))
    role, _ = leg_roles(index)
    if config.joints == "all":
        selected = np.arange(nj)
    else:
        yaw = [j for j, n in enumerate(index.joint_names) if "hip_yaw" in n]
        selected = np.unique(np.concatenate([np.nonzero(role >= 0)[0], np.asarray(yaw, dtype=int)]))
    knot_time = np.arange(0.0, duration + config.knot_s, config.knot_s)
    frame_time = np.arange(T) / fps
    knots = np.zeros((knot_time.size, selected.size))
    low, high = index.joint_range[:, 0], index.joint_range[:, 1]
    frozen = np.zeros(T, dtype=bool)
    frozen_goals = goals.copy()

    def frame_goals(candidates: np.ndarray) -> np.ndarray:  # [K, nknots, ns] -> [K, T, nj]
        K = candidates.shape[0]
        offset = np.stack([np.stack([np.interp(frame_time, knot_time, candidates[k, :, s])
                                     for s in range(selected.size)], axis=1) for k in range(K)])
        out = np.broadcast_to(goals, (K, T, nj)).copy()
        out[:, :, selected] += offset
        out = np.clip(out, low, high)
        out[:, frozen] = frozen_goals[frozen]
        return out

    qvel0 = np.zeros(index.model.nv) if initial_qvel is None else initial_qvel
    initial = physics.initial_state(qpos[0], qvel0, goals[0])
    main = physics.new_datas(initial[None])
    controller = BalanceController(plan, index.joint_range) if plan is not None else None
    pool = physics.new_datas(np.repeat(initial[None], config.samples, axis=0))
    main_cost = _Cost(index, ref, config, physics.tick_s, index.height_m, 1)
    steps = rollouts = 0
    tick0 = 0
    last_command = None  # playback's limiter state: the last goal sent
    while tick0 < nticks:
        H = min(horizon, nticks - tick0)
        # a knot is free while it still shapes a goal frame no executed tick has used
        pending = np.nonzero(~frozen)[0]
        first_open = frame_time[pending[0]] if pending.size else np.inf
        free = knot_time > first_open - config.knot_s + 1e-9
        candidates = np.repeat(knots[None], config.samples, axis=0)
        noise = rng.normal(0.0, config.noise_rad, size=candidates.shape)
        noise[0] = 0.0
        noise[:, ~free] = 0.0
        candidates = np.clip(candidates + noise, -config.max_offset_rad, config.max_offset_rad)
        trial = frame_goals(candidates)
        if config.samples > 1:
            physics.set_states(pool, np.repeat(physics.get_states(main), config.samples, axis=0))
            cost = _Cost(index, ref, config, physics.tick_s, index.height_m, config.samples)
            cost.fallen[:] = main_cost.fallen[0]
            physics.advance(pool, trial, fps, tick0, H, controller.clone(config.samples) if controller else None,
                            on_tick=cost, previous=last_command)
            best = int(np.argmin(cost.total))
            rollouts += config.samples
        else:
            best = 0
        knots = candidates[best]
        n = min(replan, nticks - tick0)
        chosen = trial[best]
        sent = physics.advance(main, chosen[None], fps, tick0, n, controller, on_tick=main_cost, previous=last_command)
        last_command = sent[:, -1]
        # freeze every goal frame the executed ticks interpolated between
        last = int(np.ceil(min((tick0 + n) * physics.tick_s * fps, T - 1)))
        newly = ~frozen & (np.arange(T) <= last)
        frozen_goals[newly] = chosen[newly]
        frozen |= newly
        tick0 += n
        steps += 1
        if progress is not None:
            progress(tick0 * physics.tick_s, nticks * physics.tick_s)
    frozen_goals[~frozen] = goals[~frozen]
    # the warm start's own cost over the same ticks: the search is greedy over a short horizon,
    # so its plan can end worse than where it started; then the warm start is kept
    warm = physics.new_datas(initial[None])
    warm_cost = _Cost(index, ref, config, physics.tick_s, index.height_m, 1)
    physics.advance(warm, goals[None], fps, 0, nticks,
                    BalanceController(plan, index.joint_range) if plan is not None else None, on_tick=warm_cost)
    kept = "refined" if main_cost.total[0] <= warm_cost.total[0] else "warm start"
    chosen = frozen_goals if kept == "refined" else goals
    executed, _ = execute(index, qpos[0], chosen, fps, plan, timestep_s, qvel0)
    chosen_cost = main_cost if kept == "refined" else warm_cost
    return RefineResult(goals=chosen, offsets=chosen - goals, executed_qpos=executed,
                        fell=bool(chosen_cost.fallen[0]), cost=float(chosen_cost.total[0]), cost_start=float(warm_cost.total[0]),
                        planning_steps=steps, rollouts=rollouts, wall_s=time.perf_counter() - start, config=config,
                        kept=kept, cost_searched=float(main_cost.total[0]))
