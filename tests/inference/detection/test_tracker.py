"""Ball tracker on synthetic candidate sequences, against WASB's max-score tracker on the same input.

The synthetic clip (1280×720, 30 fps, original pixels): the ball flies in parabolas (image gravity),
bounces on a floor line (y = 600) and is hit once; a still ball lies on court (a static false candidate
in most frames, scoring like the ball); near the floor the mirror image of the ball across the floor line
appears (a reflection, sometimes scoring higher than the ball); random clutter; the detector misses the
ball in some frames; a 3-frame occlusion; then 50 frames with the ball out of the frame before a second
flight.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from inference.clipio.tables import InactiveBalls
from inference.detection import (
    BallTracker,
    FrameCandidates,
    TrackerConfig,
    TrackState,
    evaluate_detections,
    format_table,
    inactive_positions,
    max_score_track,
    track_candidates,
)
from inference.detection.tracker import (
    ConstantAcceleration,
    StaticMemory,
    TrackResult,
    claim_free_frames,
    drop_unclosed_coasts,
    mirror_pairs,
    reflection_flags,
)

W, H, FPS = 1280, 720, 30.0
FLOOR_Y = 600.0
STATIC_XY = np.array([900.0, 640.0])
GRAVITY = 900.0                 # px/s², image rows grow downwards
OCCLUDED = range(40, 43)        # behind a player: visibility 3, no candidate
OUT_OF_FRAME = range(120, 170)
SECOND_FLIGHT = 170


# ------------------------------------------------------------------------------------ synthetic clip
@dataclass
class Rally:
    candidates: list[FrameCandidates]
    gt_visibility: np.ndarray   # (T,) 0 out of frame, 1 visible, 3 occluded
    gt_xy: np.ndarray           # (T, 2), NaN where visibility 0
    reflection_xy: np.ndarray   # (T, 2), NaN where there is no reflection candidate
    detected: np.ndarray        # (T,) bool: the ball has a candidate
    reflection_wins: np.ndarray  # (T,) bool: the reflection out-scores the detected ball

    def evaluate(self, result: TrackResult, tau_px: float = 4.0):
        """Occluded frames (3) are left out: whether to report an estimate there is a separate choice."""
        return evaluate_detections(result.visible, result.xy, result.score, self.gt_visibility, self.gt_xy,
                                   tau_px=tau_px, ignore_flags={3})


def ball_path(n: int, start, velocity, fps: float = FPS, hit_at: int | None = None, hit_velocity=None):
    """(n, 2) positions: ballistic flight, bounces on FLOOR_Y (restitution 0.7), one hit at ``hit_at``."""
    dt, g = 1.0 / fps, np.array([0.0, GRAVITY])
    p, v = np.array(start, float), np.array(velocity, float)
    out = np.empty((n, 2))
    for i in range(n):
        out[i] = p
        if i == hit_at:
            v = np.array(hit_velocity, float)
        p, v = p + v * dt + 0.5 * g * dt * dt, v + g * dt
        if p[1] > FLOOR_Y:
            p[1], v[1] = 2 * FLOOR_Y - p[1], -0.7 * v[1]
    return out


def frame_candidates(rng, ball_xy, reflection_xy, static: bool, clutter_rate: float
                     ) -> tuple[FrameCandidates, bool]:
    """One frame: the ball, its reflection, the still ball and clutter, as a detector would give them;
    and whether the reflection out-scores the detected ball."""
    xy, score = [], []
    ball_score = rng.uniform(3, 10)
    if ball_xy is not None:
        xy.append(ball_xy + rng.normal(0, 0.7, 2))
        score.append(ball_score)
    if reflection_xy is not None:
        xy.append(reflection_xy)
        score.append(ball_score * rng.uniform(0.5, 1.4))
    if static:
        xy.append(STATIC_XY + rng.normal(0, 0.4, 2))
        score.append(rng.uniform(4, 10))
    if rng.random() < clutter_rate:
        xy.append(rng.uniform([0, 0], [W, H]))
        score.append(rng.uniform(1, 6))
    order = np.argsort(-np.asarray(score))
    wins = ball_xy is not None and reflection_xy is not None and score[1] > score[0]
    return FrameCandidates.from_arrays(np.reshape(xy, (-1, 2))[order], np.asarray(score)[order]), wins


def make_rally(seed: int = 0, miss_rate: float = 0.08, clutter_rate: float = 0.1) -> Rally:
    rng = np.random.default_rng(seed)
    T = 240
    gt_xy = np.full((T, 2), np.nan)
    gt_xy[:OUT_OF_FRAME.start] = ball_path(120, (150, 380), (420, -150), hit_at=75, hit_velocity=(-520, -650))
    gt_xy[SECOND_FLIGHT:] = ball_path(T - SECOND_FLIGHT, (1150, 200), (-420, 60))
    vis = np.where(np.isnan(gt_xy[:, 0]), 0, 1).astype(np.int8)
    vis[list(OCCLUDED)] = 3
    detected = (vis == 1) & (rng.random(T) > miss_rate)
    height = FLOOR_Y - gt_xy[:, 1]
    has_reflection = (vis == 1) & (height > 4) & (height < 150)
    refl = np.where(has_reflection[:, None], np.stack([gt_xy[:, 0], 2 * FLOOR_Y - gt_xy[:, 1]], 1), np.nan)
    refl[has_reflection] += rng.normal(0, 0.7, (has_reflection.sum(), 2))
    frames = [frame_candidates(rng, gt_xy[t] if detected[t] else None,
                               refl[t] if has_reflection[t] else None, rng.random() < 0.9, clutter_rate)
              for t in range(T)]
    return Rally([f[0] for f in frames], vis, gt_xy, refl, detected, np.array([f[1] for f in frames]))


@pytest.fixture(scope="module")
def rally():
    return make_rally(0)


@pytest.fixture(scope="module")
def tracked(rally):
    return track_candidates(rally.candidates, FPS, image_size=(W, H))


# ------------------------------------------------------------------------------- tracker vs max-score
@pytest.mark.parametrize("seed", range(5))
def test_tracker_beats_max_score(seed):
    r = make_rally(seed)
    ours, base = r.evaluate(track_candidates(r.candidates, FPS, image_size=(W, H))), r.evaluate(
        max_score_track(r.candidates))
    assert ours.f1 >= 0.95 and ours.ap >= 0.9
    assert base.f1 <= 0.7
    assert ours.f1 - base.f1 >= 0.3


def test_summary_table(capsys):
    """Seed 0 as a table and the mean F1 over 10 clips (pytest -s shows them)."""
    rows = {"tracker": [], "max-score (WASB)": []}
    for seed in range(10):
        r = make_rally(seed)
        rows["tracker"].append(r.evaluate(track_candidates(r.candidates, FPS, image_size=(W, H))))
        rows["max-score (WASB)"].append(r.evaluate(max_score_track(r.candidates)))
    first = {k: v[0] for k, v in rows.items()}
    print(format_table(list(first.items()), counts=True))
    mean_f1 = {k: np.mean([rep.f1 for rep in v]) for k, v in rows.items()}
    print({k: round(v, 3) for k, v in mean_f1.items()})
    assert mean_f1["tracker"] > 0.97 > 0.6 > mean_f1["max-score (WASB)"]


@pytest.mark.parametrize("miss_rate, clutter_rate", [(0.2, 0.3), (0.0, 0.0)])
def test_harder_and_easier_inputs(miss_rate, clutter_rate):
    rallies = [make_rally(seed, miss_rate, clutter_rate) for seed in range(5)]
    f1 = [r.evaluate(track_candidates(r.candidates, FPS, image_size=(W, H))).f1 for r in rallies]
    assert min(f1) >= (0.99 if miss_rate == 0 else 0.9)


# --------------------------------------------------------------------------------- specific behaviours
def test_ignores_the_still_ball(rally, tracked):
    assert np.linalg.norm(rally.gt_xy - STATIC_XY, axis=1)[rally.gt_visibility > 0].min() > 30
    near_static = np.linalg.norm(tracked.xy - STATIC_XY, axis=1) < 10
    assert not near_static.any()
    base = max_score_track(rally.candidates)
    assert (np.linalg.norm(base.xy - STATIC_XY, axis=1) < 10).sum() > 20   # the baseline takes it often


def test_follows_the_ball_not_its_reflection(rally, tracked):
    has = ~np.isnan(rally.reflection_xy[:, 0])
    assert has.sum() > 30
    d_ball = np.linalg.norm(tracked.xy - rally.gt_xy, axis=1)
    d_refl = np.linalg.norm(tracked.xy - rally.reflection_xy, axis=1)
    assert not np.any(has & tracked.visible & (d_refl < d_ball))
    assert rally.reflection_wins.sum() >= 5      # though the reflection out-scores the ball in these frames
    base = max_score_track(rally.candidates)
    assert np.sum(has & (np.linalg.norm(base.xy - rally.reflection_xy, axis=1) < 4)) >= 5


def test_short_occlusion_is_bridged(rally, tracked):
    frames = list(OCCLUDED)
    assert (tracked.state[frames] == TrackState.COASTED).all()
    err = np.linalg.norm(tracked.xy[frames] - rally.gt_xy[frames], axis=1)
    assert err.max() < 6.0
    ids = tracked.track_id[frames[0] - 1: frames[-1] + 2]
    assert len(set(ids.tolist())) == 1 and ids[0] >= 0          # same track before, during and after
    ball = tracked.to_ball_track(W, H)
    assert (ball.visibility[frames] == 3).all()                  # "occluded, estimated position"
    assert (tracked.to_ball_track(W, H, coast_visibility=0).visibility[frames] == 0).all()


def test_long_gap_reports_no_ball_then_reinitialises(rally, tracked):
    gap = list(OUT_OF_FRAME)
    assert (tracked.state[gap] == TrackState.NONE).all()
    assert (tracked.to_ball_track(W, H).visibility[gap] == 0).all()
    first_flight = slice(0, OUT_OF_FRAME.start)
    before = tracked.track_id[first_flight][tracked.visible[first_flight]][-1]
    after = tracked.track_id[SECOND_FLIGHT + 5]
    assert before >= 0 and after >= 0 and before != after       # a new track for the new ball
    detected_second = rally.detected[SECOND_FLIGHT:]
    reported_second = tracked.state[SECOND_FLIGHT:] == TrackState.DETECTED
    assert reported_second[:5].sum() >= detected_second[:5].sum() - 1   # back-filled from the birth


def test_online_mode_coasts_then_gives_up(rally):
    cfg = TrackerConfig(drop_trailing_coast=False)
    online = track_candidates(rally.candidates, FPS, cfg, image_size=(W, H))
    gap = np.array(OUT_OF_FRAME)
    coasted = online.state[gap] == TrackState.COASTED
    max_gap = cfg.frames(cfg.max_gap_s, FPS)
    assert 1 <= coasted.sum() <= max_gap and not coasted[max_gap:].any()


def test_result_to_ball_track_codes(tracked):
    ball = tracked.to_ball_track(W, H, first_frame=10)
    assert ball.frame[0] == 10 and len(ball) == len(tracked)
    assert set(np.unique(ball.visibility).tolist()) <= {0, 1, 3}
    np.testing.assert_allclose(ball.to_pixels(W, H)[ball.visibility == 1],
                               tracked.xy[tracked.state == TrackState.DETECTED])
    assert tracked.score[tracked.state == TrackState.NONE].max() == 0.0


@pytest.mark.parametrize("fps", [25.0, 60.0, 120.0])
def test_frame_rate_aware(fps):
    rng = np.random.default_rng(int(fps))
    n = int(3 * fps)
    path = ball_path(n, (100, 300), (380, -250), fps=fps, hit_at=int(1.8 * fps), hit_velocity=(-400, -500))
    detected = rng.random(n) > 0.1
    cands = [frame_candidates(rng, path[t] if detected[t] else None, None, True, 0.05)[0] for t in range(n)]
    result = track_candidates(cands, fps, image_size=(W, H))
    rep = evaluate_detections(result.visible, result.xy, result.score, np.ones(n, int), path, tau_px=4)
    assert rep.f1 >= 0.95
    assert not (np.linalg.norm(result.xy - STATIC_XY, axis=1) < 10).any()


def test_reflection_from_the_start_with_a_glass_line():
    """No track yet and a brighter mirror image below the floor line: with the line known, the upper wins."""
    rng = np.random.default_rng(5)
    path = np.stack([np.linspace(300, 500, 30), 560 + 0.3 * (np.arange(30) - 15.0) ** 2 / 10], axis=1)
    mirror = path * [1, -1] + [0, 2 * FLOOR_Y]
    cands = [FrameCandidates.from_arrays(np.stack([p + rng.normal(0, 0.5, 2), m]), [4.0, 8.0])
             for p, m in zip(path, mirror)]
    cfg = TrackerConfig(glass_lines_y=(FLOOR_Y,))
    result = track_candidates(cands, FPS, cfg, image_size=(W, H))
    ok = result.visible
    assert ok.sum() >= 27
    assert np.all(np.linalg.norm(result.xy[ok] - path[ok], axis=1) < 3)


def test_known_inactive_balls_are_never_tracked():
    """A still ball whose detections jitter (so it looks like it moves) is ignored once it is known."""
    rng = np.random.default_rng(2)
    n = 90
    still = np.array([400.0, 500.0])
    cands = [FrameCandidates.from_arrays([still + rng.normal(0, 2.0, 2)], [9.0]) for _ in range(n)]
    inactive = InactiveBalls(np.arange(n), np.zeros(n, int), np.tile(still / [W, H], (n, 1)))
    static_xy = inactive_positions(inactive, n, W, H)
    assert len(static_xy) == n and np.allclose(static_xy[0], [still])
    cfg = TrackerConfig(static_radius_px=8.0)
    result = track_candidates(cands, FPS, cfg, image_size=(W, H), static_xy=static_xy)
    assert not result.visible.any()


def test_empty_and_bad_input():
    tracker = BallTracker(FPS)
    est = tracker.update(np.empty((0, 2)), np.empty(0))
    assert est.state == TrackState.NONE and np.isnan(est.xy).all()
    assert len(track_candidates([], FPS)) == 0
    with pytest.raises(ValueError):
        BallTracker(0.0)
    with pytest.raises(ValueError):
        tracker.update([[1.0, 2.0]], [1.0, 2.0])


# -------------------------------------------------------------------------------------------- parts
def test_constant_acceleration_filter_learns_a_parabola():
    dt = 1 / 30
    f = ConstantAcceleration(dt, jerk_std=1e3, meas_std=0.1)
    t = np.arange(20) * dt
    path = np.stack([100 + 300 * t, 200 - 400 * t + 0.5 * 900 * t ** 2], axis=1)
    f.start(path[0], (0, 0), 0.1, 2000, 3000)
    for z in path[1:]:
        f.predict()
        f.update(z)
    f.predict()
    t_next = 20 * dt
    np.testing.assert_allclose(f.position, [100 + 300 * t_next, 200 - 400 * t_next + 450 * t_next ** 2],
                               atol=0.1)
    np.testing.assert_allclose(f.x[2], [0, 900], atol=20)


def test_static_memory():
    mem = StaticMemory(radius=3.0, min_frames=5, forget_frames=10)
    flags = [mem.observe(np.array([[50.0, 50.0], [10.0 * t, 0.0]]), t) for t in range(8)]
    assert [f[0] for f in flags] == [False] * 4 + [True] * 4        # static after 5 sightings
    assert not any(f[1] for f in flags)                             # a moving candidate never is
    assert not mem.observe(np.array([[50.0, 50.0]]), 30)[0]          # forgotten after a long absence


def test_mirror_pairs_and_reflection_flags():
    xy = np.array([[100.0, 500.0], [101.0, 700.0], [400.0, 300.0]])   # mid-row of the pair: 600
    pairs = mirror_pairs(xy, dx_max=6, dy_min=6)
    assert pairs.tolist() == [[False, True, False], [True, False, False], [False, False, False]]
    assert reflection_flags(xy, 450.0, pairs).tolist() == [False, True, False]     # track above
    assert reflection_flags(xy, 750.0, pairs).tolist() == [True, False, False]     # track below
    assert reflection_flags(xy, -np.inf, pairs).tolist() == [False, True, False]   # prefer upper
    assert not mirror_pairs(xy, 6, 6, lines_y=(300.0,), line_tol=10).any()           # not about a line


def test_drop_unclosed_coasts():
    D, C, N = TrackState.DETECTED, TrackState.COASTED, TrackState.NONE
    state = np.array([D, C, C, D, C, C, N, D, C], np.int8)
    tid = np.array([0, 0, 0, 0, 0, 0, -1, 1, 1])
    res = TrackResult(state, np.zeros((9, 2)), np.ones(9), tid)
    drop_unclosed_coasts(res)
    assert res.state.tolist() == [D, C, C, D, N, N, N, D, N]
    assert np.isnan(res.xy[[4, 5, 8]]).all() and (res.track_id[[4, 5, 8]] == -1).all()


def test_max_score_baseline_is_wasb_online():
    cands = [FrameCandidates.from_arrays([[0, 0], [500, 0]], [1.0, 2.0]),      # best: (500, 0)
             FrameCandidates.from_arrays([[450, 0], [900, 0]], [1.0, 5.0]),    # 900 is 400 px away: gated
             FrameCandidates.empty(),
             FrameCandidates.from_arrays([[0, 0], [900, 0]], [1.0, 5.0])]      # no previous: best score
    res = max_score_track(cands)
    assert res.xy[[0, 1, 3]].tolist() == [[500, 0], [450, 0], [900, 0]]
    assert res.state.tolist() == [1, 1, 0, 1]


def test_config_scales_with_the_frame_height():
    cfg = TrackerConfig().for_image_height(1080)
    assert cfg.static_radius_px == pytest.approx(4.5) and cfg.max_speed_px_s == pytest.approx(6000)
    assert cfg.gate_chi2 == TrackerConfig().gate_chi2 and cfg.for_image_height(1080) is cfg
    assert TrackerConfig(reference_height=None).for_image_height(1080).static_radius_px == 3.0


def test_claim_free_frames_answers_with_unflagged_candidates_only():
    from dataclasses import replace

    # a ball jumping about at random rarely confirms a track: the tracker alone reports little
    rng = np.random.default_rng(3)
    T = 60
    ball = rng.uniform([100, 100], [1100, 600], (T, 2))
    cands = [FrameCandidates.from_arrays(np.stack([ball[t], STATIC_XY]), np.array([4.0, 9.0])) for t in range(T)]
    plain = track_candidates(cands, FPS, image_size=(W, H))
    assert (plain.state == TrackState.DETECTED).mean() < 0.25
    claimed = track_candidates(cands, FPS, replace(TrackerConfig(), claim_min_score=1.0), image_size=(W, H))
    det = claimed.state == TrackState.DETECTED
    # the still ball out-scores the moving one, but once the static memory knows it, it is vetoed
    settled = np.arange(T) > FPS  # static_min_s = 0.5 s plus margin
    assert det[settled].all()
    assert np.allclose(claimed.xy[settled], ball[settled])
    # a minimum score above every candidate's claims nothing
    strict = track_candidates(cands, FPS, replace(TrackerConfig(), claim_min_score=10.0), image_size=(W, H))
    assert np.array_equal(strict.state, plain.state)


def test_claim_free_frames_prefers_the_candidate_near_a_coast():
    result = TrackResult.empty(2)
    result.set(0, TrackState.COASTED, np.array([100.0, 100.0]), 0.5, 0)
    cand = FrameCandidates.from_arrays(np.array([[500.0, 500.0], [104.0, 101.0], [300.0, 90.0]]),
                                       np.array([5.0, 3.0, 1.0]))
    claim_free_frames(result, [cand, cand], [np.zeros(3, bool), np.array([True, False, False])], 0.0)
    assert np.allclose(result.xy[0], [104.0, 101.0])     # near the coast, and ≥ half the best score
    assert np.allclose(result.xy[1], [104.0, 101.0])     # the best unflagged
    assert (result.state == TrackState.DETECTED).all() and (result.track_id == -1).all()
