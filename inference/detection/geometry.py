"""The aspect-preserving resize between original frames and the detectors' input (and heatmap) grid.

A :class:`Letterbox` is one similarity transform ``p_net = s · p_src + t`` (no rotation, equal scale on
both axes), centred so the scaled frame sits in the middle of the network grid with equal padding on
opposite sides. Points use the **pixel-index convention** of ``cv2.warpAffine``: the centre of pixel
``(col, row)`` has coordinates ``(col, row)``. With that convention :meth:`Letterbox.forward` puts a
point exactly where :meth:`Letterbox.warp` moves the image content, so heatmap targets drawn at
``forward(ball_xy)`` line up with the warped frames, and :meth:`Letterbox.inverse` maps heatmap blob
centres back to original-frame pixels. (WASB-SBDT draws its disk targets around
``forward(ball_xy).astype(int)``, a truncation that shifts them by up to one grid pixel; for a
heatmap grid of another size use :meth:`Letterbox.resized`.)

Two scale rules (``mode``):

- ``"contain"`` (default): ``s = min(W_net / W, H_net / H)``; the whole frame is visible, padded on
  one axis.
- ``"wasb"``: WASB-SBDT's ``get_transform`` (centre = image centre, scale = ``max(h, w)`` mapped to the
  network width), i.e. ``s = W_net / max(W, H)``. Portrait or narrower-than-16:9 frames are then
  cropped top and bottom.

For 16:9 frames into the 512×288 grid both rules give ``s = 512 / W``, ``t = 0``: exactly WASB's
matrix, so the published checkpoints see the inputs they were trained on.

Example:
    >>> box = Letterbox(1280, 720)
    >>> box.forward([[640.0, 360.0]]).tolist()
    [[256.0, 144.0]]
    >>> box.inverse(box.forward([[10.0, 20.0]])).round(9).tolist()
    [[10.0, 20.0]]
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

NET_SIZE: tuple[int, int] = (512, 288)
"""Default network input ``(width, height)`` of TrackNetV2, MonoTrack and WASB."""

MODES: tuple[str, ...] = ("contain", "wasb")


@dataclass(frozen=True)
class Letterbox:
    """Similarity transform from a ``src_w × src_h`` frame to a ``net_w × net_h`` grid.

    Attributes:
        src_w, src_h: original frame size in pixels.
        net_w, net_h: network (or heatmap) grid size in pixels; default 512×288.
        mode: ``"contain"`` (scale = min of the two ratios) or ``"wasb"`` (scale = net_w / max(W, H)).
    """

    src_w: int
    src_h: int
    net_w: int = NET_SIZE[0]
    net_h: int = NET_SIZE[1]
    mode: str = "contain"

    def __post_init__(self) -> None:
        for name in ("src_w", "src_h", "net_w", "net_h"):
            if int(getattr(self, name)) <= 0:
                raise ValueError(f"{name} must be a positive pixel count, got {getattr(self, name)}")
        if self.mode not in MODES:
            raise ValueError(f"unknown letterbox mode {self.mode!r}; choose one of {MODES}")

    # ---------------------------------------------------------------------------------- parameters
    @property
    def scale(self) -> float:
        """Network pixels per original pixel."""
        if self.mode == "wasb":
            return self.net_w / max(self.src_w, self.src_h)
        return min(self.net_w / self.src_w, self.net_h / self.src_h)

    @property
    def offset(self) -> tuple[float, float]:
        """``(tx, ty)``: where the original origin lands on the grid (the padding, centred)."""
        s = self.scale
        return (self.net_w - s * self.src_w) / 2.0, (self.net_h - s * self.src_h) / 2.0

    @property
    def matrix(self) -> np.ndarray:
        """``(2, 3)`` affine matrix original → network, for ``cv2.warpAffine``."""
        s, (tx, ty) = self.scale, self.offset
        return np.array([[s, 0.0, tx], [0.0, s, ty]], dtype=np.float64)

    @property
    def inverse_matrix(self) -> np.ndarray:
        """``(2, 3)`` affine matrix network → original."""
        s, (tx, ty) = self.scale, self.offset
        return np.array([[1.0 / s, 0.0, -tx / s], [0.0, 1.0 / s, -ty / s]], dtype=np.float64)

    @property
    def content_box(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)`` network-pixel bounds of the original frame (outside is padding)."""
        s, (tx, ty) = self.scale, self.offset
        return tx, ty, tx + s * self.src_w, ty + s * self.src_h

    def resized(self, net_w: int, net_h: int) -> Letterbox:
        """The same rule for another grid, e.g. a half-resolution heatmap; ``self`` if unchanged."""
        if (net_w, net_h) == (self.net_w, self.net_h):
            return self
        return Letterbox(self.src_w, self.src_h, net_w, net_h, self.mode)

    # ------------------------------------------------------------------------------------- points
    def forward(self, points) -> np.ndarray:
        """Original-frame pixels ``(..., 2)`` → network pixels ``(..., 2)`` (float64)."""
        s, (tx, ty) = self.scale, self.offset
        return _apply(points, s, tx, ty)

    def inverse(self, points) -> np.ndarray:
        """Network pixels ``(..., 2)`` → original-frame pixels ``(..., 2)`` (float64)."""
        s, (tx, ty) = self.scale, self.offset
        return _apply(points, 1.0 / s, -tx / s, -ty / s)

    # ------------------------------------------------------------------------------------- images
    def warp(self, image: np.ndarray, interpolation: int = cv2.INTER_LINEAR, border_value: float = 0.0
             ) -> np.ndarray:
        """Resample ``image (src_h, src_w[, C])`` onto the grid: ``(net_h, net_w[, C])``, padding filled.

        Uses ``cv2.warpAffine`` with bilinear sampling, as WASB-SBDT does for its inputs.
        """
        self._check_shape(image, self.src_h, self.src_w, "image")
        return cv2.warpAffine(image, self.matrix, (self.net_w, self.net_h), flags=interpolation,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=border_value)

    def unwarp(self, image: np.ndarray, interpolation: int = cv2.INTER_LINEAR, border_value: float = 0.0
               ) -> np.ndarray:
        """Resample a grid image ``(net_h, net_w[, C])`` (e.g. a heatmap) back to ``(src_h, src_w[, C])``."""
        self._check_shape(image, self.net_h, self.net_w, "grid image")
        return cv2.warpAffine(image, self.inverse_matrix, (self.src_w, self.src_h), flags=interpolation,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=border_value)

    @staticmethod
    def _check_shape(image: np.ndarray, h: int, w: int, what: str) -> None:
        if image.ndim not in (2, 3) or image.shape[:2] != (h, w):
            raise ValueError(f"{what} must have shape ({h}, {w}[, C]), got {image.shape}")


def _apply(points, s: float, tx: float, ty: float) -> np.ndarray:
    """``s · p + (tx, ty)`` for points ``(..., 2)``."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape[-1:] != (2,):
        raise ValueError(f"points must have shape (..., 2), got {pts.shape}")
    return pts * s + np.array([tx, ty])
