"""Implausible versions of real motion, used as extra negatives when training the evaluator
(:mod:`motok_robot.eval.train_evaluator`) and to measure what its FID notices
(:mod:`motok_robot.eval.sanity`). Numpy only."""

from __future__ import annotations

import numpy as np

CORRUPTIONS = ("shuffle", "reverse", "freeze", "jitter")


def corrupt(features: np.ndarray, kind: str, rng: np.random.Generator) -> np.ndarray:
    """An implausible version of raw features ``[T, 263]``: frames in random order, played
    backwards, the first frame held (same poses, wrong or no motion), or per-frame noise of
    half each feature's spread over the clip (jitter)."""
    if kind == "jitter":
        scale = 0.5 * features.std(axis=0, keepdims=True) + 1e-3
        return (features + scale * rng.normal(size=features.shape)).astype(features.dtype)
    if kind == "shuffle":
        return features[rng.permutation(len(features))]
    if kind == "reverse":
        return features[::-1].copy()
    if kind == "freeze":
        return np.repeat(features[:1], len(features), axis=0)
    raise ValueError(f"unknown corruption {kind!r}; use one of {CORRUPTIONS}")
