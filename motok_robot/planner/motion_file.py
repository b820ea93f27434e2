"""``motion.npz`` -- the generation output (schema in docs/CONTRACTS.md), written reproducibly.

Keys: ``joints`` float32 ``[T, 22, 3]`` (metres, z up), ``features`` float32 ``[T, 263]``, ``fps``
(int), ``text`` (str; "" when unconditional), ``tokens`` int64 ``[N]``, ``seed`` (int), ``model``
(str: identifiers of the models used), ``decoder_seed`` (int) only when the decoder's noise
came from another seed than ``seed``, and ``vocabulary_check`` (str, JSON) only when the prompt
was compared with the planner's training captions
(:class:`~motok_robot.text.vocabulary.VocabularyCheck`). No object arrays: ``np.load(path)`` works with the default
``allow_pickle=False``.

The file is a zip written with fixed timestamps, so the same content gives byte-identical files
(``numpy.savez`` stamps the current time), and it is written to a temporary name then renamed,
so an interrupted run never leaves a truncated ``motion.npz``.
"""

from __future__ import annotations

import io
import os
import zipfile
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.motion.skeleton import NUM_JOINTS
from motok_robot.npz_files import read_npz_fields

_EPOCH = (1980, 1, 1, 0, 0, 0)


def write_npz_reproducible(path: str | Path, arrays: dict[str, np.ndarray]) -> Path:
    """Like ``numpy.savez`` but byte-for-byte reproducible and atomic."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_STORED) as zf:
        for key in sorted(arrays):
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.asanyarray(arrays[key]), allow_pickle=False)
            info = zipfile.ZipInfo(key + ".npy", date_time=_EPOCH)
            info.external_attr = 0o644 << 16
            zf.writestr(info, buf.getvalue())
    os.replace(tmp, path)
    return path


def save_motion(path: str | Path, joints: np.ndarray, features: np.ndarray, tokens: np.ndarray, text: str,
                seed: int, model: str, fps: int = 20, decoder_seed: int | None = None,
                vocabulary_check: str | None = None) -> Path:
    """Validate and write a ``motion.npz``; ``vocabulary_check`` is
    :meth:`~motok_robot.text.vocabulary.VocabularyCheck.to_json` of the prompt's check."""
    joints = np.asarray(joints, dtype=np.float32)
    features = np.asarray(features, dtype=np.float32)
    if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3):
        raise InputError(f"motion.npz joints must be [T, {NUM_JOINTS}, 3], got {joints.shape}")
    if features.shape != (joints.shape[0], 263):
        raise InputError(f"motion.npz features must be [{joints.shape[0]}, 263], got {features.shape}")
    if not (np.isfinite(joints).all() and np.isfinite(features).all()):
        raise InputError("motion.npz: joints/features contain NaN or inf (the models produced invalid output)")
    arrays = {
        "joints": joints,
        "features": features,
        "fps": np.array(int(fps)),
        "text": np.array(str(text)),
        "tokens": np.asarray(tokens, dtype=np.int64).reshape(-1),
        "seed": np.array(int(seed)),
        "model": np.array(str(model)),
    }
    if decoder_seed is not None:
        arrays["decoder_seed"] = np.array(int(decoder_seed))
    if vocabulary_check is not None:
        from motok_robot.text.vocabulary import VocabularyCheck

        arrays["vocabulary_check"] = np.array(VocabularyCheck.from_json(vocabulary_check, "motion.npz "
                                                                        "vocabulary_check").to_json())
    return write_npz_reproducible(path, arrays)


def load_motion(path: str | Path) -> dict[str, np.ndarray | str | int]:
    """Read a ``motion.npz`` -> dict with numpy arrays and plain ``text``/``model``/``seed``/``fps``
    (and ``decoder_seed`` when the file has one; ``vocabulary_check`` as a checked dict, see
    :meth:`~motok_robot.text.vocabulary.VocabularyCheck.to_dict`)."""
    path = Path(path)
    data = read_npz_fields(path, "motion file")
    for key in ("joints", "fps"):
        if key not in data:
            raise InputError(f"{path}: missing field {key!r}")
    out: dict = dict(data)
    for key in ("text", "model"):
        if key in data:
            out[key] = str(data[key])
    for key in ("seed", "fps", "decoder_seed"):
        if key in data:
            out[key] = int(data[key])
    if "vocabulary_check" in data:
        from motok_robot.text.vocabulary import VocabularyCheck

        field = np.asarray(data["vocabulary_check"])
        if field.dtype.kind != "U" or field.shape != ():
            raise InputError(f"{path}: field 'vocabulary_check' must be one JSON string, got {field.dtype} "
                             f"{field.shape}")
        out["vocabulary_check"] = VocabularyCheck.from_json(str(field), f"{path}: field 'vocabulary_check'").to_dict()
    return out
