"""The detector-degradation model (training/events/synthetic/degrade.py) on real simulated padel rallies: gaps at the
near player's hits, miss and outlier rates as configured, the smoother, clean clips, config errors, and
the data module's fresh draws per epoch."""
from __future__ import annotations

import numpy as np
import pytest

from training.events.data.datamodule import EventDataModule
from training.events.synthetic.degrade import DegradeConfig, degrade, degrade_all
from training.events.synthetic.simulate import simulate_clip

OFF = dict(p_clean=0.0, p_occlude_near=0.0, p_occlude_far=0.0, p_gap_event=0.0, miss_frac=0.0, outlier_frac=0.0,
           jitter_px=(0.0, 0.0), p_smooth=0.0)


@pytest.fixture(scope="module")
def clips():
    return [simulate_clip("padel", 9000 + k) for k in range(6)]


def test_occlusion_gaps_cover_near_hits(clips):
    cfg = DegradeConfig(**{**OFF, "p_occlude_near": 1.0})
    hidden, total = 0, 0
    for k, c in enumerate(clips):
        d = degrade(c, np.random.default_rng(k), cfg)
        vis = c.ball.visibility > 0
        near = [int(f) for f, e in zip(c.events.frame, c.events.event) if e == "player_near" and vis[f]]
        assert near, "every simulated rally has near-team hits"
        for f in near:
            total += 1
            hidden += int(d.track.visibility[f] == 0)
        # each gap is a run of 5–15 frames at 30 fps, scaled with the clip's fps
        lo, hi = (round(s * c.fps) for s in cfg.occlude_s)
        assert 0.5 * lo <= d.occluded.sum() / len(near) <= hi
        # nothing else was touched: away from hits the track is the annotated one
        far_from_hits = vis & ~d.occluded
        assert np.allclose(d.track.xy[far_from_hits], c.ball.xy[far_from_hits])
    assert hidden == total  # p_occlude_near = 1: every near hit is inside a gap


def test_miss_and_outlier_rates_match_config(clips):
    cfg = DegradeConfig(**{**OFF, "miss_frac": 0.3, "outlier_frac": 0.12, "outlier_px": (20.0, 100.0)})
    for k, c in enumerate(clips):
        d = degrade(c, np.random.default_rng(k), cfg)
        vis = c.ball.visibility > 0
        miss_rate = (d.missed & vis).sum() / vis.sum()
        assert abs(miss_rate - 0.3) <= 1.5 / vis.sum() + 1e-9
        det = d.track.visibility > 0
        assert np.array_equal(det, vis & ~d.missed)
        assert abs(d.outlier.sum() / det.sum() - 0.12) <= 1.5 / det.sum()
        size = np.array([c.width, c.height])
        off = np.linalg.norm((d.track.xy - c.ball.xy) * size, axis=1)
        assert np.median(off[d.outlier]) >= 20.0
        assert np.all(off[det & ~d.outlier] < 1e-6)  # no jitter configured: correct detections are exact
        # misses come in runs of 3–10 frames at 30 fps, not single frames
        edges = np.flatnonzero(np.diff(np.r_[0, d.missed.astype(int), 0]))
        assert np.mean(edges[1::2] - edges[::2]) >= 2.0


def test_default_model_looks_like_the_real_detector(clips):
    """Recall ~0.5–0.65 and precision ~0.85–0.95 after the smoother, as measured on real detector tracks."""
    rec, prec = [], []
    for c, track in zip(clips, degrade_all(clips, 3, DegradeConfig(p_clean=0.0, p_smooth=1.0))):
        vis = c.ball.visibility > 0
        det = track.visibility > 0
        err = np.linalg.norm((track.xy - c.ball.xy) * [c.width, c.height], axis=1)
        good = vis & det & (err <= 10)
        rec.append(good.sum() / vis.sum())
        prec.append(good.sum() / det.sum())
        assert len(track) == c.n_frames and np.all(np.isnan(track.xy[~det]))
    assert 0.45 <= np.mean(rec) <= 0.72
    assert 0.8 <= np.mean(prec) <= 0.97


