"""The offline passes of ``track_candidates``: backward pass, gap filling, and what they must not take.

Constructed candidate sequences (1280×720, 30 fps, original pixels): a ball in a parabola whose start the
detector sees only every fourth frame (too sparse for a forward birth), a still ball lying on court, a
brighter mirror image of the ball below a floor line, clutter.
"""
from __future__ import annotations

import numpy as np
import pytest

from inference.detection import FrameCandidates, TrackerConfig, TrackState, track_candidates
from inference.detection.tracker import TrackResult, fill_gaps, merge_backward

W, H, FPS = 1280, 720, 30.0
STILL = np.array([900.0, 650.0])


def parabola(n: int, start=(200.0, 300.0), velocity=(450.0, -300.0), gravity: float = 900.0) -> np.ndarray:
    t = np.arange(n)[:, None] / FPS
    return np.asarray(start) + np.asarray(velocity) * t + 0.5 * np.array([0.0, gravity]) * t ** 2


def frames_with(path: np.ndarray, seen: np.ndarray, rng, still: bool = True, clutter: float = 0.0,
                score=(2.0, 6.0)) -> list[FrameCandidates]:
    """Per frame: the ball where ``seen`` (weak scores), the still ball, random clutter."""
    out = []
    for t, p in enumerate(path):
        xy, sc = [], []
        if seen[t]:
            xy.append(p + rng.normal(0, 0.5, 2))
            sc.append(rng.uniform(*score))
        if still:
            xy.append(STILL + rng.normal(0, 0.3, 2))
            sc.append(rng.uniform(5, 9))
        if rng.random() < clutter:
            xy.append(rng.uniform([0, 0], [W, H]))
            sc.append(rng.uniform(1, 6))
        out.append(FrameCandidates.from_arrays(np.reshape(xy, (-1, 2)), sc))
    return out


def sparse_start(n: int = 60, sparse: int = 15) -> np.ndarray:
    """Seen every fourth frame for the first ``sparse`` frames, then every frame."""
    seen = np.ones(n, bool)
    seen[:sparse] = np.arange(sparse) % 4 == 0
    return seen


def hits(result: TrackResult, path: np.ndarray, frames, tol: float = 3.0) -> int:
    frames = np.asarray(list(frames))
    ok = result.state[frames] == TrackState.DETECTED
    return int(np.sum(ok & (np.linalg.norm(result.xy[frames] - path[frames], axis=1) < tol)))


def test_backward_pass_recovers_a_weak_start_before_the_birth():
    rng = np.random.default_rng(0)
    path, seen = parabola(60), sparse_start()
    cands = frames_with(path, seen, rng, clutter=0.1)
    early = np.flatnonzero(seen[:15])                                   # frames 0, 4, 8, 12
    forward = track_candidates(cands, FPS, TrackerConfig(backward_pass=False), image_size=(W, H))
    both = track_candidates(cands, FPS, image_size=(W, H))
    assert hits(forward, path, early) <= 1                              # too sparse for a forward birth
    assert hits(both, path, early) == len(early)                        # followed backwards from later on
    assert hits(both, path, np.flatnonzero(seen)) == seen.sum()         # and every seen frame is the ball
    assert not (np.linalg.norm(both.xy - STILL, axis=1) < 10).any()     # the still ball never is


def test_reversed_clip_gives_the_mirror_result():
    """The backward pass is the forward pass of the reversed clip: a weak *end* is recovered too."""
    rng = np.random.default_rng(1)
    path, seen = parabola(60), sparse_start()[::-1]
    cands = frames_with(path, seen, rng)
    late = np.flatnonzero(seen[-15:]) + 45                             # seen every fourth frame
    both = track_candidates(cands, FPS, image_size=(W, H))
    assert hits(both, path, late) == len(late)


