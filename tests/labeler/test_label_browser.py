"""End to end in headless Chromium: click the ball, press event keys, place court points, reload (back to the
frame and mode), two tabs, the page's frame player (step, hold to play, Space)."""
from __future__ import annotations

import numpy as np
import pytest
import yaml
from conftest import WEBGL_CANVAS, wait_for_canvas, wait_until
from label_helpers import SAMPLE, click_pixel, copy_sample, press, ready_view, select_point

from inference.camera import Camera
from inference.clipio import Clip
from labeler.app import LabelerApp
from labeler.frames import code_cell_centres, read_frame_code
from labeler.player_js import PROBE_JS
from labeler.viewer_common import screen_of_pixel

pytestmark = pytest.mark.browser

COURT_POINTS = ["far_left", "far_right", "near_service_left", "near_service_right", "net_post_left_top",
                "net_post_right_top", "glass_far_left_top"]


@pytest.fixture
def app_and_clip(tmp_path, port):
    clip = copy_sample(tmp_path / "clip", keep_labels=False)
    app = LabelerApp(clip, port=port)
    yield app, clip
    app.stop()


def test_label_ball_event_court_points_and_reload(app_and_clip, viser_page):
    app, clip_dir = app_and_clip
    clip = Clip(clip_dir)
    size = np.array([1280.0, 720.0])
    gt_ball = Clip(SAMPLE).read_ball()
    page = viser_page(app.server.get_port())
    view = ready_view(app, page)

    press(page, "l", 3)  # next frame ×3 (hotkey L; auto-repeat coalesces)
    wait_until(lambda: view.shown == 3, what="frame 3 after three L presses")
    target = gt_ball.xy[3] * size
    click_pixel(page, view, target)
    wait_until(lambda: clip.ball_path.exists(), what="ball.csv")
    saved = clip.read_ball()
    assert saved.frame.tolist() == [3] and saved.visibility.tolist() == [1]
    assert np.abs(saved.xy[0] * size - target).max() < 1.0, (saved.xy[0] * size, target)

    press(page, "1")  # first event of the padel vocabulary
    wait_until(lambda: clip.events_path.exists(), what="events.csv")
    events = clip.read_events()
    assert events.frame.tolist() == [3] and events.event.tolist() == [view.session.event_labels[0]] == ["ground"]

    press(page, "m", 2)  # ball → stationary → court
    wait_until(lambda: view.mode == "court", what="court mode")
    court_tab = page.get_by_role("tab", name="Court")       # the panel's tab followed the mode (no click)
    wait_until(lambda: court_tab.get_attribute("aria-selected") == "true", what="the Court tab shown by M M")
    gt_points = Clip(SAMPLE).read_court_points().as_dict()
    for name in COURT_POINTS:
        select_point(page, view, name)
        n_before = len(view.session.points)
        click_pixel(page, view, np.array(gt_points[name]) * size)
        wait_until(lambda: len(view.session.points) == n_before + 1, what=f"court point {name}")
    wait_until(lambda: clip.court_points_path.exists() and set(clip.read_court_points().names) == set(COURT_POINTS),
               what="court_points.csv with every clicked point")  # saved after the session counts them
    points = clip.read_court_points()
    for name, xy in points.as_dict().items():
        assert np.abs((np.array(xy) - gt_points[name]) * size).max() < 1.0, name
    # camera.yaml is written from 6 points on, then again with the 7th
    wait_until(lambda: clip.camera_path.exists()
               and set(yaml.safe_load(clip.camera_path.read_text())["points_used"]) == set(COURT_POINTS),
               what="camera.yaml calibrated from all 7 points")
    cam = Camera.load(clip.camera_path)
    assert cam.rms_px is not None and cam.rms_px < 2.0
    assert np.linalg.norm(cam.centre - Camera.load(clip_dir / "gt" / "camera.yaml").centre) < 0.5

    old = set(app.views)
    page.reload(wait_until="load")
    wait_for_canvas(page)
    view2 = ready_view(app, page, known=old)
    assert view2 is not view and view2.session.summary()["court_points"] == 7
    # back where the page was: frame 3, court mode (it opened on frame 0 in ball mode)
    wait_until(lambda: view2.shown == 3 and view2.mode == "court", what="frame 3 in court mode after the reload")
    wait_until(lambda: "where this page was left" in page.inner_text("body"), what="the reload's notice")
    wait_until(lambda: page.get_by_role("tab", name="Court").get_attribute("aria-selected") == "true",
               what="the Court tab shown again after the reload")
    status = "labelled 1 (0.4 %) · events 1 · still balls 0 · court points 7"
    wait_until(lambda: status in page.inner_text("body"), what="the same counts after a reload")
    assert view2.session.calibration is not None  # the court model is drawn again from the saved points


