"""Turn what the user gives ``rally3d infer`` (a video file or a clip folder) into the clip folder it writes.

* a **video**: a new clip folder (``--out``, default ``runs/infer/<video stem>``) whose ``clip.yaml`` points at
  the video (relative path; the video is not copied) with the size, frame rate and frame count read from it
  (a variable-frame-rate video: its nominal rate, and ``timing:`` says which frames the reader repeats and
  drops to present it at that rate);
* a **clip folder** without ``--out``: the clip itself (results are written beside its files);
* a **clip folder** with ``--out``: a new clip folder pointing at the same video, with the calibration inputs
  (``court_points.csv``, ``camera.yaml``) copied, but *not* the annotations — so the original can serve as the
  reference the results are scored against.

``--camera`` and ``--court-points`` files are copied in after checking that they fit the video; a different
``camera.yaml`` / ``court_points.csv`` already in the clip (clicked by hand) is first copied to
``.rally3d/backup/`` and the command says so.

With ``--start``/``--end`` (seconds), the stretch of a long video is re-encoded into the new clip folder's
``video.mp4`` (H.264, CRF 18) and ``clip.yaml`` records where it came from (``cut:``); a re-run with the same
stretch reuses it.
"""
from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path

from inference.camera import Camera
from inference.clipio import Clip, ClipInfo, FormatError
from inference.clipio.span import Span

