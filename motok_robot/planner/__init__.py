"""Planning stage: condition features -> MoTok token sequences -> motion.

* :class:`~motok_robot.planner.masked.MaskedPlanner` -- masked discrete diffusion (bidirectional);
* :class:`~motok_robot.planner.autoregressive.ARPlanner` -- autoregressive (causal, end token);
* both: ``plan(conditions, n_tokens, seed, cfg_scale, ...) -> LongTensor [B, N]``;
* :func:`motok_robot.planner.generate.generate` -- text -> ``motion.npz``.

Importing this package does not import torch; import the submodules.
"""
