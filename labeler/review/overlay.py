"""The video frame with the reconstruction drawn over it (OpenCV), to judge the fit by eye. UI-free.

Drawn: the court's lines (every layer of the court YAML) and the 3D ball reprojected through the clip's
camera, the ball's recent 3D path, and the 2D ball of ball.csv as a ring (where they differ, the fit is off).

Example:
    >>> img = draw_overlay(frame, camera, court, ball_xyz=data.ball_at(100), observed_px=data.uv[100])
"""
from __future__ import annotations

import cv2
import numpy as np

from inference.camera import Camera
from inference.court import Court

from .scene import BALL_RGB, LINE_RGB

OBSERVED_RGB = (255, 60, 200)
"""Ring around the 2D ball of ball.csv."""
SUBDIVIDE = 16
"""Court lines are drawn as this many pieces each, so lens distortion bends them."""


def project_segments(camera: Camera, segments: np.ndarray, n: int = SUBDIVIDE) -> np.ndarray:
    """(L, 2, 3) 3D segments → (L, n + 1, 2) pixel polylines (NaN where behind the camera)."""
    segs = np.asarray(segments, float).reshape(-1, 2, 3)
    t = np.linspace(0.0, 1.0, n + 1)[None, :, None]
    pts = segs[:, :1] + t * (segs[:, 1:] - segs[:, :1])
    return camera.project(pts.reshape(-1, 3)).reshape(len(segs), n + 1, 2)


def _pt(p: np.ndarray, s: float) -> tuple[int, int]:
    return int(round(p[0] * s)), int(round(p[1] * s))


def draw_overlay(frame: np.ndarray, camera: Camera, court: Court, *, ball_xyz=None, trail_xyz=None,
                 observed_px=None, out_width: int | None = 640, text: str = "") -> np.ndarray:
    """Draw the reprojected court and ball over an RGB frame.

    Args:
        frame: (H, W, 3) uint8 RGB (not modified).
        camera: the clip's camera (pixels of ``camera.image_size``; rescaled to the frame's size).
        court: its ``lines`` are drawn.
        ball_xyz: (3,) the 3D ball (NaN or None: not drawn); trail_xyz: (K, 3) its recent path.
        observed_px: (2,) the 2D ball in camera pixels (NaN or None: not drawn).
        out_width: resize the result to this width first (None keeps the frame's size).
        text: a caption in the top-left corner.
    Returns:
        (h, w, 3) uint8 RGB.
    """
    h0, w0 = frame.shape[:2]
    if out_width and out_width != w0:
        h = int(round(h0 * out_width / w0))
        img = cv2.resize(frame, (out_width, h), interpolation=cv2.INTER_AREA)
    else:
        img = np.array(frame, copy=True)
    s = img.shape[1] / float(camera.image_size[0])  # camera pixels → output pixels
    thick = max(1, int(round(2 * img.shape[1] / 1280)))
    for layer, segs in court.lines.items():
        color = LINE_RGB.get(layer, (255, 255, 255))
        for poly in project_segments(camera, segs):
            ok = np.isfinite(poly).all(axis=1)
            pts = np.round(poly[ok] * s).astype(np.int32)
            if len(pts) >= 2:
                cv2.polylines(img, [pts], False, color, thick, cv2.LINE_AA)
    if trail_xyz is not None and len(trail_xyz) >= 2:
        tr = camera.project(np.asarray(trail_xyz, float))
        tr = tr[np.isfinite(tr).all(axis=1)]
        if len(tr) >= 2:
            cv2.polylines(img, [np.round(tr * s).astype(np.int32)], False, BALL_RGB, thick, cv2.LINE_AA)
    if observed_px is not None and np.isfinite(observed_px).all():
        cv2.circle(img, _pt(np.asarray(observed_px, float), s), max(6, 5 * thick), OBSERVED_RGB, thick, cv2.LINE_AA)
    if ball_xyz is not None and np.isfinite(ball_xyz).all():
        c = camera.project(np.asarray(ball_xyz, float))[0]
        if np.isfinite(c).all():
            edge = camera.project(np.asarray(ball_xyz, float) + [0, 0, court.ball.radius])[0]
            r = max(3, int(round(np.linalg.norm(edge - c) * s)) if np.isfinite(edge).all() else 3)
            cv2.circle(img, _pt(c, s), r, BALL_RGB, -1, cv2.LINE_AA)
            cv2.circle(img, _pt(c, s), r, (0, 0, 0), 1, cv2.LINE_AA)
    if text:
        cv2.putText(img, text, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(img, text, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def placeholder_frame(camera: Camera, width: int = 640) -> np.ndarray:
    """A grey frame of the camera's aspect, for clips whose video cannot be read."""
    w, h = camera.image_size
    return np.full((int(round(h * width / w)), width, 3), 60, np.uint8)
