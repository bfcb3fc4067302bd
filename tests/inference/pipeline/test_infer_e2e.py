"""End to end: ``rally3d infer`` on a generated padel clip writes every file and reports the 3D error."""
from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from inference.cli import main
from inference.clipio import Clip


@pytest.fixture(scope="module")
def generated_clip(tmp_path_factory) -> Path:
    from synth.generate import SynthConfig, generate_clip

    root = tmp_path_factory.mktemp("e2e") / "rally"
    cfg = SynthConfig(sport="padel", camera="padel_installed", randomise_camera=False, fps=30.0, width=1280,
                      height=720, codec="mp4v", max_frames=150)
    generate_clip(root, seed=21, config=cfg)
    return root


def test_infer_writes_every_file_and_scores_3d(generated_clip, tmp_path, capsys):
    out = tmp_path / "result"
    code = main(["infer", str(generated_clip), "--out", str(out), "--no-progress", "--pose", "none"])
    text = capsys.readouterr().out
    assert code == 0, text
    clip = Clip(out)
    for name in ("clip.yaml", "camera.yaml", "ball.csv", "events.csv", "ball_3d.csv", "segments.json"):
        assert (out / name).is_file(), name
    # the results are well-formed and cover the clip
    ball = clip.read_ball()
    assert (ball.visibility > 0).sum() > 0.4 * clip.n_frames
    events = clip.read_events()
    assert len(events) >= 2
    from inference.events.rally import read_rally_yaml

    start, end = read_rally_yaml(out / "rally.yaml")  # the point's start and end beside events.csv
    assert 0 <= start <= end < clip.n_frames
    # and reports them apart in the terminal: the point's frames and the events judged outside it
    assert f"rally frames {start}–{end}" in text and " outside the point" in text, text
    b3 = clip.read_ball_3d()
    assert len(b3) > 0 and np.isfinite(b3.xyz).all()  # at least one flight fitted from detected inputs
    # per-stage timing table and scores against the generated ground truth
    for stage in ("camera", "detect", "smooth", "events", "reconstruct"):
        assert re.search(rf"^{stage}\s+done\s+\d+\.\d\d", text, re.M), stage
    m = re.search(r"3D ball\s+MAE ([\d.]+) m\s+MedAE ([\d.]+) m", text)
    assert m, text
    # a plumbing check, not the quality figure (bench/bench_pipeline.py measures that): a wrong frame, unit or
    # camera convention anywhere between the stages puts the ball tens of metres off the court
    assert 0.0 < float(m.group(2)) < 5.0
    assert re.search(r"2D ball\s+F1 0\.\d+", text) and re.search(r"events\s+F1 [01]\.\d+", text)

    # a second run reuses everything
    code = main(["infer", str(generated_clip), "--out", str(out), "--no-progress", "--pose", "none"])
    text = capsys.readouterr().out
    assert code == 0
    assert all(re.search(rf"^{s}\s+cached", text, re.M) for s in ("detect", "smooth", "events", "reconstruct"))
