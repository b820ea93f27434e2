"""CLIP text encoder loaded from a user's local files (OpenAI or Hugging Face layout).

The text tower of CLIP is re-implemented here in plain torch and its weights are read
from a safetensors file or a torch state dict (``torch.load(weights_only=True)``; never
a pickle of arbitrary objects).  Two key layouts are understood:

* OpenAI (``clip.load`` state dict): ``token_embedding.weight``, ``positional_embedding``,
  ``transformer.resblocks.{i}.{ln_1,attn.in_proj_weight,attn.out_proj,ln_2,mlp.c_fc,mlp.c_proj}``,
  ``ln_final``, ``text_projection`` ``[width, embed]``.  Image-tower keys (``visual.*``) are ignored.
* Hugging Face (``CLIPModel`` / ``CLIPTextModelWithProjection``): ``text_model.embeddings.*``,
  ``text_model.encoder.layers.{i}.{self_attn.{q,k,v,out}_proj,layer_norm1,mlp.fc1,mlp.fc2,layer_norm2}``,
  ``text_model.final_layer_norm``, ``text_projection.weight`` ``[embed, width]``.

Sizes (vocabulary, context length, width, layers, MLP size, projection size) are read
from the tensor shapes; the number of attention heads and the activation come from a
``config.json`` next to the weights when there is one (``num_attention_heads``,
``hidden_act``), else OpenAI's convention (``width // 64`` heads, QuickGELU).

The BPE tokenizer is read from the same directory (``tokenizer.json``, or ``vocab.json`` +
``merges.txt``) with the ``transformers`` CLIP tokenizer, offline.

Output of :meth:`CLIPTextEncoder.encode`: the projected feature at the end-of-text token,
L2-normalised, float32 ``[B, embed_dim]``.
"""

from __future__ import annotations

import json
import os
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

from motok_robot.errors import InputError
from motok_robot.text.base import TextEncoder

WEIGHT_FILE_NAMES = (
    "model.safetensors",
    "text_model.safetensors",
    "open_clip_model.safetensors",
    "pytorch_model.bin",
    "model.pt",
    "model.pth",
)


@dataclass
class CLIPTextConfig:
    """Shape of a CLIP text tower (all sizes are counts)."""

    vocab_size: int = 49408
    context_length: int = 77
    width: int = 512
    layers: int = 12
    heads: int = 8
    mlp_width: int = 2048
    embed_dim: int = 512
    activation: str = "quick_gelu"  # "quick_gelu" (OpenAI) or "gelu"


class QuickGELU(nn.Module):
    """``x * sigmoid(1.702 x)``, the activation of the original CLIP."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x * torch.sigmoid(1.702 * x)


class _Block(nn.Module):
    """Pre-norm transformer block with OpenAI's parameter names."""

    def __init__(self, cfg: CLIPTextConfig) -> None:
        super().__init__()
        act = QuickGELU() if cfg.activation == "quick_gelu" else nn.GELU()
        self.ln_1 = nn.LayerNorm(cfg.width)
        self.attn = nn.MultiheadAttention(cfg.width, cfg.heads, batch_first=True)
        self.ln_2 = nn.LayerNorm(cfg.width)
        self.mlp = nn.Sequential(
            OrderedDict(
                c_fc=nn.Linear(cfg.width, cfg.mlp_width),
                gelu=act,
                c_proj=nn.Linear(cfg.mlp_width, cfg.width),
            )
        )

    def forward(self, x: torch.Tensor, causal: torch.Tensor) -> torch.Tensor:
        h = self.ln_1(x)
        x = x + self.attn(h, h, h, attn_mask=causal, need_weights=False)[0]
        return x + self.mlp(self.ln_2(x))


class CLIPTextTransformer(nn.Module):
    """CLIP's text tower: token ids ``[B, L]`` -> projected features ``[B, embed_dim]``."""

    def __init__(self, cfg: CLIPTextConfig) -> None:
        super().__init__()
        self.config = cfg
        self.token_embedding = nn.Embedding(cfg.vocab_size, cfg.width)
        self.positional_embedding = nn.Parameter(torch.zeros(cfg.context_length, cfg.width))
        self.transformer = nn.Module()
        self.transformer.resblocks = nn.ModuleList(_Block(cfg) for _ in range(cfg.layers))
        self.ln_final = nn.LayerNorm(cfg.width)
        self.text_projection = nn.Parameter(torch.zeros(cfg.width, cfg.embed_dim))

    def forward(self, ids: torch.Tensor, eot_index: torch.Tensor) -> torch.Tensor:
        """``ids`` int64 ``[B, L]`` (L <= context_length); ``eot_index`` int64 ``[B]`` position of
        the end-of-text token -> float ``[B, embed_dim]`` (not normalised)."""
        length = ids.shape[1]
        x = self.token_embedding(ids) + self.positional_embedding[:length]
        causal = torch.full((length, length), float("-inf"), device=ids.device).triu(1)
        for block in self.transformer.resblocks:
            x = block(x, causal)
        x = self.ln_final(x)
        x = x[torch.arange(ids.shape[0], device=ids.device), eot_index]
        return x @ self.text_projection


