"""Prompt checks shared by the planner, the pipeline and the text encoders (light: no torch).

A prompt is a non-empty string of at most :data:`MAX_TEXT_CHARS` characters once runs of
whitespace are collapsed to single spaces; anything else is an
:class:`~motok_robot.errors.InputError` naming the prompt, never a silent truncation.
"""

from __future__ import annotations

from collections.abc import Sequence

from motok_robot.errors import InputError

#: longest prompt accepted, in characters (longer text is an input error, never truncated silently)
MAX_TEXT_CHARS = 500


def check_text(text, name: str = "text", hint: str = "") -> str:
    """The prompt with whitespace collapsed; InputError when not a string, empty or too long.

    ``name`` names the prompt in messages (``"text"``, ``"text #3"``); ``hint`` is appended to the
    empty-text message (e.g. ``" (or use --unconditional)"``).
    """
    if not isinstance(text, str):
        raise InputError(f"{name} must be a string, got {type(text).__name__}")
    clean = " ".join(text.split())
    if not clean:
        raise InputError(f'{name} is empty: give a sentence such as "a person walks forward"{hint}')
    if len(clean) > MAX_TEXT_CHARS:
        raise InputError(f"{name} is {len(clean)} characters long; at most {MAX_TEXT_CHARS} are accepted")
    return clean


def check_texts(texts: Sequence[str]) -> list[str]:
    """:func:`check_text` for each of a list of prompts (named ``text #i`` in messages)."""
    if isinstance(texts, str):
        raise InputError("texts must be a list of strings, got a single string (wrap it in a list)")
    return [check_text(text, name=f"text #{i}") for i, text in enumerate(texts)]
