"""Evaluation stage: text-motion metrics computed as in the HumanML3D protocol.

* :mod:`~motok_robot.eval.metrics`: FID, R-precision, MM-dist, diversity, multimodality, CI (numpy);
* :mod:`~motok_robot.eval.evaluator` / :mod:`~motok_robot.eval.train_evaluator`: motok-robot's own
  contrastive text-motion evaluator and its resumable training;
* :mod:`~motok_robot.eval.official`: the official HumanML3D evaluator, from a user's local files;
* :mod:`~motok_robot.eval.protocol`: the generation-evaluation protocol (reference row,
  shuffled-text control, one row per generator), independent of models (numpy);
* :mod:`~motok_robot.eval.embedders`, :mod:`~motok_robot.eval.generation`: adapters from the
  evaluators and the planners to the protocol; :mod:`~motok_robot.eval.sanity`: evaluator checks;
* :mod:`~motok_robot.eval.cli`: ``train evaluator``, ``eval generation``, ``eval evaluator``.

Importing this package does not import torch; import the submodules. See docs/evaluation.md.
"""
