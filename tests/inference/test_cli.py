"""The rally3d command: discovery of subcommands, --help on each, calibrate/check/courts on real clips."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from inference.camera import Camera
from inference.cli import main

SAMPLE = Path(__file__).resolve().parents[2] / "datasets" / "sample" / "padel_sample"


@pytest.fixture
def sample(tmp_path) -> Path:
    dst = tmp_path / "padel_sample"
    shutil.copytree(SAMPLE, dst)
    return dst


def test_subcommands_are_discovered_from_entry_points(capsys):
    assert main([]) == 0
    out = capsys.readouterr().out
    for cmd in ("calibrate", "check", "courts"):
        assert cmd in out


@pytest.mark.parametrize("cmd", ["calibrate", "check", "courts"])
def test_help_on_each_subcommand(cmd, capsys):
    with pytest.raises(SystemExit) as e:
        main([cmd, "--help"])
    assert e.value.code == 0
    assert f"rally3d {cmd}" in capsys.readouterr().out


def test_console_script_runs():
    exe = Path(sys.executable).with_name("rally3d")
    if not exe.exists():
        pytest.skip("console script not installed (run make test)")
    out = subprocess.run([str(exe), "courts"], capture_output=True, text=True, check=True).stdout
    assert "padel" in out and "tennis" in out


def test_calibrate_writes_camera_close_to_ground_truth(sample, capsys):
    assert main(["calibrate", str(sample)]) == 0
    out = capsys.readouterr().out
    assert "RMS" in out and "net_post_left_top" in out and "camera centre error" in out
    cam = Camera.load(sample / "camera.yaml")
    gt = Camera.load(sample / "gt" / "camera.yaml")
    assert np.linalg.norm(cam.centre - gt.centre) < 0.1
    assert cam.rms_px < 1.5
    names = [ln.split(",")[0] for ln in (sample / "court_points.csv").read_text().splitlines()[1:]]
    assert sorted(cam.residuals_px) == sorted(names)


def test_calibrate_dry_run_writes_nothing(sample, capsys):
    assert main(["calibrate", str(sample), "--dry-run"]) == 0
    assert not (sample / "camera.yaml").exists()


def test_calibrate_from_floor_points_only(sample, capsys):
    lines = (sample / "court_points.csv").read_text().splitlines()
    ground = [lines[0]] + [ln for ln in lines[1:] if ln.split(",")[0] in {
        "far_left", "far_right", "near_service_left", "near_service_right", "far_service_center",
        "net_left", "net_right", "net_center"}]
    (sample / "court_points.csv").write_text("\n".join(ground) + "\n")
    assert main(["calibrate", str(sample)]) == 0
    out = capsys.readouterr().out
    assert "plane calibration" in out and "camera centre ±" in out
    cam = Camera.load(sample / "camera.yaml")
    assert cam.meta["method"] == "plane" and len(cam.meta["centre_sigma_m"]) == 3
    assert np.linalg.norm(cam.centre - Camera.load(sample / "gt" / "camera.yaml").centre) < 0.3


def test_calibrate_collinear_points_say_what_to_click(sample, capsys):
    (sample / "court_points.csv").write_text("name,x,y\n" + "".join(
        f"{n},0.{k + 1},0.5\n" for k, n in enumerate(["near_left", "near_service_left", "net_left",
                                                     "far_service_left", "far_left", "step_near_left_end_ground"])))
    assert main(["calibrate", str(sample)]) == 1
    err = capsys.readouterr().err
    assert "lie on one line" in err and "net_post_left_top" in err
    assert not (sample / "camera.yaml").exists()


def test_calibrate_unknown_point_name_names_file_and_line(sample, capsys):
    path = sample / "court_points.csv"
    path.write_text(path.read_text() + "net_top_middle,0.5,0.5\n")
    assert main(["calibrate", str(sample)]) == 1
    err = capsys.readouterr().err
    n_lines = len(path.read_text().splitlines())
    assert "court_points.csv" in err and f"line {n_lines}" in err and "net_center_top" in err


def test_check_reports_bad_file_with_line(sample, capsys):
    (sample / "ball.csv").write_text("frame,visibility,x,y\n0,1,0.5,0.5\n1,1,1.7,0.5\n")
    assert main(["check", str(sample)]) == 1
    out = capsys.readouterr().out
    assert "FAIL" in out and "ball.csv, line 3" in out
    assert "ok   events.csv" in out


def test_check_frame_beyond_video(sample, capsys):
    (sample / "events.csv").write_text("frame,event\n5,ground\n600,net\n")
    assert main(["check", str(sample)]) == 1
    assert "events.csv, line 3" in capsys.readouterr().out


def test_courts_lists_points(capsys):
    assert main(["courts", "padel"]) == 0
    out = capsys.readouterr().out
    assert "glass_near_left_top" in out and "wall_left" in out


def test_missing_clip_is_a_clear_error(tmp_path, capsys):
    assert main(["calibrate", str(tmp_path / "nope")]) == 1
    assert "clip.yaml" in capsys.readouterr().err


def test_check_opens_the_video_empty_and_truncated(sample, capsys):
    video = sample / "video.mp4"
    data = video.read_bytes()
    video.write_bytes(b"")
    assert main(["check", str(sample)]) == 1
    assert "video.mp4: the video file is empty" in capsys.readouterr().out
    video.write_bytes(data[: len(data) // 2])  # cut in half: the index (moov) or the last frames are lost
    assert main(["check", str(sample)]) == 1
    out = capsys.readouterr().out
    assert "FAIL" in out and "video.mp4" in out and "re-encode" in out
    video.write_bytes(data)
    assert main(["check", str(sample), "--full"]) == 0
    assert "240 frames, 240 decoded" in capsys.readouterr().out


def test_check_finds_frames_lost_at_the_end_of_a_faststart_video(tmp_path, capsys):
    """A video whose index sits at the start (faststart) still opens when its end is cut off."""
    import av

    clip = tmp_path / "c"
    clip.mkdir()
    with av.open(str(clip / "video.mp4"), "w", format="mp4", options={"movflags": "faststart"}) as out:
        stream = out.add_stream("libx264", rate=30)
        stream.width, stream.height, stream.pix_fmt = 320, 240, "yuv420p"
        rng = np.random.default_rng(0)
        for _ in range(60):  # noise: every frame is big, so cutting the file loses frames
            img = rng.integers(0, 255, (240, 320, 3), np.uint8)
            for packet in stream.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                out.mux(packet)
        for packet in stream.encode():
            out.mux(packet)
    data = (clip / "video.mp4").read_bytes()
    (clip / "video.mp4").write_bytes(data[: int(len(data) * 0.6)])
    (clip / "clip.yaml").write_text("sport: padel\nfps: 30\nwidth: 320\nheight: 240\nvideo: video.mp4\n")
    assert main(["check", str(clip)]) == 1
    out = capsys.readouterr().out
    assert "FAIL" in out and "video.mp4" in out and "cannot decode frame" in out


def test_check_refuses_a_camera_of_another_frame_size(sample, capsys):
    from dataclasses import replace

    cam = Camera.load(sample / "gt" / "camera.yaml")
    replace(cam, image_size=(1920, 1080)).save(sample / "camera.yaml")
    assert main(["check", str(sample)]) == 1
    out = capsys.readouterr().out
    assert "camera.yaml: the calibration is for 1920×1080 frames but the video is 1280×720" in out


def test_check_events_use_the_courts_labels(sample, capsys):
    (sample / "clip.yaml").write_text((sample / "clip.yaml").read_text().replace("sport: padel", "sport: tennis"))
    (sample / "events.csv").write_text("frame,event\n5,ground\n9,wall_left\n")
    assert main(["check", str(sample)]) == 1
    assert "events.csv, line 3: unknown event 'wall_left'" in capsys.readouterr().out


def test_reconstruct_refuses_a_camera_of_another_frame_size(sample, capsys):
    from dataclasses import replace

    cam = Camera.load(sample / "gt" / "camera.yaml")
    replace(cam, image_size=(1920, 1080)).save(sample / "camera.yaml")
    assert main(["reconstruct", str(sample)]) == 1
    err = capsys.readouterr().err
    assert "camera.yaml" in err and "1920×1080" in err and "1280×720" in err
    assert not (sample / "ball_3d.csv").exists()


HEAVY = ("torch", "lightning", "pytorch_lightning", "cv2", "viser", "scipy")
_LOADED_AFTER_HELP = """
import sys
from inference.cli import main
try:
    main(sys.argv[1:])
