"""The labeler's UI-free state: edits, undo/redo, autosave, interpolation, stationary balls, court points, merges."""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from label_helpers import copy_sample

from inference.camera import Camera
from inference.clipio import Clip, FormatError
from labeler.state import LabelSession, clip_overview, find_clips


@pytest.fixture
def clip_dir(tmp_path):
    return copy_sample(tmp_path / "clip", keep_labels=False)


def test_ball_edits_are_saved_at_once_and_reload(clip_dir):
    s = LabelSession(clip_dir)
    s.set_ball(10, (0.25, 0.5))
    s.set_ball(11, (0.26, 0.49), visibility=2)
    s.set_visibility(12, 0)
    track = Clip(clip_dir).read_ball()
    assert track.frame.tolist() == [10, 11, 12]
    assert track.visibility.tolist() == [1, 2, 0]
    np.testing.assert_allclose(track.xy[0], [0.25, 0.5])
    assert np.isnan(track.xy[2]).all()
    again = LabelSession(clip_dir)
    assert set(again.ball) == {10, 11, 12} and again.ball[11][0] == 2
    np.testing.assert_allclose(again.ball[11][1:], (0.26, 0.49))
    assert again.summary()["labelled"] == 3


def test_visibility_change_keeps_position_and_needs_one(clip_dir):
    s = LabelSession(clip_dir)
    assert s.set_visibility(5, 3) is False  # no position yet: click the ball first
    s.set_ball(5, (0.4, 0.6))
    assert s.set_visibility(5, 3)
    assert s.ball[5] == (3, 0.4, 0.6)
    s.clear_ball(5)
    assert 5 not in s.ball and len(Clip(clip_dir).read_ball()) == 0


def test_undo_redo_restores_rows_and_files(clip_dir):
    s = LabelSession(clip_dir)
    s.set_ball(3, (0.1, 0.2))
    s.set_ball(3, (0.3, 0.4))
    s.set_event(3, "ground")
    s.undo()
    assert 3 not in s.events and not Clip(clip_dir).read_events(missing_ok=True).frame.size
    s.undo()
    assert s.ball[3] == (1, 0.1, 0.2)
    np.testing.assert_allclose(Clip(clip_dir).read_ball().xy[0], [0.1, 0.2])
    s.redo()
    s.redo()
    assert s.ball[3] == (1, 0.3, 0.4) and s.events[3] == "ground"
    assert s.redo() is None
    s.undo()
    s.set_ball(7, (0.5, 0.5))  # a new edit clears the redo stack
    assert s.redo() is None


def test_bad_input_is_a_clear_error(clip_dir):
    s = LabelSession(clip_dir)
    with pytest.raises(ValueError, match="outside the clip"):
        s.set_ball(10_000, (0.5, 0.5))
    with pytest.raises(ValueError, match="normalised"):
        s.set_ball(1, (math.nan, 0.5))
    with pytest.raises(ValueError, match="unknown event 'bounce'"):
        s.set_event(1, "bounce")
    with pytest.raises(KeyError, match="unknown court point"):
        s.set_point("centre_spot", (0.5, 0.5))
    (clip_dir / "ball.csv").write_text("frame,visibility,x,y\n0,7,0.5,0.5\n")
    with pytest.raises(FormatError, match="ball.csv, line 2"):
        LabelSession(clip_dir)


def test_linear_interpolation_is_provisional_until_accepted(clip_dir):
    s = LabelSession(clip_dir)
    s.set_ball(0, (0.1, 0.5))
    s.set_ball(4, (0.5, 0.1))
    assert s.interpolate("linear") == 3
    np.testing.assert_allclose(s.ball_proposals[2][1:], [0.3, 0.3])
    assert 2 not in s.ball and len(Clip(clip_dir).read_ball()) == 2  # provisional: not saved
    assert s.accept_ball_proposals([1]) == 1
    assert set(s.ball) == {0, 1, 4} and set(s.ball_proposals) == {2, 3}
    assert s.accept_ball_proposals() == 2
    assert len(Clip(clip_dir).read_ball()) == 5
    s.undo()
    assert set(s.ball) == {0, 1, 4}


