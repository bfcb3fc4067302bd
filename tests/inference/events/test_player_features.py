"""The player-aware HitNet's input (``features.poses``): shapes and masks with and without players or
poses, the side's player nearest the ball, the racket hand, and model files: the shipped ball-only weights
still load, a player-aware file records its features and is fed players by ``predict``."""
from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
import pytest
import torch

from inference.clipio import BallTrack, PlayerTracks
from inference.court import load_court
from inference.events import ClassSet, DecodeParams, EventDetector, FeatureConfig, HitNet
from inference.events.features import PLAYER_COLUMNS, clip_features, player_features, racket_hand
from inference.events.metrics import EventCounts
from training.events.synthetic.simulate import simulate_clip, simulate_clips

COL = {n: i for i, n in enumerate(PLAYER_COLUMNS)}
P = len(PLAYER_COLUMNS)


@pytest.fixture(scope="module")
def tennis():
    return simulate_clip("tennis", 5151, players=True)


def test_block_shapes_and_masks_with_players(tennis):
    c, court = tennis, load_court("tennis")
    fc = FeatureConfig(poses=True)
    assert fc.n_features == 5 + 2 * P == 29 and fc.player_offset == 5
    feats = clip_features(c.ball, c.n_frames, c.fps, fc, camera=c.camera, court=court, players=c.players)
    n_ref = int(round(c.n_frames * 50 / c.fps))
    assert feats.shape == (n_ref, 29) and np.isfinite(feats).all()
    ball_only = clip_features(c.ball, c.n_frames, c.fps, FeatureConfig(), camera=c.camera, court=court)
    assert np.array_equal(feats[:, :5], ball_only)  # the ball part is unchanged
    near, far = feats[:, 5:5 + P], feats[:, 5 + P:]
    assert near[:, COL["present"]].mean() > 0.95 and far[:, COL["present"]].mean() > 0.95
    assert (near[:, COL["court_y"]] < 0).mean() > 0.95 and (far[:, COL["court_y"]] > 0).mean() > 0.95
    assert near[:, COL["pose"]].mean() > 0.9
    # ball-relative columns are zero exactly where the ball is not seen; body-relative wrists stay
    seen = feats[:, 4] > 0
    for side in (near, far):
        assert np.all(side[~seen][:, [COL["body_dx"], COL["body_dy"], COL["wrist_dx"], COL["wrist_dy"]]] == 0)
    # at a near player's hit the racket wrist is close to the ball (in image fractions × rel_scale 10)
    hits = [int(round(f * 50 / c.fps)) for f, e in zip(c.events.frame, c.events.event) if e == "player_near"]
    d = [np.hypot(*near[h, [COL["wrist_dx"], COL["wrist_dy"]]]) for h in hits if seen[h]]
    assert d and np.median(d) < 1.0, d  # under 10 % of the image from the ball


def test_no_players_or_no_poses_degrade_to_zeros_and_masks(tennis):
    c, court = tennis, load_court("tennis")
    fc = FeatureConfig(poses=True)
    none = clip_features(c.ball, c.n_frames, c.fps, fc, camera=c.camera, court=court, players=None)
    assert none.shape[1] == 29 and np.all(none[:, 5:] == 0)
    empty = clip_features(c.ball, c.n_frames, c.fps, fc, court=court, players=PlayerTracks.empty())
    assert np.array_equal(empty, none)
    pl = c.players
    no_kp = PlayerTracks(pl.frame, pl.player_id, pl.team, pl.score, pl.bbox, np.full_like(pl.keypoints, np.nan),
                         pl.court_xy)
    f = clip_features(c.ball, c.n_frames, c.fps, fc, court=court, players=no_kp)
    for s in (0, 1):
        side = f[:, 5 + s * P:5 + (s + 1) * P]
        assert side[:, COL["present"]].mean() > 0.95 and np.any(side[:, COL["court_x"]] != 0)
        assert np.all(side[:, COL["pose"]] == 0)
        assert np.all(side[:, COL["wrist_dx"]:] == 0)        # no wrists without keypoints
        assert np.any(side[:, COL["body_dx"]] != 0)          # the box centre still places the player
    # a missing far player: its slot is all zeros, the near one unchanged
    near_only = PlayerTracks(*(getattr(pl, k)[pl.team == "near"] for k in ("frame", "player_id", "team", "score",
                                                                          "bbox", "keypoints", "court_xy")))
    g = clip_features(c.ball, c.n_frames, c.fps, fc, court=court, players=near_only)
    full = clip_features(c.ball, c.n_frames, c.fps, fc, court=court, players=pl)
    assert np.all(g[:, 5 + P:] == 0) and np.array_equal(g[:, :5 + P], full[:, :5 + P])


