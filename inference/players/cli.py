"""``rally3d players``: poses → tracked players with teams and court positions (players.csv)."""
from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    from .backends import BACKENDS
    from .tracking import TRACKERS

    p = sub.add_parser(
        "players",
        help="track the players of a clip and write players.csv (teams, keypoints, court positions)",
        description="Runs a pose backend (or imports another tool's predictions), tracks identities "
        "(OC-SORT), keeps the players (time on court + distance travelled, per side), assigns teams by "
        "court side, fills short gaps and places each player on court through camera.yaml.",
    )
    p.add_argument("clip", type=Path)
    p.add_argument("--pose", choices=BACKENDS, default="import", help="pose backend (default: import)")
    p.add_argument("--predictions", type=Path, help="import: predictions file or folder (MMPose/RTMPose "
                   "JSON, COCO, OpenPose, Ultralytics, CSV)")
    p.add_argument("--format", default="auto", help="import: mmpose, coco, openpose, ultralytics, csv (default auto)")
    p.add_argument("--pose-model", type=Path, help="rtmpose/rtmo: the pose ONNX file")
    p.add_argument("--det-model", type=Path, help="rtmpose: the person detector (YOLOX) ONNX file")
    p.add_argument("--model", type=Path, help="movenet: the MultiPose Lightning .tflite file")
    p.add_argument("--tracker", choices=TRACKERS, default="ocsort")
    from .sampling import parse_pose_every

    p.add_argument("--pose-every", type=parse_pose_every, default=0, metavar="N|auto",
                   help="movenet/rtmpose/rtmo: pose every N-th frame, the tracker fills the frames between "
                   "(default auto: about 15 looks a second, as rally3d infer; 1: every frame)")
    p.add_argument("--gt-camera", action="store_true", help="use gt/camera.yaml instead of camera.yaml")
    p.add_argument("--out", type=Path, help="write here instead of the clip's players.csv (an existing file is "
                   "backed up in .rally3d/backup/ beside it, as the clip's players.csv is)")
    from inference.clipio.span import add_span_arguments

    add_span_arguments(p, "track the players")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from inference.clipio import Clip, read_players_csv, write_players_csv
    from inference.clipio.atomic import replace_keeping_backup
    from inference.clipio.span import merge_span, span_of
    from inference.court import load_court

    from .backends import BackendUnavailable, make_backend
    from .sampling import pose_stride
    from .tracking import TrackingConfig, in_play_area, players_from_poses

    clip = Clip(args.clip)
    camera = clip.read_camera(gt=args.gt_camera)
    court = load_court(clip.court_path())
    backend = make_backend(args.pose, predictions=args.predictions, fmt=args.format, pose_model=args.pose_model,
                           det_model=args.det_model, model=args.model)
    ok, reason = backend.available()
    if not ok:
        raise BackendUnavailable(f"pose backend {args.pose!r}: {reason}")
    span = span_of(args)
    target = args.out or clip.players_path
    old = read_players_csv(target) if span.active and target.is_file() else None  # a bad file fails now
    active = span.mask(clip.info.fps, clip.n_frames) if span.active else None
    tracking = TrackingConfig(tracker=args.tracker)
    poses = backend.run(clip, active=active, stride=pose_stride(clip.info.fps, args.pose_every),
                        focus=in_play_area(camera, court, tracking))
    players = players_from_poses(poses, camera, court, clip.info.fps, tracking)
    if span.active:
        first, stop = span.frames(clip.info.fps, clip.n_frames)
        print(f"players: {span.describe(clip.info.fps, clip.n_frames)} only")
        players = merge_span(old if old is not None else players.empty(), players, first, stop)
    path = replace_keeping_backup(target, lambda tmp: write_players_csv(tmp, players),
                                  command="rally3d players").path
    n_det = sum(len(p) for p in poses.frames)
    print(f"{clip.root.name}: {n_det} detections in {len(poses)} frames → {len(players.ids())} players")
    for pid in players.ids():
        rows = players.of_player(pid)
        med = np.nanmedian(rows.court_xy, axis=0)
        print(f"  player {pid} ({rows.team[0]}): {len(rows)} frames, median court position "
              f"({med[0]:.2f}, {med[1]:.2f}) m")
    if len(players.ids()) < court.n_players:
        print(f"warning: found {len(players.ids())} of {court.n_players} players")
    print(f"wrote {path}")
    return 0
