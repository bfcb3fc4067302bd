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
- 2 × 12 player values (``poses``, :data:`PLAYER_COLUMNS`), for the near side then the far side: the
  side's player nearest the ball (padel: of its two), from ``players.csv`` — ``present`` (a row on that side),
  the court position (``court_x, court_y``: metres from the centre / half the court's width, from the net /
  half its length), the body centre minus the ball (image fractions × ``rel_scale``), ``pose`` (the racket
  hand's wrist found), the racket wrist minus the ball (× ``rel_scale``), and both wrists relative to the
  body centre in units of its torso (racket hand first: the wrist that moves most over the clip). Every
  value is 0 where unknown (no player, no pose, no ball), so a missing player or pose reads as zeros with
  its mask at 0.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from inference.clipio import BallTrack, PlayerTracks

CORNERS = ("near_left", "near_right", "far_left", "far_right")
SIDES = ("near", "far")
#: The per-side player columns of the ``poses`` block (see the module docstring).
PLAYER_COLUMNS = ("present", "court_x", "court_y", "body_dx", "body_dy", "pose", "wrist_dx", "wrist_dy",
                  "racket_wrist_x", "racket_wrist_y", "other_wrist_x", "other_wrist_y")
#: Layout version of the ``poses`` block written into model files (1: raw keypoints, never trained, dropped).
POSE_LAYOUT = 2


@dataclass(frozen=True)
class FeatureConfig:
    """Which features to compute.

    Attributes:
        ref_fps: frame rate the track is resampled to (None: keep the clip's).
        velocity: add ``vx, vy, seen``; corners: add the 4 projected ground corners; poses: add the
            players (near and far side: position, body and wrists relative to the ball, masks).
        players: players on court (informative; the ``poses`` block always has one slot per side).
        velocity_scale: multiplies the per-frame displacement (normalised units) of ``vx, vy``.
        rel_scale: multiplies image offsets from the ball (body, wrist) in the ``poses`` block.
        fill_holes_s: holes in the track of at most this long (s; the frames a detector drops now and then,
            shorter than the gaps at contacts) are filled linearly between their two seen neighbours, which
            then count as seen (0: none).
    """

    ref_fps: float | None = 50.0
    velocity: bool = True
    corners: bool = False
    poses: bool = False
    players: int = 4
    velocity_scale: float = 10.0
    rel_scale: float = 10.0
    fill_holes_s: float = 0.0

    def __post_init__(self) -> None:
        if self.ref_fps is not None and self.ref_fps <= 0:
            raise ValueError(f"ref_fps must be > 0, got {self.ref_fps}")
        if not 0.0 <= self.fill_holes_s <= 0.5:
            raise ValueError(f"fill_holes_s must be within 0–0.5 s (short holes, not gaps), got {self.fill_holes_s}")

    @classmethod
    def from_dict(cls, d) -> FeatureConfig:
        if isinstance(d, FeatureConfig):
            return d
        d = dict(d or {})
        return cls(**{k: d[k] for k in ("ref_fps", "velocity", "corners", "poses", "players", "velocity_scale",
                                        "rel_scale", "fill_holes_s") if k in d})

    @classmethod
    def from_model_file(cls, d) -> FeatureConfig:
        """The features a model file records; a file of the first ``poses`` layout (raw keypoints, which no
        shipped or trained model used) is an error that says to retrain."""
        if dict(d or {}).get("poses") and int(dict(d).get("pose_layout", 1)) != POSE_LAYOUT:
            raise ValueError("this hit-event model was made with the first `poses` layout (raw keypoints), which "
                             "rally3d no longer builds: retrain it (python train.py +experiment=hitnet_<sport>_players)")
        return cls.from_dict(d)

    def to_dict(self) -> dict:
        return {"ref_fps": self.ref_fps, "velocity": self.velocity, "corners": self.corners,
                "poses": self.poses, "players": self.players, "velocity_scale": self.velocity_scale,
                "rel_scale": self.rel_scale, "fill_holes_s": self.fill_holes_s,
                **({"pose_layout": POSE_LAYOUT} if self.poses else {})}

    @property
    def n_player_features(self) -> int:
        return len(SIDES) * len(PLAYER_COLUMNS) * self.poses

    @property
    def player_offset(self) -> int:
        """First column of the ``poses`` block."""
        return 2 + 3 * self.velocity + 8 * self.corners

    @property
    def n_features(self) -> int:
        return self.player_offset + self.n_player_features


# ------------------------------------------------------------------------------------------- resampling
def dense_xy(ball: BallTrack, n_frames: int) -> np.ndarray:
    """``(n_frames, 2)`` ball position, NaN where missing (not labelled or not in the frame)."""
    d = ball.dense(n_frames)
    xy = d.xy.copy()
    xy[d.visibility <= 0] = np.nan
    return xy


def fill_holes(xy: np.ndarray, max_frames: int) -> np.ndarray:
    """``(T, 2)`` positions (NaN missing) with every run of at most ``max_frames`` missing frames between two
    seen ones filled linearly; longer gaps and the ends stay missing."""
    out = np.array(xy, dtype=float, copy=True)
    seen = np.isfinite(out).all(axis=1)
    if max_frames <= 0 or seen.sum() < 2:
        return out
    t, n = np.arange(len(out)), len(out)
    before = np.maximum.accumulate(np.where(seen, t, -1))             # last seen frame at or before each frame
    after = np.minimum.accumulate(np.where(seen, t, n)[::-1])[::-1]   # first seen frame at or after it
    short = ~seen & (before >= 0) & (after < n) & (after - before - 1 <= max_frames)
    out[short] = _fill_ball(out)[short]
    return out


def track_xy(ball: BallTrack, n_frames: int, fps: float, config: FeatureConfig) -> np.ndarray:
    """``(n_frames, 2)`` the positions the features read: :func:`dense_xy` with the holes of at most
    ``config.fill_holes_s`` filled (:func:`fill_holes`)."""
    return fill_holes(dense_xy(ball, n_frames), int(np.floor(config.fill_holes_s * fps + 1e-6)))


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


_WRISTS = (9, 10)        # COCO-17 left, right wrist
_TORSO = (5, 6, 11, 12)  # shoulders, hips


def _nanmean(a: np.ndarray, axis: int) -> np.ndarray:
    n = np.isfinite(a).sum(axis=axis)
    return np.where(n > 0, np.nansum(a, axis=axis) / np.maximum(n, 1), np.nan)


def _fill_ball(xy: np.ndarray) -> np.ndarray:
    """``(T, 2)`` ball positions with gaps filled linearly (ends held): where the ball probably is."""
    known = np.flatnonzero(np.isfinite(xy).all(axis=1))
    if len(known) == 0:
        return xy.copy()
    t = np.arange(len(xy))
    return np.stack([np.interp(t, known, xy[known, k]) for k in range(2)], axis=1)


def player_side(players: PlayerTracks, court=None) -> np.ndarray:
    """``(N,)`` side of each row: its ``team``, else the court position against the net, else ``""``."""
    side = players.team.astype(object).copy()
    if court is not None:
        y = players.court_xy[:, 1]
        unknown = (side == "") & np.isfinite(y)
        side[unknown] = np.where(y[unknown] < court.net_y, "near", "far")
    return side


def _dense_player(p: PlayerTracks, n: int, min_score: float) -> dict[str, np.ndarray]:
    """One player's rows → per-frame ``(n, …)`` arrays: present, court (2), centre (2), wrists (2, 2),
    torso scale; NaN where unknown."""
    keep = p.frame < n
    f = p.frame[keep]
    kp = p.keypoints[keep].copy()
    score = kp[:, :, 2]
    kp[(np.isfinite(score) & (score < min_score))[..., None].repeat(3, axis=2)] = np.nan
    out = {"present": np.zeros(n, bool), "court": np.full((n, 2), np.nan), "centre": np.full((n, 2), np.nan),
           "wrists": np.full((n, 2, 2), np.nan), "scale": np.full(n, np.nan)}
    out["present"][f] = True
    out["court"][f] = p.court_xy[keep]
    torso = kp[:, list(_TORSO), :2]
    centre = _nanmean(torso, axis=1)
    box = p.bbox[keep]
    box_c = np.stack([(box[:, 0] + box[:, 2]) / 2, (box[:, 1] + box[:, 3]) / 2], axis=1)
    out["centre"][f] = np.where(np.isfinite(centre), centre, box_c)
    shoulders, hips = _nanmean(kp[:, [5, 6], :2], axis=1), _nanmean(kp[:, [11, 12], :2], axis=1)
    torso_len = np.linalg.norm(shoulders - hips, axis=1)
    box_len = (box[:, 3] - box[:, 1]) / 3.0
    out["scale"][f] = np.where(np.isfinite(torso_len) & (torso_len > 1e-4), torso_len, box_len)
    out["wrists"][f] = kp[:, list(_WRISTS), :2]
    return out


def racket_hand(wrists: np.ndarray, centre: np.ndarray) -> int:
    """0 (left) or 1 (right): the wrist that moves more about the body over the clip (the racket swings);
    right when unknown. ``wrists (T, 2, 2)``, ``centre (T, 2)``."""
    rel = wrists - centre[:, None, :]
    spread = [float(np.nansum(np.nanvar(rel[:, k], axis=0))) if np.isfinite(rel[:, k]).all(axis=1).sum() > 2
              else -1.0 for k in range(2)]
    return 0 if spread[0] > spread[1] else 1


def player_features(players: PlayerTracks | None, ball_xy: np.ndarray, court=None, rel_scale: float = 10.0,
                    min_score: float = 0.1) -> np.ndarray:
    """``(T, 24)`` the ``poses`` block at the clip's frames (near side, then far; :data:`PLAYER_COLUMNS`).

    Args:
        players: ``players.csv`` (None or empty: all zeros).
        ball_xy: ``(T, 2)`` ball positions (normalised, NaN missing) at the same frames.
        court: places rows without a team by their court position; normalises court positions.
        min_score: keypoints scored below this are missing.
    """
    n = len(ball_xy)
    P = len(PLAYER_COLUMNS)
    out = np.zeros((n, len(SIDES) * P))
    if players is None or len(players) == 0 or n == 0:
        return out
    half = (np.asarray(court.size, float)[0] / 2, float(court.net_y)) if court is not None else (5.0, 10.0)
    ball_seen = np.isfinite(ball_xy).all(axis=1)
    ball_where = _fill_ball(ball_xy)
    side = player_side(players, court)
    for s, name in enumerate(SIDES):
        dense = [_dense_player(players.of_player(pid), n, min_score)
                 for pid in sorted(set(players.player_id[side == name].tolist()))]
        if not dense:
            continue
        # per frame, the side's player nearest to where the ball is (padel: one of two)
        dist = np.stack([np.where(d["present"], np.nan_to_num(np.linalg.norm(d["centre"] - ball_where, axis=1),
                                                               nan=5.0), np.inf) for d in dense])
        pick = np.argmin(dist, axis=0)
        cols = np.zeros((n, P))
        for k, d in enumerate(dense):
            m = (pick == k) & d["present"]
            if not m.any():
                continue
            hand = racket_hand(d["wrists"], d["centre"])
            court_n = (d["court"] - [half[0], half[1]]) / [half[0], half[1]]
            body = (d["centre"] - ball_xy) * rel_scale
            wr = d["wrists"][:, hand]
            wrist = (wr - ball_xy) * rel_scale
            scale = np.where(np.isfinite(d["scale"]) & (d["scale"] > 1e-4), d["scale"], np.nan)
            rel = (d["wrists"] - d["centre"][:, None, :]) / scale[:, None, None]
            vals = np.concatenate([np.ones((n, 1)), court_n, np.clip(body, -3, 3),
                                   np.isfinite(wr).all(axis=1, keepdims=True).astype(float), np.clip(wrist, -3, 3),
                                   np.clip(rel[:, hand], -4, 4), np.clip(rel[:, 1 - hand], -4, 4)], axis=1)
            cols[m] = np.nan_to_num(vals[m], nan=0.0)
        cols[~ball_seen, 3:5] = 0.0
        cols[~ball_seen, 6:8] = 0.0
        out[:, s * P:(s + 1) * P] = cols
    return out


def clip_features(ball: BallTrack, n_frames: int, fps: float, config: FeatureConfig, *, camera=None,
                  court=None, players: PlayerTracks | None = None) -> np.ndarray:
    """``(T', F)`` features of a clip at the reference rate (``F = config.n_features``)."""
    native_xy = track_xy(ball, n_frames, fps, config)
    xy = resample_xy(native_xy, fps, config.ref_fps)
    parts = [ball_features(xy, config.velocity, config.velocity_scale)]
    if config.corners:
        parts.append(court_corner_features(camera, court, len(xy)))
    if config.poses:
        native = player_features(players, native_xy, court, config.rel_scale)
        src = np.clip(np.round(np.arange(len(xy)) * fps / (config.ref_fps or fps)).astype(int), 0, n_frames - 1)
        parts.append(native[src])
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


def check_label_block(window: int, last_k: int, lookahead: int = 0) -> None:
    """Raise ``ValueError`` unless the label block (K frames ending ``lookahead`` frames before the
    window's end) fits in a window of W frames: ``1 <= K`` and ``K + lookahead <= W``."""
    if not (1 <= last_k and 0 <= lookahead and last_k + lookahead <= window):
        raise ValueError(f"need 1 <= last_k, 0 <= lookahead and last_k + lookahead <= window, got "
                         f"last_k={last_k}, lookahead={lookahead}, window={window}")


def window_probs_to_frames(win_probs: np.ndarray, n: int, window: int, last_k: int,
                           lookahead: int = 0) -> np.ndarray:
    """``(T + W + 1, C)`` window probabilities → ``(T, C)`` per frame: frame t is the mean of the K
    windows whose label block covers it (padded starts ``t + L + 1 .. t + L + K``, L = ``lookahead``)."""
    check_label_block(window, last_k, lookahead)
    c = np.cumsum(np.concatenate([np.zeros((1, win_probs.shape[1])), win_probs]), axis=0)
    t = np.arange(n) + lookahead
    return (c[t + last_k + 1] - c[t + 1]) / last_k


def window_labels(y: np.ndarray, window: int, last_k: int, lookahead: int = 0) -> np.ndarray:
    """``(T,)`` per-frame classes → ``(T + W + 1,)`` window labels: the event in the window's label
    block — its K frames that end ``lookahead`` (L) frames before the window's end, so that the network
    also sees L frames after the event (the latest event when several; 0 when none)."""
    check_label_block(window, last_k, lookahead)
    padded = np.concatenate([np.zeros(window, y.dtype), y, np.zeros(window, y.dtype)])
    starts = window_starts(len(y), window)
    first = window - lookahead - last_k
    block = padded[starts[:, None] + np.arange(first, first + last_k)[None]]
    has = block > 0
    last = np.where(has.any(axis=1), first + (last_k - 1 - np.argmax(has[:, ::-1], axis=1)), 0)
    return np.where(has.any(axis=1), padded[starts + last], 0)
