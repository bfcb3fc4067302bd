"""Pose-backend statistics against the truth (training/events/stats/pose_stats.py) and the settings they give."""
from __future__ import annotations

import numpy as np
import pytest

from training.events.synthetic.pose_noise import PoseNoiseConfig, noisy_players
from training.events.stats.pose_stats import PoseClipTruth, measure_players, pose_noise_settings, refine_settings
from training.events.synthetic.simulate import simulate_clip


@pytest.fixture(scope="module")
def clips():
    return [simulate_clip("padel", s, players=True) for s in (4141, 4142)]


def truths(clips, cfg: PoseNoiseConfig, seed: int = 0) -> list[PoseClipTruth]:
    return [PoseClipTruth(c.name, c.fps, c.width, c.height, c.players, noisy_players(c, np.random.default_rng(seed + k), cfg))
            for k, c in enumerate(clips)]


OFF = dict(p_no_players=0.0, p_no_poses=0.0, miss_near=(0, 0), miss_far=(0, 0), jitter_px=(0, 0), p_joint_miss=0.0,
           p_wrist_miss=0.0, p_flip_lr=0.0, p_swap_sides=0.0, court_sigma_m=(0, 0))


def test_exact_players_measure_as_exact(clips):
    s = measure_players(truths(clips, PoseNoiseConfig(enabled=False)))
    for side in ("near", "far"):
        assert s[side]["players"] == 4 and s[side]["miss_frac"][2] == 0
        assert s[side]["body_sigma_px"] == [0, 0] and s[side]["wrist_outlier_frac"] == 0
        assert s[side]["flip_runs_per_s"] == 0 and s[side]["team_wrong"] == 0


def test_known_noise_is_read_back(clips):
    cfg = PoseNoiseConfig(**{**OFF, "miss_far": (0.3, 0.3), "miss_run_s": (0.1, 0.3), "wrist_outlier_near": 0.2,
                             "wrist_outlier_rel": (0.3, 0.5), "p_flip_lr": 2.0, "p_flip_lr_far": 0.0,
                             "bias_rel": (0.04, 0.04)})
    s = measure_players(truths(clips, cfg))
    assert s["near"]["miss_frac"][2] < 0.02 and 0.2 < s["far"]["miss_frac"][1] < 0.4
    assert 0.1 < s["near"]["wrist_outlier_frac"] < 0.3 and s["far"]["wrist_outlier_frac"] < 0.05
    assert s["near"]["flip_runs_per_s"] > 0.5 and s["far"]["flip_runs_per_s"] < 0.1
    assert s["near"]["lag_corr"] > 0.3                                 # the offset drifts slowly
    settings = pose_noise_settings(s)
    again = PoseNoiseConfig.from_dict(settings)                        # the settings are a valid config
    assert again.wrist_outlier_near > again.wrist_outlier_far and again.p_flip_lr > again.p_flip_lr_far
    assert 0.02 < again.bias_rel[0] <= again.bias_rel[1] < 0.08
    sim = measure_players(truths(clips, again, seed=10), lag_s=s["lag_s"])
    fixed = refine_settings(settings, s, sim)
    assert PoseNoiseConfig.from_dict(fixed).p_flip_lr >= 0 and set(fixed) == set(settings)
