"""Ball flights sampled at the frame times of a clip: the forward model of the segment fits.

:func:`sample_flight` integrates a batch of free flights (no contacts) with fixed-step RK4 and keeps the
positions at exactly the frame times 0, 1/fps, …, n/fps. The step is ``1/(fps·k)`` with ``k =
ceil(600/fps)`` substeps per frame (at least 600 steps per second, as :data:`inference.physics.DEFAULT_DT`).
Without spin (or without lift) the Magnus term vanishes and a drag-and-gravity kernel on (3, B) arrays does
the same arithmetic with fewer array operations; otherwise :func:`inference.physics.rk4_step` runs on the
batch. Either way one call costs about the same for 1 ball or 50, which the fits use to get a Jacobian by
finite differences from a single batched flight.

Example:
    >>> model = FlightModel.from_ball(load_court("padel").ball)
    >>> xyz = sample_flight(p0[None], v0[None], None, n_frames=30, fps=30.0, model=model)   # (1, 31, 3)
"""
from __future__ import annotations

import math

import numpy as np

from inference.physics import FlightModel, rk4_step


def substeps_per_frame(fps: float) -> int:
    """k = ceil(600/fps): RK4 steps per frame interval."""
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    return max(1, math.ceil(600.0 / fps - 1e-9))


def sample_flight(
    p0: np.ndarray,
    v0: np.ndarray,
    spin: np.ndarray | None,
    n_frames: int,
    fps: float,
    model: FlightModel,
    substeps: int | None = None,
) -> np.ndarray:
    """Positions of B free flights at the frame times 0, 1/fps, …, n_frames/fps.

    Args:
        p0, v0: (B, 3) initial positions (m) and velocities (m/s); (3,) is one ball.
        spin: (B, 3) initial angular velocities (rad/s), or None for no spin.
        n_frames: frame intervals to integrate (>= 0).
        fps: frame rate.
        model: flight constants.
        substeps: RK4 steps per frame; default ``ceil(600/fps)``.
    Returns:
        (B, n_frames + 1, 3) ball centres; row 0 is ``p0``.
    """
    p = np.atleast_2d(np.asarray(p0, dtype=float))
    v = np.atleast_2d(np.asarray(v0, dtype=float))
    if p.shape != v.shape or p.shape[1] != 3:
        raise ValueError(f"p0 and v0 must both be (B, 3), got {p.shape} and {v.shape}")
    if n_frames < 0:
        raise ValueError(f"n_frames must be >= 0, got {n_frames}")
    k = substeps or substeps_per_frame(fps)
    h = 1.0 / (fps * k)
    w = None if spin is None else np.broadcast_to(np.atleast_2d(np.asarray(spin, dtype=float)), p.shape)
    if w is None or model.lift_k == 0.0 or not np.any(w):
        out = _drag_flight(p.T.copy(), v.T.copy(), n_frames, k, h, model.drag_k, model.gravity)
    else:
        out = _spin_flight(p, v, w, n_frames, k, h, model)
    return np.ascontiguousarray(out.transpose(2, 0, 1))


def _drag_accel(v: np.ndarray, drag_k: float, g: np.ndarray) -> np.ndarray:
    """(3, B) velocities, (3, 1) gravity vector → (3, B) accelerations ``-k |v| v + g``."""
    a = v * (-drag_k * np.sqrt(np.einsum("ib,ib->b", v, v)))
    a += g
    return a


def _drag_flight(p: np.ndarray, v: np.ndarray, n_frames: int, k: int, h: float, drag_k: float,
                 gravity: float) -> np.ndarray:
    """RK4 of gravity and drag on (3, B) states → (n_frames + 1, 3, B) positions at every k-th step.

    Same stage arithmetic as :func:`inference.physics.rk4_step` with zero spin."""
    out = np.empty((n_frames + 1, *p.shape))
    out[0] = p
    hh, h6 = 0.5 * h, h / 6.0
    hp = h * h6
    g = np.array([[0.0], [0.0], [-gravity]])
    for f in range(n_frames):
        for _ in range(k):
            a1 = _drag_accel(v, drag_k, g)
            a2 = _drag_accel(v + hh * a1, drag_k, g)
            a3 = _drag_accel(v + hh * a2, drag_k, g)
            a4 = _drag_accel(v + h * a3, drag_k, g)
            s23 = a2 + a3
            p = p + h * v + hp * (a1 + s23)
            v = v + h6 * (a1 + a4 + 2.0 * s23)
        out[f + 1] = p
    return out


def _spin_flight(p: np.ndarray, v: np.ndarray, w: np.ndarray, n_frames: int, k: int, h: float,
                 model: FlightModel) -> np.ndarray:
    """RK4 with Magnus lift (:func:`inference.physics.rk4_step`) on (B, 3) states → (n_frames + 1, 3, B)."""
    c = model.kernel()
    state = tuple(np.ascontiguousarray(a[:, i]) for a in (p, v, w) for i in range(3))
    out = np.empty((n_frames + 1, 3, len(p)))
    out[0] = p.T
    for f in range(n_frames):
        for _ in range(k):
            state = rk4_step(state, h, c)
        out[f + 1] = np.stack(state[:3])
    return out


def vacuum_positions(p0: np.ndarray, v0: np.ndarray, times: np.ndarray, gravity: float) -> np.ndarray:
    """Closed-form flight without air: ``p0 + v0 t - ½ g t² ẑ``.

    Args:
        p0, v0: (3,) or (B, 3) initial positions (m) and velocities (m/s).
        times: (T,) seconds after the start.
        gravity: m/s².
    Returns:
        (T, 3) for one ball, (B, T, 3) for a batch.
    """
    p = np.asarray(p0, dtype=float)
    v = np.asarray(v0, dtype=float)
    t = np.asarray(times, dtype=float)[:, None]
    drop = np.array([0.0, 0.0, -0.5 * gravity]) * t * t
    return p[..., None, :] + v[..., None, :] * t + drop


def gravity_launch_velocity(p0: np.ndarray, p1: np.ndarray, duration: float, gravity: float) -> np.ndarray:
    """(3,) the launch velocity of the vacuum parabola from ``p0`` to ``p1`` in ``duration`` seconds."""
    if not duration > 0:
        raise ValueError(f"duration must be > 0, got {duration}")
    lift = np.array([0.0, 0.0, 0.5 * gravity * duration])
    return (np.asarray(p1, float) - np.asarray(p0, float)) / duration + lift
