"""Loading the official HumanML3D evaluator from files laid out as its release (random weights)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from motok_robot.errors import InputError  # noqa: E402
from motok_robot.eval.official import (  # noqa: E402
    BiGRUEncoder,
    MovementConvEncoder,
    load_official_evaluator,
)


def write_release(tmp_path, seed=0, hidden=16, out=8, word=6):
    torch.manual_seed(seed)
    state = {
        "text_encoder": BiGRUEncoder(word, hidden, out, pos_size=15).state_dict(),
        "movement_encoder": MovementConvEncoder(259, hidden, hidden).state_dict(),
        "motion_encoder": BiGRUEncoder(hidden, hidden, out).state_dict(),
        "epoch": 10,
    }
    ckpt = tmp_path / f"finest{seed}.tar"
    torch.save(state, ckpt)
    glove = tmp_path / "glove"
    glove.mkdir(exist_ok=True)
    words = ["unk", "sos", "eos", "a", "person", "walk", "left"]
    np.save(glove / "our_vab_data.npy", np.random.default_rng(seed).normal(size=(len(words), word)).astype(np.float32))
    with open(glove / "our_vab_idx.pkl", "wb") as f:
        pickle.dump({w: i for i, w in enumerate(words)}, f)
    with open(glove / "our_vab_words.pkl", "wb") as f:
        pickle.dump(words, f)
    np.save(tmp_path / "mean.npy", np.zeros(263, np.float32))
    np.save(tmp_path / "std.npy", np.ones(263, np.float32))
    return ckpt, glove, tmp_path / "mean.npy", tmp_path / "std.npy"


def test_official_evaluator_loads_and_embeds(tmp_path):
    files = write_release(tmp_path)
    ev = load_official_evaluator(*files)
    motions = np.random.default_rng(1).normal(size=(3, 40, 263)).astype(np.float32)
    z = ev.embed_motion(motions, np.array([40, 24, 16]))
    assert z.shape == (3, 8) and np.isfinite(z).all()
    t = ev.embed_text(["a/DET person/NOUN walk/VERB left/ADV", "a/DET zebra/NOUN"])
    assert t.shape == (2, 8)
    # deterministic, and frames beyond the conv receptive field of the last code (length + 4) are ignored
    np.testing.assert_allclose(ev.embed_motion(motions, np.array([40, 24, 16])), z, atol=1e-6)
    padded = motions.copy()
    padded[1, 28:] = 100.0
    np.testing.assert_allclose(ev.embed_motion(padded, np.array([40, 24, 16]))[1], z[1], atol=1e-5)
    # other weights give other embeddings
    other = load_official_evaluator(*write_release(tmp_path, seed=1))
    assert not np.allclose(other.embed_motion(motions, np.array([40, 24, 16])), z)


def test_official_evaluator_errors_name_the_problem(tmp_path):
    ckpt, glove, mean, std = write_release(tmp_path)
    with pytest.raises(InputError, match="does not exist"):
        load_official_evaluator(tmp_path / "nope.tar", glove, mean, std)
    bad = tmp_path / "bad.tar"
    torch.save({"text_encoder": {}}, bad)
    with pytest.raises(InputError, match="missing 'movement_encoder'"):
        load_official_evaluator(bad, glove, mean, std)
    with open(glove / "our_vab_idx.pkl", "wb") as f:
        pickle.dump({"unk": np.int64(0)}, f)  # numpy scalar needs a class import: refused
    with pytest.raises(InputError, match="refusing to unpickle"):
        load_official_evaluator(ckpt, glove, mean, std)
