"""Crop-tracking: the detector runs on a quarter-size window around the expected ball and finds what the
full frame finds; it goes back to the full frame to (re)acquire the ball."""
from __future__ import annotations

import numpy as np
import pytest
from detection_helpers import YellowNet, render_clip

from inference.detection.crop import CropConfig, place_crop
from inference.detection.detect import BallDetectorRunner
from inference.detection.metrics import evaluate_ball_tracks

W, H = 640, 360


def rally(n: int = 90, fps: float = 30.0, hit=(-250.0, -250.0), hit_frame: int = 60) -> np.ndarray:
    """A ball flying right on a parabola, bouncing at frame 30 (vertical speed reversed) and hit back at
    ``hit_frame`` (60; thrown up and left): two changes of direction the motion model cannot foresee."""
    xy = np.empty((n, 2))
    p, v, g = np.array([60.0, 200.0]), np.array([250.0, -200.0]), 400.0
    for i in range(n):
        xy[i] = p
        if i == 30:
            v[1] = -0.8 * abs(v[1])
        if i == hit_frame:
            v[:] = hit
        p = p + v / fps
        v[1] += g / fps
    return xy


@pytest.fixture(scope="module")
def rally_clip(tmp_path_factory):
    return render_clip(tmp_path_factory.mktemp("crop") / "rally", rally(), (W, H))


def runner(crop: CropConfig | None) -> BallDetectorRunner:
    return BallDetectorRunner(YellowNet(), normalize="unit", crop=crop)


def positions(result) -> dict[int, np.ndarray]:
    px = result.track.to_pixels(W, H)
    return {int(f): px[k] for k, f in enumerate(result.track.frame) if result.track.visibility[k] == 1}


def test_crop_tracking_finds_the_same_ball_as_the_full_frame(rally_clip):
    full = runner(None).run(rally_clip)
    crop = runner(CropConfig()).run(rally_clip)
    assert full.windows == {"full": 30, "crop": 0, "crop_rerun": 0}
    # most windows ran on a crop; the full frame only to find the ball and once a second
    assert crop.windows["crop"] - crop.windows["crop_rerun"] >= 18, crop.windows
    assert crop.windows["full"] < full.windows["full"] / 2, crop.windows
    a, b = positions(full), positions(crop)
    assert len(a) >= 85 and set(a) == set(b)
    err = np.array([np.linalg.norm(a[f] - b[f]) for f in a])
    assert err.max() < 1.0, err.max()           # the same blob, same centroid (a 1×1 network: no border)
    gt = rally_clip.read_ball()
    f1 = [evaluate_ball_tracks(r.track, gt, W, H, tau_px=4.0).f1 for r in (full, crop)]
    assert f1[0] > 0.95 and abs(f1[0] - f1[1]) <= 0.01, f1


def test_a_hit_that_leaves_the_crop_reruns_the_window_on_the_full_frame(tmp_path):
    """A smash (3,000 px/s upwards, in mid-window) throws the ball out of the crop placed on the old path:
    that window is re-run on the full frame at once, and no frame is lost."""
    clip = render_clip(tmp_path / "hit", rally(60, hit=(250.0, -3000.0), hit_frame=52), (W, H))
    full, crop = runner(None).run(clip), runner(CropConfig()).run(clip)
    assert crop.windows["crop_rerun"] >= 1, crop.windows
    a, b = positions(full), positions(crop)
    assert len(a) >= 52 and set(a) == set(b)
    assert max(np.linalg.norm(a[f] - b[f]) for f in a) < 1.0


def test_the_ball_is_reacquired_after_a_long_gap(tmp_path):
    """The ball vanishes for 1.5 s (the track dies) and comes back elsewhere: found again on the full frame,
    then followed on crops again."""
    xy = rally(120)
    xy[40:85] = np.nan
    xy[85:] = np.stack([500 - 6.0 * np.arange(35), 80 + 3.0 * np.arange(35)], axis=1)   # another place
    clip = render_clip(tmp_path / "gap", xy, (W, H))
    result = runner(CropConfig()).run(clip)
    found = positions(result)
    back = [f for f in range(85, 120) if f in found]
    assert len(back) >= 32 and min(back) <= 88, back
    assert all(np.linalg.norm(found[f] - xy[f]) < 2.0 for f in back)
    assert not any(40 <= f < 85 for f in found)          # nothing made up during the gap
    assert result.windows["crop"] - result.windows["crop_rerun"] >= 20, result.windows
    # crops after the comeback, and not only before the gap
    full_only = runner(None).run(clip)
    assert set(positions(full_only)) == set(found)