def _player(pid, team, frames, centre, wrist_offsets, court_xy):
    n = len(frames)
    kp = np.full((n, 17, 3), np.nan)
    for j in (5, 6, 11, 12):  # torso around the centre: shoulders 0.05 above, hips 0.05 below
        kp[:, j, :2] = np.asarray(centre) + [0.0, -0.05 if j < 11 else 0.05]
        kp[:, j, 2] = 0.9
    kp[:, 9, :2], kp[:, 10, :2] = np.asarray(centre) + wrist_offsets[0], np.asarray(centre) + wrist_offsets[1]
    kp[:, 9:11, 2] = 0.9
    c = np.asarray(centre)
    return dict(frame=frames, player_id=np.full(n, pid), team=[team] * n, score=np.ones(n),
                bbox=np.tile(np.r_[c - 0.05, c + 0.1], (n, 1)), keypoints=kp, court_xy=np.tile(court_xy, (n, 1)))


def _tracks(*players):
    cat = {k: np.concatenate([np.asarray(p[k], dtype=object if k == "team" else None) for p in players])
           for k in players[0]}
    order = np.lexsort((cat["player_id"], cat["frame"]))
    return PlayerTracks(cat["frame"][order].astype(np.int64), cat["player_id"][order].astype(np.int64),
                        list(cat["team"][order]), cat["score"][order].astype(float), cat["bbox"][order].astype(float),
                        cat["keypoints"][order].astype(float), cat["court_xy"][order].astype(float))


def test_the_sides_player_nearest_the_ball_and_teams_from_court_positions():
    court = load_court("padel")
    n = 10
    f = np.arange(n)
    swing = np.zeros((n, 2))
    swing[:, 0] = np.linspace(-0.04, 0.04, n)  # this player's right wrist swings; the left one stays
    a = _player(0, "near", f, (0.3, 0.8), (np.zeros((n, 2)) + [-0.02, 0.0], swing + [0.02, 0.0]), (3.0, 4.0))
    b = _player(1, "near", f, (0.7, 0.8), (np.zeros((n, 2)), np.zeros((n, 2))), (7.0, 4.0))
    far = _player(2, "", f, (0.5, 0.3), (np.zeros((n, 2)), np.zeros((n, 2))), (5.0, 16.0))  # no team: court y
    ball = np.tile([0.68, 0.7], (n, 1))
    ball[4:6] = np.nan                                     # a gap: the nearest player is still found
    out = player_features(_tracks(a, b, far), ball, court)
    near_cols, far_cols = out[:, :P], out[:, P:]
    assert np.allclose(near_cols[:, COL["court_x"]], (7.0 - 5.0) / 5.0)  # player 1, beside the ball
    assert np.all(near_cols[:, COL["present"]] == 1) and np.all(far_cols[:, COL["present"]] == 1)
    assert np.allclose(far_cols[:, COL["court_y"]], (16.0 - 10.0) / 10.0)
    assert np.all(near_cols[4:6, COL["body_dx"]:COL["body_dy"] + 1] == 0)  # no ball: no ball-relative values
    assert np.all(near_cols[[0, 9], COL["body_dx"]] != 0)
    # the racket hand is the wrist that moves
    pa = _tracks(a)
    centre = np.tile([0.3, 0.8], (n, 1))
    assert racket_hand(pa.keypoints[:, [9, 10], :2], centre) == 1
    flipped = pa.keypoints[:, [10, 9], :2]
    assert racket_hand(flipped, centre) == 0
    # the racket wrist relative to the body, in torso lengths (0.1): player 0's right wrist, 0.2 → 0.6
    only_a = player_features(pa, np.tile([0.3, 0.7], (n, 1)), court)
    assert np.allclose(only_a[[0, -1], COL["racket_wrist_x"]], [(0.02 - 0.04) / 0.1, (0.02 + 0.04) / 0.1])


