"""Benchmark the synthetic frame renderer at 1280x720: 4 moving, swinging players, a fast motion-blurred
ball (with its glass reflections), two stationary balls, sensor noise and a JPEG round trip. Prints
frames/s and the share of time per step; asserts nothing.

    .venv/bin/python bench/bench_render.py [--frames 150] [--sport padel|tennis] [--no-jpeg]
"""
from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

from inference.camera import Camera
from inference.court import load_court
from synth.bodies import articulate
from synth.render import Appearance, CourtRenderer, ball_exposure
from synth.types import BallPath, InactiveBall, PlayerPlan, Swing

FPS = 30.0


def scene(sport: str, n_frames: int, rng: np.random.Generator):
    """Four players running across their half with a swing each second, a ball crossing the court."""
    court = load_court(sport)
    sx, sy = court.size
    t = np.arange(n_frames) / FPS
    plans = []
    for i, (fx, fy) in enumerate([(0.3, 0.2), (0.7, 0.3), (0.3, 0.8), (0.7, 0.7)]):
        far = i >= 2
        x = fx * sx + 1.2 * np.sin(2 * np.pi * t / 3.0 + i)
        y = np.full(n_frames, fy * sy) + 0.6 * np.cos(2 * np.pi * t / 4.0 + i)
        heading = np.full(n_frames, np.pi if far else 0.0)
        swings = []
        for k, th in enumerate(np.arange(0.6 + 0.2 * i, t[-1] - 0.5, 1.3)):
            f = round(th * FPS)
            side = 1.0 if k % 2 == 0 else -1.0
            fwd = -1.0 if far else 1.0
            hit = np.array([x[f] + 0.7 * side * fwd, y[f] + 0.4 * fwd, rng.uniform(0.5, 1.6)])
            swings.append(Swing(float(th), hit, "forehand" if side > 0 else "backhand"))
        plans.append(PlayerPlan(i, "far" if far else "near", "right", rng.uniform(1.65, 1.95), t,
                                np.c_[x, y], heading, swings))
    poses = [articulate(p, FPS, rng, sport=sport) for p in plans]
    tt = np.arange(0, t[-1] + 0.1, 1 / (10 * FPS))
    v = np.array([2.0, 0.9 * sy / 1.2, 3.0])  # crosses the court in 1.2 s, bouncing around
    period = 1.2
    phase = (tt % period) / period
    pos = np.c_[0.2 * sx + 0.6 * sx * phase, 0.05 * sy + 0.9 * sy * np.abs(np.sin(np.pi * tt / period / 2)),
                0.1 + 2.5 * np.abs(np.sin(2 * np.pi * tt / period))]
    path = BallPath(tt, pos, np.tile(v, (len(tt), 1)), np.zeros((len(tt), 3)), np.ones(len(tt), bool))
    still = [InactiveBall(0, np.array([0.3, 0.45 * sy, court.ball.radius]), 0, n_frames),
             InactiveBall(1, np.array([0.8 * sx, 0.95 * sy, court.ball.radius]), 0, n_frames)]
    return court, poses, path, still


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--sport", default="padel")
    ap.add_argument("--no-jpeg", action="store_true")
    a = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    court, poses, path, still = scene(a.sport, a.frames, rng)
    app = replace(Appearance.sample(rng, a.sport), noise_sigma=3.0, shutter=1.0,
                  jpeg_quality=None if a.no_jpeg else 85)
    eye, target = ([5, -3, 6], [5, 9, 0]) if a.sport == "padel" else ([5.5, -8, 7], [5.5, 11, 0])
    cam = Camera.from_look_at(eye, target, (1280, 720), fov_deg=80 if a.sport == "padel" else 70)
    t0 = time.perf_counter()
    renderer = CourtRenderer(court, cam, app, profile=True)
    setup = time.perf_counter() - t0
    streaks = []
    t0 = time.perf_counter()
    for f in range(a.frames):
        _, info = renderer.render(f, ball_exposure(path, f, FPS, app.shutter), poses, still)
        streaks.append(info.ball.streak_px)
    total = time.perf_counter() - t0
    print(f"{a.sport} 1280x720, 4 players, blurred ball (median streak {np.median(streaks):.0f} px), "
          f"noise, JPEG {'off' if a.no_jpeg else 'q85'}")
    print(f"setup (static scene) {setup:.2f} s; "
          f"render {a.frames / total:.1f} frames/s ({1e3 * total / a.frames:.1f} ms/frame)")
    steps = renderer.timings
    for step, sec in steps.items():
        print(f"  {step:8s} {1e3 * sec / a.frames:6.2f} ms  {100 * sec / sum(steps.values()):5.1f} %")


if __name__ == "__main__":
    main()