def test_physics_interpolation_follows_a_parabola_between_events(clip_dir):
    s = LabelSession(clip_dir)
    t = np.arange(0, 21, 5)  # keyframes of one flight: x linear, y parabolic in time
    for f in t:
        s.set_ball(int(f), (0.2 + 0.02 * f, 0.2 + 0.001 * (f - 10) ** 2))
    s.set_event(0, "player_near")
    s.set_event(20, "ground")
    s.interpolate("physics")
    for f in (3, 12, 17):
        np.testing.assert_allclose(s.ball_proposals[f][1:], [0.2 + 0.02 * f, 0.2 + 0.001 * (f - 10) ** 2],
                                   atol=1e-9)
    s.interpolate("linear")
    assert abs(s.ball_proposals[12][2] - (0.2 + 0.001 * 4)) > 1e-3  # linear cannot follow the curve


def test_interpolation_never_crosses_an_event_or_a_long_gap(clip_dir):
    s = LabelSession(clip_dir)
    for f, xy in [(0, (0.1, 0.1)), (5, (0.2, 0.3)), (10, (0.3, 0.5)), (20, (0.5, 0.3)), (120, (0.9, 0.9))]:
        s.set_ball(f, xy, visibility=3)  # occluded keyframes: the filled rows are still "visible"
    s.set_event(15, "ground")
    n = s.interpolate("physics")
    assert n == 8 and set(s.ball_proposals) == set(range(1, 5)) | set(range(6, 10))
    assert {r[0] for r in s.ball_proposals.values()} == {1}
    assert [why for *_, why in s.interpolation_skipped] == ["event @15", "100 frames apart (max 15)"]
    assert s.interpolate("linear", max_gap=200) == 8 + 99  # a longer limit fills 20..120 (no event there)
    assert not set(range(11, 20)) & set(s.ball_proposals)


def test_physics_interpolation_meets_both_keyframes_and_bends(clip_dir):
    s = LabelSession(clip_dir)
    t = [0, 4, 8, 12, 16]
    for f in t:
        s.set_ball(f, (0.2 + 0.02 * f, 0.6 - 0.04 * f + 0.003 * f * f))  # y: a parabola (up, then down)
    s.interpolate("physics")
    for f in (2, 6, 10, 14):
        np.testing.assert_allclose(s.ball_proposals[f][1:], (0.2 + 0.02 * f, 0.6 - 0.04 * f + 0.003 * f * f),
                                   atol=1e-9)


def test_accepting_a_flight_stops_at_its_events(clip_dir):
    s = LabelSession(clip_dir)
    for f in (0, 6, 12, 20, 26):
        s.set_ball(f, (0.1 + 0.01 * f, 0.5))
    s.set_event(12, "player_near")
    s.interpolate("linear")
    assert s.flight(8) == (0, 12) and s.flight(12) == (12, 239)
    n, (lo, hi) = s.accept_flight_proposals(3)
    assert n == 10 and (lo, hi) == (0, 12)
    assert all(f in s.ball for f in range(0, 13)) and 13 not in s.ball and 21 in s.ball_proposals


def test_model_proposals_only_fill_unlabelled_frames_unless_overwrite(clip_dir):
    s = LabelSession(clip_dir)
    s.set_ball(1, (0.5, 0.5))
    gt = Clip(copy_sample(clip_dir.parent / "gt_copy")).read_ball()
    assert s.set_ball_proposals(gt, "detector") == len(gt)
    assert s.accept_ball_proposals(range(0, 3)) == 2  # frame 1 is labelled already
    assert s.ball[1] == (1, 0.5, 0.5)
    s.set_ball_proposals(gt, "detector")
    s.accept_ball_proposals([1], overwrite=True)
    np.testing.assert_allclose(s.ball[1][1:], gt.xy[1], atol=1e-7)
    assert s.reject_ball_proposals(range(100, 110)) == 10


