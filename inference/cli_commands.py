"""The ``inference`` package's own subcommands (registered through the ``rally3d.commands`` entry points)."""
from __future__ import annotations

import argparse
from collections.abc import Callable, Collection, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from inference.clipio.errors import FormatError


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
        print(f"wrote {_write_camera(clip, fit.camera)}")
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
    from inference.camera.calibration import calibrate_court, court_view_problems
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
    lines = clip.read_court_line_points(known_names=court.point_names, missing_ok=True)
    size = np.array([clip.info.width, clip.info.height], dtype=float)
    image_points = {n: xy * size for n, xy in zip(points.names, points.xy)}
    line_points = [(a, b, xy * size) for a, b, xy in zip(lines.start, lines.end, lines.xy)]
    result = calibrate_court(court, image_points, (clip.info.width, clip.info.height),
                             model=args.model, n_dist=args.distortion, line_points=line_points)
    cam = result.camera
    along = f" + {len(line_points)} along court lines ({clip.court_line_points_path.name})" if line_points else ""
    print(f"court {court.name}, {len(result.names)} points{along}, model {args.model}"
          + (f", lens k1 {cam.dist[0]:+.3f}" if args.distortion and cam.dist is not None else ""))
    print(result.table())
    print(f"camera centre (m): {np.array2string(cam.centre, precision=3)}   "
          f"focal (px): {cam.K[0, 0]:.1f}, {cam.K[1, 1]:.1f}")
    if result.suspect:
        print(f"warning: these points fit badly, check the clicks: {', '.join(result.suspect)}")
    _compare_gt(clip, cam)
    problems = court_view_problems(cam, court)
    if problems:
        import sys

        print(f"rally3d calibrate: error: {clip.court_points_path}: this calibration cannot be right — "
              f"{'; '.join(problems)}. Nothing written. Check the clicked points (rally3d label {clip.root}): "
              "spread over the court, on the right named points, not all on one line.", file=sys.stderr)
        return 1
    if not args.dry_run:
        print(f"wrote {_write_camera(clip, cam)}")
    return 0


def _write_camera(clip, cam) -> Path:
    """Write the clip's camera.yaml; a different one already there is backed up first (and said so)."""
    from inference.clipio.atomic import replace_keeping_backup

    return replace_keeping_backup(clip.camera_path, cam.save, command="rally3d calibrate").path


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
    p = sub.add_parser("check", help="validate every file of clip folders or datasets",
                       description="Reads each file of each clip folder that exists and reports problems "
                       "with file, line and fix: opens the video and decodes its first and last frames "
                       "(every frame with --full), checks that the video and camera.yaml have clip.yaml's "
                       "frame size, and that events.csv uses the court's event labels. A dataset (a folder "
                       "with manifest.yaml, a manifest.yaml, or a folder of clip folders) is checked clip by "
                       "clip, every clip, and ends with a summary. Exit code 1 if any file is invalid.")
    p.add_argument("clips", type=Path, nargs="+",
                   help="clip folders, dataset folders (manifest.yaml or clip folders) or manifest.yaml files")
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


@dataclass
class ClipCheck:
    """What :func:`check_clip` found in one clip folder: the lines ``rally3d check`` prints, and the problems."""

    root: Path
    lines: list[str] = field(default_factory=list)
    problems: list[FormatError] = field(default_factory=list)  # each names its file, line and fix

    def fail(self, err: FormatError) -> None:
        self.problems.append(err)
        self.lines.append(f"  FAIL {err}")


@dataclass
class CheckReport:
    """Every clip :func:`check_paths` checked, and the problems of the datasets themselves (a manifest that
    cannot be read, an entry without its clip folder)."""

    clips: list[ClipCheck] = field(default_factory=list)
    dataset_problems: list[FormatError] = field(default_factory=list)

    @property
    def problems(self) -> list[FormatError]:
        return self.dataset_problems + [p for c in self.clips for p in c.problems]

    def summary(self) -> str:
        """``3 of 24 clips have problems: a, b, c`` (plus the datasets' own problems), or ``24 clips, all fine``."""
        bad = [c.root.name or str(c.root) for c in self.clips if c.problems]
        n = len(self.clips)
        text = f"{n} clip{'s' * (n != 1)}, all fine"
        if bad:
            more = f" … (+{len(bad) - 20})" if len(bad) > 20 else ""
            text = f"{len(bad)} of {n} clips have problems: {', '.join(bad[:20])}{more}"
        if self.dataset_problems:
            text += f"; {len(self.dataset_problems)} problem(s) in the dataset itself (its manifest)"
        return text


