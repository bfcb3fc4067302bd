"""Which frames the pose model looks at: every N-th frame.

Posing is the players stage's cost (MoveNet at 960 px: ~0.1 CPU-s a 1080p frame). Players move slowly, so a
pose every N-th frame (:func:`sampled_frames`) with the tracker filling the frames between keeps their court
positions, identities and the event model's F1 (docs/players.md, "Posing every N-th frame").
"""
from __future__ import annotations

import numpy as np


def sampled_frames(n: int, stride: int = 1) -> np.ndarray:
    """(n,) bool: the frames of a run of ``n`` that a pose model looks at when it runs on every ``stride``-th
    frame — ``0, stride, 2·stride, …`` and the last (so the frames between two looks can be filled up to the
    run's end). ``stride`` 1: every frame."""
    if stride < 1:
        raise ValueError(f"pose stride must be ≥ 1, got {stride}")
    mask = np.zeros(n, bool)
    mask[::stride] = True
    if n:
        mask[n - 1] = True
    return mask
