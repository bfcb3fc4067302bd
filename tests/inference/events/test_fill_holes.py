"""Short holes in a detector's track (dropped detections) are filled before the hit-event features."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from inference.clipio import BallTrack
from inference.events import EventDetector
from inference.events.features import FeatureConfig, clip_features, dense_xy, fill_holes
from training.events.synthetic.simulate import simulate_clips


def _parabola(n: int = 40) -> np.ndarray:
    t = np.arange(n) / 50.0
    return np.stack([0.2 + 0.3 * t, 0.7 - 1.2 * t + 2.0 * t**2], axis=1)


def test_holes_up_to_the_limit_are_filled_and_longer_gaps_and_the_ends_are_not():
    truth = _parabola()
    xy = truth.copy()
    xy[[0, 1]] = np.nan              # the start: no seen neighbour before it
    xy[5] = np.nan                   # 1 frame
    xy[10:13] = np.nan               # 3 frames
    xy[20:25] = np.nan               # 5 frames: a gap, not a hole
    xy[38:] = np.nan                 # the end
    out = fill_holes(xy, 3)
    filled = np.r_[5, 10, 11, 12]
    assert np.allclose(out[filled], truth[filled], atol=4e-3)   # a chord of the parabola over ≤ 0.08 s
    assert np.isnan(out[[0, 1, 20, 21, 22, 23, 24, 38, 39]]).all()
    seen = np.isfinite(xy).all(axis=1)
    assert np.array_equal(out[seen], xy[seen])                    # seen positions untouched
    assert np.isnan(fill_holes(xy, 0)[5]).all()                   # 0: nothing filled


def test_a_track_with_dropped_detections_reads_like_the_whole_one():
    clip = simulate_clips("tennis", 1, seed=23, progress=False, fps=50.0)[0]
    full = dense_xy(clip.ball, clip.n_frames)
    seen = np.flatnonzero(np.isfinite(full).all(axis=1))
    rng = np.random.default_rng(0)
    drop = rng.choice(seen[2:-2], size=len(seen) // 6, replace=False)
    drop = drop[np.isfinite(full[drop - 1]).all(axis=1) & np.isfinite(full[drop + 1]).all(axis=1)]
    drop = drop[~np.isin(drop - 1, drop) & ~np.isin(drop + 1, drop)]   # single-frame holes
    keep = np.setdiff1d(np.arange(clip.n_frames), drop)
    vis = clip.ball.dense(clip.n_frames).visibility[keep]
    holed = BallTrack(keep.astype(np.int64), vis, full[keep])
    fc = FeatureConfig()
    whole = clip_features(clip.ball, clip.n_frames, clip.fps, fc)
    raw = clip_features(holed, clip.n_frames, clip.fps, fc)
    fixed = clip_features(holed, clip.n_frames, clip.fps, dataclasses.replace(fc, fill_holes_s=0.06))
    assert len(drop) > 10
    assert (raw[drop, 4] == 0).all() and (fixed[drop, 4] == 1).all()      # the `seen` column
    off = np.abs(fixed[drop, :2] - whole[drop, :2])                        # positions where the ball was
    assert np.median(off) < 0.002 and off.max() < 0.02                      # (a chord across a bounce: ~1 %)
    assert np.abs(fixed[:, :2] - whole[:, :2]).mean() < np.abs(raw[:, :2] - whole[:, :2]).mean() / 10


def test_the_setting_is_recorded_in_model_files_and_older_files_read_as_none():
    for name in ("tennis", "padel"):
        assert EventDetector.from_checkpoint(None, sport=name).features.fill_holes_s == pytest.approx(0.06)
    older = {"ref_fps": 50, "velocity": True, "corners": False, "poses": False, "players": 2}
    assert FeatureConfig.from_model_file(older).fill_holes_s == 0.0
    fc = FeatureConfig(fill_holes_s=0.04)
    assert FeatureConfig.from_dict(fc.to_dict()) == fc
    with pytest.raises(ValueError, match="fill_holes_s"):
        FeatureConfig(fill_holes_s=2.0)
