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
        description="Calibrates from the clip's clicked court points (≥ 6; floor points alone suffice: focal "
        "length and pose from the floor homography, principal point at the image centre; with off-floor points "
        "also a DLT start and a principal point under a prior at the centre), refined on the reprojection error. "
        "Prints the per-point residuals, the camera's uncertainty and weak-geometry warnings, and writes "
        "camera.yaml atomically. See docs/calibration.md.",
    )
    p.add_argument("clip", type=Path, help="clip folder (with clip.yaml and court_points.csv)")
    p.add_argument("--model", choices=["square", "pinhole"], default="square",
                   help="square: fx = fy (default); pinhole: fx, fy free")
    p.add_argument("--distortion", type=int, choices=[0, 1, 2], default=0,
                   help="number of radial distortion coefficients to fit (default 0)")
    p.add_argument("--dry-run", action="store_true", help="print the result without writing camera.yaml")
    p.add_argument("--auto", action="store_true",
                   help="no clicks: find the court's painted lines in the video (median of a few frames) and fit "
                   "the court to them; writes camera.yaml (source: auto) only when the fit passes its gate, and the "
                   "fitted floor points (court_points.csv when there is none, else court_points_auto.csv) to "
                   "check or correct in the labeler")
    p.add_argument("--frames", help="with --auto: frame indices to use, e.g. 0,50,100 (default: 9 spread over "
                   "the clip)")
    p.add_argument("--drift", action="store_true",
                   help="check the clip's camera.yaml against the video: the court lines' image shift every second "
                   "and whether the camera drifts beyond the calibration's residuals (writes nothing)")
    p.set_defaults(func=run_calibrate)


def run_auto_calibrate(args: argparse.Namespace, clip, court) -> int:
    """``rally3d calibrate CLIP --auto``: the automatic court fit, its figures and its gate."""
    import sys

    from inference.clipio import CourtPoints, write_court_points_csv
    from inference.courtfit import fit_court

    frames = [int(v) for v in args.frames.split(",")] if args.frames else None
    fit = fit_court(clip, court, frames=frames)
    print(f"court {court.name}, frames {fit.frames}")
    print(fit.summary())
    if fit.camera is not None:
        cam = fit.camera
        print(f"camera centre (m): {np.array2string(cam.centre, precision=3)}   focal (px): {cam.K[0, 0]:.1f}")
        _compare_gt(clip, cam)
    if not fit.accepted:
        print(f"not written: the fit is not reliable ({fit.reason or 'no court found'}). Click court points "
              f"instead (rally3d label {clip.root}) and run rally3d calibrate.", file=sys.stderr)
        return 1
    if not args.dry_run:
        print(f"wrote {clip.write_camera(fit.camera)}")
        pts = fit.court_points(court)
        size = np.array([clip.info.width, clip.info.height], dtype=float)
        table = CourtPoints(list(pts), np.array(list(pts.values())).reshape(-1, 2) / size)
        if clip.court_points_path.is_file():  # never replace a person's clicks
            path = write_court_points_csv(clip.root / AUTO_POINTS, table)
            print(f"wrote {path}: the fitted floor points (court_points.csv, your clicks, is left alone)")
        else:
            path = clip.write_court_points(table)
            print(f"wrote {path}: the fitted floor points; check or drag them in `rally3d label {clip.root}` "
                  "(the camera is recalibrated from them live)")
    return 0


#: where ``calibrate --auto`` writes the fitted points when the clip already has clicked court points
AUTO_POINTS = "court_points_auto.csv"


def _compare_gt(clip, cam) -> None:
    gt = clip.root / "gt" / "camera.yaml"
    if gt.is_file():
        from inference.camera import Camera

        err = float(np.linalg.norm(Camera.load(gt).centre - cam.centre))
        print(f"camera centre error vs gt/camera.yaml: {err:.3f} m")


def run_calibrate(args: argparse.Namespace) -> int:
    from inference.calibration import calibrate_court
    from inference.clipio import Clip

    clip = Clip(args.clip)
    court = _clip_court(clip)
    if args.drift:
        from inference.courtfit.drift import measure_drift

        report = measure_drift(clip, clip.read_camera(), court)
        print(report.table())
        return 0
    if args.auto:
        return run_auto_calibrate(args, clip, court)
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
    _compare_gt(clip, cam)
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
            print(f"{c.name:<13} {c.size[0]:g} x {c.size[1]:g} m, {len(c.points)} points, "
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
