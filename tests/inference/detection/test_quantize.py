"""int8 companions of detector weights: made by `python -m training.quantize`, run by `--backend onnx-int8` only
while they match the checkpoint's bytes (never by `auto`), and the shipped one finds the ball where the float
network does."""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from detection_helpers import render_clip

from inference.cli import main
from inference.clipio import Clip
from inference.detection.detect import SHIPPED, BallDetectorRunner
from inference.detection.engine import make_engine
from inference.detection.geometry import Letterbox
from inference.detection.preprocess import normalize
from inference.detection.quantize import SOURCE_KEY, companion_path, file_sha256, int8_companion, source_sha256
from inference.models.checkpoint import save_wasb_checkpoint
from inference.models.registry import build_model

try:
    import onnxruntime  # noqa: F401
    HAVE_ORT = True
except ImportError:
    HAVE_ORT = False
needs_ort = pytest.mark.skipif(not HAVE_ORT, reason="onnxruntime is not installed (`make test` installs it)")

SAMPLE = Path(__file__).resolve().parents[3] / "datasets" / "sample" / "padel_sample"


def test_companion_path_sits_beside_the_checkpoint():
    assert companion_path("w/wasb_padel.pth.tar") == Path("w/wasb_padel.int8.onnx")
    assert companion_path("run/best.ckpt") == Path("run/best.int8.onnx")
    assert companion_path("m.pth") == Path("m.int8.onnx")


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    t = np.arange(24) / 30.0
    xy = np.stack([80 + 250 * t, 300 - 400 * t + 200 * t**2], axis=1)
    return render_clip(tmp_path_factory.mktemp("quant") / "clip", xy)


@needs_ort
def test_quantize_then_detect_runs_the_companion_until_the_weights_change(clip, tmp_path, monkeypatch, capsys,
                                                                          caplog):
    from training.quantize import main as quantize_main

    monkeypatch.setenv("RALLY3D_CACHE", str(tmp_path / "cache"))
    weights = save_wasb_checkpoint(build_model("monotrack"), tmp_path / "mono.pth.tar")
    assert quantize_main(["--weights", str(weights), "--data", str(clip.root), "--every", "1", "--windows", "3"]) == 0
    companion = tmp_path / "mono.int8.onnx"
    assert companion.is_file() and "from 3 windows of 1 clips" in capsys.readouterr().out
    assert source_sha256(companion) == file_sha256(weights)
    assert int8_companion(weights) == companion

    out = tmp_path / "ball.csv"
    assert main(["detect", str(clip.root), "--weights", str(weights), "--backend", "onnx-int8", "--out", str(out)]) == 0
    assert "onnx-int8; windows" in capsys.readouterr().out and out.is_file()
    assert main(["detect", str(clip.root), "--weights", str(weights), "--out", str(out)]) == 0
    assert "onnx; windows" in capsys.readouterr().out          # auto: the float network, companion or not

    # the checkpoint retrained (other bytes): the stale companion is named and never run
    save_wasb_checkpoint(build_model("monotrack"), weights, epoch=7)
    with caplog.at_level(logging.WARNING):
        assert int8_companion(weights) is None
    assert "training.quantize" in caplog.text
    with pytest.raises(ValueError, match="training.quantize"):
        BallDetectorRunner.from_weights("monotrack", weights, backend="onnx-int8")


@needs_ort
def test_onnx_int8_without_a_companion_says_how_to_make_one(tmp_path):
    model = build_model("monotrack").eval()
    with pytest.raises(ValueError, match="training.quantize"):
        make_engine(model, "onnx-int8", 3, onnx_dir=tmp_path)
    assert make_engine(model, "auto", 3, onnx_dir=tmp_path).name == "onnx"     # no companion: the float network
    assert make_engine(model, "onnx", 3, onnx_dir=tmp_path, int8=tmp_path / "x.onnx").name == "onnx"


def test_quantize_tool_names_a_folder_without_clips(tmp_path, capsys):
    from training.quantize import main as quantize_main

    assert quantize_main(["--data", str(tmp_path)]) == 2
    assert "no clip folders" in capsys.readouterr().err


@needs_ort
def test_the_shipped_companion_matches_the_shipped_weights_and_finds_the_same_ball(tmp_path):
    """Retraining wasb_padel.pth.tar without re-quantising would ship a stale companion (onnx-int8 would then
    refuse to run): its recorded SHA-256 must be the checkpoint's. On the padel sample's frames the int8
    heatmaps peak where the float ones do."""
    companion = companion_path(SHIPPED["wasb"])
    assert companion.is_file(), "the shipped int8 companion is missing: python -m training.quantize --data ..."
    assert source_sha256(companion) == file_sha256(SHIPPED["wasb"]), f"{companion}: stale, lacks {SOURCE_KEY}"
    fp32 = BallDetectorRunner.from_weights("wasb", SHIPPED["wasb"], backend="onnx", onnx_dir=tmp_path)
    int8 = BallDetectorRunner.from_weights("wasb", SHIPPED["wasb"], backend="onnx-int8", onnx_dir=tmp_path)
    assert int8.engine.name == "onnx-int8" and fp32.engine.name == "onnx"
    clip = Clip(SAMPLE)
    lb = Letterbox(clip.info.width, clip.info.height, 512, 288)
    with clip.frames(cache_size=0) as src:
        frames = [lb.warp(src.read(i)) for i in range(60, 72)]
    x = np.stack([normalize(np.stack(frames[k:k + 3]), "imagenet") for k in range(0, 12, 3)])
    a, b = fp32.engine(x), int8.engine(x)
    a, b = a.reshape(-1, *a.shape[2:]), b.reshape(-1, *b.shape[2:])
    found = [k for k in range(len(a)) if a[k].max() > 0.5]
    assert len(found) >= 6, [float(m.max()) for m in a]          # the ball is on these frames
    for k in found:
        pa = np.array(np.unravel_index(np.argmax(a[k]), a[k].shape))
        pb = np.array(np.unravel_index(np.argmax(b[k]), b[k].shape))
        assert np.abs(pa - pb).max() <= 2 and b[k].max() > 0.3, (k, pa, pb, float(b[k].max()))
