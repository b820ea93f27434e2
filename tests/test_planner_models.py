"""Planner models: overfitting, guidance, causality, inpainting, local-condition alignment."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from motok_robot.errors import InputError
from motok_robot.planner.autoregressive import ARPlanner
from motok_robot.planner.checkpoint import build_planner
from motok_robot.planner.conditions import Conditions, LocalConditions, random_local_conditions, stack_local
from motok_robot.planner.config import ControlConfig, PlannerConfig
from motok_robot.planner.masked import MaskedPlanner
from motok_robot.planner.sampling import filter_logits, guided_logits

torch.set_num_threads(1)

K, D, N = 16, 8, 12


def tiny(kind: str, **kw) -> PlannerConfig:
    base = dict(kind=kind, codebook_size=K, downsample=4, max_frames=4 * 16, width=64, layers=2, heads=4,
                ff_mult=2, dropout=0.0, text_dim=D, local_hidden=16, length_hidden=32)
    base.update(kw)
    return PlannerConfig(**base)


def _data(n_seq: int = 4):
    gen = torch.Generator().manual_seed(0)
    tokens = torch.randint(0, K, (n_seq, N), generator=gen)
    emb = torch.randn(n_seq, D, generator=gen)
    lengths = torch.tensor([N, N, 9, 6][:n_seq])
    return tokens, emb, lengths


def _overfit(kind: str, steps: int = 300):
    torch.manual_seed(0)
    model = build_planner(tiny(kind))
    tokens, emb, lengths = _data()
    opt = torch.optim.Adam(model.parameters(), lr=3e-3)
    gen = torch.Generator().manual_seed(0)
    cond = Conditions(text_embedding=emb)
    for _ in range(steps):
        out = model.loss(tokens, lengths, cond, gen)
        loss = out["loss"] + model.length_estimator.loss(emb, lengths)
        opt.zero_grad()
        loss.backward()
        opt.step()
    return model.eval(), tokens, emb, lengths


@pytest.fixture(scope="module")
def masked_fit():
    return _overfit("masked")


@pytest.fixture(scope="module")
def ar_fit():
    return _overfit("ar")


def _expected(tokens, lengths):
    out = tokens.clone()
    for i, n in enumerate(lengths.tolist()):
        out[i, n:] = -1
    return out


@pytest.mark.slow  # 7-13 s per planner
@pytest.mark.parametrize("fit", ["masked_fit", "ar_fit"])
def test_tiny_planner_overfits_token_sequences(fit, request):
    model, tokens, emb, lengths = request.getfixturevalue(fit)
    planned = model.plan(Conditions(text_embedding=emb), lengths, seed=0, temperature=0.0, cfg_scale=1.0)
    assert torch.equal(planned, _expected(tokens, lengths)[:, : int(lengths.max())])
    # sampled (temperature 1) plans also reproduce memorised data, and the length estimator learned the lengths
    sampled = model.plan(Conditions(text_embedding=emb), lengths, seed=3, temperature=1.0)
    assert (sampled == _expected(tokens, lengths)).float().mean() > 0.9
    assert torch.equal(model.length_estimator.predict(emb), lengths)


def test_ar_planner_stops_at_its_end_token(ar_fit):
    model, tokens, emb, lengths = ar_fit
    planned = model.plan(Conditions(text_embedding=emb), None, seed=0, temperature=0.0)
    assert torch.equal(planned, _expected(tokens, lengths)[:, : int(lengths.max())])


def test_masked_predicts_length_from_text_when_not_given(masked_fit):
    model, tokens, emb, lengths = masked_fit
    planned = model.plan(Conditions(text_embedding=emb), None, seed=0, temperature=0.0)
    assert torch.equal((planned >= 0).sum(1), lengths)


@pytest.mark.parametrize("fit", ["masked_fit", "ar_fit"])
def test_cfg_scale_one_equals_conditional_sampling(fit, request):
    model, tokens, emb, lengths = request.getfixturevalue(fit)
    cond = Conditions(text_embedding=emb)
    plain = model.plan(cond, N, seed=5, temperature=1.0, cfg_scale=1.0)
    guided_one = model.plan(cond, N, seed=5, temperature=1.0, cfg_scale=1.0, always_guide=True)
    assert torch.equal(plain, guided_one)
    # a real guidance scale changes the distribution (cond and null branches differ after training)
    strong = [model.plan(cond, N, seed=s, temperature=1.0, cfg_scale=0.0) for s in range(3)]
    assert any(not torch.equal(p, plain) for p in strong)


def test_guided_logits_formula():
    c, u = torch.randn(3, 7), torch.randn(3, 7)
    assert torch.equal(guided_logits(c, u, 1.0), c)
    assert torch.allclose(guided_logits(c, u, 0.0), u)
    assert torch.allclose(guided_logits(c, u, 3.0), u + 3.0 * (c - u), atol=1e-6)


@pytest.mark.parametrize("every, end", [(False, False), (True, False), (False, True)])
def test_autoregressive_logits_are_causal(every, end):
    torch.manual_seed(1)
    model = ARPlanner(tiny("ar", global_every_position=every, end_embedding=end)).eval()
    if end:  # a trained (non-zero) end embedding; the length is a condition, not a later token
        with torch.no_grad():
            model.end_embedding.weight.normal_()
    with torch.no_grad():  # make the (zero-initialised) local path active
        for p in model.local_encoder.out.parameters():
            p.normal_()
    frames = N * 4
    traj = np.cumsum(np.random.default_rng(0).normal(size=(frames, 2)) * 0.05, axis=0)
    cond = Conditions(text_embedding=torch.randn(1, D), local=LocalConditions.from_arrays(frames, trajectory=traj))
    a = torch.randint(0, K, (1, N))
    for i in (0, 3, 7, N - 2):
        b = a.clone()
        b[:, i + 1:] = torch.randint(0, K, (1, N - i - 1))
        length = torch.tensor([N]) if end else None
        la, lb = model.logits(a, cond, N, lengths=length), model.logits(b, cond, N, lengths=length)
        # output j predicts token j (0-based) from tokens < j: outputs 0..i+1 only see tokens 0..i
        assert torch.allclose(la[:, : i + 2], lb[:, : i + 2], atol=1e-5), i
        assert not torch.allclose(la[:, i + 2:], lb[:, i + 2:], atol=1e-5)


@pytest.mark.parametrize("every, end", [(False, False), (True, False), (False, True)])
@pytest.mark.parametrize("cfg_scale", [1.0, 2.5])
def test_ar_cached_sampling_matches_full_logits(every, end, cfg_scale):
    """Greedy sampling with the key/value cache picks, at every position, the argmax of the full
    (uncached) forward pass on the tokens it drew: both paths condition each token the same way
    (with ``end_embedding``, on the count of tokens still to draw)."""
    torch.manual_seed(3)
    model = ARPlanner(tiny("ar", global_every_position=every, end_embedding=end)).eval()
    if end:
        with torch.no_grad():
            model.end_embedding.weight.normal_()
    cond = Conditions(text_embedding=torch.randn(2, D))
    tokens = model.plan(cond, n_tokens=10, seed=0, cfg_scale=cfg_scale, temperature=0.0)
    length = torch.tensor([10, 10]) if end else None
    with torch.no_grad():
        logits = model.logits(tokens, cond, lengths=length)[:, :10]
        if cfg_scale != 1.0:
            logits = guided_logits(logits, model.logits(tokens, cond.without_global(), lengths=length)[:, :10],
                                   cfg_scale)
    logits[..., model.end_id] = float("-inf")
    assert torch.equal(logits.argmax(-1), tokens)


def test_global_every_position_is_for_the_ar_planner():
    with pytest.raises(InputError, match="global_every_position is for the AR planner"):
        tiny("masked", global_every_position=True).validate()


def test_ar_local_features_sit_at_the_preceding_position():
    """A constraint on the frames of token t changes the prediction of token t, not of earlier tokens."""
    torch.manual_seed(2)
    model = ARPlanner(tiny("ar")).eval()
    with torch.no_grad():
        for p in model.local_encoder.out.parameters():
            p.normal_()
    frames, t = N * 4, 5
    traj = np.full((frames, 2), np.nan)
    traj[t * 4: (t + 1) * 4] = [1.0, 0.5]
    tokens = torch.randint(0, K, (1, N))
    text = torch.randn(1, D)
    free = model.logits(tokens, Conditions(text_embedding=text, local=LocalConditions.empty(1, frames)), N)
    held = model.logits(tokens, Conditions(text_embedding=text, local=LocalConditions.from_arrays(frames, trajectory=traj)), N)
    assert torch.allclose(free[:, :t], held[:, :t], atol=1e-6)
    assert not torch.allclose(free[:, t], held[:, t], atol=1e-4)


def test_masked_sampling_keeps_given_tokens_exactly():
    torch.manual_seed(3)
    model = MaskedPlanner(tiny("masked")).eval()
    gen = torch.Generator().manual_seed(0)
    keep = torch.randint(0, K, (2, N), generator=gen)
    mask = torch.rand(2, N, generator=gen) < 0.5
    keep_tokens = torch.where(mask, keep, torch.full_like(keep, -1))
    for seed in range(3):
        out = model.plan(Conditions(text_embedding=torch.randn(2, D)), N, seed=seed, cfg_scale=2.0,
                         keep_tokens=keep_tokens, steps=6)
        assert torch.equal(out[mask], keep[mask])
        assert ((out >= 0) & (out < K)).all()
    with pytest.raises(InputError, match="kept ids"):
        model.plan(Conditions(text_embedding=torch.randn(1, D)), N, keep_tokens=torch.full((N,), K + 3))


@pytest.mark.parametrize("kind", ["masked", "ar"])
def test_plan_is_seeded(kind):
    torch.manual_seed(4)
    model = build_planner(tiny(kind)).eval()
    cond = Conditions(text_embedding=torch.randn(2, D))
    a = model.plan(cond, N, seed=7, cfg_scale=2.0)
    assert torch.equal(a, model.plan(cond, N, seed=7, cfg_scale=2.0))
    assert not torch.equal(a, model.plan(cond, N, seed=8, cfg_scale=2.0))
    assert a.shape == (2, N) and a.dtype == torch.long


@pytest.mark.parametrize("kind", ["masked", "ar"])
def test_action_and_null_conditions(kind):
    model = build_planner(tiny(kind, action_labels=["walk", "run"])).eval()
    out = model.plan(Conditions(action=torch.tensor([0, 1])), 4, seed=0)
    assert out.shape == (2, 4)
    out = model.plan(Conditions(batch=3), 4, seed=0)
    assert out.shape == (3, 4)
    g = model.global_encoder
    assert torch.equal(g(Conditions(batch=2)), model.global_encoder.null.expand(2, -1))
    with pytest.raises(InputError, match="out of range"):
        model.plan(Conditions(action=torch.tensor([2])), 4)
    with pytest.raises(InputError, match="n_tokens"):
        model.plan(Conditions(batch=1), model.config.max_tokens + 1)


def test_local_encoder_is_token_aligned_and_zero_where_unconstrained():
    model = MaskedPlanner(tiny("masked"))
    with torch.no_grad():
        for p in model.local_encoder.out.parameters():
            p.normal_()
    frames = N * 4
    traj = np.full((frames, 3), np.nan)
    traj[8:12, :2] = 0.3  # frames of token 2
    local = LocalConditions.from_arrays(frames, trajectory=traj)
    m_s = model.local_encoder(local, N)
    assert m_s.shape == (1, N, 64)
    nonzero = m_s.abs().sum(-1)[0] > 0
    assert nonzero.tolist() == [i == 2 for i in range(N)]


def test_random_local_conditions_cover_every_mode():
    rng = np.random.default_rng(0)
    joints = np.random.default_rng(1).normal(size=(40, 22, 3)).astype(np.float32)
    seen = set()
    for _ in range(60):
        lc = random_local_conditions(joints, ControlConfig(), rng)
        root, jm = lc.root_mask[0].sum().item(), lc.joint_mask[0]
        if root:
            assert torch.allclose(lc.root[0, :, :2], torch.from_numpy(joints[:, 0, :2]))
            seen.add("root")
        elif jm.sum() == 0:
            seen.add("none")
        elif (jm.sum(0) == 40).any():
            seen.add("joints")
        else:
            seen.add("keyframes")
        given = jm.bool()
        assert torch.allclose(lc.joints[0][given], torch.from_numpy(joints)[given])
    assert seen == {"root", "none", "joints", "keyframes"}
    both = stack_local([lc, lc])
    assert both.batch_size == 2


def test_local_condition_validation():
    with pytest.raises(InputError, match="trajectory"):
        LocalConditions.from_arrays(10, trajectory=np.zeros((10, 4)))
    with pytest.raises(InputError, match="frames"):
        LocalConditions.from_arrays(10, trajectory=np.zeros((9, 2)))
    with pytest.raises(InputError, match="joint targets"):
        LocalConditions.from_arrays(10, joints=np.zeros((10, 21, 3)))
    with pytest.raises(InputError, match="more than"):
        LocalConditions.empty(1, 20).fit_frames(10)


def test_top_k_top_p_filtering():
    logits = torch.tensor([[4.0, 3.0, 2.0, 1.0, 0.0]])
    assert torch.isinf(filter_logits(logits, top_k=2)[0, 2:]).all()
    assert torch.isfinite(filter_logits(logits, top_k=2)[0, :2]).all()
    p = logits.softmax(-1)[0]
    kept = torch.isfinite(filter_logits(logits, top_p=float(p[0]) + 1e-3)[0])
    assert kept.tolist() == [True, True, False, False, False]


def test_action_labels_from_index_records():
    from motok_robot.data.groups import clip_action

    assert clip_action({"action": " wave "}) == "wave"
    assert clip_action({"label": "kick", "source": "bandai"}) == "kick"
    assert clip_action({"source": "bandai", "file": "/d/dataset-2_wave-right-hand_active_003.bvh"}) == "wave-right-hand"
    assert clip_action({"source": "cmu", "file": "/d/01_01.amc"}) is None
    # a mirrored clip shows the other side, as its texts say
    mirror = {"source": "bandai", "file": "/d/dataset-1_walk-turn-left_normal_001.bvh", "mirror_of": "bandai/x"}
    assert clip_action(mirror) == "walk-turn-right"
    assert clip_action({"label": "raise-up-Right-hand", "mirror_of": "cmu/y"}) == "raise-up-left-hand"
    assert clip_action({"action": "wave", "mirror_of": "cmu/y"}) == "wave"


def test_ar_input_corruption_changes_inputs_not_targets(monkeypatch):
    """With ``corruption`` the AR loss sees some random input codes (about the asked fraction),
    never touches padding, and still scores the real next tokens."""
    torch.manual_seed(0)
    model = ARPlanner(tiny("ar")).eval()
    tokens, emb, lengths = _data()
    cond = Conditions(text_embedding=emb)
    seen = {}
    real_logits = model.logits

    def spy(inputs, *a, **kw):
        seen["inputs"] = inputs.clone()
        return real_logits(inputs, *a, **kw)

    monkeypatch.setattr(model, "logits", spy)
    plain = model.loss(tokens, lengths, cond, torch.Generator().manual_seed(0))
    plain_inputs = seen["inputs"]
    valid = torch.arange(N)[None] < lengths[:, None]
    assert torch.equal(plain_inputs[valid], tokens[valid])
    swapped = []
    for seed in range(20):
        corrupted = model.loss(tokens, lengths, cond, torch.Generator().manual_seed(seed), corruption=0.9)
        inputs = seen["inputs"]
        assert torch.equal(inputs[~valid], plain_inputs[~valid])  # padding stays padding
        assert int(inputs[valid].max()) < K  # random codes are real codes, never [END] or [PAD]
        swapped.append(float((inputs[valid] != tokens[valid]).float().mean()))
        assert corrupted["count"] == plain["count"]  # the same targets are scored
    # U(0, 0.9) per sample, minus the 1/K chance of drawing the same code: mean about 0.42
    assert 0.25 < np.mean(swapped) < 0.6, np.mean(swapped)


def test_training_switches_are_checked(tmp_path):
    from motok_robot.planner.train import train_planner

    with pytest.raises(InputError, match="input_corruption is for the AR planner"):
        train_planner(tmp_path / "none", tmp_path / "none", "masked", tmp_path / "run", train_overrides={"input_corruption": 0.3})
    with pytest.raises(InputError, match=r"input_corruption must be in \[0, 1\)"):
        train_planner(tmp_path / "none", tmp_path / "none", "ar", tmp_path / "run", train_overrides={"input_corruption": 1.5})
    with pytest.raises(InputError, match="masked_loss_average must be 'token' or 'sample'"):
        train_planner(tmp_path / "none", tmp_path / "none", "masked", tmp_path / "run", train_overrides={"masked_loss_average": "clip"})
    with pytest.raises(InputError, match="masked_loss_average is for the masked planner"):
        train_planner(tmp_path / "none", tmp_path / "none", "ar", tmp_path / "run", train_overrides={"masked_loss_average": "sample"})


def test_token_conv_does_not_read_padding():
    """With ``token_conv_kernel`` padding past a sample's length reads as the sequence's end
    (zero), so a padded sample equals the same sample alone; the kernel is checked."""
    torch.manual_seed(0)
    model = MaskedPlanner(tiny("masked", token_conv_kernel=3)).eval()
    torch.nn.init.normal_(model.token_conv.weight, std=0.3)
    emb = torch.randn(1, D)
    tokens = torch.randint(0, K, (1, 6))
    alone = model.logits(tokens, torch.tensor([6]), Conditions(text_embedding=emb))
    padded = torch.cat([tokens, torch.full((1, 4), model.pad_id)], dim=1)
    batch = model.logits(padded, torch.tensor([6]), Conditions(text_embedding=emb))
    torch.testing.assert_close(batch[:, :6], alone, atol=1e-5, rtol=1e-5)
    for bad, kind, match in ((4, "masked", "0 or odd"), (-1, "masked", "0 or odd"), (3, "ar", "masked planner only")):
        with pytest.raises(InputError, match=match):
            tiny(kind, token_conv_kernel=bad).validate()


def test_masked_loss_per_sample_weighs_every_sample_equally():
    """``per_sample``: the mean over samples of each sample's mean masked-token cross-entropy
    (recomputed here from the same mask draws); the default is the mean over all masked tokens."""
    import torch.nn.functional as F

    from motok_robot.planner.sampling import cosine_mask_ratio

    torch.manual_seed(0)
    model = MaskedPlanner(tiny("masked")).eval()
    tokens, emb, lengths = _data()
    cond = Conditions(text_embedding=emb)
    per_sample = model.loss(tokens, lengths, cond, torch.Generator().manual_seed(5), per_sample=True)
    pooled = model.loss(tokens, lengths, cond, torch.Generator().manual_seed(5))
    g = torch.Generator().manual_seed(5)  # the draws of MaskedPlanner.loss, in its order
    b, n = tokens.shape
    valid = torch.arange(n)[None] < lengths[:, None]
    n_mask = torch.minimum(torch.ceil(cosine_mask_ratio(torch.rand(b, generator=g)) * lengths).clamp(min=1).long(), lengths)
    rank = torch.rand(b, n, generator=g).masked_fill(~valid, 2.0).argsort(1).argsort(1)
    masked = (rank < n_mask[:, None]) & valid
    inputs = torch.where(masked, torch.full_like(tokens, model.mask_id), tokens).masked_fill(~valid, model.pad_id)
    ce = F.cross_entropy(model.logits(inputs, lengths, cond).transpose(1, 2), tokens, reduction="none")
    assert len(set(masked.sum(1).tolist())) > 1  # samples differ in how many tokens are masked
    torch.testing.assert_close(per_sample["loss"], torch.stack([ce[i][masked[i]].mean() for i in range(b)]).mean())
    torch.testing.assert_close(pooled["loss"], ce[masked].mean())
    assert not torch.isclose(per_sample["loss"], pooled["loss"])
    assert float(per_sample["accuracy"]) == float(pooled["accuracy"])


def test_token_conv_defaults_per_kind_and_old_runs_load_without_it(tmp_path):
    import json

    from motok_robot.planner.checkpoint import load_planner, save_planner_weights, write_run_config
    from motok_robot.planner.config import MASKED_TOKEN_CONV_KERNEL

    assert PlannerConfig(kind="masked").validate().token_conv_kernel == MASKED_TOKEN_CONV_KERNEL
    assert PlannerConfig(kind="ar").validate().token_conv_kernel == 0
    model = build_planner(tiny("masked", token_conv_kernel=0))
    save_planner_weights(model, tmp_path)
    write_run_config(tmp_path, model.config, {})
    data = json.loads((tmp_path / "config.json").read_text())
    del data["planner"]["token_conv_kernel"]  # a run written before the field existed
    (tmp_path / "config.json").write_text(json.dumps(data))
    loaded, _ = load_planner(tmp_path)
    assert loaded.token_conv is None and loaded.config.token_conv_kernel == 0


@pytest.mark.slow  # about 10 s
def test_end_embedding_tells_the_masked_planner_where_the_motion_ends():
    """Each token gets the embedding of its distance to the end (``ends`` False, a crop that stops
    mid-clip: the "end unknown" entry), and a tiny planner with it learns sequences of 5-12 tokens
    that end with code 2 after codes 1, at every length."""
    torch.manual_seed(0)
    model = build_planner(tiny("masked", token_conv_kernel=0, end_embedding=True))
    seen = []
    model.end_embedding.register_forward_hook(lambda module, args, out: seen.append(args[0].clone()))
    cond = Conditions(text_embedding=torch.ones(2, D))
    model.logits(torch.full((2, 5), model.mask_id), torch.tensor([3, 5]), cond, ends=torch.tensor([True, False]))
    unknown = model.config.max_tokens
    assert seen[0].tolist() == [[2, 1, 0, 0, 0], [unknown] * 5]  # past the length: padding, never attended to
    model.logits(torch.full((1, 4), model.mask_id), torch.tensor([4]), cond.select(torch.tensor([0])))
    assert seen[1].tolist() == [[3, 2, 1, 0]]  # sampling: the end is known

    lengths = torch.arange(5, 13)
    tokens = torch.ones(len(lengths), 12, dtype=torch.long)
    tokens[torch.arange(len(lengths)), lengths - 1] = 2
    cond = Conditions(text_embedding=torch.ones(len(lengths), D))
    opt = torch.optim.Adam(model.parameters(), lr=3e-3)
    gen = torch.Generator().manual_seed(0)
    for _ in range(200):
        loss = model.loss(tokens, lengths, cond, gen, ends=torch.ones(len(lengths), dtype=torch.bool))["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
    model.eval()
    planned = model.plan(cond, lengths, seed=0, temperature=0.0, cfg_scale=1.0, steps=1)
    assert torch.equal(planned, _expected(tokens, lengths))


def test_end_embedding_tells_the_ar_planner_how_many_tokens_are_left():
    """The position that predicts token ``i`` (1-based) gets the count of tokens still to draw,
    ``length - i + 1`` (0 at the [END] position; "end unknown" for a crop that stops mid-clip or
    when no length is given), and a tiny AR planner with it learns sequences of 5-12 tokens that
    end with code 2 after codes 1: asked for a length, it draws the 2 exactly at the end, which
    the position embedding alone cannot tell it (the text is the same for every length)."""
    torch.manual_seed(0)
    model = build_planner(tiny("ar", end_embedding=True))
    # it starts small, like the position embedding, so no length outweighs the text at first
    assert float(model.end_embedding.weight.detach().std()) == pytest.approx(0.02, rel=0.2)
    seen = []
    model.end_embedding.register_forward_hook(lambda module, args, out: seen.append(args[0].clone()))
    cond = Conditions(text_embedding=torch.ones(2, D))
    model.logits(torch.zeros(2, 5, dtype=torch.long), cond, lengths=torch.tensor([3, 5]), ends=torch.tensor([True, False]))
    unknown = model.config.max_tokens + 1
    assert seen[0].tolist() == [[3, 2, 1, 0, 0, 0], [unknown] * 6]
    model.logits(torch.zeros(1, 2, dtype=torch.long), cond.select(torch.tensor([0])))
    assert seen[1].tolist() == [[unknown] * 3]

    lengths = torch.arange(5, 13)
    tokens = torch.ones(len(lengths), 12, dtype=torch.long)
    tokens[torch.arange(len(lengths)), lengths - 1] = 2
    cond = Conditions(text_embedding=torch.ones(len(lengths), D))
    opt = torch.optim.Adam(model.parameters(), lr=3e-3)
    gen = torch.Generator().manual_seed(0)
    for _ in range(200):
        loss = model.loss(tokens, lengths, cond, gen)["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
    model.eval()
    planned = model.plan(cond, lengths, seed=0, temperature=0.0, cfg_scale=1.0)
    assert torch.equal(planned, _expected(tokens, lengths))
    # the same planner without its end embedding's help (all "unknown") cannot place the 2
    del seen[:]
    blind = model.plan(cond, None, seed=0, temperature=0.0, cfg_scale=1.0)
    assert all((row == unknown).all() for row in seen)
    assert not torch.equal(blind, _expected(tokens, lengths)[:, : blind.shape[1]])


def test_end_horizon_hides_counts_beyond_it():
    """With ``end_horizon`` 3 every count of tokens still to draw above 3 is shown as one entry
    (4), so the first positions of a long clip look the same whatever its length; near the end
    the count is exact, and "end unknown" stays its own entry."""
    model = build_planner(tiny("ar", end_embedding=True, end_horizon=3))
    seen = []
    model.end_embedding.register_forward_hook(lambda module, args, out: seen.append(args[0].clone()))
    cond = Conditions(text_embedding=torch.ones(2, D))
    model.logits(torch.zeros(2, 7, dtype=torch.long), cond, lengths=torch.tensor([7, 6]), ends=torch.tensor([True, False]))
    assert seen[0].tolist() == [[4, 4, 4, 4, 3, 2, 1, 0], [model.config.max_tokens + 1] * 8]
    with torch.no_grad():  # a trained embedding: the first logits differ between lengths 9 and 12 only without a cap
        model.end_embedding.weight.normal_()
    model.eval()
    one = cond.select(torch.tensor([0]))
    for horizon, same in ((3, True), (0, False)):
        model.config.end_horizon = horizon
        a, b = (model.logits(torch.zeros(1, 2, dtype=torch.long), one, lengths=torch.tensor([n]))[:, :3] for n in (9, 12))
        assert torch.allclose(a, b, atol=1e-6) == same, horizon
    # sampling with a length shows the same capped counts
    model.config.end_horizon = 3
    del seen[:]
    model.plan(one, n_tokens=6, seed=0)
    assert torch.cat(seen, dim=1).tolist() == [[4, 4, 4, 3, 2, 1]]


def test_end_horizon_is_for_the_ar_planner_with_its_end_embedding():
    with pytest.raises(InputError, match="end_horizon is for the AR planner"):
        tiny("masked", end_embedding=True, end_horizon=4).validate()
    with pytest.raises(InputError, match="end_horizon needs end_embedding"):
        tiny("ar", end_horizon=4).validate()
    with pytest.raises(InputError, match="end_horizon must be in"):
        tiny("ar", end_embedding=True, end_horizon=10_000).validate()
