"""Contacts inside the tracker's gaps: time a decoded event from the flights on both sides.

A real tracker loses the ball around many contacts (the body hides a hit, a far ball is a few pixels,
the smoother cuts at the change). HitNet still fires near such a gap but cannot place the contact inside
it. :func:`bridge_contact` fits a quadratic in time to each coordinate of the known positions just before
the gap and just after it, and takes the time where the two extrapolated flights meet (their image
distance is smallest) as the contact; the uncertainty is the half-width of the interval where the two
flights stay within ``meet_tol`` of that smallest distance, at least half a frame, at most half the gap.
Each flight ends at the neighbouring decoded events (``others``): the bounce before a far hit is not part
of the flight into the racket, and a gap that holds another event as well is not bridged.

A serve whose toss the tracker lost (a broadcast tracker loses the far server's ball high against the crowd:
the gap opens on the toss and closes on the serve's flight) is timed by :func:`toss_contact` instead: the
racket meets the ball above the toss, so the contact is where the serve's flight, followed back into the gap,
crosses the toss's image column.

Example:
    >>> t, sigma = bridge_contact(xy, fps, frame)     # frame: a decoded event inside a gap
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BridgeParams:
    """Settings of :func:`bridge_contact`.

    Attributes:
        min_gap: gaps shorter than this many frames are left to the model.
        fit_s: seconds of flight on each side used by the fits; min_points: fewest known positions per side.
        meet_tol: image heights within which the two flights count as meeting (the uncertainty).
        max_shift_s: the contact may move at most this far from the decoded frame (s).
        max_fit_rms: a side's flight whose quadratic misses its own positions by more than this RMS (image
            heights) is not a clean flight (outliers, smoothing, a missed event inside it): no bridge.
        max_sigma: a bridged time less certain than this (frames: slow flights that stay close a long while)
            is left to the model.
        classes: the decoded classes that are bridged: the far player's hits, whose gaps on real broadcast
            tracks are long (half of them hidden, median 0.16 s) and which the models time early there; the
            near player's contact is timed by the models from the swing (docs/events.md).
    """

    min_gap: int = 2
    fit_s: float = 0.4
    min_points: int = 3
    meet_tol: float = 0.005
    max_shift_s: float = 0.2
    max_fit_rms: float | None = 0.005
    max_sigma: float = 1.5
    classes: tuple[str, ...] = ("player_far",)


def gap_around(seen: np.ndarray, frame: int, reach: int = 2) -> tuple[int, int] | None:
    """``(first missing, last missing)`` of the gap that contains ``frame`` or lies within ``reach``
    frames of it, or None."""
    T = len(seen)
    for d in range(reach + 1):
        for f in (frame - d, frame + d):
            if 0 <= f < T and not seen[f]:
                a = f
                while a > 0 and not seen[a - 1]:
                    a -= 1
                b = f
                while b < T - 1 and not seen[b + 1]:
                    b += 1
                return a, b
    return None


def _fit(t: np.ndarray, p: np.ndarray) -> np.ndarray | None:
    """Per-coordinate polynomial (degree 2, or 1 with 3 points) coefficients ``(2, deg + 1)``."""
    deg = 2 if len(t) >= 4 else 1
    try:
        return np.stack([np.polyfit(t, p[:, k], deg) for k in range(2)])
    except (np.linalg.LinAlgError, ValueError):
        return None


def _rms(coef: np.ndarray, t: np.ndarray, p: np.ndarray) -> float:
    """RMS image distance between the positions ``p[t]`` and the fitted flight ``coef`` at ``t``."""
    fit = np.stack([np.polyval(coef[k], t.astype(float)) for k in range(2)], axis=1)
    return float(np.sqrt(np.mean(np.sum((fit - p[t]) ** 2, axis=1))))


def bridge_contact(xy: np.ndarray, fps: float, frame: int, aspect: float = 16 / 9,
                   params: BridgeParams | None = None, others=()) -> tuple[float, float] | None:
    """The contact time (in frames, sub-frame) of a decoded event at ``frame`` that lies in a gap of the
    track ``xy (T, 2)`` (normalised, NaN missing), and its uncertainty (frames); None when there is no
    gap there, too little flight on either side, or another event in the gap.

    ``others``: the frames of the other decoded events; each flight stops at the nearest one.
    """
    params = params or BridgeParams()
    seen = np.isfinite(xy).all(axis=1)
    g = gap_around(seen, int(frame))
    if g is None or g[1] - g[0] + 1 < params.min_gap:
        return None
    a, b = g
    n = max(params.min_points, int(round(params.fit_s * fps)))
    lo, hi = max(a - n, 0), b + 1 + n
    others = [int(o) for o in others if int(o) != int(frame)]
    if any(a <= o <= b for o in others):
        return None  # two events in one gap: the two flights are not one hit's
    lo = max([lo] + [o + 1 for o in others if lo <= o < a])
    hi = min([hi] + [o for o in others if b < o < hi])
    before = np.flatnonzero(seen[lo:a]) + lo
    after = np.flatnonzero(seen[b + 1:hi]) + b + 1
    if len(before) < params.min_points or len(after) < params.min_points:
        return None
    p = xy * np.array([aspect, 1.0])
    fb, fa = _fit(before.astype(float), p[before]), _fit(after.astype(float), p[after])
    if fb is None or fa is None:
        return None
    if params.max_fit_rms is not None and max(_rms(fb, before, p), _rms(fa, after, p)) > params.max_fit_rms:
        return None
    ts = np.linspace(a - 1, b + 1, max(8, 10 * (b - a + 3)))
    d = np.hypot(*(np.stack([np.polyval(fb[k], ts) - np.polyval(fa[k], ts) for k in range(2)])))
    i = int(np.argmin(d))
    t = float(ts[i])
    if abs(t - frame) > params.max_shift_s * fps:
        return None
    close = ts[d <= d[i] + params.meet_tol]
    sigma = float(np.clip((close.max() - close.min()) / 2, 0.5, max(0.5, (b - a + 2) / 2)))
    if sigma > params.max_sigma:
        return None
    return t, sigma


@dataclass(frozen=True)
class TossParams:
    """Settings of :func:`toss_contact`.

    Attributes:
        toss_s: seconds before the gap read as the toss; min_toss: fewest seen positions there.
        vertical: the toss rises at least this many times faster than it drifts across.
        serve_s: seconds after the gap read as the serve's flight; min_serve: fewest seen positions there.
        faster: the serve leaves at least this many times faster than the toss rose.
        noise: image heights of position noise behind the uncertainty (a crossing's σ = noise / the flight's
            speed across); max_sigma: frames; a crossing less certain than this is not used.
    """

    toss_s: float = 0.3
    min_toss: int = 3
    vertical: float = 2.0
    serve_s: float = 0.25
    min_serve: int = 4
    faster: float = 2.0
    noise: float = 0.002
    max_sigma: float = 2.0


def toss_contact(xy: np.ndarray, fps: float, frame: int, aspect: float = 16 / 9, params: TossParams | None = None,
                 others=()) -> tuple[float, float] | None:
    """The serve's contact (frames, sub-frame) and its uncertainty when the gap of ``xy (T, 2)`` (normalised,
    NaN missing) at ``frame`` opens on a toss (the ball rising at one image x) and closes on a faster flight:
    the time that flight, followed back into the gap, crosses the toss's column (the racket meets the ball
    above the toss). None when the gap is not a lost toss, the flight crosses no column inside it, or the
    crossing is too uncertain (a serve straight along the column). ``others``: other decoded events' frames; the
    serve's flight stops at the next one.

    On a real final's far serves (a broadcast tracker's tracks) the crossing lies within 2.5 frames of the
    hand label for 52 of the 79 serves whose toss and flight are seen (the quadratic bridge: 38 of 117).
    """
    params = params or TossParams()
    seen = np.isfinite(xy).all(axis=1)
    g = gap_around(seen, int(frame))
    if g is None:
        return None
    a, b = g
    T = len(xy)
    nt, ns = max(params.min_toss, int(round(params.toss_s * fps))), max(params.min_serve, int(round(params.serve_s * fps)))
    others = [int(o) for o in others if int(o) != int(frame)]
    if any(a <= o <= b for o in others):
        return None
    lo = max([max(a - nt, 0)] + [o + 1 for o in others if a - nt <= o < a])
    hi = min([min(b + 1 + ns, T)] + [o for o in others if b < o < b + 1 + ns])
    toss, serve = np.flatnonzero(seen[lo:a]) + lo, np.flatnonzero(seen[b + 1:hi]) + b + 1
    if len(toss) < params.min_toss or len(serve) < params.min_serve:
        return None
    p = xy * np.array([aspect, 1.0])
    vt = np.polyfit(toss.astype(float), p[toss], 1)[0]            # (vx, vy) of the toss, per frame
    if not (vt[1] < 0 and abs(vt[1]) >= params.vertical * abs(vt[0])):  # rising (image y falls), upright
        return None
    deg = 2 if len(serve) >= 6 else 1
    cx = np.polyfit(serve.astype(float), p[serve, 0], deg)
    vs = np.polyfit(serve.astype(float), p[serve], 1)[0]
    if np.hypot(*vs) < params.faster * np.hypot(*vt):
        return None
    column = float(np.median(p[toss[-min(len(toss), 5):], 0]))
    ts = np.linspace(a - 1, b + 1, max(8, 10 * (b - a + 3)))
    dx = np.polyval(cx, ts) - column
    cross = np.flatnonzero(np.sign(dx[:-1]) != np.sign(dx[1:]))
    if not len(cross):
        return None
    i = int(cross[-1])                                             # the crossing nearest the flight
    t = float(ts[i] - dx[i] * (ts[i + 1] - ts[i]) / (dx[i + 1] - dx[i]))
    speed = abs(float(np.polyval(np.polyder(cx), t))) if deg == 2 else abs(float(cx[0]))
    sigma = max(0.5, params.noise / max(speed, 1e-9))
    if sigma > params.max_sigma:
        return None
    return t, sigma


def bridge_events(xy: np.ndarray, fps: float, frames: np.ndarray, aspect: float = 16 / 9,
                  params: BridgeParams | None = None, which: np.ndarray | None = None,
                  toss: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Decoded event frames ``(N,)`` → frames moved to their bridged contacts (kept where no gap or no fit)
    and their uncertainty ``(N,)`` in frames (NaN: not in a gap, the model's own timing). ``which``: ``(N,)``
    bool, the events to bridge (default all); every event still ends its neighbours' flights. ``toss``: a gap
    that opens on a lost toss is timed by :func:`toss_contact` first."""
    frames = np.asarray(frames, np.int64)
    out = frames.copy()
    sigma = np.full(len(out), np.nan)
    todo = np.ones(len(frames), bool) if which is None else np.asarray(which, bool)
    for k in np.flatnonzero(todo):
        others = np.delete(frames, k)
        r = toss_contact(xy, fps, int(frames[k]), aspect, others=others) if toss else None
        r = r or bridge_contact(xy, fps, int(frames[k]), aspect, params, others=others)
        if r is not None:
            out[k] = int(np.clip(round(r[0]), 0, len(xy) - 1))
            sigma[k] = r[1]
    return out, sigma
