"""Camera drift: a video whose court creeps is reported, a fixed one is not."""
from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

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


def test_camera_tracked_per_frame_undoes_the_drift_in_3d(tmp_path):
    """A 12/−6 px creep: the per-frame track follows it within a pixel, and the 3D fit of the drifting 2D ball
    moved back by the track is as good as the fit of the still camera's (it is worse without)."""
    from inference.courtfit.drift import CameraTrack, track_camera
    from inference.reconstruct import reconstruct
    from inference.reconstruct.evaluate import Scores, Setting, prepare

    clip = _drifting_copy(tmp_path / "drift")
    track, report = track_camera(clip, Camera.load(SAMPLE / "gt" / "camera.yaml"), load_court("padel"))
    truth = np.outer(np.arange(240) / 239, [12.0, -6.0])
    err = np.linalg.norm(track.shift - truth, axis=1)
    assert err.max() < 1.0, err.max()
    assert track.measured.sum() == len(report.frames) >= 40  # every 0.2 s
    track.write(tmp_path / "camera_track.csv")
    again = CameraTrack.read(tmp_path / "camera_track.csv", 240)
    np.testing.assert_allclose(again.shift, track.shift, atol=1e-3)

    obs, gt_frames, gt_xyz = prepare(Clip(SAMPLE), Setting(noise_px=1.0, players="gt"))
    drifted = obs.with_track(obs.uv + truth)

    def mae(o) -> float:
        scores = Scores()
        scores.add(reconstruct(o), o, gt_frames, gt_xyz)
        return scores.row()["MAE_m"]

    still, moved, fixed = mae(obs), mae(drifted), mae(drifted.with_track(track.stabilise(drifted.uv)))
    print(f"3D MAE: still camera {still:.3f} m, drifting {moved:.3f} m, tracked {fixed:.3f} m")
    assert fixed < moved and fixed < still + 0.03, (still, moved, fixed)


def test_camera_track_file_errors(tmp_path):
    from inference.clipio import FormatError
    from inference.courtfit.drift import CameraTrack

    path = tmp_path / "camera_track.csv"
    path.write_text("frame,dx_px,dy_px,measured\n0,0.5,0.1,1\n2,0.6,0.1,1\n")
    with pytest.raises(FormatError, match="camera_track.csv.*one row per frame"):
        CameraTrack.read(path, 3)
    path.write_text("frame,dx_px,dy_px,measured\n0,abc,0.1,1\n")
    with pytest.raises(FormatError, match="camera_track.csv, line 2"):
        CameraTrack.read(path, 1)


def test_infer_tracks_a_drifting_camera_and_the_3d_stage_uses_it(tmp_path):
    from inference.pipeline.run import run_pipeline
    from inference.pipeline.stages import PipelineConfig

    clip = _drifting_copy(tmp_path / "drift")
    shutil.copy(SAMPLE / "gt" / "camera.yaml", clip.root / "camera.yaml")
    report = run_pipeline(clip, PipelineConfig(progress=False, pose="none"), only={"camera", "reconstruct"},
                          log=lambda *_: None)
    notes = {s.name: s.note for s in report.stages}
    assert "tracked per frame (camera_track.csv" in notes["camera"], notes
    assert "2D stabilised by camera_track.csv" in notes["reconstruct"], notes
    assert (clip.root / "camera_track.csv").is_file()
    still = Clip(shutil.copytree(SAMPLE, tmp_path / "still"))  # a fixed camera: no track, none used
    shutil.copy(SAMPLE / "gt" / "camera.yaml", still.root / "camera.yaml")
    (still.root / "camera_track.csv").write_text("stale\n")  # from an older calibration: dropped
    report = run_pipeline(still, PipelineConfig(progress=False, pose="none"), only={"camera"}, log=lambda *_: None)
    assert not (still.root / "camera_track.csv").exists() and "tracked" not in report.stages[0].note


def test_the_track_reuses_the_frames_the_drift_check_measured(monkeypatch):
    """`rally3d infer` checks drift every second, then tracks every 0.2 s: the frames of the first pass are not
    measured again, and the track is the same as measured from scratch."""
    import inference.courtfit.drift as drift

    clip, cam, court = Clip(SAMPLE), Camera.load(SAMPLE / "gt" / "camera.yaml"), load_court("padel")
    first = measure_drift(clip, cam, court, every_s=2.0)
    fresh, _ = drift.track_camera(clip, cam, court, every_s=0.5)
    measured = []
    real = drift.frame_shift
    monkeypatch.setattr(drift, "frame_shift", lambda frame, *a, **k: measured.append(1) or real(frame, *a, **k))
    reused, report = drift.track_camera(clip, cam, court, every_s=0.5, known=first)
    overlap = len(set(first.frames) & set(report.frames))
    assert overlap >= 4 and len(measured) == len(report.frames) - overlap
    np.testing.assert_array_equal(reused.shift, fresh.shift)
    np.testing.assert_array_equal(reused.measured, fresh.measured)
