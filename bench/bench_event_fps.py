"""Event F1 of a hit-event model per frame rate and input quality (the accuracy table of docs/events.md).

    .venv/bin/python bench/bench_event_fps.py [--sport padel] [--clips 30]

The same simulated rallies (held-out seed) at 25, 30, 50 and 60 fps, with the annotated ball, with
pipeline-like tracks (``training.events.degrade``, every clip degraded) and with real-tracker-like ones
(the same plus whole-pixel positions, the far end lost more often, the top 5 % of the image cropped and
the far player's hits hidden like the near one's: gaps at the contacts); tolerance ±40 ms (±2 frames at
50 fps, scaled and rounded). Prints a Markdown table and the CPU time.
"""
from __future__ import annotations

import argparse
import time

import torch


def main(argv=None) -> None:
    from inference.events import EventDetector
    from inference.events.metrics import EventCounts, tolerance_frames
    from training.events.degrade import DegradeConfig, degrade_all
    from training.events.simulate import simulate_clips

    ap = argparse.ArgumentParser()
    ap.add_argument("--sport", default="padel")
    ap.add_argument("--clips", type=int, default=30)
    ap.add_argument("--cache", default="runs/events_cache")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    t0 = time.process_time()
    det = EventDetector.from_checkpoint(None, sport=args.sport)
    cs = det.class_set
    print(f"\n{args.sport}, {args.clips} held-out simulated rallies per rate, shipped model, every event kept\n")
    print("| fps | tolerance | annotated ball F1 | pipeline-like track F1 | real-tracker-like, gaps at contacts F1 |\n"
          "|---|---|---|---|---|")
    real = DegradeConfig(p_clean=0.0, integer_px=True, far_miss=0.3, top_crop=0.05, p_occlude_far=0.8)
    for fps in (25.0, 30.0, 50.0, 60.0):
        clips = simulate_clips(args.sport, args.clips, 5151, args.cache, progress=False, fps=fps)
        row = []
        for tracks in ([c.ball for c in clips], degrade_all(clips, 3, DegradeConfig(p_clean=0.0)),
                       degrade_all(clips, 3, real)):
            counts = EventCounts(cs.classes)
            for c, tr in zip(clips, tracks):
                r = det.predict(tr, c.fps, c.width, c.height, camera=c.camera, n_frames=c.n_frames, keep_all=True)
                counts.add(c.events.frame, [cs.encode_label(str(e)) or 0 for e in c.events.event], r.events.frame,
                           [cs.index(x) for x in r.coarse], tolerance_frames(c.fps))
            row.append(counts.scores()["f1"])
        tol = tolerance_frames(fps)
        print(f"| {fps:g} | ±{tol} frames ({1000 * tol / fps:.0f} ms) | {row[0]:.3f} | {row[1]:.3f} | {row[2]:.3f} |", flush=True)
    print(f"\nCPU time {time.process_time() - t0:.1f} s")


if __name__ == "__main__":
    main()
