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


class ShapeRecordingYellowNet(YellowNet):
    """YellowNet that records the input shapes it is given (a class list: the runner deep-copies the model)."""

    shapes: list = []

    def forward(self, x):
        ShapeRecordingYellowNet.shapes.append(tuple(x.shape))
        return super().forward(x)


def test_4k_mov_is_downscaled_for_the_network_and_answers_in_4k_pixels(tmp_path):
    """A 3840×2160 .mov at 50 fps: the network sees its own 288×512 input, ball.csv is in the 4K frame."""
    import cv2

    from inference.clipio import ClipInfo, write_video

    n, w, h = 12, 3840, 2160
    clip = Clip.create(tmp_path / "uhd", ClipInfo(sport="padel", fps=50.0, width=w, height=h, video="video.mov"))
    truth = np.stack([600 + 230 * np.arange(n), 1700 - 90 * np.arange(n)], axis=1).astype(float)
    frames = []
    for p in truth:
        img = np.full((h, w, 3), (40, 70, 140), np.uint8)
        cv2.circle(img, tuple(np.round(p).astype(int)), 16, (215, 232, 62), -1, cv2.LINE_AA)
        frames.append(img)
    write_video(clip.video_path, frames, 50.0, fourcc="h264")
    ShapeRecordingYellowNet.shapes.clear()
    result = BallDetectorRunner(ShapeRecordingYellowNet(), normalize="unit", step=3).run(clip)
    assert {s[1:] for s in ShapeRecordingYellowNet.shapes} == {(9, 288, 512)}
    best = np.array([c.xy[0] for c in result.candidates])  # original pixels, best candidate per frame
    err = np.linalg.norm(best - truth, axis=1)
    assert err.max() < 8.0, err  # one network pixel is 7.5 px of the 4K frame
    seen = result.track.visibility == 1
    assert seen.sum() >= n - 2
    px = result.track.to_pixels(w, h)[seen]
    assert np.linalg.norm(px - truth[seen], axis=1).max() < 8.0


def test_only_active_frames_are_searched_and_tracks_stop_at_cuts(clip):
    """``active`` (court-view scenes): frames outside get no candidates and no ball; no track crosses the gap."""
    active = np.ones(clip.n_frames, bool)
    active[25:35] = False
    result = BallDetectorRunner(YellowNet(), normalize="unit", batch_size=8).run(clip, active=active)
    assert len(result.track) == clip.n_frames
    assert all(result.candidates[i].count == 0 for i in range(25, 35))
    assert not (result.track.visibility[25:35] > 0).any()
    ids = result.tracked.track_id
    before, after = set(ids[:25][ids[:25] >= 0]), set(ids[35:][ids[35:] >= 0])
    assert before and after and not before & after
    report = evaluate_ball_tracks(result.track, clip.read_ball(), 640, 360, tau_px=4.0, ignore_flags=(3,))
    assert report.recall > 0.7, report.as_dict()


def test_auto_mask_hides_a_burnt_in_scoreboard_from_the_detector(tmp_path):
    """A noisy, drifting 640×360 clip with court lines, the ball and a score panel whose yellow serve dot
    looks like a ball: with ``mask: auto`` the network gets no candidate inside the panel."""
    import cv2

    from inference.clipio import BallTrack, ClipInfo, write_video
    from inference.video.masks import clip_mask

    n, box = 60, (20, 15, 190, 60)
    clip = Clip.create(tmp_path / "board", ClipInfo(sport="padel", fps=30.0, width=640, height=360, video="video.mp4",
                                                    n_frames=n))
    rng = np.random.default_rng(3)
    t = np.arange(n) / 30.0
    xy = np.stack([80 + 250 * t, 300 - 400 * t + 200 * t**2], axis=1)
    frames = []
    for i, p in enumerate(xy):
        img = np.full((360, 640, 3), (40, 70, 140), np.uint8)
        d = 5.0 * i / (n - 1)  # the camera creeps: the court's edges move, the panel's do not
        for (x0, y0), (x1, y1) in (((60, 330), (580, 330)), ((150, 120), (490, 120)), ((60, 330), (150, 120)),
                                   ((580, 330), (490, 120)), ((320, 120), (320, 330))):
            cv2.line(img, (int(x0 + d), int(y0 - d)), (int(x1 + d), int(y1 - d)), (235, 235, 235), 2, cv2.LINE_AA)
        cv2.circle(img, tuple(np.round(p).astype(int)), 5, (215, 232, 62), -1, cv2.LINE_AA)
        img = np.clip(img + rng.normal(0, 3.0, img.shape), 0, 255).astype(np.uint8)
        img[box[1]:box[3], box[0]:box[2]] = (25, 30, 70)
        cv2.putText(img, "GALAN 6 4", (box[0] + 8, box[1] + 30), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 2)
        cv2.circle(img, (box[2] - 16, box[1] + 22), 5, (215, 232, 62), -1, cv2.LINE_AA)  # the serve dot
        frames.append(img)
    write_video(clip.video_path, frames, 30.0, fourcc="h264", crf=18)
    clip.write_ball(BallTrack(np.arange(n), np.ones(n, np.int8), xy / [640, 360]))

    def in_panel(c: Clip) -> tuple[int, float]:
        result = BallDetectorRunner(YellowNet(), normalize="unit", batch_size=8).run(c)
        hits = sum(int(np.any((fc.xy[:, 0] >= box[0]) & (fc.xy[:, 0] < box[2]) & (fc.xy[:, 1] >= box[1]) &
                              (fc.xy[:, 1] < box[3]))) for fc in result.candidates if len(fc.xy))
        recall = evaluate_ball_tracks(result.track, c.read_ball(), 640, 360, tau_px=4.0).recall
        return hits, recall

    hits, _ = in_panel(clip)
    assert hits > 30  # the dot fires without a mask
    (clip.root / "clip.yaml").write_text((clip.root / "clip.yaml").read_text() + "mask: auto\n")
    rects = clip_mask(Clip(clip.root))
    assert len(rects) == 1
    hits, recall = in_panel(Clip(clip.root))
    assert hits == 0 and recall > 0.8


@pytest.mark.parametrize("n, batch", [(20, 1), (20, 8), (22, 4), (21, 8)])
def test_every_frame_is_searched_up_to_the_last(tmp_path, n, batch):
    """Windows of 3 every 3 frames leave the last (n - 3) % 3 frames out unless one more window ends at the
    last frame; its frames that earlier windows searched are not counted twice, whatever the batch size."""
    xy = np.stack([np.linspace(60, 560, n), np.full(n, 180.0)], axis=1)
    clip = render_clip(tmp_path / f"c{n}_{batch}", xy, still=())
    result = BallDetectorRunner(YellowNet(), normalize="unit", batch_size=batch).run(clip)
    assert len(result.candidates) == n
    assert all(c.count == 1 for c in result.candidates)             # one ball each, none repeated
    assert np.linalg.norm(result.candidates[-1].xy[0] - xy[-1]) < 2.0
    crop = BallDetectorRunner(YellowNet(), normalize="unit", batch_size=batch)
    maps, _ = crop.heatmaps(iter([np.zeros((288, 512, 3), np.uint8)] * n))
    assert sorted(maps) == list(range(n)) and all(len(v) == 1 for v in maps.values())
