"""Overlay geometry, the frame cache (JPEG transport, prefetch) and the model-assistance helpers of the labeler."""
from __future__ import annotations



import cv2
import numpy as np
import pytest
from conftest import wait_until
from label_helpers import copy_sample

from inference.camera import Camera
from inference.clipio import Clip, HitEvents
from labeler.assist import ProgressClip, propose_events
from labeler.frames import FrameCache, serve_next
from labeler.render import clip_segments, court_segments, ring
from labeler.state import LabelSession
from labeler.viewer_common import ImagePlane, fit_distance, screen_of_pixel


def test_image_plane_round_trip_and_ray_intersection():
    plane = ImagePlane(1280, 720)
    px = np.array([[0.0, 0.0], [640.0, 360.0], [1279.5, 719.5]])
    np.testing.assert_allclose(plane.scene_to_pixel(plane.pixel_to_scene(px)), px)
    origin = np.array([0.0, 0.0, -2.0])
    target = plane.pixel_to_scene([[100.25, 600.75]])[0]
    assert plane.ray_to_pixel(origin, target - origin) == pytest.approx((100.25, 600.75))
    assert plane.ray_to_pixel(origin, (5.0, 0.0, 1.0)) is None  # misses the image
    assert plane.ray_to_pixel(origin, (0.0, 0.0, -1.0)) is None  # away from the plane


def test_fitted_view_maps_the_image_into_the_canvas():
    plane = ImagePlane(1280, 720)
    for w, h in [(1012, 900), (1600, 600)]:
        d = fit_distance(plane, w / h)
        corners = screen_of_pixel([[0, 0], [1280, 720]], plane, w, h, d)
        assert corners.min() >= -1e-6 and corners[1, 0] <= w + 1e-6 and corners[1, 1] <= h + 1e-6
        assert np.isclose(corners[1, 0] - corners[0, 0], w) or np.isclose(corners[1, 1] - corners[0, 1], h)


def test_clip_segments_to_the_image():
    seg = np.array([[[-10, 50], [110, 50]], [[20, 20], [30, 30]], [[-5, -5], [-1, -1]], [[np.nan, 0], [1, 1]]])
    out = clip_segments(seg, 100, 80)
    assert len(out) == 2
    np.testing.assert_allclose(out[0], [[0, 50], [100, 50]])
    np.testing.assert_allclose(out[1], seg[1])
    assert len(ring((5, 5), 3, 12)) == 12


def test_court_model_reprojects_onto_the_clicked_points(tmp_path):
    clip = copy_sample(tmp_path / "c")
    s = LabelSession(clip, autosave=False)
    cam = Camera.load(clip / "gt" / "camera.yaml")
    layers = court_segments(cam, s.court)
    assert {"paint", "net"} <= set(layers) and all(len(v) for v in layers.values())
    # the far baseline's end points are among the reprojected segment ends
    ends = np.concatenate([v.reshape(-1, 2) for v in layers.values()])
    far_left = cam.project(s.court.points["far_left"][None])[0]
    assert np.linalg.norm(ends - far_left, axis=1).min() < 1e-6
    assert all(((v >= -1e-6) & (v <= np.array([1280, 720]) + 1e-6)).all() for v in layers.values())


def test_frame_cache_serves_jpegs_of_the_right_frame_and_prefetches(tmp_path):
    clip = Clip(copy_sample(tmp_path / "c"))
    cache = FrameCache(clip, capacity=16, ahead=5, behind=2)
    try:
        with clip.frames() as src:
            ref = src.read(7)
        img = cv2.imdecode(np.frombuffer(cache.get(7), np.uint8), cv2.IMREAD_COLOR)[..., ::-1]
        assert img.shape == ref.shape and np.abs(img.astype(int) - ref).mean() < 4  # JPEG q85
        cache.prefetch(7, 1)
        wanted = [*range(8, 13), 6, 5]  # ahead first, then behind
        wait_until(lambda: all(cache.cached(i) for i in wanted), what="the prefetched frames")
        assert not cache.cached(14)
        with pytest.raises(IndexError, match="outside the clip"):
            cache.get(240)
    finally:
        cache.close()


def test_progress_clip_reports_every_frame(tmp_path):
    root = copy_sample(tmp_path / "c")
    seen = []
    clip = ProgressClip(root, lambda done, total: seen.append((done, total)))
    with clip.frames(cache_size=0) as src:
        n = sum(1 for _ in src.iter(0, 30))
    assert n == 30 and seen[-1] == (30, 240) and len(seen) == 30


def test_proposed_events_match_the_annotated_rally(tmp_path):
    """The shipped hit-event model proposes the sample's events from its labelled ball track."""
    from inference.events.metrics import match_events

    root = copy_sample(tmp_path / "c")
    s = LabelSession(root, autosave=False)
    events = propose_events(s)
    assert isinstance(events, HitEvents)
    gt = Clip(root).read_events(gt=True)
    hits = [e.startswith("player") for e in events.event]
    gt_hits = [e.startswith("player") for e in gt.event]
    assert match_events(gt.frame[gt_hits], events.frame[hits], tol=1) >= 0.8 * sum(gt_hits)
    assert s.set_event_proposals(events) == len(events)


def test_no_event_model_gives_a_clear_message(tmp_path, monkeypatch):
    import inference.events.detector as det

    monkeypatch.setattr(det, "choose_weights", lambda path, sport, players=None: tmp_path / "missing.pth.tar")
    s = LabelSession(copy_sample(tmp_path / "c"), autosave=False)
    with pytest.raises(RuntimeError, match="no hit-event model available"):
        propose_events(s)


