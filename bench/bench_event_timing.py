"""Is the hit-event model's timing uncertainty informative? Events by quarter of ``sigma_frames`` (and of
``confidence``) against how often they are off by more than the tolerance.

    .venv/bin/python bench/bench_event_timing.py [--sport tennis] [--clips 60] [--weights MODEL]

Held-out simulated rallies (seed 6161, as bench_events_players.py) with their players through the measured
pose noise and the real-tracker-like ball with gaps at the contacts; the sport's default model (the event
tagger) unless ``--weights``. For every decoded event: its ``uncertainty`` (the spread of the model's
probability around it, :func:`inference.events.decode.event_spread`) and ``confidence``, and its distance to
the nearest true event of its class. Prints one Markdown table per measure and the CPU time.
"""
from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

import numpy as np
import torch

from bench_events_players import GAPS  # bench/ is the script's folder


def main(argv=None) -> None:
    from inference.events import EventDetector
    from inference.events.detector import choose_weights, has_players
    from inference.events.metrics import tolerance_frames
    from training.events.synthetic.degrade import DegradeConfig, degrade_all
    from training.events.synthetic.pose_noise import PoseNoiseConfig, noisy_all
    from training.events.synthetic.simulate import simulate_clips

    ap = argparse.ArgumentParser()
    ap.add_argument("--sport", default="tennis")
    ap.add_argument("--clips", type=int, default=60)
    ap.add_argument("--weights", default=None, help="a hit-event model file (default: the sport's default)")
    ap.add_argument("--pose-noise", type=Path, default=Path("conf/data/pose_noise/movenet_measured.yaml"))
    ap.add_argument("--cache", default="runs/events_cache")
    args = ap.parse_args(argv)
    logging.getLogger("inference.events.detector").setLevel(logging.ERROR)
    torch.set_num_threads(1)
    t0 = time.process_time()
    clips = simulate_clips(args.sport, args.clips, 6161, args.cache, progress=False, fps=50.0, players=True)
    players = noisy_all(clips, 17, PoseNoiseConfig.from_file(args.pose_noise))
    tracks = degrade_all(clips, 11, DegradeConfig.from_dict(GAPS))
    path = choose_weights(args.weights, args.sport, next((p for p in players if has_players(p)), None))
    det = EventDetector.from_checkpoint(path, sport=args.sport)
    cs = det.class_set
    rows = []  # (sigma, confidence, |error| in frames)
    for c, tr, pl in zip(clips, tracks, players):
        r = det.predict(tr, c.fps, c.width, c.height, camera=c.camera, n_frames=c.n_frames, players=pl)
        gf = np.asarray(c.events.frame)
        gc = np.array([cs.encode_label(str(e)) or 0 for e in c.events.event])
        for f, name, s, p in zip(r.events.frame, r.coarse, r.uncertainty, r.confidence):
            d = gf[gc == cs.index(name)] - f
            rows.append((s, p, np.abs(d).min() if len(d) else np.inf))
    a = np.asarray(rows, float)
    tol = tolerance_frames(50.0)
    print(f"\n{args.sport}, {len(clips)} held-out rallies, real-tracker-like ball with gaps at the contacts, players "
          f"through {args.pose_noise}; {Path(path).name}; {len(a)} events, tolerance ±{tol} frames\n")
    for name, col in (("sigma_frames", 0), ("confidence", 1)):
        q = np.quantile(a[:, col], [0, 0.25, 0.5, 0.75, 1.0])
        print(f"| {name} quarter | range | events | within ±{tol} | off by {tol + 1}–5 | further or none |")
        print("|---|---|---|---|---|---|")
        for k in range(4):
            m = (a[:, col] >= q[k]) & (a[:, col] <= q[k + 1])
            e = a[m, 2]
            print(f"| {k + 1} | {q[k]:.2f}–{q[k + 1]:.2f} | {m.sum()} | {np.mean(e <= tol):.0%} | "
                  f"{np.mean((e > tol) & (e <= 5)):.0%} | {np.mean(e > 5):.0%} |")
        print()
    print(f"CPU time {time.process_time() - t0:.1f} s")


if __name__ == "__main__":
    main()
