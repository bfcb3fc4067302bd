"""Many videos: one process against a local Dask cluster (``rally3d infer … --workers N``), same results.

Renders ``--clips`` short padel clips (1280×720), then runs ``rally3d infer`` over them (a) in one process
(Lightning's loop, torch's default threads) and (b) with ``--workers N --threads T``, each in a fresh
interpreter, and prints wall and CPU time of each, the speed-up, and whether every clip's ball.csv, events.csv
and ball_3d.csv agree (largest difference).

    .venv/bin/python bench/bench_distributed.py [--clips 4] [--frames 90] [--workers 2] [--threads 1]
"""
from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def run(args: list[str], log: Path) -> tuple[int, float, float]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    with open(log, "w") as f:
        code = subprocess.call([sys.executable, "-m", "inference.cli", *args], stdout=f, stderr=subprocess.STDOUT,
                               cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return code, time.perf_counter() - t0, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def compare(a: Path, b: Path) -> str:
    from inference.clipio import Clip

    ca, cb = Clip(a), Clip(b)
    ba, bb = ca.read_ball(), cb.read_ball()
    ea, eb = ca.read_events(), cb.read_events()
    d_ball = float(np.nanmax(np.abs(ba.xy - bb.xy))) * ca.info.width if len(ba.xy) else 0.0
    same_events = np.array_equal(ea.frame, eb.frame) and list(ea.event) == list(eb.event)
    d3 = 0.0
    if (a / "ball_3d.csv").is_file() and (b / "ball_3d.csv").is_file():
        xa, xb = ca.read_ball_3d().xyz, cb.read_ball_3d().xyz
        d3 = float(np.max(np.abs(xa - xb))) if xa.shape == xb.shape and len(xa) else float("inf")
    return (f"ball ≤ {d_ball:.2g} px, events {'same' if same_events else 'DIFFER'}, 3D ≤ {d3:.2g} m"
            + ("" if np.array_equal(ba.visibility, bb.visibility) else ", visibility DIFFERS"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clips", type=int, default=4)
    ap.add_argument("--frames", type=int, default=90)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "bench_distributed")
    args = ap.parse_args()
    from synth.generate import SynthConfig, generate_clip

    shutil.rmtree(args.out, ignore_errors=True)
    clips = []
    for k in range(args.clips):
        cfg = SynthConfig(sport="padel", camera="padel_installed", randomise_camera=False, fps=30.0, width=1280,
                          height=720, codec="mp4v", max_frames=args.frames)
        generate_clip(args.out / "inputs" / f"clip{k}", seed=100 + k, config=cfg)
        clips.append(args.out / "inputs" / f"clip{k}")
    common = ["infer", *map(str, clips), "--pose", "none", "--no-progress"]
    c1, w1, cpu1 = run([*common, "--out", str(args.out / "one")], args.out / "one.log")
    c2, w2, cpu2 = run([*common, "--workers", str(args.workers), "--threads", str(args.threads), "--out",
                        str(args.out / "dask")], args.out / "dask.log")
    print(f"{args.clips} clips × {args.frames} frames (1280×720), --pose none, {os.cpu_count()} CPU cores")
    print(f"one process:            exit {c1}, wall {w1:6.1f} s, CPU {cpu1:6.1f} s")
    print(f"--workers {args.workers} --threads {args.threads}: exit {c2}, wall {w2:6.1f} s, CPU {cpu2:6.1f} s "
          f"(wall speed-up {w1 / w2:.2f}×)")
    for c in clips:
        print(f"  {c.name}: {compare(args.out / 'one' / c.name, args.out / 'dask' / c.name)}")
    return 0 if c1 == c2 == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