VIDEO_SUFFIXES = {".mp4", ".mov", ".avi", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg"}


@dataclass
class Prepared:
    """The clip folder to write and where it came from.

    Attributes:
        clip: the output clip folder (``clip.yaml`` written).
        source: the input path (video or clip folder).
        reference: a clip with annotations or ground truth to score against, if any.
    """

    clip: Clip
    source: Path
    reference: Clip | None = None


def is_clip_folder(path: Path) -> bool:
    return path.is_dir() and (path / "clip.yaml").is_file()


def probe_video(path: Path) -> tuple[int, int, float, int]:
    """(width, height, fps, n_frames) of a video file; a clear :class:`FormatError` if it cannot be read."""
    if not path.is_file():
        raise FormatError(path, "video file not found", fix="check the path")
    from inference.clipio.frames import VIDEO_FIX, FrameSource  # here: `rally3d infer --help` needs no OpenCV

    with FrameSource.open(path, cache_size=0) as src:  # decodes frame 0: a corrupt file fails here
        if not src.fps or src.fps <= 0:
            raise FormatError(path, "the video does not state its frame rate", fix=VIDEO_FIX)
        return src.width, src.height, float(src.fps), len(src)


def video_timing(path: Path, fps: float, first: int = 0, stop: int | None = None) -> dict | None:
    """clip.yaml's ``timing`` for a variable-frame-rate video presented at ``fps`` (its frames
    ``first .. stop-1``): the rates and the frames repeated and dropped
    (:meth:`~inference.clipio.probe.Resampling.record`); None when the timing is regular or the container
    cannot be probed."""
    from inference.clipio.probe import probe_video_file

    probe = probe_video_file(path)
    if probe is None or not probe.vfr:
        return None
    return probe.resampling(fps).record(first, stop)


def picture_repeats(path: Path, fps: float):
    """The regular beat of repeated pictures of a video at a constant rate
    (:func:`~inference.clipio.probe.find_picture_repeats`; a 25 fps broadcast in a 30 fps file), or None."""
    from inference.clipio.probe import find_picture_repeats, probe_video_file

    probe = probe_video_file(path)
    if probe is not None and probe.vfr:
        return None  # resampled by its timestamps instead
    return find_picture_repeats(path, fps)


def _content(path: Path) -> tuple[int, int, float, int, dict | None, object]:
    """(width, height, fps, n_frames, clip.yaml's ``timing`` or None, the repeats or None) of a video as a
    clip reads it: at its nominal rate, the repeated pictures of a converted broadcast left out."""
    width, height, fps, n = probe_video(path)
    repeats = picture_repeats(path, fps)
    if repeats is not None:
        from inference.clipio.frames import FrameSource

        with FrameSource.open(path, cache_size=0, repeats=repeats) as src:
            return width, height, float(src.fps), len(src), {"repeated_pictures": repeats.record()}, repeats
    return width, height, fps, n, video_timing(path, fps), None


def video_notes(path: Path) -> list[str]:
    """What the reader does to present ``path`` (a video file or clip folder) at a constant rate,
    progressive: variable frame rate resampled, interlacing removed ([] when nothing, or not a video)."""
    from inference.clipio.frames import FrameSource

    try:
        with FrameSource.open(path, cache_size=0) as src:
            return list(getattr(src, "notes", []))
    except (FormatError, OSError):
        return []


#: a stretch of a long video, in seconds (``--start``/``--end``); the same as the other commands' stretches
Cut = Span


def prepare(source: Path, out: Path | None, court: str | None, camera: Path | None = None,
            court_points: Path | None = None, cut: Cut | None = None) -> Prepared:
    """Create or reuse the clip folder for ``source`` (see the module docstring)."""
    source = Path(source)
    if cut is not None and cut.active:
        return _prepare_cut(source, out, court, camera, court_points, cut)
    if is_clip_folder(source):
        src_clip = Clip(source)
        info = src_clip.info
        if court and court != info.sport:
            raise ValueError(f"{src_clip.clip_yaml_path}: the clip is {info.sport!r} but --court {court!r} was "
                             "given; leave --court out or fix clip.yaml")
        if out is None or Path(out).resolve() == source.resolve():
            clip, reference = src_clip, None
        else:
            timing = info.extra.get("timing")  # how the video is read (its rate, repeated pictures) goes along
            clip = _new_clip(Path(out), info, src_clip.video_path, {"timing": timing} if timing else None)
            for name in ("court_points.csv", "camera.yaml"):
                if (source / name).is_file() and not (clip.root / name).exists():
                    shutil.copy2(source / name, clip.root / name)
            reference = src_clip
    elif source.suffix.lower() in VIDEO_SUFFIXES or source.is_file():
        if not court:
            raise ValueError(f"{source}: a video needs --court (padel or tennis, or a court YAML path)")
        width, height, fps, n, timing, _ = _content(source)
        out = Path(out) if out is not None else Path("runs/infer") / source.stem
        info = ClipInfo(sport=Path(court).stem if court.endswith(".yaml") else court, fps=fps, width=width,
                        height=height, video="video.mp4", n_frames=n, source=str(source))
        if court.endswith(".yaml"):
            info.court = os.path.relpath(Path(court).resolve(), out.resolve())
        clip, reference = _new_clip(out, info, source, {"timing": timing} if timing else None), None
    else:
        raise FileNotFoundError(f"{source}: neither a video file nor a clip folder (with clip.yaml)")
    _install_calibration(clip, camera, court_points)
    return Prepared(clip, source, reference)


def _prepare_cut(source: Path, out: Path | None, court: str | None, camera: Path | None,
                 court_points: Path | None, cut: Cut) -> Prepared:
    """A new clip folder holding ``[start, end)`` of the video (re-encoded as ``video.mp4``, H.264)."""
    from inference.clipio import write_video

    if is_clip_folder(source):
        src_info = Clip(source).info
        video, court = Clip(source).video_path, court or src_info.sport
    else:
        video = source
    if not court:
        raise ValueError(f"{source}: a video needs --court (padel or tennis, or a court YAML path)")
    width, height, fps, n, _, repeats = _content(video)
    first, stop = cut.frames(fps, n)
    tag = f"_{first}-{stop}"
    out = Path(out) if out is not None else Path("runs/infer") / (Path(video).stem + tag)
    if is_clip_folder(source) and out.resolve() == source.resolve():
        raise ValueError(f"{source}: --start/--end write a new clip folder; pass --out elsewhere")
    record = {"video": os.path.relpath(Path(video).resolve(), out.resolve()), "start_s": cut.start_s,
              "end_s": cut.end_s, "first_frame": first, "stop_frame": stop,
              **({"repeated_pictures_left_out": repeats.record()} if repeats is not None else {})}
    clip_yaml = out / "clip.yaml"
    if clip_yaml.is_file() and Clip(out).info.extra.get("cut") == record and (out / "video.mp4").is_file():
        clip = Clip(out)  # the same cut as before: resume
    else:
        if clip_yaml.is_file() and "cut" not in Clip(out).info.extra:
            raise FileExistsError(f"{clip_yaml} belongs to another clip; choose another --out")
        out.mkdir(parents=True, exist_ok=True)
        from inference.clipio.frames import FrameSource

        with FrameSource.open(video, cache_size=0, repeats=repeats) as src:  # the repeats left out
            written = write_video(out / "video.mp4", src.iter(first, stop), fps, fourcc="h264", crf=18)
        timing = None if repeats is not None else video_timing(video, fps, first, stop)
        info = ClipInfo(sport=Path(court).stem if court.endswith(".yaml") else court, fps=fps, width=width,
                        height=height, video="video.mp4", n_frames=written,
                        source=f"{video} from {first / fps:.2f} s (frame {first})",
                        extra={"cut": record, **({"timing": timing} if timing else {})})
        if court.endswith(".yaml"):
            info.court = os.path.relpath(Path(court).resolve(), out.resolve())
        clip = Clip.create(out, info, exist_ok=True)
    if is_clip_folder(source) and camera is None and (source / "camera.yaml").is_file():
        camera = source / "camera.yaml"  # the camera does not change along a video; clicked points neither
    if is_clip_folder(source) and court_points is None and (source / "court_points.csv").is_file():
        court_points = source / "court_points.csv"
    _install_calibration(clip, camera, court_points)
    return Prepared(clip, source, None)


def request_auto_mask(clip: Clip, log=print) -> Clip:
    """Put ``mask: auto`` into ``clip``'s clip.yaml (``infer --mask auto``); the previous clip.yaml is kept
    in ``.rally3d/backup/``. Rectangles already there win (a user's mask is never replaced)."""
    from inference.clipio import write_clip_yaml
    from inference.video.masks import AUTO

    mask = clip.info.extra.get("mask")
    if mask == AUTO:
        return clip
    if mask:
        log(f"rally3d infer: {clip.clip_yaml_path} has its own mask rectangles; --mask auto is not applied")
        return clip
    from .state import backup_file

    copy = backup_file(clip.root, clip.clip_yaml_path)
    info = clip.info
    info.extra = {**info.extra, "mask": AUTO}
    write_clip_yaml(clip.clip_yaml_path, info)
    log(f"rally3d infer: mask: auto written to {clip.clip_yaml_path} (previous file kept in {copy})")
    return Clip(clip.root)


def _new_clip(out: Path, info: ClipInfo, video: Path, extra: dict | None = None) -> Clip:
    """A clip folder at ``out`` whose clip.yaml points (relatively) at ``video``; ``extra``: keys to add (not
    ``info``'s own extra keys, which belong to the source clip)."""
    out.mkdir(parents=True, exist_ok=True)
    rel = os.path.relpath(Path(video).resolve(), out.resolve())
    new = ClipInfo(**{**{k: v for k, v in info.to_dict().items() if k in ClipInfo.__dataclass_fields__},
                      "video": rel, "extra": dict(extra or {})})
    if (out / "clip.yaml").is_file():
        old = Clip(out).info
        if old.video != new.video or (old.width, old.height) != (new.width, new.height):
            raise FileExistsError(f"{out}/clip.yaml belongs to another video ({old.video}); choose another --out")
    return Clip.create(out, new, exist_ok=True)


def _install_calibration(clip: Clip, camera: Path | None, court_points: Path | None, log=print) -> None:
    """Copy ``--camera`` / ``--court-points`` into the clip (previous versions backed up). New court points
    without ``--camera`` retire a camera.yaml made by hand from other points (backed up, then recalibrated by
    the camera stage from the new points), so that points and camera never disagree."""
    if camera is not None:
        _install_camera(clip, Path(camera), log)
    if court_points is None or not _install_court_points(clip, Path(court_points), log):
        return
    if camera is None and clip.camera_path.is_file():
        from .state import RunState, backup_file

        if RunState(clip.root).written_by_pipeline(clip.camera_path):
            return  # the camera stage recalibrates it from the new points anyway
        copy = backup_file(clip.root, clip.camera_path)
        clip.camera_path.unlink()
        log(f"rally3d infer: {clip.camera_path} was not calibrated from the new court points; it is kept in "
            f"{copy} and the camera is calibrated from {court_points}")


def _install_camera(clip: Clip, path: Path, log=print) -> None:
    from inference.camera.calibration import require_court_view
    from inference.court import load_court

    cam = Camera.load(path)  # clear FormatError on a malformed file
    clip.check_camera(cam, path)
    require_court_view(cam, load_court(clip.court_path()), path)  # before a long run that cannot place anything
    if path.resolve() != clip.camera_path.resolve():
        _replace_from(clip.camera_path, path, log)


def _install_court_points(clip: Clip, path: Path, log=print) -> bool:
    """Copy ``path`` to the clip's court_points.csv; whether its content changed."""
    if path.resolve() == clip.court_points_path.resolve():
        return False
    from inference.clipio import read_court_points_csv

    read_court_points_csv(path)  # clear FormatError on a malformed file
    return _replace_from(clip.court_points_path, path, log)


def _replace_from(target: Path, source: Path, log) -> bool:
    """Copy ``source`` over ``target`` keeping a backup of a different ``target`` (the one rule of
    :func:`inference.clipio.atomic.replace_keeping_backup`); whether ``target`` changed."""
    from inference.clipio.atomic import replace_keeping_backup

    data = source.read_bytes()
    return replace_keeping_backup(target, lambda tmp: tmp.write_bytes(data), log=log,
                                  command="rally3d infer").changed
