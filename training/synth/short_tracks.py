"""Short tracks with real ball physics, simulated outside the rally generator: a racket hit, one bounce and a
few frames after it (the shape of the short motion-capture trajectories that monocular methods are compared
on). Used by ``bench/bench_short_tracks.py`` and the short-track tests.

Drag, Magnus with random topspin or slice (:func:`inference.physics.integrate`), the rigid-ball impact of the
court's floor at the bounce (:func:`inference.physics.bounce`), then 3–8 frames; the first frame is a random
phase after the hit. :func:`hitter_players` gives the hitter's court position a players stage would write.
"""
from __future__ import annotations

import numpy as np

from inference.clipio import PlayerTracks
from inference.court import Court
from inference.physics import FlightModel, bounce, integrate

FPS = 25.0


def simulate(rng: np.random.Generator, court: Court, model: FlightModel, fps: float = FPS) -> dict | None:
    """One hit → bounce → a few frames: positions at the frames (n, 3), the hit and bounce frames, the hit
    point (3,)."""
    r = court.ball.radius
    floor = court.materials["floor"]
    hit = np.array([rng.uniform(1.5, 9.5), rng.uniform(-1.0, 3.0), rng.uniform(0.5, 1.6)])
    land = np.array([rng.uniform(1.5, 9.5), rng.uniform(15.0, 22.5)])
    speed = rng.uniform(15.0, 32.0)
    d = np.r_[land - hit[:2], 0.0]
    d /= np.linalg.norm(d)
    elev = np.radians(rng.uniform(2.0, 14.0))
    vel = speed * np.r_[np.cos(elev) * d[:2], np.sin(elev)]
    spin = np.cross([0.0, 0.0, 1.0], d) * rng.uniform(-250.0, 150.0)   # topspin (<0 here) or slice
    dt = 1.0 / 1000.0
    s = integrate(hit, vel, spin, 3.0, model, dt=dt)
    z = s.pos[:, 0, 2]
    below = np.flatnonzero(z <= r)
    if not len(below):
        return None
    k = int(below[0])
    net = np.flatnonzero((s.pos[:k, 0, 1] >= court.net_y))
    if not len(net) or s.pos[net[0], 0, 2] < 0.914 + 3 * r or s.pos[k, 0, 1] > court.size[1] + 2:
        return None                                          # into the net or far out: not a rally shot
    t_b = s.t[k]
    up = np.array([0.0, 0.0, 1.0])
    v_out, w_out = bounce(s.vel[k], s.spin[k], up, floor.restitution, floor.friction, r)
    p_b = s.pos[k, 0].copy()
    p_b[2] = r
    after = rng.integers(3, 9)
    t_hit = -rng.uniform(0.0, 1.0 / fps)                    # the hit between frames −1 and 0 (seconds)
    last = int(np.floor((t_b + t_hit) * fps)) + int(after)
    frames = np.arange(0, last + 1)
    since = frames / fps - t_hit                             # seconds since the hit
    pos = np.empty((len(frames), 3))
    pre = since <= t_b
    idx = np.clip(np.round(since[pre] / dt).astype(int), 0, len(s.t) - 1)
    pos[pre] = s.pos[idx, 0]
    if (~pre).any():
        s2 = integrate(p_b, v_out[0], w_out[0], float(since[~pre].max() - t_b) + dt, model, dt=dt)
        j = np.clip(np.round((since[~pre] - t_b) / dt).astype(int), 0, len(s2.t) - 1)
        pos[~pre] = s2.pos[j, 0]
    bounce_frame = int(np.round((t_b + t_hit) * fps))
    return {"frames": frames, "xyz": pos, "bounce": bounce_frame, "hit": 0, "after": int(after), "hit_xyz": hit}


def hitter_players(rng: np.random.Generator, track: dict, sigma_m: float = 0.3,
                   reach: tuple[float, float] = (0.4, 1.1), behind_m: float = 0.2) -> PlayerTracks:
    """players.csv of the track's hitter at the hit frame, as a players stage would place them: the body
    ``reach`` metres to one side of the ball at the hit (forehand or backhand, drawn), ``behind_m`` behind
    it, plus Gaussian noise of ``sigma_m`` per axis; team ``near`` (the tracks are hit from the near side)."""
    hit = track["hit_xyz"]
    side = rng.choice([-1.0, 1.0]) * rng.uniform(*reach)
    xy = np.array([hit[0] + side, hit[1] - behind_m]) + rng.normal(0.0, sigma_m, 2)
    return PlayerTracks(np.array([track["hit"]]), np.array([0]), ["near"], np.array([1.0]), np.full((1, 4), np.nan),
                        np.full((1, 17, 3), np.nan), xy[None])
