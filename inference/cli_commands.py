"""The ``inference`` package's own subcommands (registered through the ``rally3d.commands`` entry points)."""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def _clip_court(clip):
    """The court of a clip: clip.yaml's ``court`` path, else ``conf/court/<sport>.yaml``."""
    from inference.court import load_court

    return load_court(clip.court_path())


# --- rally3d calibrate ---------------------------------------------------------------------------------
def calibrate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "calibrate",
        help="calibrate the camera of a clip from its court_points.csv and write camera.yaml",
        description="Normalised DLT + reprojection-error refinement from the clip's clicked court points "
        "(≥ 6, not all on the ground). Prints the per-point residuals and writes camera.yaml atomically.",
    )
    p.add_argument("clip", type=Path, help="clip folder (with clip.yaml and court_points.csv)")
    p.add_argument("--model", choices=["square", "pinhole"], default="square",
                   help="square: fx = fy (default); pinhole: fx, fy free")
    p.add_argument("--distortion", type=int, choices=[0, 1, 2], default=0,
                   help="number of radial distortion coefficients to fit (default 0)")
    p.add_argument("--dry-run", action="store_true", help="print the result without writing camera.yaml")
    p.set_defaults(func=run_calibrate)


def run_calibrate(args: argparse.Namespace) -> int:
    from inference.calibration import calibrate_court
    from inference.clipio import Clip

    clip = Clip(args.clip)
    court = _clip_court(clip)
    points = clip.read_court_points(known_names=court.point_names)
    size = np.array([clip.info.width, clip.info.height], dtype=float)
    image_points = {n: xy * size for n, xy in zip(points.names, points.xy)}
    result = calibrate_court(court, image_points, (clip.info.width, clip.info.height),
                             model=args.model, n_dist=args.distortion)
    cam = result.camera
    print(f"court {court.name}, {len(result.names)} points, model {args.model}")
    print(result.table())
    print(f"camera centre (m): {np.array2string(cam.centre, precision=3)}   "
          f"focal (px): {cam.K[0, 0]:.1f}, {cam.K[1, 1]:.1f}")
    if result.suspect:
        print(f"warning: these points fit badly, check the clicks: {', '.join(result.suspect)}")
    gt = clip.root / "gt" / "camera.yaml"
    if gt.is_file():
        from inference.camera import Camera

        err = float(np.linalg.norm(Camera.load(gt).centre - cam.centre))
        print(f"camera centre error vs gt/camera.yaml: {err:.3f} m")
    if not args.dry_run:
        path = clip.write_camera(cam)
        print(f"wrote {path}")
    return 0


