"""Generated clips: reproducible, self-consistent ground truth, labels on the rendered ball, datasets."""
from __future__ import annotations

import numpy as np
import pytest

from inference.clipio import Clip, Manifest
from inference.court import load_court
from synth.generate import SynthConfig, generate_clip, generate_dataset, split_assignment
from synth.render import Appearance, CourtRenderer

FAST = dict(randomise_camera=False, width=1280, height=720, fps=30.0, max_frames=48, codec="mp4v")


@pytest.fixture(scope="module")
def padel_clip(tmp_path_factory):
    out = tmp_path_factory.mktemp("synth") / "padel"
    generate_clip(out, seed=5, config=SynthConfig(sport="padel", randomise_look=False, **FAST))
    return Clip(out)


def files_of(root):
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("codec", ["mp4v", "h264"])
def test_same_seed_identical_files(tmp_path, codec):
    cfg = SynthConfig(sport="padel", **{**FAST, "max_frames": 12, "codec": codec})
    generate_clip(tmp_path / "a", seed=11, config=cfg)
    generate_clip(tmp_path / "b", seed=11, config=cfg)
    generate_clip(tmp_path / "c", seed=12, config=cfg)
    a, b, c = files_of(tmp_path / "a"), files_of(tmp_path / "b"), files_of(tmp_path / "c")
    assert a.keys() == b.keys() and all(a[k] == b[k] for k in a)
    assert a["gt/players.csv"] != c["gt/players.csv"]


def test_clip_folder_is_complete_and_valid(padel_clip):
    info = padel_clip.info
    assert (info.width, info.height, info.fps) == (1280, 720, 30.0)
    n = padel_clip.n_frames
    assert len(padel_clip.frames()) == n
    for read in (padel_clip.read_ball, padel_clip.read_events, padel_clip.read_inactive_balls,
                 padel_clip.read_court_points):
        read()
    assert len(padel_clip.read_ball()) == n
    players = padel_clip.read_players(gt=True)
    assert players.has_3d and len(players.ids()) == 4
    assert sorted(set(players.team.tolist())) == ["far", "near"]


def test_labels_are_projections_of_3d_truth(padel_clip):
    cam = padel_clip.read_camera(gt=True)
    ball = padel_clip.read_ball()
    gt = padel_clip.read_ball_3d(gt=True)
    shown = np.isin(ball.frame, gt.frame) & (ball.visibility > 0)
    assert shown.sum() > 10
    proj = cam.project_normalized(gt.xyz[np.searchsorted(gt.frame, ball.frame[shown])])
    np.testing.assert_allclose(proj * [1280, 720], ball.xy[shown] * [1280, 720], atol=0.75)


def test_labelled_ball_is_on_the_rendered_ball(padel_clip):
    """Pixel check: at each visible label the frame is pulled from the background towards the ball colour."""
    court = load_court("padel")
    look = Appearance.plain("padel")
    background = CourtRenderer(court, padel_clip.read_camera(gt=True), look).background().astype(float)
    frames = padel_clip.frames()
    ball = padel_clip.read_ball()
    ball_rgb = np.asarray(look.ball, float)
    checked = 0
    for f in np.flatnonzero(ball.visibility == 1):
        x, y = np.round(ball.to_pixels(1280, 720)[f]).astype(int)
        px = frames[int(f)][y - 1:y + 2, x - 1:x + 2].reshape(-1, 3).astype(float)
        bg = background[y - 1:y + 2, x - 1:x + 2].reshape(-1, 3)
        # the best pixel of the 3x3 neighbourhood is nearer the ball colour than the background was
        assert (np.linalg.norm(px - ball_rgb, axis=1).min() < np.linalg.norm(bg - ball_rgb, axis=1).min()), f
        checked += 1
    assert checked >= 5


def test_event_frames_are_where_the_ball_touched(padel_clip):
    court = load_court("padel")
    events = padel_clip.read_events()
    gt = padel_clip.read_ball_3d(gt=True)
    players = padel_clip.read_players(gt=True)
    fps = padel_clip.info.fps
    vel = np.gradient(gt.xyz, axis=0) * fps
    assert len(events) >= 2
    for f, label in zip(events.frame, events.event):
        i = int(np.searchsorted(gt.frame, f))
        assert gt.frame[i] == f
        p, slack = gt.xyz[i], np.linalg.norm(vel[i]) / fps + 0.02  # ≤ one frame of travel
        if label.startswith("player"):
            team = label.split("_")[1]
            rows = (players.frame == f) & (players.team == team)
            wrists = players.joints_3d[rows][:, [9, 10]].reshape(-1, 3)
            assert np.linalg.norm(wrists - p, axis=1).min() < 1.2 + slack, (f, label)
        else:
            planes = court.planes_for(label)
            d = min(abs((p - pl.origin) @ pl.normal) for pl in planes)
            assert d < court.ball.radius + slack, (f, label, d)


def test_dataset_with_manifest_and_splits(tmp_path):
    cfg = SynthConfig(sport="tennis", **{**FAST, "max_frames": 8})
    manifest = generate_dataset(tmp_path / "ds", n_clips=4, seed=3, config=cfg)
    back = Manifest.load(tmp_path / "ds")
    assert [c.path for c in back.clips] == [f"clip_{k:04d}" for k in range(4)]
    assert back.counts() == manifest.counts() and back.counts()["val"] == 1 and back.counts()["test"] == 1
    for entry, path in zip(back.clips, back.paths()):
        assert Clip(path).info.split == entry.split and Clip(path).info.sport == "tennis"


def test_split_assignment_proportions():
    s = split_assignment(100, (0.8, 0.1, 0.1), np.random.default_rng(0))
    assert s.count("train") == 80 and s.count("val") == 10 and s.count("test") == 10


def test_cli_synth(tmp_path, capsys):
    from inference.cli import main

    rc = main(["synth", "--sport", "padel", "--clips", "1", "--out", str(tmp_path / "d"), "--seed", "1",
               "--fixed-camera", "--plain", "--max-frames", "6", "--codec", "mp4v", "--size", "640x360",
               "--fps", "25"])
    assert rc == 0
    assert "wrote 1 clips" in capsys.readouterr().out
    assert Clip(tmp_path / "d" / "clip_0000").info.width == 640
