"""The ball detectors' frame store (training/detection/frame_store.py) as load_clip and BallWindows use it:
decoded pixels within JPEG's tolerance of the letterboxed video (exact for the scored splits), far smaller
than the raw cache it replaces, clear errors for a short video, damaged stores rebuilt or named, old raw
caches removed."""
from __future__ import annotations

import logging
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from inference.clipio import Clip, FormatError
from inference.detection.geometry import Letterbox
from training.detection import frame_store
from training.detection.data import BallWindows, ClipData, WindowSpec, _cache_key, collate, load_clip
from training.detection.frame_store import FrameStore, StoreError, write_store
from synth.generate import SynthConfig, generate_clip

NET = (144, 256)


@pytest.fixture(scope="module")
def clip_dir(tmp_path_factory) -> Path:
    """One short synthetic padel clip (40 frames, 320×192, mp4v)."""
    root = tmp_path_factory.mktemp("store_clip") / "clip_a"
    generate_clip(root, 7, SynthConfig(sport="padel", randomise_camera=False, width=320, height=192, fps=30.0,
                                       codec="mp4v", randomise_look=False, max_frames=40))
    return root


@pytest.fixture
def clip(clip_dir, tmp_path) -> Clip:
    """A private copy of the clip (tests edit clip.yaml)."""
    shutil.copytree(clip_dir, tmp_path / "clip_a")
    return Clip(tmp_path / "clip_a")


def video_frames(clip: Clip, size=NET) -> np.ndarray:
    """What the raw cache held: every frame of the video, letterboxed, uint8."""
    info = clip.info
    lb = Letterbox(info.width, info.height, size[1], size[0])
    with clip.frames(cache_size=0) as src:
        return np.stack([lb.warp(f) for f in src.iter(0, clip.n_frames)])


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(((a.astype(np.float64) - b) ** 2).mean())
    return 10 * np.log10(255 ** 2 / max(mse, 1e-12))


def test_round_trip_is_within_jpeg_tolerance_and_indexes_like_an_array(tmp_path):
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:NET[0], 0:NET[1]]
    frames = []
    for k in range(12):  # smooth court-like gradients, a little noise and a bright 5-px ball that moves
        f = np.stack([60 + xx * 0.5, 90 + yy * 0.4, 140 + k * 2 + 0 * xx], -1) + rng.normal(0, 2, (*NET, 3))
        cy, cx = 30 + 3 * k, 20 + 9 * k
        f[(yy - cy) ** 2 + (xx - cx) ** 2 <= 6] = (230, 240, 60)
        frames.append(np.clip(f, 0, 255).astype(np.uint8))
    path = tmp_path / "s.npy"
    assert write_store(path, frames, NET) == 12
    store = FrameStore(path)
    assert len(store) == 12 and store.shape == (12, *NET, 3) and store.dtype == np.uint8
    window = store[4:7]
    assert window.shape == (3, *NET, 3) and window.dtype == np.uint8
    assert np.array_equal(store[-1], store[11]) and np.array_equal(store[[2, 5]][1], store[5])
    assert np.asarray(store[0:12:5]).shape == (3, *NET, 3)
    for k in range(12):
        assert psnr(store[k], frames[k]) > 32
        assert np.abs(store[k].astype(int) - frames[k]).mean() < 2.5
        cy, cx = 30 + 3 * k, 20 + 9 * k  # the ball is still the brightest yellow where it was
        assert store[k][cy, cx, 0] > 180 and store[k][cy, cx, 2] < 120
    with pytest.raises(IndexError):
        store[12]
    clone = pickle.loads(pickle.dumps(store))  # what a DataLoader worker receives: the path, not the frames
    assert len(pickle.dumps(store)) < 1000 and np.array_equal(clone[3], store[3])