def test_clean_setting_and_seeds(clips):
    c = clips[0]
    same = degrade(c, np.random.default_rng(0), DegradeConfig(p_clean=1.0))
    assert same.track is c.ball and not same.occluded.any()
    off = degrade(c, np.random.default_rng(0), DegradeConfig.from_dict({"enabled": False}))
    assert off.track is c.ball
    a, b = (degrade_all(clips[:2], 5, DegradeConfig(p_clean=0.0)) for _ in range(2))
    assert all(np.array_equal(x.visibility, y.visibility) for x, y in zip(a, b))


@pytest.mark.parametrize("bad, word", [({"miss_frac": 1.5}, "miss_frac"), ({"occlude_s": [0.5, 0.1]}, "occlude_s"),
                                       ({"jitter_px": "big"}, "jitter_px"), ({"typo": 1}, "unknown data.degrade")])
def test_bad_config_names_the_key(bad, word):
    with pytest.raises(ValueError, match=word):
        DegradeConfig.from_dict(bad)


def test_data_module_draws_new_degradations_each_epoch(tmp_path):
    dm = EventDataModule(n_train=3, n_val=2, n_test=2, seed=77, window=24, cache_dir=str(tmp_path),
                         degrade={"p_clean": 0.0}, features={"ref_fps": 50, "velocity_scale": 100})
    dm.setup("fit")
    loader = dm.train_dataloader()
    ds = loader.dataset
    list(iter(loader.sampler))  # epoch 1: the draw made by setup
    first = ds.x.clone()
    list(iter(loader.sampler))  # epoch 2: a new draw, same windows and labels
    second = ds.x
    assert first.shape == second.shape and not np.allclose(first.numpy(), second.numpy())
    clean = len(dm.labelled("val"))
    sims, tracks = dm.tuning_clips()
    assert len(sims) == len(tracks) == 2 * clean  # clean + one degraded copy
    assert (tracks[clean].visibility > 0).sum() < (tracks[0].visibility > 0).sum()


def test_real_tracker_options_integer_pixels_far_end_and_cropped_top(clips):
    """integer_px rounds to whole pixels, far_miss loses the ball high in the image more than low,
    top_crop removes every detection in the cropped band; all off by default (draws unchanged)."""
    base = dict(p_clean=0.0, p_smooth=0.0, miss_frac=0.0, outlier_frac=0.0, p_occlude_near=0.0,
                p_occlude_far=0.0, p_gap_event=0.0)
    c = clips[0]
    a = degrade(c, np.random.default_rng(1), DegradeConfig(**base)).track
    b = degrade(c, np.random.default_rng(1), DegradeConfig(**base, integer_px=True)).track
    ok = b.visibility > 0
    px = b.xy[ok] * np.array([c.width, c.height])
    assert np.allclose(px, np.round(px), atol=1e-6) and np.abs(a.xy[ok] - b.xy[ok]).max() > 0
    far, near_lost = [], []
    for k, cl in enumerate(clips):
        t = degrade(cl, np.random.default_rng(k), DegradeConfig(**base, far_miss=0.6)).track
        vis = (cl.ball.visibility > 0) & np.isfinite(cl.ball.xy).all(axis=1)
        hi = vis & (cl.ball.xy[:, 1] < 0.45)
        lo = vis & (cl.ball.xy[:, 1] >= 0.45)
        far.append((t.visibility[hi] == 0).mean() if hi.any() else np.nan)
        near_lost.append((t.visibility[lo] == 0).mean() if lo.any() else np.nan)
    assert np.nanmean(far) > 0.4 and np.nanmean(near_lost) < 0.05
    t = degrade(c, np.random.default_rng(2), DegradeConfig(**base, top_crop=0.3)).track
    assert not ((t.visibility > 0) & (c.ball.xy[:, 1] < 0.3)).any()
    with pytest.raises(ValueError, match="far_miss"):
        DegradeConfig(far_miss=1.5)