def test_shipped_ball_only_weights_still_load_and_run(tennis):
    from inference.events import detector as mod

    for sport in ("padel", "tennis"):
        det = EventDetector.from_checkpoint(mod.ball_only_weights(sport))
        assert not det.wants_players and det.features.n_features == 5 and det.net.hparams["n_features"] == 5
    det = EventDetector.from_checkpoint(mod.ball_only_weights("tennis"))
    c = tennis
    r1 = det.predict(c.ball, c.fps, c.width, c.height, n_frames=c.n_frames)
    r2 = det.predict(c.ball, c.fps, c.width, c.height, n_frames=c.n_frames, players=c.players)  # ignored
    assert np.array_equal(r1.probs, r2.probs) and len(r1.events) > 5


def test_player_aware_model_file_records_its_features_and_reads_players(tennis, tmp_path, caplog, monkeypatch):
    torch.manual_seed(0)
    fc = FeatureConfig(poses=True)
    det = EventDetector("hitnet", ClassSet.load("tennis4"), fc, DecodeParams(), net=HitNet(fc.n_features, 4, 8, 1),
                        window=12)
    path = det.save(tmp_path / "players.pth.tar")
    blob = torch.load(path, weights_only=True)
    assert blob["features"]["poses"] is True and blob["features"]["pose_layout"] == 2
    loaded = EventDetector.from_checkpoint(path)
    assert loaded.wants_players and loaded.features == fc
    c = tennis
    with_p = loaded.predict(c.ball, c.fps, c.width, c.height, n_frames=c.n_frames, players=c.players)
    with caplog.at_level(logging.INFO, logger="inference.events.detector"):
        without = loaded.predict(c.ball, c.fps, c.width, c.height, n_frames=c.n_frames)
    # a sport in PLAYERS_OPTIONAL: said, not warned (its player-aware model is the default without players too);
    # other sports: warned
    assert "no players given" in caplog.text and not [r for r in caplog.records if r.levelno >= logging.WARNING]
    caplog.clear()
    from inference.events import detector as mod

    monkeypatch.setattr(mod, "PLAYERS_OPTIONAL", frozenset({"tennis"}))
    pd = EventDetector("hitnet", ClassSet.load("padel6"), fc, DecodeParams(), net=HitNet(fc.n_features, 6, 8, 1),
                       window=12)
    with caplog.at_level(logging.WARNING, logger="inference.events.detector"):
        pd.predict(c.ball, c.fps, c.width, c.height, n_frames=c.n_frames)
    assert "reads the players but none were given" in caplog.text
    assert with_p.probs.shape == without.probs.shape and not np.allclose(with_p.probs, without.probs)
    # a file of the first poses layout (raw keypoints) is refused with the fix
    blob["features"] = {**blob["features"], "pose_layout": 1}
    torch.save(blob, tmp_path / "old.pth.tar")
    with pytest.raises(ValueError, match="retrain"):
        EventDetector.from_checkpoint(tmp_path / "old.pth.tar")


