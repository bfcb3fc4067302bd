"""Contacts inside the tracker's gaps: time a decoded event from the flights on both sides.

A real tracker loses the ball around many contacts (the body hides a hit, a far ball is a few pixels,
the smoother cuts at the change). HitNet still fires near such a gap but cannot place the contact inside
it. :func:`bridge_contact` fits a quadratic in time to each coordinate of the known positions just before
the gap and just after it, and takes the time where the two extrapolated flights meet (their image
distance is smallest) as the contact; the uncertainty is the half-width of the interval where the two
flights stay within ``meet_tol`` of that smallest distance, at least half a frame, at most half the gap.

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
    """

    min_gap: int = 2
    fit_s: float = 0.2
    min_points: int = 3
    meet_tol: float = 0.01
    max_shift_s: float = 0.2


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


def bridge_contact(xy: np.ndarray, fps: float, frame: int, aspect: float = 16 / 9,
                   params: BridgeParams | None = None) -> tuple[float, float] | None:
    """The contact time (in frames, sub-frame) of a decoded event at ``frame`` that lies in a gap of the
    track ``xy (T, 2)`` (normalised, NaN missing), and its uncertainty (frames); None when there is no
    gap there or too little flight on either side."""
    params = params or BridgeParams()
    seen = np.isfinite(xy).all(axis=1)
    g = gap_around(seen, int(frame))
    if g is None or g[1] - g[0] + 1 < params.min_gap:
        return None
    a, b = g
    n = max(params.min_points, int(round(params.fit_s * fps)))
    before = np.flatnonzero(seen[max(a - n, 0):a]) + max(a - n, 0)
    after = np.flatnonzero(seen[b + 1:b + 1 + n]) + b + 1
    if len(before) < params.min_points or len(after) < params.min_points:
        return None
    p = xy * np.array([aspect, 1.0])
    fb, fa = _fit(before.astype(float), p[before]), _fit(after.astype(float), p[after])
    if fb is None or fa is None:
        return None
    ts = np.linspace(a - 1, b + 1, max(8, 10 * (b - a + 3)))
    d = np.hypot(*(np.stack([np.polyval(fb[k], ts) - np.polyval(fa[k], ts) for k in range(2)])))
    i = int(np.argmin(d))
    t = float(ts[i])
    if abs(t - frame) > params.max_shift_s * fps:
        return None
    close = ts[d <= d[i] + params.meet_tol]
    sigma = float(np.clip((close.max() - close.min()) / 2, 0.5, max(0.5, (b - a + 2) / 2)))
    return t, sigma


def bridge_events(xy: np.ndarray, fps: float, frames: np.ndarray, aspect: float = 16 / 9,
                  params: BridgeParams | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Decoded event frames ``(N,)`` → frames moved to their bridged contacts (kept where no gap or no fit)
    and their uncertainty ``(N,)`` in frames (NaN: not in a gap, the model's own timing)."""
    out = np.asarray(frames, np.int64).copy()
    sigma = np.full(len(out), np.nan)
    for k, f in enumerate(out):
        r = bridge_contact(xy, fps, int(f), aspect, params)
        if r is not None:
            out[k] = int(np.clip(round(r[0]), 0, len(xy) - 1))
            sigma[k] = r[1]
    return out, sigma
