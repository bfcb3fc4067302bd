"""Heatmap → candidates: weighted centroids, scores, threshold, empty maps, letterbox mapping, pooling."""
from __future__ import annotations

import numpy as np
import pytest

from inference.detection import FrameCandidates, Letterbox, PostprocessConfig, heatmap_to_candidates
from inference.detection.postprocess import heatmaps_to_candidates, pool_candidates, sigmoid


def two_blobs():
    """A (40, 60) map with two blobs of hand-set values and their exact centroids and sums."""
    hm = np.zeros((40, 60), np.float32)
    hm[10, 10:13] = [0.6, 0.9, 0.7]          # blob A: row 10, cols 10..12
    hm[11, 11] = 0.8                         # ... and row 11, col 11
    hm[30:32, 40:42] = [[0.55, 0.95], [0.65, 0.75]]   # blob B
    hm[5, 50] = 0.5                          # exactly the threshold: not a blob
    hm[20, 20] = 0.3                         # below
    a_w = np.array([0.6, 0.9, 0.7, 0.8], np.float32).astype(np.float64)
    a_x, a_y = np.array([10, 11, 12, 11]), np.array([10, 10, 10, 11])
    b_w = np.array([0.55, 0.95, 0.65, 0.75], np.float32).astype(np.float64)
    b_x, b_y = np.array([40, 41, 40, 41]), np.array([30, 30, 31, 31])
    expect = {name: ((w @ x / w.sum(), w @ y / w.sum()), w.sum(), len(w), (x.mean(), y.mean()))
              for name, w, x, y in (("A", a_w, a_x, a_y), ("B", b_w, b_x, b_y))}
    return hm, expect


def test_weighted_centroids_and_scores():
    hm, expect = two_blobs()
    xy, score, area = heatmap_to_candidates(hm)
    assert xy.shape == (2, 2) and score.shape == (2,) and area.tolist() == [4, 4]
    for i, name in enumerate(("A", "B")):                     # best score first: Σ 3.0 before Σ 2.9
        centre, total, _, _ = expect[name]
        np.testing.assert_allclose(xy[i], centre, atol=0.01)
        assert abs(xy[i] - np.array(centre)).max() < 1e-6       # in fact exact
        assert score[i] == pytest.approx(total, rel=1e-6)


def test_unweighted_is_mean_and_pixel_count():
    hm, expect = two_blobs()
    xy, score, _ = heatmap_to_candidates(hm, use_weights=False)
    assert score.tolist() == [4.0, 4.0]
    got = sorted(map(tuple, np.round(xy, 6)))
    assert got == sorted(tuple(np.round(e[3], 6)) for e in expect.values())


def test_matches_a_per_blob_loop_on_random_maps():
    """Same result as the straightforward per-label loop (np.where per blob), WASB's formulation."""
    import cv2
    rng = np.random.default_rng(3)
    hm = (rng.random((72, 128)) ** 6).astype(np.float32)
    hm = cv2.GaussianBlur(hm, (5, 5), 1.0) * 4
    xy, score, _ = heatmap_to_candidates(np.clip(hm, 0, 1), max_candidates=None)
    n, labels = cv2.connectedComponents((np.clip(hm, 0, 1) > 0.5).astype(np.uint8))
    ref = []
    for m in range(1, n):
        ys, xs = np.where(labels == m)
        w = np.clip(hm, 0, 1)[ys, xs].astype(np.float64)
        ref.append((w.sum(), (xs * w).sum() / w.sum(), (ys * w).sum() / w.sum()))
    ref.sort(key=lambda r: -r[0])
    assert len(ref) == len(score) > 3
    np.testing.assert_allclose(score, [r[0] for r in ref], rtol=1e-6)
    np.testing.assert_allclose(xy, [[r[1], r[2]] for r in ref], atol=1e-6)


