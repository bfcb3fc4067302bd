"""One clip folder (docs/formats.md): paths of its files and typed reads/writes of each."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from . import csvfiles
from .clip_yaml import ClipInfo, read_clip_yaml, write_clip_yaml
from .errors import FormatError
from .players import PlayerTracks, read_players_csv, write_players_csv
from .tables import Ball3D, BallTrack, CourtLinePoints, CourtPoints, HitEvents, InactiveBalls

if TYPE_CHECKING:
    from .frames import FrameSource
    from inference.camera import Camera

T = TypeVar("T")


class Clip:
    """A clip folder. Reading is lazy: nothing is opened until asked for.

    Example::

        clip = Clip("clips/rally_001")
        track = clip.read_ball()
        clip.write_events(HitEvents(frame=[12], event=["ground"]))
    """

    def __init__(self, root: str | Path):
        self.root = Path(root)

    def __repr__(self) -> str:
        return f"Clip({str(self.root)!r})"

    @classmethod
    def create(cls, root: str | Path, info: ClipInfo, *, exist_ok: bool = False) -> Clip:
        """Create the folder ``root`` and write its ``clip.yaml``."""
        root = Path(root)
        if (root / "clip.yaml").exists() and not exist_ok:
            raise FileExistsError(f"{root / 'clip.yaml'} already exists (pass exist_ok=True to overwrite)")
        clip = cls(root)
        clip.write_info(info)
        return clip

    # ---------------------------------------------------------------------------------------- paths
    @property
    def clip_yaml_path(self) -> Path:
        return self.root / "clip.yaml"

    @property
    def video_path(self) -> Path:
        """The video file or frames folder named by ``clip.yaml``."""
        return self.root / self.info.video

    @property
    def ball_path(self) -> Path:
        return self.root / "ball.csv"

    @property
    def inactive_balls_path(self) -> Path:
        return self.root / "inactive_balls.csv"

    @property
    def events_path(self) -> Path:
        return self.root / "events.csv"

    @property
    def court_points_path(self) -> Path:
        return self.root / "court_points.csv"

    @property
    def camera_path(self) -> Path:
        return self.root / "camera.yaml"

    @property
    def players_path(self) -> Path:
        return self.root / "players.csv"

    @property
    def ball_3d_path(self) -> Path:
        return self.root / "ball_3d.csv"

    @property
    def segments_path(self) -> Path:
        return self.root / "segments.json"

    @property
    def gt_dir(self) -> Path:
        """Ground truth, where it exists: ``gt/ball_3d.csv``, ``gt/camera.yaml``, ``gt/events.csv`` ..."""
        return self.root / "gt"

    def _path(self, name: str, gt: bool) -> Path:
        return (self.gt_dir if gt else self.root) / name

    def court_path(self, court_dir: str | Path | None = None) -> Path:
        """The court YAML: clip.yaml's ``court`` (relative to the clip), else ``<court_dir>/<sport>.yaml``.

        ``court_dir`` defaults to the repository's ``conf/court``.
        """
        if self.info.court:
            return self.root / self.info.court
        if court_dir is None:
            from inference.court import CONF_DIR

            court_dir = CONF_DIR / "court"
        return Path(court_dir) / f"{self.info.sport}.yaml"

    # ---------------------------------------------------------------------------- clip.yaml, frames
    @cached_property
    def info(self) -> ClipInfo:
        """``clip.yaml``, read on first use."""
        return read_clip_yaml(self.clip_yaml_path)

    def write_info(self, info: ClipInfo) -> Path:
        """Write ``clip.yaml`` (and remember it)."""
        path = write_clip_yaml(self.clip_yaml_path, info)
        self.__dict__["info"] = info
        return path

    def frames(self, *, cache_size: int = 8) -> FrameSource:
        """The clip's frames (lazy; close it or use ``with``)."""
        from .frames import FrameSource, clip_repeats  # here: OpenCV loads only when frames are read

        return FrameSource.open(self.video_path, fps=self.info.fps, cache_size=cache_size,
                                repeats=clip_repeats(self.info))

    @cached_property
    def n_frames(self) -> int:
        """Number of frames: ``clip.yaml``'s ``n_frames``, else counted from the frame source, else (no
        video, e.g. a CSV-only clip) one past the last frame that ball.csv, events.csv or players.csv name."""
        if self.info.n_frames is not None:
            return self.info.n_frames
        if not self.video_path.exists():
            n = self.frames_in_data()
            if n:
                warnings.warn(f"{self.video_path}: not found; {n} frames taken from the clip's tables "
                              "(write n_frames in clip.yaml to fix the count)", stacklevel=2)
                return n
            raise FormatError(self.video_path, "not found, and no table names a frame",
                              fix="write n_frames in clip.yaml, or put the video where clip.yaml's video says")
        with self.frames(cache_size=1) as src:
            return len(src)

    def frames_in_data(self) -> int:
        """One past the last frame named by ball.csv, events.csv or players.csv (0 when none exists)."""
        last = -1
        for path, read in ((self.ball_path, self.read_ball), (self.events_path, self.read_events),
                           (self.players_path, self.read_players)):
            if path.is_file():
                frames = read(n_frames=None).frame
                if len(frames):
                    last = max(last, int(frames.max()))
        return last + 1

    def _frame_limit(self, n_frames: int | None) -> int | None:
        """``n_frames`` if given, else clip.yaml's ``n_frames`` (None when neither is known)."""
        if n_frames is not None:
            return n_frames
        return self.info.n_frames if self.clip_yaml_path.is_file() else None

    # --------------------------------------------------------------------------------------- tables
    def _read(
        self, path: Path, reader: Callable[..., T], empty: Callable[[], T], missing_ok: bool, **kwargs: Any
    ) -> T:
        if missing_ok and not path.exists():
            return empty()
        return reader(path, **kwargs)

    def read_ball(
        self, *, missing_ok: bool = False, n_frames: int | None = None, skipped: list[FormatError] | None = None
    ) -> BallTrack:
        """``ball.csv``; frames must be below ``n_frames`` (default: clip.yaml's, when it has one).

        With ``skipped=[]`` (every table reader takes it) bad rows are left out and their errors appended.
        """
        return self._read(
            self.ball_path,
            csvfiles.read_ball_csv,
            BallTrack.empty,
            missing_ok,
            n_frames=self._frame_limit(n_frames),
            skipped=skipped,
        )

    def write_ball(self, track: BallTrack) -> Path:
        return csvfiles.write_ball_csv(self.ball_path, track)

    def read_inactive_balls(
        self, *, missing_ok: bool = False, n_frames: int | None = None, skipped: list[FormatError] | None = None
    ) -> InactiveBalls:
        return self._read(
            self.inactive_balls_path,
            csvfiles.read_inactive_balls_csv,
            InactiveBalls.empty,
            missing_ok,
            n_frames=self._frame_limit(n_frames),
            skipped=skipped,
        )

    def write_inactive_balls(self, balls: InactiveBalls) -> Path:
        return csvfiles.write_inactive_balls_csv(self.inactive_balls_path, balls)

    def read_events(
        self,
        *,
        gt: bool = False,
        missing_ok: bool = False,
        n_frames: int | None = None,
        labels: Iterable[str] | None = None,
        skipped: list[FormatError] | None = None,
    ) -> HitEvents:
        """``events.csv`` (or ``gt/events.csv``); ``labels``: the court's vocabulary (default: every label)."""
        return self._read(
            self._path("events.csv", gt),
            csvfiles.read_events_csv,
            HitEvents.empty,
            missing_ok,
            n_frames=self._frame_limit(n_frames),
            labels=None if labels is None else list(labels),
            skipped=skipped,
        )

    def write_events(self, events: HitEvents, *, gt: bool = False) -> Path:
        return csvfiles.write_events_csv(self._path("events.csv", gt), events)

    def read_court_points(
        self,
        *,
        known_names: Iterable[str] | None = None,
        missing_ok: bool = False,
        skipped: list[FormatError] | None = None,
    ) -> CourtPoints:
        """``court_points.csv``; with ``known_names`` (the court YAML's points) other names are rejected."""
        return self._read(
            self.court_points_path,
            csvfiles.read_court_points_csv,
            lambda: CourtPoints([], []),
            missing_ok,
            known_names=known_names,
            skipped=skipped,
        )

    @property
    def court_line_points_path(self) -> Path:
        return self.root / "court_line_points.csv"

    def read_court_line_points(self, *, known_names: Iterable[str] | None = None, missing_ok: bool = False,
                               skipped: list[FormatError] | None = None) -> CourtLinePoints:
        """``court_line_points.csv`` (optional: points clicked along straight court lines)."""
        return self._read(self.court_line_points_path, csvfiles.read_court_line_points_csv,
                          CourtLinePoints.empty, missing_ok, known_names=known_names,
                          skipped=skipped)

    def write_court_points(self, points: CourtPoints) -> Path:
        return csvfiles.write_court_points_csv(self.court_points_path, points)

    def read_ball_3d(
        self, *, gt: bool = False, missing_ok: bool = False, n_frames: int | None = None
    ) -> Ball3D:
        """``ball_3d.csv`` (or ``gt/ball_3d.csv``)."""
        return self._read(
            self._path("ball_3d.csv", gt),
            csvfiles.read_ball_3d_csv,
            Ball3D.empty,
            missing_ok,
            n_frames=self._frame_limit(n_frames),
        )

    def write_ball_3d(self, ball: Ball3D, *, gt: bool = False) -> Path:
        return csvfiles.write_ball_3d_csv(self._path("ball_3d.csv", gt), ball)

    def read_players(
        self, *, gt: bool = False, missing_ok: bool = False, n_frames: int | None = None
    ) -> PlayerTracks:
        """``players.csv`` (or ``gt/players.csv``)."""
        return self._read(
            self._path("players.csv", gt),
            read_players_csv,
            PlayerTracks.empty,
            missing_ok,
            n_frames=self._frame_limit(n_frames),
        )

    def write_players(self, players: PlayerTracks, *, gt: bool = False) -> Path:
        return write_players_csv(self._path("players.csv", gt), players)

    # --------------------------------------------------------------------------------------- camera
    def read_camera(self, *, gt: bool = False) -> Camera:
        """``camera.yaml`` (or ``gt/camera.yaml``) via :meth:`inference.camera.Camera.load`."""
        from inference.camera import Camera

        path = self._path("camera.yaml", gt)
        if not path.is_file():
            raise FormatError(path, "file not found",
                              fix=f"run `rally3d calibrate {self.root}` (court_points.csv → camera.yaml)")
        return Camera.load(path)

    def check_camera(self, camera: Camera, path: Path | None = None) -> None:
        """Refuse a calibration made for another frame size than clip.yaml's (its projection is wrong everywhere).

        Raises:
            FormatError: naming ``path`` (default camera.yaml), both sizes and the fix.
        """
        size = tuple(int(v) for v in camera.image_size)
        if size != (self.info.width, self.info.height):
            raise FormatError(
                path or self.camera_path,
                f"the calibration is for {size[0]}×{size[1]} frames but the video is "
                f"{self.info.width}×{self.info.height}",
                fix="calibrate this video (court_points.csv + rally3d calibrate) or pass the right --camera",
            )

    def write_camera(self, camera: Camera, *, gt: bool = False) -> Path:
        """Save ``camera`` to ``camera.yaml`` (or ``gt/camera.yaml``) via ``camera.save``."""
        path = self._path("camera.yaml", gt)
        path.parent.mkdir(parents=True, exist_ok=True)
        camera.save(path)
        return path
