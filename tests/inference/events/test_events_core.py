"""Class sets, features, windows, the decoder and the metrics of the hit-event models, on simulated rallies."""
from __future__ import annotations

import numpy as np
import pytest

from inference.clipio import BallTrack, HitEvents
from inference.events import ClassSet, DecodeParams, EventCounts, UnmappedLabelError, decode, tolerance_frames
from inference.events.features import (
    FeatureConfig,
    ball_features,
    clip_features,
    make_windows,
    resample_xy,
    window_labels,
    window_probs_to_frames,
)
from training.events.data.datamodule import label_clips
from training.events.synthetic.simulate import simulate_clips


@pytest.fixture(scope="module")
def padel_clips():
    return simulate_clips("padel", 4, seed=11, progress=False)


def test_class_sets_map_fine_labels_and_refuse_uncovered_ones():
    padel, tennis = ClassSet.load("padel6"), ClassSet.load("tennis4")
    assert padel.n == 6 and tennis.n == 4
    assert padel.encode_label("wall_left") == padel.encode_label("ground") == padel.index("ground_or_other_wall")
    assert padel.fine_label("ground_or_other_wall") == "ground" and padel.fine_label("wall_near") == "wall_near"
    ev = HitEvents([2, 5], ["ground", "wall_near"])
    with pytest.raises(UnmappedLabelError, match="wall_near"):
        tennis.encode(ev, 10, where="clip_x")
    with pytest.warns(UserWarning, match="wall_near"):
        y = tennis.encode(ev, 10, on_unmapped="warn")
    assert y.tolist() == [0, 0, 1, 0, 0, 0, 0, 0, 0, 0]  # the uncovered event became none, not another class
    with pytest.raises(FileNotFoundError, match="known"):
        ClassSet.load("no_such_set")


def test_mirror_swaps_left_and_right_wall_classes():
    d = ClassSet.load("padel6").to_dict()
    d.update(name="walls", classes=["none", "wall_left", "wall_right", "player_near", "player_far"],
             map={"wall_left": "wall_left", "wall_right": "wall_right", "player_near": "player_near",
                  "player_far": "player_far"}, default_fine={}, resolve_with_camera={})
    d["rules"]["requires_last_hit"] = {}
    cs = ClassSet.from_dict(d)
    assert cs.mirror_permutation().tolist() == [0, 2, 1, 3, 4]
    assert ClassSet.load("padel6").mirror_permutation().tolist() == list(range(6))  # grouped: unchanged


def test_features_are_shifted_positions_with_missing_zero():
    xy = np.array([[0.2, 0.4], [np.nan, np.nan], [0.3, 0.5], [0.35, 0.5]])
    f = ball_features(xy, velocity=True)
    assert f.shape == (4, 5)
    assert np.allclose(f[0, :2], [1.2, 1.4]) and np.all(f[1] == 0)
    assert np.allclose(f[3, 2:4], [0.5, 0.0]) and f[2, 2] == 0  # no velocity across a gap
    assert ((f[:, :2] == 0) | ((f[:, :2] >= 1) & (f[:, :2] <= 2))).all()


def test_resampling_keeps_duration_and_gaps():
    xy = np.stack([np.linspace(0, 1, 30), np.full(30, 0.5)], 1)
    xy[10:13] = np.nan
    r = resample_xy(xy, 30.0, 50.0)
    assert len(r) == 50
    assert np.isnan(r[int(11 * 50 / 30)]).all() and np.isfinite(r[0]).all()
    assert np.allclose(r[np.isfinite(r[:, 0]), 1], 0.5)


def test_windows_label_the_last_k_frames_and_recover_event_frames():
    y = np.zeros(40, np.int64)
    y[[10, 25]] = [2, 3]
    wl = window_labels(y, 12, 6)
    starts = np.flatnonzero(wl == 2)  # padded starts t+1 .. t+K for t = 10
    assert starts.tolist() == list(range(11, 17))
    per_frame = window_probs_to_frames(np.eye(5)[wl], len(y), 12, 6)
    assert per_frame[:, 2].argmax() == 10 and per_frame[:, 3].argmax() == 25


def test_lookahead_puts_frames_after_the_event_in_the_window_and_maps_back():
    y = np.zeros(40, np.int64)
    y[[3, 10, 36]] = [2, 3, 4]
    window, k, look = 20, 6, 8
    wl = window_labels(y, window, k, look)
    starts = np.flatnonzero(wl == 3)  # the block [W-L-K, W-L) covers t = 10: padded starts t+L+1 .. t+L+K
    assert starts.tolist() == list(range(10 + look + 1, 10 + look + k + 1))
    windows = make_windows(np.arange(40, dtype=float)[:, None], window)
    for s in starts:  # every labelled window sees the event and the L frames after it
        real = windows[s, :, 0][windows[s, :, 0] > 0]
        assert 10 in real and (10 + look) in real
    per_frame = window_probs_to_frames(np.eye(5)[wl], len(y), window, k, look)
    assert [int(per_frame[:, c].argmax()) for c in (2, 3, 4)] == [3, 10, 36]
    assert np.allclose(per_frame.sum(axis=1), 1.0)
    with pytest.raises(ValueError, match="lookahead"):
        window_labels(y, 12, 6, 7)