def test_stationary_balls_carry_over_until_removed(clip_dir):
    s = LabelSession(clip_dir)
    b = s.add_inactive(100, (0.3, 0.8))
    assert s.inactive_at(99) == {} and s.inactive_at(239) == {b: (0.3, 0.8)}
    c = s.add_inactive(120, (0.6, 0.8))
    assert c != b
    s.move_inactive(150, b, (0.31, 0.81))
    assert s.inactive_at(149)[b] == (0.3, 0.8) and s.inactive_at(200)[b] == (0.31, 0.81)
    s.remove_inactive(180, b)
    assert b not in s.inactive_at(180) and b in s.inactive_at(179) and c in s.inactive_at(239)
    assert s.nearest_inactive(130, (0.6 + 5 / 1280, 0.8)) == c
    table = Clip(clip_dir).read_inactive_balls()
    assert len(table) == (180 - 100) + (240 - 120)
    s.undo()  # the removal comes back
    assert b in s.inactive_at(239)


def test_events_hotkey_vocabulary_and_navigation(clip_dir):
    s = LabelSession(clip_dir)
    assert s.event_labels[:1] == ["ground"] and {"wall_near", "mesh", "net", "player_far"} <= set(s.event_labels)
    s.toggle_event(30, "player_near")
    s.toggle_event(60, "ground")
    assert Clip(clip_dir).read_events().frame.tolist() == [30, 60]
    s.toggle_event(60, "ground")
    assert s.events == {30: "player_near"}
    assert s.next_event(0) == 30 and s.next_event(30) is None and s.next_event(100, -1) == 30


def test_court_points_calibrate_live_and_write_camera_yaml(clip_dir):
    gt = Camera.load(clip_dir / "gt" / "camera.yaml")
    s = LabelSession(clip_dir)
    names = ["near_service_left", "near_service_right", "far_left", "far_right", "net_post_left_top",
             "net_post_right_top", "near_service_center"]
    for i, name in enumerate(names):
        uv = gt.project_normalized(s.court.points[name][None])[0]
        s.set_point(name, uv)
        if i < 5:
            assert s.calibration is None and "at least 6" in s.calibration_error
            assert not (clip_dir / "camera.yaml").exists()
    assert s.calibration is not None and s.calibration.rms_px < 0.05
    cam = Camera.load(clip_dir / "camera.yaml")
    assert np.linalg.norm(cam.centre - gt.centre) < 0.05
    assert set(yaml.safe_load((clip_dir / "camera.yaml").read_text())["points_used"]) == set(names)


def test_floor_points_alone_calibrate_live(clip_dir):
    s = LabelSession(clip_dir)
    gt = Camera.load(clip_dir / "gt" / "camera.yaml")
    for name in ["near_service_left", "near_service_right", "far_left", "far_right", "net_left", "net_right"]:
        s.set_point(name, gt.project_normalized(s.court.points[name][None])[0])
    assert s.calibration is not None and s.calibration.method == "plane"
    assert np.linalg.norm(s.calibration.camera.centre - gt.centre) < 0.05


def test_two_sessions_on_one_clip_merge_and_report(clip_dir):
    a, b = LabelSession(clip_dir), LabelSession(clip_dir)
    a.set_ball(10, (0.1, 0.1))
    b.set_ball(20, (0.2, 0.2))  # b has not seen a's row: it must merge, not overwrite
    assert set(Clip(clip_dir).read_ball().frame.tolist()) == {10, 20}
    assert set(b.ball) == {10, 20} and "loaded 1 row(s) saved by another tab" in b.notices[-1]
    a.set_event(5, "ground")
    b.set_event(5, "net")  # b reads a's row first: its undo brings a's value back, not "no event"
    assert Clip(clip_dir).read_events().at(5) == "net"
    assert b.undo_stack[-1].changes[0].old == "ground"
    a.sync()
    assert a.events[5] == "net" and set(a.ball) == {10, 20}
    a.clear_ball(20)  # a deletes a row b wrote: deletions merge too
    b.set_ball(30, (0.3, 0.3))
    assert set(Clip(clip_dir).read_ball().frame.tolist()) == {10, 30}


