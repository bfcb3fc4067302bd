"""Labeler guards in headless Chromium, as an annotator hits them: the keyboard leaving fields, the court
dropdown by keyboard, interpolation that stays inside one flight, a bad file and a hostile clip name shown in
the page, and undo in two tabs."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import wait_until
from label_helpers import SAMPLE, click_pixel, copy_sample, press, ready_view

from inference.clipio import Clip
from labeler.app import LabelerApp

pytestmark = pytest.mark.browser

XSS_NAME = '<img src=x onerror="window.__pwned=1">'
"""A clip folder name that runs script wherever it is put into the page as HTML."""


@pytest.fixture
def labeler(port):
    apps = []

    def start(target):
        apps.append(LabelerApp(target, port=port))
        return apps[-1]

    yield start
    for app in apps:
        app.stop()


def body(page) -> str:
    return page.inner_text("body")


def test_keyboard_leaves_fields_picks_typed_point_and_interpolates_inside_one_flight(labeler, tmp_path, viser_page):
    clip_dir = copy_sample(tmp_path / "clip", keep_labels=False)
    # keyframes 0/5/10 (occluded), an event at 15, a keyframe at 20 and the next one 100 frames later
    (clip_dir / "ball.csv").write_text("frame,visibility,x,y\n0,3,0.1,0.1\n5,3,0.2,0.3\n10,3,0.3,0.5\n"
                                       "20,1,0.5,0.3\n120,1,0.9,0.9\n")
    (clip_dir / "events.csv").write_text("frame,event\n15,ground\n")
    clip = Clip(clip_dir)
    app = labeler(clip_dir)
    page = viser_page(app.server.get_port())
    view = ready_view(app, page)

    # I proposes only inside the flight 0–10; Shift+Y on frame 0 accepts that flight only
    press(page, "i")
    wait_until(lambda: "not filled" in body(page), what="the interpolation notice naming the skipped gaps")
    assert set(view.session.ball_proposals) == set(range(1, 5)) | set(range(6, 10))
    assert "event @15" in body(page) and "100 frames apart" in body(page)
    press(page, "Shift+Y")
    wait_until(lambda: len(clip.read_ball()) == 5 + 8, what="the accepted flight in ball.csv")
    ball = clip.read_ball()
    frames = set(ball.frame.tolist())
    assert frames == set(range(0, 11)) | {20, 120}  # nothing across the event (11–19) or the gap (21–119)
    filled = np.isin(ball.frame, [f for f in range(11) if f % 5])
    assert set(ball.visibility[filled].tolist()) == {1}  # filled rows are "visible", not the keyframes' 3

    # go to 50 + Enter leaves the field: the next "1" is the event hotkey, not a digit typed into the field
    field = page.get_by_label("go to")
    field.click()
    field.fill("50")
    field.press("Enter")
    wait_until(lambda: view.shown == 50, what="frame 50 after go to")
    wait_until(lambda: page.evaluate("document.activeElement === document.body || "
                                     "document.activeElement.tagName !== 'INPUT'"), what="the field left")
    press(page, "1")
    wait_until(lambda: 50 in view.session.events, what="event hotkey on frame 50")
    assert view.session.events[50] == "ground" and view.shown == 50 and int(view.nav.goto.value) == 50

    # ? opens the cheat-sheet with this court's event names
    press(page, "?")
    wait_until(lambda: "this cheat-sheet" in body(page), what="the shortcut cheat-sheet")
    assert "event glass_left" in body(page) or "event ground" in body(page)
    page.get_by_role("button", name="close", exact=True).click()

    # court point by keyboard: type part of a name + Enter selects it; the next click is saved under it
    press(page, "m", 2)
    wait_until(lambda: view.mode == "court", what="court mode")
    # the panel's tab follows the mode from the server: wait for it rather than race it with a click
    wait_until(lambda: page.get_by_role("tab", name="Court").get_attribute("aria-selected") == "true",
               what="the Court tab shown by M M")
    combo = page.get_by_role("combobox", name="point")
    combo.click()
    combo.press_sequentially("near_service_ri")
    combo.press("Enter")
    wait_until(lambda: view.court_panel.point.value == "near_service_right", what="the typed point selected")
    gt = Clip(SAMPLE).read_court_points().as_dict()["near_service_right"]
    click_pixel(page, view, np.array(gt) * [1280.0, 720.0])
    wait_until(lambda: clip.court_points_path.exists(), what="court_points.csv")
    assert clip.read_court_points().names == ["near_service_right"]
    # the point's name is drawn next to it, and the dropdown moved on to another point
    wait_until(lambda: view.court_panel.point.value != "near_service_right", what="the next point chosen")


def test_bad_file_is_shown_in_the_page_keeps_the_clip_and_a_hostile_name_stays_text(labeler, tmp_path,
                                                                                     viser_page):
    data = tmp_path / "data"
    copy_sample(data / "0_good", keep_labels=False)
    bad = copy_sample(data / XSS_NAME, keep_labels=False)
    text = "frame,visibility,x,y\n0,1,0.5,0.5\n1,1,1.2,0.5\n2,1,0.4,0.4\n"
    (bad / "ball.csv").write_text(text)
    app = labeler(data)
    assert [c.root.name for c in app.clips] == ["0_good", XSS_NAME]
    page = viser_page(app.server.get_port())
    view = ready_view(app, page)
    assert view.clip.root.name == "0_good"

    page.get_by_role("combobox", name="clip").click()
    page.get_by_role("option", name=XSS_NAME, exact=True).click()
    page.get_by_role("button", name="open clip").click()
    wait_until(lambda: f"cannot open {XSS_NAME}" in body(page), what="the error in the page")
    page_text = body(page)
    assert "ball.csv, line 3" in page_text and "fix:" in page_text and "Still showing 0_good" in page_text
    assert app.views[view.client.client_id] is view and view.clip.root.name == "0_good"  # previous clip kept

    page.get_by_role("button", name="open anyway, skip bad rows").click()
    def opened() -> bool:  # while the tab switches clips its old view is gone and the new one not yet made
        current = app.views.get(view.client.client_id)
        return current is not None and current.clip.root.name == XSS_NAME

    wait_until(opened, what="the clip opened")
    new = app.views[view.client.client_id]
    assert set(new.session.ball) == {0, 2}
    wait_until(lambda: "1 bad row(s) left out" in body(page), what="the notice of the skipped row")
    assert (bad / "ball.csv").read_text() == text  # opening anyway does not touch the file
    assert XSS_NAME in body(page)  # the name is shown as text …
    assert page.evaluate("window.__pwned === undefined")  # … and its script never ran
    assert page.locator("img[onerror]").count() == 0


def test_undo_in_one_tab_keeps_what_another_tab_changed(labeler, tmp_path, viser_page):
    clip_dir = copy_sample(tmp_path / "clip", keep_labels=False)
    clip = Clip(clip_dir)
    app = labeler(clip_dir)
    page_a = viser_page(app.server.get_port())
    view_a = ready_view(app, page_a)
    page_b = viser_page(app.server.get_port())
    view_b = ready_view(app, page_b, known={i for i, v in app.views.items() if v is view_a})
    click_pixel(page_a, view_a, (400.0, 300.0))
    wait_until(lambda: clip.ball_path.exists(), what="tab A's row")
    wait_until(lambda: 0 in view_b.session.ball, what="tab B picking up A's row")
    click_pixel(page_b, view_b, (800.0, 500.0))  # B moves the ball of the same frame
    wait_until(lambda: abs(clip.read_ball().xy[0][0] * 1280 - 800) < 1, what="B's value in ball.csv")
    press(page_a, "Control+z")
    wait_until(lambda: "changed since" in body(page_a), what="tab A saying who changed the row")
    assert f"by {view_b.session.name}" in body(page_a)
    ball = clip.read_ball()
    assert ball.frame.tolist() == [0] and abs(ball.xy[0][0] * 1280 - 800) < 1  # B's value kept
