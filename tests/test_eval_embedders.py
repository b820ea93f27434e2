"""The protocol's adapters over motok-robot's evaluator and the official HumanML3D one."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from motok_robot.errors import InputError  # noqa: E402
from motok_robot.eval.config import EvaluatorConfig  # noqa: E402
from motok_robot.eval.embedders import (  # noqa: E402
    OfficialEmbedder,
    OwnEvaluatorEmbedder,
    humanml3d_token_captions,
    pad_batch,
)
from motok_robot.eval.evaluator import TextMotionEvaluator  # noqa: E402
from motok_robot.eval.official import load_official_evaluator  # noqa: E402

torch.set_num_threads(1)


def tiny_evaluator(seed=0):
    torch.manual_seed(seed)
    cfg = EvaluatorConfig(width=32, latent_dim=16, layers=1, heads=2, max_frames=80)
    rng = np.random.default_rng(seed)
    return TextMotionEvaluator(cfg, 8, rng.normal(size=263).astype(np.float32), rng.uniform(0.5, 2, 263).astype(np.float32))


def test_pad_batch_shapes_and_limits():
    feats, lengths = pad_batch([np.ones((5, 263)), np.ones((3, 263))])
    assert feats.shape == (2, 5, 263) and lengths.tolist() == [5, 3] and feats[1, 3:].sum() == 0
    with pytest.raises(InputError, match="longer than the evaluator's 4"):
        pad_batch([np.ones((5, 263))], max_frames=4)


def test_own_embedder_is_unit_norm_and_independent_of_batch_padding():
    model = tiny_evaluator()
    embedder = OwnEvaluatorEmbedder(model, encode_text=lambda texts: np.eye(8)[[len(t) % 8 for t in texts]], batch_size=2)
    rng = np.random.default_rng(1)
    motions = [rng.normal(size=(n, 263)).astype(np.float32) for n in (41, 80, 57, 63, 44)]
    together = embedder.embed_motion(motions)
    alone = np.concatenate([embedder.embed_motion([m]) for m in motions])
    np.testing.assert_allclose(together, alone, atol=1e-5)  # batch composition and padding do not matter
    np.testing.assert_allclose(np.linalg.norm(together, axis=1), 1.0, atol=1e-6)
    t = embedder.embed_text(["a", "bb", "a"])
    assert t.shape == (3, 16) and np.allclose(t[0], t[2]) and not np.allclose(t[0], t[1])
    assert embedder.min_frames == 40 and embedder.max_frames == 80


def test_official_embedder_reads_pos_tagged_captions(tmp_path):
    from test_eval_official import write_release

    evaluator = load_official_evaluator(*write_release(tmp_path))
    texts = tmp_path / "texts"
    texts.mkdir()
    (texts / "000001.txt").write_text("A person walks left.#a/DET person/NOUN walk/VERB left/ADV#0.0#0.0\n")
    (texts / "M000001.txt").write_text("a person walks right#a/DET person/NOUN walk/VERB right/ADV#0.0#0.0\n")
    table = humanml3d_token_captions(texts)
    assert table["a person walks left."] == "a/DET person/NOUN walk/VERB left/ADV"
    embedder = OfficialEmbedder(evaluator, table)
    z = embedder.embed_text(["a  person walks LEFT.", "a/DET person/NOUN walk/VERB left/ADV"])
    np.testing.assert_allclose(z[0], z[1], atol=1e-6)  # plain caption -> its token string
    with pytest.raises(InputError, match="'a zebra dances' has no HumanML3D token string"):
        embedder.embed_text(["a zebra dances"])
    motions = [np.random.default_rng(0).normal(size=(n, 263)).astype(np.float32) for n in (43, 40)]
    m = embedder.embed_motion(motions)
    assert m.shape == (2, 8)
    # cropped to a multiple of 4 frames, as the official evaluation does
    np.testing.assert_allclose(m[0], embedder.embed_motion([motions[0][:40]])[0], atol=1e-5)
    with pytest.raises(InputError, match="no HumanML3D caption lines"):
        humanml3d_token_captions(tmp_path / "glove")
    with pytest.raises(InputError, match="does not exist"):
        humanml3d_token_captions(tmp_path / "missing")


def test_corruptions_and_extra_negatives():
    from motok_robot.eval.corruptions import corrupt
    from motok_robot.eval.train_evaluator import corrupted_copies

    rng = np.random.default_rng(0)
    x = np.arange(12, dtype=np.float32).reshape(6, 2)
    np.testing.assert_array_equal(corrupt(x, "reverse", rng), x[::-1])
    np.testing.assert_array_equal(corrupt(x, "freeze", rng), np.repeat(x[:1], 6, 0))
    shuffled = corrupt(x, "shuffle", rng)
    assert sorted(map(tuple, shuffled)) == sorted(map(tuple, x))
    jittered = corrupt(x, "jitter", rng)
    assert jittered.shape == x.shape and not np.allclose(jittered, x) and np.abs(jittered - x).max() < 10
    with pytest.raises(ValueError, match="unknown corruption"):
        corrupt(x, "melt", rng)
    feats = torch.zeros(4, 8, 2)
    feats[:, :5] = torch.arange(5.0)[None, :, None] + 1
    lengths = torch.tensor([5, 5, 5, 5])
    bad, bad_len = corrupted_copies(feats, lengths, 2, rng)
    assert bad.shape == (2, 8, 2) and bad_len.tolist() == [5, 5] and (bad[:, 5:] == 0).all()
    # extra negatives can only make the text -> motion classification harder
    model = tiny_evaluator()
    t = torch.nn.functional.normalize(torch.randn(4, 16), dim=-1)
    m = torch.nn.functional.normalize(torch.randn(4, 16), dim=-1)
    same = torch.zeros(4, 4, dtype=torch.bool)
    plain = model.contrastive_loss(t, m, same)
    harder = model.contrastive_loss(t, m, same, torch.nn.functional.normalize(torch.randn(3, 16), dim=-1))
    assert harder > plain


def test_runs_written_before_the_delta_channels_still_load(tmp_path):
    import json

    from motok_robot.eval.evaluator import load_evaluator, save_evaluator

    torch.manual_seed(0)
    cfg = EvaluatorConfig(width=32, latent_dim=16, layers=1, heads=2, max_frames=80, motion_deltas=False,
                          corrupt_negatives=0.0)
    old = TextMotionEvaluator(cfg, 8, np.zeros(263, np.float32), np.ones(263, np.float32))
    save_evaluator(old, tmp_path)
    config = json.loads((tmp_path / "config.json").read_text())
    for key in ("motion_deltas", "corrupt_negatives"):
        del config["evaluator"][key]
    (tmp_path / "config.json").write_text(json.dumps(config))
    loaded = load_evaluator(tmp_path)
    assert loaded.cfg.motion_deltas is False and loaded.motion.stem[0].in_channels == 263
    assert tiny_evaluator().motion.stem[0].in_channels == 2 * 263  # the default feeds frame differences too
