"""Rebuild the README gallery: run the pipeline for a few prompts, shrink each video to a GIF.

Usage::

    python examples/make_gallery.py [--out out/gallery] [--dest docs/gallery] [--robot op3_like]

Each prompt goes through ``motok-robot run`` (default models, seed 0, 6 s or the planner's
length estimate, plus the prompt's options in ``PROMPTS``) into ``OUT/NAME``;
its ``video.mp4`` (reference motion | physics rollout, failing frames marked red) is
resampled to ``--fps`` and ``--width`` and written to ``DEST/NAME.gif``.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

#: name -> (prompt, extra ``motok-robot run`` options, clip length: None = ``--seconds``,
#: "estimated" = the planner's length estimate)
PROMPTS = {
    "wave_right_hand": ("a person waves the right hand", [], None),
    "raise_both_hands": ("a person raises both hands", [], None),
    "bow": ("a person bows", [], None),
    # the generated walk, turn and kick at their estimated lengths (7.2, 4.4 and 1.8 s with the
    # models shipped 2026-11-28), as `motok-robot run` picks them; the README's Gallery says
    # which pass and which checks the others fail
    "walk_forward": ("a person walks forward", [], "estimated"),
    "walk_turn_left": ("a person walks and turns left", [], "estimated"),
    "kick": ("a person kicks with the right leg", [], "estimated"),
}


def video_to_gif(video: Path, gif: Path, fps: float, width: int) -> Path:
    """Resample ``video`` to ``fps`` frames per second and ``width`` pixels wide, as a looping GIF."""
    import imageio.v2 as imageio
    from PIL import Image

    reader = imageio.get_reader(str(video))
    source_fps = float(reader.get_meta_data().get("fps", 30.0))
    every = max(1, int(round(source_fps / fps)))
    frames = []
    for i, frame in enumerate(reader):
        if i % every:
            continue
        image = Image.fromarray(frame)
        height = int(round(image.height * width / image.width))
        frames.append(np.asarray(image.resize((width, height), Image.Resampling.LANCZOS)))
    reader.close()
    if not frames:
        raise SystemExit(f"{video}: no frames")
    gif.parent.mkdir(parents=True, exist_ok=True)
    imageio.mimsave(str(gif), frames, duration=1000.0 * every / source_fps, loop=0)
    return gif


def motok_robot_command() -> str:
    """The ``motok-robot`` on PATH, else the one installed beside this Python (a virtual
    environment that is not activated)."""
    found = shutil.which("motok-robot")
    beside = Path(sys.executable).with_name("motok-robot")
    if found is None and not beside.is_file():
        raise SystemExit("motok-robot not found on PATH or beside this Python: pip install -e . first")
    return found or str(beside)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/gallery"))
    parser.add_argument("--dest", type=Path, default=Path("docs/gallery"))
    parser.add_argument("--robot", default="op3_like")
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--fps", type=float, default=6.0)
    parser.add_argument("--width", type=int, default=320)
    parser.add_argument("--only", nargs="+", default=None, choices=sorted(PROMPTS))
    args = parser.parse_args(argv)
    motok_robot = motok_robot_command()
    for name in args.only or PROMPTS:
        run_dir = args.out / name
        text, extra, length = PROMPTS[name]
        seconds = [] if length == "estimated" else ["--seconds", str(args.seconds)]
        cmd = [motok_robot, "run", text, "--robot", args.robot, *seconds, "--out", str(run_dir), "--overwrite", *extra]
        print("$", " ".join(cmd), flush=True)
        # a failing validation exits non-zero but still writes the video: that is gallery material too
        subprocess.run(cmd, check=False)
        video = run_dir / "video.mp4"
        if not video.is_file():
            print(f"{name}: no video written (see {run_dir}.failed/FAILED.txt)", file=sys.stderr)
            return 1
        print("wrote", video_to_gif(video, args.dest / f"{name}.gif", args.fps, args.width))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
