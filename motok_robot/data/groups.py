"""What a clip shows, for balancing the draw of training samples across groups of clips.

A clip's group is its action label (the index record's ``action`` / ``label``, or for Bandai
Namco the content of the file name), else its first sentence, else its id.  The tokenizer and
the planner trainers both draw clips with :func:`balanced_weights`, so one label with hundreds
of takes (a walk) does not drown one with a dozen (a bow).
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Hashable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from motok_robot.errors import InputError

_BANDAI_NAME = re.compile(r"dataset-[12]_(?P<content>[a-z-]+)_[a-z-]+_\d+", re.IGNORECASE)


_SIDE = re.compile(r"\b(left|right)\b", re.IGNORECASE)


def _mirrored(label: str) -> str:
    """``label`` with the words left and right swapped (``walk-turn-left`` -> ``walk-turn-right``)."""
    return _SIDE.sub(lambda m: {"left": "right", "right": "left"}[m.group(1).lower()], label)


def clip_action(record: dict) -> str | None:
    """The action label of an index record, if any.

    The record's ``action`` or ``label`` field; for Bandai Namco clips without one, the content
    label of the file name (``dataset-1_{content}_{style}_{NNN}.bvh``, e.g. ``walk-left``).  A
    mirrored clip (``mirror_of`` set) shows the other side: left and right swap in its label,
    as they do in its texts (a mirrored walk-turn-left turns right).
    """
    label = None
    for key in ("action", "label"):
        value = record.get(key)
        if isinstance(value, str) and value.strip():
            label = value.strip()
            break
    if label is None and record.get("source") == "bandai":
        match = _BANDAI_NAME.search(Path(str(record.get("file", ""))).name)
        if match:
            label = match.group("content").lower()
    if label is not None and record.get("mirror_of"):
        label = _mirrored(label)
    return label


def clip_group(record: dict, clip_id: str) -> tuple[str, str]:
    """The balancing group of a clip: ``("action", label)``, else ``("text", first sentence)``,
    else ``("clip", clip_id)``."""
    action = clip_action(record)
    if action:
        return ("action", action)
    texts = record.get("texts") or []
    if texts and str(texts[0]).strip():
        return ("text", " ".join(str(texts[0]).split()))
    return ("clip", clip_id)


def check_balance(balance: float, where: str) -> None:
    if not 0.0 <= float(balance) <= 1.0:
        raise InputError(f"{where}: balance_groups must be in [0, 1] (got {balance})")


def balanced_weights(groups: Sequence[Hashable], balance: float, base: Sequence[float] | None = None) -> np.ndarray:
    """Draw weights (summing to 1) of items in ``groups`` (one group key per item).

    Every item starts with weight ``base`` (default 1: every item equally often; the tokenizer
    passes clip lengths, so every frame is seen equally often) and is divided by
    ``n ** balance``, where ``n`` is the number of items of its group: a group then holds
    ``sum(its base) / n ** balance`` of the total.  ``balance`` 0 leaves the base weights, 1
    weighs every group by its mean base weight (with base 1: every group equally often), 0.5 is
    square-root balancing.
    """
    check_balance(balance, "balanced_weights")
    if not len(groups):
        raise InputError("balanced_weights: no items")
    counts = Counter(groups)
    weights = np.ones(len(groups), dtype=np.float64) if base is None else np.asarray(base, dtype=np.float64).copy()
    if weights.shape != (len(groups),) or not np.all(weights > 0):
        raise InputError(f"balanced_weights: base must hold {len(groups)} positive weights")
    if balance:
        weights /= np.array([counts[g] for g in groups], dtype=np.float64) ** float(balance)
    return weights / weights.sum()


def action_labels_shown(groups: Sequence[Hashable]) -> str:
    """The action labels among ``groups`` for an error message: sorted, the first 12, or 'none'."""
    have = sorted({g[1] for g in groups if isinstance(g, tuple) and len(g) == 2 and g[0] == "action"})
    return (", ".join(have[:12]) + (" ..." if len(have) > 12 else "")) or "none"


def check_action_shares(shares: Any, where: str) -> dict[str, float]:
    """``shares`` as ``{label: share}`` after checking it: labels are non-empty strings, each share
    is in (0, 1) and together they leave room for the other clips (sum < 1)."""
    if not isinstance(shares, dict):
        raise InputError(f"{where}: action_share must map action labels to shares, e.g. {{\"bow\": 0.05}} (got {shares!r})")
    out: dict[str, float] = {}
    for label, share in shares.items():
        if not isinstance(label, str) or not label.strip():
            raise InputError(f"{where}: action_share has an empty or non-text label ({label!r})")
        if isinstance(share, bool) or not isinstance(share, (int, float)) or not 0.0 < float(share) < 1.0:
            raise InputError(f"{where}: action_share[{label!r}] must be a number in (0, 1) (got {share!r})")
        out[label.strip()] = float(share)
    if sum(out.values()) >= 1.0:
        raise InputError(f"{where}: action_share adds up to {sum(out.values()):.3g}; it must stay below 1 "
                         "so the other clips keep a share")
    return out


def parse_action_shares(items: list[str]) -> dict[str, float]:
    """``--action-share`` items, ``["bow=0.05", ...]``, as ``{"bow": 0.05}``; an error names an item that
    is not LABEL=NUMBER (the shares themselves are checked by :func:`check_action_shares`)."""
    shares: dict[str, float] = {}
    for item in items:
        label, sep, value = item.rpartition("=")
        try:
            share = float(value)
        except ValueError:
            share = None
        if not sep or not label.strip() or share is None:
            raise InputError(f"--action-share: expected LABEL=SHARE such as bow=0.05 (got {item!r})")
        shares[label.strip()] = share
    return shares


def with_action_shares(weights: Sequence[float], groups: Sequence[Hashable], shares: dict[str, float],
                       where: str) -> np.ndarray:
    """Draw weights in which the items of each action label in ``shares`` (group
    ``("action", label)``, see :func:`clip_group`) hold that share of the total, keeping their
    relative weights; every other item keeps its relative weight within the rest.

    An error names a label that has no item (with the labels there) and the case where every
    item belongs to a labelled group (no rest to scale).
    """
    weights = np.asarray(weights, dtype=np.float64)
    if weights.shape != (len(groups),):
        raise InputError(f"{where}: action_share needs one weight per clip")
    if not shares:
        return weights / weights.sum()
    out = np.zeros_like(weights)
    taken = np.zeros(len(groups), dtype=bool)
    for label, share in shares.items():
        members = np.array([g == ("action", label) for g in groups], dtype=bool)
        if not members.any():
            raise InputError(f"{where}: action_share names {label!r}, which no clip has "
                             f"(labels there: {action_labels_shown(groups)})")
        out[members] = share * weights[members] / weights[members].sum()
        taken |= members
    if taken.all():
        raise InputError(f"{where}: every clip is of an action in action_share, so the shares cannot hold; "
                         "use only_actions to train on those actions alone")
    out[~taken] = (1.0 - sum(shares.values())) * weights[~taken] / weights[~taken].sum()
    return out
