"""The ONNX Runtime backend: the exported detector agrees with eager PyTorch (full frames and crops), is
cached by weights, and `rally3d detect --backend onnx --crop ...` runs it."""
from __future__ import annotations

import sys

import numpy as np
import pytest
import torch
from detection_helpers import YellowNet, render_clip

from inference.cli import main
from inference.detection.detect import SHIPPED, BallDetectorRunner
from inference.detection.engine import OnnxEngine, TorchEngine, cached_onnx, make_engine, require_onnxruntime
from inference.detection.geometry import Letterbox
from inference.detection.preprocess import normalize
from inference.models.checkpoint import load_detector, save_wasb_checkpoint
from inference.models.fuse import fold_batchnorm
from inference.models.registry import build_model

try:
    import onnxruntime  # noqa: F401
    HAVE_ORT = True
except ImportError:
    HAVE_ORT = False
needs_ort = pytest.mark.skipif(not HAVE_ORT, reason="onnxruntime is not installed (pip install 'rally3d[onnx]'; "
                               "`make test` installs it)")


def detector(name: str) -> torch.nn.Module:
    """The shipped WASB weights (trained batch-norm statistics), or a freshly initialised network."""
    if name == "wasb":
        return load_detector(SHIPPED["wasb"])[0].eval()
    torch.manual_seed(0)
    return build_model(name).eval()


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    t = np.arange(30) / 30.0
    xy = np.stack([80 + 250 * t, 300 - 400 * t + 200 * t**2], axis=1)
    return render_clip(tmp_path_factory.mktemp("engine") / "clip", xy)


def clip_windows(clip, net_hw=(288, 512)) -> np.ndarray:
    """Two normalised 3-frame windows of the generated clip's letterboxed frames: ``(2, 9, H, W)``."""
    lb = Letterbox(clip.info.width, clip.info.height, net_hw[1], net_hw[0])
    with clip.frames(cache_size=0) as src:
        frames = [lb.warp(f) for _, f in zip(range(6), src.iter())]
    return np.stack([normalize(np.stack(frames[k:k + 3]), "imagenet") for k in (0, 3)])


@needs_ort
@pytest.mark.parametrize("name", ["wasb", "monotrack"])
def test_onnx_heatmaps_agree_with_eager_pytorch(name, clip, tmp_path):
    """Full frames and a crop-sized input (dynamic height and width) give the same heatmaps."""
    model, _ = fold_batchnorm(detector(name))
    torch_engine, onnx_engine = TorchEngine(model), make_engine(model, "onnx", 3, onnx_dir=tmp_path)
    assert isinstance(onnx_engine, OnnxEngine)
    x = clip_windows(clip, (144, 256))                       # a small grid keeps the test fast
    for batch in (x, x[:1, :, 32:96, 64:192]):               # the whole grid, then a 64×128 crop
        ref, out = torch_engine(batch), onnx_engine(batch)
        assert out.shape == ref.shape == (len(batch), model.frames_out, *batch.shape[2:])
        np.testing.assert_allclose(out, ref, atol=1e-4)
        assert ref.std() > 1e-3   # not a constant map: the comparison means something


@needs_ort
def test_onnx_file_is_cached_by_weights(tmp_path):
    model = build_model("monotrack").eval()
    path = cached_onnx(model, 3, tmp_path)
    stamp = path.stat().st_mtime_ns
    assert cached_onnx(model, 3, tmp_path) == path and path.stat().st_mtime_ns == stamp   # not exported again
    with torch.no_grad():
        next(model.parameters()).add_(0.1)
    other = cached_onnx(model, 3, tmp_path)
    assert other != path and other.is_file()                                        # other weights, new file


@needs_ort
def test_onnx_runner_tracks_the_same_ball(clip, tmp_path):
    runs = [BallDetectorRunner(YellowNet(), normalize="unit", backend=b, onnx_dir=tmp_path).run(clip)
            for b in ("torch", "onnx")]
    a, b = (r.track for r in runs)
    np.testing.assert_array_equal(a.visibility, b.visibility)
    assert (a.visibility == 1).sum() >= 25
    np.testing.assert_allclose(a.to_pixels(640, 360), b.to_pixels(640, 360), atol=0.05)


def test_missing_onnxruntime_says_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "onnxruntime", None)
    with pytest.raises(RuntimeError, match=r"rally3d\[onnx\]"):
        require_onnxruntime()
    with pytest.raises(ValueError, match="unknown detector backend"):
        make_engine(YellowNet(), "tensorrt")


@needs_ort
def test_cli_detect_backend_and_crop_flags(clip, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("RALLY3D_CACHE", str(tmp_path / "cache"))
    weights = save_wasb_checkpoint(build_model("monotrack"), tmp_path / "mono.pth.tar")
    out = tmp_path / "ball.csv"
    assert main(["detect", str(clip.root), "--weights", str(weights), "--backend", "onnx", "--crop", "off",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    windows = text.split("windows:")[1].split("); wrote")[0]
    assert "onnx" in text and windows.strip() == "10 full"
    assert out.read_text().startswith("frame,visibility,x,y")
    assert len(list((tmp_path / "cache" / "onnx").glob("*.onnx"))) == 1       # exported into the cache


def test_cli_crop_auto_uses_crops_on_a_visible_ball(clip, tmp_path, capsys, monkeypatch):
    """`--crop auto` (the default) with a network that sees the ball: crops after the first windows."""
    import inference.detection.detect as detect

    monkeypatch.setattr(detect.BallDetectorRunner, "from_weights",
                        classmethod(lambda cls, *a, **kw: cls(YellowNet(), normalize="unit",
                                                              **{k: v for k, v in kw.items() if k != "trust"})))
    weights = save_wasb_checkpoint(build_model("monotrack"), tmp_path / "mono.pth.tar")
    assert main(["detect", str(clip.root), "--weights", str(weights), "--out", str(tmp_path / "b.csv")]) == 0
    text = capsys.readouterr().out
    windows = text.split("windows:")[1].split("); wrote")[0]
    assert "crop (" in windows and int(windows.split(" full")[0]) < 5, text
