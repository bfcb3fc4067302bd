"""Everything the review shows, read once from a clip folder (docs/formats.md), UI-free.

Example:
    >>> data = ReviewData.load("runs/demo/padel_sample")
    >>> data.ball_at(100), data.analysis.shots[0].verdict
"""
from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from inference.camera import Camera
from inference.clipio import Clip, FormatError, HitEvents, PlayerTracks
from inference.court import Court, load_court

from .shots import Contact, RallyAnalysis, Trajectory, analyse_reconstruction, read_segments_json


@dataclass
class ReviewData:
    """A reconstructed clip, ready to review.

    Attributes:
        clip, court, camera: the scene; fps; n_frames: frames of the video (clip.yaml).
        traj: the reconstructed 3D ball; uv: (n_frames, 2) the 2D ball of ball.csv in pixels (NaN none).
        events: events.csv; contacts: events placed in 3D; analysis: shots and line calls, and the clip-level
        plausibility (``analysis.plausibility``; shots over failed flights carry no figure).
        players: players.csv (None when absent or empty); segments: segments.json's list ([] if absent).
        video_ok: whether the video can be opened (else the review shows a placeholder frame).
    """

    clip: Clip
    court: Court
    camera: Camera
    fps: float
    n_frames: int
    traj: Trajectory
    uv: np.ndarray
    events: HitEvents
    contacts: list[Contact]
    analysis: RallyAnalysis
    players: PlayerTracks | None
    segments: list[dict]
    video_ok: bool = True

    @classmethod
    def load(cls, root: str | Path, *, first_hit_is_serve: bool = True) -> ReviewData:
        """Read a clip folder. Missing inputs raise :class:`FormatError` naming the command that makes them."""
        root = Path(root)
        clip = Clip(root)
        if not clip.clip_yaml_path.is_file():
            raise FormatError(clip.clip_yaml_path, "not a clip folder (no clip.yaml)",
                              fix="pass a clip folder written by `rally3d infer` (or `rally3d synth`)")
        court = load_court(clip.court_path())
        camera = clip.read_camera()
        if not clip.ball_3d_path.is_file():
            raise FormatError(clip.ball_3d_path, "file not found",
                              fix=f"run `rally3d reconstruct {root}` (or `rally3d infer`) first")
        ball = clip.read_ball_3d()
        if not len(ball):
            raise FormatError(clip.ball_3d_path, "no reconstructed frames",
                              fix="check events.csv and ball.csv, then re-run `rally3d reconstruct`")
        traj = Trajectory.from_ball_3d(ball)
        info = clip.info
        n_frames = int(info.n_frames) if info.n_frames is not None else int(traj.frame[-1]) + 1
        video_ok = True
        try:
            with clip.frames(cache_size=1) as src:
                n_frames = len(src)
                src[0]  # decodes: a file that is no video fails here
        except (FormatError, OSError, IndexError, ValueError) as e:
            warnings.warn(f"the video cannot be opened, the review shows no frames: {e}", stacklevel=2)
            video_ok = False
        uv = np.full((max(n_frames, int(traj.frame[-1]) + 1), 2), np.nan)
        track = clip.read_ball(missing_ok=True, n_frames=len(uv))
        vis = track.visibility > 0
        uv[track.frame[vis]] = track.xy[vis] * np.asarray(camera.image_size, float)
        events = clip.read_events(missing_ok=True, n_frames=len(uv))
        doc = read_segments_json(clip.segments_path)
        segments = [] if doc is None else doc["segments"]
        contacts, analysis = analyse_reconstruction(court, traj, events, doc, info.fps,
                                                    first_hit_is_serve=first_hit_is_serve)
        players = clip.read_players(missing_ok=True, n_frames=len(uv))
        return cls(clip, court, camera, float(info.fps), len(uv), traj, uv, events, contacts, analysis,
                   players if len(players) else None, segments, video_ok)

    # --------------------------------------------------------------------------------------- queries
    @property
    def first_frame(self) -> int:
        """First frame of the reconstructed ball."""
        return int(self.traj.frame[0])

    @property
    def last_frame(self) -> int:
        return int(self.traj.frame[-1])

    def ball_at(self, frame: int) -> np.ndarray:
        """(3,) the 3D ball at ``frame``, NaN where there is none."""
        return self.traj.at(frame)

    def trail(self, frame: int, length: int) -> np.ndarray:
        """(K, 3) the 3D ball over the ``length`` frames up to ``frame`` (frames without a position skipped)."""
        _, xyz = self.traj.window(frame - length + 1, frame)
        return xyz

    def players_at(self, frame: int) -> PlayerTracks | None:
        """The players' rows at ``frame`` (None when there are no players)."""
        if self.players is None:
            return None
        m = self.players.frame == frame
        p = self.players
        return PlayerTracks(p.frame[m], p.player_id[m], p.team[m], p.score[m], p.bbox[m], p.keypoints[m],
                            p.court_xy[m], p.joints_3d[m])

    def event_marks(self) -> tuple[tuple[int, str], ...]:
        """Slider marks: one per event, labelled with a short name (hits by team, contacts by surface)."""
        short = {"ground": "•", "player_near": "N", "player_far": "F", "net": "net", "mesh": "mesh"}
        return tuple((int(f), short.get(e, e.replace("wall_", "g·"))) for f, e in
                     zip(self.events.frame.tolist(), self.events.event.tolist()))

    def summary(self) -> dict:
        """A few figures for the console and the panel."""
        rms = [s.get("reprojection_rms_px") for s in self.segments
               if isinstance(s, dict) and s.get("reconstructed") is True]
        rms = [r for r in rms if isinstance(r, (int, float)) and math.isfinite(r)]
        return {"frames": self.n_frames, "reconstructed": len(self.traj.frame), "shots": len(self.analysis.shots),
                "reprojection_rms_px": round(float(np.sqrt(np.mean(np.square(rms)))), 2) if rms else None,
                "method": _method(self.clip.segments_path)}


def _method(path: Path) -> str:
    try:
        return str(json.loads(path.read_text()).get("method", ""))
    except (OSError, ValueError, AttributeError):
        return ""
