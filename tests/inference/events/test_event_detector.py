"""The runtime EventDetector: shipped defaults load offline and find events on held-out simulated clips,
grouped classes resolve to their surface with a camera, bad inputs give clear errors, and the CLI
writes events.csv."""
from __future__ import annotations

import numpy as np
import pytest

from inference.clipio import BallTrack, Clip, ClipInfo, HitEvents, read_events_csv
from inference.events import ClassSet, DecodeParams, EventCounts, EventDetector, FeatureConfig, HitNet, tolerance_frames
from inference.events.detector import ball_only_weights
from training.events.synthetic.simulate import simulate_clips


@pytest.fixture(scope="module")
def clips():
    return simulate_clips("padel", 6, seed=4242, progress=False)  # seeds no training set uses


def test_shipped_padel_default_finds_events_on_held_out_clips(clips):
    det = EventDetector.from_checkpoint(None, sport="padel")
    cs = det.class_set
    assert cs.name == "padel6" and det.kind == "tagger"  # the file `rally3d events` uses (choose_weights)
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


def test_far_hits_in_gaps_are_bridged_unless_asked_not_to(clips):
    """Racket hits hidden by the tracker: with ``bridge_gaps=False`` the model's own frame stands, with the
    spread of its probability as the timing uncertainty; by default the far player's hits are timed from the
    flights on both sides of the gap, with the flights' uncertainty instead, and the near player's keep the
    model's."""
    det = EventDetector.from_checkpoint(None, sport="padel")
    moved = 0
    for c in clips:
        vis = c.ball.visibility.copy()
        for f, e in zip(c.events.frame, c.events.event):
            if e.startswith("player"):
                vis[max(f - 3, 0):f + 4] = 0  # the body hides the ball around each hit
        track = BallTrack(c.ball.frame, vis, np.where(vis[:, None] > 0, c.ball.xy, np.nan))
        plain = det.predict(track, c.fps, c.width, c.height, camera=c.camera, n_frames=c.n_frames,
                            bridge_gaps=False)
        bridged = det.predict(track, c.fps, c.width, c.height, camera=c.camera, n_frames=c.n_frames)
        radius = det.decode_params.peak_radius * c.fps / det.ref_fps
        assert len(plain.uncertainty) == len(plain.confidence) == len(plain.events)
        assert np.all((plain.uncertainty >= 0) & (plain.uncertainty <= radius))
        assert np.all((plain.confidence > 0) & (plain.confidence <= 1))
        assert np.array_equal(plain.probs, bridged.probs)
        if len(bridged.events) == len(plain.events):
            changed = ~np.isclose(bridged.uncertainty, plain.uncertainty)
            near = np.array([e == "player_near" for e in bridged.events.event])
            assert not (changed & near).any()  # the near player's hits keep the model's timing
            moved += int(changed.sum())
        else:
            moved += 1
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
        ball_only_weights("squash")
    with pytest.raises(KeyError, match="no shipped"):
        EventDetector.from_checkpoint(None, sport="squash")


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


def test_event_spread_is_small_for_a_sharp_peak_and_large_for_a_flat_one():
    from inference.events.decode import event_spread

    p = np.zeros((30, 3))
    p[:, 0] = 1.0
    p[10, :] = [0.05, 0.95, 0.0]  # sharp
    p[19:24, :] = [[0.6, 0.0, 0.4]] * 5  # flat over 5 frames
    sigma, peak = event_spread(p, np.array([10, 21, 40]), np.array([1, 2, 1]), radius=3)
    assert sigma[0] == 0.0 and peak[0] == 0.95
    assert np.isclose(sigma[1], np.sqrt(2.0)) and peak[1] == 0.4  # uniform over 21 ± 2
    assert np.isnan(sigma[2]) and np.isnan(peak[2])  # outside the clip


def test_events_csv_carries_confidence_and_timing_and_reads_back(clips, tmp_path):
    from inference.clipio import read_events_csv, write_events_csv

    det = EventDetector.from_checkpoint(None, sport="padel")
    c = clips[0]
    r = det.predict(c.ball, c.fps, c.width, c.height, camera=c.camera, n_frames=c.n_frames)
    path = write_events_csv(tmp_path / "events.csv", r.events_with_timing())
    header = path.read_text().splitlines()[0].split(",")
    assert header == ["frame", "event", "confidence", "sigma_frames"]
    back = read_events_csv(path)
    assert np.array_equal(back.frame, r.events.frame) and np.array_equal(back.event, r.events.event)
    assert np.allclose(back.extra["confidence"].astype(float), r.confidence, atol=0.006)
    assert np.allclose(back.extra["sigma_frames"].astype(float), r.uncertainty, atol=0.006)


def test_a_long_stretch_without_events_is_reported_to_check():
    """Two consecutive events 4 s apart with the ball seen between them (the model missed a hit or a bounce)
    are named among the things to check; a gap in which the ball is mostly unseen, or a short one, is not."""
    from inference.events.detector import QUIET_S, EventResult, quiet_stretches

    fps = 25.0
    seen = np.ones(400, bool)
    seen[250:330] = False  # the ball out of the picture for 3.2 s
    frames = np.array([10, 40, 140, 190, 335])
    assert quiet_stretches(frames, seen, fps) == ((40, 140),)
    assert (140 - 40) / fps > QUIET_S > (190 - 140) / fps
    r = EventResult(HitEvents(frames, ["player_near", "ground", "player_far", "ground", "player_near"]),
                    np.zeros((400, 4)), ("none", "ground", "player_near", "player_far"),
                    confidence=np.array([0.9, 0.9, 0.3, 0.9, 0.9]), quiet=quiet_stretches(frames, seen, fps))
    text = r.unsure_all(fps)
    assert "player_far 140 (0.30)" in text and "no event for 4.0 s between frames 40 and 140" in text
