"""Rally segmentation on simulated rallies with the server's bounces before the serve and the ball after
the point (``simulate_clips(..., around=True)``): serve frame within ±3 frames, end within ±0.3 s, and
event F1 of the rally's events with and without the segmentation (the model ``rally3d infer`` uses for the
sport: ``choose_weights``, with or without players).

    .venv/bin/python bench/bench_rally.py [--sport padel] [--clips 100] [--track annotated|degraded]
        [--fps 25] [--seed 8] [--plain] [--players] [--degrade conf/data/degrade/detector_measured.yaml] [--why]

Prints the figures and the CPU time; the clips are held out from training (their own seed).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch


#: pose noise measured on MoveNet and the players stage (docs/events.md#pose-noise-measured)
MEASURED_POSE_NOISE = "conf/data/pose_noise/movenet_measured.yaml"


def print_why(c, res) -> None:
    """One rally whose serve (±3 frames) or end (±0.3 s) is missed: the truth, the guess, where the serve came
    from, and the events (ground truth; decoded, 1 = judged inside the point)."""
    seg = res.rally
    ds, de = seg.start - c.rally[0], (seg.end - c.rally[1]) / c.fps
    if abs(ds) <= 3 and abs(de) <= 0.3:
        return
    what = " ".join(w for w, bad in (("SERVE", abs(ds) > 3), ("END", abs(de) > 0.3)) if bad)
    print(f"{c.name} {c.fps:g} fps: {what} missed; serve {c.rally[0]} → {seg.start} (from {seg.serve_source}), "
          f"end {c.rally[1]} → {seg.end} ({de:+.2f} s)")
    print("   truth:  ", " ".join(f"{f}:{e}" for f, e in zip(c.events.frame.tolist(), c.events.event.tolist())))
    print("   decoded:", " ".join(f"{f}:{e}{'' if k else '(out)'}" for f, e, k in
                                 zip(res.events.frame.tolist(), res.events.event.tolist(), seg.inside)))


def main(argv=None) -> dict:
    from bench_event_conditions import measured_degrade  # bench/ is the script's folder

    from inference.events import EventDetector
    from inference.events.detector import choose_weights, has_players
    from inference.events.features import dense_xy
    from inference.events.metrics import EventCounts, tolerance_frames
    from training.events.synthetic.degrade import DegradeConfig, degrade_all
    from training.events.synthetic.simulate import simulate_clips

    ap = argparse.ArgumentParser()
    ap.add_argument("--sport", default="padel")
    ap.add_argument("--clips", type=int, default=100)
    ap.add_argument("--track", choices=["annotated", "degraded"], default="annotated")
    ap.add_argument("--degrade", default=None,
                    help="with --track degraded: a data.degrade YAML instead of the default degradation "
                    "(e.g. conf/data/degrade/detector_measured.yaml, our detector as measured)")
    ap.add_argument("--fps", type=float, default=None, help="fix the frame rate (default: drawn 25–60)")
    ap.add_argument("--seed", type=int, default=8, help="clips of seed 7000 + this (7: the tuning set)")
    ap.add_argument("--weights", default=None, help="hit-event model (default: the shipped one)")
    ap.add_argument("--cache", default="runs/events_cache")
    ap.add_argument("--plain", action="store_true", help="rallies without warm-up bounces or the ball after the point "
                    "(the standard clips: does the segmentation cost their events?)")
    ap.add_argument("--players", action="store_true",
                    help="as `rally3d infer` with players found: the rallies' players seen through the pose noise "
                    "measured on MoveNet (read by a player-aware model)")
    ap.add_argument("--why", action="store_true", help="print each rally whose serve or end is missed, and why")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    t0 = time.process_time()
    clips = simulate_clips(args.sport, args.clips, 7000 + args.seed, args.cache, progress=False,
                           around=not args.plain, fps=args.fps, players=args.players)
    degrade = DegradeConfig.from_dict(measured_degrade(args.degrade)) if args.degrade else DegradeConfig(p_clean=0.0)
    tracks = [c.ball for c in clips] if args.track == "annotated" else degrade_all(clips, args.seed, degrade)
    players = [None] * len(clips)
    if args.players:
        from training.events.synthetic.pose_noise import PoseNoiseConfig, noisy_all

        players = noisy_all(clips, 17, PoseNoiseConfig.from_file(MEASURED_POSE_NOISE))
    weights = choose_weights(args.weights, args.sport, next((p for p in players if has_players(p)), None))
    det = EventDetector.from_checkpoint(weights, sport=args.sport)
    cs = det.class_set
    d_start, d_end, sources = [], [], {}
    counts = {k: EventCounts(cs.classes) for k in ("rally", "all")}
    for c, tr, pl in zip(clips, tracks, players):
        res = det.predict(tr, c.fps, c.width, c.height, camera=c.camera, n_frames=c.n_frames, keep_all=True,
                          players=pl)
        seg = res.rally
        if args.why:
            print_why(c, res)
        d_start.append(seg.start - c.rally[0])
        d_end.append((seg.end - c.rally[1]) / c.fps)
        sources[seg.serve_source] = sources.get(seg.serve_source, 0) + 1
        tol = tolerance_frames(c.fps)
        gt = [cs.encode_label(str(e)) or 0 for e in c.events.event]
        pred = [cs.index(x) for x in res.coarse]
        counts["all"].add(c.events.frame, gt, res.events.frame, pred, tol)
        k = seg.inside
        counts["rally"].add(c.events.frame, gt, res.events.frame[k], [p for p, m in zip(pred, k) if m], tol)
    d_start, d_end = np.abs(np.asarray(d_start)), np.abs(np.asarray(d_end))
    cpu = time.process_time() - t0
    out = {
        "clips": len(clips), "serve_within_3": float(np.mean(d_start <= 3)),
        "serve_median_abs_frames": float(np.median(d_start)),
        "end_within_0.3s": float(np.mean(d_end <= 0.3)), "end_median_abs_s": float(np.median(d_end)),
        "f1_rally_events": counts["rally"].scores()["f1"], "f1_all_events": counts["all"].scores()["f1"],
        "serve_from": sources, "cpu_s": cpu,
    }
    fps = f"{args.fps:g} fps" if args.fps else "25–60 fps"
    kind = "without" if args.plain else "with"
    model = f"{Path(weights).name} ({'player-aware' if det.wants_players else 'ball only'}), " + (
        "players through the measured pose noise" if args.players else "no players")
    print(f"\n{args.sport}, {len(clips)} simulated rallies {kind} pre-serve bounces and the ball after the point, "
          f"{args.track} track{' (' + args.degrade + ')' if args.degrade and args.track == 'degraded' else ''}, {fps}, {model}")
    print(f"serve frame within ±3 frames: {out['serve_within_3']:.1%} (median |error| "
          f"{out['serve_median_abs_frames']:.1f} frames; serve from {sources})")
    print(f"end within ±0.3 s: {out['end_within_0.3s']:.1%} (median |error| {out['end_median_abs_s']:.2f} s)")
    print(f"event F1 (±2 frames at 50 fps): rally's events {out['f1_rally_events']:.3f}, every event kept "
          f"{out['f1_all_events']:.3f}")
    print(f"CPU time {cpu:.1f} s")
    return out


if __name__ == "__main__":
    main()
