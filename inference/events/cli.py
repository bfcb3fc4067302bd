"""``rally3d events``: hit events of a clip from its ball track (writes events.csv)."""
from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "events",
        help="detect hit events (bounces, wall and net contacts, racket hits) from a clip's ball.csv",
        description="Runs the hit-event model on the clip's ball track (ball.csv: annotated or from rally3d "
        "detect) and writes events.csv with fine-grained labels. Grouped classes (padel ground_or_other_wall) "
        "are resolved to their surface with the clip's camera.yaml when present, else written as `ground`. "
        "Default model: the shipped one of the clip's sport (inference/weights/hitnet_<sport>.pth.tar).",
    )
    p.add_argument("clip", type=Path)
    p.add_argument("--weights", type=Path, help="a hit-event model file; default: the shipped one")
    p.add_argument("--ball", type=Path, help="ball.csv to read instead of the clip's")
    p.add_argument("--no-camera", action="store_true", help="ignore camera.yaml (grouped classes → default label)")
    p.add_argument("--out", type=Path, help="write here instead of the clip's events.csv")
    p.add_argument("--rally-only", action="store_true",
                   help="leave the events judged outside the point (warm-up bounces, the ball after it) out of "
                   "events.csv; rally.yaml lists them either way")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from inference.clipio import Clip, FormatError, read_ball_csv, write_events_csv

    from .detector import EventDetector

    clip = Clip(args.clip)
    info = clip.info
    ball = read_ball_csv(args.ball) if args.ball else clip.read_ball()
    camera = None
    if not args.no_camera:
        for gt in (False, True):
            try:
                camera = clip.read_camera(gt=gt)
                break
            except (FileNotFoundError, OSError, FormatError):
                continue
    n_frames = info.n_frames or (int(ball.frame[-1]) + 1 if len(ball) else 0)
    det = EventDetector.from_checkpoint(args.weights, sport=info.sport)
    frames = clip.frames(cache_size=0) if det.kind == "crop" else None  # the crop model looks at the video
    try:
        result = det.predict(ball, info.fps, info.width, info.height, camera=camera, n_frames=n_frames,
                             frames=frames, keep_all=not args.rally_only)
    finally:
        if frames is not None:
            frames.close()
    path = write_events_csv(args.out or clip.events_path, result.events)
    from .rally import write_rally_yaml

    rally_path = write_rally_yaml(path.parent / "rally.yaml", result.rally, info.fps,
                                  list(zip(result.outside.frame.tolist(), result.outside.event.tolist())))
    from .rally import rally_summary

    counts = {}
    for e in result.events.event:
        counts[str(e)] = counts.get(str(e), 0) + 1
    print(f"{clip.root.name}: {len(result.events)} events {counts}; "
          f"{rally_summary(result.rally, info.fps, result.outside.event, not args.rally_only)}; wrote {path} "
          f"and {rally_path}")
    return 0
