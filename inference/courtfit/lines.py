"""Painted-line evidence in a video: a background without players, its line pixels and its straight lines.

* :func:`background` — the per-pixel median of a few frames spread over the clip (players and the ball
  move, the court does not), as a "line brightness" channel ``min(R, G)``: high for white and yellow
  paint, low for blue, green and clay floors;
* :func:`line_mask` — a pixel is on a line when it is brighter than the pixels ``τ`` away on both sides
  (horizontally or vertically, for several ``τ`` so thin far lines and thick near lines both pass) and
  the local gradient has one dominant direction (structure-tensor coherence), which drops netting,
  mesh and text;
* :func:`hough_lines` — straight lines through those pixels (Hough transform, duplicates merged, each
  refitted by total least squares to its pixels).

Everything runs at a working scale (the larger side at most :data:`WORK_SIZE` px); coordinates returned
to callers are in full-resolution pixels.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

WORK_SIZE = 1280
RIDGE_STEPS = (2, 4, 7)  # τ at a 1280-px working width
RIDGE_CONTRAST = 14  # grey levels a line pixel is brighter than both sides
COHERENCE_MIN = 0.5


@dataclass
class LineEvidence:
    """Line pixels of one view.

    Attributes:
        scale: working pixels per full-resolution pixel (≤ 1).
        size: (W, H) full-resolution image size.
        mask: (h, w) bool line pixels at the working scale.
        distance: (h, w) float32 distance (working px) to the nearest line pixel.
        pixels: (N, 2) line-pixel centres in full-resolution pixels.
    """

    scale: float
    size: tuple[int, int]
    mask: np.ndarray
    distance: np.ndarray
    pixels: np.ndarray

    @classmethod
    def from_mask(cls, mask: np.ndarray, scale: float, size: tuple[int, int]) -> LineEvidence:
        dist = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 3)
        ys, xs = np.nonzero(mask)
        pixels = (np.stack([xs, ys], axis=1) + 0.5) / scale - 0.5
        return cls(scale, size, mask, dist, pixels)


def working_scale(size: tuple[int, int], work_size: int = WORK_SIZE) -> float:
    return min(1.0, work_size / max(size))


def line_channel(frame: np.ndarray, scale: float) -> np.ndarray:
    """(H, W, 3) RGB uint8 → (h, w) uint8 ``min(R, G)`` at the working scale."""
    if scale < 1.0:
        frame = cv2.resize(frame, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    return np.minimum(frame[..., 0], frame[..., 1])


def background(frames: Sequence[np.ndarray], scale: float) -> np.ndarray:
    """The per-pixel median of the frames' line channels (h, w) uint8."""
    stack = np.stack([line_channel(f, scale) for f in frames])
    if len(stack) == 1:
        return stack[0]
    return np.median(stack, axis=0).astype(np.uint8)


def _ridge(L: np.ndarray, steps: Sequence[int]) -> np.ndarray:
    L = L.astype(np.int16)
    resp = np.zeros_like(L)
    for t in steps:
        p = np.pad(L, t, mode="edge")
        c = p[t:-t, t:-t]
        dh = np.minimum(c - p[t:-t, : -2 * t], c - p[t:-t, 2 * t :])
        dv = np.minimum(c - p[: -2 * t, t:-t], c - p[2 * t :, t:-t])
        resp = np.maximum(resp, np.maximum(dh, dv))
    return resp


def _coherence(L: np.ndarray, window: int) -> np.ndarray:
    """Structure-tensor coherence (λ1 − λ2) / (λ1 + λ2) in [0, 1]: 1 where the gradient has one direction."""
    g = cv2.GaussianBlur(L.astype(np.float32), (0, 0), 1.0)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3)
    box = (window, window)
    jxx, jyy, jxy = (cv2.boxFilter(a, -1, box) for a in (gx * gx, gy * gy, gx * gy))
    return np.sqrt((jxx - jyy) ** 2 + 4 * jxy**2) / np.maximum(jxx + jyy, 1e-6)


def line_mask(L: np.ndarray, contrast: float = RIDGE_CONTRAST) -> np.ndarray:
    """(h, w) uint8 line channel → (h, w) bool line pixels (bright ridges with one orientation)."""
    k = max(L.shape) / WORK_SIZE
    steps = sorted({max(1, int(round(t * k))) for t in RIDGE_STEPS})
    mask = _ridge(L, steps) > contrast
    mask &= _coherence(L, max(5, int(round(15 * k)) | 1)) > COHERENCE_MIN
    return mask


