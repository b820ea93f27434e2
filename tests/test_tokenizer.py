"""MoTok tokenizer: shapes, codebook, save/load, emphasis projection, guidance hook, resume."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from motok_robot.errors import InputError
from motok_robot.tokenizer import MoTok, TokenizerConfig, TrainConfig, load_tokenizer, pad_to_multiple, save_tokenizer
from motok_robot.tokenizer.config import tokenizer_config_from_dict
from motok_robot.tokenizer.emphasis import EmphasisProjection
from motok_robot.tokenizer.quantizer import VectorQuantizer
from motok_robot.tokenizer.sampler import GuidanceState, cosine_alpha_bar, ddim_timesteps
from motok_robot.tokenizer.train import Clips, train_tokenizer

torch.set_num_threads(1)

TINY = dict(width=32, code_dim=16, codebook_size=16, denoiser_width=32, denoiser_blocks=2, depth=1, sample_steps=4)


def smooth_features(batch: int, frames: int, seed: int = 0) -> torch.Tensor:
    """Random smooth raw features ``[batch, frames, 263]`` (cumulative sums of noise, scaled)."""
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.normal(size=(batch, frames, 263)), axis=1) * 0.05 + rng.normal(size=(1, 1, 263))
    return torch.from_numpy(x).float()


def tiny(seed: int = 0, **overrides) -> MoTok:
    torch.manual_seed(seed)
    x = smooth_features(4, 32, seed)
    flat = x.reshape(-1, 263)
    return MoTok(TokenizerConfig(**{**TINY, **overrides}), flat.mean(0).numpy(), flat.std(0).numpy())


def train_steps(model: MoTok, steps: int = 3, seed: int = 0) -> MoTok:
    """A few optimisation steps so the EMA codebook and weights are not at their initial values."""
    model.train()
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    gen = torch.Generator().manual_seed(seed)
    x = smooth_features(4, 32, seed)
    for _ in range(steps):
        loss = model.training_losses(x, gen)["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
    return model.eval()


@pytest.mark.parametrize("downsample", [2, 4, 8])
def test_encode_decode_shapes_and_dtypes(downsample):
    model = tiny(downsample=downsample).eval()
    x = smooth_features(2, 32)
    tokens = model.encode(x)
    assert tokens.shape == (2, 32 // downsample) and tokens.dtype == torch.int64
    assert int(tokens.min()) >= 0 and int(tokens.max()) < model.config.codebook_size
    assert model.frames_per_token == downsample
    y = model.decode(tokens, length=32, steps=3)
    assert y.shape == (2, 32, 263) and y.dtype == torch.float32 and torch.isfinite(y).all()
    shorter = model.decode(tokens, length=30, steps=3)
    assert shorter.shape == (2, 30, 263)
    assert model.decode(tokens).shape == (2, 32, 263)  # length defaults to N * downsample


def test_bad_inputs_raise_input_errors():
    model = tiny().eval()
    with pytest.raises(InputError, match="multiple of 4"):
        model.encode(smooth_features(1, 30))
    with pytest.raises(InputError, match=r"\[B, T, 263\]"):
        model.encode(torch.zeros(30, 263))
    bad = smooth_features(1, 32)
    bad[0, 5, 7] = float("nan")
    with pytest.raises(InputError, match="frame 5, dim 7"):
        model.encode(bad)
    with pytest.raises(InputError, match="token ids must be in 0..15"):
        model.decode(torch.tensor([[0, 16]]))
    with pytest.raises(InputError, match="length must be in 1..8"):
        model.decode(torch.tensor([[0, 1]]), length=9)
    with pytest.raises(InputError, match="unknown key"):
        tokenizer_config_from_dict({"downsampel": 4})
    with pytest.raises(InputError, match="decoder"):
        TokenizerConfig(decoder="transformer")


def test_pad_to_multiple_repeats_last_frame():
    x = smooth_features(1, 30)
    padded, length = pad_to_multiple(x, 4)
    assert length == 30 and padded.shape == (1, 32, 263)
    assert torch.equal(padded[:, 30], x[:, -1]) and torch.equal(padded[:, 31], x[:, -1])
    model = tiny().eval()
    assert model.reconstruct(x, steps=2).shape == (1, 30, 263)


def test_dead_code_is_restarted_near_the_data():
    vq = VectorQuantizer(codebook_size=8, code_dim=4, decay=0.5, dead_code_threshold=0.5)
    gen = torch.Generator().manual_seed(0)
    data = torch.randn(1, 64, 4, generator=gen)
    vq.train()
    vq(data, gen)  # initialises the codebook from the data
    with torch.no_grad():  # move code 3 far away: it will never be chosen and its count decays
        vq.codebook[3] = 100.0
        vq.ema_sum[3] = 100.0
    before = int(vq.restarts)
    for _ in range(4):
        vq(data, gen)
    assert int(vq.restarts) > before
    assert float(vq.codebook[3].abs().max()) < 5.0, "the unused far-away code was moved back to the data"
    assert float(vq.ema_count[3]) > 0
    # directly: a dead code lands on (a jittered copy of) one of the given encoder outputs
    with torch.no_grad():
        vq.ema_count[5] = 0.0
    assert vq.restart_dead_codes(data.reshape(-1, 4), gen) >= 1
    assert float((data.reshape(-1, 4) - vq.codebook[5]).norm(dim=1).min()) < 0.05


def test_quantizer_straight_through_and_commitment():
    vq = VectorQuantizer(codebook_size=4, code_dim=2)
    vq.train()
    h = torch.randn(1, 10, 2, requires_grad=True)
    out = vq(h, torch.Generator().manual_seed(1))
    out.quantized.sum().backward()
    assert torch.allclose(h.grad, torch.ones_like(h))  # straight-through: d q / d h = I
    assert out.commitment.item() >= 0 and 1.0 <= out.perplexity.item() <= 4.0


@pytest.mark.parametrize("overrides", [{}, {"parameterisation": "eps", "emphasis": True}, {"decoder": "conv"}])
def test_save_load_gives_identical_outputs(tmp_path, overrides):
    model = train_steps(tiny(**overrides))
    save_tokenizer(model, tmp_path / "run")
    loaded = load_tokenizer(tmp_path / "run", device="cpu")
    assert loaded.config == model.config
    x = smooth_features(2, 32, seed=5)
    tokens = model.encode(x)
    assert torch.equal(loaded.encode(x), tokens)
    assert torch.equal(loaded.decode(tokens, steps=3, seed=2), model.decode(tokens, steps=3, seed=2))
    assert torch.equal(loaded.mean, model.mean) and torch.equal(loaded.codebook, model.codebook)
    data = json.loads((tmp_path / "run" / "config.json").read_text())
    assert data["format"] == "motok-tokenizer" and data["tokenizer"]["codebook_size"] == 16


def test_load_errors_name_the_file(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_tokenizer(tmp_path / "missing")
    save_tokenizer(tiny(), tmp_path / "run")
    cfg = json.loads((tmp_path / "run" / "config.json").read_text())
    cfg["tokenizer"]["codebook_size"] = 32
    (tmp_path / "run" / "config.json").write_text(json.dumps(cfg))
    with pytest.raises(InputError, match="model.safetensors"):
        load_tokenizer(tmp_path / "run")
    (tmp_path / "run" / "model.safetensors").write_bytes(b"not a safetensors file")
    with pytest.raises(InputError, match="cannot read"):
        load_tokenizer(tmp_path / "run")


def test_emphasis_projection_invertible_and_variance_preserving():
    proj = EmphasisProjection(263, (0, 1, 2, 3), c=5.0, seed=0)
    eye = torch.eye(263, dtype=torch.float64)
    assert (proj.inverse @ proj.matrix - eye).abs().max() < 1e-5
    gen = torch.Generator().manual_seed(0)
    x = torch.randn(20000, 263, generator=gen, dtype=torch.float64)
    y = proj.project(x)
    assert torch.allclose(proj.unproject(y), x, atol=1e-8)
    var = y.var(dim=0)
    # GMD: the scale sqrt(N - k + k c^2) makes the *expected* per-dimension variance 1
    assert abs(float(var.mean()) - 1.0) < 0.05
    assert float(var.min()) > 0.4 and float(var.max()) < 3.0
    # the root dims are emphasised: each carries c^2 / (N - k + k c^2) of every output's variance
    share = proj.matrix[:, :4].pow(2).sum() / proj.matrix.pow(2).sum()
    assert abs(float(share) - 100 / (259 + 100)) < 0.05
    # float32 tensors keep their dtype and round-trip closely
    x32 = torch.randn(3, 10, 263)
    assert proj.project(x32).dtype == torch.float32
    assert torch.allclose(proj.unproject(proj.project(x32)), x32, atol=1e-4)


def test_schedule_and_timesteps():
    ab = cosine_alpha_bar(1000)
    assert ab.shape == (1000,) and bool((ab[1:] < ab[:-1]).all())
    assert ab[0] > 0.999 and ab[-1] < 1e-6
    ts = ddim_timesteps(1000, 10)
    assert ts[0] == 999 and ts[-1] == 0 and len(ts) == 10


class InpaintRootHeight:
    """Trivial guidance: overwrite raw feature dim 3 (root height) with a constant at every step."""

    def __init__(self, height: float):
        self.height = height
        self.calls: list[GuidanceState] = []

    def step(self, state: GuidanceState) -> None:
        self.calls.append(state)
        feats = state.to_features(state.x0_hat)
        feats[..., 3] = self.height
        state.x0_hat = state.from_features(feats)


@pytest.mark.parametrize("overrides", [{}, {"parameterisation": "eps"}, {"emphasis": True}, {"emphasis": True, "parameterisation": "eps"}])
def test_guidance_hook_is_applied(overrides):
    model = train_steps(tiny(**overrides))
    tokens = model.encode(smooth_features(2, 32))
    free = model.decode(tokens, steps=5, seed=3)
    hook = InpaintRootHeight(0.123)
    guided = model.decode(tokens, steps=5, seed=3, guidance=hook)
    assert len(hook.calls) == 5
    assert [s.step for s in hook.calls] == list(range(5))
    assert hook.calls[0].t == 999 and hook.calls[-1].t_prev == -1
    assert hook.calls[-1].alpha_bar_prev == 1.0
    assert torch.allclose(guided[..., 3], torch.full_like(guided[..., 3], 0.123), atol=1e-4)
    assert not torch.allclose(free[..., 3], guided[..., 3], atol=1e-2)
    # the denoise closure is differentiable (for GMD-style dense guidance)
    state = hook.calls[2]
    x = state.x_t.detach().requires_grad_()
    with torch.enable_grad():
        state.denoise(x).pow(2).sum().backward()
    assert x.grad is not None and torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0


def test_callable_guidance_and_determinism():
    model = train_steps(tiny())
    tokens = torch.tensor([[1, 2, 3, 4]])
    seen = []
    a = model.decode(tokens, steps=3, seed=7, guidance=lambda state: seen.append(state.t))
    b = model.decode(tokens, steps=3, seed=7)
    c = model.decode(tokens, steps=3, seed=8)
    assert len(seen) == 3 and torch.equal(a, b) and not torch.equal(a, c)
    with pytest.raises(InputError, match="guidance"):
        model.decode(tokens, guidance=42)
    conv = tiny(decoder="conv").eval()
    with pytest.raises(InputError, match="diffusion decoder"):
        conv.decode(tokens, guidance=lambda s: None)


def test_geometric_losses_use_joints():
    model = tiny(joint_weight=1.0, velocity_weight=1.0, foot_weight=1.0)
    from motok_robot.motion.features import features_from_joints
    from motok_robot.motion.synthetic import walking_clip

    x = torch.from_numpy(features_from_joints(walking_clip(frames=33))[None]).float()  # [1, 32, 263]
    losses = model.training_losses(x, torch.Generator().manual_seed(0))
    for key in ("joints", "velocity", "foot"):
        assert key in losses and torch.isfinite(losses[key]) and losses[key] >= 0
    losses["loss"].backward()
    assert model.encoder.net[0].weight.grad is not None


def _clips(n: int, frames: int, seed: int) -> Clips:
    return Clips([f"c{i}" for i in range(n)], [smooth_features(1, frames, seed + i)[0].numpy() for i in range(n)])


@pytest.mark.parametrize("focus", [0.0, 1.5])
def test_resume_equals_uninterrupted_training(tmp_path, focus):
    train, val = _clips(4, 40, 0), _clips(2, 40, 10)
    flat = np.concatenate(train.features)
    mean, std = flat.mean(0), flat.std(0)
    tok_cfg = TokenizerConfig(**TINY)
    # with focus the draw weights measured at step 2 must come back from the step-3 checkpoint
    cfg = TrainConfig(seed=3, batch_size=2, window=16, lr=1e-3, warmup_steps=2, steps=6, steps_per_epoch=2,
                      checkpoint_every=100, val_clips=2, val_sample_steps=2, focus_errors=focus)
    full = train_tokenizer(train, val, mean, std, tmp_path / "full", tok_cfg, cfg, progress=False)
    assert full["steps"] == 6
    part = train_tokenizer(train, val, mean, std, tmp_path / "part", tok_cfg, cfg, progress=False, stop_at=3)
    assert part["steps"] == 3
    with pytest.raises(InputError, match="--resume"):
        train_tokenizer(train, val, mean, std, tmp_path / "part", tok_cfg, cfg, progress=False)
    # a kill between writing the weights and the state is detected, not silently mixed
    import shutil

    shutil.copytree(tmp_path / "part", tmp_path / "torn")
    save_tokenizer(load_tokenizer(tmp_path / "torn", device="cpu"), tmp_path / "torn", step=4)
    with pytest.raises(InputError, match="step 4 but train_state.safetensors from step 3"):
        train_tokenizer(train, val, mean, std, tmp_path / "torn", resume=True, progress=False)
    resumed = train_tokenizer(train, val, mean, std, tmp_path / "part", resume=True, progress=False)
    assert resumed["steps"] == 6
    a = load_file(str(tmp_path / "full" / "model.safetensors"))
    b = load_file(str(tmp_path / "part" / "model.safetensors"))
    assert a.keys() == b.keys()
    for key in a:
        assert torch.equal(a[key], b[key]), key
    rows_a = (tmp_path / "full" / "metrics.csv").read_text().splitlines()
    rows_b = (tmp_path / "part" / "metrics.csv").read_text().splitlines()
    assert len(rows_a) == 4  # header + 3 epochs
    strip = lambda rows: [",".join(r.split(",")[:-1]) for r in rows]  # noqa: E731 - drop wall time
    assert strip(rows_a) == strip(rows_b)
    focus_columns = [r.split(",")[-3:-1] for r in rows_a[1:]]
    if focus:  # measured after epochs 1 and 2 (not after the last)
        assert all(float(v) > 0 for row in focus_columns[:2] for v in row) and focus_columns[2] == ["", ""]
        assert "focus" in load_file(str(tmp_path / "part" / "train_state.safetensors"))
    else:
        assert all(row == ["", ""] for row in focus_columns)
    # same seed, new run: deterministic
    again = train_tokenizer(train, val, mean, std, tmp_path / "again", tok_cfg, cfg, progress=False)
    assert again["steps"] == 6
    c = load_file(str(tmp_path / "again" / "model.safetensors"))
    assert all(torch.equal(a[k], c[k]) for k in a)


def test_window_sampler_pads_short_clips_and_weights_by_length():
    from motok_robot.tokenizer.train import WindowSampler

    short = np.arange(10 * 263, dtype=np.float32).reshape(10, 263)
    long = -np.ones((100, 263), dtype=np.float32)
    tiny_clip = np.zeros((3, 263), dtype=np.float32)
    sampler = WindowSampler(Clips(["s", "l", "t"], [short, long, tiny_clip]), window=32, min_frames=8)
    assert sampler.skipped == 1 and sampler.padded == 1
    x, mask = sampler.sample(400, torch.Generator().manual_seed(0))
    assert x.shape == (400, 32, 263) and mask.shape == (400, 32) and mask.dtype == torch.bool
    is_short = x[:, 0, 0] >= 0
    assert torch.all(mask[is_short].sum(1) == 10) and torch.all(mask[~is_short])
    assert torch.equal(x[is_short][:, 10:], x[is_short][:, 9:10].expand(-1, 22, -1))  # last frame repeated
    # drawn in proportion to max(frames, window): 32 : 100
    assert abs(float(is_short.float().mean()) - 32 / 132) < 0.06


def test_decoder_finetune_keeps_every_token(tmp_path):
    """--init-from RUN --freeze-tokens: the decoder side trains, the encoder and codebook do not,
    so every clip keeps its tokens (and the token digest) while its reconstruction changes."""
    train, val = _clips(4, 40, 0), _clips(2, 40, 10)
    flat = np.concatenate(train.features)
    mean, std = flat.mean(0), flat.std(0)
    base_cfg = TrainConfig(seed=3, batch_size=2, window=16, lr=1e-3, warmup_steps=2, steps=4, steps_per_epoch=2,
                           checkpoint_every=100, val_clips=2, val_sample_steps=2)
    train_tokenizer(train, val, mean, std, tmp_path / "base", TokenizerConfig(**TINY), base_cfg, progress=False)
    # other statistics on purpose: the source's normalisation must win, or the tokens would move
    ft_cfg = TrainConfig(**{**base_cfg.__dict__, "init_from": str(tmp_path / "base"), "freeze_tokens": True, "steps": 6})
    train_tokenizer(train, val, mean + 1.0, std * 2.0, tmp_path / "ft", None, ft_cfg, progress=False, stop_at=3)
    train_tokenizer(train, val, mean, std, tmp_path / "ft", resume=True, progress=False)  # stays frozen on resume
    base, ft = load_tokenizer(tmp_path / "base", device="cpu"), load_tokenizer(tmp_path / "ft", device="cpu")
    assert json.loads((tmp_path / "ft" / "config.json").read_text())["tokenizer"] == json.loads(
        (tmp_path / "base" / "config.json").read_text())["tokenizer"]
    a, b = base.state_dict(), ft.state_dict()
    frozen = set(base.token_tensors())
    assert frozen >= {"mean", "std", "quantizer.codebook"} and any(k.startswith("encoder.") for k in frozen)
    for key in frozen | {"quantizer.ema_count", "quantizer.ema_sum"}:
        assert torch.equal(a[key], b[key]), key
    changed = [k for k in a if k.startswith(("cond_decoder.", "denoiser.")) and not torch.equal(a[k], b[k])]
    assert changed, "the decoder side did not train"
    assert base.tokens_digest() == ft.tokens_digest()
    x = torch.from_numpy(np.stack([c[:40] for c in val.features]))
    assert torch.equal(base.encode(x), ft.encode(x))
    assert not torch.allclose(base.decode(base.encode(x), length=40, seed=0), ft.decode(ft.encode(x), length=40, seed=0))
    # a tokenizer trained on its own gets another digest
    other = TrainConfig(**{**base_cfg.__dict__, "seed": 4})
    train_tokenizer(train, val, mean, std, tmp_path / "other", TokenizerConfig(**TINY), other, progress=False)
    assert load_tokenizer(tmp_path / "other", device="cpu").tokens_digest() != base.tokens_digest()


def test_decoder_finetune_errors(tmp_path):
    train = _clips(2, 40, 0)
    flat = np.concatenate(train.features)
    with pytest.raises(InputError, match="freeze_tokens needs init_from"):
        TrainConfig(freeze_tokens=True)
    cfg = TrainConfig(steps=1, batch_size=2, window=16, init_from=str(tmp_path / "missing"), freeze_tokens=True)
    with pytest.raises(InputError, match="not a tokenizer run"):
        train_tokenizer(train, None, flat.mean(0), flat.std(0), tmp_path / "ft", None, cfg, progress=False)
    save_tokenizer(tiny(), tmp_path / "src")
    cfg = TrainConfig(steps=1, batch_size=2, window=16, init_from=str(tmp_path / "src"))
    with pytest.raises(InputError, match="keeps its architecture"):
        train_tokenizer(train, None, flat.mean(0), flat.std(0), tmp_path / "ft", TokenizerConfig(**{**TINY, "width": 64}),
                        cfg, progress=False)


def test_focus_factors_weigh_clips_by_their_relative_error():
    from motok_robot.tokenizer.train import focus_factors

    errors = np.array([1.0, 1.0, 2.0, 4.0, 40.0])  # mean 9.6
    f = focus_factors(errors, power=1.0, cap=10.0)
    assert np.allclose(f[:4], np.array([1.0, 1.0, 2.0, 4.0]) / 9.6) and f[4] == pytest.approx(40 / 9.6)
    g = focus_factors(errors, power=2.0, cap=4.0)  # clamped to [1/4, 4]
    assert np.allclose(g, [0.25, 0.25, 0.25, 0.25, 4.0])
    assert np.array_equal(focus_factors(errors, power=0.0, cap=10.0), np.ones(5))
    for bad in ([], [1.0, np.nan], [1.0, -2.0]):
        with pytest.raises(InputError, match="clip errors must be finite"):
            focus_factors(np.array(bad), 1.0, 10.0)


def test_window_sampler_draws_hard_clips_more_often_with_focus():
    from motok_robot.tokenizer.train import WindowSampler, focus_factors

    features = [np.full((40, 263), i, dtype=np.float32) for i in range(4)]
    sampler = WindowSampler(Clips([f"c{i}" for i in range(4)], features), window=32)
    gen = torch.Generator().manual_seed(0)
    sampler.set_focus(focus_factors(np.array([1.0, 1.0, 1.0, 5.0]), 2.0, 10.0))  # 0.25 x 3 against 6.25
    x, _ = sampler.sample(4000, gen)
    assert abs(float((x[:, 0, 0] == 3).float().mean()) - 6.25 / 7.0) < 0.03
    with pytest.raises(InputError, match="focus needs 4 positive finite factors"):
        sampler.set_focus(np.array([1.0, 0.0, 1.0, 1.0]))
    with pytest.raises(InputError, match="focus needs 4"):
        sampler.set_focus(np.ones(3))


def test_clip_errors_are_deterministic_root_relative_and_keep_the_mode():
    from motok_robot.motion.features_torch import joints_from_features
    from motok_robot.tokenizer.train import clip_errors

    model = train_steps(tiny())
    model.train()
    clips = [smooth_features(1, 24, seed)[0].numpy() for seed in (1, 2)]
    errors = clip_errors(model, clips, progress=False)
    assert model.training and errors.shape == (2,) and np.all(errors > 0)
    assert np.array_equal(errors, clip_errors(model, clips, progress=False))  # noise seed fixed, eval mode
    # the number is the mean joint distance (cm) after both skeletons are moved to their root joint
    x = torch.from_numpy(clips[1][None])
    model.eval()
    j, jh = joints_from_features(x), joints_from_features(model.reconstruct(x, steps=1, seed=0))
    expected = float(((jh - jh[:, :, :1]) - (j - j[:, :, :1])).norm(dim=-1).mean()) * 100
    assert errors[1] == pytest.approx(expected, rel=1e-4)


@pytest.mark.parametrize("field, value, match", [("focus_errors", -1.0, "focus_errors must be within 0..4"),
                                                 ("focus_errors", 5.0, "focus_errors must be within 0..4"),
                                                 ("focus_cap", 0.5, "focus_cap must be >= 1")])
def test_train_config_rejects_bad_focus(field, value, match):
    with pytest.raises(InputError, match=match):
        TrainConfig(**{field: value})


def test_only_actions_trains_on_the_clips_of_those_labels(tmp_path):
    groups = [("action", "bow"), ("action", "walk"), ("text", "a person waves"), ("action", "bow")]
    train = Clips([f"c{i}" for i in range(4)], [smooth_features(1, 40, i)[0].numpy() for i in range(4)], groups)
    bows = train.with_actions(("bow",), "train")
    assert bows.ids == ["c0", "c3"] and bows.groups == [("action", "bow")] * 2
    assert train.with_actions(("bow", "walk"), "train").ids == ["c0", "c1", "c3"]
    with pytest.raises(InputError, match=r"train split has no clip of action \['jump'\] \(labels there: bow, walk\)"):
        train.with_actions(("bow", "jump"), "train")
    assert train.with_actions(("jump",), "val", required=False).ids == []  # a val split may lack the label
    flat = np.concatenate(train.features)
    cfg = TrainConfig(batch_size=2, window=16, steps=2, steps_per_epoch=2, val_clips=2, val_sample_steps=2,
                      only_actions=("bow",))
    summary = train_tokenizer(train, train, flat.mean(0), flat.std(0), tmp_path / "run", TokenizerConfig(**TINY), cfg,
                              progress=False)
    assert summary["train_clips"] == 2
    saved = json.loads((tmp_path / "run" / "config.json").read_text())["train"]
    assert saved["only_actions"] == ["bow"]  # a resumed run filters the same way
    with pytest.raises(InputError, match="only_actions must be a list of action labels"):
        TrainConfig(only_actions="bow")


def test_action_share_is_saved_with_the_run_and_checked_against_the_train_labels(tmp_path):
    groups = [("action", "bow"), ("action", "walk"), ("text", "a person waves"), ("action", "walk")]
    train = Clips([f"c{i}" for i in range(4)], [smooth_features(1, 40, i)[0].numpy() for i in range(4)], groups)
    flat = np.concatenate(train.features)
    cfg = TrainConfig(batch_size=2, window=16, steps=2, steps_per_epoch=2, val_clips=2, val_sample_steps=2,
                      action_share={"bow": 0.5})
    summary = train_tokenizer(train, train, flat.mean(0), flat.std(0), tmp_path / "run", TokenizerConfig(**TINY), cfg,
                              progress=False)
    assert summary["train_clips"] == 4  # every clip still trains
    saved = json.loads((tmp_path / "run" / "config.json").read_text())["train"]
    assert saved["action_share"] == {"bow": 0.5}  # a resumed run draws the same way
    bad = TrainConfig(batch_size=2, window=16, steps=2, action_share={"kick": 0.1})
    with pytest.raises(InputError, match=r"train split: action_share names 'kick', which no clip has \(labels there: bow, walk\)"):
        train_tokenizer(train, None, flat.mean(0), flat.std(0), tmp_path / "bad", TokenizerConfig(**TINY), bad,
                        progress=False)
