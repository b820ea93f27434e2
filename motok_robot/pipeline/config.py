"""The settings of a :class:`~motok_robot.pipeline.Pipeline`: :class:`PipelineConfig`."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class PipelineConfig:
    """Settings of a :class:`Pipeline` (every default in one place).

    Attributes:
        planner: ``"masked"`` (default) or ``"ar"``.
        tokenizer_run, planner_run: run directories (None: ``models/tokenizer``,
            ``models/planner_<planner>``, see :mod:`motok_robot.planner.generate`).
        device: torch device of generation.
        generation: extra keyword arguments of ``MotionGenerator.generate`` (``cfg_scale``,
            ``steps``, ``decoder_steps``, ``decoder_seed``, ``temperature``, ``top_k``, ``top_p``).
        retarget: a :class:`retarget.config.RetargetConfig` (None: its defaults).
        validation: a :class:`motok_robot.sim.config.ValidationConfig` (None: its defaults).
        playback: a :class:`motok_robot.servo.config.PlaybackConfig` (None: the robot's bus
            rate and the defaults).
        plots: write the validation PNG plots.
        realtime: play dry-run and sim playback at the wall-clock rate (default: simulated time,
            which takes a fraction of a second; hardware always runs in real time).
        sim_video: with ``playback="sim"`` and ``render``, also record ``playback_sim.mp4`` (the
            simulated servo playback, ramp included; slow: about 10x the clip with software EGL).
        max_retime: when a speed check fails (:data:`SPEED_CHECKS`: the motion asks more
            torque, speed or acceleration than the servos have), play the robot trajectory up
            to this many times slower (:func:`retarget.retime.retime`, tried at
            :data:`RETIME_STEPS`) and keep the first timing whose speed checks all pass and that
            fails no check the original timing passed; the original timing is kept when none
            does.  Thresholds are never changed.  1.0 = never slow down.
        balance_zmp_weight: when a footing or balance check fails (:data:`BALANCE_CHECKS`:
            both feet in the air, ZMP or CoM outside the support, a fall, base drift) and
            retargeting ran without the ZMP term (``retarget.weights.zmp == 0``), retarget the
            motion again with this ZMP weight and a robot foot planted in every frame where no
            human foot is (contact support ``"always"``: a servo humanoid has no flight phase),
            and keep the new trajectory when the checks it fails, speed checks aside (retiming
            comes next), are a strict subset of those the first one failed; otherwise the first
            is kept.  Clips that pass (most gestures) never pay for the slower ZMP solve.  0 =
            never re-solve.
        feasibility: the feasibility stage's settings, to run it after retargeting
            (docs/feasibility.md): a :class:`motok_robot.feasibility.config.FeasibilityConfig`
            (used as it is) or a dict of settings applied over the robot's own
            (:func:`motok_robot.feasibility.config.robot_config`; ``{}``: the robot's): the robot trajectory
            becomes the one the robot executes closed loop, judged against the retargeted one,
            and the balance repair and the slow-down are not tried (the stage owns timing and
            balance).  None (default): retargeting's trajectory is validated as it is, with the
            two repairs below.
        walk_own_steps: with no ``feasibility`` given, a motion that travels (both feet cover
            more than half a leg length and neither rises high:
            :func:`motok_robot.feasibility.stage.walks`) goes through the feasibility stage with
            the robot's own steps along its path (the robot's settings with ``gait.enabled``) instead of the two
            repairs: the human's stride topples a small humanoid, its own steps do not
            (docs/feasibility.md).  Motions on the spot are validated as retargeted, with the
            repairs.  False: every motion is validated as retargeted.
        balance_acceleration_weight: the joint-acceleration weight (``CostWeights.acceleration``)
            of that re-solve.  The ZMP term rewards CoM accelerations that move the ZMP under the
            foot, and with the plain weight (5) the optimiser gets them from frame-to-frame
            zig-zags of the stance knee, which the servos cannot deliver (the torque check then
            fails); a stiffer weight makes it shift the CoM smoothly instead (docs/retarget.md,
            balance repair).
    """

    planner: str = "masked"
    tokenizer_run: str | Path | None = None
    planner_run: str | Path | None = None
    device: str = "cpu"
    generation: dict = field(default_factory=dict)
    retarget: object | None = None
    validation: object | None = None
    playback: object | None = None
    plots: bool = True
    realtime: bool = False
    sim_video: bool = False
    max_retime: float = 2.0
    balance_zmp_weight: float = 1000.0
    balance_acceleration_weight: float = 50.0
    feasibility: object | None = None
    walk_own_steps: bool = True
