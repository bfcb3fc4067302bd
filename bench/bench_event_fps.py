"""Event F1 of a hit-event model per frame rate and input quality (the accuracy table of docs/events.md).

    .venv/bin/python bench/bench_event_fps.py [--sport padel] [--clips 30] [--weights FILE] [--players]

The same simulated rallies (held-out seed) at 25, 30, 50 and 60 fps, with the annotated ball, with
pipeline-like tracks (``training.events.synthetic.degrade``, every clip degraded) and with real-tracker-like ones
(the same plus whole-pixel positions, the far end lost more often, the top 5 % of the image cropped and
the far player's hits hidden like the near one's: gaps at the contacts); tolerance ±40 ms (±2 frames at
50 fps, scaled and rounded). The model is the one ``rally3d events`` picks for the sport (``--weights``: another);
``--players`` gives it the rallies' players through the pose noise measured on MoveNet. Prints a Markdown table and
the CPU time.
"""
from __future__ import annotations

import argparse
import time

import torch

MEASURED = "conf/data/pose_noise/movenet_measured.yaml"  # MoveNet and the players stage (docs/events.md)


def main(argv=None) -> None:
    from inference.events import EventDetector
    from inference.events.detector import choose_weights
    from training.events.synthetic.pose_noise import PoseNoiseConfig, noisy_all
    from inference.events.metrics import EventCounts, tolerance_frames
    from training.events.synthetic.degrade import DegradeConfig, degrade_all
    from training.events.synthetic.simulate import simulate_clips

    ap = argparse.ArgumentParser()
    ap.add_argument("--sport", default="padel")
    ap.add_argument("--clips", type=int, default=30)
    ap.add_argument("--cache", default="runs/events_cache")
    ap.add_argument("--weights", default=None, help="a hit-event model file (default: the sport's default)")
    ap.add_argument("--players", action="store_true", help="the rallies' players, through the measured pose noise")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    t0 = time.process_time()
    weights = choose_weights(args.weights, args.sport, None)
    det = EventDetector.from_checkpoint(weights, sport=args.sport)
    cs = det.class_set
    who = "players through the measured pose noise" if args.players else "no players"
    print(f"\n{args.sport}, {args.clips} held-out simulated rallies per rate, {weights.name}, {who}, every event kept\n")
    print("| fps | tolerance | annotated ball F1 | pipeline-like track F1 | real-tracker-like, gaps at contacts F1 |\n"
          "|---|---|---|---|---|")
    real = DegradeConfig(p_clean=0.0, integer_px=True, far_miss=0.3, top_crop=0.05, p_occlude_far=0.8)
    for fps in (25.0, 30.0, 50.0, 60.0):
        clips = simulate_clips(args.sport, args.clips, 5151, args.cache, progress=False, fps=fps, players=args.players)
        players = noisy_all(clips, 17, PoseNoiseConfig.from_file(MEASURED)) if args.players else [None] * len(clips)
        row = []
        for tracks in ([c.ball for c in clips], degrade_all(clips, 3, DegradeConfig(p_clean=0.0)),
                       degrade_all(clips, 3, real)):
            counts = EventCounts(cs.classes)
            for c, tr, pl in zip(clips, tracks, players):
                r = det.predict(tr, c.fps, c.width, c.height, camera=c.camera, n_frames=c.n_frames, keep_all=True,
                                players=pl)
                counts.add(c.events.frame, [cs.encode_label(str(e)) or 0 for e in c.events.event], r.events.frame,
                           [cs.index(x) for x in r.coarse], tolerance_frames(c.fps))
            row.append(counts.scores()["f1"])
        tol = tolerance_frames(fps)
        print(f"| {fps:g} | ±{tol} frames ({1000 * tol / fps:.0f} ms) | {row[0]:.3f} | {row[1]:.3f} | {row[2]:.3f} |", flush=True)
    print(f"\nCPU time {time.process_time() - t0:.1f} s")


if __name__ == "__main__":
    main()
