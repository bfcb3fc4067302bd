"""Image regions to ignore (a broadcast's scoreboard, logos, a clock): clip.yaml's ``mask`` key.

``mask`` is a list of rectangles ``[x0, y0, x1, y1]`` in normalised image coordinates (docs/formats.md §4).
The ball detector and the automatic court fit see those pixels filled with one flat colour, so a
scoreboard's digits give no ball candidates and its edges no court lines.

Example:
    >>> rects = clip_mask(clip)                  # [] when clip.yaml has no mask
    >>> frame = apply_mask(frame, rects)         # (H, W, 3) uint8, a copy when anything was masked
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from inference.clipio import Clip, FormatError

FIX = "write mask as a list of [x0, y0, x1, y1] rectangles in normalised image coordinates, e.g. " \
      "mask: [[0.02, 0.03, 0.30, 0.12]]"


@dataclass(frozen=True)
class MaskRect:
    """A rectangle to ignore, normalised coordinates, ``0 ≤ x0 < x1 ≤ 1`` and ``0 ≤ y0 < y1 ≤ 1``."""

    x0: float
    y0: float
    x1: float
    y1: float

    def __post_init__(self) -> None:
        if not (0 <= self.x0 < self.x1 <= 1 and 0 <= self.y0 < self.y1 <= 1):
            raise ValueError(f"[{self.x0}, {self.y0}, {self.x1}, {self.y1}] is not a rectangle inside [0, 1]²")

    def pixels(self, width: int, height: int) -> tuple[int, int, int, int]:
        """(x0, y0, x1, y1) whole pixels covering the rectangle."""
        return (int(np.floor(self.x0 * width)), int(np.floor(self.y0 * height)),
                int(np.ceil(self.x1 * width)), int(np.ceil(self.y1 * height)))


def parse_mask(value, where) -> list[MaskRect]:
    """clip.yaml's ``mask`` value → rectangles; :class:`FormatError` naming ``where`` and the entry."""
    if value is None:
        return []
    if not isinstance(value, list):
        raise FormatError(where, "mask must be a list of rectangles", fix=FIX)
    rects = []
    for k, r in enumerate(value):
        try:
            if isinstance(r, bool) or not isinstance(r, list) or len(r) != 4:
                raise ValueError("expected 4 numbers")
            rects.append(MaskRect(*(float(v) for v in r)))
        except (TypeError, ValueError) as e:
            raise FormatError(where, f"mask entry {k + 1} ({r!r}): {e}", fix=FIX) from None
    return rects


def clip_mask(clip: Clip) -> list[MaskRect]:
    """The rectangles of ``clip``'s clip.yaml ``mask`` key ([] when there is none)."""
    return parse_mask(clip.info.extra.get("mask"), clip.clip_yaml_path)


def apply_mask(frame: np.ndarray, rects: list[MaskRect]) -> np.ndarray:
    """``frame`` (H, W, 3) with every rectangle filled with the median colour of the frame's border around
    it (flat: no edges, no ball-like blobs); the input is not changed."""
    if not rects:
        return frame
    out = frame.copy()
    h, w = frame.shape[:2]
    for r in rects:
        x0, y0, x1, y1 = r.pixels(w, h)
        ring = np.concatenate([frame[max(y0 - 2, 0):y0, x0:x1].reshape(-1, 3),
                               frame[y1:y1 + 2, x0:x1].reshape(-1, 3),
                               frame[y0:y1, max(x0 - 2, 0):x0].reshape(-1, 3),
                               frame[y0:y1, x1:x1 + 2].reshape(-1, 3)])
        out[y0:y1, x0:x1] = np.median(ring, axis=0) if len(ring) else 0
    return out
