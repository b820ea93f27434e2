"""What the planners were trained to do, and how far a prompt is from it.

``models/vocabulary.json`` (built by ``benchmarks/build_vocabulary.py`` from the prepared
training data; schema below) lists the actions and styles of the training clips with their
counts, and the training captions a prompt is compared with.  :func:`check_prompt` embeds the
prompt with the vocabulary's text encoder (MiniLM) and finds the training captions nearest to it
(cosine similarity); below the vocabulary's calibrated ``threshold`` the prompt is *far* from
every training caption and generation warns (:class:`VocabularyWarning`), names the three
nearest captions and records the check in ``motion.npz`` (field ``vocabulary_check``).

Light module (json and the standard library at import); torch only inside the functions that
embed.

Schema (``format`` ``motok-vocabulary``, ``version`` 1)::

    text_encoder   {"spec": "minilm", "name": "minilm:all-MiniLM-L6-v2"}: what embeds the captions
    threshold      cosine similarity below which a prompt is far from every caption
    captions       [[caption, clips], ...]: the captions a prompt is compared with (a cover of the
                   training captions, subject written "a person"), with the train clips each
                   stands for
    partial        [[caption, clips], ...]: captions that name one part of a longer clip
                   ("Someone sits." of "Playground - climb, sit, dangle legs, descend"); listed,
                   never compared with
    actions        [{"source", "action", "clips", "seconds", "styles": {style: clips}}, ...]
    styles         {style: clips} (Bandai Namco styles, train split)
    planners       {run name: first 16 hex digits of the sha256 of its model.safetensors}: the
                   weights this vocabulary describes
    data, calibration   provenance (free-form objects)
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

from motok_robot.errors import InputError
from motok_robot.text.validate import MAX_TEXT_CHARS

FORMAT = "motok-vocabulary"
VERSION = 1
FILE_NAME = "vocabulary.json"
#: bounds on what a vocabulary file may hold (checked before anything is built from it)
MAX_FILE_BYTES = 2_000_000
MAX_CAPTIONS = 20_000
MAX_ACTIONS = 5_000
MAX_STYLES = 1_000
MAX_COUNT = 10**9
#: captions named when a prompt is far from the vocabulary
NEAREST = 3
#: longest ``vocabulary_check`` record accepted from a motion.npz
MAX_RECORD_CHARS = 16_000

_HEX16 = re.compile(r"^[0-9a-f]{16}$")


class VocabularyWarning(UserWarning):
    """A prompt is far from every caption the planner was trained on."""


@dataclass(frozen=True)
class Caption:
    """A training caption and the number of train clips (mirrors included) it stands for."""

    text: str
    clips: int


@dataclass
class Vocabulary:
    """A loaded ``vocabulary.json`` (see the module docstring for the fields)."""

    path: Path
    encoder_spec: str
    encoder_name: str
    threshold: float
    captions: list[Caption]
    partial: list[Caption] = field(default_factory=list)
    actions: list[dict] = field(default_factory=list)
    styles: dict[str, int] = field(default_factory=dict)
    planners: dict[str, str] = field(default_factory=dict)
    data: dict = field(default_factory=dict)
    calibration: dict = field(default_factory=dict)
    digest: str = ""  # first 16 hex digits of the sha256 of the file

    def describes(self, planner_digest: str) -> bool:
        """Whether these are the captions of the planner whose weights have this digest."""
        return planner_digest[:16] in self.planners.values()


# ----------------------------------------------------------------------------- loading

def vocabulary_path(models: str | Path | None = None) -> Path:
    """``vocabulary.json`` in ``models`` (default: the models folder, ``$MOTOK_ROBOT_MODELS``)."""
    if models is None:
        from motok_robot.paths import models_dir

        models = models_dir()
    return Path(models) / FILE_NAME


def load_vocabulary(path: str | Path | None = None) -> Vocabulary:
    """Read and check a vocabulary file (default :func:`vocabulary_path`); InputError naming the
    file and the field when it is missing, too large or malformed."""
    path = Path(path) if path is not None else vocabulary_path()
    if not path.is_file():
        raise InputError(f"{path}: vocabulary file not found; rebuild it with "
                         "python benchmarks/build_vocabulary.py --data PREPARED (see docs/vocabulary.md)")
    size = path.stat().st_size
    if size > MAX_FILE_BYTES:
        raise InputError(f"{path}: {size:,} bytes, a vocabulary file holds at most {MAX_FILE_BYTES:,}")
    raw = path.read_bytes()
    try:
        data = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: not a readable JSON file ({exc})") from None
    vocab = vocabulary_from_dict(data, str(path))
    vocab.path = path
    vocab.digest = hashlib.sha256(raw).hexdigest()[:16]
    return vocab


def vocabulary_from_dict(data, where: str = "vocabulary") -> Vocabulary:
    """A :class:`Vocabulary` from the parsed JSON object, every field checked."""
    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a JSON object")
    if data.get("format") != FORMAT or data.get("version") != VERSION:
        raise InputError(f"{where}: not a {FORMAT} file of version {VERSION} "
                         f"(format {data.get('format')!r}, version {data.get('version')!r})")
    enc = data.get("text_encoder")
    if not (isinstance(enc, dict) and all(isinstance(enc.get(k), str) and 0 < len(enc[k]) <= 200
                                          for k in ("spec", "name"))):
        raise InputError(f"{where}: field 'text_encoder' must be {{\"spec\": ..., \"name\": ...}} (short strings)")
    threshold = data.get("threshold")
    if isinstance(threshold, bool) or not isinstance(threshold, (int, float)) or not -1.0 <= threshold <= 1.0:
        raise InputError(f"{where}: field 'threshold' must be a cosine similarity in [-1, 1], got {threshold!r}")
    captions = _captions(data.get("captions"), f"{where}: field 'captions'", allow_empty=False)
    partial = _captions(data.get("partial", []), f"{where}: field 'partial'", allow_empty=True)
    actions = data.get("actions", [])
    if not isinstance(actions, list) or len(actions) > MAX_ACTIONS:
        raise InputError(f"{where}: field 'actions' must be a list of at most {MAX_ACTIONS:,} objects")
    for i, action in enumerate(actions):
        name = f"{where}: field 'actions' item {i}"
        if not isinstance(action, dict) or not all(isinstance(action.get(k), str) and action[k]
                                                   for k in ("source", "action")):
            raise InputError(f"{name}: needs the strings 'source' and 'action'")
        if len(action["action"]) > MAX_TEXT_CHARS or len(action["source"]) > 100:
            raise InputError(f"{name}: 'action' or 'source' is too long")
        _count(action.get("clips"), f"{name} 'clips'")
        seconds = action.get("seconds", 0.0)
        if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not 0 <= seconds < 1e9:
            raise InputError(f"{name}: 'seconds' must be a non-negative number")
        _styles(action.get("styles", {}), f"{name} 'styles'")
    styles = _styles(data.get("styles", {}), f"{where}: field 'styles'")
    planners = data.get("planners")
    if not (isinstance(planners, dict) and planners and len(planners) <= 100
            and all(isinstance(k, str) and isinstance(v, str) and _HEX16.match(v) for k, v in planners.items())):
        raise InputError(f"{where}: field 'planners' must map run names to 16 hex digits of their weights' sha256")
    for key in ("data", "calibration"):
        if not isinstance(data.get(key, {}), dict):
            raise InputError(f"{where}: field {key!r} must be an object")
    return Vocabulary(path=Path(where), encoder_spec=enc["spec"], encoder_name=enc["name"], threshold=float(threshold),
                      captions=captions, partial=partial, actions=actions, styles=styles, planners=dict(planners),
                      data=data.get("data", {}), calibration=data.get("calibration", {}))


def _count(value, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_COUNT:
        raise InputError(f"{where}: must be a whole number in 0..{MAX_COUNT:,}, got {value!r}")
    return value


def _captions(value, where: str, allow_empty: bool) -> list[Caption]:
    if not isinstance(value, list) or len(value) > MAX_CAPTIONS or (not value and not allow_empty):
        raise InputError(f"{where}: must be a {'' if allow_empty else 'non-empty '}list of at most "
                         f"{MAX_CAPTIONS:,} [caption, clips] pairs")
    out = []
    for i, item in enumerate(value):
        if not (isinstance(item, list) and len(item) == 2 and isinstance(item[0], str)):
            raise InputError(f"{where} item {i}: must be a [caption, clips] pair")
        text = " ".join(item[0].split())
        if not text or len(text) > MAX_TEXT_CHARS:
            raise InputError(f"{where} item {i}: a caption of 1..{MAX_TEXT_CHARS} characters is expected")
        out.append(Caption(text, _count(item[1], f"{where} item {i} clips")))
    if len({c.text for c in out}) != len(out):
        raise InputError(f"{where}: a caption is listed twice")
    return out


def _styles(value, where: str) -> dict[str, int]:
    if not isinstance(value, dict) or len(value) > MAX_STYLES:
        raise InputError(f"{where}: must map at most {MAX_STYLES} style names to clip counts")
    for k, v in value.items():
        if not k or len(k) > 100:
            raise InputError(f"{where}: style names are 1..100 characters")
        _count(v, f"{where} {k!r}")
    return dict(value)


def vocabulary_for_planner(planner_run: str | Path, planner_digest: str) -> tuple[Vocabulary | None, str]:
    """The vocabulary of a planner run: ``vocabulary.json`` in the folder that holds the run
    (``models/`` for the shipped planners) when it lists the run's weights.  Returns the
    vocabulary (None when there is none for this run) and a line saying why not."""
    path = Path(planner_run).resolve().parent / FILE_NAME
    if not path.is_file():
        return None, (f"no {FILE_NAME} beside the planner run ({path.parent}): prompts are not checked against "
                      "its training captions")
    vocab = load_vocabulary(path)
    if not vocab.describes(planner_digest):
        return None, (f"{path} describes other planner weights ({', '.join(sorted(vocab.planners))}): prompts are not "
                      "checked against the training captions")
    return vocab, ""


# ----------------------------------------------------------------------------- the check

@dataclass
class VocabularyCheck:
    """How near a prompt is to the training captions.

    Attributes:
        text: the prompt (whitespace collapsed).
        similarity: cosine similarity to the nearest training caption.
        threshold: below this the prompt is far from every caption.
        nearest: the :data:`NEAREST` nearest captions with their similarities, nearest first.
        encoder: the text encoder that embedded prompt and captions.
        vocabulary: digest of the vocabulary file used.
    """

    text: str
    similarity: float
    threshold: float
    nearest: list[tuple[str, float]]
    encoder: str
    vocabulary: str

    @property
    def far(self) -> bool:
        return self.similarity < self.threshold

    @property
    def message(self) -> str:
        """One line: the verdict and the nearest captions."""
        near = "; ".join(f'"{c}" ({s:.2f})' for c, s in self.nearest)
        if not self.far:
            return f'"{self.text}" is near the training captions (similarity {self.similarity:.2f}): {near}'
        return (f'"{self.text}" is far from every caption the planner was trained on (nearest similarity '
                f'{self.similarity:.2f} < {self.threshold:.2f}); the motion may not be what was asked for. '
                f"Nearest supported: {near} (motok-robot vocab --captions lists them all)")

    def to_dict(self) -> dict:
        return {"text": self.text, "similarity": round(self.similarity, 4), "threshold": round(self.threshold, 4),
                "far": self.far, "nearest": [[c, round(s, 4)] for c, s in self.nearest], "encoder": self.encoder,
                "vocabulary": self.vocabulary}

    def to_json(self) -> str:
        """The ``vocabulary_check`` field of motion.npz (sorted keys: the same check, the same bytes)."""
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_json(cls, text: str, where: str = "vocabulary_check") -> VocabularyCheck:
        """Parse and check a recorded check (InputError naming ``where`` when malformed)."""
        if not isinstance(text, str) or len(text) > MAX_RECORD_CHARS:
            raise InputError(f"{where}: must be a JSON string of at most {MAX_RECORD_CHARS:,} characters")
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(f"{where}: not valid JSON ({exc.msg})") from None
        try:
            nearest = [(str(c), float(s)) for c, s in data["nearest"]]
            check = cls(text=str(data["text"]), similarity=float(data["similarity"]),
                        threshold=float(data["threshold"]), nearest=nearest, encoder=str(data["encoder"]),
                        vocabulary=str(data["vocabulary"]))
        except (KeyError, TypeError, ValueError):
            raise InputError(f"{where}: expected an object with text, similarity, threshold, nearest "
                             "[[caption, similarity], ...], encoder and vocabulary") from None
        values = [check.similarity, check.threshold] + [s for _, s in nearest]
        if not all(math.isfinite(v) and -1.0001 <= v <= 1.0001 for v in values) or len(nearest) > 20:
            raise InputError(f"{where}: similarities must lie in [-1, 1] and at most 20 captions be named")
        if bool(data.get("far")) != check.far:
            raise InputError(f"{where}: 'far' disagrees with similarity {check.similarity} and threshold "
                             f"{check.threshold}")
        return check


_EMBEDDINGS: dict[tuple[str, str], object] = {}


def caption_embeddings(vocab: Vocabulary, encoder):
    """Unit embeddings ``[K, D]`` (torch, CPU) of ``vocab.captions`` by ``encoder``; kept per process
    and on disk in the motok-robot cache folder (``$MOTOK_ROBOT_CACHE``, off with ``off``), keyed by
    the captions and the encoder, so only the first check on a machine embeds them."""
    import numpy as np
    import torch

    texts = [c.text for c in vocab.captions]
    key = hashlib.sha256(json.dumps([encoder.name, texts]).encode()).hexdigest()[:24]
    memo = _EMBEDDINGS.get((key, encoder.name))
    if memo is not None:
        return memo
    cache = _cache_file(key)
    emb = None
    if cache is not None and cache.is_file():
        try:
            arr = np.load(cache, allow_pickle=False)
            if (arr.shape == (len(texts), encoder.dim) and arr.dtype == np.float32 and np.isfinite(arr).all()
                    and np.allclose(np.linalg.norm(arr, axis=1), 1.0, atol=1e-3)):
                emb = torch.from_numpy(arr)
        except (OSError, ValueError):
            emb = None
    if emb is None:
        emb = torch.nn.functional.normalize(encoder.encode(texts).float(), dim=1)
        if cache is not None:
            _write_cache(cache, emb.numpy())
    _EMBEDDINGS[(key, encoder.name)] = emb
    return emb


def _cache_file(key: str) -> Path | None:
    from retarget.cache import default_dir  # the project's cache folder (light: no CasADi)

    root = default_dir()
    return None if root is None else root / "vocabulary" / f"{key}.npy"


def _write_cache(path: Path, array) -> None:
    import os

    import numpy as np

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.stem}.{os.getpid()}.part.npy")
        np.save(tmp, array, allow_pickle=False)
        os.replace(tmp, path)
    except OSError:  # a read-only or full cache folder only costs the embedding next time
        pass


def check_prompt(text: str, vocab: Vocabulary, encoder=None, embedding=None) -> VocabularyCheck:
    """Compare ``text`` with the vocabulary's captions.

    ``encoder``: a loaded :class:`~motok_robot.text.TextEncoder` named like the vocabulary's (default:
    load ``vocab.encoder_spec``); ``embedding``: the prompt's embedding by that encoder, when the
    caller has it already (generation does)."""
    import torch

    from motok_robot.text.validate import check_text

    clean = check_text(text)
    if encoder is None:
        from motok_robot.text import load_text_encoder

        encoder = load_text_encoder(vocab.encoder_spec)
    if encoder.name != vocab.encoder_name:
        raise InputError(f"{vocab.path}: captions embedded with {vocab.encoder_name}, not {encoder.name}")
    table = caption_embeddings(vocab, encoder)
    query = encoder.encode([clean])[0] if embedding is None else torch.as_tensor(embedding).reshape(-1).cpu()
    query = torch.nn.functional.normalize(query.float(), dim=0)
    sims = table @ query
    best = torch.topk(sims, min(NEAREST, len(vocab.captions)))
    nearest = [(vocab.captions[int(i)].text, round(float(s), 4)) for s, i in zip(best.values, best.indices)]
    return VocabularyCheck(text=clean, similarity=nearest[0][1], threshold=vocab.threshold, nearest=nearest,
                           encoder=encoder.name, vocabulary=vocab.digest)


def warn_if_far(check: VocabularyCheck | None, stacklevel: int = 2) -> None:
    """Issue a :class:`VocabularyWarning` when ``check`` says the prompt is far from the vocabulary."""
    if check is not None and check.far:
        warnings.warn(check.message, VocabularyWarning, stacklevel=stacklevel + 1)


def vocabulary_note(motion) -> str | None:
    """The line ``run`` records (report notes, summary.md) for a generated motion: the warning when
    its prompt was far from the training captions, else None.  ``motion`` is a
    :class:`~motok_robot.planner.generate.GeneratedMotion` (or anything with a ``vocabulary``
    attribute holding a :class:`VocabularyCheck`); other motions give None."""
    check = getattr(motion, "vocabulary", None)
    if check is None or not check.far:
        return None
    return f"vocabulary: {check.message}"
