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
        "Default model: the shipped player-aware event tagger of the clip's sport "
        "(inference/weights/tagger_<sport>_players.pth.tar), which reads players.csv when the clip has one and "
        "beats the ball-only HitNet (hitnet_<sport>.pth.tar, --weights) with or without it (docs/events.md).",
    )
    p.add_argument("clip", type=Path)
    p.add_argument("--weights", type=Path, help="a hit-event model file; default: the shipped one")
    p.add_argument("--ball", type=Path, help="ball.csv to read instead of the clip's")
    p.add_argument("--players", type=Path,
                   help="players.csv to read instead of the clip's (read by player-aware models; default: the "
                   "clip's players.csv when present)")
    p.add_argument("--no-players", action="store_true", help="ignore players.csv (events from the ball alone)")
    p.add_argument("--no-camera", action="store_true", help="ignore camera.yaml (grouped classes → default label)")
    p.add_argument("--out", type=Path, help="write here instead of the clip's events.csv (an existing file is "
                   "backed up in .rally3d/backup/ beside it, as the clip's events.csv is)")
    p.add_argument("--rally-only", action="store_true",
                   help="leave the events judged outside the point (warm-up bounces, the ball after it) out of "
                   "events.csv; rally.yaml lists them either way")
    from inference.clipio.span import add_span_arguments

    add_span_arguments(p, "find events")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from inference.clipio import Clip, FormatError, read_ball_csv, read_events_csv, write_events_csv
    from inference.clipio.atomic import replace_keeping_backup
    from inference.clipio.span import merge_span, span_of

    from .detector import PLAYERS_OPTIONAL, EventDetector, choose_weights

    clip = Clip(args.clip)
    info = clip.info
    ball = read_ball_csv(args.ball) if args.ball else clip.read_ball()
    span = span_of(args)
    target = args.out or clip.events_path
    old = read_events_csv(target) if span.active and target.is_file() else None  # a bad file fails now
    camera = None
    if not args.no_camera:
        for gt in (False, True):
            try:
                camera = clip.read_camera(gt=gt)
                break
            except (FileNotFoundError, OSError, FormatError):
                continue
    n_frames = info.n_frames or (int(ball.frame[-1]) + 1 if len(ball) else 0)
    if span.active:
        n_frames = info.n_frames or clip.n_frames
        first, stop = span.frames(info.fps, n_frames)
        inside = (ball.frame >= first) & (ball.frame < stop)
        ball = merge_span(ball.empty(), ball, first, stop)  # the model sees the stretch's ball only
        print(f"events: {span.describe(info.fps, n_frames)} only ({int(inside.sum())} ball rows)")
    players = None if args.no_players else read_players_arg(clip, args.players, n_frames)
    det = EventDetector.from_checkpoint(choose_weights(args.weights, info.sport, players), sport=info.sport)
    frames = clip.frames(cache_size=0) if det.kind == "crop" else None  # the crop model looks at the video
    try:
        result = det.predict(ball, info.fps, info.width, info.height, camera=camera, n_frames=n_frames,
                             frames=frames, keep_all=not args.rally_only, players=players)
    finally:
        if frames is not None:
            frames.close()
    events = result.events_with_timing()
    if span.active:
        events = merge_span(old if old is not None else events.empty(), events, first, stop)
    path = replace_keeping_backup(target, lambda tmp: write_events_csv(tmp, events), command="rally3d events").path
    from .rally import rally_summary, write_rally_yaml

    if span.active:  # the point's start and end are judged on the whole clip
        rally_path = "no rally.yaml (--start/--end: run without them to segment the point)"
    else:
        outside = list(zip(result.outside.frame.tolist(), result.outside.event.tolist()))
        rally_path = replace_keeping_backup(
            path.parent / "rally.yaml", lambda tmp: write_rally_yaml(tmp, result.rally, info.fps, outside),
            command="rally3d events").path

    counts = {}
    for e in result.events.event:
        counts[str(e)] = counts.get(str(e), 0) + 1
    if not det.wants_players:
        model = "ball-only model"
    elif players:
        model = f"player-aware model, players of {len(players.ids())} tracks"
    elif args.weights is None and info.sport in PLAYERS_OPTIONAL:
        model = f"player-aware model without players ({info.sport}'s default either way)"
    else:
        model = "player-aware model WITHOUT players"
    print(f"{clip.root.name}: {model}; {len(result.events)} events {counts}; "
          f"{rally_summary(result.rally, info.fps, result.outside.event, not args.rally_only)}; wrote {path} "
          f"and {rally_path}")
    unsure = result.unsure_all(info.fps)
    if unsure:
        print(f"check: {unsure} (events.csv's confidence column)")
    return 0


def read_players_arg(clip, path: Path | None, n_frames: int | None):
    """``--players FILE`` (an error when unreadable) or the clip's players.csv (optional: a warning and
    None when it cannot be read); None when there is none."""
    import logging

    from inference.clipio import FormatError, read_players_csv

    if path is not None:
        if not Path(path).is_file():
            raise FileNotFoundError(f"--players {path}: file not found")
        return read_players_csv(path, n_frames=n_frames or None)
    if not clip.players_path.is_file():
        return None
    try:
        return clip.read_players(n_frames=n_frames or None)
    except (FormatError, ValueError, OSError) as e:
        logging.getLogger(__name__).warning("%s cannot be read (%s): events from the ball alone", clip.players_path, e)
        return None
