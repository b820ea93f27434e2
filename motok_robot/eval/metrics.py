"""Text-to-motion quality metrics, computed as in the HumanML3D protocol (Guo et al. 2022).

All functions take *embeddings* produced by a text-motion evaluator
(:mod:`motok_robot.eval.evaluator` or the official HumanML3D one) as float arrays
``[N, D]`` (one row per clip or caption). They are pure numpy and deterministic given
an ``np.random.Generator``.

* FID: Frechet distance between Gaussians fitted to two sets of motion embeddings.
* R-precision top-k: texts and motions are grouped in batches of 32 matched pairs; for each
  text the 32 motions are ranked by Euclidean distance and a hit is counted when the matched
  motion is among the k nearest. Chance level for top-1 is 1/32.
* Matching score (MM-dist): mean Euclidean distance between matched text and motion embeddings.
* Diversity: mean distance between two random subsets of 300 motion embeddings, paired 1:1.
* Multimodality: for each text, mean distance between pairs of motions generated for that text.
* ``confidence_interval``: mean and the 95 % half-width over repeated runs (1.96 sigma/sqrt(n)).
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy import linalg

R_PRECISION_BATCH = 32
DIVERSITY_TIMES = 300


def _as_2d(name: str, x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2:
        raise ValueError(f"{name}: expected embeddings [N, D], got shape {x.shape}")
    if not np.isfinite(x).all():
        raise ValueError(f"{name}: embeddings contain NaN or inf")
    return x


def gaussian_stats(embeddings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean ``[D]`` and covariance ``[D, D]`` of ``embeddings [N, D]``."""
    x = _as_2d("embeddings", embeddings)
    if len(x) < 2:
        raise ValueError("embeddings: need at least 2 rows to estimate a covariance")
    return x.mean(axis=0), np.cov(x, rowvar=False)


def frechet_distance(mu1: np.ndarray, sigma1: np.ndarray, mu2: np.ndarray, sigma2: np.ndarray, eps: float = 1e-6) -> float:
    """``||mu1 - mu2||^2 + Tr(S1 + S2 - 2 (S1 S2)^(1/2))``."""
    diff = np.asarray(mu1) - np.asarray(mu2)
    with warnings.catch_warnings():
        # rank-deficient covariances (fewer clips than embedding dims) are expected: fall back below
        warnings.simplefilter("ignore", linalg.LinAlgWarning)
        covmean = linalg.sqrtm(sigma1 @ sigma2)
        if not np.isfinite(covmean).all():
            offset = np.eye(sigma1.shape[0]) * eps
            covmean = linalg.sqrtm((sigma1 + offset) @ (sigma2 + offset))
    covmean = np.real(covmean)
    value = float(diff @ diff + np.trace(sigma1) + np.trace(sigma2) - 2.0 * np.trace(covmean))
    return max(value, 0.0)


def fid(real: np.ndarray, generated: np.ndarray) -> float:
    """Frechet inception-style distance between two sets of motion embeddings ``[N, D]``."""
    return frechet_distance(*gaussian_stats(real), *gaussian_stats(generated))


def euclidean_distance_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``[Na, Nb]`` Euclidean distances between rows of ``a`` and rows of ``b``."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    sq = (a * a).sum(1)[:, None] - 2.0 * a @ b.T + (b * b).sum(1)[None, :]
    return np.sqrt(np.maximum(sq, 0.0))


def r_precision(text_emb: np.ndarray, motion_emb: np.ndarray, top_k: int = 3, batch_size: int = R_PRECISION_BATCH) -> np.ndarray:
    """R-precision top-1..top_k over consecutive batches of ``batch_size`` matched pairs.

    Row i of ``text_emb`` matches row i of ``motion_emb``. A trailing incomplete batch is
    dropped (as in the HumanML3D evaluation). Returns ``[top_k]`` accuracies in [0, 1].
    """
    t = _as_2d("text_emb", text_emb)
    m = _as_2d("motion_emb", motion_emb)
    if t.shape != m.shape:
        raise ValueError(f"text_emb {t.shape} and motion_emb {m.shape} must have the same shape")
    n_batches = len(t) // batch_size
    if n_batches == 0:
        raise ValueError(f"R-precision needs at least {batch_size} pairs, got {len(t)}")
    hits = np.zeros(top_k)
    for b in range(n_batches):
        sl = slice(b * batch_size, (b + 1) * batch_size)
        dist = euclidean_distance_matrix(t[sl], m[sl])
        # rank of the matched motion for every text (0 = nearest); ties count against the match
        matched = np.diag(dist)[:, None]
        rank = (dist < matched).sum(axis=1)
        for k in range(top_k):
            hits[k] += (rank <= k).sum()
    return hits / (n_batches * batch_size)


def matching_score(text_emb: np.ndarray, motion_emb: np.ndarray) -> float:
    """Mean Euclidean distance between matched rows (MM-dist)."""
    t = _as_2d("text_emb", text_emb)
    m = _as_2d("motion_emb", motion_emb)
    if t.shape != m.shape:
        raise ValueError(f"text_emb {t.shape} and motion_emb {m.shape} must have the same shape")
    return float(np.linalg.norm(t - m, axis=1).mean())


def diversity(motion_emb: np.ndarray, times: int = DIVERSITY_TIMES, rng: np.random.Generator | None = None) -> float:
    """Mean distance between two random subsets of ``times`` embeddings, paired 1:1."""
    m = _as_2d("motion_emb", motion_emb)
    if len(m) < times:
        raise ValueError(f"diversity needs at least {times} motions, got {len(m)}")
    rng = rng or np.random.default_rng(0)
    first = rng.choice(len(m), times, replace=False)
    second = rng.choice(len(m), times, replace=False)
    return float(np.linalg.norm(m[first] - m[second], axis=1).mean())


def multimodality(grouped_emb: np.ndarray, times: int = 10, rng: np.random.Generator | None = None) -> float:
    """``grouped_emb [n_texts, n_repeats, D]``: mean distance between ``times`` random pairs per text."""
    g = np.asarray(grouped_emb, dtype=np.float64)
    if g.ndim != 3 or g.shape[1] < times:
        raise ValueError(f"multimodality needs [n_texts, >= {times} repeats, D], got shape {g.shape}")
    rng = rng or np.random.default_rng(0)
    first = np.stack([rng.choice(g.shape[1], times, replace=False) for _ in range(g.shape[0])])
    second = np.stack([rng.choice(g.shape[1], times, replace=False) for _ in range(g.shape[0])])
    rows = np.arange(g.shape[0])[:, None]
    return float(np.linalg.norm(g[rows, first] - g[rows, second], axis=-1).mean())


def confidence_interval(values: np.ndarray) -> tuple[float, float]:
    """Mean and 95 % confidence half-width (1.96 * std / sqrt(n)) over repeated runs."""
    v = np.asarray(values, dtype=np.float64).reshape(len(values), -1)
    mean = v.mean(axis=0)
    half = 1.96 * v.std(axis=0) / np.sqrt(len(v))
    if mean.size == 1:
        return float(mean[0]), float(half[0])
    return mean, half