def test_store_is_far_smaller_than_the_raw_cache_and_matches_the_video(clip, tmp_path):
    cd = load_clip(clip, NET, tmp_path / "cache")
    stores = list((tmp_path / "cache").iterdir())
    assert [p.suffix for p in stores] == [".npy"] and isinstance(cd.frames, FrameStore)
    raw = video_frames(clip)
    assert stores[0].stat().st_size < raw.nbytes / 4, (stores[0].stat().st_size, raw.nbytes)
    decoded = cd.frames[:]
    assert decoded.shape == raw.shape
    assert psnr(decoded, raw) > 32 and np.abs(decoded.astype(int) - raw).mean() < 3
    # the right frames, in order: where the ball is in frame k, the store's frame k is nearer the video's
    # frame k than its frames k ± 1 (frames where the ball moved)
    nearer, frames = 0, 0
    for k in range(1, clip.n_frames - 1):
        if np.isfinite(cd.xy_net[k]).all():
            x, y = np.round(cd.xy_net[k]).astype(int)
            patch = np.s_[max(y - 3, 0):y + 4, max(x - 3, 0):x + 4]
            err = [np.abs(decoded[k][patch].astype(int) - raw[j][patch]).mean() for j in (k - 1, k, k + 1)]
            if min(np.abs(raw[k][patch].astype(int) - raw[j][patch]).mean() for j in (k - 1, k + 1)) > 4:
                nearer += err[1] < min(err[0], err[2])
                frames += 1
    assert frames >= 15 and nearer >= 0.9 * frames, (nearer, frames)
    again = load_clip(clip, NET, tmp_path / "cache")  # found, not rebuilt
    assert again.frames.path == cd.frames.path and list((tmp_path / "cache").iterdir()) == stores


def test_windows_from_the_store_equal_windows_from_the_video(clip, tmp_path):
    cd = load_clip(clip, NET, tmp_path / "cache")
    exact = ClipData(cd.name, video_frames(clip), cd.visibility, cd.xy_net, cd.xy_px, cd.letterbox)
    for spec in (WindowSpec(), WindowSpec(crop=(32, 32), augment=True, step=1)):
        a, b = BallWindows([cd], spec, seed=3), BallWindows([exact], spec, seed=3)
        assert len(a) == len(b) > 5
        for i in range(0, len(a), 4):
            (xa, ya, ma), (xb, yb, mb) = a[i], b[i]
            assert xa.shape == xb.shape and torch.equal(ya, yb)
            assert torch.equal(ma["offset"], mb["offset"]) and torch.equal(ma["visibility"], mb["visibility"])
            # ImageNet-normalised, one grey level is ~0.017: JPEG moves a window by ~2 levels on average (the
            # brightness jitter amplifies it); which frames they are is checked at the ball in the test above
            assert (xa - xb).abs().mean() < 0.1, (i, float((xa - xb).abs().mean()))


def test_scored_splits_get_the_exact_frames(clip, tmp_path):
    """Validation and test must see what eval.py and inference see: their stores are lossless (PNG)."""
    from training.detection.data import BallDataModule

    exact = load_clip(clip, NET, tmp_path / "cache", exact=True)
    assert exact.frames.codec == "png" and np.array_equal(exact.frames[:], video_frames(clip))
    assert load_clip(clip, NET, tmp_path / "cache").frames.codec == "jpeg"  # a second file, beside it
    assert len(list((tmp_path / "cache").iterdir())) == 2
    dm = BallDataModule(train_clips=[str(clip.root)], val_clips=[str(clip.root)], net_size=NET, crop=(32, 32),
                        cache_dir=str(tmp_path / "dm"))
    dm.setup("fit")
    assert dm.data["train"].clips[0].frames.codec == "jpeg" and dm.data["val"].clips[0].frames.codec == "png"


def test_dataloader_workers_decode_the_same_windows(clip, tmp_path):
    cd = load_clip(clip, NET, tmp_path / "cache")
    ds = BallWindows([cd], WindowSpec(crop=(32, 32), augment=True), seed=1)
    batches = [list(torch.utils.data.DataLoader(ds, batch_size=4, num_workers=w, collate_fn=collate))
               for w in (0, 2)]
    for (x0, y0, _), (x1, y1, _) in zip(*batches):
        assert torch.equal(x0, x1) and torch.equal(y0, y1)


