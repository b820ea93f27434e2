"""The :class:`TextEncoder` interface: sentences -> one fixed-size feature vector each.

A text encoder is frozen (it is never trained by motok-robot); the planner learns a
projection from ``dim`` to its own width (:mod:`motok_robot.planner.conditions`).
Embeddings are cached per exact string, so encoding the same prompt twice (training
epochs, classifier-free guidance, batch generation) costs one forward pass.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence

import torch

from motok_robot.text.validate import MAX_TEXT_CHARS, check_texts

__all__ = ["MAX_TEXT_CHARS", "TextEncoder", "check_texts"]


class TextEncoder(ABC):
    """Frozen sentence encoder.

    Subclasses implement :meth:`_encode_uncached` and set :attr:`dim` and :attr:`name`.

    Attributes:
        dim: size ``D`` of one embedding.
        name: identifier written into outputs and checkpoints (e.g. ``"minilm:all-MiniLM-L6-v2"``).
    """

    dim: int
    name: str

    def __init__(self) -> None:
        self._cache: dict[str, torch.Tensor] = {}

    @abstractmethod
    def _encode_uncached(self, texts: list[str]) -> torch.Tensor:
        """Embed ``texts`` (already validated) -> float32 ``[B, dim]`` on the CPU."""

    @torch.no_grad()
    def encode(self, texts: Sequence[str]) -> torch.Tensor:
        """Embed sentences -> float32 tensor ``[B, dim]`` (CPU), one row per sentence.

        Whitespace is normalised before caching; empty or over-long sentences raise
        :class:`~motok_robot.errors.InputError`.
        """
        clean = check_texts(texts)
        missing = list(dict.fromkeys(t for t in clean if t not in self._cache))
        if missing:
            emb = self._encode_uncached(missing).detach().to("cpu", torch.float32)
            if emb.shape != (len(missing), self.dim):
                raise RuntimeError(f"{self.name} returned shape {tuple(emb.shape)}, expected {(len(missing), self.dim)}")
            for text, row in zip(missing, emb):
                self._cache[text] = row.clone()
        if not clean:
            return torch.zeros(0, self.dim)
        return torch.stack([self._cache[t] for t in clean])

    def clear_cache(self) -> None:
        """Forget every cached embedding."""
        self._cache.clear()

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, dim={self.dim})"
