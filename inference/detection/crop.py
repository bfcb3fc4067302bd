"""Crop-tracking: run the detector on a small window around where the tracker expects the ball.

The networks are trained on the letterboxed full frame (e.g. 288×512), so the ball's size in network
pixels is fixed by that downscale. A crop keeps it: the window is cut from the **letterboxed** frame (same
pixels per ball), only smaller — a 144×256 window is a quarter of the 288×512 grid, and the fully
convolutional networks run about 4–5× faster on it. Windows are placed on the 8-pixel grid of the network's
three stride-2 stages, so a crop sees the same sampling phase as the full frame.

Rules (:class:`CropConfig`), per detector window of ``F`` frames:

- **Full frame** to acquire the ball: when the online tracker has no ball track, when it coasts (missed
  the last frame), when the last detection scored below ``min_score``, when the expected positions of the
  window's frames do not fit in one crop with ``margin`` to spare, and at least every ``full_every_s``
  seconds (a new ball, a ball the track lost to a look-alike).
- **Crop** otherwise; the crop's answer is kept only if every frame of the window has a candidate scoring
  ``min_score`` or more at least ``border`` pixels inside the crop (near its edges the network sees zero
  padding instead of the scene). Otherwise the same window is **re-run on the full frame** at once — a hit
  or bounce that threw the ball out of the crop costs one extra full pass, never a lost frame.
- **Lost ball backoff**: while the tracker has no ball and ``lost_after`` full-frame windows in a row found
  none (the ball above the picture on a lob, between points), only every ``lost_skip + 1``-th window is
  searched; when one finds the ball again, the skipped windows before it are searched at once and their
  frames reach the tracker in order, so the track is the same unless a ball shows only inside a skipped
  window (under ``lost_skip × F`` frames).

Example:
    >>> cfg = CropConfig()
    >>> box = place_crop(np.array([[256.0, 144.0]]), (288, 512), cfg)   # (y0, x0) of the crop
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import Letterbox
from .postprocess import FrameCandidates, _inside

CROP_MODES = ("auto", "off")


@dataclass(frozen=True)
class CropConfig:
    """Knobs of crop-tracking (network pixels, i.e. of the letterboxed grid)."""

    size: tuple[int, int] = (144, 256)   # (H, W) of the crop, multiples of ``align``: ¼ of 288×512
    margin: int = 32                     # expected positions at least this far inside the crop
    border: int = 12                     # candidates nearer the crop's edge than this are not trusted
    min_score: float = 1.0               # Σ heatmap of a blob that counts as "the ball was found"
    full_every_s: float = 1.0            # a full-frame window at least this often
    align: int = 8                       # crops start on this grid (the networks' total stride)
    lost_after: int = 2                  # while the tracker has no ball: after this many full windows without
    lost_skip: int = 1                   # one, skip this many windows between searches (0: never); a search
                                         # that finds the ball again searches the skipped windows too

    def __post_init__(self) -> None:
        h, w = self.size
        if h % self.align or w % self.align or h <= 0 or w <= 0:
            raise ValueError(f"crop size must be positive multiples of {self.align}, got {self.size}")
        if 2 * self.margin >= min(h, w) or 2 * self.border >= min(h, w):
            raise ValueError(f"crop margin {self.margin} / border {self.border} leave nothing of {self.size}")


def crop_config(mode: str) -> CropConfig | None:
    """The crop-tracking of ``--crop`` ``auto`` (the default :class:`CropConfig`) or ``off`` (None)."""
    if mode not in CROP_MODES:
        raise ValueError(f"crop must be one of {CROP_MODES}, got {mode!r}")
    return CropConfig() if mode == "auto" else None


def place_crop(expected_net: np.ndarray, grid: tuple[int, int], cfg: CropConfig) -> tuple[int, int] | None:
    """Top-left ``(y0, x0)`` of the crop that holds every expected position ``(K, 2)`` (network px, x y)
    at least ``margin`` inside its inner edges, on the ``align`` grid, within the ``grid (H, W)``; ``None`` if none does
    (the crop would not be smaller than the grid, or the positions spread too far)."""
    (h, w), (gh, gw) = cfg.size, grid
    if h > gh or w > gw or (h, w) == (gh, gw):
        return None
    lo, hi = expected_net.min(axis=0), expected_net.max(axis=0)
    centre = 0.5 * (lo + hi)
    x0 = int(np.clip(np.round((centre[0] - w / 2) / cfg.align) * cfg.align, 0, max(gw - w, 0)))
    y0 = int(np.clip(np.round((centre[1] - h / 2) / cfg.align) * cfg.align, 0, max(gh - h, 0)))
    m = cfg.margin   # only at the crop's inner edges: where the crop ends, the grid ends too
    inside = (lo[0] >= x0 + (m if x0 > 0 else 0) and hi[0] <= x0 + w - (m if x0 + w < gw else 0)
              and lo[1] >= y0 + (m if y0 > 0 else 0) and hi[1] <= y0 + h - (m if y0 + h < gh else 0))
    return (y0, x0) if inside else None


def crop_candidates(cands: list[FrameCandidates], origin: tuple[int, int], map_scale: float,
                    letterbox: Letterbox, cfg: CropConfig) -> tuple[list[FrameCandidates], bool]:
    """Candidates found in a crop's heatmaps (heatmap pixels of the crop) → original-frame pixels.

    Args:
        cands: per frame of the window, candidates in the crop's heatmap pixels.
        origin: ``(y0, x0)`` of the crop in network pixels; map_scale: heatmap px per network px.
        letterbox: the full frame's letterbox (network grid).

    Returns:
        The candidates away from the crop's inner edges (``border``) in original pixels, and whether every
        frame has one scoring ``min_score`` or more (else the window must be re-run on the full frame).
    """
    y0, x0 = origin
    h, w = cfg.size
    out, found = [], True
    for c in cands:
        net = c.xy / map_scale + (x0, y0)
        # the grid's own edges are real edges (the full frame ends there too): only inner edges are distrusted
        ok_x = ((net[:, 0] >= x0 + cfg.border) | (x0 == 0)) & ((net[:, 0] <= x0 + w - cfg.border)
                                                               | (x0 + w >= letterbox.net_w))
        ok_y = ((net[:, 1] >= y0 + cfg.border) | (y0 == 0)) & ((net[:, 1] <= y0 + h - cfg.border)
                                                               | (y0 + h >= letterbox.net_h))
        keep = ok_x & ok_y
        c = c.take(keep)._replace(xy=letterbox.inverse(net[keep]))
        c = c.take(_inside(c.xy, letterbox.src_w, letterbox.src_h))
        found &= bool(np.any(c.score >= cfg.min_score))
        out.append(c)
    return out, found
