"""Training pieces of the crop hit-event model: the data module on a real rendered clip (crop cache,
fallback to the embedded sample), chunks = the runtime's windows, augmentations keep features, crops and
labels consistent, and the warm start reproduces the ball-only HitNet exactly.
(``fast_dev_run`` of ``+experiment=hitnet_crop_padel`` runs in test_hitnet_train.py with every hitnet*
experiment.)"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from inference.events import EventDetector
from inference.events.features import FeatureConfig, make_windows, window_labels
from training.events.data.crop_data import CropChunkSet, CropEventDataModule
from training.events.models.crop import CropAugment, CropHitNetModule, augment_crop_batch

ROOT = Path(__file__).resolve().parents[3]
HITNET = ROOT / "inference" / "weights" / "hitnet_padel.pth.tar"
FEATURES = {"ref_fps": 50, "velocity": True, "velocity_scale": 100}
FEATURE_CFG = FeatureConfig(**FEATURES)


@pytest.fixture(scope="module")
def sample_dm(tmp_path_factory):
    cache = tmp_path_factory.mktemp("crop_cache")
    with pytest.warns(UserWarning, match="embedded sample"):
        dm = CropEventDataModule(features=FEATURES, crop={"size": 16, "context": 0.04}, window=24,
                                 root=str(cache / "missing"), cache_dir=str(cache), chunk=32)
        dm.setup("fit")
    return dm, cache


def test_data_module_falls_back_to_the_sample_and_caches_crops(sample_dm):
    dm, cache = sample_dm
    (clip,) = dm.clips("train")
    T = len(clip.lc.feats)
    assert clip.crops.shape == (T, 16, 16, 3) and clip.crops.dtype == np.uint8
    seen = (clip.lc.feats[:, :2] != 0).any(1)
    assert not clip.crops[~seen].any() and clip.crops[seen].reshape(seen.sum(), -1).max(1).min() > 0
    assert clip.lc.y.sum() > 0  # the sample's events are labels
    files = list(Path(cache).glob("padel_sample_*.npy"))
    assert len(files) == 1 and np.array_equal(np.load(files[0]), clip.crops)


def test_chunks_hold_exactly_the_runtime_windows(sample_dm):
    dm, _ = sample_dm
    (clip,) = dm.clips("val")
    ds = CropChunkSet([clip], 24, 6, chunk=32, stride=32)
    wins = make_windows(clip.lc.feats, 24)
    labels = window_labels(clip.lc.y, 24, 6)
    got_y = torch.cat([ds[i][2] for i in range(len(ds))])
    assert torch.equal(got_y[: len(labels)], torch.from_numpy(labels)) and (got_y[len(labels):] == -1).all()
    x, crops, _ = ds[1]  # chunk 1: windows starting at padded index 32 .. 63
    assert x.shape == (32 + 23, 5) and crops.shape == (32 + 23, 16, 16, 3)
    assert np.array_equal(x.unfold(0, 24, 1).permute(0, 2, 1)[:5].numpy(), wins[32:37])


def test_module_forward_on_chunks_matches_per_window_forward():
    torch.manual_seed(0)
    m = CropHitNetModule(features=FEATURES, crop={"size": 16}, window=8, hidden=8, layers=1, embed=4).eval()
    x = torch.rand(2, 8 + 5 - 1, 5) + 1
    crops = torch.randint(0, 255, (2, 12, 16, 16, 3), dtype=torch.uint8)
    with torch.no_grad():
        chunk = m(x, crops)
        one = m.net(x[1:2, 3:11], crops[1:2, 3:11])
    assert chunk.shape == (2, 5, 6)
    assert torch.allclose(chunk[1, 3], one[0], atol=1e-5)
    y = torch.tensor([[0, 1, -1, -1, 2], [0, 0, 0, 3, -1]])
    assert torch.isfinite(m.chunk_loss(chunk, y))


def test_augmentations_keep_features_crops_and_labels_consistent():
    gen = torch.Generator().manual_seed(0)
    x = torch.rand(6, 10, 5) + 1
    x[:, 2] = 0  # a missing frame stays missing
    crops = torch.randint(0, 255, (6, 10, 16, 16, 3), dtype=torch.uint8, generator=gen)
    crops[:, 2] = 0
    y = torch.tensor([[1, 2, 3, 4, 5, -1]] * 6)
    perm = torch.tensor([0, 1, 2, 4, 3, 5])  # e.g. a near/far swap on mirror
    cfg = CropAugment(p_mirror=1.0, p_drop=0.0, jitter_px=0.0, max_shift_px=0, contrast=0.0)
    fx, fc, fy = augment_crop_batch(x, crops, y, cfg, FEATURE_CFG, perm, gen)
    assert torch.allclose(fx[:, :, 0][x[:, :, 0] != 0], 3.0 - x[:, :, 0][x[:, :, 0] != 0])
    assert torch.allclose(fx[:, :, 2], -x[:, :, 2]) and (fx[:, 2] == 0).all()
    assert torch.equal(fc, crops.flip(3)) and (fy[:, -1] == -1).all() and fy[0, 2].item() == 4
    drop = CropAugment(p_mirror=0.0, p_drop=1.0, drop_frac=0.5, jitter_px=0.0, max_shift_px=2, contrast=0.3)
    dx, dc, dy = augment_crop_batch(x, crops, y, drop, FEATURE_CFG, perm, gen)
    gone = (dx == 0).all(dim=2)
    assert gone.sum() > 6 and not dc[gone].any() and torch.equal(dy, y)


def test_warm_start_reproduces_the_ball_only_hitnet():
    ref = EventDetector.from_checkpoint(HITNET)
    m = CropHitNetModule(features=ref.features.to_dict(), window=ref.window, init_from=str(HITNET)).eval()
    x = torch.rand(4, ref.window, ref.features.n_features) + 1
    crops = torch.randint(0, 255, (4, ref.window, 32, 32, 3), dtype=torch.uint8)
    with torch.no_grad():
        assert torch.allclose(m.net(x, crops), ref.net(x), atol=1e-5)
    with pytest.raises(ValueError, match="hidden"):
        CropHitNetModule(features=ref.features.to_dict(), hidden=16, init_from=str(HITNET))
