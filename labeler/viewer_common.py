"""Small viser helpers shared by the labeler and the 3D review: theme, image-plane geometry, camera fitting.

The frame is an image plane in the scene's local XY at z = 0 (viser's ``add_image``): image u runs along
+x and v along +y (downwards), centred on the origin. A camera on -z looking at +z with ``up = (0, -1, 0)``
shows it upright. Clicks on the plane arrive as rays; :meth:`ImagePlane.ray_to_pixel` intersects them with
z = 0, which is pixel-accurate at any zoom (a scene-level click, by contrast, carries viser's half-CSS-pixel
pointer offset).
"""
from __future__ import annotations

import html
import math
import re
from dataclasses import dataclass

import numpy as np

DEFAULT_FOV_DEG = 50.0
"""Vertical field of view of the fitted camera."""


_MARKDOWN_PUNCTUATION = re.compile(r"([\\`*_{}\[\]()+\-.!|~])")


def md_escape(text: object) -> str:
    """Text from files or folder names made inert for viser's Markdown (which renders raw HTML).

    Markdown punctuation is backslash-escaped (no links, emphasis or table cells from the text), then
    ``& < >`` become entities and ``#`` too, so ``<iframe srcdoc=…>`` shows as text and runs nothing.
    """
    escaped = _MARKDOWN_PUNCTUATION.sub(r"\\\1", str(text))
    return html.escape(escaped, quote=False).replace("#", "&#35;")


def setup_server(server, *, dark: bool = False) -> None:
    """Theme for rally3d viewers: no viser logo (it covers the canvas corner), GUI docked on the right."""
    server.gui.configure_theme(show_logo=False, dark_mode=dark, control_width="large", show_share_button=False)
    server.gui.main_panel.dock_right()


@dataclass(frozen=True)
class ImagePlane:
    """Geometry of a ``width × height`` pixel image drawn as a plane ``render_height`` units tall.

    Pixel ``(x_px, y_px)`` (pixel centres at +0.5, the OpenCV convention for continuous coordinates)
    lies at scene ``((x_px / W - 0.5) · rw, (y_px / H - 0.5) · rh, 0)``.
    """

    width: int
    height: int
    render_height: float = 1.0

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0 or not self.render_height > 0:
            raise ValueError(f"image plane needs positive sizes, got {self.width}×{self.height}, "
                             f"render_height={self.render_height}")

    @property
    def render_width(self) -> float:
        return self.render_height * self.width / self.height

    def pixel_to_scene(self, xy_px: np.ndarray, z: float = 0.0) -> np.ndarray:
        """``(N, 2)`` pixels → ``(N, 3)`` scene points on the plane (offset ``z`` towards the camera if < 0)."""
        xy = np.atleast_2d(np.asarray(xy_px, dtype=float))
        out = np.empty((len(xy), 3))
        out[:, 0] = (xy[:, 0] / self.width - 0.5) * self.render_width
        out[:, 1] = (xy[:, 1] / self.height - 0.5) * self.render_height
        out[:, 2] = z
        return out

    def scene_to_pixel(self, xyz: np.ndarray) -> np.ndarray:
        """``(N, ≥2)`` scene points on the plane → ``(N, 2)`` pixels."""
        p = np.atleast_2d(np.asarray(xyz, dtype=float))
        return np.stack([(p[:, 0] / self.render_width + 0.5) * self.width,
                         (p[:, 1] / self.render_height + 0.5) * self.height], axis=1)

    def ray_to_pixel(self, origin, direction) -> tuple[float, float] | None:
        """Intersect a click ray with the plane z = 0; ``(x_px, y_px)`` or None when it misses the image."""
        o = np.asarray(origin, dtype=float).reshape(3)
        d = np.asarray(direction, dtype=float).reshape(3)
        if abs(d[2]) < 1e-12:
            return None
        s = -o[2] / d[2]
        if s <= 0:
            return None
        x, y = self.scene_to_pixel(o + s * d)[0]
        if not (0.0 <= x <= self.width and 0.0 <= y <= self.height):
            return None
        return float(x), float(y)


def fit_distance(plane: ImagePlane, aspect: float, fov_deg: float = DEFAULT_FOV_DEG, margin: float = 1.0) -> float:
    """Camera distance at which the whole plane fits a canvas of ``aspect`` = width / height."""
    t = math.tan(math.radians(fov_deg) / 2)
    aspect = aspect if aspect and math.isfinite(aspect) and aspect > 0 else 16 / 9
    return margin * max(plane.render_height / (2 * t), plane.render_width / (2 * t * aspect))


def fit_camera(client, plane: ImagePlane, fov_deg: float = DEFAULT_FOV_DEG, margin: float = 1.0,
               aspect: float | None = None) -> float:
    """Point ``client``'s camera at the plane so it fills the canvas; returns the distance used.

    The camera sits on -z looking at +z with ``up = (0, -1, 0)``, so the image is upright and unmirrored.
    """
    if aspect is None:
        aspect = float(getattr(client.camera, "aspect", 0.0) or 0.0)
    d = fit_distance(plane, aspect, fov_deg, margin)
    with client.atomic():  # order matters: position, then look_at, then up (up first leaves a blank view)
        client.camera.fov = math.radians(fov_deg)
        client.camera.position = (0.0, 0.0, -d)
        client.camera.look_at = (0.0, 0.0, 0.0)
        client.camera.up_direction = (0.0, -1.0, 0.0)
    return d


def screen_of_pixel(xy_px, plane: ImagePlane, canvas_w: float, canvas_h: float, distance: float,
                    fov_deg: float = DEFAULT_FOV_DEG) -> np.ndarray:
    """Where image pixel(s) appear on a canvas (CSS px from its top-left) under :func:`fit_camera`'s view.

    Used by browser tests and benchmarks to click a known pixel.
    """
    f = (canvas_h / 2) / math.tan(math.radians(fov_deg) / 2)
    p = plane.pixel_to_scene(xy_px)
    sx = canvas_w / 2 + p[:, 0] * f / distance
    sy = canvas_h / 2 + p[:, 1] * f / distance
    return np.stack([sx, sy], axis=1)


def encode_jpeg(rgb: np.ndarray, quality: int = 85) -> bytes:
    """``(H, W, 3) uint8`` RGB → JPEG bytes (OpenCV)."""
    import cv2

    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(rgb[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return buf.tobytes()


def set_image_jpeg(handle, data: bytes) -> None:
    """Replace an image node's content with already-encoded JPEG bytes (no re-encoding in viser)."""
    handle._format = "jpeg"
    handle._data = data


def set_slider_marks(handle, marks) -> None:
    """Replace a slider's marks (``[(value, label), ...]``; label may be empty); nothing is sent if unchanged."""
    from viser._messages import GuiSliderMark

    new = tuple(GuiSliderMark(value=float(v), label=(str(lab) or None)) for v, lab in marks) or None
    if getattr(handle, "_marks", None) != new:
        handle._marks = new


def boxes_overlap(a, b) -> bool:
    """Whether two screen or image boxes ``(x0, y0, x1, y1)`` overlap (touching edges do not)."""
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]