@dataclass
class ImageLine:
    """A straight line ``n · p = c`` (unit normal n) in full-resolution pixels, with its support.

    Attributes:
        normal: (2,) unit normal; offset: c.
        votes: line pixels within 1.5 working px.
        angle_deg: direction of the line from the image's x axis, in (−90, 90].
    """

    normal: np.ndarray
    offset: float
    votes: int

    @property
    def angle_deg(self) -> float:
        a = np.degrees(np.arctan2(-self.normal[0], self.normal[1]))
        return float((a + 90) % 180 - 90) if (a + 90) % 180 != 0 else 90.0

    @property
    def homogeneous(self) -> np.ndarray:
        """(3,) the line as ``(a, b, c)`` with ``a x + b y + c = 0``."""
        return np.array([self.normal[0], self.normal[1], -self.offset])

    def distance(self, pts: np.ndarray) -> np.ndarray:
        return np.abs(pts @ self.normal - self.offset)


def _tls(pts: np.ndarray) -> tuple[np.ndarray, float]:
    c = pts.mean(axis=0)
    _, _, Vt = np.linalg.svd(pts - c, full_matrices=False)
    n = Vt[-1]
    return n, float(n @ c)


def hough_lines(ev: LineEvidence, max_lines: int = 48, min_length_frac: float = 0.05,
                angles: tuple[float, float] | None = None, kept: Sequence[ImageLine] = (),
                depth: int | None = None) -> list[ImageLine]:
    """Straight lines through the line pixels, strongest first, duplicates merged, each refitted by TLS.

    Args:
        ev: the line evidence.
        max_lines: at most this many lines.
        min_length_frac: a line needs at least this fraction of the working image's larger side in votes.
        angles: only lines whose direction lies this many degrees (low, high) from the image's x axis (either
            way); None: every direction.
        kept: lines found before: a duplicate of one of them is not returned, and the line pixels on them
            (within 1.5 working px) do not count for the new lines: a line that crosses a dense band of kept
            lines at a shallow angle collects many votes from their pixels, but none of its own.
        depth: accumulator peaks examined, strongest first (default 40 per line asked for).
    """
    h, w = ev.mask.shape
    thresh = max(20, int(min_length_frac * max(h, w)))
    if angles is None:
        found = cv2.HoughLinesWithAccumulator(ev.mask.astype(np.uint8), 1, np.pi / 360, thresh)
        if found is None:
            return []
        found = found.reshape(-1, 3)
        found = found[np.argsort(-found[:, 2])]
    else:  # two ranges of the normal's angle θ (the direction's + 90°)
        a0, a1 = np.radians(angles[0]), np.radians(angles[1])
        parts = [cv2.HoughLinesWithAccumulator(ev.mask.astype(np.uint8), 1, np.pi / 360, thresh,
                                               min_theta=max(t0, 0.0), max_theta=min(t1, np.pi))
                 for t0, t1 in ((np.pi / 2 - a1, np.pi / 2 - a0), (np.pi / 2 + a0, np.pi / 2 + a1))]
        parts = [f.reshape(-1, 3) for f in parts if f is not None]
        if not parts:
            return []
        found = np.concatenate(parts)
        found = found[np.argsort(-found[:, 2], kind="stable")]
    ys, xs = np.nonzero(ev.mask)
    wpix = np.stack([xs, ys], axis=1).astype(float)
    lines: list[ImageLine] = []
    kept = list(kept)
    if kept:
        full = (wpix + 0.5) / ev.scale - 0.5
        on_kept = np.min([k.distance(full) for k in kept], axis=0) * ev.scale < 1.5
        wpix = wpix[~on_kept]
    probes = np.linspace(0, 1, 9)
    for rho, theta, _ in found[: depth or 40 * max_lines]:
        n = np.array([np.cos(theta), np.sin(theta)])
        near = wpix[np.abs(wpix @ n - rho) < 2.5]
        if len(near) < thresh // 2:
            continue
        for band in (2.0, 1.5):  # refit to the pixels of this line only
            n, c = _tls(near)
            near = wpix[np.abs(wpix @ n - c) < band]
            if len(near) < 10:
                break
        if len(near) < thresh // 2:
            continue
        # compare the visible stretch of the line with the lines already kept (all in working px)
        d = np.array([-n[1], n[0]])
        lo, hi = np.quantile(near @ d, [0.02, 0.98])
        pts = (c * n + np.outer(lo + probes * (hi - lo), d) + 0.5) / ev.scale - 0.5
        if any(np.median(k.distance(pts)) * ev.scale < 4.0 for k in kept + lines):
            continue
        full_c = (c + 0.5 * n.sum()) / ev.scale - 0.5 * n.sum()
        line = ImageLine(n, float(full_c), int(len(near)))
        if angles is not None and not angles[0] <= abs(line.angle_deg) <= angles[1]:
            continue  # the refit turned it out of the range asked for
        lines.append(line)
        if len(lines) >= max_lines:
            break
    return lines
