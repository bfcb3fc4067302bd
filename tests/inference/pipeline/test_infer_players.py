"""``rally3d infer`` runs the players before the events and feeds them to a player-aware event model (ball
only without players); ``rally3d events`` reads players.csv or ``--players FILE``."""
from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
import torch

from inference.cli import main
from inference.clipio import Clip
from inference.events import ClassSet, DecodeParams, EventDetector, FeatureConfig, HitNet, ball_only_weights
from inference.pipeline.stages import build_stages


@pytest.fixture(scope="module")
def tennis_clip(tmp_path_factory) -> Path:
    from synth.generate import SynthConfig, generate_clip

    root = tmp_path_factory.mktemp("players") / "rally"
    cfg = SynthConfig(sport="tennis", randomise_camera=False, fps=30.0, width=640, height=360, codec="mp4v",
                      max_frames=90)
    generate_clip(root, seed=33, config=cfg)
    return root


@pytest.fixture(scope="module")
def player_model(tmp_path_factory) -> Path:
    torch.manual_seed(1)
    fc = FeatureConfig(poses=True)
    det = EventDetector("hitnet", ClassSet.load("tennis4"), fc, DecodeParams(thresholds=(0.5, 0.3, 0.3, 0.3)),
                        net=HitNet(fc.n_features, 4, 8, 1), window=12)
    return det.save(tmp_path_factory.mktemp("model") / "players.pth.tar")


def test_players_stage_runs_before_events():
    names = [s.name for s in build_stages()]
    assert names.index("players") < names.index("events") < names.index("reconstruct")


def _fresh(src: Path, dest: Path, players: bool) -> Path:
    shutil.copytree(src, dest)
    (dest / "events.csv").unlink()  # the generator's copy; gt/events.csv stays the reference
    if players:
        shutil.copy(dest / "gt" / "players.csv", dest / "players.csv")  # players found earlier / by another tool
    return dest


def test_infer_feeds_players_to_a_player_aware_model(tennis_clip, player_model, tmp_path, capsys):
    clip = _fresh(tennis_clip, tmp_path / "with", players=True)
    args = ["infer", str(clip), "--only", "players,events", "--pose", "none", "--no-progress"]
    assert main([*args, "--events", str(player_model)]) == 0
    text = capsys.readouterr().out
    assert re.search(r"^events\s+done.*; player-aware\)", text, re.M), text
    assert text.index("\nplayers ") < text.index("\nevents ")  # the summary lists players first
    with_players = Clip(clip).read_events()
    # the players are an input of the events stage: changing them re-runs it
    assert main([*args, "--events", str(player_model)]) == 0
    assert re.search(r"^events\s+cached", capsys.readouterr().out, re.M)
    pl = (clip / "players.csv").read_text().splitlines()
    (clip / "players.csv").write_text("\n".join(pl[:1] + pl[1::2]) + "\n")  # every other row gone
    assert main([*args, "--events", str(player_model)]) == 0
    assert re.search(r"^events\s+done", capsys.readouterr().out, re.M)
    # without players.csv the same model runs on the ball alone; tennis's default is its shipped player-aware
    # model then too (it beats the ball-only one without players; padel falls back: test_player_features.py)
    bare = _fresh(tennis_clip, tmp_path / "without", players=False)
    args = ["infer", str(bare), "--only", "players,events", "--pose", "none", "--no-progress"]
    assert main([*args, "--events", str(player_model)]) == 0
    assert re.search(r"^events\s+done.*; player-aware, no players\)", capsys.readouterr().out, re.M)
    without = Clip(bare).read_events()
    assert len(with_players) and len(without)
    assert main([*args, "--overwrite"]) == 0
    assert re.search(r"^events\s+done.*; player-aware, no players\)", capsys.readouterr().out, re.M)
    assert main([*args, "--overwrite", "--events", str(ball_only_weights("tennis"))]) == 0
    assert re.search(r"^events\s+done.*; ball only\)", capsys.readouterr().out, re.M)
    # with players and no --events, tennis uses the shipped player-aware model
    shutil.copy(bare / "gt" / "players.csv", bare / "players.csv")
    assert main([*args, "--overwrite"]) == 0
    assert re.search(r"^events\s+done.*; player-aware\)", capsys.readouterr().out, re.M)


def test_events_command_reads_players(tennis_clip, player_model, tmp_path, capsys):
    clip = _fresh(tennis_clip, tmp_path / "c", players=False)
    out = tmp_path / "events.csv"
    assert main(["events", str(clip), "--weights", str(player_model), "--out", str(out),
                 "--players", str(clip / "gt" / "players.csv")]) == 0
    assert "player-aware model, players of 2 tracks" in capsys.readouterr().out
    a = out.read_text()
    assert main(["events", str(clip), "--weights", str(player_model), "--out", str(out), "--no-players"]) == 0
    assert "player-aware model WITHOUT players" in capsys.readouterr().out
    assert main(["events", str(clip), "--out", str(out)]) == 0  # no players.csv: tennis keeps its player-aware model
    assert "player-aware model without players (tennis's default either way)" in capsys.readouterr().out
    assert a.startswith("frame")
    assert main(["events", str(clip), "--players", str(tmp_path / "nothing.csv"), "--out", str(out)]) != 0
    err = capsys.readouterr().err
    assert "--players" in err and "nothing.csv: file not found" in err