def test_a_short_video_is_a_clear_error_naming_it(clip, tmp_path):
    cache = tmp_path / "cache"
    load_clip(clip, NET, cache)  # a complete store of the 40 frames
    text = (clip.root / "clip.yaml").read_text()
    (clip.root / "clip.yaml").write_text(text.replace("n_frames: 40", "n_frames: 55"))
    with pytest.raises(FormatError, match="video has 40 frames but the clip needs 55") as e:
        load_clip(Clip(clip.root), NET, cache)  # the store is too short: rebuilt, and the video is short
    assert e.value.path == clip.video_path
    assert not [p for p in cache.iterdir() if "tmp" in p.name]


def test_a_damaged_store_is_rebuilt_or_named(clip, tmp_path, caplog):
    cache = tmp_path / "cache"
    cd = load_clip(clip, NET, cache)
    path, good = cd.frames.path, cd.frames[:]
    data = path.read_bytes()

    path.write_bytes(data[: len(data) // 2])  # cut short (a full disk, a killed copy): rebuilt, logged
    with caplog.at_level(logging.WARNING, logger="training.detection.data"):
        cd = load_clip(clip, NET, cache)
    assert "rebuilding it from the video" in caplog.text and str(path) in caplog.text
    assert np.array_equal(cd.frames[:], good)

    path.write_bytes(b"not a frame store")
    assert np.array_equal(load_clip(clip, NET, cache).frames[:], good)

    store = FrameStore(path)  # flipped bytes inside frame 5's JPEG: the layout is intact, the frame is not
    start = 128 + int(store._offsets[5])
    damaged = bytearray(path.read_bytes())
    damaged[start + 200:start + 216] = bytes(16)
    path.write_bytes(bytes(damaged))
    cd = load_clip(clip, NET, cache)
    assert np.array_equal(cd.frames[4], good[4])
    with pytest.raises(FormatError, match="frame 5 is damaged") as e:
        cd.frames[3:6]
    assert e.value.path == path and "delete this file" in str(e.value)


def test_an_old_raw_cache_is_deleted_with_a_log_line(clip, tmp_path, caplog):
    cache = tmp_path / "cache"
    cache.mkdir()
    old = cache / f"{clip.root.name}_{_cache_key(clip, NET, store='')}.npy"
    np.save(old, np.zeros((clip.n_frames, *NET, 3), np.uint8))
    other = cache / "someone_elses.npy"
    np.save(other, np.zeros(3))
    with caplog.at_level(logging.INFO, logger="training.detection.data"):
        cd = load_clip(clip, NET, cache)
    assert not old.exists() and other.exists() and "old raw frame cache" in caplog.text
    assert isinstance(cd.frames, FrameStore) and cd.frames.path.parent == cache
    with pytest.raises(StoreError, match="older cache format"):
        FrameStore(other)


def test_lru_keeps_recent_frames_within_its_budget(tmp_path, monkeypatch):
    frames = [np.full((*NET, 3), 10 * k, np.uint8) for k in range(10)]
    write_store(tmp_path / "s.npy", frames, NET)
    store = FrameStore(tmp_path / "s.npy")
    lru = frame_store.FrameLRU(4 * frames[0].nbytes)
    monkeypatch.setattr(frame_store, "LRU", lru)
    store[0:3]
    store[1:4]  # frames 1 and 2 come from the LRU
    assert (lru.hits, lru.misses) == (2, 4) and len(lru) == 4
    assert not store[1].flags.writeable  # shared frames cannot be drawn on by a caller
    store[4:10]
    assert len(lru) == 4
    monkeypatch.setattr(frame_store, "LRU", frame_store.FrameLRU(0))  # off
    assert np.abs(store[7].astype(int) - 70).max() <= 2 and len(frame_store.LRU) == 0