@pytest.mark.parametrize("back_at", [84, 85, 86])
def test_a_lost_ball_is_searched_every_other_window_and_the_skipped_ones_are_searched_when_it_is_back(
        tmp_path, back_at):
    """While the ball is gone (a lob above the picture) only every other window runs; the window that finds it
    again runs the skipped one before it too, so the track is the one of searching every window, wherever in
    a window the ball comes back."""
    xy = rally(120)
    xy[40:back_at] = np.nan
    xy[back_at:] = np.stack([500 - 6.0 * np.arange(120 - back_at), 80 + 3.0 * np.arange(120 - back_at)], axis=1)
    clip = render_clip(tmp_path / "lost", xy, (W, H))
    every = runner(CropConfig(lost_skip=0)).run(clip)
    backoff = runner(CropConfig()).run(clip)
    assert "lost_skipped" not in every.windows
    assert backoff.windows["lost_skipped"] >= 5, backoff.windows            # ~13 windows without a ball
    assert backoff.windows["full"] <= every.windows["full"] - 5, (backoff.windows, every.windows)
    a, b = positions(every), positions(backoff)
    assert min(f for f in a if f >= 40) <= back_at + 1                     # found where it came back
    assert set(a) == set(b) and max(np.linalg.norm(a[f] - b[f]) for f in a) < 1.0
    assert len(backoff.track) == len(every.track) == 120


def test_a_ball_that_never_comes_back_leaves_the_skipped_frames_empty(tmp_path):
    xy = rally(60)
    xy[20:] = np.nan
    clip = render_clip(tmp_path / "gone", xy, (W, H))
    result = runner(CropConfig()).run(clip)
    assert result.windows["lost_skipped"] >= 3 and len(result.candidates) == 60
    assert not any(f >= 22 for f in positions(result))


def test_place_crop_keeps_the_expected_ball_inside_on_the_stride_grid():
    cfg = CropConfig(size=(144, 256), margin=32)
    y0, x0 = place_crop(np.array([[300.0, 100.0], [310.0, 104.0]]), (288, 512), cfg)
    assert y0 % 8 == 0 and x0 % 8 == 0
    assert x0 + 32 <= 300 and 310 <= x0 + 256 - 32 and y0 + 32 <= 100 <= y0 + 144 - 32
    assert place_crop(np.array([[5.0, 5.0]]), (288, 512), cfg) == (0, 0)        # clamped; the grid's edge
    assert place_crop(np.array([[250.0, 5.0]]), (288, 512), cfg) == (0, 120)    # needs no margin
    assert place_crop(np.array([[100.0, 90.0], [100.0, 190.0]]), (288, 512), cfg) is None   # inner margin
    assert place_crop(np.array([[10.0, 100.0], [400.0, 100.0]]), (288, 512), cfg) is None  # spread too far
    assert place_crop(np.array([[50.0, 50.0]]), (144, 256), cfg) is None        # crop not smaller than grid
    with pytest.raises(ValueError, match="multiples of 8"):
        CropConfig(size=(100, 256))


def test_crop_flags_reach_the_runner_from_detect_and_infer():
    """`--crop`/`--detector-crop` and `--detector-backend` are parsed into the runner's settings."""
    import argparse

    from inference.detection.cli import register as register_detect
    from inference.detection.crop import crop_config
    from inference.pipeline.cli import _config
    from inference.pipeline.cli import register as register_infer

    assert crop_config("auto") == CropConfig() and crop_config("off") is None
    with pytest.raises(ValueError, match="crop must be one of"):
        crop_config("on")
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="command")
    register_detect(sub)
    register_infer(sub)
    args = parser.parse_args(["detect", "clip"])
    assert (args.crop, args.backend) == ("auto", "auto")   # crop-tracking and ONNX-where-installed: the defaults
    args = parser.parse_args(["detect", "clip", "--crop", "off", "--backend", "onnx"])
    assert (args.crop, args.backend) == ("off", "onnx")
    cfg = _config(parser.parse_args(["infer", "v.mp4", "--detector-crop", "off", "--detector-backend", "onnx"]))
    assert (cfg.detector_crop, cfg.detector_backend) == ("off", "onnx")
    assert _config(parser.parse_args(["infer", "v.mp4"])).detector_crop == "auto"
    with pytest.raises(SystemExit):
        parser.parse_args(["detect", "clip", "--backend", "tensorrt"])