def test_brighter_reflection_at_the_end_of_a_flight_is_not_taken():
    """The ball falls to a floor line (y = 600) and its mirror image below it is brighter; the backward
    pass is born on the pair, but the forward pass flagged the image as a reflection: it is vetoed."""
    rng = np.random.default_rng(2)
    floor = 600.0
    path = parabola(40, start=(200.0, 420.0), velocity=(300.0, -100.0))
    path = path[path[:, 1] < floor - 3]
    n = len(path)
    cands = []
    for t, p in enumerate(path):
        xy, sc = [p + rng.normal(0, 0.4, 2)], [4.0]
        if floor - p[1] < 120:                                          # near the floor: its mirror image
            xy.append([p[0], 2 * floor - p[1]])
            sc.append(8.0)
        cands.append(FrameCandidates.from_arrays(xy, sc))
    result = track_candidates(cands, FPS, image_size=(W, H))
    shown = result.state == TrackState.DETECTED
    assert shown.sum() >= n - 2
    assert np.all(np.linalg.norm(result.xy[shown] - path[shown], axis=1) < 3)   # never the image


def test_a_lone_still_ball_is_rejected_in_both_directions():
    rng = np.random.default_rng(3)
    cands = [FrameCandidates.from_arrays([STILL + rng.normal(0, 0.3, 2)], [8.0]) for _ in range(90)]
    assert not track_candidates(cands, FPS, image_size=(W, H)).visible.any()


def test_fill_gaps_takes_the_clean_candidate_on_the_path():
    D, N = TrackState.DETECTED, TrackState.NONE
    state = np.array([D, N, N, N, D, N, N, N, N, N, N, N, N, D], np.int8)
    xy = np.full((14, 2), np.nan)
    xy[0], xy[4], xy[13] = [100, 100], [140, 100], [300, 100]
    res = TrackResult(state, xy, np.where(state == D, 1.0, 0.0), np.where(state == D, 7, -1))
    cands = [FrameCandidates.empty() for _ in range(14)]
    cands[1] = FrameCandidates.from_arrays([[500, 500], [111, 101]], [9.0, 1.0])     # clutter, the ball
    cands[2] = FrameCandidates.from_arrays([[120, 100], [160, 100]], [1.0, 9.0])     # flagged ball, far one
    cands[3] = FrameCandidates.from_arrays([[131, 98]], [2.0])
    cands[8] = FrameCandidates.from_arrays([[220, 100]], [2.0])                      # gap of 8: too long
    flagged = [np.zeros(c.count, bool) for c in cands]
    flagged[2][0] = True
    fill_gaps(res, cands, flagged, max_gap=6, radius=20.0)
    assert res.state.tolist()[:5] == [D, D, N, D, D]
    assert res.xy[1].tolist() == [111, 101] and res.xy[3].tolist() == [131, 98] and res.track_id[1] == 7
    assert res.state[8] == N


def test_merge_backward_fills_only_undetected_unflagged_frames():
    D, C, N = TrackState.DETECTED, TrackState.COASTED, TrackState.NONE
    fwd = TrackResult(np.array([N, C, D, N], np.int8), np.array([[np.nan] * 2, [5, 5], [9, 9], [np.nan] * 2]),
                      np.array([0, 0.5, 1, 0]), np.array([-1, 0, 0, -1]))
    back = TrackResult(np.array([D, D, D, D], np.int8), np.array([[1, 1], [4, 4], [8, 8], [50, 50]], float),
                       np.ones(4), np.zeros(4, np.int64))
    cands = [FrameCandidates.from_arrays([[1, 1]], [1.0]), FrameCandidates.from_arrays([[4, 4]], [1.0]),
             FrameCandidates.from_arrays([[8, 8], [9, 9]], [1.0, 1.0]),
             FrameCandidates.from_arrays([[50, 50]], [1.0])]
    flagged = [np.array([False]), np.array([False]), np.array([False, False]), np.array([True])]
    merge_backward(fwd, back, cands, flagged)
    assert fwd.state.tolist() == [D, D, D, N]                            # frame 3: a flagged candidate
    assert fwd.xy[:3].tolist() == [[1, 1], [4, 4], [9, 9]]               # a forward detection is kept
    assert fwd.track_id.tolist() == [1, 1, 0, -1]                        # backward ids shifted past 0


@pytest.mark.parametrize("fps", [25.0, 60.0])
def test_offline_passes_keep_the_empty_clip_empty(fps):
    assert len(track_candidates([], fps)) == 0
    empty = track_candidates([FrameCandidates.empty()] * 10, fps, image_size=(W, H))
    assert not empty.visible.any()