def test_a_second_fit_to_the_same_pose_does_not_wait_for_a_report(monkeypatch):
    """Two fits of one tab (at connection and after the canvas's first size, two threads) to the same pose:
    the browser, already there, reports nothing new, and the view must still count as fitted; a report of
    another pose (the browser resetting as it starts) is still answered by a refit."""
    import threading
    from types import SimpleNamespace

    import labeler.app as app_mod

    fits = []
    monkeypatch.setattr(app_mod, "fit_camera", lambda client, plane, aspect: fits.append(aspect) or 1.7)
    view = app_mod.ClientView.__new__(app_mod.ClientView)  # the camera logic alone, without a browser
    view.client = SimpleNamespace(camera=SimpleNamespace(aspect=1.5))
    view.plane, view.fit_distance, view.reported_camera = None, None, None
    view._aspect, view._fit_lock, view._fit_pending = 0.0, threading.RLock(), True

    def report(position, aspect=1.5):
        view._on_camera(SimpleNamespace(position=position, aspect=aspect))

    assert not view.camera_fitted
    report((0.3, 0.1, -2.5))               # the browser's first report: the canvas size → the first fit
    assert fits == [1.5] and not view.camera_fitted
    report((0.0, 0.0, -1.7))               # at the fitted pose
    assert view.camera_fitted
    view.fit(1.5)                          # the other thread's fit, to the same pose: no report will follow
    assert view.camera_fitted
    report((0.0, 0.0, -3.0))               # the browser reset to its initial camera: refit, not fitted
    assert fits == [1.5, 1.5, 1.5] and not view.camera_fitted
    report((0.0, 0.0, -1.7))
    assert view.camera_fitted


def test_court_point_labels_are_short_and_never_overlap():
    """Five points within a few pixels of each other (a far corner, the service line's ends seen edge-on):
    their short labels are laid out without two boxes overlapping or covering a point, and each label moved
    off its first place gets a leader line from its point."""
    from labeler.render import layout_labels, leader_segments, short_point_name
    from labeler.viewer_common import boxes_overlap

    assert short_point_name("near_service_left") == "N svc L"
    assert short_point_name("glass_far_left_top") == "gl F L top" and short_point_name("odd_name") == "odd name"
    names = ["far_left", "far_service_left", "far_service_center", "far_service_right", "net_post_left_top"]
    pts = {n: np.array([400.0 + 6 * i, 200.0 + 3 * i]) for i, n in enumerate(names)}
    texts = {n: short_point_name(n) for n in names}
    char, line, gap = 8.0, 16.0, 8.0
    corners = layout_labels(pts, texts, char, line, gap)
    boxes = {n: (c[0], c[1], c[0] + char * len(texts[n]), c[1] + line) for n, (c, _) in corners.items()}
    for a in names:
        for b in names:
            if a < b:
                assert not boxes_overlap(boxes[a], boxes[b]), (a, b)
        for q in pts.values():
            x0, y0, x1, y1 = boxes[a]
            assert not (x0 < q[0] < x1 and y0 < q[1] < y1), a
    moved = [n for n, (_, m) in corners.items() if m]
    assert moved and len(leader_segments(pts, corners, char, line, texts)) == len(moved)
    lone = layout_labels({"far_left": np.array([50.0, 50.0])}, texts, char, line, gap)
    assert not lone["far_left"][1] and np.allclose(lone["far_left"][0], [58.0, 58.0])   # right-below, no leader


def test_serve_next_reads_the_video_in_decode_order():
    free = {10, 11, 14, 15}
    assert serve_next([14, 15, 10, 11], set(), free) == 10  # wanted frames on the decoder's way to 14: first
    assert serve_next([14, 15, 10, 11], {15}, free) == 15  # one already encoded: at once
    assert serve_next([14, 15, 10, 11], set(), free, first=True) == 14  # the frame an annotator waits for
    # the most wanted one needs a seek: one seek to the lowest wanted one up to 32 frames below it, then up
    assert serve_next([50, 49, 48, 40, 5], set(), set()) == 40


def test_frame_cache_plays_backwards_in_runs_of_one_seek(tmp_path):
    clip = Clip(copy_sample(tmp_path / "c"))
    cache = FrameCache(clip, capacity=64, prefetch=False)
    src, seeks = cache._source, []
    seek = src._seek
    src._seek = lambda cap, index: (seeks.append(index), seek(cap, index))[1]
    try:
        cache.get(100)
        assert src.seek_free(101) and src.seek_free(101 + 32) and not src.seek_free(99)
        assert cache.next_to_serve([102, 99, 101]) == 101  # on the way to 102; 99 would need a seek
        before = len(seeks)
        for f in range(80, 60, -1):  # playing backwards: the frames below each seek come with it
            cache.get(f, backward=16)
        assert len(seeks) - before == 2  # 80 (with 64..79), then 63 (with 47..62): not one seek per frame
        assert all(cache.cached(i) for i in range(47, 81))
        with clip.frames() as frames:
            ref = frames.read(70)
        img = cv2.imdecode(np.frombuffer(cache.get(70), np.uint8), cv2.IMREAD_COLOR)[..., ::-1]
        assert np.abs(img.astype(int) - ref)[60:].mean() < 4  # the right frame (under its burned-in number)
    finally:
        cache.close()
