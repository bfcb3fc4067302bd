"""Pose-backend noise on the simulated players (training/events/synthetic/pose_noise.py), the player block through the
augmentations, and the event data module with ``features.poses``."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from inference.events import FeatureConfig
from inference.events.features import PLAYER_COLUMNS
from training.events.data.datamodule import AugmentConfig, EventDataModule, augment_batch
from training.events.synthetic.pose_noise import PoseNoiseConfig, noisy_all, noisy_players
from training.events.synthetic.simulate import simulate_clip

COL = {n: i for i, n in enumerate(PLAYER_COLUMNS)}
P = len(PLAYER_COLUMNS)


@pytest.fixture(scope="module")
def clip():
    return simulate_clip("padel", 3131, players=True)


def quiet(**kw) -> PoseNoiseConfig:
    """Every noise off except ``kw``."""
    base = dict(p_no_players=0.0, p_no_poses=0.0, miss_near=(0, 0), miss_far=(0, 0), jitter_px=(0, 0),
                p_joint_miss=0.0, p_wrist_miss=0.0, p_flip_lr=0.0, p_swap_sides=0.0, court_sigma_m=(0, 0))
    return PoseNoiseConfig(**{**base, **kw})


def test_simulated_players_are_four_padel_players_on_their_sides(clip):
    pl = clip.players
    assert sorted(pl.ids()) == [0, 1, 2, 3] and len(pl) == 4 * clip.n_frames
    near = pl.team == "near"
    assert (pl.court_xy[near, 1] < 10).mean() > 0.95 and (pl.court_xy[~near, 1] > 10).mean() > 0.95
    assert np.nanmean(pl.keypoints[near, :, 1]) > np.nanmean(pl.keypoints[~near, :, 1])  # near = image bottom


def test_noise_is_seeded_and_off_means_exact(clip):
    cfg = PoseNoiseConfig(p_no_players=0.0)
    a, b = noisy_all([clip], 3, cfg)[0], noisy_all([clip], 3, cfg)[0]
    assert np.array_equal(a.keypoints, b.keypoints, equal_nan=True) and np.array_equal(a.frame, b.frame)
    c = noisy_all([clip], 4, cfg)[0]
    assert not np.array_equal(a.keypoints, c.keypoints, equal_nan=True)
    assert noisy_players(clip, np.random.default_rng(0), PoseNoiseConfig(enabled=False)) is clip.players
    exact = noisy_players(clip, np.random.default_rng(0), quiet())
    assert np.array_equal(exact.keypoints, clip.players.keypoints, equal_nan=True)


def test_each_kind_of_noise(clip):
    pl, rng = clip.players, np.random.default_rng(1)
    assert noisy_players(clip, rng, quiet(p_no_players=1.0)) is None
    no_kp = noisy_players(clip, rng, quiet(p_no_poses=1.0))
    assert len(no_kp) == len(pl) and np.isnan(no_kp.keypoints).all() and np.isfinite(no_kp.court_xy).all()
    far_miss = noisy_players(clip, rng, quiet(miss_far=(0.5, 0.5)))
    kept_far = (far_miss.team == "far").sum() / (pl.team == "far").sum()
    assert (far_miss.team == "near").sum() == (pl.team == "near").sum() and 0.3 < kept_far < 0.7
    jit = noisy_players(clip, rng, quiet(jitter_px=(3, 3)))
    err = (jit.keypoints[..., :2] - pl.keypoints[..., :2]) * [clip.width, clip.height]
    assert 2.5 < np.nanstd(err) < 3.5
    wrists = noisy_players(clip, rng, quiet(p_wrist_miss=0.5))
    lost = np.isnan(wrists.keypoints[:, [9, 10], 0]) & np.isfinite(pl.keypoints[:, [9, 10], 0])
    assert 0.4 < lost.mean() < 0.6 and not np.isnan(wrists.keypoints[:, 0, 0]).any()
    swapped = noisy_players(clip, rng, quiet(p_swap_sides=1.0, swap_s=(1.0, 1.0)))
    changed = swapped.team != pl.team
    assert 0 < changed.sum() <= 4 * int(clip.fps) + 4
    flips = noisy_players(clip, rng, quiet(p_flip_lr=3.0))
    assert np.any(np.isclose(flips.keypoints[:, 9, 0], pl.keypoints[:, 10, 0]) & (pl.keypoints[:, 9, 0] != pl.keypoints[:, 10, 0]))
    court = noisy_players(clip, rng, quiet(court_sigma_m=(0.2, 0.2)))
    assert 0.15 < np.std(court.court_xy - pl.court_xy) < 0.25


def test_config_errors_name_the_key():
    with pytest.raises(ValueError, match="p_wrist_miss"):
        PoseNoiseConfig(p_wrist_miss=1.5)
    with pytest.raises(ValueError, match="miss_far"):
        PoseNoiseConfig(miss_far=(0.5, 1.0))
    with pytest.raises(ValueError, match="unknown data.pose_noise keys"):
        PoseNoiseConfig.from_dict({"jiter_px": [1, 2]})
    assert PoseNoiseConfig.from_dict(None).enabled is False


def test_augmentations_move_the_player_block_with_the_image():
    fc = FeatureConfig(poses=True)
    x = torch.zeros(2, 6, fc.n_features)
    x[:, :, 0:2] = 1.5
    x[:, :, 4] = 1.0
    o = fc.player_offset
    x[:, :, o + COL["court_x"]] = 0.4
    x[:, :, o + COL["wrist_dx"]] = 0.3
    x[:, :, o + COL["racket_wrist_x"]] = 0.7
    mirror_only = AugmentConfig(weights=(1, 0, 0, 0, 0, 0, 0, 0, 0, 0), p_mirror=1.0)
    y, _ = augment_batch(x, torch.zeros(2, dtype=torch.long), fc, mirror_only, torch.arange(4))
    assert torch.allclose(y[:, :, o + COL["court_x"]], torch.tensor(-0.4))
    assert torch.allclose(y[:, :, o + COL["wrist_dx"]], torch.tensor(-0.3))
    assert torch.allclose(y[:, :, o + COL["racket_wrist_x"]], torch.tensor(-0.7))
    drop = AugmentConfig(weights=(0, 0, 0, 1, 0, 0, 0, 0, 0, 0), frac=1.0, p_mirror=0.0)  # drop every frame
    z, _ = augment_batch(x, torch.zeros(2, dtype=torch.long), fc, drop, torch.arange(4))
    assert torch.all(z[:, :, :5] == 0) and torch.all(z[:, :, o + COL["wrist_dx"]] == 0)
    assert torch.allclose(z[:, :, o + COL["racket_wrist_x"]], torch.tensor(0.7))  # body-relative: kept


def test_data_module_builds_player_windows_and_redraws_the_noise(tmp_path):
    dm = EventDataModule(sport="tennis", class_set="tennis4", features={"poses": True}, window=12, n_train=3,
                         n_val=2, n_test=2, seed=5, on_unmapped="warn", cache_dir=str(tmp_path),
                         pose_noise={"p_no_players": 0.0}, degrade={"enabled": False})
    dm.setup("fit")
    ds = dm.sets["train"]
    assert ds.x.shape[1:] == (12, 29)
    present = ds.x[:, :, 5 + COL["present"]]
    assert 0.5 < float(present.mean()) < 1.0  # players present, some missed
    assert all(c.sim.players is not None for c in dm.labelled("val"))
    before = ds.x.clone()
    dm.redraw()
    dm.redraw()  # the second call draws new noise
    assert torch.equal(before[:, :, :5], ds.x[:, :, :5]) and not torch.equal(before[:, :, 5:], ds.x[:, :, 5:])


def test_folder_clips_bring_their_players_csv(clip, tmp_path):
    from inference.clipio import Clip, ClipInfo, Manifest, ManifestEntry

    root = tmp_path / "ds"
    entries = []
    for split in ("train", "val", "test"):
        c = Clip.create(root / split, ClipInfo(sport="padel", fps=clip.fps, width=clip.width, height=clip.height,
                                               video="video.mp4", n_frames=clip.n_frames, split=split), exist_ok=True)
        c.write_ball(clip.ball)
        c.write_events(clip.events)
        if split != "test":
            c.write_players(clip.players, gt=split == "val")  # a pose backend's players.csv, or the generator's
        entries.append(ManifestEntry(split, split))
    Manifest(root, entries, name="pl", sport="padel").save()
    dm = EventDataModule(sport="padel", class_set="padel6", features={"poses": True}, source="folder", root=str(root),
                         window=12, pose_noise={"enabled": False})
    for split in ("train", "val"):
        sim = dm.labelled(split)[0].sim
        assert sim.players is not None and len(sim.players) == len(clip.players)
        assert dm.labelled(split)[0].feats[:, 5 + COL["present"]].mean() > 0.95
    assert dm.labelled("test")[0].sim.players is None and np.all(dm.labelled("test")[0].feats[:, 5:] == 0)
    ball_only = EventDataModule(sport="padel", class_set="padel6", source="folder", root=str(root), window=12)
    assert ball_only.labelled("train")[0].sim.players is None  # not read when the model does not use them


def test_a_ball_only_model_file_warm_starts_a_player_aware_network(tmp_path):
    """init_weights=<ball-only file> with data.features.poses=true: the ball columns keep the file's weights and
    the players block starts at zero, so the widened network predicts exactly what the file does whatever
    the players say; any other setting that differs is still an error naming the key."""
    from pathlib import Path

    from inference.events.detector import load_model_file
    from inference.events.network import HitNet
    from training.events.run import init_events

    shipped = Path(__file__).resolve().parents[3] / "inference/weights/hitnet_padel.pth.tar"
    blob = load_model_file(shipped)
    dm = EventDataModule(sport="padel", class_set="padel6", window=blob["window"], n_train=2, n_val=2, n_test=2,
                         seed=5, cache_dir=str(tmp_path), features={**blob["features"], "poses": True})
    assert dm.features.n_features == 29

    class Module:  # what init_events touches of the Lightning module
        net = HitNet(29, 6, **{k: v for k, v in blob["net"].items() if k not in ("n_features", "n_classes")})

    init_events(Module, shipped, dm)
    ball_only = HitNet(**blob["net"])
    ball_only.load_state_dict(blob["state_dict"])
    x = torch.randn(7, blob["window"], 29)
    Module.net.eval()
    ball_only.eval()
    with torch.no_grad():
        assert torch.allclose(Module.net(x), ball_only(x[:, :, :5]), atol=1e-5)
        w = Module.net.gru.weight_ih_l0_reverse
        assert torch.equal(w[:, :5], blob["state_dict"]["gru.weight_ih_l0_reverse"]) and not w[:, 5:].any()
    other = EventDataModule(sport="padel", class_set="padel6", window=12, n_train=2, n_val=2, n_test=2, seed=5,
                            cache_dir=str(tmp_path), features={**blob["features"], "poses": True})
    with pytest.raises(ValueError, match="data.window=24"):
        init_events(Module, shipped, other)


def _height_px(clip) -> np.ndarray:
    y = clip.players.keypoints[:, :, 1] * clip.height
    return np.nanmax(y, axis=1) - np.nanmin(y, axis=1)


def test_slow_offsets_scale_with_the_player_and_drift(clip):
    pl = clip.players
    off = noisy_players(clip, np.random.default_rng(2), quiet(bias_rel=(0.05, 0.05), bias_s=0.5))
    err = (off.keypoints[..., :2] - pl.keypoints[..., :2]) * [clip.width, clip.height]
    rel = err / _height_px(clip)[:, None, None]
    assert 0.035 < np.nanstd(rel[:, :9]) < 0.065                       # head, shoulders, elbows
    assert 1.5 < np.nanstd(rel[:, [9, 10]]) / np.nanstd(rel[:, :9]) < 2.5  # wrists twice as far off
    pid = pl.player_id == 0
    e = err[pid][:, 5, 0]
    step = np.nanstd(np.diff(e)) / np.sqrt(2)
    assert step < 0.3 * np.nanstd(e)                                   # drifts, not white noise


def test_wrists_on_something_else_in_runs_only_on_the_chosen_side(clip):
    pl = clip.players
    out = noisy_players(clip, np.random.default_rng(3), quiet(wrist_outlier_near=0.3, wrist_outlier_rel=(0.3, 0.5)))
    err = np.linalg.norm((out.keypoints[..., :2] - pl.keypoints[..., :2]) * [clip.width, clip.height], axis=2)
    rel = err / _height_px(clip)[:, None]
    near, far = pl.team == "near", pl.team == "far"
    wrong = rel[near][:, [9, 10]] > 0.29
    assert 0.2 < wrong.mean() < 0.4 and (rel[near][:, [9, 10]][wrong] < 0.51).all()
    assert np.allclose(err[far], 0) and np.allclose(err[:, :9], 0)   # the far side and the body untouched


def test_dropped_detections_are_bridged_like_the_players_stage(clip):
    pl = clip.players
    cfg = quiet(drop_near=(0.2, 0.2), drop_run_s=(0.04, 0.1), fill_gap_s=0.6)
    out = noisy_players(clip, np.random.default_rng(4), cfg)
    near_rows = (out.team == "near").sum()
    assert near_rows >= 0.97 * (pl.team == "near").sum()                # short gaps filled ...
    half = out.score < 0.75 * np.nanmax(pl.score)
    assert 0.1 < half[out.team == "near"].mean() < 0.3                  # ... at half the score
    gaps = noisy_players(clip, np.random.default_rng(4), quiet(drop_near=(0.2, 0.2), drop_run_s=(0.04, 0.1)))
    assert (gaps.team == "near").sum() < 0.85 * (pl.team == "near").sum()  # without filling they stay gaps
    # a filled row lies on the line between the kept rows around it
    i = int(np.flatnonzero(half & (out.team == "near"))[0])
    pid, f = out.player_id[i], out.frame[i]
    rows = np.flatnonzero((out.player_id == pid) & ~half)
    before, after = rows[out.frame[rows] < f][-1], rows[out.frame[rows] > f][0]
    w = (f - out.frame[before]) / (out.frame[after] - out.frame[before])
    expect = (1 - w) * out.keypoints[before, 0, :2] + w * out.keypoints[after, 0, :2]
    assert np.allclose(out.keypoints[i, 0, :2], expect)


def test_far_players_can_flip_at_their_own_rate(clip):
    pl = clip.players
    out = noisy_players(clip, np.random.default_rng(5), quiet(p_flip_lr=3.0, p_flip_lr_far=0.0))
    moved = ~np.isclose(out.keypoints[:, 9, 0], pl.keypoints[:, 9, 0])
    assert moved[pl.team == "near"].any() and not moved[pl.team == "far"].any()


def test_measured_settings_file_loads():
    from pathlib import Path

    for name in ("movenet_measured", "movenet960_measured"):
        path = Path(__file__).resolve().parents[3] / f"conf/data/pose_noise/{name}.yaml"
        cfg = PoseNoiseConfig.from_file(path)
        assert cfg.fill_gap_s > 0 and cfg.bias_rel[1] > 0 and cfg.wrist_outlier_near > 0
    with pytest.raises(ValueError, match="bias_s"):
        PoseNoiseConfig(bias_s=0)