# ----------------------------------------------------------------------------- weights


def read_state_dict(path: str | Path) -> dict[str, torch.Tensor]:
    """Tensors of a ``.safetensors`` file or a torch state dict (weights only), on the CPU."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"CLIP weights not found: {path}")
    if path.suffix == ".safetensors":
        from safetensors.torch import load_file

        try:
            return load_file(str(path), device="cpu")
        except Exception as exc:  # safetensors raises its own error types
            raise InputError(f"{path}: not a readable safetensors file ({exc})") from exc
    try:
        state = torch.load(str(path), map_location="cpu", weights_only=True)
    except Exception as exc:
        raise InputError(
            f"{path}: not a torch state dict that loads with weights_only=True ({type(exc).__name__}: "
            f"{str(exc).splitlines()[0] if str(exc) else ''}). TorchScript archives (OpenAI's *.pt) must be "
            "converted first: torch.jit.load(p, map_location='cpu').state_dict() -> safetensors.torch.save_file"
        ) from exc
    if isinstance(state, dict) and "state_dict" in state and isinstance(state["state_dict"], dict):
        state = state["state_dict"]
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise InputError(f"{path}: expected a dict of tensors (a state dict)")
    return state


def _strip_prefixes(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Drop the ``module.`` prefix that DataParallel checkpoints carry."""
    return {(k[len("module."):] if k.startswith("module.") else k): v for k, v in state.items()}


