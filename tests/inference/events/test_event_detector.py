"""The runtime EventDetector: shipped defaults load offline and find events on held-out simulated clips,
grouped classes resolve to their surface with a camera, bad inputs give clear errors, and the CLI
writes events.csv."""
from __future__ import annotations

import numpy as np
import pytest

from inference.clipio import BallTrack, Clip, ClipInfo, HitEvents, read_events_csv
from inference.events import ClassSet, DecodeParams, EventCounts, EventDetector, FeatureConfig, HitNet, tolerance_frames
from inference.events.detector import default_weights
from training.events.simulate import simulate_clips


@pytest.fixture(scope="module")
def clips():
    return simulate_clips("padel", 6, seed=4242, progress=False)  # seeds no training set uses


def test_shipped_padel_default_finds_events_on_held_out_clips(clips):
    det = EventDetector.from_checkpoint(None, sport="padel")
    cs = det.class_set
    assert cs.name == "padel6" and det.kind in ("hitnet", "physics")
    counts = EventCounts(cs.classes)
    for c in clips:
        r = det.predict(c.ball, c.fps, c.width, c.height, camera=c.camera, n_frames=c.n_frames)
        assert isinstance(r.events, HitEvents) and r.probs.shape == (c.n_frames, cs.n) and r.classes == cs.classes
        assert np.allclose(r.probs.sum(axis=1), 1.0, atol=1e-4)
        assert set(r.events.event.tolist()) <= set(cs.map)
        gt = cs.encode(c.events, c.n_frames)
        counts.add(np.flatnonzero(gt), gt[gt > 0], r.events.frame, [cs.encode_label(e) for e in r.events.event],
                   tolerance_frames(c.fps))
    assert counts.scores()["f1"] > 0.6, counts.scores()


def test_hits_in_gaps_keep_the_models_timing_unless_bridging_is_asked(clips):
    """Racket hits hidden by the tracker: by default the model's own frame stands (no uncertainty given);
    ``bridge_gaps=True`` times them from the flights on both sides of the gap and says how sure it is."""
    det = EventDetector.from_checkpoint(None, sport="padel")
    moved = 0
    for c in clips:
        vis = c.ball.visibility.copy()
        for f, e in zip(c.events.frame, c.events.event):
            if e.startswith("player"):
                vis[max(f - 3, 0):f + 4] = 0  # the body hides the ball around each hit
        track = BallTrack(c.ball.frame, vis, np.where(vis[:, None] > 0, c.ball.xy, np.nan))
        plain = det.predict(track, c.fps, c.width, c.height, camera=c.camera, n_frames=c.n_frames)
        bridged = det.predict(track, c.fps, c.width, c.height, camera=c.camera, n_frames=c.n_frames,
                              bridge_gaps=True)
        assert np.isnan(plain.uncertainty).all()
        assert np.array_equal(plain.probs, bridged.probs)
        moved += int(np.isfinite(bridged.uncertainty).sum())
    assert moved > 0


def test_shipped_tennis_default_loads():
    det = EventDetector.from_checkpoint(None, sport="tennis")
    assert det.class_set.classes == ("none", "ground", "player_near", "player_far")


def test_grouped_class_resolves_to_the_surface_with_a_camera(clips):
    det = EventDetector("hitnet", ClassSet.load("padel6"), FeatureConfig(), DecodeParams(),
                        net=HitNet(5, 6, 8, 1))
    seen = 0
    for c in clips:
        for f, e in zip(c.events.frame, c.events.event):
            if e in ("wall_far", "wall_left", "wall_right") and c.ball.visibility[f] > 0:
                assert det.resolve("ground_or_other_wall", int(f), c.ball, c.n_frames, c.camera) in (
                    "wall_far", "wall_left", "wall_right", "ground")
                assert det.resolve("ground_or_other_wall", int(f), c.ball, c.n_frames, None) == "ground"
                seen += 1
            if e == "ground" and c.ball.visibility[f] > 0:
                assert det.resolve("ground_or_other_wall", int(f), c.ball, c.n_frames, c.camera) == "ground"
    assert seen > 0


def test_all_missing_ball_warns_and_finds_nothing():
    det = EventDetector.from_checkpoint(None, sport="padel")
    empty = BallTrack(np.arange(50), np.zeros(50), np.full((50, 2), np.nan))
    with pytest.warns(UserWarning, match="no visible ball"):
        r = det.predict(empty, 30.0, 1280, 720)
    assert len(r.events) == 0 and r.probs.shape == (50, 6) and np.all(r.probs[:, 0] == 1)
    with pytest.raises(ValueError, match="fps"):
        det.predict(empty, 0.0, 1280, 720)


def test_bad_model_files_are_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="train one"):
        EventDetector.from_checkpoint(tmp_path / "nope.pth.tar")
    bad = tmp_path / "bad.pth.tar"
    bad.write_bytes(b"not a model")
    with pytest.raises(ValueError, match="not a readable"):
        EventDetector.from_checkpoint(bad)
    with pytest.raises(KeyError, match="no shipped"):
        default_weights("squash")


def test_saved_model_round_trips(tmp_path):
    det = EventDetector("hitnet", ClassSet.load("tennis4"), FeatureConfig(), DecodeParams(thresholds=(0.5, 0.3, 0.4, 0.6)),
                        net=HitNet(5, 4, 16, 1, False))
    path = det.save(tmp_path / "m.pth.tar")
    back = EventDetector.from_checkpoint(path)
    assert back.decode_params == det.decode_params and back.class_set == det.class_set
    x = np.random.default_rng(0).random((3, 12, 5)).astype(np.float32)
    import torch

    assert torch.allclose(back.net.probs(torch.from_numpy(x)), det.net.probs(torch.from_numpy(x)))


def test_cli_writes_events_csv(clips, tmp_path):
    from inference.cli import main

    c = clips[0]
    clip = Clip.create(tmp_path / "clip", ClipInfo(sport="padel", fps=c.fps, width=c.width, height=c.height,
                                                   video="video.mp4", n_frames=c.n_frames))
    clip.write_ball(c.ball)
    clip.write_camera(c.camera)
    assert main(["events", str(clip.root)]) == 0
    events = read_events_csv(clip.events_path)
    assert len(events) > 0 and events.frame.max() < c.n_frames
    from inference.events.rally import read_rally_yaml

    start, end = read_rally_yaml(clip.root / "rally.yaml")  # the point, beside events.csv
    assert 0 <= start <= end < c.n_frames
    import yaml

    outside = yaml.safe_load((clip.root / "rally.yaml").read_text())["outside"]
    assert main(["events", str(clip.root), "--rally-only"]) == 0
    assert len(read_events_csv(clip.events_path)) == len(events) - len(outside)
