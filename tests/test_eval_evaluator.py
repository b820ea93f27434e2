"""The contrastive evaluator learns a toy text-motion pairing, saves/loads, and resumes exactly."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from motok_robot.eval.config import EvaluatorConfig  # noqa: E402
from motok_robot.eval.evaluator import load_evaluator  # noqa: E402
from motok_robot.eval.train_evaluator import train_evaluator  # noqa: E402

CAPTIONS = ["a person walks", "a person jumps", "a person waves", "a person bows"]


class ToyDataset:
    """Four motion classes (a different dimension oscillates), 48 clips, one caption each."""

    def __init__(self, n: int, seed: int):
        rng = np.random.default_rng(seed)
        self.clip_ids = [f"c{i}" for i in range(n)]
        self._features, self._texts = {}, {}
        for i, cid in enumerate(self.clip_ids):
            label = i % 4
            length = int(rng.integers(40, 80))
            x = 0.1 * rng.normal(size=(length, 263)).astype(np.float32)
            x[:, 10 * label : 10 * label + 10] += np.sin(np.arange(length) / 3.0)[:, None]
            self._features[cid] = x
            self._texts[cid] = [CAPTIONS[label]]
        self.mean = np.zeros(263, np.float32)
        self.std = np.ones(263, np.float32)

    def features(self, cid):
        return self._features[cid]

    def texts(self, cid):
        return self._texts[cid]


def one_hot_text(texts):
    return np.stack([np.eye(8)[CAPTIONS.index(t)] for t in texts]).astype(np.float32)


def small_config(steps: int) -> EvaluatorConfig:
    return EvaluatorConfig(width=32, latent_dim=16, layers=1, heads=2, batch_size=16, steps=steps, eval_every=10, max_frames=80, lr=2e-3)


def test_evaluator_learns_toy_pairing_and_roundtrips(tmp_path):
    torch.set_num_threads(1)
    train, val = ToyDataset(48, 0), ToyDataset(32, 1)
    run = train_evaluator(train, val, one_hot_text, 8, tmp_path / "run", small_config(60))
    rows = (run / "metrics.csv").read_text().strip().splitlines()
    last = rows[-1].split(",")
    # with 4 classes in a batch of 32 and duplicate captions ranked as ties against the match,
    # a perfect model reaches top-1 >= 1/8 ... top-3 well above chance (3/32)
    assert float(last[4]) > 0.3, rows
    model = load_evaluator(run)
    feats = torch.as_tensor(np.stack([val.features(c)[:40] for c in val.clip_ids[:4]]))
    lengths = torch.full((4,), 40)
    z = model.embed_motion(feats, lengths)
    t = model.embed_text(torch.as_tensor(one_hot_text(CAPTIONS)))
    # every motion is nearest to its own caption
    assert (torch.cdist(z, t).argmin(1) == torch.arange(4)).all()
    torch.testing.assert_close(z.norm(dim=1), torch.ones(4))


def test_evaluator_resume_continues_exactly(tmp_path):
    torch.set_num_threads(1)
    train, val = ToyDataset(24, 0), ToyDataset(32, 1)
    straight = train_evaluator(train, val, one_hot_text, 8, tmp_path / "a", small_config(20))
    train_evaluator(train, val, one_hot_text, 8, tmp_path / "b", small_config(10))
    resumed = train_evaluator(train, val, one_hot_text, 8, tmp_path / "b", small_config(20), resume=True)
    a, b = load_evaluator(straight), load_evaluator(resumed)
    for (name, pa), (_, pb) in zip(a.state_dict().items(), b.state_dict().items()):
        torch.testing.assert_close(pa, pb, msg=name)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_evaluator_trains_and_validates_on_cuda(tmp_path):
    """Validation batches follow the model to the GPU (they were built on the CPU and crashed)."""
    train, val = ToyDataset(48, 0), ToyDataset(32, 1)
    run = train_evaluator(train, val, one_hot_text, 8, tmp_path / "run", small_config(20), device="cuda")
    rows = (run / "metrics.csv").read_text().strip().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == ["10", "20"], rows
    assert all(0.0 <= float(r.split(",")[2]) <= 1.0 for r in rows[1:]), rows
    model = load_evaluator(run)  # saved weights load on the CPU
    assert model.mean.device.type == "cpu"