def test_choose_weights_prefers_a_shipped_player_model_only_with_players(tennis, tmp_path, monkeypatch):
    from inference.events import detector as mod

    monkeypatch.setattr(mod, "WEIGHTS_DIR", tmp_path)
    (tmp_path / mod.DEFAULT_WEIGHTS["tennis"]).write_bytes(b"x")
    assert mod.choose_weights(None, "tennis", tennis.players).name == mod.DEFAULT_WEIGHTS["tennis"]  # none shipped
    (tmp_path / mod.PLAYER_WEIGHTS["tennis"]).write_bytes(b"x")
    assert mod.choose_weights(None, "tennis", tennis.players).name == mod.PLAYER_WEIGHTS["tennis"]
    assert mod.choose_weights(tmp_path / "mine.pth.tar", "tennis", tennis.players).name == "mine.pth.tar"
    # without players: a sport in PLAYERS_OPTIONAL keeps its player-aware model (it wins there too), others fall back
    (tmp_path / mod.DEFAULT_WEIGHTS["padel"]).write_bytes(b"x")
    (tmp_path / mod.PLAYER_WEIGHTS["padel"]).write_bytes(b"x")
    assert mod.choose_weights(None, "padel", tennis.players).name == mod.PLAYER_WEIGHTS["padel"]
    for sport in ("padel", "tennis"):
        assert mod.choose_weights(None, sport, PlayerTracks.empty()).name == mod.PLAYER_WEIGHTS[sport]
        assert mod.choose_weights(None, sport, None).name == mod.PLAYER_WEIGHTS[sport]
    monkeypatch.setattr(mod, "PLAYERS_OPTIONAL", frozenset({"tennis"}))
    assert mod.choose_weights(None, "padel", None).name == mod.DEFAULT_WEIGHTS["padel"]
    assert mod.choose_weights(None, "padel", tennis.players).name == mod.PLAYER_WEIGHTS["padel"]
    monkeypatch.setattr(mod, "PLAYERS_OPTIONAL", frozenset())
    assert mod.choose_weights(None, "tennis", None).name == mod.DEFAULT_WEIGHTS["tennis"]


@pytest.mark.parametrize("sport", ["tennis", "padel"])
def test_the_shipped_player_model_beats_the_ball_only_one_without_players(sport):
    """Why a sport keeps its player-aware model without players: on held-out rallies with a degraded track and no
    players.csv it finds more of the events than the ball-only model."""
    from inference.events import detector as mod
    from inference.events.metrics import EventCounts, tolerance_frames
    from training.events.synthetic.degrade import DegradeConfig, degrade_all

    clips = simulate_clips(sport, 6, seed=6262, progress=False, fps=50.0)
    tracks = degrade_all(clips, 3, DegradeConfig(p_clean=0.0, integer_px=True, far_miss=0.3))
    f1 = {}
    for name, path in (("players", mod.WEIGHTS_DIR / mod.PLAYER_WEIGHTS[sport]), ("ball", mod.ball_only_weights(sport))):
        det = EventDetector.from_checkpoint(path)
        counts = EventCounts(det.class_set.classes)
        for c, tr in zip(clips, tracks):
            r = det.predict(tr, c.fps, c.width, c.height, n_frames=c.n_frames, players=None)
            counts.add(c.events.frame, [det.class_set.encode_label(str(e)) or 0 for e in c.events.event],
                       r.events.frame, [det.class_set.index(x) for x in r.coarse], tolerance_frames(c.fps))
        f1[name] = counts.scores()["f1"]
    assert f1["players"] > f1["ball"] + 0.05, f1


def test_the_shipped_player_aware_tennis_model_reads_players(tennis):
    from inference.events.detector import choose_weights

    det = EventDetector.from_checkpoint(choose_weights(None, "tennis", tennis.players), sport="tennis")
    assert det.wants_players and det.features.n_features == 29 and det.class_set.name == "tennis4"
    c = tennis
    r = det.predict(c.ball, c.fps, c.width, c.height, n_frames=c.n_frames, players=c.players)
    assert len(r.events) > 5 and np.allclose(r.probs.sum(axis=1), 1.0, atol=1e-4)


def test_the_shipped_player_aware_padel_model_reads_players_and_runs_without():
    from inference.events.detector import choose_weights

    c = simulate_clip("padel", 515, players=True)
    path = choose_weights(None, "padel", c.players)
    assert path.name == "tagger_padel_players.pth.tar"
    det = EventDetector.from_checkpoint(path, sport="padel")
    assert det.wants_players and det.class_set.name == "padel6"
    r = det.predict(c.ball, c.fps, c.width, c.height, n_frames=c.n_frames, players=c.players)
    scored = EventCounts(det.class_set.classes)
    cs = det.class_set
    scored.add(c.events.frame, [cs.encode_label(str(e)) or 0 for e in c.events.event], r.events.frame,
               [cs.index(x) for x in r.coarse], 2)
    assert scored.scores()["f1"] > 0.6, scored.scores()          # an exact rally: most events found
    alone = det.predict(c.ball, c.fps, c.width, c.height, n_frames=c.n_frames)   # no players: still runs
    assert len(alone.events) > 0 and choose_weights(None, "padel", None).name == "tagger_padel_players.pth.tar"
