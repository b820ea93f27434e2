"""A tiny MoTok (diffusion decoder) overfits a handful of short clips to MPJPE < 1 cm."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from motok_robot.motion.features import features_from_joints
from motok_robot.motion.features_torch import joints_from_features
from motok_robot.motion.synthetic import walking_clip
from motok_robot.tokenizer import TokenizerConfig, TrainConfig, load_tokenizer
from motok_robot.tokenizer.train import Clips, train_tokenizer


@pytest.mark.slow  # about 45 s on 2 cores
def test_tiny_tokenizer_overfits_a_handful_of_clips(tmp_path):
    torch.set_num_threads(1)
    features = [
        features_from_joints(walking_clip(frames=17, speed=0.8 + 0.3 * i, turn_rate=-0.5 + 0.3 * i, start_yaw=0.5 * i, step_hz=0.7 + 0.2 * i))
        for i in range(4)
    ]  # 4 clips x [16, 263]
    flat = np.concatenate(features)
    clips = Clips([f"walk{i}" for i in range(4)], features)
    # the plain diffusion + commitment objective: overfitting must not depend on the geometric terms
    tok_cfg = TokenizerConfig(width=64, code_dim=32, codebook_size=32, denoiser_width=64, denoiser_blocks=4, depth=1,
                              sample_steps=10, joint_weight=0.0, velocity_weight=0.0, foot_weight=0.0)
    cfg = TrainConfig(seed=0, batch_size=8, window=16, lr=1e-3, warmup_steps=20, lr_min_ratio=0.5, steps=600,
                      steps_per_epoch=600, checkpoint_every=600, val_clips=0)
    train_tokenizer(clips, None, flat.mean(0), flat.std(0), tmp_path / "run", tok_cfg, cfg, progress=False)

    tok = load_tokenizer(tmp_path / "run", device="cpu")
    x = torch.from_numpy(np.stack(features)).float()
    tokens = tok.encode(x)
    assert tokens.shape == (4, 4)
    y = tok.decode(tokens, length=16, steps=10, seed=0)
    mpjpe_cm = 100 * float((joints_from_features(y) - joints_from_features(x)).norm(dim=-1).mean())
    assert mpjpe_cm < 1.0, f"MPJPE {mpjpe_cm:.2f} cm"
    # a different seed (another noise draw) decodes the same motion: the tokens carry it
    y2 = tok.decode(tokens, length=16, steps=10, seed=1)
    assert 100 * float((joints_from_features(y2) - joints_from_features(x)).norm(dim=-1).mean()) < 1.0
