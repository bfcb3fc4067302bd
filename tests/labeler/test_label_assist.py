"""The labeler's pieces without a browser: escaping of file-derived text, the in-page error and the cheat-sheet,
the frame number and code burned into each picture, the page player's reports, detector-driven navigation and colours, proposed
events and the next court point."""
from __future__ import annotations

import html
import json

import cv2

import numpy as np
import pytest
from label_helpers import copy_sample

from inference.clipio import Clip, FormatError
from inference.clipio.tables import BallTrack, HitEvents
from labeler.app import error_markdown, shortcuts_markdown
from labeler.frames import code_cell_centres, read_frame_code, stamp_frame_number
from labeler.player import PlayerReport, in_time
from labeler.render import COLORS, confidence_color
from labeler.state import LabelSession
from labeler.viewer_common import md_escape

HOSTILE = '<iframe srcdoc="<script>parent.x=1</script>">|**b**'


@pytest.fixture
def clip_dir(tmp_path):
    return copy_sample(tmp_path / "clip", keep_labels=False)


def test_markdown_escaping_leaves_no_html_or_markup():
    out = md_escape(HOSTILE)
    assert "<" not in out and ">" not in out and "|" not in out.replace("\\|", "")
    assert "\\*\\*b\\*\\*" in out  # emphasis shown as the characters typed


def test_error_markdown_names_file_line_and_fix_escaped(tmp_path):
    clip = Clip(tmp_path / HOSTILE)
    err = FormatError(tmp_path / HOSTILE / "ball.csv", "x is outside [0, 1]: 1.2 <b>", line=3,
                      fix="write x as a fraction of the width")
    text = error_markdown(clip, err)
    assert "line 3" in text and "fix: write x as a fraction of the width" in text
    assert "<" not in text.replace("&lt;", "")


def test_cheat_sheet_names_the_courts_events():
    text = shortcuts_markdown(["ground", "net"])
    assert "| 1 | event ground |" in text and "| 2 | event net |" in text and "| 3 |" not in text
    assert "| ? | this cheat-sheet |" in text and "Enter or Escape leaves a field" in text


def test_frame_number_is_burned_into_the_top_left_only():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 255, (720, 1280, 3), dtype=np.uint8)
    a, b = stamp_frame_number(img, 12), stamp_frame_number(img, 13)
    changed = np.argwhere((a != img).any(-1))
    assert changed[:, 0].max() < 60 and changed[:, 1].max() < 150  # a small box in the corner
    assert (a[:60, :150] != b[:60, :150]).any()  # the numbers differ
    np.testing.assert_array_equal(a[60:], img[60:])


@pytest.mark.parametrize("size", [(640, 360), (1280, 720), (1920, 1080), (3840, 2160)])
def test_frame_code_reads_back_after_jpeg(size):
    """The binary code burned under the frame number survives JPEG and is read at the cell centres."""
    w, h = size
    rng = np.random.default_rng(0)
    picture = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)  # worst case: noise right beside the code
    for index in (0, 1, 6, 241, 4095, 65535):
        ok, buf = cv2.imencode(".jpg", stamp_frame_number(picture, index), [cv2.IMWRITE_JPEG_QUALITY, 80])
        img = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        c = np.round(code_cell_centres(w)).astype(int)
        assert read_frame_code(img[c[:, 1], c[:, 0]].mean(axis=1)) == index


def test_frames_a_playing_page_would_get_too_late_are_not_sent():
    # 30 frames/s from frame 100, 0.1 s since the report + serving: the clock is at 103 when they arrive
    assert in_time([101, 102, 103, 104, 110], 100, 1, 0.1, 30.0) == [103, 104, 110]
    assert in_time([99, 97, 96, 90], 100, -1, 0.1, 30.0) == [97, 96, 90]  # backwards
    # a page that loops (the review) wants the first frames again after the last
    assert in_time([238, 0, 1, 120], 235, 1, 0.05, 30.0, loop=(0, 239)) == [238, 0, 1]


def test_player_report_parsing_rejects_what_the_page_would_never_send():
    good = {"seq": 3, "token": "abc", "shown": 5, "goal": 6, "dir": -1, "playing": False, "want": [6, 7, 900, -1]}
    rep = PlayerReport.parse(json.dumps(good), 0, 239)
    assert rep == PlayerReport(3, "abc", 5, 6, -1, False, (6, 7), 0)  # frames outside the clip are dropped
    for bad in ("", "[]", "{", json.dumps({**good, "shown": 240}), json.dumps({**good, "goal": "x"}),
                json.dumps({k: v for k, v in good.items() if k != "want"})):
        assert PlayerReport.parse(bad, 0, 239) is None


def test_next_uncertain_frame_and_confidence_colours(clip_dir):
    s = LabelSession(clip_dir)
    n = s.n_frames
    scores = np.full(n, 0.9)
    scores[[7, 30]] = [0.2, 0.1]
    track = BallTrack(np.arange(n), np.ones(n, np.int8), np.full((n, 2), 0.5))
    s.set_ball_proposals(track, "detector", scores)
    s.set_ball(7, (0.4, 0.4))  # labelled: no longer uncertain
    assert s.next_uncertain(0) == 30 and s.next_uncertain(30) == 30  # wraps round to itself
    assert confidence_color(None) == COLORS["proposal"] and confidence_color(1.0) == COLORS["proposal"]
    assert confidence_color(0.0) == COLORS["unsure"]


