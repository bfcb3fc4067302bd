"""The browser-test setup itself: Debian Chromium renders a viser scene and its clicks reach Python."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import WEBGL_CANVAS, wait_until

pytestmark = pytest.mark.browser


def test_viser_image_plane_renders_and_click_reaches_python(viser_page, port):
    import cv2
    import viser

    server = viser.ViserServer(host="127.0.0.1", port=port, verbose=False)
    try:
        server.gui.configure_theme(show_logo=False)
        server.gui.main_panel.dock_right()
        img = np.zeros((90, 160, 3), np.uint8)
        img[:] = (200, 40, 160)  # magenta-ish, not a viser UI colour
        plane = server.scene.add_image("/frame", img, render_width=1.6, render_height=0.9, format="png")
        clicks = []
        plane.on_click(lambda ev: clicks.append(ev))
        connected = []
        server.on_client_connect(lambda c: connected.append(c))

        page = viser_page(port)
        wait_until(lambda: bool(connected), what="the browser to connect")
        client = connected[0]
        client.camera.position = (0.0, 0.0, -2.0)
        client.camera.look_at = (0.0, 0.0, 0.0)
        client.camera.up_direction = (0.0, -1.0, 0.0)
        box = page.locator(WEBGL_CANVAS).bounding_box()

        def centre_pixel() -> np.ndarray:
            shot = cv2.imdecode(np.frombuffer(page.screenshot(), np.uint8), cv2.IMREAD_COLOR)
            cx, cy = int(box["x"] + box["width"] / 2), int(box["y"] + box["height"] / 2)
            return shot[cy, cx][::-1].astype(int)  # BGR -> RGB

        wait_until(lambda: np.abs(centre_pixel() - (200, 40, 160)).max() < 30, what="the image plane to render")
        page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        wait_until(lambda: bool(clicks), what="the click callback")
        ev = clicks[0]
        assert np.asarray(ev.ray_direction)[2] > 0.5  # a ray from the camera at -z towards the plane
    finally:
        server.stop()
