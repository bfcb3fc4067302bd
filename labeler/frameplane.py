"""The frame's image node in viser's scene: shows the frame until the page's player takes over, then takes the clicks.

Before the page's frame player (:mod:`labeler.player_js`) has attached, the server shows a frame by
replacing the node's JPEG (the browser decodes and uploads it after the key). Once attached, the page draws
the frames into a canvas of its own placed exactly under this node's place on screen, and stops drawing the
node; the node stays in the scene for the clicks, and the server never touches its picture again. Every
frame carries its number (and its binary code) burned into the picture
(:func:`labeler.frames.stamp_frame_number`), so the number on screen always belongs to the image shown.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .viewer_common import ImagePlane, set_image_jpeg

NODE = "/frames/0"
"""Scene name of the frame's image node (the page's player finds it by this name)."""


class FramePlane:
    """The image node of one client's scene showing the frame.

    Args:
        scene: the client's viser scene.
        plane: the frame's geometry.
        on_click: called with viser's click event on the frame.
    """

    def __init__(self, scene, plane: ImagePlane, on_click: Callable):
        self.plane = plane
        self.node = scene.add_image(NODE, np.zeros((8, 8, 3), np.uint8), render_width=plane.render_width,
                                    render_height=plane.render_height, format="jpeg", position=(0.0, 0.0, 0.0),
                                    cast_shadow=False, receive_shadow=False)
        self.node.on_click(on_click)
        self.node.on_drag("left")(lambda ev: None)  # a left-drag on the frame must not orbit the camera
        self.shown = -1

    def show(self, frame: int, jpeg: Callable[[int], bytes]) -> None:
        """Replace the node's picture by ``frame`` (call inside the client's ``atomic()``)."""
        if frame != self.shown:
            set_image_jpeg(self.node, jpeg(frame))
            self.shown = frame

    def handles(self) -> list:
        return [self.node]
