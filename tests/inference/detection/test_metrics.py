"""Detection metrics: each outcome, τ boundary, visibility flags, ignored frames, AP, RMSE, tables."""
from __future__ import annotations

import numpy as np
import pytest

from inference.clipio.tables import BallTrack
from inference.detection import (
    DetectionCounts,
    Outcome,
    TableRow,
    average_precision,
    classify_frames,
    evaluate_ball_tracks,
    evaluate_detections,
    format_table,
)

NAN2 = [np.nan, np.nan]


def test_each_outcome():
    pred_vis = [True, True, False, True, False]
    pred_xy = [[100, 100], [100, 100], NAN2, [5, 5], NAN2]
    gt_vis = [1, 1, 1, 0, 0]
    gt_xy = [[102, 100], [110, 100], [50, 50], NAN2, NAN2]
    outcome, dist = classify_frames(pred_vis, pred_xy, gt_vis, gt_xy, tau_px=4)
    assert outcome.tolist() == [Outcome.TP, Outcome.FP1, Outcome.FN, Outcome.FP2, Outcome.TN]
    np.testing.assert_allclose(dist, [2, 10, np.nan, np.nan, np.nan])
    r = evaluate_detections(pred_vis, pred_xy, None, gt_vis, gt_xy, tau_px=4)
    assert r.counts == DetectionCounts(tp=1, fp1=1, fp2=1, fn=1, tn=1)
    assert r.precision == pytest.approx(1 / 3) and r.recall == pytest.approx(1 / 2)
    assert r.f1 == pytest.approx(2 * (1 / 3) * (1 / 2) / (1 / 3 + 1 / 2))
    assert r.accuracy == pytest.approx(2 / 5)
    assert r.rmse_px == pytest.approx(np.sqrt((4 + 100) / 2))       # over TP + FP1
    assert r.space == "original-frame px" and r.tau_px == 4.0


def test_tau_boundary_is_strict():
    gt = [[100.0, 100.0]] * 3
    pred = [[103.999, 100.0], [104.0, 100.0], [100.0, 96.0]]
    outcome, _ = classify_frames([True] * 3, pred, [1, 1, 1], gt, tau_px=4.0)
    assert outcome.tolist() == [Outcome.TP, Outcome.FP1, Outcome.FP1]
    outcome, _ = classify_frames([True] * 3, pred, [1, 1, 1], gt, tau_px=10.0)
    assert (outcome == Outcome.TP).all()


def test_visible_flags_and_ignored_codes():
    codes = [0, 1, 2, 3, -1]
    xy = [NAN2, [10, 10], [10, 10], [10, 10], [10, 10]]
    pred_all = ([True] * 5, [[10, 10]] * 5)
    # default {1, 2}: code 3 counts as absent (WASB tennis), code -1 (no ground-truth row) is ignored
    out, _ = classify_frames(*pred_all, codes, xy, 4)
    assert out.tolist() == [Outcome.FP2, Outcome.TP, Outcome.TP, Outcome.FP2, Outcome.IGNORED]
    out, _ = classify_frames(*pred_all, codes, xy, 4, visible_flags={1})
    assert out.tolist() == [Outcome.FP2, Outcome.TP, Outcome.FP2, Outcome.FP2, Outcome.IGNORED]
    out, _ = classify_frames(*pred_all, codes, xy, 4, visible_flags={1, 2, 3})
    assert out.tolist() == [Outcome.FP2, Outcome.TP, Outcome.TP, Outcome.TP, Outcome.IGNORED]
    out, _ = classify_frames(*pred_all, codes, xy, 4, ignore_flags={3})
    assert out.tolist() == [Outcome.FP2, Outcome.TP, Outcome.TP, Outcome.IGNORED, Outcome.IGNORED]
    r = evaluate_detections(*pred_all, None, codes, xy, 4, ignore_flags={3})
    assert r.counts.total == 3


def test_perfect_detector_has_ap_one():
    rng = np.random.default_rng(0)
    gt_vis = rng.integers(0, 2, 200)
    gt_xy = np.where(gt_vis[:, None] > 0, rng.uniform(0, 1000, (200, 2)), np.nan)
    r = evaluate_detections(gt_vis > 0, gt_xy, rng.random(200), gt_vis, gt_xy, tau_px=4)
    assert r.ap == 1.0 and r.f1 == 1.0 and r.accuracy == 1.0 and r.rmse_px == 0.0