def openai_from_hf(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Rename a Hugging Face CLIP text state dict to OpenAI's key layout (q/k/v fused)."""
    out: dict[str, torch.Tensor] = {}
    tm = "text_model."

    def take(key: str) -> torch.Tensor:
        if key not in state:
            raise InputError(f"CLIP weights (Hugging Face layout): missing tensor {key!r}")
        return state[key]

    out["token_embedding.weight"] = take(tm + "embeddings.token_embedding.weight")
    out["positional_embedding"] = take(tm + "embeddings.position_embedding.weight")
    n_layers = 1 + max(
        (int(k.split(".")[3]) for k in state if k.startswith(tm + "encoder.layers.")), default=-1
    )
    for i in range(n_layers):
        src, dst = f"{tm}encoder.layers.{i}.", f"transformer.resblocks.{i}."
        out[dst + "attn.in_proj_weight"] = torch.cat([take(src + f"self_attn.{p}_proj.weight") for p in "qkv"])
        out[dst + "attn.in_proj_bias"] = torch.cat([take(src + f"self_attn.{p}_proj.bias") for p in "qkv"])
        for a, b in (
            ("self_attn.out_proj", "attn.out_proj"),
            ("layer_norm1", "ln_1"),
            ("layer_norm2", "ln_2"),
            ("mlp.fc1", "mlp.c_fc"),
            ("mlp.fc2", "mlp.c_proj"),
        ):
            out[dst + b + ".weight"] = take(src + a + ".weight")
            out[dst + b + ".bias"] = take(src + a + ".bias")
    out["ln_final.weight"] = take(tm + "final_layer_norm.weight")
    out["ln_final.bias"] = take(tm + "final_layer_norm.bias")
    out["text_projection"] = take("text_projection.weight").t().contiguous()
    return out


def config_from_state(state: dict[str, torch.Tensor], meta: dict | None = None) -> CLIPTextConfig:
    """Infer :class:`CLIPTextConfig` from OpenAI-layout tensors (+ optional HF ``config.json``)."""
    for key in ("token_embedding.weight", "positional_embedding", "text_projection",
                "transformer.resblocks.0.mlp.c_fc.weight"):
        if key not in state:
            raise InputError(f"CLIP weights: missing tensor {key!r} (is this a CLIP text model?)")
    vocab, width = state["token_embedding.weight"].shape
    layers = 1 + max(int(k.split(".")[2]) for k in state if k.startswith("transformer.resblocks."))
    meta = dict(meta or {})
    text_meta = meta.get("text_config") or meta
    heads = int(text_meta.get("num_attention_heads", max(1, width // 64)))
    if width % heads:
        raise InputError(f"CLIP config: width {width} is not divisible by {heads} attention heads")
    act = text_meta.get("hidden_act", "quick_gelu")
    if act not in ("quick_gelu", "gelu"):
        raise InputError(f"CLIP config: unsupported hidden_act {act!r} (quick_gelu or gelu)")
    return CLIPTextConfig(
        vocab_size=int(vocab),
        context_length=int(state["positional_embedding"].shape[0]),
        width=int(width),
        layers=int(layers),
        heads=heads,
        mlp_width=int(state["transformer.resblocks.0.mlp.c_fc.weight"].shape[0]),
        embed_dim=int(state["text_projection"].shape[1]),
        activation=act,
    )


def load_clip_text_model(weights: str | Path, config_json: str | Path | None = None) -> CLIPTextTransformer:
    """Build :class:`CLIPTextTransformer` from a weights file (either layout), strictly."""
    state = _strip_prefixes(read_state_dict(weights))
    if any(k.startswith("text_model.") for k in state):
        state = openai_from_hf(state)
    meta = None
    if config_json is not None and Path(config_json).is_file():
        meta = json.loads(Path(config_json).read_text())
    cfg = config_from_state(state, meta)
    model = CLIPTextTransformer(cfg)
    wanted = model.state_dict()
    text_state = {k: v for k, v in state.items() if k in wanted}
    missing = sorted(set(wanted) - set(text_state))
    if missing:
        raise InputError(f"{weights}: CLIP text weights incomplete, missing {missing[:5]}"
                         + (f" and {len(missing) - 5} more" if len(missing) > 5 else ""))
    for key, value in text_state.items():
        if value.shape != wanted[key].shape:
            raise InputError(f"{weights}: tensor {key!r} has shape {tuple(value.shape)}, "
                             f"expected {tuple(wanted[key].shape)}")
    model.load_state_dict({k: v.float() for k, v in text_state.items()}, strict=True)
    return model.eval().requires_grad_(False)


def _find_weights(directory: Path) -> Path:
    for name in WEIGHT_FILE_NAMES:
        if (directory / name).is_file():
            return directory / name
    candidates = sorted(directory.glob("*.safetensors")) + sorted(directory.glob("*.bin")) + sorted(directory.glob("*.pt"))
    if len(candidates) == 1:
        return candidates[0]
    raise InputError(
        f"{directory}: no CLIP weights found (looked for {', '.join(WEIGHT_FILE_NAMES)}"
        + (f"; several candidates: {[c.name for c in candidates]}" if candidates else "") + ")"
    )


def load_clip_tokenizer(directory: str | Path):
    """The CLIP BPE tokenizer from ``tokenizer.json`` or ``vocab.json`` + ``merges.txt`` (offline)."""
    directory = Path(directory)
    has_fast = (directory / "tokenizer.json").is_file()
    has_bpe = (directory / "vocab.json").is_file() and (directory / "merges.txt").is_file()
    if not (has_fast or has_bpe):
        raise InputError(f"{directory}: CLIP tokenizer files missing (tokenizer.json, or vocab.json + merges.txt)")
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    from transformers import CLIPTokenizer

    try:
        if has_bpe and not has_fast:
            return CLIPTokenizer(vocab=str(directory / "vocab.json"), merges=str(directory / "merges.txt"))
        return CLIPTokenizer.from_pretrained(str(directory), local_files_only=True)
    except Exception as exc:
        raise InputError(f"{directory}: cannot read the CLIP tokenizer ({type(exc).__name__}: {exc})") from exc


class CLIPTextEncoder(TextEncoder):
    """CLIP text encoder from a local directory or weights file (tokenizer files beside it).

    Args:
        path: a directory holding weights (see :data:`WEIGHT_FILE_NAMES`), tokenizer files and
            optionally ``config.json``; or a weights file whose directory holds the rest.
        device: torch device for the forward pass.
    """

    def __init__(self, path: str | Path, device: str = "cpu") -> None:
        super().__init__()
        path = Path(path).expanduser()
        if not path.exists():
            raise InputError(f"CLIP path does not exist: {path}")
        directory = path if path.is_dir() else path.parent
        weights = _find_weights(path) if path.is_dir() else path
        self.model = load_clip_text_model(weights, directory / "config.json").to(device)
        self.tokenizer = load_clip_tokenizer(directory)
        self.device = device
        self.dim = self.model.config.embed_dim
        self.name = f"clip:{weights.resolve()}"
        eos = self.tokenizer.eos_token_id
        if eos is None or eos >= self.model.config.vocab_size:
            raise InputError(f"{directory}: tokenizer end-of-text id {eos} outside the model vocabulary "
                             f"({self.model.config.vocab_size})")
        self._eos = int(eos)

    def token_ids(self, texts: list[str]) -> tuple[torch.Tensor, torch.Tensor]:
        """Tokenise -> (ids int64 ``[B, L]``, position of end-of-text ``[B]``); L <= context length."""
        batch = self.tokenizer(
            texts, padding="longest", truncation=True, max_length=self.model.config.context_length,
            return_tensors="pt",
        )
        ids = batch["input_ids"].long()
        if int(ids.max()) >= self.model.config.vocab_size:
            raise InputError(f"{self.name}: tokenizer produced ids beyond the model vocabulary")
        is_eos = ids == self._eos
        eot = torch.where(is_eos.any(1), is_eos.float().argmax(1), torch.full_like(ids[:, 0], ids.shape[1] - 1))
        return ids, eot

    def _encode_uncached(self, texts: list[str]) -> torch.Tensor:
        ids, eot = self.token_ids(texts)
        with torch.no_grad():
            feats = self.model(ids.to(self.device), eot.to(self.device))
        return torch.nn.functional.normalize(feats.float(), dim=-1).cpu()
