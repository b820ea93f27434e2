"""``motok-robot data prepare`` and ``motok-robot data show`` (light: heavy imports in handlers)."""

from __future__ import annotations

import argparse

from motok_robot.errors import InputError

KINDS = ("bandai", "cmu", "deepmimic", "acrnn", "bvh", "asf", "humanml3d")


def _source(text: str) -> tuple[str, str]:
    kind, sep, path = text.partition("=")
    if not sep or not path:
        raise argparse.ArgumentTypeError(f"expected KIND=PATH, got {text!r}")
    kind = kind.strip().lower()
    if kind not in KINDS:
        raise argparse.ArgumentTypeError(f"unknown source kind {kind!r}; use one of {', '.join(KINDS)}")
    return kind, path


def register(commands, groups) -> None:
    data = groups["data"]
    p = data.add_parser(
        "prepare",
        help="import motion capture (BVH, ASF/AMC, DeepMimic, HumanML3D) into a training dataset",
        description=(
            "Import motion sources onto the canonical 22-joint body, compute HumanML3D 263-d features at "
            "20 fps, write texts, mirrors, a deterministic train/val/test split and mean/std. KIND is one of "
            + ", ".join(KINDS) + "; PATH a folder or a .tar.xz/.zip archive. See docs/data.md."
        ),
    )
    p.add_argument("--source", action="append", type=_source, required=True, metavar="KIND=PATH",
                   help="a data source (repeat for several)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--texts", help="user text index (CSV with file,text columns or JSON {file: [texts]})")
    p.add_argument("--map", dest="joint_map", action="append", metavar="[KIND=]FILE",
                   help="joint-map JSON for 'bvh' (required) and 'asf' sources; KIND=FILE targets one kind")
    p.add_argument("--no-mirror", dest="mirror", action="store_false", help="do not add left/right mirrored clips")
    p.add_argument("--seed", type=int, default=0, help="salt of the hash-based split (default 0)")
    p.add_argument("--split-by", choices=("group", "clip"), default="group",
                   help="what the split holds out: whole Bandai content+style groups (default) or single clips "
                        "(HumanML3D-style; a mirror stays with its original)")
    p.add_argument("--limit", type=int, default=None, help="at most N files per source (for quick tries)")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2; 1 = in-process)")
    p.add_argument("--asf-fps", type=float, default=120.0, help="frame rate of 'asf' AMC files (default 120)")
    p.add_argument("--overwrite", action="store_true", help="replace a prepared dataset already in --out")
    p.add_argument("--allow-skips", action="store_true",
                   help="finish even when more than --max-skip-share of the files are skipped (each is listed)")
    p.add_argument("--max-skip-share", type=float, default=0.05,
                   help="share of skipped files above which prepare fails unless --allow-skips (default 0.05)")
    p.set_defaults(func=_prepare)

    s = data.add_parser(
        "show",
        help="render one prepared clip as a 3D stick figure (MP4 or GIF)",
        description="Render a clip of a prepared dataset (joints/ID.npy) as a stick-figure animation.",
    )
    s.add_argument("dir", help="prepared dataset folder")
    s.add_argument("--clip", required=True, help="clip id (as in index.jsonl), e.g. bandai/dataset-1_walk_normal_001")
    s.add_argument("--out", required=True, help="output .mp4 or .gif")
    s.set_defaults(func=_show)


def _prepare(args: argparse.Namespace) -> int:
    from motok_robot.data.prepare import PrepareConfig, format_summary, prepare

    if args.limit is not None and args.limit < 1:
        raise InputError(f"--limit must be >= 1, got {args.limit}")
    if args.workers < 1:
        raise InputError(f"--workers must be >= 1, got {args.workers}")
    if not 0.0 <= args.max_skip_share <= 1.0:
        raise InputError(f"--max-skip-share must lie in 0..1, got {args.max_skip_share}")
    joint_map = None
    for item in args.joint_map or []:
        kind, sep, path = item.partition("=")
        if sep and kind in KINDS:
            joint_map = (joint_map if isinstance(joint_map, dict) else {}) | {kind: path}
        elif joint_map is None:
            joint_map = item
        else:
            raise InputError("give one --map FILE, or several --map KIND=FILE")
    cfg = PrepareConfig(
        sources=list(args.source), out=args.out, texts=args.texts, joint_map=joint_map, mirror=args.mirror,
        seed=args.seed, split_by=args.split_by, limit=args.limit, workers=args.workers, asf_fps=args.asf_fps,
        overwrite=args.overwrite, allow_skips=args.allow_skips, max_skip_share=args.max_skip_share,
    )
    summary = prepare(cfg)
    print(format_summary(summary))
    return 0


def _show(args: argparse.Namespace) -> int:
    from pathlib import Path

    from motok_robot.data.dataset import PreparedDataset

    out = Path(args.out)
    if out.suffix.lower() not in (".mp4", ".gif"):
        raise InputError(f"--out must end in .mp4 or .gif, got {out.name!r}")
    ds = PreparedDataset(args.dir, "all")
    if args.clip not in ds:
        close = [c for c in ds.clip_ids if args.clip in c][:5]
        raise InputError(f"{args.dir}: no clip {args.clip!r}" + (f"; did you mean {close}?" if close else ""))
    try:
        from motok_robot.motion.render import render_stick_figure
    except ModuleNotFoundError as exc:
        if exc.name == "motok_robot.motion.render":
            raise InputError("the stick-figure renderer (motok_robot.motion.render) is not installed in this build") from None
        raise
    rec = ds.record(args.clip)
    title = f"{args.clip}: {rec['texts'][0]}" if rec["texts"] else args.clip
    if len(title) > 64:
        title = title[:63] + "\u2026"
    render_stick_figure(ds.joints(args.clip), out, fps=rec["fps"], title=title)
    print(f"wrote {out}")
    return 0
