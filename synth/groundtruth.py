"""Ground-truth tables of a simulated rally, in the clip-folder format (docs/formats.md).

Pure functions from a :class:`Rally` and a camera to the typed tables of :mod:`inference.clipio`;
the renderer supplies what only it knows (the ball's 2D visibility, players' 2D keypoints).
"""
from __future__ import annotations

import numpy as np

from inference.camera import Camera
from inference.clipio import Ball3D, CourtPoints, HitEvents, InactiveBalls
from inference.court import Court

from .types import Rally


def event_table(rally: Rally) -> HitEvents:
    """events.csv: each contact at the frame nearest its time; frames are unique.

    Two contacts that round to the same frame (a corner bounce floor → glass inside one frame) keep
    their order: the later one moves to the next free frame, so no contact is lost.
    """
    frames, labels = [], []
    for frame, label in sorted(rally.event_frames(), key=lambda x: x[0]):
        frame = max(frame, frames[-1] + 1) if frames else frame
        if frame >= rally.n_frames:
            break
        frames.append(frame)
        labels.append(label)
    return HitEvents(np.array(frames, dtype=np.int64), np.array(labels, dtype=str))


def segment_index(rally: Rally, times: np.ndarray) -> np.ndarray:
    """(T,) flight segment of each time: the number of contacts strictly before it."""
    contact_t = np.array([c.t for c in rally.contacts])
    return np.searchsorted(contact_t, times, side="left").astype(np.int64) if len(contact_t) else np.zeros(
        len(times), np.int64)


def ball_3d_table(rally: Rally) -> Ball3D:
    """gt/ball_3d.csv: the true ball centre at every frame the simulated ball exists (from the serve's
    toss to a little after the point ends)."""
    t = rally.frame_times
    frames = np.flatnonzero((t >= rally.ball.t[0]) & (t <= rally.ball.t[-1]))
    xyz = rally.ball.sample(t[frames])
    return Ball3D(frame=frames, xyz=xyz, segment=segment_index(rally, t[frames]), kind=["gt"] * len(frames))


def inside_image(px: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(N, 2) pixels → (N,) bool: finite and inside the image."""
    w, h = size
    return np.isfinite(px).all(axis=1) & (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)


def inactive_ball_table(rally: Rally, camera: Camera) -> InactiveBalls:
    """inactive_balls.csv: every stationary ball at every frame it lies on court and is in the image."""
    frames, numbers, xy = [], [], []
    size = np.asarray(camera.image_size, dtype=float)
    for ball in rally.inactive_balls:
        px = camera.project(ball.position[None])[0]
        if not inside_image(px[None], camera.image_size)[0]:
            continue
        for f in range(max(ball.first, 0), min(ball.last, rally.n_frames - 1) + 1):
            frames.append(f)
            numbers.append(ball.ball_no)
            xy.append(px / size)
    order = np.lexsort((numbers, frames)) if frames else np.zeros(0, np.int64)
    return InactiveBalls(np.array(frames, np.int64)[order], np.array(numbers, np.int64)[order],
                         np.array(xy, float).reshape(-1, 2)[order])


def court_point_table(court: Court, camera: Camera, rng: np.random.Generator | None = None,
                      click_noise_px: float = 0.0) -> CourtPoints:
    """court_points.csv: the named court points inside the image, optionally with uniform click noise."""
    names = court.point_names
    px = camera.project(court.point_array(names))
    ok = inside_image(px, camera.image_size)
    px = px[ok]
    if click_noise_px > 0 and rng is not None:
        px = px + rng.uniform(-click_noise_px, click_noise_px, px.shape)
    size = np.asarray(camera.image_size, dtype=float)
    return CourtPoints([n for n, k in zip(names, ok) if k], np.clip(px / size, 0.0, 1.0))
