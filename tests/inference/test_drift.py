"""Camera drift: a video whose court creeps is reported, a fixed one is not."""
from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np

from inference.camera import Camera
from inference.cli import main
from inference.clipio import Clip, write_video
from inference.clipio.frames import FrameSource
from inference.court import load_court
from inference.courtfit.drift import measure_drift

SAMPLE = Path(__file__).resolve().parents[2] / "datasets" / "sample" / "padel_sample"


def _drifting_copy(root: Path, total=(12.0, -6.0)) -> Clip:
    shutil.copytree(SAMPLE, root)
    frames = []
    with FrameSource.open(SAMPLE / "video.mp4") as src:
        n = len(src)
        for i, f in enumerate(src.iter()):
            m = np.float32([[1, 0, total[0] * i / (n - 1)], [0, 1, total[1] * i / (n - 1)]])
            frames.append(cv2.warpAffine(f, m, (f.shape[1], f.shape[0]), borderMode=cv2.BORDER_REPLICATE))
    write_video(root / "video.mp4", frames, 30.0)
    return Clip(root)


def test_drift_is_measured_and_reported(tmp_path, capsys):
    clip = _drifting_copy(tmp_path / "drift")
    cam = Camera.load(SAMPLE / "gt" / "camera.yaml")
    report = measure_drift(clip, cam, load_court("padel"))
    assert report.drifting and 10 < report.max_drift_px < 17
    np.testing.assert_allclose(report.shifts[-1] - report.shifts[0], [12, -6], atol=2.0)
    assert report.valid.all()
    shutil.copy(SAMPLE / "gt" / "camera.yaml", clip.root / "camera.yaml")
    assert main(["calibrate", str(clip.root), "--drift"]) == 0
    assert "the camera moves during the clip" in capsys.readouterr().out


def test_a_fixed_camera_does_not_drift():
    report = measure_drift(Clip(SAMPLE), Camera.load(SAMPLE / "gt" / "camera.yaml"), load_court("padel"),
                           every_s=2.0)
    assert not report.drifting and report.max_drift_px < 2.0, report.table()
    assert "camera drift" in report.summary()