def wasb_ap(scores, ys, n_positive):
    """WASB-SBDT's AP loop, written out as the reference."""
    inds = np.argsort(-np.asarray(scores), kind="stable")
    tp, r2p = 0, {}
    for i, ind in enumerate(inds, start=1):
        tp += ys[ind]
        p, r = tp / i, tp / n_positive
        r2p[r] = max(r2p.get(r, 0.0), p)
    ap, prev = 0.0, 0.0
    for r, p in r2p.items():
        ap += (r - prev) * p
        prev = r
    return ap


def test_ap_by_hand_and_against_the_reference_loop():
    # ranked: TP, FP, TP, FP with 3 positives → recall 1/3 @ p 1, 2/3 @ p 2/3 → AP = 1/3 + 1/3 · 2/3
    assert average_precision([0.9, 0.8, 0.7, 0.6], [1, 0, 1, 0], 3) == pytest.approx(1 / 3 + 2 / 9)
    assert average_precision([0.9, 0.8], [0, 0], 3) == 0.0
    assert average_precision([], [], 0) == 0.0
    rng = np.random.default_rng(1)
    for _ in range(20):
        n = int(rng.integers(1, 60))
        scores, ys = rng.integers(0, 5, n).astype(float), rng.integers(0, 2, n)   # with ties
        n_pos = int(ys.sum() + rng.integers(0, 5))
        if n_pos:
            assert average_precision(scores, ys, n_pos) == pytest.approx(wasb_ap(scores, ys, n_pos))


def test_ap_ranks_by_score():
    gt_xy = [[10, 10], [20, 20], NAN2]
    pred_xy = [[10, 10], [40, 40], [5, 5]]     # TP, FP1, FP2
    good = evaluate_detections([True] * 3, pred_xy, [0.9, 0.1, 0.2], [1, 1, 0], gt_xy, 4)
    bad = evaluate_detections([True] * 3, pred_xy, [0.1, 0.9, 0.8], [1, 1, 0], gt_xy, 4)
    # recall's denominator is TP + FN = 1 (FP1 is not in it): AP = precision at the TP's rank
    assert good.ap == pytest.approx(1.0) and bad.ap == pytest.approx(1 / 3)


def test_ball_tracks_are_aligned_by_frame_and_measured_in_pixels():
    W, H = 1280, 720
    gt = BallTrack.from_pixels([0, 1, 2, 5], [1, 1, 0, 1], [[640, 360], [100, 100], NAN2, [10, 10]], W, H)
    # pred: frame 0 is 3 px off, frame 1 has no row (= no ball), frame 2 FP2, frame 3 has no gt row
    pred = BallTrack.from_pixels([0, 2, 3, 5], [1, 1, 1, 1], [[643, 360], [5, 5], [7, 7], [10, 30]], W, H)
    r = evaluate_ball_tracks(pred, gt, W, H, pred_score=[0.9, 0.5, 0.4, 0.3], tau_px=4)
    assert r.counts == DetectionCounts(tp=1, fp1=1, fp2=1, fn=1, tn=0)
    assert r.rmse_px == pytest.approx(np.sqrt((9 + 400) / 2))
    assert "1280×720" in r.space
    assert evaluate_ball_tracks(BallTrack.empty(), gt, W, H).counts == DetectionCounts(fn=3, tn=1)


def test_counts_add_and_ratios_when_empty():
    a, b = DetectionCounts(1, 2, 3, 4, 5), DetectionCounts(1, 1, 1, 1, 1)
    assert a + b == DetectionCounts(2, 3, 4, 5, 6)
    assert DetectionCounts().f1 == 0.0 and DetectionCounts().accuracy == 0.0


def test_format_table_states_tau_and_space():
    gt_xy = [[10, 10], [20, 20]]
    r = evaluate_detections([True, False], gt_xy, [1.0, 0.0], [1, 1], gt_xy, tau_px=4)
    table = format_table([TableRow("WASB", r, 120.0), ("max-score", r)], counts=True)
    lines = table.splitlines()
    assert lines[0].startswith("τ = 4 px in original-frame px")
    assert lines[2].startswith("| Method | F1 (%) | Acc (%) | AP (%) | Precision (%) | Recall (%) |")
    assert "| WASB | 66.67 | 50.00 | 50.00 | 100.00 | 50.00 | 0.00 | 120.0 | 1 | 0 | 0 | 1 | 0 |" in lines
    assert lines[-1].startswith("| max-score |") and "| – |" in lines[-1]
    other = evaluate_detections([True], [[10, 10]], None, [1], [[10, 10]], tau_px=10)
    with pytest.raises(ValueError, match="different τ"):
        format_table([("a", r), ("b", other)])
