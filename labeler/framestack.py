"""The frame on screen, with the next frames already in the browser: a stack of image planes.

Stepping by replacing one image's JPEG makes the browser decode and upload it after the key press (≈0.5 s
with software WebGL), so the status line runs ahead of the picture. Here ``slots`` image planes share the
frame's place: the shown frame's plane at z = 0, the prefetched frames' planes a hair behind it and shrunk to
a speck (:data:`BACK_SCALE`), where the browser draws them (so it has decoded and uploaded their textures)
but the front plane hides them and they cost almost no fill (software WebGL pays per pixel drawn). Showing
a prefetched frame only moves and scales two planes. Every frame carries its number burned into the picture
(:func:`labeler.frames.stamp_frame_number`), so the number on screen always belongs to the image shown.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Iterable

import numpy as np

from .viewer_common import ImagePlane, set_image_jpeg

BACK_Z = 0.0005
"""Scene depth between stacked planes (the overlays lie at z < 0, in front of every plane)."""
BACK_SCALE = 0.02
"""Scale of the planes behind the shown one: drawn (texture uploaded), but a few pixels on screen."""


class FrameStack:
    """``slots`` image planes of one client's scene showing one frame and holding the next ones.

    Args:
        scene: the client's viser scene.
        plane: the frame's geometry.
        slots: planes (1 = no prefetch in the browser: every step sends and decodes a JPEG).
        on_click: called with viser's click event on the shown frame (one call per click).
    """

    def __init__(self, scene, plane: ImagePlane, slots: int, on_click: Callable):
        self.plane = plane
        self.slots = max(1, int(slots))
        self._on_click = on_click
        self._last_click: tuple | None = None
        self.nodes = []
        for i in range(self.slots):
            node = scene.add_image(f"/frames/{i}", np.zeros((8, 8, 3), np.uint8), render_width=plane.render_width,
                                   render_height=plane.render_height, format="jpeg",
                                   position=(0.0, 0.0, BACK_Z * (i + 1)), scale=BACK_SCALE)
            node.on_click(self._click)
            node.on_drag("left")(lambda ev: None)  # a left-drag on the frame must not orbit the camera
            self.nodes.append(node)
        self.frame_of = [-1] * self.slots
        self._used = [0.0] * self.slots
        self.front = -1

    @property
    def shown(self) -> int:
        """The frame of the front plane (-1 before the first)."""
        return self.frame_of[self.front] if self.front >= 0 else -1

    def handles(self) -> list:
        return list(self.nodes)

    def _click(self, ev) -> None:
        key = (tuple(np.round(ev.ray_origin, 6)), tuple(np.round(ev.ray_direction, 6)))
        now = time.monotonic()
        if self._last_click is not None and self._last_click[0] == key and now - self._last_click[1] < 0.2:
            return  # the planes behind report the same click
        self._last_click = (key, now)
        self._on_click(ev)

    def _slot(self, frame: int) -> int | None:
        return self.frame_of.index(frame) if frame in self.frame_of else None

    def _victim(self, keep: set[int]) -> int | None:
        """The least recently used plane whose frame is not in ``keep`` (never the front one)."""
        cands = [i for i in range(self.slots) if i != self.front and self.frame_of[i] not in keep]
        if not cands:
            return None if self.slots > 1 else 0
        return min(cands, key=lambda i: self._used[i])

    def show(self, frame: int, jpeg: Callable[[int], bytes]) -> None:
        """Bring ``frame`` to the front (call inside the client's ``atomic()``); ``jpeg(i)`` gives frame bytes."""
        i = self._slot(frame)
        if i is None:
            i = self._victim({frame})
            if i is None:
                i = self.front
            set_image_jpeg(self.nodes[i], jpeg(frame))
            self.frame_of[i] = frame
        self._used[i] = time.monotonic()
        if i != self.front:
            if self.front >= 0:
                self.nodes[self.front].position = (0.0, 0.0, BACK_Z * (self.front + 1))
                self.nodes[self.front].scale = BACK_SCALE
            self.nodes[i].position = (0.0, 0.0, 0.0)
            self.nodes[i].scale = 1.0
            self.front = i

    def preload(self, frames: Iterable[int], jpeg: Callable[[int], bytes | None]) -> list[int]:
        """Put ``frames`` (most wanted first) into the planes behind; ``jpeg(i)`` None = not ready yet.

        Returns the frames still missing (not ready, or no plane left).
        """
        wanted = [f for f in frames if f >= 0]
        keep = set(wanted) | {self.shown}
        missing = []
        for f in wanted[: self.slots - 1]:
            if self._slot(f) is not None:
                continue
            data = jpeg(f)
            i = self._victim(keep) if data is not None else None
            if data is None or i is None:
                missing.append(f)
                continue
            set_image_jpeg(self.nodes[i], data)
            self.frame_of[i] = f
            self._used[i] = time.monotonic()
        return missing