def test_proposed_events_are_accepted_one_by_one(clip_dir):
    s = LabelSession(clip_dir)
    s.set_event_proposals(HitEvents(np.array([10, 40]), np.array(["player_near", "ground"])))
    assert s.accept_event_proposals([40]) == 1
    assert s.events == {40: "ground"} and s.event_proposals == {10: "player_near"}
    assert Clip(clip_dir).read_events().frame.tolist() == [40]


def test_next_court_point_prefers_points_in_view(clip_dir):
    s = LabelSession(clip_dir)
    gt = Clip(copy_sample(clip_dir.parent / "labelled")).read_court_points().as_dict()
    for name in ["far_left", "far_right", "near_service_left", "near_service_right", "net_post_left_top",
                 "net_post_right_top", "glass_far_left_top"]:
        s.set_point(name, gt[name])  # calibrated: the other points are expected from the court model
    left = (0.0, 0.0, s.width / 2, s.height)
    right = (s.width / 2, 0.0, float(s.width), s.height)
    expected = s.expected_points_px()
    a, b = s.next_point(None, left), s.next_point(None, right)
    assert expected[a][0] <= s.width / 2 <= expected[b][0]


def test_the_point_dropdown_offers_only_points_inside_the_picture(clip_dir):
    """Once the clicks calibrate the camera, the court points it puts outside the picture (the padel sample's
    near corners, the near glass and steps: 8 of 40) are not offered; clicked points always are."""
    s = LabelSession(clip_dir)
    assert s.offered_points() == s.court.point_names          # nothing known yet: every point
    gt = Clip(copy_sample(clip_dir.parent / "labelled")).read_court_points().as_dict()
    for name in ["far_left", "far_right", "near_service_left", "near_service_right", "net_post_left_top",
                 "net_post_right_top", "glass_far_left_top"]:
        s.set_point(name, gt[name])
    expected = s.expected_points_px()
    mx, my = 0.02 * s.width, 0.02 * s.height                  # a point just beyond the edge is still offered
    outside = {n for n, (x, y) in expected.items() if not (-mx <= x <= s.width + mx and -my <= y <= s.height + my)}
    offered = s.offered_points()
    assert {"near_left", "near_right", "glass_near_left_top"} <= outside and len(outside) == 8
    assert not outside & set(offered) and set(s.points) <= set(offered)
    assert len(offered) == len(s.court.point_names) - len(outside)
    order = s.court.point_names
    assert offered == [n for n in order if n in offered]      # in the court's order
    nxt = s.next_point()
    assert nxt in offered and nxt not in s.points


def test_pages_served_beyond_this_machine_show_paths_relative_to_the_dataset(tmp_path, port):
    """Served on 0.0.0.0 the error page names ``clip/ball.csv``, not the server's absolute folders; on
    localhost the whole path (the user's own machine)."""
    from labeler.app import LabelerApp, relative_to

    clip_dir = copy_sample(tmp_path / "data" / "clip", keep_labels=False)
    err = FormatError(clip_dir / "ball.csv", f"cannot read {clip_dir / 'ball.csv'}", line=3,
                      fix=f"compare with {clip_dir.parent / 'other' / 'ball.csv'}")
    for host, shown in [("0.0.0.0", "clip/ball.csv"), ("127.0.0.1", str(clip_dir / "ball.csv"))]:
        app = LabelerApp(clip_dir, host=host, port=port)
        try:
            text = error_markdown(Clip(clip_dir), err, app.shown_base)
        finally:
            app.stop()
        assert md_escape(shown) in text and "line 3" in text
        if host == "0.0.0.0":
            assert str(tmp_path) not in text and md_escape("other/ball.csv") in text
    assert relative_to(f"{tmp_path}/a/b.csv and {tmp_path}", tmp_path) == "a/b.csv and ."
    assert relative_to("/x/y", None) == "/x/y"


def test_the_dataset_table_fits_its_panel():
    """Long clip names and errors are shortened around an ellipsis (the dropdown keeps the full names), the
    headers are short, and a row shows at most 64 characters; file-derived text is escaped."""
    from labeler.app import dataset_markdown, shorten

    long_name = "wpt2022_master_final_women_point_0123_camera_main"
    rows = [{"clip": long_name, "frames": 1234, "labelled_pct": 57.4, "events": 88, "court_points": 12},
            {"clip": HOSTILE, "error": "ball.csv, line 3: x is outside [0, 1]: 1.2 — fix: write x as a fraction"}]
    table = dataset_markdown(rows)
    lines = table.splitlines()
    assert lines[0] == "| clip | frames | done | events | pts |"
    short = shorten(long_name, 20)
    assert md_escape(long_name) not in table and md_escape(short) in table and len(short) == 20
    assert short == "wpt2022_ma…mera_main"
    assert "57 %" in lines[2] and "<" not in table
    for line in lines:
        visible = html.unescape(line.replace("\\", ""))
        assert len(visible) <= 64, line
    assert shorten("short", 20) == "short"
