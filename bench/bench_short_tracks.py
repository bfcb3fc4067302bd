"""Short tracks with real ball physics: a racket hit, one bounce and a few frames after it, seen at 25 fps
with σ 2–3 px noise by a camera at the side, oblique or behind — the shape of the short motion-capture
trajectories that monocular methods are compared on. Prints the 3D error split along and across each
frame's line of sight, and how many tracks were reconstructed, with the hit and the bounce as events and
with the bounce alone (one event).

    .venv/bin/python bench/bench_short_tracks.py [--tracks 30] [--seed 0]

The tracks are simulated here (tennis court and ball from conf/court/tennis.yaml): drag, Magnus with
random topspin or slice, the rigid-ball impact (restitution and friction of the court's floor) at the
bounce, then 3–8 frames; the first frame is a random phase after the hit. They are not made by
`rally3d synth` and the reconstruction knows only the court YAML, the camera, the 2D track and the events.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from inference.camera import Camera  # noqa: E402
from inference.court import load_court  # noqa: E402
from inference.physics import FlightModel, bounce, integrate  # noqa: E402
from inference.reconstruct import Observations  # noqa: E402
from inference.reconstruct.joint import JointConfig, fit_joint  # noqa: E402

FPS = 25.0
SIZE = (1280, 720)
#: (eye, target, horizontal field of view) of the three views
CAMERAS = {
    "side": ((-14.0, 11.9, 5.0), (5.5, 11.9, 0.0), 75.0),
    "oblique": ((-8.0, -6.0, 7.0), (5.5, 12.0, 0.0), 60.0),
    "behind": ((5.5, -10.0, 5.0), (5.5, 12.0, 0.0), 45.0),
}


def simulate(rng: np.random.Generator, court, model: FlightModel) -> dict | None:
    """One hit → bounce → a few frames: positions at the frames (n, 3), the hit and bounce frames."""
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
    v_out, w_out = bounce(s.vel[k], s.spin[k], np.array([0.0, 0.0, 1.0]), floor.restitution, floor.friction, r)
    p_b = s.pos[k, 0].copy()
    p_b[2] = r
    after = rng.integers(3, 9)
    t_hit = -rng.uniform(0.0, 1.0 / FPS)                    # the hit between frames −1 and 0 (seconds)
    last = int(np.floor((t_b + t_hit) * FPS)) + int(after)
    frames = np.arange(0, last + 1)
    since = frames / FPS - t_hit                             # seconds since the hit
    pos = np.empty((len(frames), 3))
    pre = since <= t_b
    idx = np.clip(np.round(since[pre] / dt).astype(int), 0, len(s.t) - 1)
    pos[pre] = s.pos[idx, 0]
    if (~pre).any():
        s2 = integrate(p_b, v_out[0], w_out[0], float(since[~pre].max() - t_b) + dt, model, dt=dt)
        j = np.clip(np.round((since[~pre] - t_b) / dt).astype(int), 0, len(s2.t) - 1)
        pos[~pre] = s2.pos[j, 0]
    bounce_frame = int(np.round((t_b + t_hit) * FPS))
    return {"frames": frames, "xyz": pos, "bounce": bounce_frame, "hit": 0, "after": int(after)}


def run(n: int, seed: int, noise: tuple[float, float]) -> None:
    court = load_court("tennis")
    model = FlightModel.from_ball(court.ball)
    rng = np.random.default_rng(seed)
    tracks = []
    while len(tracks) < n:
        tr = simulate(rng, court, model)
        if tr is not None:
            tracks.append(tr)
    print(f"{n} simulated tracks (tennis ball and court), 25 fps, hit → bounce → 3–8 frames, "
          f"{np.mean([len(t['frames']) for t in tracks]):.0f} frames on average, noise σ ∈ {noise} px\n")
    print("| camera | events | reconstructed | along-ray median m | along mean m | across median m | "
          "3D median m | 3D mean per track m | frames/CPU-s |")
    print("|---|---|---|---|---|---|---|---|---|")
    cfg = JointConfig(pixel_sigma=float(np.mean(noise)))
    for name, (eye, target, fov) in CAMERAS.items():
        cam = Camera.from_look_at(eye, target, SIZE, fov_deg=fov)
        for events in ("hit + bounce", "bounce only"):
            along, across, per_track, ok, frames, cpu = [], [], [], 0, 0, 0.0
            for k, tr in enumerate(tracks):
                r2 = np.random.default_rng(seed * 1000 + k)
                sigma = r2.uniform(*noise)
                uv = cam.project(tr["xyz"]) + r2.normal(0.0, sigma, (len(tr["xyz"]), 2))
                inside = (uv[:, 0] >= 0) & (uv[:, 0] < SIZE[0]) & (uv[:, 1] >= 0) & (uv[:, 1] < SIZE[1])
                uv[~inside] = np.nan
                if events == "hit + bounce":
                    ev, lab = [tr["hit"], tr["bounce"]], ["player_near", "ground"]
                else:
                    ev, lab = [tr["bounce"]], ["ground"]
                obs = Observations(court, cam, FPS, uv, np.array(ev), lab)
                c0 = time.process_time()
                fit = fit_joint(obs, cfg)
                cpu += time.process_time() - c0
                b = fit.ball_3d()
                if not len(b):
                    continue
                ok += 1
                frames += len(b)
                gt = tr["xyz"][b.frame]
                d = b.xyz - gt
                ray = gt - cam.centre
                ray /= np.linalg.norm(ray, axis=1)[:, None]
                a = np.einsum("ij,ij->i", d, ray)
                along.append(np.abs(a))
                across.append(np.linalg.norm(d - a[:, None] * ray, axis=1))
                per_track.append(float(np.linalg.norm(d, axis=1).mean()))
            A, C = np.concatenate(along), np.concatenate(across)
            E = np.sqrt(A**2 + C**2)
            print(f"| {name} | {events} | {ok}/{len(tracks)} | {np.median(A):.3f} | {A.mean():.3f} | "
                  f"{np.median(C):.4f} | {np.median(E):.3f} | {np.mean(per_track):.3f} | {frames / cpu:.0f} |",
                  flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tracks", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--noise", default="2,3", help="2D noise σ range in px (default 2,3)")
    args = ap.parse_args()
    lo, hi = (float(x) for x in args.noise.split(","))
    run(args.tracks, args.seed, (lo, hi))


if __name__ == "__main__":
    main()
