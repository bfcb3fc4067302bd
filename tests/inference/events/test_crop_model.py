"""The crop hit-event model: crops cut around the ball from a real frame source (positions, borders,
missing ball, resampling), the network's shapes, export → EventDetector loading, the error without frames."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from inference.clipio import BallTrack, Clip, FrameSource
from inference.events import ClassSet, EventDetector
from inference.events.crop import CropConfig, CropHitNet, crop_at, extract_crops, n_parameters, ref_to_source
from inference.events.decode import DecodeParams
from inference.events.features import FeatureConfig, dense_xy, resample_xy

ROOT = Path(__file__).resolve().parents[3]
SAMPLE = ROOT / "datasets" / "sample" / "padel_sample"
W, H = 320, 180


def _marked_frames(tmp_path: Path, centres: list[tuple[int, int]]) -> Path:
    """A frames folder: frame i is grey with a 4×4 white square centred on ``centres[i]`` and its index
    encoded in the red channel of the top-left pixel."""
    d = tmp_path / "frames"
    d.mkdir()
    for i, (x, y) in enumerate(centres):
        img = np.full((H, W, 3), 60, np.uint8)
        img[y - 2:y + 2, x - 2:x + 2] = 255
        cv2.imwrite(str(d / f"{i:05d}.png"), img)
    return d


def test_crop_at_centres_pads_borders_and_blanks_missing():
    frame = np.zeros((H, W, 3), np.uint8)
    frame[100:104, 50:54] = 200  # a ball centred at (52, 102)
    c = crop_at(frame, np.array([52.0, 102.0]), 16, 16)
    assert c.shape == (16, 16, 3) and c.dtype == np.uint8
    ys, xs = np.nonzero(c[..., 0])
    assert ys.min() == 6 and ys.max() == 9 and xs.min() == 6 and xs.max() == 9  # the ball in the middle
    corner = crop_at(np.full((H, W, 3), 90, np.uint8), np.array([0.0, 0.0]), 16, 16)
    assert (corner[:8, :8] == 0).all() and (corner[8:, 8:] == 90).all()  # outside the image = zeros
    outside = crop_at(frame, np.array([-100.0, -100.0]), 16, 16)
    assert not outside.any()
    assert not crop_at(frame, np.array([np.nan, 5.0]), 16, 8).any()
    big = crop_at(frame, np.array([52.0, 102.0]), 32, 8)  # resized down: the ball stays in the middle
    assert big.shape == (8, 8, 3) and big[3:5, 3:5].max() > 0 and big[0].max() == 0


def test_extract_crops_streams_the_frames_in_order_and_follows_the_ball(tmp_path):
    n = 12
    centres = [(40 + 15 * i, 60 + 5 * i) for i in range(n)]
    src = FrameSource.open(_marked_frames(tmp_path, centres), fps=25.0)
    xy = np.array(centres, float) / [W, H]
    xy[3] = np.nan  # the ball is missing in frame 3
    cfg = CropConfig(size=16, context=0.05)  # 16 px cut at 320 wide: no resize
    crops = extract_crops(src, xy, 25.0, None, cfg, n)
    assert crops.shape == (n, 16, 16, 3)
    assert not crops[3].any()
    for i in (0, 5, 11):
        white = np.argwhere(crops[i][..., 0] == 255)
        assert white.min(0).tolist() == [6, 6] and white.max(0).tolist() == [9, 9]
    # at a reference rate of 50 fps every clip frame is shown twice; positions are interpolated
    xy50 = resample_xy(xy, 25.0, 50.0)
    crops50 = extract_crops(src, xy50, 25.0, 50.0, cfg, n)
    assert len(crops50) == 2 * n
    assert ref_to_source(2 * n, 25.0, 50.0, n)[10] == 5 and ref_to_source(2 * n, 25.0, 50.0, n)[-1] == n - 1
    assert np.array_equal(crops50[10], crops[5])  # ref frame 10 = clip frame 5, same position
    assert not crops50[6].any() and not crops50[7].any()  # around the missing frame 3


def test_extract_crops_names_a_short_frame_source(tmp_path):
    src = FrameSource.open(_marked_frames(tmp_path, [(50, 50)] * 3), fps=25.0)
    xy = np.full((6, 2), 0.3)
    with pytest.raises(ValueError, match="frame source ended after 3 frames"):
        extract_crops(src, xy, 25.0, None, CropConfig(size=16), 6)


def test_crop_config_validates():
    with pytest.raises(ValueError, match="crop size"):
        CropConfig(size=2)
    with pytest.raises(ValueError, match="context"):
        CropConfig(context=0.9)
    assert CropConfig(context=0.05).side_px(1280) == 64


def test_network_shapes_and_missing_ball_embedding():
    torch.manual_seed(0)
    net = CropHitNet(5, 6, hidden=16, layers=1, crop_size=32, embed=8)
    assert n_parameters(net.encoder) <= 100_000
    x = torch.rand(3, 12, 5) + 1.0
    x[0, 4, :] = 0.0  # ball missing in one frame
    crops = torch.randint(0, 255, (3, 12, 32, 32, 3), dtype=torch.uint8)
    assert net(x, crops).shape == (3, 6)
    z = net.frame_inputs(x[0], crops[0])
    assert z.shape == (12, 5 + 8) and not z[4].any() and z[5, 5:].abs().sum() > 0
    assert net.probs(z[None]).sum().item() == pytest.approx(1.0, abs=1e-5)
    with pytest.raises(ValueError, match="crops must be"):
        net.frame_inputs(x[0], torch.zeros(12, 16, 16, 3, dtype=torch.uint8))


def _crop_detector(window: int = 12) -> EventDetector:
    torch.manual_seed(0)
    cs = ClassSet.load("padel6")
    feats = FeatureConfig(velocity_scale=100)
    net = CropHitNet(feats.n_features, cs.n, hidden=16, layers=1, crop_size=16, embed=4)
    return EventDetector("crop", cs, feats, DecodeParams(thresholds=0.2), net=net, window=window, last_k=6,
                         crop=CropConfig(size=16, context=0.04))


def test_exported_crop_model_loads_and_predicts_on_a_real_clip(tmp_path):
    path = _crop_detector().save(tmp_path / "crop.pth.tar")
    det = EventDetector.from_checkpoint(path)
    assert det.kind == "crop" and isinstance(det.net, CropHitNet) and det.crop == CropConfig(size=16, context=0.04)
    clip = Clip(SAMPLE)
    ball, info = clip.read_ball(), clip.info
    with clip.frames(cache_size=0) as frames:
        r = det.predict(ball, info.fps, info.width, info.height, frames=frames, n_frames=clip.n_frames)
    assert r.probs.shape == (clip.n_frames, 6)
    assert np.allclose(r.probs.sum(1), 1.0, atol=1e-4)
    # the same probabilities as the network on crops cut by hand (the runtime path is the model)
    xy = resample_xy(dense_xy(ball, clip.n_frames), info.fps, 50.0)
    with clip.frames(cache_size=0) as frames:
        p = det.ref_probs(ball, clip.n_frames, info.fps, frames=frames)
    assert p.shape == (len(xy), 6)


def test_crop_model_without_frames_is_a_clear_error():
    det = _crop_detector()
    ball = BallTrack(np.arange(50), np.ones(50, np.int64), np.tile([0.5, 0.5], (50, 1)))
    with pytest.raises(ValueError, match="crop model: it needs the clip's frames"):
        det.predict(ball, 50.0, 1280, 720)
    with pytest.raises(ValueError, match="crop model"):
        det.ref_probs(ball, 50, 50.0)
    with pytest.raises(ValueError, match="needs its network"):
        EventDetector("crop", det.class_set, det.features, det.decode_params)


def test_events_command_feeds_the_frames_to_a_crop_model(tmp_path):
    import shutil

    from inference.cli import main

    root = tmp_path / "clip"
    shutil.copytree(SAMPLE, root)
    path = _crop_detector().save(tmp_path / "crop.pth.tar")
    assert main(["events", str(root), "--weights", str(path), "--out", str(tmp_path / "ev.csv")]) == 0
    assert (tmp_path / "ev.csv").read_text().startswith("frame,event")
