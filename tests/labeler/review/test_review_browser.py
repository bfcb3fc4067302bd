"""E2E: `rally3d review` on the reconstructed sample in headless Chromium — press play, screenshot, and check
by pixel colours that the court floor and the ball are visible and that the ball moved.

``REVIEW_SCREENSHOT=docs/img/review.png pytest tests/labeler/review/test_review_browser.py`` also saves the
README screenshot.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import cv2
import numpy as np
import pytest
from conftest import WAIT_CEILING_S, WEBGL_CANVAS, wait_for_canvas, wait_until
from review_fixtures import reconstructed_clip, sample_shots  # noqa: F401  (fixture)

from labeler.frames import code_cell_centres
from labeler.review.app import ReviewApp
from labeler.review.data import ReviewData
from labeler.review.export import export_review

pytestmark = pytest.mark.browser


def rgb_of(png: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[..., ::-1].astype(int)


def floor_mask(img: np.ndarray) -> np.ndarray:
    """The padel floor: saturated blue (shaded), unlike viser's white/grey UI."""
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return (b > r + 60) & (b > g + 30)


def ball_mask(img: np.ndarray) -> np.ndarray:
    """The ball's yellow-green (200, 255, 0), lit: green high, red a bit lower, blue low."""
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return (g > 170) & (r > 110) & (r < g - 15) & (b < 110)


def test_review_plays_and_shows_court_and_ball(reconstructed_clip, viser_page, port, tmp_path):
    app = ReviewApp(reconstructed_clip, port=port)
    app.start()
    try:
        page = viser_page(port, width=1700, height=760)
        wait_until(lambda: bool(app.sessions), what="the review session")
        session = next(iter(app.sessions.values()))
        session.playback.seek(40)  # the serve in flight, over the court
        session.render()
        canvas = page.locator(WEBGL_CANVAS)
        # the video beside the 3D view at a usable size, named by the same frame number as the 3D ball
        wait_until(lambda: "frame 40 (3D view and video)" in page.inner_text("body"), what="the frame caption")
        # the clip's 3D status comes first in the panel
        status = page.locator(".rally3d-banner").first
        wait_until(lambda: status.is_visible(), what="the 3D status banner")
        n = len(json.loads((reconstructed_clip / "segments.json").read_text())["segments"])
        assert status.inner_text().startswith(f"3D plausible: {n}/{n} flights reconstructed")
        assert "3D covers 100% of the rally" in status.inner_text()
        wait_until(lambda: session.paged, what="the page's player")
        video = page.locator("canvas.r3d-video").first  # the video frame, drawn by the page's player
        wait_until(lambda: (video.bounding_box() or {}).get("width", 0) >= 600, what="the video panel at 600+ px")
        vbox, cbox = video.bounding_box(), canvas.bounding_box()
        assert vbox["height"] >= 300 and vbox["x"] + vbox["width"] <= cbox["x"] + 1  # beside, not over the 3D view
        assert cbox["width"] >= 600
        wait_until(lambda: session.shown == 40, what="the page to report frame 40")
        shots: list[np.ndarray] = []

        def court_and_ball_drawn() -> bool:
            shots.append(rgb_of(canvas.screenshot()))
            return floor_mask(shots[-1]).mean() > 0.15 and int(ball_mask(shots[-1]).sum()) >= 15

        wait_until(court_and_ball_drawn, what="the court floor and the ball to be drawn")
        first = shots[-1]
        ball0 = np.argwhere(ball_mask(first))

        # press play in the GUI, as a user would
        # check()/uncheck() click and then wait until the box shows the state (a click sent while the page is
        # still laying out its panel on a loaded machine is retried instead of lost)
        play = page.get_by_role("checkbox", name="play")
        play.check(timeout=WAIT_CEILING_S * 1000)
        wait_until(lambda: session.playback.playing, what="play to reach the server")
        start = session.playback.frame
        wait_until(lambda: session.playback.frame >= start + 8, what="playback to advance")
        play.uncheck(timeout=WAIT_CEILING_S * 1000)
        wait_until(lambda: not session.playback.playing, what="pause")
        # on a busy machine playback may run on while the pause click is delivered (past the reconstructed
        # frames, where no ball is drawn): look at a fixed frame 8 after the start for the on-screen check
        session.playback.seek(start + 8)
        session.render()

        def moved() -> bool:
            img = rgb_of(canvas.screenshot())
            pts = np.argwhere(ball_mask(img))
            return len(pts) >= 12 and np.linalg.norm(pts.mean(0) - ball0.mean(0)) > 10

        wait_until(moved, what="the ball to move on screen")
        out = os.environ.get("REVIEW_SCREENSHOT")
        if out:
            page.set_viewport_size({"width": 1600, "height": 900})
            page.mouse.move(5, 880)  # no tooltip
            session.playback.seek(45)
            session.render()
            pngs = [page.screenshot()]

            def settled() -> bool:  # two screenshots in a row alike: the frame is rendered
                pngs.append(page.screenshot())
                a, b = rgb_of(pngs[-2]), rgb_of(pngs[-1])
                return np.abs(a - b).mean() < 0.5 and int(ball_mask(b).sum()) >= 15

            wait_until(settled, what="the screenshot to settle")
            png = pngs[-1]
            cv2.imwrite(out, cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR),
                        [cv2.IMWRITE_PNG_COMPRESSION, 9])
    finally:
        app.stop()


