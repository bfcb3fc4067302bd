"""Which frames the pose model looks at: every N-th frame.

Posing is the players stage's cost (MoveNet at 960 px: ~0.3 CPU-s a 1080p frame). Players move slowly, so a
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


#: How often the pose model looks at the players by default (Hz). On held-out rendered rallies posing every
#: 2nd frame at 25 fps (12.5 Hz) or every 3rd at 50 fps kept the court error, identities and event F1 of posing
#: every frame for half or a third of the pose CPU; at 6–12 Hz the players' coverage starts to fall
#: (docs/players.md, ``bench/bench_pose_stride.py``).
POSE_RATE_HZ = 15.0


def pose_stride(fps: float, every: int = 0) -> int:
    """The pose stride: ``every`` when given (≥ 1), else the one that looks about :data:`POSE_RATE_HZ` times a
    second (25 and 30 fps → 2, 50 fps → 3, 60 fps → 4, 12 fps → 1)."""
    if every > 0:
        return int(every)
    return max(1, int(round(fps / POSE_RATE_HZ)))


def parse_pose_every(text: str) -> int:
    """``--pose-every`` of ``rally3d infer`` and ``rally3d players``: ``auto`` (0) or a whole number ≥ 1."""
    import argparse

    if text == "auto":
        return 0
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected auto or a whole number ≥ 1, got {text!r}")
    return value
