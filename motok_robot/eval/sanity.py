"""Sanity checks of a text-motion evaluator on real motions (``motok-robot eval evaluator``).

An evaluator is worth using when (issue 10's acceptance):

* real test vs real train FID is small: two sets of real motions are close. For scale the
  report also gives ``fid_frozen``, the FID between the real test windows and the same windows
  frozen at their first frame (a clearly wrong "motion" with the right poses); the check asks
  for ``fid_test_vs_matched_train < fid_frozen / 10``, where the train sample has the test
  set's content mix (:func:`motok_robot.eval.protocol.content_matched_clips`; a split held out
  by content+style groups gives the test set another mix of contents, which FID counts as a
  difference).  ``fid_test_vs_train`` against a plain random train sample is reported too;
* the FID notices implausible motion: for each corruption of :mod:`motok_robot.eval.corruptions`
  (frames shuffled, time reversed, frozen, jittered) the FID between the real test windows and
  their corrupted copies exceeds 3x ``fid_train_vs_train``, the FID of two disjoint train
  samples as large as the test set (the floor that sample size allows);
* R-precision collapses with shuffled captions: top-1 below twice chance (2/32), while the
  matched top-1 is at least three times chance;
* results repeat: the same seed gives identical numbers, and a different sampling seed gives
  means within the two runs' 95 % confidence intervals (summed) for at least 80 % of the
  row/metric pairs (with 95 % intervals from a few repeats, an occasional miss is expected).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from motok_robot.eval import metrics
from motok_robot.eval.config import GenerationEvalConfig
from motok_robot.eval.corruptions import CORRUPTIONS, corrupt
from motok_robot.eval.protocol import CONTROL_ROW, METRICS, REFERENCE_ROW, EvalClip, EvalResult, draw, run_protocol

#: share of row/metric means that must agree within the summed CIs between two sampling seeds
MIN_AGREEMENT = 0.8


@dataclass
class SanityReport:
    result: EvalResult
    checks: dict[str, dict] = field(default_factory=dict)
    values: dict = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return all(c["passed"] for c in self.checks.values())

    def to_dict(self) -> dict:
        return {**self.result.to_dict(), "sanity": {"passed": self.passed, "values": self.values, "checks": self.checks}}


def frozen_windows(windows: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Each window ``[T, 263]`` replaced by its first frame repeated ``T`` times."""
    return [np.repeat(w[:1], len(w), axis=0) for w in windows]


def repeat_agreement(a: EvalResult, b: EvalResult, rows: Sequence[str] = (REFERENCE_ROW, CONTROL_ROW)) -> dict[str, dict]:
    """Per ``row/metric``: the two means, their summed CI half-widths and whether they agree."""
    out = {}
    for row in rows:
        ra, rb = a.row(row), b.row(row)
        for key in METRICS:
            if key in ra.metrics and key in rb.metrics:
                va, vb = ra.metrics[key], rb.metrics[key]
                tolerance = va.ci95 + vb.ci95
                out[f"{row}/{key}"] = {"a": va.mean, "b": vb.mean, "tolerance": tolerance,
                                       "agree": bool(abs(va.mean - vb.mean) <= tolerance + 1e-12)}
    return out


def corruption_fids(windows: Sequence[np.ndarray], real_z: np.ndarray, embedder, seed: int = 0) -> dict[str, float]:
    """FID between real windows (embedded as ``real_z``) and each corrupted copy of them."""
    out = {}
    for k, kind in enumerate(CORRUPTIONS):
        rng = np.random.default_rng([seed, k])
        out[kind] = metrics.fid(real_z, embedder.embed_motion([corrupt(w, kind, rng) for w in windows]))
    return out