SAMPLE_JS = """
(cfg) => {
  const P = window.__r3dPlayer, out = window.__r3dSamples = [];
  const ctx = P.video.getContext("2d", {willReadFrequently: true});
  const timer = setInterval(() => {
    let n = 0;
    for (const [x, y] of cfg.cells) {
      const d = ctx.getImageData(Math.round(x), Math.round(y), 1, 1).data;
      n = n * 2 + ((d[0] + d[1] + d[2]) / 3 > 127 ? 1 : 0);
    }
    const p = P.ball.position;
    out.push([n, P.ballMesh.visible ? [p.x, p.y, p.z] : null]);
    if (out.length >= cfg.samples) clearInterval(timer);
  }, 100);
}
"""
"""Every 100 ms: the frame number read from the video canvas's burned-in code, and the 3D ball's position."""


def test_review_video_and_3d_stay_in_step_while_playing_under_load(reconstructed_clip, viser_page, port):
    """10 s of playing at 1× with a CPU-bound job beside it (one busy process per core): at every sample the
    video's burned-in frame and the frame of the 3D ball agree within 2 frames, and the video advances."""
    app = ReviewApp(reconstructed_clip, port=port)
    app.start()
    busy = []
    try:
        page = viser_page(port, width=1700, height=760)
        wait_until(lambda: bool(app.sessions), what="the review session")
        session = next(iter(app.sessions.values()))
        wait_until(lambda: session.paged, what="the page's player")
        ball = [None if b is None else np.array(b) for b in session.player.config["ball_xyz"]]
        first = session.player.config["offset"]
        busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(os.cpu_count() or 2)]
        page.get_by_role("checkbox", name="play").check(timeout=WAIT_CEILING_S * 1000)
        wait_until(lambda: session.playback.playing, what="play to reach the page")
        page.evaluate(SAMPLE_JS, {"cells": code_cell_centres(session.player.config["width"]).tolist(), "samples": 100})
        wait_until(lambda: page.evaluate("window.__r3dSamples.length") >= 100, what="10 s of samples")
        samples = page.evaluate("window.__r3dSamples")
        video = [n for n, _ in samples]
        apart = []
        for n, xyz in samples:
            if xyz is None:
                continue
            frames = [first + k for k, b in enumerate(ball) if b is not None and np.abs(b - xyz).max() < 2e-3]
            assert frames, f"the 3D ball at {xyz} is at no frame of the path"
            apart.append(min(abs(f - n) for f in frames))
        assert len(apart) >= 30, f"the ball was shown in only {len(apart)} of 100 samples"
        assert max(apart) <= 2, f"video and 3D apart by up to {max(apart)} frames: {apart}"
        assert len(set(video)) >= 10, f"the video showed only {len(set(video))} distinct frames in 10 s: {video}"
    finally:
        for p in busy:
            p.kill()
            p.wait()
        app.stop()


HOSTILE = '<img src=x onerror="window.__pwned=1">'


def test_replay_html_has_the_video_the_shot_table_and_frame_numbers(reconstructed_clip, browser, tmp_path):
    clip = shutil.copytree(reconstructed_clip, tmp_path / HOSTILE)  # a hostile folder name stays text
    seg = clip / "segments.json"  # and a hostile reason why the clip is not plausible
    doc = json.loads(seg.read_text())
    doc["plausibility"].update(plausible=False, not_plausible_because=[HOSTILE], covered_share=0.76)
    seg.write_text(json.dumps(doc))
    data = ReviewData.load(clip)
    res = export_review(data, tmp_path / "out", stride=4, progress=False)
    page = browser.new_page(viewport={"width": 1500, "height": 850})
    page.set_default_timeout(WAIT_CEILING_S * 1000)
    try:
        page.goto(res.html.as_uri(), wait_until="load")
        wait_for_canvas(page)
        rows = page.locator("#rally3d-shots tbody tr")
        assert rows.count() == len(data.analysis.shots) == len(sample_shots())  # one per racket hit
        first = [c.strip() for c in rows.nth(1).locator("td").all_inner_texts()]
        shot = data.analysis.shots[1]
        assert first[:2] == [str(shot.index), f"{shot.team} shot @{shot.hit.frame}"] and first[5] == shot.verdict
        assert page.locator("#rally3d-side h3").inner_text() == HOSTILE
        banner = page.locator("#rally3d-banner")  # the 3D status, red, at the top of the page
        box = banner.bounding_box()
        assert banner.is_visible() and box["y"] <= 1 and box["height"] >= 20
        assert banner.inner_text().startswith(f"3D NOT plausible: {HOSTILE} — calls and figures below")
        assert "3D covers 76% of the rally" in banner.inner_text()
        assert page.evaluate("window.__pwned === undefined")
        side, canvas = page.locator("#rally3d-side").bounding_box(), page.locator(WEBGL_CANVAS).bounding_box()
        assert side["x"] + side["width"] <= canvas["x"] + 1 and canvas["width"] >= 600  # side by side
        assert page.locator("#rally3d-video").get_attribute("src") == "video.mp4"
        rows.nth(2).click()  # the video jumps to the shot's hit and names its frame; the row is highlighted
        hit = data.analysis.shots[2].hit.frame
        out = page.locator("#rally3d-video-frame")
        wait_until(lambda: out.inner_text().strip() == f"video: frame {hit}", what=f"the video on frame {hit}")
        assert "now" in (rows.nth(2).get_attribute("class") or "")
    finally:
        page.close()
