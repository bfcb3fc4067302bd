"""Rally segmentation: where the point starts (the serve) and ends (the ball is dead), from the ball
track and the decoded events, so that the server's bounces before the serve and the ball after the
point are reported apart from the rally's events.

The serve: among the decoded racket hits after which the ball's image speed rises (``speed_ratio``) and
the ball stays away from where it was (``away_s``; a bounce in the server's hand or a toss comes back, a
serve does not), the first, or within ``serve_window_s`` of it the one with the fastest ball after it.
Without such a hit, the first frame from which the ball stays ``min_travel`` away and the sharpest change
of its velocity there. Sports whose serve bounces first (padel) keep that bounce in the point.

The end: the second floor bounce after a hit; else, when the events stop (a gap of ``gap_s`` in the
track, no event for ``max_flight_s``), where the ball is lost, stands still, or ``dead_s`` after the last
event. Times are in seconds and distances in image heights, so the constants hold at 25–60 fps.

Example:
    >>> seg = segment_rally(xy, fps, events.frame, coarse, hits=("player_near", "player_far"))
    >>> seg.start, seg.end, seg.inside
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class RallyParams:
    """Segmentation constants (seconds and image heights).

    Attributes:
        away_s, min_travel: the track's serve test (:func:`serve_candidate`); behind_s, leave_ratio,
            hit_travel: a decoded hit is the serve when the ball then stays ``leave_ratio`` × (how far it
            moved in the ``behind_s`` before) and ``hit_travel`` away, and its image speed during the
            ``speed_s`` after is ``speed_ratio`` × that before (a catch is not a serve); of such hits within
            ``serve_window_s`` of the first, the one with the fastest ball after it (not the toss).
        snap_s: a decoded racket hit this close to the serve test's frame is the serve.
        serve_bounce: the sport's serve bounces first (padel); serve_bounce_s: how long before the serve.
        gap_s: a gap this long ends the point; max_flight_s: no event for this long after an event ends it;
        dead_s: the ball is dead this long after the last event when the track goes on.
        still_s, still_speed: the ball moving less than ``still_speed`` image heights per second for
            ``still_s`` ends the point.
    """

    away_s: tuple[float, float] = (0.3, 0.8)
    min_travel: float = 0.08
    behind_s: float = 1.0
    leave_ratio: float = 1.0
    hit_travel: float = 0.02
    speed_s: float = 0.12
    speed_ratio: float = 1.5
    serve_window_s: float = 1.2
    snap_s: float = 0.15
    serve_bounce: bool = False
    serve_bounce_s: float = 1.2
    gap_s: float = 1.0
    max_flight_s: float = 2.6
    dead_s: float = 0.5
    still_s: float = 0.5
    still_speed: float = 0.05

    @classmethod
    def for_sport(cls, sport: str | None) -> RallyParams:
        """The sport's constants (tuned on 100 simulated rallies of seed 7007 per sport, ``bench_rally.py``
        reports on others): padel's serve bounces; its far serves and near bounces need a stricter test."""
        if sport == "padel":
            return cls(serve_bounce=True, leave_ratio=2.0, speed_ratio=3.0)
        if sport == "tennis":
            return cls(hit_travel=0.05)
        return cls()


@dataclass
class RallySegment:
    """The point of a clip.

    Attributes:
        start: the serve's frame; end: the frame where the ball is dead (``start <= end``).
        inside: ``(N,)`` bool per event given, True for the rally's events.
        serve_source: ``hit`` (a decoded racket hit) or ``track`` (the velocity change) or ``none``.
    """

    start: int
    end: int
    inside: np.ndarray
    serve_source: str = "hit"


def _scaled(xy: np.ndarray, aspect: float) -> np.ndarray:
    """Normalised image positions → image-height units (x scaled by width / height)."""
    return xy * np.array([aspect, 1.0])


