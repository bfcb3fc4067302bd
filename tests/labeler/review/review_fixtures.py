"""Fixtures of the review tests: the embedded padel sample, calibrated and reconstructed in a tmp folder.

Imported by the test modules (``from review_fixtures import reconstructed_clip``); a second conftest.py
would clash with tests/conftest.py (no packages under tests/).
"""
from __future__ import annotations

import csv
import shutil
from pathlib import Path

import pytest

SAMPLE = Path(__file__).resolve().parents[3] / "datasets" / "sample" / "padel_sample"


def sample_events() -> list[tuple[int, str]]:
    """The sample's events.csv as (frame, event) rows, in frame order: the tests derive the expected shots
    from them (one shot per racket hit) rather than hard-coding the figures of one regeneration."""
    with (SAMPLE / "events.csv").open() as f:
        return sorted((int(r["frame"]), r["event"]) for r in csv.DictReader(f))


def sample_shots() -> list[tuple[int, str, bool]]:
    """One (hit frame, team, bounces before the next hit) per racket hit of the sample: the shots the review
    must show, and whether each has a floor bounce to call (the last one, cut by the clip's end, has none)."""
    ev = sample_events()
    hits = [k for k, (_, e) in enumerate(ev) if e.startswith("player_")]
    out = []
    for n, k in enumerate(hits):
        nxt = hits[n + 1] if n + 1 < len(hits) else len(ev)
        bounced = any(e == "ground" for _, e in ev[k + 1: nxt])
        out.append((ev[k][0], ev[k][1].removeprefix("player_"), bounced))
    return out


def make_reconstructed_clip(dest: Path, players_from_gt: bool = True) -> Path:
    """Copy the sample to ``dest``, run ``rally3d calibrate`` and ``rally3d reconstruct`` on it; with
    ``players_from_gt`` the ground-truth players.csv stands in for the pose backend's (it is slow)."""
    from inference.cli import main

    clip = dest / "padel_sample"
    shutil.copytree(SAMPLE, clip)
    if players_from_gt:
        shutil.copy(clip / "gt" / "players.csv", clip / "players.csv")
    assert main(["calibrate", str(clip)]) == 0
    assert main(["reconstruct", str(clip)]) == 0
    return clip


@pytest.fixture(scope="session")
def reconstructed_clip(tmp_path_factory) -> Path:
    return make_reconstructed_clip(tmp_path_factory.mktemp("review"))