def test_perfect_probabilities_decode_to_the_true_events(padel_clips):
    cs, fc = ClassSet.load("padel6"), FeatureConfig()
    for lc in label_clips(padel_clips, cs, fc):
        probs = window_probs_to_frames(np.eye(cs.n)[window_labels(lc.y, 12, 6)], len(lc.y), 12, 6)
        f, c = decode(probs, 50.0, cs, DecodeParams(thresholds=0.5, min_gap=1))
        truth = np.flatnonzero(lc.y)
        # one label per window (12 frames, stride 6): two contacts closer than the stride (a corner's floor and
        # glass 4 frames apart) share a window, and only one of them can come back
        crowded = np.diff(truth) < 6
        lone = truth[~(np.r_[crowded, False] | np.r_[False, crowded])]
        every, alone = EventCounts(cs.classes), EventCounts(cs.classes)
        every.add(truth, lc.y[truth], f, c, tol=2)
        alone.add(lone, lc.y[lone], f, c, tol=2)
        assert every.scores()["prec"] >= 0.95 and alone.scores()["recall"] >= 0.95, (f.tolist(), truth.tolist())
        assert len(f) >= len(truth) - crowded.sum(), (f.tolist(), truth.tolist())


def _peaks(T, spec, C=6, width=2):
    p = np.zeros((T, C))
    p[:, 0] = 1
    for t, c, v in spec:
        for d in range(-width, width + 1):
            p[t + d, c] = max(p[t + d, c], v * (1 - 0.2 * abs(d)))
    p[:, 0] = 1 - p[:, 1:].max(axis=1)
    return p


def test_decoder_enforces_alternating_hits_and_the_near_wall_rule():
    cs = ClassSet.load("padel6")
    near, far, wall = cs.index("player_near"), cs.index("player_far"), cs.index("wall_near")
    p = _peaks(200, [(20, near, 0.9), (60, near, 0.6), (100, far, 0.9), (140, wall, 0.8)])
    f, c = decode(p, 50.0, cs, DecodeParams(thresholds=0.3))
    assert list(zip(f.tolist(), c.tolist())) == [(20, near), (100, far), (140, wall)]
    p = _peaks(200, [(20, near, 0.9), (60, wall, 0.9)])  # wall_near right after a near hit: impossible
    f, c = decode(p, 50.0, cs, DecodeParams(thresholds=0.3))
    assert wall not in c.tolist()
    f, c = decode(p, 50.0, cs, DecodeParams(thresholds=0.3, use_rules=False))
    assert wall in c.tolist()


def test_decoder_min_gap_and_max_rate():
    cs = ClassSet.load("padel6")
    g = cs.index("ground_or_other_wall")
    p = _peaks(400, [(t, g, 0.5 + 0.01 * k) for k, t in enumerate(range(10, 390, 10))], width=1)
    f, _ = decode(p, 50.0, cs, DecodeParams(thresholds=0.3, max_rate=100, min_gap=1))
    assert len(f) == 38
    f, _ = decode(p, 50.0, cs, DecodeParams(thresholds=0.3, max_rate=2.0, min_gap=1))
    assert len(f) <= 16 and len(f) >= 10  # 8 s at 2 events/s
    assert f.min() >= 10 * (38 - len(f))  # the weakest (earliest) ones were dropped
    f, _ = decode(p, 50.0, cs, DecodeParams(thresholds=0.3, max_rate=100, min_gap=15))
    assert np.diff(f).min() >= 15


def test_tolerance_and_event_set_metrics():
    assert [tolerance_frames(f) for f in (25, 30, 50, 60)] == [1, 1, 2, 2]
    counts = EventCounts(("none", "a", "b"))
    counts.add([10, 20, 30], [1, 1, 2], [11, 24, 30, 40], [1, 1, 1, 2], tol=2)
    s = counts.scores()
    assert (s["n_gt"], s["n_pred"]) == (3, 4)
    assert np.isclose(s["recall"], 1 / 3) and np.isclose(s["prec"], 1 / 4) and np.isclose(s["acc"], 1 / 6)
    assert np.isclose(counts.scores(2)["recall"], 0.0)


def test_clip_features_shape_with_corners(padel_clips):
    from inference.court import load_court

    c = padel_clips[0]
    fc = FeatureConfig(corners=True)
    f = clip_features(c.ball, c.n_frames, c.fps, fc, camera=c.camera, court=load_court("padel"))
    assert f.shape == (round(c.n_frames * 50 / c.fps), fc.n_features)
    assert (f[:, 5:13] > 0).any()  # projected court corners present
    empty = BallTrack(np.arange(5), np.zeros(5), np.full((5, 2), np.nan))
    assert np.all(clip_features(empty, 5, 50.0, FeatureConfig()) == 0)
