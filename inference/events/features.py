"""Per-frame input features of the hit-event models and their windows.

The ball track is first resampled to a reference frame rate (``ref_fps``, 50 by default) so one model
serves 25–60 fps clips with the same window duration; probabilities and events are mapped back to the
clip's frames afterwards.

Feature columns per (resampled) frame, in this order:

- ``x, y``: ball position, normalised image coordinates shifted to ``[1, 2]``; missing ball = ``0, 0``.
- ``vx, vy`` (``velocity``): displacement per reference frame × ``velocity_scale`` (0 where either end is
  missing).
- ``seen`` (``velocity``): 1 where the ball is known.
- 8 corner values (``corners``): the four ground corners of the court projected by the camera, in
  ``[1, 2]`` (0 when no camera or outside the image).
- 34 × players values (``poses``): COCO-17 keypoints of up to ``players`` players (near team first),
  in ``[1, 2]``, 0 where missing.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from inference.clipio import BallTrack, PlayerTracks

CORNERS = ("near_left", "near_right", "far_left", "far_right")


@dataclass(frozen=True)
class FeatureConfig:
    """Which features to compute.

    Attributes:
        ref_fps: frame rate the track is resampled to (None: keep the clip's).
        velocity: add ``vx, vy, seen``; corners: add the 4 projected ground corners; poses: add keypoints.
        players: number of players whose keypoints are used (poses).
        velocity_scale: multiplies the per-frame displacement (normalised units) of ``vx, vy``.
    """

    ref_fps: float | None = 50.0
    velocity: bool = True
    corners: bool = False
    poses: bool = False
    players: int = 4
    velocity_scale: float = 10.0

    def __post_init__(self) -> None:
        if self.ref_fps is not None and self.ref_fps <= 0:
            raise ValueError(f"ref_fps must be > 0, got {self.ref_fps}")

    @classmethod
    def from_dict(cls, d) -> FeatureConfig:
        if isinstance(d, FeatureConfig):
            return d
        d = dict(d or {})
        return cls(**{k: d[k] for k in ("ref_fps", "velocity", "corners", "poses", "players", "velocity_scale")
                     if k in d})

    def to_dict(self) -> dict:
        return {"ref_fps": self.ref_fps, "velocity": self.velocity, "corners": self.corners,
                "poses": self.poses, "players": self.players, "velocity_scale": self.velocity_scale}

    @property
    def n_features(self) -> int:
        return 2 + 3 * self.velocity + 8 * self.corners + 34 * self.players * self.poses


# ------------------------------------------------------------------------------------------- resampling
def dense_xy(ball: BallTrack, n_frames: int) -> np.ndarray:
    """``(n_frames, 2)`` ball position, NaN where missing (not labelled or not in the frame)."""
    d = ball.dense(n_frames)
    xy = d.xy.copy()
    xy[d.visibility <= 0] = np.nan
    return xy


def resample_xy(xy: np.ndarray, fps: float, ref_fps: float | None) -> np.ndarray:
    """``(T, 2)`` positions at ``fps`` → ``(T', 2)`` at ``ref_fps``, T' = round(T · ref/fps).

    Linear interpolation between known neighbours; a reference frame is missing when either neighbour
    is missing (gaps are not bridged).
    """
    if ref_fps is None or abs(ref_fps - fps) < 1e-9:
        return xy.copy()
    n = len(xy)
    n_ref = max(int(round(n * ref_fps / fps)), 1)
    t = np.arange(n_ref) * fps / ref_fps  # position in source frames
    i0 = np.clip(np.floor(t).astype(int), 0, n - 1)
    i1 = np.clip(i0 + 1, 0, n - 1)
    w = (t - i0)[:, None]
    a, b = xy[i0], xy[i1]
    out = a * (1 - w) + b * w
    exact = w[:, 0] < 1e-9
    out[exact] = a[exact]
    return out


def to_ref_frames(frames: np.ndarray, fps: float, ref_fps: float | None) -> np.ndarray:
    """Clip frame indices → reference-rate frame indices (nearest)."""
    if ref_fps is None:
        return np.asarray(frames, np.int64)
    return np.round(np.asarray(frames, float) * ref_fps / fps).astype(np.int64)


def from_ref_frames(frames: np.ndarray, fps: float, ref_fps: float | None) -> np.ndarray:
    """Reference-rate frame indices → clip frame indices (nearest)."""
    if ref_fps is None:
        return np.asarray(frames, np.int64)
    return np.round(np.asarray(frames, float) * fps / ref_fps).astype(np.int64)


def probs_to_clip(probs_ref: np.ndarray, n_frames: int, fps: float, ref_fps: float | None) -> np.ndarray:
    """``(T', C)`` probabilities at the reference rate → ``(n_frames, C)`` at the clip's (linear)."""
    if ref_fps is None or len(probs_ref) == n_frames and abs(ref_fps - fps) < 1e-9:
        return probs_ref[:n_frames]
    t = np.arange(n_frames) * ref_fps / fps
    src = np.arange(len(probs_ref))
    return np.stack([np.interp(t, src, probs_ref[:, c]) for c in range(probs_ref.shape[1])], axis=1)


# -------------------------------------------------------------------------------------------- features
def ball_features(xy: np.ndarray, velocity: bool = True, scale: float = 10.0) -> np.ndarray:
    """``(T, 2)`` positions (NaN missing) → ``(T, 2 or 5)`` ball features (see the module docstring)."""
    seen = np.isfinite(xy).all(axis=1)
    pos = np.where(seen[:, None], xy + 1.0, 0.0)
    if not velocity:
        return pos
    v = np.zeros_like(pos)
    ok = seen[1:] & seen[:-1]
    v[1:][ok] = (xy[1:] - xy[:-1])[ok] * scale
    return np.concatenate([pos, v, seen[:, None].astype(float)], axis=1)


def court_corner_features(camera, court, n: int) -> np.ndarray:
    """``(n, 8)`` the four ground corners of ``court`` projected by ``camera``, in ``[1, 2]``."""
    out = np.zeros((n, 8))
    if camera is None or court is None:
        return out
    uv = camera.project_normalized(court.point_array(CORNERS))
    ok = np.isfinite(uv).all(axis=1) & (uv >= 0).all(axis=1) & (uv <= 1).all(axis=1)
    vals = np.where(ok[:, None], uv + 1.0, 0.0).reshape(-1)
    out[:] = vals
    return out


def pose_features(players: PlayerTracks | None, n_frames: int, fps: float, ref_fps: float | None,
                  n_players: int) -> np.ndarray:
    """``(T', 34 · n_players)`` keypoints (near team first, then by id) in ``[1, 2]``, 0 where missing."""
    t_ref = n_frames if ref_fps is None else max(int(round(n_frames * ref_fps / fps)), 1)
    out = np.zeros((t_ref, 34 * n_players))
    if players is None or len(players) == 0:
        return out
    ids = sorted(players.ids(), key=lambda i: (0 if players.of_player(i).team[:1].tolist() == ["near"] else 1, i))
    src = np.arange(t_ref) if ref_fps is None else np.round(np.arange(t_ref) * fps / ref_fps).astype(int)
    for k, pid in enumerate(ids[:n_players]):
        p = players.of_player(pid)
        kp = np.full((n_frames, 34), np.nan)
        keep = p.frame < n_frames
        kp[p.frame[keep]] = p.keypoints[keep, :, :2].reshape(-1, 34)
        vals = kp[np.clip(src, 0, n_frames - 1)]
        out[:, 34 * k:34 * (k + 1)] = np.where(np.isfinite(vals), vals + 1.0, 0.0)
    return out


def clip_features(ball: BallTrack, n_frames: int, fps: float, config: FeatureConfig, *, camera=None,
                  court=None, players: PlayerTracks | None = None) -> np.ndarray:
    """``(T', F)`` features of a clip at the reference rate (``F = config.n_features``)."""
    xy = resample_xy(dense_xy(ball, n_frames), fps, config.ref_fps)
    parts = [ball_features(xy, config.velocity, config.velocity_scale)]
    if config.corners:
        parts.append(court_corner_features(camera, court, len(xy)))
    if config.poses:
        parts.append(pose_features(players, n_frames, fps, config.ref_fps, config.players)[: len(xy)])
    feats = np.concatenate(parts, axis=1).astype(np.float32)
    assert feats.shape[1] == config.n_features
    return feats


# --------------------------------------------------------------------------------------------- windows
def window_starts(n: int, window: int) -> np.ndarray:
    """Start indices (into the sequence padded with ``window`` zero rows at both ends) of every window
    whose last-K block can cover a real frame: ``0 .. n + window``."""
    return np.arange(n + window + 1)


def make_windows(feats: np.ndarray, window: int) -> np.ndarray:
    """``(T, F)`` → ``(T + W + 1, W, F)``: all windows of the sequence zero-padded by W at both ends."""
    pad = np.zeros((window, feats.shape[1]), feats.dtype)
    padded = np.concatenate([pad, feats, pad])
    idx = window_starts(len(feats), window)[:, None] + np.arange(window)[None]
    return padded[idx]


def window_probs_to_frames(win_probs: np.ndarray, n: int, window: int, last_k: int) -> np.ndarray:
    """``(T + W + 1, C)`` window probabilities → ``(T, C)`` per frame: frame t is the mean of the K
    windows whose last-K block covers it (padded starts ``t + 1 .. t + K``)."""
    c = np.cumsum(np.concatenate([np.zeros((1, win_probs.shape[1])), win_probs]), axis=0)
    t = np.arange(n)
    return (c[t + last_k + 1] - c[t + 1]) / last_k


def window_labels(y: np.ndarray, window: int, last_k: int) -> np.ndarray:
    """``(T,)`` per-frame classes → ``(T + W + 1,)`` window labels: the event in the window's last K
    frames (the latest one when several; 0 when none)."""
    padded = np.concatenate([np.zeros(window, y.dtype), y, np.zeros(window, y.dtype)])
    starts = window_starts(len(y), window)
    idx = starts[:, None] + np.arange(window - last_k, window)[None]
    block = padded[idx]
    has = block > 0
    last = np.where(has.any(axis=1), window - last_k + (last_k - 1 - np.argmax(has[:, ::-1], axis=1)), 0)
    return np.where(has.any(axis=1), padded[starts + last], 0)
