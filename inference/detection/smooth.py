"""Rauch–Tung–Striebel smoothing of a 2D ball track that respects bounces and hits.

A constant-acceleration Kalman filter runs over each *piece* of the track; a piece ends where the track
cannot be one smooth flight: a gap longer than ``max_gap_s``, a known event frame (a bounce or a hit from
``events.csv``), or a change point found by the filter itself (a measurement far outside the predicted
gate that the next measurement confirms). An isolated measurement outside the gate that the next one
does not confirm is an outlier and is dropped (its row becomes "not visible"). Each piece is then
smoothed backwards (RTS), so the positions of a flight use the frames after them as well as before.

Before that, *islands* are dropped (:func:`off_track_islands`): a short run of detections, cut from the rest
by gaps or jumps, that lies far from where the track around it says the ball was — a detector that found
a player's head or a shoe for a few frames while the ball itself was lost. Seen from both sides, the runs
around it must agree on one smooth path across the gap (a quadratic through both fits them), the island
must lie far from that path, and the ball must have been unable to reach it (flying there, or back, would
take several times its speed on either side): a real piece between hidden contacts (a bounce, a rebound off
the glass) may lie far from the sides' path, but the ball gets there at its own pace. Seen from one side
(the ball lost before it, a jump after it back to a longer run, or the mirror), the jump must be far
beyond what that run and the island move in a frame, and the island far from the run's own path.

Units are pixels of the original frame; the defaults are for 1280-px-wide video and scale with width.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from inference.clipio import BallTrack

GATE_CHI2_2DOF = 13.8  # chi-square 99.9 % with 2 degrees of freedom
#: an island seen from one side: the ball lost this long (s) on its other side
ISLAND_LOST_S = 0.12


@dataclass(frozen=True)
class SmootherConfig:
    """Parameters of :func:`smooth_track`.

    Attributes:
        meas_sigma_px: σ of a detection's position at 1280 px width (scaled with the frame width).
        jerk_psd: spectral density of the white jerk, px²/s⁵ at 1280 px (how fast acceleration may change).
        max_gap_s: a longer gap without detections starts a new piece.
        gate_chi2: normalised innovation squared above which a measurement does not fit the flight.
        min_piece: pieces with fewer detections are left unsmoothed (kept as measured).
        island_max_s: runs of detections at most this long may be judged off the track (0: never).
        island_context_s: two runs at most this far apart (the gap across the island) give the path across
            it, from their detections within ``island_side_s`` of the gap; each run holds 4+ detections, both
            together ``island_min_context`` and twice the island's.
        island_off, island_ratio, island_max_rms: an island is off the track when its median distance from
            that path is over ``island_off`` × the frame width and ``island_ratio`` × the path's largest
            residual on its sides, and that residual is at most ``island_max_rms`` × the width.
        island_max_acc: the path's acceleration is at most this × the width per s² (a ball's, under gravity and
            perspective, is far less: a path bent more than that joins pieces of two things).
        island_jump: a step larger than this × the width per frame starts a new run.
        island_speedup: and the ball would have had to fly to the island (or from it back to the track) this many
            times faster than it moves on either side: a real piece between hidden contacts (a rebound off the
            glass near the camera) can lie far from the path the sides agree on, but the ball still reaches it;
            a side's speed counts as at least ``island_min_speed`` × the width per frame.
    """

    meas_sigma_px: float = 2.5
    jerk_psd: float = 4.0e7
    max_gap_s: float = 0.25
    gate_chi2: float = GATE_CHI2_2DOF
    min_piece: int = 4
    island_max_s: float = 0.3
    island_context_s: float = 0.7
    island_side_s: float = 0.3
    island_min_context: int = 5
    island_off: float = 0.03
    island_ratio: float = 6.0
    island_max_acc: float = 3.0
    island_max_rms: float = 0.03
    island_jump: float = 0.04
    island_speedup: float = 3.0
    island_min_speed: float = 0.005

    def __post_init__(self) -> None:
        for name in ("meas_sigma_px", "jerk_psd", "max_gap_s", "gate_chi2"):
            v = getattr(self, name)
            if not np.isfinite(v) or v <= 0:
                raise ValueError(f"SmootherConfig.{name} must be a positive number, got {v!r}")
        if self.min_piece < 1:
            raise ValueError(f"SmootherConfig.min_piece must be ≥ 1, got {self.min_piece}")
        for name in ("island_max_s", "island_context_s", "island_side_s", "island_off", "island_speedup",
                     "island_min_speed", "island_ratio", "island_max_rms",
                     "island_max_acc", "island_jump"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise ValueError(f"SmootherConfig.{name} must be a number ≥ 0 (island_max_s 0: no islands "
                                 f"dropped), got {v!r}")


@dataclass
class SmoothResult:
    """A smoothed track and how it was cut.

    Attributes:
        track: the smoothed :class:`BallTrack` (same frames and visibility, outliers set to 0).
        pieces: ``(P, 2)`` int, first and last frame of each smoothed piece.
        outliers: ``(K,)`` int, frames whose detection was dropped.
    """

    track: BallTrack
    pieces: np.ndarray
    outliers: np.ndarray


def _model(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Constant-acceleration transition F (3×3) and white-jerk process noise Q (3×3) for one axis."""
    F = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    Q = q * np.array([[dt**5 / 20, dt**4 / 8, dt**3 / 6],
                      [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                      [dt**3 / 6, dt**2 / 2, dt]])
    return F, Q


class _AxisPair:
    """Kalman filter over both image axes (independent, identical models): state (3, 2) = [p, v, a] × [u, v]."""

    def __init__(self, z0: np.ndarray, r: float, q: float, fps: float):
        self.r, self.q, self.fps = r, q, fps
        self.x = np.zeros((3, 2))
        self.x[0] = z0
        self.P = np.diag([r, 1e7, 1e9])  # velocity/acceleration unknown at the start

    def predict(self, steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        F, Q = _model(steps / self.fps, self.q)
        return F @ self.x, F @ self.P @ F.T + Q, F, Q

    def nis(self, z: np.ndarray, x_pred: np.ndarray, P_pred: np.ndarray) -> float:
        s = P_pred[0, 0] + self.r
        return float(np.sum((z - x_pred[0]) ** 2) / s)

    def update(self, z: np.ndarray, x_pred: np.ndarray, P_pred: np.ndarray) -> None:
        s = P_pred[0, 0] + self.r
        k = P_pred[:, 0] / s
        self.x = x_pred + np.outer(k, z - x_pred[0])
        self.P = P_pred - np.outer(k, P_pred[0])


def _smooth_piece(frames: np.ndarray, z: np.ndarray, r: float, q: float, fps: float) -> np.ndarray:
    """RTS-smoothed positions ``(N, 2)`` of one piece (frames increasing, measurements ``z (N, 2)``)."""
    n = len(frames)
    kf = _AxisPair(z[0], r, q, fps)
    xs_f, Ps_f, xs_p, Ps_p, Fs = [kf.x.copy()], [kf.P.copy()], [None], [None], [None]
    for i in range(1, n):
        x_pred, P_pred, F, _ = kf.predict(int(frames[i] - frames[i - 1]))
        kf.update(z[i], x_pred, P_pred)
        xs_f.append(kf.x.copy())
        Ps_f.append(kf.P.copy())
        xs_p.append(x_pred)
        Ps_p.append(P_pred)
        Fs.append(F)
    xs = [None] * n
    xs[-1], P_next = xs_f[-1], Ps_f[-1]
    for i in range(n - 2, -1, -1):
        C = Ps_f[i] @ Fs[i + 1].T @ np.linalg.inv(Ps_p[i + 1])
        xs[i] = xs_f[i] + C @ (xs[i + 1] - xs_p[i + 1])
        P_next = Ps_f[i] + C @ (P_next - Ps_p[i + 1]) @ C.T
    return np.array([x[0] for x in xs])


def split_pieces(frames: np.ndarray, z: np.ndarray, fps: float, cfg: SmootherConfig, r: float, q: float,
                 breaks: np.ndarray) -> tuple[list[np.ndarray], list[int]]:
    """Cut measurement indices into flights; returns (pieces as index arrays, outlier indices)."""
    pieces: list[list[int]] = []
    outliers: list[int] = []
    max_gap = max(1, int(round(cfg.max_gap_s * fps)))
    breaks = set(int(b) for b in breaks)
    cur: list[int] = []
    kf: _AxisPair | None = None
    i = 0
    n = len(frames)
    while i < n:
        if kf is None:
            cur, kf = [i], _AxisPair(z[i], r, q, fps)
            i += 1
            continue
        gap = int(frames[i] - frames[cur[-1]])
        crossed = any(frames[cur[-1]] < b <= frames[i] for b in breaks)
        if gap > max_gap or crossed:  # a long gap or a known contact: the next detection starts a new flight
            pieces.append(cur)
            kf = None
            continue
        x_pred, P_pred, _, _ = kf.predict(gap)
        if len(cur) >= 3 and kf.nis(z[i], x_pred, P_pred) > cfg.gate_chi2:
            # outlier or change point? an outlier is one bad measurement that the next one does not follow
            if i + 1 < n and frames[i + 1] - frames[cur[-1]] <= max_gap:
                x2, P2, _, _ = kf.predict(int(frames[i + 1] - frames[cur[-1]]))
                if kf.nis(z[i + 1], x2, P2) <= cfg.gate_chi2:
                    outliers.append(i)
                    i += 1
                    continue
            pieces.append(cur)
            kf = None
            continue
        kf.update(z[i], x_pred, P_pred)
        cur.append(i)
        i += 1
    if cur:
        pieces.append(cur)
    return [np.asarray(p) for p in pieces], outliers


def track_runs(frames: np.ndarray, z: np.ndarray, jump: float) -> list[np.ndarray]:
    """Index runs of detections ``(frames (M,) sorted, z (M, 2) px)``: consecutive ones at most 2 frames apart
    whose step per frame stays below ``jump`` px (a larger step is the detector moving to something else)."""
    if not len(frames):
        return []
    gap = np.diff(frames)
    step = np.linalg.norm(np.diff(z, axis=0), axis=1) / np.maximum(gap, 1)
    cut = np.flatnonzero((gap > 2) | (step > jump)) + 1
    return np.split(np.arange(len(frames)), cut)


def _bridge(frames: np.ndarray, z: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, float, float]:
    """A quadratic in time through ``z (K, 2)`` at ``frames (K,)``: its positions at ``at``, its largest
    residual (px) and its acceleration (px per frame²)."""
    t0 = float(np.mean(frames))
    A = np.vander(frames - t0, 3)
    coef, *_ = np.linalg.lstsq(A, z, rcond=None)
    worst = float(np.max(np.linalg.norm(A @ coef - z, axis=1)))
    return np.vander(at - t0, 3) @ coef, worst, float(2 * np.linalg.norm(coef[0]))


def off_track_islands(frames: np.ndarray, z: np.ndarray, fps: float, width: int,
                      cfg: SmootherConfig | None = None) -> np.ndarray:
    """``(M,)`` bool: the detections ``(frames (M,) sorted, z (M, 2) px)`` in islands off the track — runs of
    detections at most ``island_max_s`` long that lie far from the smooth path two runs around them agree on
    and out of the ball's reach (:func:`_unreachable`), or that the track jumps away from where the ball is
    lost on their other side (:func:`_jumped_island`); see the module docstring and :class:`SmootherConfig`.
    Nearer runs are tried first; dropping an island can let another be judged, so the search repeats (at
    most 4 rounds)."""
    cfg = cfg or SmootherConfig()
    out = np.zeros(len(frames), bool)
    longest = int(round(cfg.island_max_s * fps))
    if longest < 1 or len(frames) < cfg.island_min_context + 1:
        return out
    reach = max(2, int(round(cfg.island_context_s * fps)))
    span = max(3, int(round(cfg.island_side_s * fps)))
    for _ in range(4):
        idx = np.flatnonzero(~out)
        f, p = frames[idx], z[idx]
        runs = track_runs(f, p, cfg.island_jump * width)
        found = False
        for k, r in enumerate(runs):
            if f[r[-1]] - f[r[0]] + 1 > longest:
                continue
            before = [b for b in runs[max(0, k - 3):k][::-1] if len(b) >= 4 and not out[idx[b]].any()]
            after = [a for a in runs[k + 1:k + 4] if len(a) >= 4]
            for b, a in ((b, a) for b in before for a in after):
                # the two sides: close enough to bridge, long enough (4+ each) to outweigh the island
                if f[a[0]] - f[b[-1]] > reach or len(b) + len(a) < max(cfg.island_min_context, 2 * len(r)):
                    continue
                side = np.r_[b[f[b] >= f[b[-1]] - span], a[f[a] <= f[a[0]] + span]]
                if _off_path(f, p, side, r, fps, width, cfg) and \
                        _unreachable(f, p, b, r, a, cfg.island_speedup, cfg.island_min_speed * width):
                    out[idx[r]] = found = True
                    break
            if not out[idx[r[0]]] and _jumped_island(f, p, runs, k, out[idx], fps, cfg, width):
                out[idx[r]] = found = True
        if not found:
            break
    return out


def _off_path(f: np.ndarray, p: np.ndarray, side: np.ndarray, r: np.ndarray, fps: float, width: int,
              cfg: SmootherConfig) -> bool:
    """Whether run ``r`` lies off the quadratic path through the detections ``side`` (indices into ``f (M,)``
    frames, ``p (M, 2)`` px): the path fits them (largest residual ≤ ``island_max_rms`` × the width, acceleration
    ≤ ``island_max_acc`` × the width per s²) and ``r``'s median distance from it is over ``island_off`` × the
    width and ``island_ratio`` × that residual."""
    path, res, acc = _bridge(f[side].astype(float), p[side], f[r].astype(float))
    if res > cfg.island_max_rms * width or acc > cfg.island_max_acc * width / fps ** 2:
        return False
    d = float(np.median(np.linalg.norm(p[r] - path, axis=1)))
    return d > max(cfg.island_off * width, cfg.island_ratio * res)


def _speed(f: np.ndarray, p: np.ndarray, run: np.ndarray, how=np.median) -> float:
    """Px per frame of a run's consecutive detections (their median, or ``how``)."""
    return float(how(np.linalg.norm(np.diff(p[run], axis=0), axis=1) / np.diff(f[run])))


def _unreachable(f: np.ndarray, p: np.ndarray, b: np.ndarray, r: np.ndarray, a: np.ndarray, speedup: float,
                 floor: float) -> bool:
    """Whether the ball could not have flown to run ``r`` from run ``b`` before it, or from it to run ``a``
    after it: the straight line across either gap needs over ``speedup`` × the faster side's own speed (their
    median px per frame, at least ``floor``: a ball at rest before a serve says nothing of the serve's speed) —
    a hit or a rebound between changes the path, not how far the ball can go in the time."""
    v = speedup * max(_speed(f, p, b), _speed(f, p, a), floor)
    into = np.linalg.norm(p[r[0]] - p[b[-1]]) / (f[r[0]] - f[b[-1]])
    out_of = np.linalg.norm(p[a[0]] - p[r[-1]]) / (f[a[0]] - f[r[-1]])
    return bool(max(into, out_of) > v)


def _jumped_island(f: np.ndarray, p: np.ndarray, runs: list[np.ndarray], k: int, flagged: np.ndarray, fps: float,
                   cfg: SmootherConfig, width: int) -> bool:
    """Whether run ``k`` of ``runs`` (indices into ``f (M,)`` frames, ``p (M, 2)`` px) is an island seen from one
    side only: the track jumps between it and a run next to it (at most 2 frames apart) that holds 4+
    detections and twice the island's, while on its other side the ball is lost (no detection for
    :data:`ISLAND_LOST_S`, or the track's end); the island holds 2+ detections, the jump is over
    ``island_speedup`` × the speed of that run and of
    the island (a ball leaving a hit fast steps as far as it jumps; a shoe does not move), and it lies far (as in
    :func:`off_track_islands`) from where that run's own quadratic, extrapolated over the gap, puts the ball —
    a ball cannot jump."""
    r = runs[k]
    if len(r) < 2:   # one detection next to a jump may be the ball leaving a hit fast: nothing tells
        return False
    lost = max(3, int(round(ISLAND_LOST_S * fps)))
    span = max(3, int(round(cfg.island_side_s * fps)))
    for j, other in ((k + 1, k - 1), (k - 1, k + 1)):
        if not 0 <= j < len(runs):
            continue
        n = runs[j]
        if len(n) < max(4, 2 * len(r)) or flagged[n].any():
            continue
        near = (f[n[0]] - f[r[-1]]) if j > k else (f[r[0]] - f[n[-1]])
        far_side = (f[runs[other][-1]] if other < k else f[runs[other][0]]) if 0 <= other < len(runs) else None
        if near > 2 or (far_side is not None and abs(f[r[0] if other < k else r[-1]] - far_side) <= lost):
            continue
        side = n[f[n] <= f[n[0]] + span] if j > k else n[f[n] >= f[n[-1]] - span]
        if len(side) < 4:
            continue
        # the jump must be far beyond what the ball moves there: a fast ball near the camera steps far
        a, b = (r[-1], n[0]) if j > k else (n[-1], r[0])
        speed = max(_speed(f, p, side), _speed(f, p, r))
        if np.linalg.norm(p[b] - p[a]) <= max(cfg.island_off * width, cfg.island_speedup * speed * (f[b] - f[a])):
            continue
        if _off_path(f, p, side, r, fps, width, cfg):
            return True
    return False


def smooth_track(track: BallTrack, width: int, height: int, fps: float,
                 cfg: SmootherConfig | None = None, event_frames=()) -> SmoothResult:
    """Smooth the positions of ``track`` (normalised coordinates) flight by flight.

    Args:
        track: rows with visibility 1–3 carry measurements; visibility 0 rows are kept as they are.
        width, height: frame size in pixels; fps: frames per second.
        cfg: smoother settings (defaults for 1280-px video).
        event_frames: frames of known contacts (bounces, hits): the smoother never smooths across them.

    Returns:
        :class:`SmoothResult`; ``track`` has the same frames and visibility codes except dropped outliers.
    """
    cfg = cfg or SmootherConfig()
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be positive, got {fps}")
    scale = width / 1280.0
    r = (cfg.meas_sigma_px * scale) ** 2
    q = cfg.jerk_psd * scale**2
    x = np.array(track.xy[:, 0], dtype=float, copy=True)
    y = np.array(track.xy[:, 1], dtype=float, copy=True)
    vis = np.array(track.visibility, copy=True)
    seen = np.flatnonzero((vis > 0) & np.isfinite(x) & np.isfinite(y))
    frames = np.asarray(track.frame)[seen]
    z = np.stack([x[seen] * width, y[seen] * height], axis=1) if len(seen) else np.zeros((0, 2))
    islands = off_track_islands(frames, z, fps, width, cfg)
    keep = np.flatnonzero(~islands)
    pieces, out = split_pieces(frames[keep], z[keep], fps, cfg, r, q, np.asarray(list(event_frames), dtype=np.int64))
    pieces = [keep[p] for p in pieces]
    out = sorted([int(keep[i]) for i in out] + np.flatnonzero(islands).tolist())
    spans = []
    for p in pieces:
        if len(p) >= cfg.min_piece:
            zs = _smooth_piece(frames[p], z[p], r, q, fps)
            x[seen[p]] = zs[:, 0] / width
            y[seen[p]] = zs[:, 1] / height
        spans.append((int(frames[p[0]]), int(frames[p[-1]])))
    for i in out:
        vis[seen[i]] = 0
        x[seen[i]] = np.nan
        y[seen[i]] = np.nan
    xy = np.clip(np.stack([x, y], axis=1), 0.0, 1.0)
    smoothed = BallTrack(frame=track.frame, visibility=vis, xy=xy)
    return SmoothResult(smoothed, np.asarray(spans, dtype=np.int64).reshape(-1, 2),
                        np.asarray([int(frames[i]) for i in out], dtype=np.int64))
