"""The evaluation protocol on toy clips with a transparent embedder and fake generators.

Every toy clip carries a random 8-d signature in its first feature dims; the toy embedder maps
a motion to its (normalised) time-mean signature and a caption to the signature of the clip it
names. So real motions match their captions almost perfectly, and any generator's quality is
known in advance.
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest

from motok_robot.errors import InputError
from motok_robot.eval.config import GenerationEvalConfig
from motok_robot.eval.protocol import (
    CONTROL_ROW,
    METRICS,
    REFERENCE_ROW,
    EvalClip,
    clips_from_dataset,
    derange_captions,
    derangement,
    format_table,
    generate_checked,
    run_protocol,
    sample_clips,
)
from motok_robot.eval.sanity import evaluator_sanity, format_sanity, frozen_windows

SIG = 8
MOVING = 4.0 * np.linspace(0.0, 1.0, 60).std()  # the motion embedding's spread entry for a moving clip
STEP = 10.0 / 59  # ... and its step entries


def make_clips(n: int, seed: int, prefix: str = "clip", lengths=(40, 80)) -> tuple[list[EvalClip], dict[str, np.ndarray]]:
    rng = np.random.default_rng(seed)
    clips, signatures = [], {}
    for i in range(n):
        sig = 0.3 * rng.normal(size=SIG)
        length = int(rng.integers(*lengths))
        feats = 0.02 * rng.normal(size=(length, 263)).astype(np.float32)
        feats[:, :SIG] += sig
        feats[:, SIG] = np.linspace(0.0, 1.0, length)  # moves over time (frozen copies differ)
        captions = [f"{prefix} {i} walks", f"{prefix} {i} walks slowly"]
        for c in captions:
            signatures[c] = sig
        clips.append(EvalClip(f"{prefix}{i}", feats, captions))
    return clips, signatures


class ToyEmbedder:
    min_frames = 40
    max_frames = 80

    def __init__(self, signatures: dict[str, np.ndarray]):
        self.signatures = signatures

    def embed_text(self, captions):
        z = np.stack([np.r_[self.signatures[c], MOVING, STEP, 4 * STEP] for c in captions])
        return z / np.linalg.norm(z, axis=1, keepdims=True)

    def embed_motion(self, features):
        """Mean signature, spread, mean |step| and mean signed step of the moving dimension
        (so freezing, shuffling, reversing and jitter all move the embedding)."""
        rows = []
        for f in features:
            step = np.diff(f[:, SIG])
            rows.append(np.r_[f[:, :SIG].mean(0), 4.0 * f[:, SIG].std(), 10 * np.abs(step).mean(), 40 * step.mean()])
        z = np.stack(rows)
        return z / np.linalg.norm(z, axis=1, keepdims=True)


def oracle_generator(clips):
    """Returns the real clip named by each caption (clips no longer than the embedder's window)."""
    by_caption = {c: clip for clip in clips for c in clip.captions}

    def generate(texts, lengths, seed):
        return [by_caption[t].features[:n] for t, n in zip(texts, lengths)]

    return generate


def wrong_clip_generator(clips):
    """Returns another clip's motion (resized to the requested length) for every caption."""
    index = {c: i for i, clip in enumerate(clips) for c in clip.captions}

    def generate(texts, lengths, seed):
        return [np.resize(clips[(index[t] + 7) % len(clips)].features, (n, 263)) for t, n in zip(texts, lengths)]

    return generate


def noisy_generator(clips, scale):
    base = oracle_generator(clips)

    def generate(texts, lengths, seed):
        rng = np.random.default_rng(seed)
        return [m + scale * rng.normal(size=(1, 263)).astype(np.float32) for m in base(texts, lengths, seed)]

    return generate


CFG = GenerationEvalConfig(repeats=4, diversity_times=50, mm_texts=0, mm_repeats=0, batch_size=16)


def test_oracle_generator_matches_the_reference_row_and_wrong_clips_fall_to_chance():
    clips, sigs = make_clips(64, 0)
    reference, ref_sigs = make_clips(64, 1, prefix="train")
    embedder = ToyEmbedder({**sigs, **ref_sigs})
    result = run_protocol(clips, embedder, {"oracle": oracle_generator(clips), "wrong": wrong_clip_generator(clips)},
                          CFG, reference, progress=False)
    real, control = result.row(REFERENCE_ROW), result.row(CONTROL_ROW)
    oracle, wrong = result.row("oracle"), result.row("wrong")
    assert [r.name for r in result.rows] == [REFERENCE_ROW, CONTROL_ROW, "oracle", "wrong"]
    assert real.metrics["r_precision_top1"].mean > 0.9
    assert real.metrics["r_precision_top1"].mean <= real.metrics["r_precision_top3"].mean <= 1.0
    # the oracle returns exactly the real windows: identical matching metrics, FID ~ 0
    for key in ("r_precision_top1", "r_precision_top2", "r_precision_top3", "mm_dist"):
        assert oracle.metrics[key].values == pytest.approx(real.metrics[key].values, abs=1e-12), key
    assert oracle.metrics["fid"].mean < 1e-6
    assert abs(oracle.metrics["diversity"].mean - real.metrics["diversity"].mean) < 0.2
    # another clip's motion, or another clip's caption: R-precision at chance (1/32), larger MM-dist
    for row in (wrong, control):
        assert row.metrics["r_precision_top1"].mean < 0.1, row.name
        assert row.metrics["mm_dist"].mean > 2 * real.metrics["mm_dist"].mean, row.name
    assert wrong.metrics["fid"].mean < 0.1  # real motions (tiled to length), only mismatched
    # the reference FID compares two real sets from the same distribution: small next to a frozen set
    assert "fid" in real.metrics and "fid" not in control.metrics and "multimodality" not in real.metrics
    assert 0 < real.metrics["fid"].mean < 0.5
    assert len(real.metrics["fid"].values) == CFG.repeats
    table = format_table(result, "toy")
    assert "| oracle |" in table and "± " in table and "chance top-1 = 0.031" in table
    assert "| shuffled texts |" in table and " - |" in table


def test_fid_grows_with_generator_noise_and_multimodality_measures_spread():
    clips, sigs = make_clips(40, 2)
    cfg = GenerationEvalConfig(repeats=2, diversity_times=40, mm_texts=6, mm_repeats=10, mm_times=5, batch_size=8)
    gens = {"exact": oracle_generator(clips), "noisy": noisy_generator(clips, 0.3), "noisier": noisy_generator(clips, 1.0)}
    result = run_protocol(clips, ToyEmbedder(sigs), gens, cfg, progress=False)
    fids = [result.row(g).metrics["fid"].mean for g in gens]
    assert fids[0] < 1e-6 < fids[1] < fids[2]
    mm = [result.row(g).metrics["multimodality"].mean for g in gens]
    assert mm[0] == pytest.approx(0.0, abs=1e-9) and 0 < mm[1] < mm[2]
    assert result.settings["mm_texts"] == 6 and "fid" not in result.row(REFERENCE_ROW).metrics


def test_protocol_is_deterministic_given_the_seed_and_varies_with_it():
    clips, sigs = make_clips(40, 3)
    gens = {"noisy": noisy_generator(clips, 0.3)}
    a = run_protocol(clips, ToyEmbedder(sigs), gens, CFG, progress=False).to_dict()
    b = run_protocol(clips, ToyEmbedder(sigs), gens, CFG, progress=False).to_dict()
    c = run_protocol(clips, ToyEmbedder(sigs), gens, GenerationEvalConfig(**{**CFG.__dict__, "seed": 5}), progress=False).to_dict()
    assert a == b
    assert a["rows"][2]["metrics"]["fid"] != c["rows"][2]["metrics"]["fid"]
    assert set(a["rows"][2]["metrics"]) == set(METRICS) - {"multimodality"}


def test_a_row_does_not_depend_on_the_rows_evaluated_with_it():
    """Every generator gets the same sampling seeds, so a model evaluated alone, or after another
    one, gives the same numbers."""
    clips, sigs = make_clips(40, 4)
    alone = run_protocol(clips, ToyEmbedder(sigs), {"b": noisy_generator(clips, 0.5)}, CFG, progress=False)
    second = run_protocol(clips, ToyEmbedder(sigs), {"a": noisy_generator(clips, 0.2), "b": noisy_generator(clips, 0.5)},
                          CFG, progress=False)
    assert alone.row("b").metrics == second.row("b").metrics


def test_generator_outputs_are_checked_and_restored_to_input_order():
    texts, lengths = ["a", "b", "c", "d", "e"], [50, 41, 60, 41, 45]
    seen = []

    def gen(t, n, seed):
        seen.append(list(n))
        return [np.full((k, 263), float(k), np.float32) for k in n]

    out = generate_checked("g", gen, texts, lengths, seed=0, batch_size=2)
    assert [m.shape[0] for m in out] == lengths and all(m[0, 0] == n for m, n in zip(out, lengths))
    assert seen == [[41, 41], [45, 50], [60]]  # sorted by length, in chunks of 2
    with pytest.raises(InputError, match=r"generator 'bad': motion for text 'a' has shape \(49, 263\)"):
        generate_checked("bad", lambda t, n, s: [np.zeros((k - 1, 263)) for k in n], texts[:1], [50], 0, 4)
    with pytest.raises(InputError, match="NaN"):
        generate_checked("bad", lambda t, n, s: [np.full((k, 263), np.nan) for k in n], texts[:1], [50], 0, 4)
    with pytest.raises(InputError, match="returned 0 motions for 1 texts"):
        generate_checked("bad", lambda t, n, s: [], texts[:1], [50], 0, 4)


def test_setup_errors_name_the_problem():
    clips, sigs = make_clips(20, 4)
    with pytest.raises(InputError, match="20 usable clips.*at least 32"):
        run_protocol(clips, ToyEmbedder(sigs), {}, CFG, progress=False)
    clips, sigs = make_clips(40, 4)
    with pytest.raises(InputError, match="reserved"):
        run_protocol(clips, ToyEmbedder(sigs), {REFERENCE_ROW: oracle_generator(clips)}, CFG, progress=False)
    with pytest.raises(InputError, match="mm_repeats"):
        run_protocol(clips, ToyEmbedder(sigs), {}, GenerationEvalConfig(mm_texts=2, mm_repeats=3), progress=False)


def test_derangements_leave_nothing_in_place():
    rng = np.random.default_rng(0)
    for n in (2, 3, 10, 33):
        perm = derangement(n, rng)
        assert sorted(perm) == list(range(n)) and (perm != np.arange(n)).all()
    captions = ["walk", "walk", "run", "jump", "walk", "sit"]  # repeated captions (e.g. mirrored clips)
    for seed in range(20):
        shuffled = derange_captions(captions, np.random.default_rng(seed))
        assert sorted(shuffled) == sorted(captions)
        assert all(a != b for a, b in zip(shuffled, captions))


def test_clips_from_dataset_skips_short_and_uncaptioned_clips():
    class Split:
        clip_ids = ["ok", "short", "silent", "ok2"]
        data = {"ok": (60, ["a  person walks"]), "short": (30, ["x"]), "silent": (80, ["", "  "]), "ok2": (45, ["y"])}

        def features(self, cid):
            return np.zeros((self.data[cid][0], 263), np.float32)

        def texts(self, cid):
            return self.data[cid][1]

    clips = clips_from_dataset(Split(), min_frames=40)
    assert [c.clip_id for c in clips] == ["ok", "ok2"] and clips[0].captions == ["a person walks"]
    assert [c.clip_id for c in clips_from_dataset(Split(), 40, max_clips=1)] == ["ok"]
    # a seeded random subset of usable clips (the reference set for the FID floor)
    picks = {tuple(c.clip_id for c in sample_clips(Split(), 40, 1, seed=s)) for s in range(12)}
    assert picks == {("ok",), ("ok2",)}
    assert sorted(c.clip_id for c in sample_clips(Split(), 40, 5, seed=0)) == ["ok", "ok2"]
    assert sample_clips(Split(), 40, 1, seed=3)[0].clip_id == sample_clips(Split(), 40, 1, seed=3)[0].clip_id


def test_sanity_passes_for_a_matching_evaluator_and_fails_for_a_blind_one():
    clips, sigs = make_clips(64, 5)
    reference, ref_sigs = make_clips(64, 6, prefix="train")
    embedder = ToyEmbedder({**sigs, **ref_sigs})
    floor, floor_sigs = make_clips(64, 7, prefix="floor")
    embedder = ToyEmbedder({**sigs, **ref_sigs, **floor_sigs})
    report = evaluator_sanity(clips, embedder, CFG, reference, floor)
    text = format_sanity(report)
    assert report.passed, text
    assert report.checks["fid_test_vs_train_small"]["fid_frozen"] > 10 * report.checks["fid_test_vs_train_small"]["fid_test_vs_train"]
    assert set(report.values["fid_corrupted"]) == {"shuffle", "reverse", "freeze", "jitter"}
    assert report.checks["corruptions_detected"]["passed"] and report.values["fid_train_vs_train"] > 0
    assert "Sanity: PASSED" in text and "FID: fid_train_vs_train" in text
    assert "multimodality" not in format_table(report.result)  # no generator: no multimodality note

    class TimeBlind(ToyEmbedder):  # sees only the mean pose: frame order and freezing go unnoticed
        def embed_motion(self, features):
            z = np.stack([np.r_[f[:, :SIG].mean(0), MOVING, STEP, 4 * STEP] for f in features])
            return z / np.linalg.norm(z, axis=1, keepdims=True)

    blind_time = evaluator_sanity(clips, TimeBlind(embedder.signatures), CFG, reference, floor)
    assert not blind_time.checks["corruptions_detected"]["passed"]

    class Blind(ToyEmbedder):  # captions embedded at random: no text-motion relation
        def embed_text(self, captions):
            z = np.stack([np.random.default_rng(zlib.crc32(c.encode())).normal(size=SIG + 3) for c in captions])
            return z / np.linalg.norm(z, axis=1, keepdims=True)

    blind = evaluator_sanity(clips, Blind(embedder.signatures), CFG, reference)
    assert not blind.passed and not blind.checks["matched_above_chance"]["passed"]
    assert "FAIL" in format_sanity(blind)


def test_frozen_windows_repeat_the_first_frame():
    w = [np.arange(6, dtype=np.float32).reshape(3, 2)]
    np.testing.assert_array_equal(frozen_windows(w)[0], [[0, 1], [0, 1], [0, 1]])


def test_content_of_names_what_a_clip_shows():
    from motok_robot.data.sources import content_of

    assert content_of("bandai/dataset-1_walk-turn-right_angry_003") == "walk-turn-right"
    assert content_of("mirror/bandai/dataset-1_walk-turn-right_angry_003") == "walk-turn-left"  # mirrored motion
    assert content_of("mirror/bandai/dataset-2_raise-up-left-hand_active_090") == "raise-up-right-hand"
    assert content_of("bandai/dataset-2_bow_normal_001") == "bow"
    assert content_of("cmu/02_01") == "cmu" and content_of("mirror/deepmimic/humanoid3d_walk") == "deepmimic"


def test_content_matched_clips_follow_the_test_mix():
    from motok_robot.data.sources import content_of
    from motok_robot.eval.protocol import content_matched_clips

    names = ([f"bandai/dataset-1_walk_normal_{i:03d}" for i in range(10)]
             + [f"bandai/dataset-1_run_normal_{i:03d}" for i in range(3)] + ["bandai/dataset-1_run_short_001"])

    class Train:
        clip_ids = list(names)

        def features(self, cid):
            return np.zeros((20 if "short" in cid else 60, 263), np.float32)

        def texts(self, cid):
            return [cid]

    test = [EvalClip(cid, np.zeros((60, 263), np.float32), ["t"]) for cid in
            ["bandai/dataset-1_run_angry_001"] * 4 + ["bandai/dataset-1_walk_angry_001", "cmu/02_01"]]
    picked = content_matched_clips(test, Train(), min_frames=40, seed=0)
    assert len(picked) == len(test)
    assert [content_of(c.clip_id) for c in picked[:5]] == ["run"] * 4 + ["walk"]
    runs = [c.clip_id for c in picked[:4]]
    assert len(set(runs[:3])) == 3 and runs[3] in runs[:3]  # three usable runs, then reuse
    assert all("short" not in c for c in runs)  # too short for the evaluator: skipped
    assert picked[5].clip_id in names  # a content the split lacks draws from all of it
    again = content_matched_clips(test, Train(), min_frames=40, seed=0)
    assert [c.clip_id for c in again] == [c.clip_id for c in picked]


def test_sanity_checks_test_vs_train_on_the_matched_mix():
    clips, sigs = make_clips(64, 5)
    shifted, shift_sigs = make_clips(64, 6, prefix="other")  # another content mix: signatures moved away
    for clip in shifted:
        clip.features[:, :SIG] += 0.6
    matched, matched_sigs = make_clips(64, 8, prefix="matched")  # same mix as the test clips
    floor, floor_sigs = make_clips(64, 7, prefix="floor")
    embedder = ToyEmbedder({**sigs, **shift_sigs, **matched_sigs, **floor_sigs})
    report = evaluator_sanity(clips, embedder, CFG, shifted, floor, matched)
    check = report.checks["fid_test_vs_train_small"]
    assert check["passed"], format_sanity(report)
    assert report.values["fid_test_vs_train"] > 5 * report.values["fid_test_vs_matched_train"]
    assert check["fid_test_vs_train_unmatched"] == report.values["fid_test_vs_train"]
    assert "fid_test_vs_matched_train" in format_sanity(report)
    # without a matched sample the plain one is checked, and the shifted mix fails it
    assert not evaluator_sanity(clips, embedder, CFG, shifted, floor).checks["fid_test_vs_train_small"]["passed"]
