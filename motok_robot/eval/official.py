"""The official HumanML3D text-motion matching evaluator, loaded from a user's local files.

HumanML3D (Guo et al., CVPR 2022) reports FID / R-precision / MM-dist with a fixed pair of
encoders trained on HumanML3D. A user who has those files can score motok-robot with the
standard numbers; nothing is downloaded. Expected inputs:

* ``checkpoint``: the text-motion matching checkpoint (``text_mot_match/model/finest.tar``),
  a torch dictionary with the state dicts ``text_encoder``, ``movement_encoder`` and
  ``motion_encoder``. It is read with ``torch.load(weights_only=True)`` (no code executes).
* ``glove_dir``: the word-vector folder (``our_vab_data.npy`` [V, 300], ``our_vab_words.pkl``
  list of words, ``our_vab_idx.pkl`` word -> row). The two pickles are read by a restricted
  unpickler that accepts only lists, dicts, strings and ints.
* ``mean``/``std``: the evaluator's feature statistics (``t2m/.../meta/mean.npy``, ``std.npy``).

Captions are given as HumanML3D token strings ``word/POS word/POS ...`` (the second field of
a HumanML3D ``texts/ID.txt`` line), as the official evaluator uses spaCy POS tags.

Architecture (from the paper's released model description): a movement encoder of two
stride-2 Conv1d (kernel 4) layers with LeakyReLU on the 259 non-contact feature dims and a
linear output; a bidirectional GRU motion encoder over movement codes (one per 4 frames);
a bidirectional GRU text encoder over GloVe word vectors plus an embedded 15-way POS one-hot.
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn.utils.rnn import pack_padded_sequence

from motok_robot.errors import InputError

POS_CATEGORIES = (
    "VERB", "NOUN", "DET", "ADP", "NUM", "AUX", "PRON", "ADJ", "ADV",
    "Loc_VIP", "Body_VIP", "Obj_VIP", "Act_VIP", "Desc_VIP", "OTHER",
)  # fmt: skip
VIP_WORDS = {
    "Loc_VIP": {"left", "right", "clockwise", "counterclockwise", "anticlockwise", "forward", "back", "backward", "up", "down", "straight", "curve"},
    "Body_VIP": {"arm", "chin", "foot", "feet", "face", "hand", "mouth", "leg", "waist", "eye", "knee", "shoulder", "thigh"},
    "Obj_VIP": {"stair", "dumbbell", "chair", "window", "floor", "car", "ball", "handrail", "baseball", "basketball"},
    "Act_VIP": {
        "walk", "run", "swing", "pick", "bring", "kick", "put", "squat", "throw", "hop", "dance", "jump", "turn",
        "stumble", "stop", "sit", "lift", "lower", "raise", "wash", "stand", "kneel", "stroll", "rub", "bend",
        "balance", "flap", "jog", "shuffle", "lean", "rotate", "spin", "spread", "climb",
    },
    "Desc_VIP": {"slowly", "carefully", "fast", "careful", "slow", "quickly", "happy", "angry", "sad", "happily", "angrily", "sadly"},
}  # fmt: skip
UNIT_LENGTH = 4
MAX_TEXT_TOKENS = 20


def _gru_head(hidden: int, output: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(hidden * 2, hidden), nn.LayerNorm(hidden), nn.LeakyReLU(0.2, inplace=True), nn.Linear(hidden, output))


class MovementConvEncoder(nn.Module):
    def __init__(self, input_size: int = 259, hidden_size: int = 512, output_size: int = 512):
        super().__init__()
        self.main = nn.Sequential(
            nn.Conv1d(input_size, hidden_size, 4, 2, 1), nn.Dropout(0.2), nn.LeakyReLU(0.2, inplace=True),
            nn.Conv1d(hidden_size, output_size, 4, 2, 1), nn.Dropout(0.2), nn.LeakyReLU(0.2, inplace=True),
        )  # fmt: skip
        self.out_net = nn.Linear(output_size, output_size)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.out_net(self.main(x.permute(0, 2, 1)).permute(0, 2, 1))


class BiGRUEncoder(nn.Module):
    """Shared shape of the official motion and text encoders (input projection, BiGRU, head)."""

    def __init__(self, input_size: int, hidden_size: int, output_size: int, pos_size: int | None = None):
        super().__init__()
        if pos_size is not None:
            self.pos_emb = nn.Linear(pos_size, input_size)
        self.input_emb = nn.Linear(input_size, hidden_size)
        self.gru = nn.GRU(hidden_size, hidden_size, batch_first=True, bidirectional=True)
        self.output_net = _gru_head(hidden_size, output_size)
        self.hidden = nn.Parameter(torch.zeros(2, 1, hidden_size))

    def forward(self, x: torch.Tensor, lengths: torch.Tensor, pos: torch.Tensor | None = None) -> torch.Tensor:
        if pos is not None:
            x = x + self.pos_emb(pos)
        emb = self.input_emb(x)
        hidden = self.hidden.repeat(1, x.shape[0], 1)
        packed = pack_padded_sequence(emb, lengths.cpu(), batch_first=True, enforce_sorted=False)
        _, last = self.gru(packed, hidden)
        return self.output_net(torch.cat([last[0], last[1]], dim=-1))


class GloveVectors:
    """Restricted reader of the HumanML3D GloVe subset."""

    class _SafeUnpickler(pickle.Unpickler):
        def find_class(self, module, name):  # only plain containers may appear
            raise InputError(f"refusing to unpickle {module}.{name}: word lists must hold only lists, dicts, str and int")

    def __init__(self, glove_dir: str | Path):
        folder = Path(glove_dir)
        try:
            self.vectors = np.load(folder / "our_vab_data.npy")
            with open(folder / "our_vab_idx.pkl", "rb") as f:
                self.index = self._SafeUnpickler(f).load()
        except FileNotFoundError as exc:
            raise InputError(f"GloVe folder {folder}: missing {Path(exc.filename).name}") from None
        if not isinstance(self.index, dict) or self.vectors.ndim != 2:
            raise InputError(f"GloVe folder {folder}: our_vab_idx.pkl must map word -> row and our_vab_data.npy be [V, D]")
        if "unk" not in self.index:
            raise InputError(f"GloVe folder {folder}: the vocabulary has no 'unk' entry")

    def __call__(self, word: str) -> np.ndarray:
        return self.vectors[self.index.get(word, self.index["unk"])]


def pos_one_hot(word: str, tag: str) -> np.ndarray:
    vec = np.zeros(len(POS_CATEGORIES), np.float32)
    category = next((name for name, words in VIP_WORDS.items() if word in words), None)
    if category is None:
        category = tag if tag in POS_CATEGORIES else "OTHER"
    vec[POS_CATEGORIES.index(category)] = 1.0
    return vec


@dataclass
class OfficialEvaluator:
    text_encoder: BiGRUEncoder
    movement_encoder: MovementConvEncoder
    motion_encoder: BiGRUEncoder
    glove: GloveVectors
    mean: np.ndarray
    std: np.ndarray

    @torch.no_grad()
    def embed_motion(self, raw_features: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        """Raw HumanML3D features ``[B, T, 263]`` + frame counts ``[B]`` -> ``[B, 512]``."""
        x = (np.asarray(raw_features, np.float32) - self.mean) / self.std
        movements = self.movement_encoder(torch.as_tensor(x[..., :-4]))
        codes = torch.as_tensor(np.maximum(np.asarray(lengths) // UNIT_LENGTH, 1))
        return self.motion_encoder(movements, codes).numpy()

    @torch.no_grad()
    def embed_text(self, token_strings: list[str]) -> np.ndarray:
        """HumanML3D token strings ``"a/DET man/NOUN walk/VERB ..."`` -> ``[B, 512]``."""
        words, poses, lengths = [], [], []
        for caption in token_strings:
            pairs = [tok.rsplit("/", 1) for tok in caption.split() if "/" in tok][:MAX_TEXT_TOKENS]
            if not pairs:
                raise InputError(f"caption {caption!r}: expected HumanML3D tokens 'word/POS ...'")
            tokens = [("sos", "OTHER"), *pairs, ("eos", "OTHER")]
            words.append(np.stack([self.glove(w) for w, _ in tokens]))
            poses.append(np.stack([pos_one_hot(w, t) for w, t in tokens]))
            lengths.append(len(tokens))
        width = max(lengths)
        word_arr = np.zeros((len(words), width, words[0].shape[1]), np.float32)
        pos_arr = np.zeros((len(words), width, len(POS_CATEGORIES)), np.float32)
        for i, (w, p) in enumerate(zip(words, poses)):
            word_arr[i, : len(w)] = w
            pos_arr[i, : len(p)] = p
        return self.text_encoder(torch.as_tensor(word_arr), torch.as_tensor(lengths), torch.as_tensor(pos_arr)).numpy()


def load_official_evaluator(checkpoint: str | Path, glove_dir: str | Path, mean: str | Path, std: str | Path) -> OfficialEvaluator:
    """Build the official encoders and load their weights (see the module docstring)."""
    path = Path(checkpoint)
    if not path.exists():
        raise InputError(f"official evaluator checkpoint {path} does not exist")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - any unreadable file is reported by name
        raise InputError(f"official evaluator checkpoint {path}: cannot be read as torch weights ({exc.__class__.__name__})") from None
    for key in ("text_encoder", "movement_encoder", "motion_encoder"):
        if key not in state:
            raise InputError(f"official evaluator checkpoint {path}: missing '{key}' (found {sorted(state)})")
    word_dim = state["text_encoder"]["input_emb.weight"].shape[1]
    text_hidden = state["text_encoder"]["input_emb.weight"].shape[0]
    text_out = state["text_encoder"]["output_net.3.weight"].shape[0]
    move_in = state["movement_encoder"]["main.0.weight"].shape[1]
    move_hidden = state["movement_encoder"]["main.0.weight"].shape[0]
    move_out = state["movement_encoder"]["out_net.weight"].shape[0]
    motion_hidden = state["motion_encoder"]["input_emb.weight"].shape[0]
    motion_out = state["motion_encoder"]["output_net.3.weight"].shape[0]
    text = BiGRUEncoder(word_dim, text_hidden, text_out, pos_size=len(POS_CATEGORIES))
    movement = MovementConvEncoder(move_in, move_hidden, move_out)
    motion = BiGRUEncoder(move_out, motion_hidden, motion_out)
    for name, module in (("text_encoder", text), ("movement_encoder", movement), ("motion_encoder", motion)):
        try:
            module.load_state_dict(state[name])
        except RuntimeError as exc:
            first = str(exc).splitlines()[0]
            raise InputError(f"official evaluator checkpoint {path}: '{name}' does not match the architecture: {first}") from None
        module.eval()
    mean_arr, std_arr = np.load(mean).astype(np.float32), np.load(std).astype(np.float32)
    if mean_arr.shape != (move_in + 4,) or std_arr.shape != mean_arr.shape:
        raise InputError(f"evaluator mean/std must have shape ({move_in + 4},), got {mean_arr.shape} and {std_arr.shape}")
    return OfficialEvaluator(text, movement, motion, GloveVectors(glove_dir), mean_arr, std_arr)