def check_clip(root: Path, *, full: bool = False, files: Collection[str] | None = None,
               labels: Sequence[str] | None = None) -> ClipCheck:
    """Read the files of clip folder ``root``: clip.yaml, then the video and every table that exists
    (``files``: only those names that exist, ``"video"`` for the video; ``()``: clip.yaml alone).

    ``labels``: the event labels events.csv may hold (default: the clip's court's, loaded when ``files``
    is None, else any). Never raises for a bad file: each problem is a :class:`FormatError` in the result.
    """
    from inference.clipio import Clip
    from inference.clipio.atomic import stale_temp_files
    from inference.clipio.errors import FormatError

    clip, check = Clip(root), ClipCheck(Path(root))
    try:
        info = clip.info
        court = _clip_court(clip) if files is None else None
    except (FormatError, FileNotFoundError) as e:  # FileNotFoundError: clip.yaml names no known court
        err = e if isinstance(e, FormatError) else FormatError(clip.clip_yaml_path, str(e),
                                                               fix="set sport (or court) to a known court")
        check.problems.append(err)
        check.lines.append(f"FAIL {root}: {err}")
        return check
    check.lines.append(f"{root}: {info.sport}, {info.width}x{info.height} @ {info.fps:g} fps")
    n_frames = info.n_frames
    if files is None or "video" in files:
        try:
            check.lines.append(f"  ok   {info.video} {check_video(clip, full)}")
            n_frames = clip.n_frames
        except FormatError as e:
            check.fail(e)
    for name, read in _table_readers(clip, n_frames, court, labels).items():
        if (files is not None and name not in files) or not (clip.root / name).is_file():
            continue
        try:
            obj = read()
            check.lines.append(f"  ok   {name} {len(obj) if hasattr(obj, '__len__') else ''}")
        except FormatError as e:
            check.fail(e)
        except ValueError as e:  # a reader's own check that does not name the file yet
            check.fail(FormatError(clip.root / name, str(e), fix="correct the file (docs/formats.md)"))
    for tmp in stale_temp_files(clip.root):
        check.lines.append(f"  note {tmp.name}: left by a save that did not finish (the labeler removes it at start)")
    return check


def _table_readers(clip, n_frames: int | None, court, labels: Sequence[str] | None) -> dict[str, Callable]:
    """The readers of a clip's tables and calibrations by file name (``court``: its labels and point names)."""
    labels = labels if labels is not None or court is None else court.annotation_labels
    points = court.point_names if court is not None else None

    def camera(gt: bool = False):
        path = clip.root / ("gt" if gt else "") / "camera.yaml"
        cam = clip.read_camera(gt=gt)
        clip.check_camera(cam, path)
        if court is not None:  # a camera that cannot see the court (focal ~0 px, under the floor, looking away)
            from inference.camera.calibration import require_court_view

            require_court_view(cam, court, path)
        return cam

    return {
        "ball.csv": lambda: clip.read_ball(n_frames=n_frames),
        "inactive_balls.csv": lambda: clip.read_inactive_balls(n_frames=n_frames),
        "events.csv": lambda: clip.read_events(n_frames=n_frames, labels=labels),
        "court_points.csv": lambda: clip.read_court_points(known_names=points),
        "court_line_points.csv": lambda: clip.read_court_line_points(known_names=points),
        "camera.yaml": camera,
        "ball_3d.csv": lambda: clip.read_ball_3d(n_frames=n_frames),
        "players.csv": lambda: clip.read_players(n_frames=n_frames),
        "gt/camera.yaml": lambda: camera(gt=True),
        "gt/ball_3d.csv": lambda: clip.read_ball_3d(gt=True, n_frames=n_frames),
        "gt/events.csv": lambda: clip.read_events(gt=True, n_frames=n_frames, labels=labels),
        "gt/players.csv": lambda: clip.read_players(gt=True, n_frames=n_frames),
    }


def check_paths(paths: Iterable[Path], *, full: bool = False, files: Callable[[Path], Collection[str]] | None = None,
                labels: Sequence[str] | None = None,
                on_clip: Callable[[ClipCheck], None] | None = None) -> CheckReport:
    """Check every clip of ``paths`` (clip folders, dataset folders or manifest.yaml files) with
    :func:`check_clip`; ``files(root)``: the names to read of each clip (None: every file that exists);
    ``on_clip(check)`` is called after each clip. Nothing stops at a bad clip: all problems are reported."""
    from inference.clipio.errors import FormatError
    from inference.clipio.manifest import dataset_clips

    report = CheckReport()
    for path in paths:
        try:
            roots = dataset_clips(path, skipped=report.dataset_problems) or [Path(path)]
        except FormatError as e:  # a manifest.yaml that cannot be read at all
            report.dataset_problems.append(e)
            continue
        for root in roots:
            result = check_clip(root, full=full, files=None if files is None else files(root), labels=labels)
            report.clips.append(result)
            if on_clip is not None:
                on_clip(result)
    return report


def run_check(args: argparse.Namespace) -> int:
    report = check_paths(args.clips, full=args.full, on_clip=lambda c: print("\n".join(c.lines)))
    for e in report.dataset_problems:
        print(f"FAIL {e}")
    if len(report.clips) > 1 or report.dataset_problems:
        print(report.summary())
    return 1 if report.problems else 0
