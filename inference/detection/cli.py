"""``rally3d detect``: the ball in every frame of a clip with a detector (writes ball.csv)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "detect",
        help="detect and track the ball of a clip with a detector network (writes ball.csv)",
        description="Streams the clip's frames through TrackNetV2, MonoTrack or WASB at full resolution "
        "(288×512 letterbox; with --crop auto a quarter-size window around the tracked ball), turns heatmaps into candidates and tracks the ball (motion model, static-ball "
        "and reflection rejection). Default: WASB with the shipped padel weights (the only shipped ball "
        "detector: a tennis clip gets them too, and the command says so).",
    )
    p.add_argument("clip", type=Path)
    p.add_argument("--model", choices=["wasb", "tracknetv2", "monotrack"],
                   help="architecture when the checkpoint does not name one (default wasb); rally3d's files name it")
    p.add_argument("--weights", type=Path, help="checkpoint (ours or WASB-SBDT); default: the shipped weights. Its "
                   "input normalisation, frames and size are read from the file (WASB-SBDT's files: ImageNet)")
    p.add_argument("--trust-checkpoint", action="store_true",
                   help="allow a checkpoint that holds pickled Python objects (unpickling runs code stored in the "
                   "file: only for files you trust); without it such a file is refused")
    p.add_argument("--step", type=int, default=3, help="window step in frames (3: non-overlapping, 1: pooled)")
    p.add_argument("--batch-size", type=int, default=1,
                   help="windows per forward pass (default 1: fastest on a CPU; raise it on a GPU)")
    p.add_argument("--backend", choices=["auto", "torch", "onnx", "onnx-int8"], default="auto",
                   help="auto (default): ONNX Runtime on the CPU where installed (same heatmaps within 1e-4, ~1.5x "
                   "faster), else eager PyTorch; torch; onnx: ONNX Runtime (pip install 'rally3d[onnx]'), the "
                   "checkpoint exported once and cached in $RALLY3D_CACHE/onnx; onnx-int8: the weights' int8 "
                   "companion NAME.int8.onnx, ~2.5x faster but it loses a few %% of the weak detections "
                   "(docs/detectors.md#int8)")
    p.add_argument("--crop", choices=["auto", "off"], default="auto",
                   help="auto (default): the full frame only to find the ball, then a quarter-size window "
                   "around where the tracker expects it; off: the full frame everywhere")
    p.add_argument("--out", type=Path, help="write here instead of the clip's ball.csv (an existing file is backed "
                   "up in .rally3d/backup/ beside it, as the clip's ball.csv is)")
    from inference.clipio.span import add_span_arguments

    add_span_arguments(p, "detect the ball")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from inference.clipio import Clip, read_ball_csv, write_ball_csv
    from inference.clipio.atomic import replace_keeping_backup
    from inference.clipio.span import merge_span, span_of

    from .crop import crop_config
    from .detect import SHIPPED_SPORT, BallDetectorRunner, shipped_weights

    clip = Clip(args.clip)
    span = span_of(args)
    active = span.mask(clip.info.fps, clip.n_frames) if span.active else None
    target = args.out or clip.ball_path
    old = read_ball_csv(target) if active is not None and target.is_file() else None  # a bad file fails now
    weights = args.weights
    if weights is None:
        model = args.model or "wasb"
        weights, which = shipped_weights(model, clip.info.sport)
        other_sport = SHIPPED_SPORT.get(model) != clip.info.sport
        print(f"{'warning' if other_sport else 'detector'}: {which}", file=sys.stderr if other_sport else sys.stdout)
    else:
        print(f"detector: weights {weights}")
    runner = BallDetectorRunner.from_weights(args.model, weights, trust=args.trust_checkpoint,
                                             step=args.step, batch_size=args.batch_size, backend=args.backend,
                                             crop=crop_config(args.crop))
    result = runner.run(clip, progress=True, active=active)
    track = result.track
    if active is not None:  # the stretch's rows replace those of the existing file; the others are kept
        first, stop = span.frames(clip.info.fps, clip.n_frames)
        track = merge_span(old if old is not None else track.empty(), track, first, stop)
        print(f"detect: {span.describe(clip.info.fps, clip.n_frames)} only")
        seen = int(np.sum(track.visibility[(track.frame >= first) & (track.frame < stop)] == 1))
        n_done = stop - first
    else:
        seen, n_done = int(np.sum(track.visibility == 1)), result.n_frames
    path = replace_keeping_backup(target, lambda tmp: write_ball_csv(tmp, track), command="rally3d detect").path
    print(f"{clip.root.name}: ball detected in {seen} of {n_done} frames, {result.fps:.1f} frames/s "
          f"(network {result.n_frames / max(result.seconds_network, 1e-9):.1f} frames/s, {runner.engine.name}; windows: "
          f"{_windows(result.windows)}); wrote {path}")
    return 0


def _windows(counts: dict[str, int]) -> str:
    """``12 full, 40 crop (3 re-run on the full frame)``."""
    text = f"{counts.get('full', 0)} full"
    if counts.get("crop"):
        text += f", {counts['crop']} crop ({counts.get('crop_rerun', 0)} re-run on the full frame)"
    if counts.get("lost_skipped"):
        text += f", {counts['lost_skipped']} skipped while the ball was lost"
    return text
