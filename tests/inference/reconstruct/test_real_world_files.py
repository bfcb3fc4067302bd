"""`rally3d reconstruct` on clip folders assembled from other tools' files: a CSV-only clip (no video, no
n_frames), another tracker's players.csv, a mapping `source`, two events on one frame, a single event."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from inference.cli import main
from inference.clipio import Clip

SAMPLE = Path(__file__).resolve().parents[3] / "datasets" / "sample" / "padel_sample"


def csv_only_clip(root: Path) -> Path:
    """The sample as another tool would hand it over: tables and a camera, no video, provenance as a mapping."""
    root.mkdir()
    for name in ("ball.csv", "events.csv"):
        shutil.copy(SAMPLE / name, root / name)
    gt = yaml.safe_load((SAMPLE / "gt" / "camera.yaml").read_text())
    (root / "camera.yaml").write_text(yaml.safe_dump({"image_size": gt["image_size"], "P": gt["P"]}))
    (root / "clip.yaml").write_text("sport: padel\nfps: 30\nwidth: 1280\nheight: 720\nvideo: gone.mp4\n"
                                    "source:\n  tool: other-tracker 2.1\n  match: {id: 812, set: 2}\n")
    return root


def foreign_players(root: Path) -> None:
    """gt/players.csv's court positions written as another tracker's ``frame,track_id,team,x_m,y_m``."""
    rows = [ln.split(",") for ln in (SAMPLE / "gt" / "players.csv").read_text().splitlines()[1:]]
    out = ["frame,track_id,team,x_m,y_m"]
    out += [f"{r[0]},{int(r[1]) + 10},{'A' if r[2] == 'near' else 'B'},{r[8]},{r[9]}" for r in rows]
    (root / "players.csv").write_text("\n".join(out) + "\n")


def test_csv_only_clip_with_a_foreign_players_csv_is_reconstructed(tmp_path, capsys):
    root = csv_only_clip(tmp_path / "clip")
    foreign_players(root)
    with pytest.warns(UserWarning) as rec:
        assert main(["reconstruct", str(root)]) == 0
    messages = " ".join(str(w.message) for w in rec)
    assert "frames taken from the clip's tables" in messages and "another layout" in messages
    ball = Clip(root).read_ball_3d()
    events = Clip(root).read_events()
    assert ball.frame[0] <= events.frame[0] and ball.frame[-1] >= events.frame[-1]
    seg = json.loads((root / "segments.json").read_text())
    assert seg["plausibility"]["plausible"] and seg["plausibility"]["failed"] == 0
    assert "plausibility: plausible" in capsys.readouterr().out
    assert yaml.safe_load((root / "clip.yaml").read_text())["source"]["match"] == {"id": 812, "set": 2}


def test_two_events_on_one_frame(tmp_path):
    """A bounce and a hit written on the same frame (an annotator's habit): both kept, the clip reconstructs."""
    root = csv_only_clip(tmp_path / "clip")
    lines = (root / "events.csv").read_text().splitlines()
    frame, label = lines[3].split(",")                 # the first mid-rally bounce
    lines.insert(4, f"{frame},player_far")             # a second event on that frame
    (root / "events.csv").write_text("\n".join(lines) + "\n")
    with pytest.warns(UserWarning, match="one frame"):
        assert main(["reconstruct", str(root)]) == 0
    seg = json.loads((root / "segments.json").read_text())
    assert len(seg["segments"]) >= 12
    assert any(s["start_frame"] == int(frame) + 1 and s["start_event"] == "player_far" for s in seg["segments"])


def test_a_clip_with_one_event_is_reconstructed(tmp_path):
    """One event (a single bounce): the flights on both sides of it are fitted as free ends."""
    root = csv_only_clip(tmp_path / "clip")
    ev = Clip(root).read_events()
    k = int(np.flatnonzero(ev.event == "ground")[1])
    f = int(ev.frame[k])
    (root / "events.csv").write_text(f"frame,event\n{f},ground\n")
    ball = (root / "ball.csv").read_text().splitlines()
    keep = [ln for ln in ball[1:] if abs(int(ln.split(",")[0]) - f) <= 12]
    (root / "ball.csv").write_text("\n".join([ball[0], *keep]) + "\n")
    with pytest.warns(UserWarning):
        assert main(["reconstruct", str(root)]) == 0
    out = Clip(root).read_ball_3d()
    assert out.frame[0] < f < out.frame[-1]
    gt = Clip(SAMPLE).read_ball_3d(gt=True)
    err = np.linalg.norm(out.xyz - gt.xyz[np.searchsorted(gt.frame, out.frame)], axis=1)
    assert np.median(err) < 0.25
