"""Benchmark the synthetic rally generator: frames/s at 1280x720, single process, per stage; sample size.

    .venv/bin/python bench/bench_synth.py [--clips 3]

Prints figures; asserts nothing. Stages: rally simulation, body articulation, rendering (with a random
look: noise, JPEG round trip, blur, reflections), and video encoding (H.264 via PyAV), measured on the
same clips in the same run.
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from inference.clipio import write_video
from inference.court import load_court
from synth.bodies import articulate
from synth.cameras import CameraSpec
from synth.generate import SynthConfig, generate_clip
from synth.rally import simulate_rally
from synth.render import Appearance, CourtRenderer, ball_exposure

ROOT = Path(__file__).resolve().parents[1]


def stage_times(sport: str, seed: int) -> dict[str, float]:
    court = load_court(sport)
    rng = np.random.default_rng(seed)
    spec = CameraSpec.preset("padel_installed" if sport == "padel" else "tennis_broadcast")
    cam = spec.build(court)
    t = {}
    t0 = time.perf_counter()
    rally = simulate_rally(court, 30.0, rng, sport=sport)
    t["simulate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    poses = [articulate(p, 30.0, rng, sport=sport) for p in rally.players]
    t["articulate"] = time.perf_counter() - t0
    look = Appearance.sample(rng, sport)
    t0 = time.perf_counter()
    renderer = CourtRenderer(court, cam, look, seed=seed)
    t["background"] = time.perf_counter() - t0
    frames = []
    t0 = time.perf_counter()
    for i in range(rally.n_frames):
        img, _ = renderer.render(i, ball_exposure(rally.ball, i, 30.0, look.shutter), poses, rally.inactive_balls)
        frames.append(img)
    t["render"] = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        write_video(Path(d) / "v.mp4", frames, 30.0, fourcc="h264")
        t["encode_h264"] = time.perf_counter() - t0
    t["frames"] = rally.n_frames
    return t


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clips", type=int, default=3, help="clips per sport")
    args = ap.parse_args()
    print("per-stage, 1280x720 @ 30 fps, single process (frames/s of each stage alone):")
    for sport in ("padel", "tennis"):
        tot: dict[str, float] = {}
        for seed in range(args.clips):
            for k, v in stage_times(sport, seed).items():
                tot[k] = tot.get(k, 0.0) + v
        n = tot.pop("frames")
        work = sum(tot.values())
        parts = ", ".join(f"{k} {v / work * 100:.0f}%" for k, v in tot.items())
        print(f"  {sport:6s} {int(n)} frames: render {n / tot['render']:.1f} fps, end to end "
              f"{n / work:.1f} fps  ({parts})")
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        n = sum(generate_clip(Path(d) / f"c{k}", k, SynthConfig(sport="padel", randomise_camera=False,
                                                                width=1280, height=720, fps=30.0)).n_frames
                for k in range(args.clips))
        print(f"generate_clip (padel, 1280x720, h264, all stages and files): {n / (time.perf_counter() - t0):.1f} "
              f"frames/s over {n} frames")
    sample = ROOT / "datasets" / "sample"
    size = sum(p.stat().st_size for p in sample.rglob("*") if p.is_file())
    print(f"embedded sample datasets/sample: {size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
