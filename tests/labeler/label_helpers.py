"""Helpers shared by the labeler tests: a writable copy of the embedded padel sample clip, and driving a
labeler tab in the browser (wait for its view, click an image pixel, press keys, pick a court point)."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
from conftest import WEBGL_CANVAS, wait_until

from labeler.viewer_common import screen_of_pixel

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "datasets" / "sample" / "padel_sample"


def copy_sample(dst: Path, *, keep_labels: bool = True) -> Path:
    """Copy ``datasets/sample/padel_sample`` (240 frames, 1280×720) to ``dst``; optionally without its labels."""
    shutil.copytree(SAMPLE, dst)
    if not keep_labels:
        for name in ("ball.csv", "inactive_balls.csv", "events.csv", "court_points.csv", "camera.yaml"):
            (dst / name).unlink(missing_ok=True)
    return dst


def ready_view(app, page, known: set[int] = frozenset()):
    """The new tab's view, once its camera is fitted to the canvas and its first frame is shown."""
    wait_until(lambda: set(app.views) - set(known), what="the tab's labeler view")
    view = app.views[max(set(app.views) - set(known))]
    box = page.locator(WEBGL_CANVAS).bounding_box()
    wait_until(lambda: abs(view._aspect - box["width"] / box["height"]) < 1e-3, what="the camera fit to the canvas")
    wait_until(lambda: view.shown >= 0, what="the first frame")
    wait_until(lambda: view.camera_fitted, what="the browser to report the fitted camera "
               f"({view.reported_camera}, {view.fit_distance}, {view._aspect})")
    return view


def point_field(page):
    """The court tab's "point" dropdown in the page."""
    return page.get_by_role("combobox", name="point")


def select_point(page, view, name: str) -> None:
    """Choose the court point ``name`` in the page's dropdown, as an annotator does."""
    point_field(page).click()
    page.get_by_role("option", name=name, exact=True).click()
    wait_until(lambda: view.court_panel.point.value == name, what=f"{name} selected")


def click_pixel(page, view, xy_px) -> None:
    box = page.locator(WEBGL_CANVAS).bounding_box()
    sx, sy = screen_of_pixel(np.asarray(xy_px, float)[None], view.plane, box["width"], box["height"],
                             view.fit_distance)[0]
    page.mouse.click(box["x"] + sx, box["y"] + sy)  # every caller then waits for the click's effect


def press(page, key: str, times: int = 1) -> None:
    for _ in range(times):
        page.keyboard.press(key)