except SystemExit:
    pass
print(" ".join(sorted(m for m in sys.modules if m.split(".")[0] in {heavy!r})))
"""


def _heavy_modules_after(argv: list[str]) -> set[str]:
    """Top-level heavy packages in ``sys.modules`` after ``rally3d *argv`` ran in a fresh interpreter."""
    repo = str(Path(__file__).resolve().parents[2])
    code = _LOADED_AFTER_HELP.format(heavy=set(HEAVY))
    res = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, cwd=repo,
                         env={**os.environ, "PYTHONPATH": repo}, check=True)
    assert "usage: rally3d" in res.stdout, res.stdout + res.stderr
    return {line.split(".")[0] for line in res.stdout.splitlines()[-1].split()}


def test_help_loads_no_heavy_library():
    """`rally3d --help` and every command's --help parse without torch, Lightning, OpenCV, viser or SciPy."""
    from importlib.metadata import entry_points

    from inference.cli import GROUP

    names = sorted(ep.name for ep in entry_points(group=GROUP))
    assert {"reconstruct", "detect", "label", "infer"} <= set(names)
    assert _heavy_modules_after(["--help"]) == set()
    for name in names:
        assert _heavy_modules_after([name, "--help"]) == set(), f"rally3d {name} --help"


def test_calibrate_reads_points_clicked_along_court_lines(sample, capsys):
    """court_line_points.csv (start,end,x,y): clicks along the two side lines of a wide-angle camera, with eight
    floor points in court_points.csv, give the lens (--distortion 1) and the camera; rally3d check reads the
    file, and a name that is no court point is an error naming the file and its line."""
    from inference.court import load_court

    court = load_court("padel")
    true = Camera.from_look_at(eye=[5.0, -1.5, 6.5], target=[5.0, 8.5, 0.0], image_size=(1280, 720), fov_deg=100,
                               dist=np.array([-0.45, 0, 0, 0, 0]))
    size = np.array([1280.0, 720.0])
    names = ["near_service_left", "near_service_right", "far_service_left", "far_service_right", "net_left",
             "net_right", "far_left", "far_right"]
    px = true.project(court.point_array(names)) / size
    (sample / "court_points.csv").write_text("name,x,y\n" + "".join(f"{n},{x:.6f},{y:.6f}\n" for n, (x, y) in zip(names, px)))
    rows = []
    for a, b in (("near_left", "far_left"), ("near_right", "far_right")):
        for s in np.linspace(0.1, 0.9, 6):
            x, y = true.project((court.points[a] + s * (court.points[b] - court.points[a]))[None])[0] / size
            rows.append(f"{a},{b},{x:.6f},{y:.6f}\n")
    (sample / "court_line_points.csv").write_text("start,end,x,y\n" + "".join(rows))
    (sample / "camera.yaml").unlink(missing_ok=True)
    assert main(["calibrate", str(sample), "--distortion", "1"]) == 0
    out = capsys.readouterr().out
    assert "+ 12 along court lines (court_line_points.csv)" in out and "lens k1" in out
    cam = Camera.load(sample / "camera.yaml")
    assert np.linalg.norm(cam.centre - true.centre) < 0.1 and abs(cam.dist[0] + 0.45) < 0.02
    assert main(["check", str(sample)]) == 0
    assert "ok   court_line_points.csv 12" in capsys.readouterr().out
    (sample / "court_line_points.csv").write_text("start,end,x,y\nnear_left,far_left,0.2,0.5\nnear_left,far_lft,0.3,0.4\n")
    assert main(["calibrate", str(sample)]) == 1
    err = capsys.readouterr().err
    assert "court_line_points.csv" in err and "line 3" in err and "far_left" in err
