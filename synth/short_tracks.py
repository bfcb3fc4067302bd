"""Short tracks with real ball physics, simulated outside the rally generator: a racket hit, one bounce and a
few frames after it (the shape of the short motion-capture trajectories that monocular methods are compared
on). Used by ``bench/bench_short_tracks.py`` and the short-track tests.

Drag, Magnus with random topspin or slice (:func:`inference.physics.integrate`), the rigid-ball impact of the
court's playing surface at the bounce (:func:`inference.physics.bounce`), then 3–8 frames; the first frame is a
random phase after the hit. The shots of each sport are a :class:`Shots` of :data:`SHOTS` (tennis from behind
the near baseline into the far half; table tennis from behind the near end of the table onto the far half of
it). :func:`hitter_players` gives the hitter's court position a players stage would write.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from inference.clipio import PlayerTracks
from inference.court import Court
from inference.physics import FlightModel, bounce, integrate

FPS = 25.0

Range = tuple[float, float]


@dataclass(frozen=True)
class Shots:
    """The shots drawn for one sport (metres, m/s, degrees, rad/s; the court frame of the court YAML).

    Attributes:
        hit: (x, y, z) ranges of the hit point.
        aim: (x, y) ranges of the point aimed at on the playing surface (sets the direction only).
        speed, elevation: launch speed and angle above the horizontal.
        spin: signed spin about the horizontal axis across the shot (negative: topspin).
        land_x, land_y: where the bounce must be (a shot landing elsewhere is drawn again).
        duration: seconds of flight simulated to find the bounce.

    The playing surface (height, material) is the court's first ``ground`` plane and the net's height its
    ``net_center_top`` point.
    """

    hit: tuple[Range, Range, Range]
    aim: tuple[Range, Range]
    speed: Range
    elevation: Range
    spin: Range
    land_x: Range
    land_y: Range
    duration: float = 3.0

    def __post_init__(self) -> None:
        for name in ("speed", "elevation", "spin", "land_x", "land_y"):
            lo, hi = getattr(self, name)
            if not lo <= hi:
                raise ValueError(f"Shots.{name} must be (low, high) with low <= high, got {(lo, hi)}")


#: The shots of each court's sport
SHOTS: dict[str, Shots] = {
    "tennis": Shots(hit=((1.5, 9.5), (-1.0, 3.0), (0.5, 1.6)), aim=((1.5, 9.5), (15.0, 22.5)), speed=(15.0, 32.0),
                    elevation=(2.0, 14.0), spin=(-250.0, 150.0), land_x=(-np.inf, np.inf),
                    land_y=(-np.inf, 23.77 + 2.0)),
    # drives, loops and pushes from 0.2-1 m behind the end line, 5-16 m/s, up to about 95 rev/s of topspin
    "table_tennis": Shots(hit=((0.1, 1.425), (-0.8, -0.2), (0.8, 1.15)), aim=((0.3, 1.225), (1.8, 2.5)),
                          speed=(6.0, 14.0), elevation=(3.0, 20.0), spin=(-500.0, 250.0), land_x=(0.0, 1.525),
                          land_y=(1.37, 2.74), duration=1.0),
}


#: (eye, target, horizontal field of view) of the side, oblique, behind and facing views of each sport's short
#: tracks (``bench/bench_short_tracks.py`` and the short-track tests)
VIEWS: dict[str, dict[str, tuple]] = {
    "tennis": {
        "side": ((-14.0, 11.9, 5.0), (5.5, 11.9, 0.0), 75.0),
        "oblique": ((-8.0, -6.0, 7.0), (5.5, 12.0, 0.0), 60.0),
        "behind": ((5.5, -10.0, 5.0), (5.5, 12.0, 0.0), 45.0),
        # a broadcast's long lens 22 m behind the near baseline, 9 m up: it looks along the flights
        "behind 22 m": ((5.5, -22.0, 9.0), (5.5, 12.0, 0.0), 30.0),
        # the same camera behind the far baseline: the shots fly at it (half of a rally's shots)
        "facing 22 m": ((5.5, 23.77 + 22.0, 9.0), (5.5, 11.9, 0.0), 30.0),
    },
    # the table (1.525 x 2.74 m, top 0.76 m) seen from 3-4 m, as the motion-capture rooms film it
    "table_tennis": {
        "side": ((-4.0, 1.0, 1.8), (0.76, 1.0, 0.76), 65.0),
        "oblique": ((-2.6, -2.0, 2.2), (0.76, 1.2, 0.76), 60.0),
        "behind": ((0.76, -3.4, 2.0), (0.76, 1.6, 0.76), 50.0),
        # behind the far end: the shots fly at the camera (a rally's other half), from 3.4 m and from 6 m
        "facing": ((0.76, 2.74 + 3.4, 2.0), (0.76, 1.14, 0.76), 50.0),
        "facing 6 m": ((0.76, 2.74 + 6.0, 3.0), (0.76, 1.14, 0.76), 35.0),
    },
}
#: how far beside the ball the hitter's body is drawn (m): a tennis player reaches farther than a table-tennis one
REACH = {"tennis": (0.4, 1.1), "table_tennis": (0.2, 0.7)}

def simulate(rng: np.random.Generator, court: Court, model: FlightModel, fps: float = FPS,
             shots: Shots | None = None) -> dict | None:
    """One hit → bounce → a few frames, or None when the drawn shot fails (into the net, off the surface):
    positions at the frames (n, 3), the hit and bounce frames, the hit point (3,). ``shots`` defaults to
    ``SHOTS[court.sport]``."""
    sh = shots or SHOTS[court.sport]
    r = court.ball.radius
    surface = court.planes_for("ground")[0]
    surface_z, mat = float(surface.origin[2]), court.materials[surface.material]
    net_top = float(court.points["net_center_top"][2])
    hit = np.array([rng.uniform(*sh.hit[0]), rng.uniform(*sh.hit[1]), rng.uniform(*sh.hit[2])])
    land = np.array([rng.uniform(*sh.aim[0]), rng.uniform(*sh.aim[1])])
    speed = rng.uniform(*sh.speed)
    d = np.r_[land - hit[:2], 0.0]
    d /= np.linalg.norm(d)
    elev = np.radians(rng.uniform(*sh.elevation))
    vel = speed * np.r_[np.cos(elev) * d[:2], np.sin(elev)]
    spin = np.cross([0.0, 0.0, 1.0], d) * rng.uniform(*sh.spin)   # topspin (<0 here) or slice
    dt = 1.0 / 1000.0
    s = integrate(hit, vel, spin, sh.duration, model, dt=dt)
    z = s.pos[:, 0, 2]
    below = np.flatnonzero(z <= surface_z + r)
    if not len(below):
        return None
    k = int(below[0])
    net = np.flatnonzero((s.pos[:k, 0, 1] >= court.net_y))
    x_b, y_b = s.pos[k, 0, :2]
    if (not len(net) or s.pos[net[0], 0, 2] < net_top + 3 * r
            or not sh.land_x[0] <= x_b <= sh.land_x[1] or not sh.land_y[0] <= y_b <= sh.land_y[1]):
        return None                                          # into the net or off the surface: not a rally shot
    t_b = s.t[k]
    up = np.array([0.0, 0.0, 1.0])
    v_out, w_out = bounce(s.vel[k], s.spin[k], up, mat.restitution, mat.friction, r)
    p_b = s.pos[k, 0].copy()
    p_b[2] = surface_z + r
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


def draw_tracks(court: Court, n: int, seed: int, fps: float = FPS) -> list[dict]:
    """The first ``n`` tracks :func:`simulate` draws (shots that fail are drawn again) from ``seed``, with the
    court's ball."""
    model = FlightModel.from_ball(court.ball)
    rng = np.random.default_rng(seed)
    out: list[dict] = []
    while len(out) < n:
        tr = simulate(rng, court, model, fps)
        if tr is not None:
            out.append(tr)
    return out


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
