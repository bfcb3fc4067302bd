"""A player's court position: the foot point, lifted to ankle height and intersected through the camera.

The foot point in the image is the midpoint of the ankles (or the one visible ankle); without ankles it
is extrapolated from the hips and knees (the shank is about as long as the thigh). Its line of sight is
intersected with the horizontal plane ``z = λ`` (the ankle height, default 0.08 m) and the (x, y) of the
hit is the player's position on court.
"""
from __future__ import annotations

import numpy as np

from inference.camera import Camera
from inference.players.skeleton import JOINT

ANKLE_HEIGHT = 0.08  # m, λ: ankle joint above the floor
MIN_SCORE = 0.3      # keypoints below this confidence are ignored


def _mid(kp: np.ndarray, ok: np.ndarray, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) midpoint of joints a and b where both are confident, else the confident one; (N,) found."""
    pa, pb = kp[:, a], kp[:, b]
    oa, ob = ok[:, a], ok[:, b]
    out = np.where((oa & ob)[:, None], 0.5 * (pa + pb), np.where(oa[:, None], pa, pb))
    return out, oa | ob


def foot_points(keypoints: np.ndarray, scores: np.ndarray, min_score: float = MIN_SCORE) -> np.ndarray:
    """(N, 17, 2) keypoints px and (N, 17) scores → (N, 2) foot point px (NaN when it cannot be placed)."""
    kp = np.asarray(keypoints, dtype=float).reshape(-1, 17, 2)
    ok = (np.asarray(scores, dtype=float).reshape(-1, 17) >= min_score) & np.isfinite(kp).all(axis=2)
    ankle, has_ankle = _mid(kp, ok, JOINT["left_ankle"], JOINT["right_ankle"])
    hip, has_hip = _mid(kp, ok, JOINT["left_hip"], JOINT["right_hip"])
    knee, has_knee = _mid(kp, ok, JOINT["left_knee"], JOINT["right_knee"])
    from_legs = knee + (knee - hip)  # shank ≈ thigh
    out = np.where(has_ankle[:, None], ankle, np.where((has_hip & has_knee)[:, None], from_legs, np.nan))
    return out


def court_positions(keypoints: np.ndarray, scores: np.ndarray, camera: Camera,
                    ankle_height: float = ANKLE_HEIGHT, min_score: float = MIN_SCORE) -> np.ndarray:
    """(N, 17, 2) keypoints px and (N, 17) scores → (N, 2) court (x, y) in metres (NaN where unknown).

    Points whose line of sight does not descend to the ankle plane in front of the camera are NaN.
    """
    feet = foot_points(keypoints, scores, min_score)
    out = np.full((len(feet), 2), np.nan)
    ok = np.isfinite(feet).all(axis=1)
    if not ok.any():
        return out
    o, d = camera.rays(feet[ok])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ankle_height - o[:, 2]) / d[:, 2]
    good = np.isfinite(t) & (t > 0)
    pts = o + t[:, None] * d
    idx = np.flatnonzero(ok)
    out[idx[good]] = pts[good, :2]
    return out