def evaluator_sanity(clips: Sequence[EvalClip], embedder, cfg: GenerationEvalConfig | None = None,
                     reference_clips: Sequence[EvalClip] | None = None,
                     floor_clips: Sequence[EvalClip] | None = None,
                     matched_clips: Sequence[EvalClip] | None = None) -> SanityReport:
    """Run the protocol without generators three times (seed, the same seed again, seed + 1)
    and compute the checks listed in the module docstring.

    ``reference_clips``: train clips (as many as test clips) for the test-vs-train FID;
    ``floor_clips``: another, disjoint set of train clips of the same size, for the FID two
    samples of one distribution reach (the floor the corruption FIDs are compared with);
    ``matched_clips``: train clips with the test clips' content mix (the test-vs-train check;
    without them the plain ``reference_clips`` are checked).
    """
    cfg = cfg or GenerationEvalConfig()
    first = run_protocol(clips, embedder, None, cfg, reference_clips, progress=False)
    again = run_protocol(clips, embedder, None, cfg, reference_clips, progress=False)
    other = run_protocol(clips, embedder, None, replace(cfg, seed=cfg.seed + 1), reference_clips, progress=False)
    report = SanityReport(first)
    chance = 1.0 / cfg.r_precision_batch
    ref, ctl = first.row(REFERENCE_ROW), first.row(CONTROL_ROW)

    windows = draw(list(clips), np.random.default_rng([cfg.seed, 0]), embedder.max_frames).windows(list(clips))
    real_z = embedder.embed_motion(windows)
    corrupted = corruption_fids(windows, real_z, embedder, cfg.seed)
    report.values["fid_corrupted"] = corrupted
    floor = None
    if reference_clips and floor_clips:
        za = embedder.embed_motion(draw(list(reference_clips), np.random.default_rng([cfg.seed, 7]), embedder.max_frames).windows(list(reference_clips)))
        zb = embedder.embed_motion(draw(list(floor_clips), np.random.default_rng([cfg.seed, 8]), embedder.max_frames).windows(list(floor_clips)))
        floor = metrics.fid(za, zb)
        report.values["fid_train_vs_train"] = floor
    if "fid" in ref.metrics:
        report.values["fid_test_vs_train"] = ref.metrics["fid"].mean
    if matched_clips:  # mean over the same repeats as the reference row: test windows vs matched windows
        repeats = [metrics.fid(embedder.embed_motion(draw(list(clips), np.random.default_rng([cfg.seed, 20 + r]),
                                                          embedder.max_frames).windows(list(clips))),
                               embedder.embed_motion(draw(list(matched_clips), np.random.default_rng([cfg.seed, 40 + r]),
                                                          embedder.max_frames).windows(list(matched_clips))))
                   for r in range(max(1, cfg.repeats))]
        report.values["fid_test_vs_matched_train"] = float(np.mean(repeats))
    key = "fid_test_vs_matched_train" if "fid_test_vs_matched_train" in report.values else "fid_test_vs_train"
    if key in report.values:
        report.checks["fid_test_vs_train_small"] = {
            "passed": bool(report.values[key] < corrupted["freeze"] / 10), key: report.values[key],
            "fid_test_vs_train_unmatched": report.values.get("fid_test_vs_train"),
            "fid_frozen": corrupted["freeze"], "fid_train_vs_train": floor,
            "rule": f"{key} < fid_frozen / 10"}
    if floor is not None:
        report.checks["corruptions_detected"] = {
            "passed": all(v > 3 * floor for v in corrupted.values()), "fid_train_vs_train": floor,
            **{f"fid_{k}": v for k, v in corrupted.items()},
            "rule": "FID of every corruption > 3 x fid_train_vs_train"}
    r1, r1_shuffled = ref.metrics["r_precision_top1"].mean, ctl.metrics["r_precision_top1"].mean
    report.checks["matched_above_chance"] = {"passed": bool(r1 >= 3 * chance), "r_precision_top1": r1,
                                             "chance": chance, "rule": "top-1 >= 3 x chance"}
    report.checks["shuffled_near_chance"] = {"passed": bool(r1_shuffled < 2 * chance), "r_precision_top1": r1_shuffled,
                                             "chance": chance, "rule": "shuffled top-1 < 2 x chance"}
    identical = first.to_dict()["rows"] == again.to_dict()["rows"]
    report.checks["same_seed_identical"] = {"passed": bool(identical), "rule": "same seed -> identical values"}
    agreement = repeat_agreement(first, other)
    share = float(np.mean([v["agree"] for v in agreement.values()]))
    report.checks["other_seed_within_ci"] = {
        "passed": share >= MIN_AGREEMENT, "seed_a": cfg.seed, "seed_b": cfg.seed + 1, "share_agreeing": share,
        "metrics": agreement,
        "rule": f"|mean_a - mean_b| <= ci_a + ci_b for at least {MIN_AGREEMENT:.0%} of the metrics"}
    return report


def format_sanity(report: SanityReport) -> str:
    lines = [f"Sanity: {'PASSED' if report.passed else 'FAILED'}"]
    v = report.values
    if v:
        fids = [f"{k} {v[k]:.4f}" for k in ("fid_train_vs_train", "fid_test_vs_train", "fid_test_vs_matched_train")
                if k in v]
        fids += [f"{kind} {x:.4f}" for kind, x in v.get("fid_corrupted", {}).items()]
        lines.append("FID: " + ", ".join(fids))
    for name, check in report.checks.items():
        facts = ", ".join(f"{k}={v:.4f}" if isinstance(v, float) else f"{k}={v}"
                          for k, v in check.items() if k not in ("passed", "rule", "metrics") and v is not None)
        if name == "other_seed_within_ci":
            bad = [k for k, v in check["metrics"].items() if not v["agree"]]
            facts += f", disagreeing: {bad or 'none'}"
        lines.append(f"- {name}: {'pass' if check['passed'] else 'FAIL'} ({check['rule']}; {facts})")
    return "\n".join(lines)
