"""Results of a 3D reconstruction: per-segment fits, the rally, ball_3d.csv and segments.json.

Example:
    >>> fit = reconstruct(obs, method="joint")
    >>> fit.ball_3d()                      # Ball3D: every frame from the first to the last event
    >>> fit.save(clip)                     # ball_3d.csv + segments.json, atomically
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from inference.camera import Camera
from inference.clipio import Ball3D, Clip
from inference.clipio.atomic import atomic_write_text

from .observations import Segment


#: ball_3d.csv's covariance columns (m²) → their (row, column) in the 3×3 matrix
COV_COLUMNS = {"cov_xx_m2": (0, 0), "cov_yy_m2": (1, 1), "cov_zz_m2": (2, 2), "cov_xy_m2": (0, 1),
               "cov_xz_m2": (0, 2), "cov_yz_m2": (1, 2)}


@dataclass
class SegmentFit:
    """One reconstructed flight.

    Attributes:
        segment: which flight.
        ok: whether it was reconstructed; reason: why not (empty when ok).
        frames: (n,) frames from start to end; xyz: (n, 3) ball centre; sigma: (n,) 1-σ uncertainty (m):
            √(trace of the covariance), NaN when unknown; cov: (n, 3, 3) position covariances (m²) or None.
        start, end: (3,) contact points; start_plane, end_plane: surfaces touched (None for hits).
        velocity: (3,) launch velocity at the start contact (m/s); spin: (3,) rad/s; drag_k: 1/m.
        reproj_rms_px: RMS reprojection error over the segment's observed frames.
        n_observed: 2D points used.
    """

    segment: Segment
    ok: bool
    reason: str = ""
    frames: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    xyz: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    sigma: np.ndarray | None = None
    cov: np.ndarray | None = None
    start: np.ndarray | None = None
    end: np.ndarray | None = None
    start_plane: str | None = None
    end_plane: str | None = None
    velocity: np.ndarray | None = None
    spin: np.ndarray | None = None
    drag_k: float | None = None
    reproj_rms_px: float = float("nan")
    n_observed: int = 0
    figures: dict = field(default_factory=dict)

    @classmethod
    def failed(cls, segment: Segment, reason: str) -> SegmentFit:
        return cls(segment, False, reason)

    def shot_figures(self, fps: float) -> dict:
        """Per-shot figures: launch and end speed (km/h), duration (s)."""
        if not self.ok or len(self.xyz) < 2:
            return {}
        v = np.gradient(self.xyz, axis=0) * fps
        launch = float(np.linalg.norm(self.velocity)) if self.velocity is not None else float(np.linalg.norm(v[0]))
        return {"launch_speed_kmh": round(launch * 3.6, 1), "end_speed_kmh": round(float(np.linalg.norm(v[-1])) * 3.6, 1),
                "duration_s": round(self.segment.duration_frames / fps, 3)}

    def to_dict(self, fps: float) -> dict:
        s = self.segment
        d = {"index": s.index, "start_frame": s.start, "end_frame": s.end, "start_event": s.start_event,
             "end_event": s.end_event, "reconstructed": self.ok}
        if s.start_event is None or s.end_event is None:
            d["free_end"] = "before the first event" if s.start_event is None else "after the last event"
        if not self.ok:
            d["reason"] = self.reason
            return d

        def vec(a):
            return None if a is None else [round(float(x), 4) for x in a]

        d.update({"start_point_m": vec(self.start), "end_point_m": vec(self.end), "start_plane": self.start_plane,
                  "end_plane": self.end_plane, "launch_velocity_ms": vec(self.velocity), "spin_rads": vec(self.spin),
                  "drag_k": None if self.drag_k is None else round(float(self.drag_k), 6),
                  "reprojection_rms_px": round(float(self.reproj_rms_px), 3), "n_observed": self.n_observed})
        d.update(self.shot_figures(fps))
        d.update(self.figures)
        return d


@dataclass
class RallyFit:
    """A whole reconstructed rally.

    Attributes:
        method: the method's name; fps: frame rate; segments: one fit per flight; seconds: compute time.
    """

    method: str
    fps: float
    segments: list[SegmentFit]
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)
    cpu_seconds: float | None = None
    #: the joint method's per-frame error model (``shooting.FrameErrorModel``; for calibration checks, not saved)
    error_model: object | None = field(default=None, repr=False, compare=False)

    @property
    def n_frames(self) -> int:
        """Frames covered (first to last event)."""
        if not self.segments:
            return 0
        return max(s.segment.end for s in self.segments) - min(s.segment.start for s in self.segments) + 1

    def ball_3d(self) -> Ball3D:
        """Ball3D rows for every reconstructed frame (``kind`` contact at the events, else fitted), with the
        covariance's six entries as extra columns ``cov_xx_m2`` … when the fit has them.

        A frame shared by two segments (the contact) is written once, from the later segment's start.
        """
        rows: dict[int, tuple] = {}
        nan3 = np.full((3, 3), np.nan)
        for fit in self.segments:
            if not fit.ok:
                continue
            seg = fit.segment
            sig = fit.sigma if fit.sigma is not None else np.full(len(fit.frames), np.nan)
            cov = fit.cov if fit.cov is not None else np.broadcast_to(nan3, (len(fit.frames), 3, 3))
            last = len(fit.frames) - 1
            for k, f in enumerate(fit.frames.tolist()):
                contact = (k == 0 and seg.start_event is not None) or (k == last and seg.end_event is not None)
                if f in rows and k == last:
                    continue
                rows[f] = (fit.xyz[k], seg.index, "contact" if contact else "fitted", sig[k], cov[k])
        frames = np.array(sorted(rows), dtype=np.int64)
        if not len(frames):
            return Ball3D.empty()
        xyz = np.array([rows[f][0] for f in frames])
        cov = np.array([rows[f][4] for f in frames])
        extra = {}
        if np.isfinite(cov).any():
            for name, (a, b) in COV_COLUMNS.items():
                extra[name] = np.array(["" if not np.isfinite(v) else f"{v:.6g}" for v in cov[:, a, b]])
        return Ball3D(frames, xyz, np.array([rows[f][1] for f in frames]), [rows[f][2] for f in frames],
                      np.array([rows[f][3] for f in frames], float), extra)

    def covariances(self) -> tuple[np.ndarray, np.ndarray]:
        """Frames (M,) and (M, 3, 3) position covariances of :meth:`ball_3d`'s rows (NaN where unknown)."""
        b = self.ball_3d()
        cov = np.full((len(b), 3, 3), np.nan)
        for name, (a, c) in COV_COLUMNS.items():
            if name in b.extra:
                v = np.array([float(x) if x != "" else np.nan for x in b.extra[name]])
                cov[:, a, c] = cov[:, c, a] = v
        return b.frame, cov

    def segments_json(self) -> dict:
        return {"method": self.method, "fps": self.fps, "seconds": round(self.seconds, 4),
                **({"cpu_seconds": round(self.cpu_seconds, 4)} if self.cpu_seconds is not None else {}),
                "segments": [s.to_dict(self.fps) for s in self.segments], **self.extra}

    def save(self, clip: Clip) -> None:
        """Write ball_3d.csv and segments.json into the clip folder (atomically)."""
        clip.write_ball_3d(self.ball_3d())
        atomic_write_text(clip.segments_path, json.dumps(self.segments_json(), indent=1) + "\n")

    def reprojection_errors(self, camera: Camera, uv: np.ndarray) -> np.ndarray:
        """(M,) pixel distances between the reprojected fit and the observed 2D ball at every frame that has
        both."""
        b = self.ball_3d()
        if not len(b):
            return np.zeros(0)
        obs = uv[b.frame]
        ok = np.isfinite(obs).all(axis=1)
        return np.linalg.norm(camera.project(b.xyz[ok]) - obs[ok], axis=1)