# --- rally3d courts --------------------------------------------------------------------------------------
def courts(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("courts", help="list the court models, or the named points and planes of one",
                       description="Court models are YAML files under conf/court/.")
    p.add_argument("court", nargs="?", help="a court name (padel, tennis) or a path to a court YAML")
    p.set_defaults(func=run_courts)


def run_courts(args: argparse.Namespace) -> int:
    from inference.court import CONF_DIR, load_court

    if not args.court:
        for f in sorted((CONF_DIR / "court").glob("*.yaml")):
            c = load_court(f)
            print(f"{c.name:<10} {c.size[0]:g} x {c.size[1]:g} m, {len(c.points)} points, "
                  f"{len(c.planes)} planes  ({f})")
        return 0
    c = load_court(args.court)
    print(f"{c.name}: points (x, y, z in metres)")
    for n, xyz in c.points.items():
        print(f"  {n:<28} {xyz[0]:7.3f} {xyz[1]:7.3f} {xyz[2]:6.3f}")
    print("planes (event label, material):")
    for pl in c.planes:
        print(f"  {pl.name:<28} {pl.event:<12} {pl.material}")
    return 0


# --- rally3d check ---------------------------------------------------------------------------------------
def check(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("check", help="validate every file of a clip folder",
                       description="Reads each file of the clip folder that exists and reports problems "
                       "with file, line and fix: opens the video and decodes its first and last frames "
                       "(every frame with --full), checks that the video and camera.yaml have clip.yaml's "
                       "frame size, and that events.csv uses the court's event labels. Exit code 1 if any "
                       "file is invalid.")
    p.add_argument("clips", type=Path, nargs="+", help="clip folders")
    p.add_argument("--full", action="store_true", help="decode every frame of the video (slow on long videos)")
    p.set_defaults(func=run_check)


def check_video(clip, full: bool = False) -> str:
    """Open ``clip``'s video and decode its first and last frames (every frame with ``full``).

    Returns a one-line summary; raises :class:`FormatError` (file, problem, fix) for a video that is
    missing, empty, truncated, undecodable or of another size than clip.yaml says.
    """
    from inference.clipio.errors import FormatError
    from inference.clipio.frames import VIDEO_FIX

    info = clip.info
    path = clip.video_path
    if path.is_file() and path.stat().st_size == 0:
        raise FormatError(path, "the video file is empty (0 bytes)", fix=VIDEO_FIX)
    with clip.frames(cache_size=1) as src:
        n = len(src)
        if n <= 0:
            raise FormatError(path, "the video has no frames", fix=VIDEO_FIX)
        if (src.width, src.height) != (info.width, info.height):
            raise FormatError(path, f"the video is {src.width}×{src.height} but clip.yaml says "
                              f"{info.width}×{info.height}", fix="correct width/height in clip.yaml")
        if full:
            decoded = sum(1 for _ in src.iter())
        else:
            src.read(n - 1)  # a truncated file fails here (its index still counts the lost frames)
            decoded = 2 if n > 1 else 1
        if info.n_frames is not None and info.n_frames > n:
            raise FormatError(clip.clip_yaml_path, f"n_frames is {info.n_frames} but the video has {n} frames",
                              fix=f"set n_frames: {n} (or leave it out)")
    return f"{n} frames, {decoded} decoded"


def run_check(args: argparse.Namespace) -> int:
    from inference.clipio import Clip
    from inference.clipio.atomic import stale_temp_files
    from inference.clipio.errors import FormatError

    bad = 0
    for root in args.clips:
        clip = Clip(root)
        try:
            info = clip.info
            court = _clip_court(clip)
        except (FormatError, FileNotFoundError) as e:
            print(f"FAIL {root}: {e}")
            bad += 1
            continue
        print(f"{root}: {info.sport}, {info.width}x{info.height} @ {info.fps:g} fps")
        try:
            print(f"  ok   {info.video} {check_video(clip, args.full)}")
            n_frames = clip.n_frames
        except FormatError as e:
            print(f"  FAIL {e}")
            bad += 1
            n_frames = info.n_frames

        def camera(gt: bool = False):
            cam = clip.read_camera(gt=gt)
            clip.check_camera(cam, clip.root / ("gt" if gt else "") / "camera.yaml")
            return cam

        labels = court.annotation_labels
        checks = {
            "ball.csv": lambda: clip.read_ball(n_frames=n_frames),
            "inactive_balls.csv": lambda: clip.read_inactive_balls(n_frames=n_frames),
            "events.csv": lambda: clip.read_events(n_frames=n_frames, labels=labels),
            "court_points.csv": lambda: clip.read_court_points(known_names=court.point_names),
            "camera.yaml": camera,
            "ball_3d.csv": lambda: clip.read_ball_3d(n_frames=n_frames),
            "players.csv": lambda: clip.read_players(n_frames=n_frames),
            "gt/camera.yaml": lambda: camera(gt=True),
            "gt/ball_3d.csv": lambda: clip.read_ball_3d(gt=True, n_frames=n_frames),
            "gt/events.csv": lambda: clip.read_events(gt=True, n_frames=n_frames, labels=labels),
            "gt/players.csv": lambda: clip.read_players(gt=True, n_frames=n_frames),
        }
        for name, read in checks.items():
            if not (clip.root / name).is_file():
                continue
            try:
                obj = read()
                n = len(obj) if hasattr(obj, "__len__") else ""
                print(f"  ok   {name} {n}")
            except FormatError as e:
                print(f"  FAIL {e}")
                bad += 1
        for tmp in stale_temp_files(clip.root):
            print(f"  note {tmp.name}: left by a save that did not finish (the labeler removes it at start)")
    return 1 if bad else 0
