"""Constrained text-to-motion: the coarse path (planner) and the fine path (decoder) together.

``generate_motion`` is the planner's :func:`~motok_robot.planner.generate.generate` with
kinematic constraints: the constraints are sent to the planner as local conditions (coarse,
token level), to the diffusion decoder as guidance hooks (fine, every denoising step), or to
both (``control_path``), which is the ablation of issue 4.
"""

from __future__ import annotations

import numpy as np

from motok_robot.control.config import ControlConfig
from motok_robot.control.constraints import Constraints
from motok_robot.errors import InputError

CONTROL_PATHS = ("both", "planner", "decoder")


def local_conditions_from(constraints: Constraints):
    """:class:`~motok_robot.planner.conditions.LocalConditions` of the constraints' positions."""
    from motok_robot.planner.conditions import LocalConditions

    c = constraints
    trajectory = np.full((c.frames, 3), np.nan)
    root_given = c.joint_mask[:, 0]
    trajectory[root_given, :2] = c.joint_targets[root_given, 0, :2]
    height = root_given & c.root_height_mask
    trajectory[height, 2] = c.joint_targets[height, 0, 2]
    joint_mask = c.joint_mask.copy()
    joint_mask[:, 0] = False
    joints = np.where(joint_mask[..., None], c.joint_targets, np.nan)
    return LocalConditions.from_arrays(c.frames, trajectory=trajectory, joints=joints, joint_mask=joint_mask)


def generate_motion(
    text: str | None = None,
    constraints: Constraints | None = None,
    control: ControlConfig | None = None,
    control_path: str = "both",
    seconds: float | None = None,
    seed: int = 0,
    planner: str = "masked",
    tokenizer_run=None,
    planner_run=None,
    device: str = "cpu",
    out=None,
    generator=None,
    **sample_options,
):
    """Generate a motion that follows ``constraints``; returns a ``GeneratedMotion``.

    ``constraints`` must be built for the clip's frame count (``seconds * 20``); ``seconds``
    defaults to that count when constraints are given. Other keyword arguments are those of
    :meth:`motok_robot.planner.generate.MotionGenerator.generate` (cfg_scale, action, steps, ...).
    ``generator`` is a loaded :class:`~motok_robot.planner.generate.MotionGenerator` to use
    instead of loading one from ``planner`` / ``tokenizer_run`` / ``planner_run``.
    """
    from motok_robot.control.decode import decode_with_control
    from motok_robot.planner.generate import load_generator

    if control_path not in CONTROL_PATHS:
        raise InputError(f"control_path must be one of {CONTROL_PATHS}, got {control_path!r}")
    if generator is None:
        generator = load_generator(planner, tokenizer_run, planner_run, device)
    if constraints is None or constraints.is_empty:
        motion = generator.generate(text=text, seconds=seconds, seed=seed, **sample_options)
    else:
        control = control or ControlConfig()
        if seconds is None:
            seconds = constraints.frames / generator.planner.config.fps
        frames = generator.frames_for(seconds)
        if frames != constraints.frames:
            raise InputError(f"constraints are for {constraints.frames} frames but {seconds:g} s is {frames} frames")
        local = local_conditions_from(constraints) if control_path in ("both", "planner") else None
        decode = None
        if control_path in ("both", "decoder"):

            def decode(tokenizer, tokens, length, steps, seed):
                return decode_with_control(tokenizer, tokens, length, constraints, control, steps=steps, seed=seed)

        motion = generator.generate(text=text, seconds=seconds, seed=seed, local=local, decode=decode, **sample_options)
    if out is not None:
        motion.save(out)
    return motion
