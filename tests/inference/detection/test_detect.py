"""The whole-clip detection pipeline (letterbox → windows → heatmaps → candidates → tracker), with a
hand-made colour "network" that sees the rendered ball, and the rally3d detect command."""
from __future__ import annotations

import numpy as np
import pytest
from detection_helpers import YellowNet, render_clip

from inference.cli import main
from inference.clipio import Clip
from inference.detection.detect import BallDetectorRunner
from inference.detection.metrics import evaluate_ball_tracks
from inference.models.checkpoint import save_wasb_checkpoint
from inference.models.registry import build_model


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    """A 640×360 clip: a yellow ball on a parabola, a still yellow ball on the floor, a dark court."""
    t = np.arange(60) / 30.0
    xy = np.stack([80 + 250 * t, 300 - 400 * t + 200 * t**2], axis=1)    # stays in the frame
    return render_clip(tmp_path_factory.mktemp("det") / "clip", xy)


def test_pipeline_finds_the_rendered_ball(clip):
    runner = BallDetectorRunner(YellowNet(), normalize="unit", batch_size=8)
    result = runner.run(clip)
    assert len(result.track) == clip.n_frames == len(result.candidates)
    report = evaluate_ball_tracks(result.track, clip.read_ball(), 640, 360, tau_px=4.0, ignore_flags=(3,))
    assert report.f1 > 0.9, report.as_dict()
    seen = result.track.visibility == 1
    assert not np.any(np.linalg.norm(result.track.to_pixels(640, 360)[seen] - [500, 320], axis=1) < 6)


def test_overlapping_windows_pool_candidates(clip):
    dense = BallDetectorRunner(YellowNet(), normalize="unit", step=1).run(clip)
    sparse = BallDetectorRunner(YellowNet(), normalize="unit", step=3).run(clip)
    assert sum(len(c.score) for c in dense.candidates) > sum(len(c.score) for c in sparse.candidates)


def test_cli_detect_with_weights(clip, tmp_path, capsys):
    weights = save_wasb_checkpoint(build_model("wasb"), tmp_path / "w.pth.tar")
    assert main(["detect", str(clip.root), "--weights", str(weights), "--out", str(tmp_path / "ball.csv")]) == 0
    assert "frames/s" in capsys.readouterr().out
    assert (tmp_path / "ball.csv").read_text().startswith("frame,visibility,x,y")


def test_cli_detect_missing_weights(clip, tmp_path, capsys):
    assert main(["detect", str(clip.root), "--weights", str(tmp_path / "nope.pth")]) == 1
    assert "never downloads weights" in capsys.readouterr().err


def test_tennis_clip_says_plainly_which_detector_it_gets(tmp_path, capsys):
    """No tennis detector is shipped: `rally3d detect` on a tennis clip names the padel weights it uses."""
    from inference.clipio import ClipInfo, write_video
    from inference.detection.detect import SHIPPED, shipped_weights

    path, which = shipped_weights("wasb", "tennis")
    assert path == SHIPPED["wasb"] and "no tennis ball detector" in which and "padel" in which
    assert "wasb_tennis" in which  # and how to train one
    assert "no " not in shipped_weights("wasb", "padel")[1]
    clip = Clip.create(tmp_path / "tennis", ClipInfo(sport="tennis", fps=25.0, width=320, height=180,
                                                     video="video.mp4", n_frames=3))
    write_video(clip.video_path, [np.full((180, 320, 3), (60, 120, 60), np.uint8) for _ in range(3)], 25.0)
    main(["detect", str(clip.root), "--out", str(tmp_path / "ball.csv")])
    err = capsys.readouterr().err
    assert "warning: no tennis ball detector is shipped" in err and "wasb_padel" in err


def test_mask_in_clip_yaml_hides_a_scoreboard_from_the_detector(clip, tmp_path):
    """A still yellow blob stands for a scoreboard: masked in clip.yaml, the network sees no candidate there."""
    import shutil

    from inference.clipio import FormatError

    def near_still_ball(c: Clip) -> int:
        result = BallDetectorRunner(YellowNet(), normalize="unit", batch_size=8).run(c)
        return sum(int(np.any(np.linalg.norm(fc.xy - [500, 320], axis=1) < 8)) for fc in result.candidates
                   if len(fc.xy))

    masked = tmp_path / "masked"
    shutil.copytree(clip.root, masked)
    text = (masked / "clip.yaml").read_text()
    assert near_still_ball(Clip(masked)) > 30
    (masked / "clip.yaml").write_text(text + "mask:\n  - [0.74, 0.82, 0.82, 0.96]\n")
    assert near_still_ball(Clip(masked)) == 0
    (masked / "clip.yaml").write_text(text + "mask:\n  - [0.9, 0.1, 0.8, 0.2]\n")
    with pytest.raises(FormatError, match=r"clip.yaml.*mask entry 1") as e:
        BallDetectorRunner(YellowNet(), normalize="unit").run(Clip(masked))
    assert "normalised" in str(e.value)
