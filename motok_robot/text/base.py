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

from motok_robot.errors import InputError

#: longest prompt accepted, in characters (longer text is an input error, never truncated silently)
MAX_TEXT_CHARS = 500


def check_texts(texts: Sequence[str]) -> list[str]:
    """Validate prompts: a list of non-empty strings of at most :data:`MAX_TEXT_CHARS` characters."""
    if isinstance(texts, str):
        raise InputError("texts must be a list of strings, got a single string (wrap it in a list)")
    out = []
    for i, text in enumerate(texts):
        if not isinstance(text, str):
            raise InputError(f"text #{i} is a {type(text).__name__}, expected a string")
        stripped = " ".join(text.split())
        if not stripped:
            raise InputError(f"text #{i} is empty: give a sentence such as 'a person walks forward'")
        if len(stripped) > MAX_TEXT_CHARS:
            raise InputError(
                f"text #{i} is {len(stripped)} characters long; at most {MAX_TEXT_CHARS} are accepted"
            )
        out.append(stripped)
    return out


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
