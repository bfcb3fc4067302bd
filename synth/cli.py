"""``rally3d synth``: generate a synthetic dataset (clip folders + manifest.yaml)."""
from __future__ import annotations

import argparse
import time
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "synth",
        help="generate synthetic padel/tennis rally clips with full ground truth",
        description="Simulates rallies (gravity, drag, spin, bounces on floor, glass and net), renders "
        "them from a (randomised) camera and writes one clip folder per rally plus manifest.yaml with "
        "train/val/test splits. The same --seed gives identical files.",
    )
    p.add_argument("--sport", choices=["padel", "tennis"], default="padel")
    p.add_argument("--clips", type=int, default=20, help="number of clips (default 20)")
    p.add_argument("--out", type=Path, required=True, help="dataset folder to write")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--camera", help="camera preset (padel_installed, padel_broadcast, padel_tv, tennis_broadcast, "
                   "tennis_high, tennis_tv; default per sport)")
    p.add_argument("--fixed-camera", action="store_true", help="do not randomise the camera preset")
    p.add_argument("--plain", action="store_true", help="clean look: no noise, no JPEG, neutral colours")
    p.add_argument("--fps", type=float, help="fix the frame rate (default: drawn from 25, 30, 50, 60)")
    p.add_argument("--size", help="fix the resolution, e.g. 1280x720")
    p.add_argument("--codec", choices=["h264", "mp4v", "frames"], default="h264",
                   help="h264 (default, realistic compression), mp4v (fast) or frames (JPEG folder)")
    p.add_argument("--max-frames", type=int, help="cut clips to this many frames")
    p.add_argument("--click-noise", type=float, default=1.0, help="±px noise on court_points.csv (default 1)")
    p.add_argument("--around-point", action="store_true",
                   help="add the server's bounces before the serve and the ball after the point (not events; "
                   "gt/rally.yaml marks the point)")
    p.add_argument("--venue", choices=["club", "tour"], default="club",
                   help="club (default look) or tour (padel: a tour event as broadcast — bright glass rails and "
                   "posts, the court's outline unpainted, floor logos, a score box, an advertising board; use "
                   "it with --camera padel_tv)")
    p.add_argument("--mid-rally", action="store_true",
                   help="cut each clip's start in the middle of a flight after the serve, as broadcast clips are "
                   "(no serve in the clip)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from .generate import SynthConfig, generate_dataset

    width = height = None
    if args.size:
        try:
            width, height = (int(v) for v in args.size.lower().split("x"))
        except ValueError:
            raise ValueError(f"--size must look like 1280x720, got {args.size!r}") from None
    if args.clips < 1:
        raise ValueError("--clips must be >= 1")
    check_out_folder(args.out)
    config = SynthConfig(sport=args.sport, camera=args.camera, randomise_camera=not args.fixed_camera,
                         fps=args.fps, width=width, height=height, randomise_look=not args.plain,
                         codec=args.codec, click_noise_px=args.click_noise, max_frames=args.max_frames,
                         around_point=args.around_point, venue=args.venue, mid_rally=args.mid_rally)
    frames = [0]
    t0 = time.perf_counter()
    with tqdm(total=args.clips, unit="clip", desc=f"synth {args.sport}") as bar:
        def progress(k, summary):
            frames[0] += summary.n_frames
            bar.set_postfix(frames=frames[0], fps=f"{frames[0] / (time.perf_counter() - t0):.1f}")
            bar.update(1)

        manifest = generate_dataset(args.out, args.clips, args.seed, config, progress=progress)
    print(f"wrote {len(manifest.clips)} clips ({frames[0]} frames) to {args.out}: {manifest.counts()}")
    return 0


def check_out_folder(out: Path) -> None:
    """Refuse an ``--out`` that is a file, or a folder holding clips that ``rally3d synth`` did not make
    (a person's labelled clips must never be overwritten by generated ones).

    Raises:
        ValueError: naming the path and the fix.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file, not a folder: name a new or empty folder for the dataset")
    if not out.is_dir():
        return
    for clip_yaml in sorted(out.glob("*/clip.yaml")):
        try:
            import yaml

            made_here = "synth" in (yaml.safe_load(clip_yaml.read_text(encoding="utf-8")) or {})
        except (OSError, UnicodeDecodeError, yaml.YAMLError, TypeError):
            made_here = False
        if not made_here:
            raise ValueError(f"--out {out} holds clips that rally3d synth did not make ({clip_yaml.parent.name}); "
                             "generated clips would overwrite them: name a new or empty folder")
