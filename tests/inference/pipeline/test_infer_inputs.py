"""``rally3d infer`` on bad inputs: clear message, partial results kept, exit code non-zero; resuming."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from inference.cli import main
from inference.clipio import Clip, write_frames_folder, write_video

SAMPLE = Path(__file__).resolve().parents[3] / "datasets" / "sample" / "padel_sample"


def _blank_clip(root: Path, n: int = 9, frames_folder: bool = False) -> Path:
    """A padel clip of grey frames (no ball) with the sample's court points."""
    root.mkdir(parents=True)
    frames = [np.full((720, 1280, 3), 90, np.uint8) for _ in range(n)]
    if frames_folder:
        write_frames_folder(root / "frames", frames)
        video = "frames/"
    else:
        write_video(root / "video.mp4", frames, fps=30.0)
        video = "video.mp4"
    (root / "clip.yaml").write_text(f"sport: padel\nfps: 30\nwidth: 1280\nheight: 720\nvideo: {video}\n")
    shutil.copy(SAMPLE / "court_points.csv", root / "court_points.csv")
    return root


def test_corrupt_video_is_named_with_a_fix(tmp_path, capsys):
    bad = tmp_path / "rally.mp4"
    bad.write_bytes(b"\x00\x00\x00\x18ftypmp42" + bytes(range(256)) * 40)
    code = main(["infer", str(bad), "--court", "padel", "--out", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 1
    assert "rally.mp4" in err and "re-encode" in err


def test_video_needs_a_court(tmp_path, capsys):
    code = main(["infer", str(SAMPLE / "video.mp4"), "--out", str(tmp_path / "o"), "--no-progress"])
    assert code == 1 and "--court" in capsys.readouterr().err


def test_calibration_of_another_frame_size_stops_before_detection(tmp_path, capsys):
    clip = _blank_clip(tmp_path / "c")
    cam = Clip(SAMPLE).read_camera(gt=True)
    from dataclasses import replace

    other = replace(cam, image_size=(1920, 1080))
    other.save(tmp_path / "camera_1080.yaml")
    code = main(["infer", str(clip), "--camera", str(tmp_path / "camera_1080.yaml"), "--no-progress", "--pose", "none"])
    out = capsys.readouterr()
    assert code == 1
    assert "1920×1080" in out.err + out.out and "1280×720" in out.err + out.out
    assert not (clip / "camera.yaml").exists()


def test_missing_detector_weights(tmp_path, capsys):
    clip = _blank_clip(tmp_path / "c")
    code = main(["infer", str(clip), "--detector", str(tmp_path / "nope.pth.tar"), "--no-progress", "--pose", "none"])
    out = capsys.readouterr()
    assert code == 1
    assert "nope.pth.tar" in out.out and "never downloaded" in out.out
    assert (clip / "camera.yaml").is_file()  # the calibration (done before) is kept


def test_no_detections_keeps_partial_results(tmp_path, capsys):
    clip = _blank_clip(tmp_path / "c")
    code = main(["infer", str(clip), "--no-progress", "--pose", "none"])
    out = capsys.readouterr()
    assert code == 1
    assert "no ball detected" in out.out
    assert (clip / "camera.yaml").is_file()
    assert "reconstruct  blocked" in out.out


def test_truncated_frames_keep_the_decoded_part(tmp_path, capsys):
    clip = _blank_clip(tmp_path / "c", n=12, frames_folder=True)
    (clip / "frames" / "000007.jpg").write_bytes(b"not a jpeg")
    code = main(["infer", str(clip), "--no-progress", "--pose", "none", "--only", "camera,detect,smooth"])
    out = capsys.readouterr().out
    assert code == 1
    assert "truncated" in out and "000007.jpg" in out
    ball = Clip(clip).read_ball()
    assert ball.frame.max() == 6  # frames 0..6 decoded and kept


def test_hand_annotations_are_never_overwritten(tmp_path, capsys):
    clip = tmp_path / "annotated"
    shutil.copytree(SAMPLE, clip)
    before = (clip / "ball.csv").read_bytes()
    code = main(["infer", str(clip), "--no-progress", "--pose", "none", "--only", "camera,smooth"])
    out = capsys.readouterr().out
    assert code == 1
    assert (clip / "ball.csv").read_bytes() == before
    assert "--out" in out or "detect" in out


def test_resume_skips_unchanged_stages(tmp_path, capsys):
    clip = _blank_clip(tmp_path / "c")
    main(["infer", str(clip), "--no-progress", "--pose", "none", "--only", "camera"])
    capsys.readouterr()
    main(["infer", str(clip), "--no-progress", "--pose", "none", "--only", "camera"])
    assert "camera       cached" in capsys.readouterr().out
    (clip / "court_points.csv").write_text((clip / "court_points.csv").read_text().replace("0.", "0.0", 1))
    main(["infer", str(clip), "--no-progress", "--pose", "none", "--only", "camera"])
    assert "camera       done" in capsys.readouterr().out


def test_a_code_change_reruns_the_stages_it_touches(tmp_path, capsys, monkeypatch):
    """An upgrade that changes a stage's code must not keep that stage's stale outputs."""
    from inference.pipeline import state

    clip = _blank_clip(tmp_path / "c")
    main(["infer", str(clip), "--no-progress", "--pose", "none", "--only", "camera"])
    capsys.readouterr()
    real = state.code_fingerprint
    changed = lambda mods: real(mods) + ("-new" if "inference.camera" in mods else "")  # noqa: E731
    monkeypatch.setattr(state, "code_fingerprint", changed)
    main(["infer", str(clip), "--no-progress", "--pose", "none", "--only", "camera"])
    assert "camera       done" in capsys.readouterr().out


def test_code_fingerprint_follows_the_source(tmp_path, monkeypatch):
    from inference.pipeline.state import code_fingerprint

    pkg = tmp_path / "fp_pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "mod.py").write_text("X = 1\n")
    (pkg / "other.py").write_text("Y = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    before = code_fingerprint.__wrapped__(("fp_pkg",))
    assert code_fingerprint.__wrapped__(("fp_pkg.other",)) != before
    (pkg / "sub" / "mod.py").write_text("X = 2\n")  # a file deep in the package
    assert code_fingerprint.__wrapped__(("fp_pkg",)) != before
    with pytest.raises(ModuleNotFoundError, match="fp_pkg_typo"):
        code_fingerprint.__wrapped__(("fp_pkg_typo",))


def test_several_clips_go_through_lightnings_predict_loop(tmp_path, capsys):
    a, b = _blank_clip(tmp_path / "a"), _blank_clip(tmp_path / "b", n=6)
    code = main(["infer", str(a), str(b), "--out", str(tmp_path / "out"), "--no-progress", "--pose", "none",
                 "--accelerator", "cpu"])
    out = capsys.readouterr().out
    assert code == 1  # grey frames: no ball, so both are incomplete
    assert out.count("INCOMPLETE") == 2 and "0/2 clips complete" in out
    for name in ("a", "b"):
        assert (tmp_path / "out" / name / "camera.yaml").is_file()
        assert (tmp_path / "out" / name / ".rally3d" / "pipeline.json").is_file()


def test_start_end_cut_a_stretch_of_a_long_video(tmp_path, capsys):
    from inference.clipio.frames import FrameSource

    out = tmp_path / "cut"
    args = ["infer", str(SAMPLE / "video.mp4"), "--court", "padel", "--court-points",
            str(SAMPLE / "court_points.csv"), "--start", "2", "--end", "3", "--out", str(out), "--no-progress",
            "--pose", "none", "--only", "camera"]
    assert main(args) == 0, capsys.readouterr()
    clip = Clip(out)
    assert clip.n_frames == 30 and clip.info.extra["cut"]["first_frame"] == 60
    with FrameSource.open(SAMPLE / "video.mp4") as src, FrameSource.open(clip.video_path) as cut:
        same = np.abs(cut.read(0).astype(float) - src.read(60)).mean()
        other = np.abs(cut.read(0).astype(float) - src.read(0)).mean()
    assert same < 3.0 and same < other
    assert (out / "camera.yaml").is_file()
    mtime = clip.video_path.stat().st_mtime_ns
    assert main(args) == 0  # the same stretch again: resumed, not re-cut
    assert clip.video_path.stat().st_mtime_ns == mtime
    assert main(["infer", str(SAMPLE / "video.mp4"), "--court", "padel", "--start", "3", "--end", "2",
                 "--out", str(tmp_path / "bad")]) == 1
    assert "must come after --start" in capsys.readouterr().err


def test_court_points_given_in_place_back_up_the_clicked_file(tmp_path, capsys):
    clip = _blank_clip(tmp_path / "c")
    clicked = (clip / "court_points.csv").read_text()
    other = tmp_path / "other_points.csv"
    lines = clicked.splitlines()
    other.write_text("\n".join(lines[:-1]) + "\n")  # one point fewer: a different file
    code = main(["infer", str(clip), "--court-points", str(other), "--no-progress", "--pose", "none",
                 "--only", "camera"])
    out = capsys.readouterr().out
    assert code == 0
    assert (clip / "court_points.csv").read_text() != clicked
    backups = list((clip / ".rally3d" / "backup").glob("court_points.csv.*"))
    assert len(backups) == 1 and backups[0].read_text() == clicked
    assert "court_points.csv replaced" in out and str(backups[0]) in out


def test_camera_given_in_place_backs_up_the_clip_camera(tmp_path, capsys):
    clip = _blank_clip(tmp_path / "c")
    cam = Clip(SAMPLE).read_camera(gt=True)
    cam.save(clip / "camera.yaml")
    mine = (clip / "camera.yaml").read_text()
    from dataclasses import replace

    moved = replace(cam, P=cam.P * 1.0001)
    moved.save(tmp_path / "new_camera.yaml")
    code = main(["infer", str(clip), "--camera", str(tmp_path / "new_camera.yaml"), "--no-progress",
                 "--pose", "none", "--only", "camera"])
    out = capsys.readouterr().out
    assert code == 0
    backups = list((clip / ".rally3d" / "backup").glob("camera.yaml.*"))
    assert len(backups) == 1 and backups[0].read_text() == mine
    assert "camera.yaml replaced" in out
    # the same file again: nothing to back up
    main(["infer", str(clip), "--camera", str(tmp_path / "new_camera.yaml"), "--no-progress", "--pose", "none",
          "--only", "camera"])
    capsys.readouterr()
    assert len(list((clip / ".rally3d" / "backup").glob("camera.yaml.*"))) == 1