def test_threshold_is_strict_and_tunable():
    hm = np.zeros((10, 10), np.float32)
    hm[2, 2] = 0.5
    hm[7, 7] = 0.4
    assert heatmap_to_candidates(hm).count == 0
    xy, _, _ = heatmap_to_candidates(hm, threshold=0.45)
    assert xy.tolist() == [[2.0, 2.0]]
    assert heatmap_to_candidates(hm, threshold=0.3).count == 2
    with pytest.raises(ValueError):
        heatmap_to_candidates(hm, threshold=1.0)


@pytest.mark.parametrize("hm", [np.zeros((288, 512), np.float32), np.full((5, 5), np.nan)])
def test_empty_maps(hm):
    xy, score, area = heatmap_to_candidates(hm)
    assert xy.shape == (0, 2) and score.shape == (0,) and area.shape == (0,)


def test_min_area_max_candidates_and_connectivity():
    hm = np.zeros((20, 20), np.float32)
    hm[1, 1] = hm[2, 2] = 0.9                # diagonal neighbours: one blob (8-conn), two (4-conn)
    hm[10:13, 10:13] = 0.8
    assert heatmap_to_candidates(hm).count == 2
    assert heatmap_to_candidates(hm, connectivity=4).count == 3
    assert heatmap_to_candidates(hm, min_area=3).area.tolist() == [9]
    assert heatmap_to_candidates(hm, connectivity=4, max_candidates=1).area.tolist() == [9]
    with pytest.raises(ValueError):
        heatmap_to_candidates(np.zeros((2, 3, 4)))


def _disk(h, w, centre, r=2.5, value=0.9):
    yy, xx = np.mgrid[0:h, 0:w]
    return np.where((xx - centre[0]) ** 2 + (yy - centre[1]) ** 2 <= r * r, value, 0.0).astype(np.float32)


@pytest.mark.parametrize("size", [(1280, 720), (640, 480), (1920, 1080)])
def test_batch_maps_back_to_original_pixels(size):
    box = Letterbox(*size)
    truth = np.array([[0.3 * size[0], 0.6 * size[1]], [0.8 * size[0], 0.1 * size[1]]])
    net = np.round(box.forward(truth))                      # integer grid centres: symmetric disks
    maps = np.stack([_disk(288, 512, c) for c in net] + [np.zeros((288, 512), np.float32)])
    out = heatmaps_to_candidates(maps, box)
    assert [c.count for c in out] == [1, 1, 0]
    for c, centre in zip(out, net):
        np.testing.assert_allclose(c.xy[0], box.inverse(centre), atol=0.01)


def test_batch_half_resolution_logits_and_padding():
    box = Letterbox(640, 480)                                # 64 px of padding each side at 512 wide
    logits = np.full((2, 144, 256), -8.0, np.float32)
    logits[0, 70:73, 100:103] = 8.0                          # inside the frame
    logits[1, 70:73, 5:8] = 8.0                              # in the left padding
    out = heatmaps_to_candidates(logits, box, from_logits=True)
    half = box.resized(256, 144)
    np.testing.assert_allclose(out[0].xy, half.inverse([[101, 71]]), atol=0.01)
    assert out[1].count == 0
    assert heatmaps_to_candidates(logits, box, from_logits=True, drop_outside=False)[1].count == 1
    cfg = PostprocessConfig(use_weights=False)
    assert heatmaps_to_candidates(logits, box, cfg, from_logits=True)[0].score.tolist() == [9.0]
    assert sigmoid(np.array([0.0]))[0] == 0.5


def test_pool_candidates():
    a = FrameCandidates.from_arrays([[10, 10], [50, 50]], [3.0, 1.0])
    b = FrameCandidates.from_arrays([[10.5, 10], [90, 90]], [4.0, 2.0])
    pooled = pool_candidates([a, b])
    assert pooled.score.tolist() == [4.0, 3.0, 2.0, 1.0]
    merged = pool_candidates([a, b], merge_radius=2.0)
    assert merged.score.tolist() == [4.0, 2.0, 1.0] and merged.xy[0].tolist() == [10.5, 10]
    assert pool_candidates([a, b], max_candidates=2).count == 2
    assert pool_candidates([]).count == 0
    with pytest.raises(ValueError):
        FrameCandidates.from_arrays([[1, 2]], [1.0, 2.0])
