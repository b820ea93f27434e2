"""CLIP text encoder: real loading code, exercised with small random weights written here."""

from __future__ import annotations

import json
import string

import pytest
import torch

from motok_robot.errors import InputError
from motok_robot.text import load_text_encoder
from motok_robot.text.clip import CLIPTextConfig, CLIPTextEncoder, CLIPTextTransformer

torch.set_num_threads(1)

CFG = CLIPTextConfig(vocab_size=0, context_length=16, width=128, layers=2, heads=2, mlp_width=256, embed_dim=24)


def _write_tokenizer(directory) -> int:
    """A tiny CLIP BPE vocabulary (letters, a few merges, the two special tokens); returns its size."""
    letters = list(string.ascii_lowercase)
    vocab_list = letters + [c + "</w>" for c in letters]
    merges = ["w a", "wa l", "wal k</w>", "r u", "ru n</w>"]
    vocab_list += ["wa", "wal", "walk</w>", "ru", "run</w>", "<|startoftext|>", "<|endoftext|>"]
    vocab = {tok: i for i, tok in enumerate(vocab_list)}
    (directory / "vocab.json").write_text(json.dumps(vocab))
    (directory / "merges.txt").write_text("#version: 0.2\n" + "\n".join(merges) + "\n")
    return len(vocab)


def _random_model(vocab_size: int, seed: int) -> CLIPTextTransformer:
    gen = torch.Generator().manual_seed(seed)
    model = CLIPTextTransformer(CLIPTextConfig(**{**CFG.__dict__, "vocab_size": vocab_size}))
    with torch.no_grad():
        for p in model.parameters():
            p.copy_(torch.randn(p.shape, generator=gen) * 0.2)
    return model


def _hf_state(model: CLIPTextTransformer) -> dict[str, torch.Tensor]:
    """The same weights in the Hugging Face CLIPTextModelWithProjection key layout."""
    sd = model.state_dict()
    tm = "text_model."
    out = {
        tm + "embeddings.token_embedding.weight": sd["token_embedding.weight"],
        tm + "embeddings.position_embedding.weight": sd["positional_embedding"],
        tm + "final_layer_norm.weight": sd["ln_final.weight"],
        tm + "final_layer_norm.bias": sd["ln_final.bias"],
        "text_projection.weight": sd["text_projection"].t().contiguous(),
    }
    for i in range(CFG.layers):
        s, d = f"transformer.resblocks.{i}.", f"{tm}encoder.layers.{i}."
        for name, w, b in zip("qkv", sd[s + "attn.in_proj_weight"].chunk(3), sd[s + "attn.in_proj_bias"].chunk(3)):
            out[d + f"self_attn.{name}_proj.weight"] = w.contiguous()
            out[d + f"self_attn.{name}_proj.bias"] = b.contiguous()
        for a, b_ in (("self_attn.out_proj", "attn.out_proj"), ("layer_norm1", "ln_1"), ("layer_norm2", "ln_2"),
                      ("mlp.fc1", "mlp.c_fc"), ("mlp.fc2", "mlp.c_proj")):
            out[d + a + ".weight"] = sd[s + b_ + ".weight"]
            out[d + a + ".bias"] = sd[s + b_ + ".bias"]
    return out


@pytest.fixture()
def clip_dirs(tmp_path):
    from safetensors.torch import save_file

    dirs = {}
    for name in ("openai", "hf", "other", "torch"):
        (tmp_path / name).mkdir()
        n_vocab = _write_tokenizer(tmp_path / name)
    model = _random_model(n_vocab, seed=0)
    openai_state = {k: v.contiguous() for k, v in model.state_dict().items()}
    # a full OpenAI CLIP file also holds the image tower: it must be ignored
    save_file({**openai_state, "visual.proj": torch.randn(4, 4)}, str(tmp_path / "openai" / "model.safetensors"))
    save_file(_hf_state(model), str(tmp_path / "hf" / "model.safetensors"))
    (tmp_path / "hf" / "config.json").write_text(json.dumps(
        {"text_config": {"num_attention_heads": CFG.heads, "hidden_act": "quick_gelu"}}))
    save_file({k: v.contiguous() for k, v in _random_model(n_vocab, seed=1).state_dict().items()},
              str(tmp_path / "other" / "model.safetensors"))
    torch.save(openai_state, tmp_path / "torch" / "pytorch_model.bin")
    for name in dirs or ("openai", "hf", "other", "torch"):
        dirs[name] = tmp_path / name
    return dirs


TEXTS = ["walk", "run", "walk run walk"]


def test_clip_loads_and_is_deterministic(clip_dirs):
    enc = CLIPTextEncoder(clip_dirs["openai"])
    assert enc.dim == CFG.embed_dim
    a = enc.encode(TEXTS)
    assert a.shape == (3, CFG.embed_dim) and a.dtype == torch.float32
    assert torch.allclose(a.norm(dim=1), torch.ones(3), atol=1e-5)
    enc.clear_cache()
    assert torch.equal(enc.encode(TEXTS), a)
    assert torch.equal(CLIPTextEncoder(clip_dirs["openai"]).encode(TEXTS), a)
    # different sentences give different features
    assert not torch.allclose(a[0], a[1], atol=1e-3)


def test_clip_same_weights_same_output_in_every_layout(clip_dirs):
    ref = CLIPTextEncoder(clip_dirs["openai"]).encode(TEXTS)
    hf = CLIPTextEncoder(clip_dirs["hf"]).encode(TEXTS)
    pt = CLIPTextEncoder(clip_dirs["torch"] / "pytorch_model.bin").encode(TEXTS)
    assert torch.allclose(ref, hf, atol=1e-5)
    assert torch.allclose(ref, pt, atol=1e-6)


def test_clip_output_depends_on_weights(clip_dirs):
    ref = CLIPTextEncoder(clip_dirs["openai"]).encode(TEXTS)
    other = CLIPTextEncoder(clip_dirs["other"]).encode(TEXTS)
    assert (ref - other).abs().max() > 1e-2


def test_clip_selected_by_config_string(clip_dirs):
    enc = load_text_encoder(f"clip:{clip_dirs['openai']}", reuse=False)
    assert isinstance(enc, CLIPTextEncoder) and enc.dim == CFG.embed_dim


def test_clip_bad_files_are_clear_errors(tmp_path, clip_dirs):
    with pytest.raises(InputError, match="does not exist"):
        CLIPTextEncoder(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no CLIP weights"):
        CLIPTextEncoder(tmp_path / "empty")
    from safetensors.torch import save_file

    (tmp_path / "broken").mkdir()
    _write_tokenizer(tmp_path / "broken")
    save_file({"token_embedding.weight": torch.zeros(3, 4)}, str(tmp_path / "broken" / "model.safetensors"))
    with pytest.raises(InputError, match="missing tensor"):
        CLIPTextEncoder(tmp_path / "broken")
    (tmp_path / "garbage").mkdir()
    (tmp_path / "garbage" / "model.safetensors").write_bytes(b"not a safetensors file")
    with pytest.raises(InputError, match="safetensors"):
        CLIPTextEncoder(tmp_path / "garbage")
    with pytest.raises(InputError, match="unknown text_encoder"):
        load_text_encoder("bert")
    enc = CLIPTextEncoder(clip_dirs["openai"])
    with pytest.raises(InputError, match="empty"):
        enc.encode(["   "])
