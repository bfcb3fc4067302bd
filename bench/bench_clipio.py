"""Benchmark the foundation: CSV I/O, frame access and calibration. Prints figures; asserts nothing.

    .venv/bin/python bench/bench_clipio.py
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from inference.camera.calibration import calibrate_court
from inference.camera import Camera
from inference.clipio import BallTrack, FrameSource, read_ball_csv, write_ball_csv, write_video
from inference.court import load_court


def timed(fn, repeat: int = 3) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        n = 100_000
        vis = rng.integers(0, 4, n)
        track = BallTrack(np.arange(n), vis, np.where((vis > 0)[:, None], rng.random((n, 2)), np.nan))
        tw = timed(lambda: write_ball_csv(d / "ball.csv", track))
        tr = timed(lambda: read_ball_csv(d / "ball.csv", n_frames=n))
        print(f"ball.csv {n} rows: write {n / tw / 1e3:.0f}k rows/s, read {n / tr / 1e3:.0f}k rows/s")

        frames = (np.full((720, 1280, 3), i % 255, np.uint8) for i in range(120))
        write_video(d / "v.mp4", frames, 30.0)
        src = FrameSource.open(d / "v.mp4", cache_size=0)
        ts = timed(lambda: [None for _ in src.iter()], repeat=1)
        order = rng.permutation(120)[:40]
        trand = timed(lambda: [src.read(int(i)) for i in order], repeat=1)
        print(f"video 1280x720 mp4v: sequential {120 / ts:.0f} frames/s, random access {40 / trand:.1f} frames/s "
              f"(ratio {ts / 120 / (trand / 40):.2f})")

    court = load_court("padel")
    cam = Camera.from_look_at([5, -3, 6], [5, 9, 0], (1280, 720), fov_deg=80)
    px = cam.project(court.point_array(court.point_names))
    ok = (px[:, 0] > 0) & (px[:, 0] < 1280) & (px[:, 1] > 0) & (px[:, 1] < 720)
    pts = {n: px[i] + rng.uniform(-1, 1, 2) for i, n in enumerate(court.point_names) if ok[i]}
    tc = timed(lambda: calibrate_court(court, pts, (1280, 720)), repeat=5)
    res = calibrate_court(court, pts, (1280, 720))
    print(f"calibration from {len(pts)} points: {tc * 1e3:.1f} ms, RMS {res.rms_px:.2f} px, "
          f"centre error {np.linalg.norm(res.camera.centre - cam.centre) * 100:.1f} cm")


if __name__ == "__main__":
    main()