def test_dataset_overview_and_clip_discovery(tmp_path):
    copy_sample(tmp_path / "ds" / "a")
    copy_sample(tmp_path / "ds" / "b", keep_labels=False)
    clips = find_clips(tmp_path / "ds")
    assert [c.root.name for c in clips] == ["a", "b"]
    ov = [clip_overview(c) for c in clips]
    assert ov[0]["labelled_pct"] == 100.0 and ov[0]["events"] > 0 and ov[1]["labelled"] == 0
    assert [c.root.name for c in find_clips(tmp_path / "ds" / "a")] == ["a"]
    with pytest.raises(FileNotFoundError, match="neither a clip folder"):
        find_clips(tmp_path)


def test_undo_restores_only_what_this_tab_wrote(clip_dir):
    a, b = LabelSession(clip_dir, name="tab 1"), LabelSession(clip_dir, name="tab 2")
    a.set_ball(5, (0.1, 0.1))
    a.set_ball(6, (0.2, 0.2))
    b.set_ball(5, (0.5, 0.5))  # b changes a's row
    a.undo()  # undoes frame 6 (a's own, untouched by b)
    assert 6 not in a.ball
    a.undo()  # frame 5 now holds b's value: left alone, and a says who changed it
    assert a.ball[5] == (1, 0.5, 0.5)
    assert Clip(clip_dir).read_ball().frame.tolist() == [5]
    assert "ball @5 (by tab 2)" in a.notices[-1]
    b.undo()  # b's own edit undoes to what it replaced (a's value)
    np.testing.assert_allclose(Clip(clip_dir).read_ball().xy[0], (0.1, 0.1))


def test_unknown_columns_survive_labelling(clip_dir):
    (clip_dir / "ball.csv").write_text("frame,visibility,x,y,note\n3,1,0.5,0.5,check this\n")
    (clip_dir / "events.csv").write_text("frame,event,who\n3,ground,ann\n")
    s = LabelSession(clip_dir)
    s.set_ball(4, (0.6, 0.6))
    s.set_event(9, "net")
    ball, events = Clip(clip_dir).read_ball(), Clip(clip_dir).read_events()
    assert ball.extra["note"].tolist() == ["check this", ""] and events.extra["who"].tolist() == ["ann", ""]


def test_a_bad_row_is_an_error_or_skipped_with_a_backup(clip_dir):
    text = "frame,visibility,x,y\n0,1,0.5,0.5\n1,1,1.2,0.5\n2,1,0.4,0.4\n"
    (clip_dir / "ball.csv").write_text(text)
    with pytest.raises(FormatError, match="ball.csv, line 3"):
        LabelSession(clip_dir)
    s = LabelSession(clip_dir, skip_bad_rows=True)
    assert set(s.ball) == {0, 2} and [e.line for e in s.skipped["ball"]] == [3]
    assert (clip_dir / "ball.csv").read_text() == text  # opening does not touch the file
    s.set_ball(5, (0.3, 0.3))
    backups = list((clip_dir / ".rally3d" / "backup").glob("ball.csv.*"))
    assert len(backups) == 1 and backups[0].read_text() == text and "original is kept" in s.notices[-1]
    assert Clip(clip_dir).read_ball().frame.tolist() == [0, 2, 5]


def test_events_of_another_sport_are_refused(clip_dir):
    (clip_dir / "clip.yaml").write_text((clip_dir / "clip.yaml").read_text().replace("padel", "tennis"))
    (clip_dir / "events.csv").write_text("frame,event\n3,wall_left\n")
    with pytest.raises(FormatError, match="unknown event 'wall_left'"):
        LabelSession(clip_dir)


def test_temp_files_of_a_crashed_save_are_removed_at_start(clip_dir):
    import os
    import time

    litter = clip_dir / ".events.csv.k2j3h4.tmp"
    litter.write_text("frame,ev")
    os.utime(litter, (time.time() - 600, time.time() - 600))
    s = LabelSession(clip_dir)
    assert not litter.exists() and "removed 1 temporary file" in s.notices[-1]
