"""Helpers shared by the labeler tests: a writable copy of the embedded padel sample clip."""
from __future__ import annotations

import shutil
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "datasets" / "sample" / "padel_sample"


def copy_sample(dst: Path, *, keep_labels: bool = True) -> Path:
    """Copy ``datasets/sample/padel_sample`` (240 frames, 1280×720) to ``dst``; optionally without its labels."""
    shutil.copytree(SAMPLE, dst)
    if not keep_labels:
        for name in ("ball.csv", "inactive_balls.csv", "events.csv", "court_points.csv", "camera.yaml"):
            (dst / name).unlink(missing_ok=True)
    return dst
