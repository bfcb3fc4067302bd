"""Fixtures of the review tests: the embedded padel sample, calibrated and reconstructed in a tmp folder.

Imported by the test modules (``from review_fixtures import reconstructed_clip``); a second conftest.py
would clash with tests/conftest.py (no packages under tests/).
"""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

SAMPLE = Path(__file__).resolve().parents[3] / "datasets" / "sample" / "padel_sample"


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
