"""Statistics of a detector's track against the truth (training/events/stats/track_stats.py) on generated tracks
with known misses, wrong positions and jitter, the degradation settings made from them, and the
degradation's misses drawn by the ball's image size (training/events/synthetic/degrade.py ``miss_by_diameter``)."""
from __future__ import annotations

import numpy as np
import pytest

from inference.clipio import BallTrack, HitEvents
from training.events.synthetic.degrade import DegradeConfig, ball_diameter_px, degrade
from training.events.stats.track_stats import ClipTruth, degrade_settings, measure_clips


def _truth_and_detection(seed: int = 0):
    """300 frames at 30 fps, 1280×720: the ball is small (3 px) in the first half, large (10 px) after;
    the detector misses 6-frame runs every 30 frames in the first half and the 7 frames around a near hit
    at 200, puts 6 detections 50 px off, and jitters the rest by σ = 1 px."""
    rng = np.random.default_rng(seed)
    n, W, H = 300, 1280, 720
    t = np.arange(n)
    xy = np.stack([0.2 + 0.5 * t / n, 0.5 + 0.2 * np.sin(t / 20)], axis=1)
    truth = ClipTruth("gen", 30.0, W, H, BallTrack(t, np.ones(n, np.int8), xy),
                      np.where(t < 150, 3.0, 10.0), np.where(t < 150, 25.0, 8.0),
                      HitEvents(np.array([200]), np.array(["player_near"])))
    px = xy * [W, H] + rng.normal(0, 1.0, (n, 2))
    vis = np.ones(n, np.int8)
    for a in range(0, 150, 30):
        vis[a + 10:a + 16] = 0
    vis[197:204] = 0
    px[250:256] += [50.0, 0.0]
    px[vis == 0] = np.nan
    return truth, BallTrack(t, vis, px / [W, H])


def test_measured_figures_match_what_the_detector_did():
    truth, det = _truth_and_detection()
    s = measure_clips([(truth, det)], tau_px=10.0, contact_s=0.1)
    small = next(b for b in s["miss_by_diameter_px"] if b["from"] == 0.0)
    large = next(b for b in s["miss_by_diameter_px"] if b["from"] == 9.0)
    assert small["miss"] == pytest.approx(30 / 150, abs=1e-3) and small["frames"] == 150
    # the large ball: 7 frames in the gap at the hit and 6 wrong positions
    assert large["miss"] == pytest.approx(13 / 150, abs=1e-3)
    far = next(b for b in s["miss_by_distance_m"] if b["from"] == 20.0)
    assert far["miss"] == pytest.approx(30 / 150, abs=1e-3)
    assert s["miss_near_contacts"]["near"]["miss"] == pytest.approx(1.0, abs=1e-3)  # ±3 frames of the hit: missed
    assert s["gap_s"]["count"] == 5 + 1 + 1  # five runs, the gap at the hit, the wrong run
    assert s["gap_s"]["quantiles"]["0.5"] == pytest.approx(6 / 30, abs=1e-3)
    assert s["false_rate"] == pytest.approx(6 / int((det.visibility > 0).sum()), abs=1e-3)
    assert 45 <= s["false_distance_px_at_1280"]["0.5"] <= 55
    assert 0.8 <= s["jitter_px"]["x"] <= 1.2 and 0.8 <= s["jitter_px"]["y"] <= 1.2
    assert s["whole_pixels"] < 0.05
    # a detector that reports whole pixels is recognised
    whole = BallTrack(det.frame, det.visibility, np.round(det.xy * [1280, 720]) / [1280, 720])
    assert measure_clips([(truth, whole)])["whole_pixels"] == pytest.approx(1.0, abs=1e-3)


def test_degrade_settings_reproduce_the_measured_rates():
    truth, det = _truth_and_detection()
    s = measure_clips([(truth, det)])
    d = degrade_settings(s)
    cfg = DegradeConfig.from_dict({**d, "measured": s})  # the YAML keeps the figures beside the settings
    assert cfg.p_occlude_near == pytest.approx(1.0, abs=1e-3)
    assert cfg.outlier_frac == pytest.approx(s["false_rate"], abs=1e-3)
    assert cfg.miss_by_diameter[0][1] > cfg.miss_by_diameter[-1][1]  # small balls are missed more
    assert cfg.jitter_px[0] <= 1.0 <= cfg.jitter_px[1] + 0.3
    with pytest.raises(ValueError, match="miss_by_diameter"):
        DegradeConfig(miss_by_diameter=[[3.0, 1.5]])


def test_degradation_misses_small_balls_more_when_told():
    from training.events.synthetic.simulate import simulate_clip

    clips = [simulate_clip("tennis", 7100 + k) for k in range(3)]
    base = dict(p_clean=0.0, p_occlude_near=0.0, p_occlude_far=0.0, p_gap_event=0.0, miss_frac=0.3,
                outlier_frac=0.0, jitter_px=(0.0, 0.0), p_smooth=0.0, miss_run_s=(0.03, 0.07))
    gap_small, gap_plain = [], []
    for k, c in enumerate(clips):
        diam = ball_diameter_px(c)
        vis = (c.ball.visibility > 0) & np.isfinite(diam)
        assert np.nanmedian(diam[vis]) > 0
        y = c.ball.xy[vis, 1]  # the far end (top of the image) shows a smaller ball
        assert np.mean(diam[vis][y < np.median(y)]) < np.mean(diam[vis][y >= np.median(y)])
        m = float(np.nanmedian(diam[vis]))
        small = diam < m
        told = [[0.0, 1.0], [m - 0.05, 1.0], [m + 0.05, 0.0]]  # runs start only where the ball is small
        for cfg, out in ((DegradeConfig(**base, miss_by_diameter=told), gap_small),
                         (DegradeConfig(**base), gap_plain)):
            d = degrade(c, np.random.default_rng(k), cfg)
            out.append(float(small[d.missed & vis].mean()))
    assert np.mean(gap_small) > 0.8 and np.mean(gap_small) > np.mean(gap_plain) + 0.2


def test_shipped_measured_setting_loads_and_composes():
    """conf/data/degrade/detector_measured.yaml (bench_track_stats.py's output) is a valid degradation and
    Hydra puts it at data.degrade."""
    from pathlib import Path

    import yaml

    path = Path(__file__).resolve().parents[3] / "conf" / "data" / "degrade" / "detector_measured.yaml"
    d = yaml.safe_load(path.read_text())
    assert d["measured"]["clips"] >= 2 and d["measured"]["miss_by_diameter_px"]
    cfg = DegradeConfig.from_dict(d)
    assert cfg.enabled and cfg.miss_by_diameter and 0 < cfg.miss_frac < 0.95