def test_two_tabs_on_one_clip_keep_both_edits(app_and_clip, viser_page):
    app, clip_dir = app_and_clip
    clip = Clip(clip_dir)
    page_a = viser_page(app.server.get_port())
    view_a = ready_view(app, page_a)
    page_b = viser_page(app.server.get_port())
    view_b = ready_view(app, page_b, known={id_ for id_, v in app.views.items() if v is view_a})
    click_pixel(page_a, view_a, (400.0, 300.0))  # both tabs on frame 0 … then B on frame 1
    wait_until(lambda: clip.ball_path.exists(), what="tab A's ball.csv")
    press(page_b, "l")
    wait_until(lambda: view_b.shown == 1, what="tab B on frame 1")
    click_pixel(page_b, view_b, (500.0, 320.0))
    wait_until(lambda: len(clip.read_ball()) == 2, what="both tabs' rows in ball.csv")
    assert clip.read_ball().frame.tolist() == [0, 1]
    # B picked A's row up (idle re-read) or merged it when saving; either way it says so
    wait_until(lambda: "saved by another tab" in page_b.inner_text("body"), what="tab B telling it took A's row")
    wait_until(lambda: 1 in view_a.session.ball, what="tab A picking up B's row")


def test_page_player_steps_plays_while_held_and_keeps_the_colours(app_and_clip, viser_page):
    """J/L step in the page (the frame code read from the canvas names the new frame, and the server hears of
    it); the page's own texture shows frame 0 as viser's did; holding L plays, releasing stops; Space plays
    and pauses."""
    app, _clip = app_and_clip
    page = viser_page(app.server.get_port())
    view = ready_view(app, page)
    wait_until(lambda: view.paged, what="the page's frame player")
    box = page.locator(WEBGL_CANVAS).bounding_box()
    w, h = view.plane.width, view.plane.height
    cells = screen_of_pixel(code_cell_centres(w), view.plane, box["width"], box["height"], view.fit_distance)
    grid_px = np.array([[x, y] for x in (0.2, 0.4, 0.6, 0.8) for y in (0.3, 0.5, 0.7)]) * [w, h]
    grid = screen_of_pixel(grid_px, view.plane, box["width"], box["height"], view.fit_distance)
    n_bits = len(cells)

    def read() -> tuple[int, np.ndarray]:
        levels = page.evaluate(PROBE_JS, np.concatenate([cells, grid]).tolist())
        return read_frame_code(levels[:n_bits]), np.asarray(levels[n_bits:])

    wait_until(lambda: read()[0] == 0, what="frame 0's code on the canvas")
    viser_picture = read()[1]                   # frame 0 as viser's own image node drew it
    press(page, "l")
    wait_until(lambda: read()[0] == 1 and view.shown == 1, what="frame 1 on the canvas and at the server")
    press(page, "Shift+L")
    wait_until(lambda: read()[0] == 11 and view.shown == 11, what="frame 11 after Shift+L")
    press(page, "Shift+J")
    press(page, "j")
    wait_until(lambda: read()[0] == 0 and view.shown == 0, what="back on frame 0")
    assert np.abs(read()[1] - viser_picture).max() < 12  # the page's texture: same picture, same colours

    def ball_layer_shown() -> bool:
        handle = view.overlay._handles.get("/overlay/ball")
        return handle is not None and handle.visible

    with view.lock:                             # a labelled ball on every frame the hold may reach
        for f in range(view.session.n_frames):
            view.session.set_ball(f, (0.5, 0.5))
    view.request(overlay=True)
    wait_until(ball_layer_shown, what="frame 0's ball overlay")
    page.keyboard.down("l")                     # held: plays at the clip's rate
    wait_until(lambda: read()[0] >= 12, what="frames advancing while L is held")
    # while playing, the overlays of one frame are hidden (drawn twice a second they would sit on other
    # frames, and every draw re-renders the 3D scene)
    wait_until(lambda: view.playing and not ball_layer_shown(), what="the ball overlay hidden while playing")
    page.keyboard.up("l")
    wait_until(lambda: not view.playing and view.shown == read()[0], what="playing to stop on release")
    stopped = read()[0]
    assert stopped >= 12
    wait_until(ball_layer_shown, what=f"the ball overlay of frame {stopped} (where it stopped) after the stop")
    press(page, "Shift+J")                      # a step from where it stopped
    wait_until(lambda: read()[0] == stopped - 10 and view.shown == stopped - 10, what="Shift+J after the hold")
    stopped -= 10

    press(page, " ")                            # Space: plays until Space again
    wait_until(lambda: view.playing and read()[0] >= stopped + 5, what="Space to play")
    press(page, " ")
    wait_until(lambda: not view.playing and view.shown == read()[0], what="Space to pause")