def away_and_back(xy: np.ndarray, fps: float, aspect: float, params: RallyParams) -> tuple[np.ndarray, np.ndarray]:
    """Per frame ``t`` (image heights): ``away`` = the smallest distance from ``p[t]`` of the known
    positions within ``away_s`` after ``t`` (inf when too few are known: ``-inf`` is never away) and
    ``back`` = the largest distance moved during the ``behind_s`` before ``t``."""
    p = _scaled(xy, aspect)
    T = len(p)
    a, b = (max(1, int(round(s * fps))) for s in params.away_s)
    away = np.full(T, np.inf)
    known = np.zeros(T, int)
    for s in range(a, min(b, T - 1) + 1):
        d = np.linalg.norm(p[s:] - p[:-s], axis=1)
        ok = np.isfinite(d)
        away[:-s] = np.where(ok, np.minimum(away[:-s], np.where(ok, d, np.inf)), away[:-s])
        known[:-s] += ok
    away[(known < max(2, (b - a + 1) // 3)) | ~np.isfinite(p).all(axis=1)] = -np.inf
    back = np.zeros(T)
    for s in range(1, min(max(1, int(round(params.behind_s * fps))), T - 1) + 1):
        d = np.linalg.norm(p[s:] - p[:-s], axis=1)
        back[s:] = np.fmax(back[s:], np.nan_to_num(d, nan=0.0))
    return away, back


def serve_candidate(xy: np.ndarray, fps: float, aspect: float, params: RallyParams) -> int | None:
    """First frame after which the ball stays at least ``min_travel`` image heights away for ``away_s``
    (a bounce by the server or a toss comes back to the hand; a serve does not), or None."""
    away, _ = away_and_back(xy, fps, aspect, params)
    idx = np.flatnonzero(away > params.min_travel)
    return int(idx[0]) if len(idx) else None


def sharpest_turn(xy: np.ndarray, lo: int, hi: int, aspect: float) -> int | None:
    """Frame in ``[lo, hi]`` with the largest change of the ball's velocity (None: not enough track)."""
    p = _scaled(xy, aspect)
    acc = np.full(len(p), -1.0)
    if len(p) >= 3:
        a = np.linalg.norm(p[2:] - 2 * p[1:-1] + p[:-2], axis=1)
        acc[1:-1] = np.nan_to_num(a, nan=-1.0)
    lo, hi = max(lo, 0), min(hi, len(p) - 1)
    if hi < lo or acc[lo:hi + 1].max() < 0:
        return None
    return lo + int(np.argmax(acc[lo:hi + 1]))


def rally_end(xy: np.ndarray, fps: float, start: int, frames: np.ndarray, labels: list[str], hits, aspect: float,
              params: RallyParams) -> tuple[int, int]:
    """``(end frame, index of the last rally event + 1)`` given the serve frame and the sorted events:
    the point is over at the second floor bounce after a hit, or, when the events stop (a gap of
    ``gap_s``, no event for ``max_flight_s``), where the ball is lost, stands still or ``dead_s`` later."""
    T = len(xy)
    seen = np.isfinite(xy).all(axis=1)
    gap = max(1, int(round(params.gap_s * fps)))
    max_flight = int(round(params.max_flight_s * fps))
    k = int(np.searchsorted(frames, start, side="left"))
    last, bounces = k, 0  # events [.., last) are in the rally
    while last < len(frames):
        f = int(frames[last])
        prev = int(frames[last - 1]) if last > k else start
        if f - prev > max_flight or _gap_between(seen, prev, f, gap):
            break
        last += 1
        bounces = 0 if labels[last - 1] in hits else bounces + (labels[last - 1] == "ground")
        if bounces >= 2:
            return f, last  # the second bounce: the point is over
    last_f = int(frames[last - 1]) if last > k else start
    end = min(T - 1, last_f + int(round(params.dead_s * fps)))
    nxt = np.flatnonzero(~seen[last_f + 1:])
    if len(nxt):
        g0 = last_f + 1 + int(nxt[0])
        run = np.flatnonzero(seen[g0:])
        if (len(run) == 0 or run[0] >= gap) and g0 - 1 < end:
            end = max(g0 - 1, last_f)
    p = _scaled(xy, aspect)
    still = max(2, int(round(params.still_s * fps)))
    v = np.linalg.norm(np.diff(p, axis=0), axis=1) * fps
    for t in range(last_f + 1, min(end, T - still)):
        w = v[t:t + still]
        if np.isfinite(w).all() and (w < params.still_speed).all():
            end = t
            break
    return int(max(end, start)), last


def _gap_between(seen: np.ndarray, a: int, b: int, gap: int) -> bool:
    """Whether the track has a run of ``gap`` or more missing frames between frames a and b."""
    miss = ~seen[a + 1:b]
    if len(miss) < gap:
        return False
    run = np.convolve(miss.astype(int), np.ones(gap, int), "valid")
    return bool((run >= gap).any())


def segment_rally(xy: np.ndarray, fps: float, frames: np.ndarray, labels, hits=("player_near", "player_far"),
                  aspect: float = 16 / 9, params: RallyParams | None = None) -> RallySegment:
    """Segment one clip.

    Args:
        xy: ``(T, 2)`` normalised ball positions at the clip's frames, NaN where missing.
        fps: the clip's frame rate; frames: ``(N,)`` event frames (sorted); labels: their N labels
            (events.csv's; ``ground`` counts bounces).
        hits: the racket-hit labels; aspect: image width / height.
    Returns:
        the :class:`RallySegment`.
    """
    params = params or RallyParams()
    frames = np.asarray(frames, np.int64)
    labels = [str(c) for c in labels]
    T = len(xy)
    hit_frames = np.array([f for f, c in zip(frames, labels) if c in hits], np.int64)
    snap = int(round(params.snap_s * fps))
    reach = int(round(params.away_s[0] * fps))
    start, source = None, "none"
    away, back = away_and_back(xy, fps, aspect, params)
    p = _scaled(xy, aspect)
    v = np.full(T, np.nan)
    v[1:] = np.linalg.norm(np.diff(p, axis=0), axis=1)
    k = max(2, int(round(params.speed_s * fps)))
    passing, speed = [], []
    for h in hit_frames:  # decoded hits after which the ball is fast and stays away
        w = slice(max(h - 1, 0), min(h + 2, T))
        before, after = v[max(h - k + 1, 0):h + 1], v[h + 2:h + 2 + k]
        if np.isfinite(after).sum() < 2:
            continue
        fast = not np.isfinite(before).any() or np.nanmedian(after) > params.speed_ratio * np.nanmedian(before)
        if fast and len(away[w]) and (away[w] > np.maximum(params.hit_travel, params.leave_ratio * back[w])).any():
            passing.append(int(h))
            speed.append(float(np.nanmedian(after)))
    if passing:  # the toss or the drop before a serve can pass too: the fastest within serve_window_s
        sel = [i for i, h in enumerate(passing) if h - passing[0] <= params.serve_window_s * fps]
        start, source = passing[max(sel, key=lambda i: speed[i])], "hit"
    cand = serve_candidate(xy, fps, aspect, params) if start is None else None
    if cand is not None:
        near = hit_frames[(hit_frames >= cand - snap) & (hit_frames <= cand + reach + snap)]
        if len(near):
            start, source = int(near[0]), "hit"
        else:
            start = sharpest_turn(xy, cand - reach, cand + reach, aspect)
            source = "track" if start is not None else "none"
    if start is None:
        start = int(hit_frames[0]) if len(hit_frames) else (int(frames[0]) if len(frames) else 0)
        source = "hit" if len(hit_frames) else "none"
    end, last = rally_end(xy, fps, start, frames, labels, hits, aspect, params)
    first = int(np.searchsorted(frames, start, side="left"))
    if params.serve_bounce and first > 0 and labels[first - 1] not in hits and \
            start - frames[first - 1] <= params.serve_bounce_s * fps:
        first -= 1
    inside = np.zeros(len(frames), bool)
    inside[first:last] = True
    return RallySegment(int(min(start, T - 1)) if T else 0, int(min(end, T - 1)) if T else 0, inside, source)


# ------------------------------------------------------------------------------------------- file
def write_rally_yaml(path: str | Path, seg: RallySegment, fps: float, outside: list[tuple[int, str]] | None = None,
                     source: str = "rally3d events") -> Path:
    """Write ``rally.yaml`` (docs/formats.md): the point's start/end frames and times and the events
    detected outside it."""
    import yaml

    from inference.clipio import atomic_write_bytes

    d = {"start": int(seg.start), "end": int(seg.end), "start_s": round(seg.start / fps, 4),
         "end_s": round(seg.end / fps, 4), "serve": seg.serve_source, "source": source,
         "outside": [{"frame": int(f), "event": str(e)} for f, e in (outside or [])]}
    return atomic_write_bytes(Path(path), yaml.safe_dump(d, sort_keys=False).encode())


def read_rally_yaml(path: str | Path) -> tuple[int, int]:
    """``(start, end)`` frames of ``rally.yaml``; a clear error naming the file when malformed."""
    import yaml

    path = Path(path)
    try:
        d = yaml.safe_load(path.read_text())
        start, end = int(d["start"]), int(d["end"])
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as e:
        raise ValueError(f"{path}: not a rally.yaml with integer `start` and `end` frames ({type(e).__name__}: "
                         f"{e}); fix or delete the file") from None
    if not 0 <= start <= end:
        raise ValueError(f"{path}: need 0 <= start <= end, got start={start}, end={end}")
    return start, end
