"""Per-class event F1 of hit-event models under input conditions (the tables of docs/events.md).

    .venv/bin/python bench/bench_event_conditions.py [--sport tennis] [--clips 60] [--fps 50]
        [--weights shipped runs/other.pth.tar ...] [--degrade conf/data/degrade/detector_measured.yaml]
        [--no-bridge-too]

Held-out simulated rallies (their own seed) with the annotated ball, pipeline-like tracks
(``training.events.synthetic.degrade`` on every clip) and real-tracker-like tracks with gaps at the contacts (whole
pixels, the far end lost more often, the top 5 % cropped, 90 % of the near and far hits hidden); every
event kept, ±2 frames at 50 fps (scaled). ``--degrade FILE`` adds tracks degraded with a measured setting
(bench_track_stats.py), every clip; ``--no-bridge-too`` scores each model also without the gap-aware timing
of the far hits (:mod:`inference.events.gaps`, on by default). Prints one Markdown table per condition and the CPU time.
"""
from __future__ import annotations

import argparse
import time

import torch

CONDITIONS = {
    "annotated": None,
    "pipeline-like": dict(p_clean=0.0),
    "real-tracker-like, gaps at contacts": dict(p_clean=0.0, integer_px=True, far_miss=0.3, top_crop=0.05,
                                                p_occlude_near=0.9, p_occlude_far=0.9),
}


def arg_parser() -> argparse.ArgumentParser:
    """The options shared with bench_events_players.py."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--sport", default="tennis")
    ap.add_argument("--clips", type=int, default=60)
    ap.add_argument("--fps", type=float, default=50.0)
    ap.add_argument("--weights", nargs="+", default=["shipped"],
                    help="model files; `shipped`: the sport's default, the file `rally3d events` uses (the event tagger "
                         "since 2026-11-29; earlier tables in docs/events.md name the ball-only HitNet `shipped`)")
    ap.add_argument("--cache", default="runs/events_cache")
    ap.add_argument("--degrade", default=None, help="a measured data.degrade YAML: one more condition")
    ap.add_argument("--no-bridge-too", action="store_true",
                    help="each model also without the far hits' gap bridging (on by default)")
    ap.add_argument("--only", nargs="+", default=None, help="run only these conditions (names as printed)")
    return ap


def measured_degrade(path) -> dict:
    """A measured ``data.degrade`` YAML (bench_track_stats.py) as a condition: every clip degraded."""
    import yaml

    with open(path) as f:
        return {**yaml.safe_load(f), "p_clean": 0.0}


def conditions_of(args, base: dict | None = None) -> dict:
    """The conditions to run: the standard ones (``base``, default :data:`CONDITIONS`), a measured
    ``--degrade`` file, filtered by ``--only``."""
    conditions = dict(CONDITIONS if base is None else base)
    if args.degrade:
        conditions[f"measured detector ({args.degrade})"] = measured_degrade(args.degrade)
    if args.only:
        conditions = {k: v for k, v in conditions.items() if any(k.startswith(o) for o in args.only)}
    return conditions


def event_counts(det, clips, tracks, players=None, bridge_gaps: bool = True):
    """Event counts of ``det`` on ``clips`` with these ball tracks (and players, one per clip), every event
    kept, ±2 frames at 50 fps (scaled)."""
    from inference.events.metrics import EventCounts, tolerance_frames

    cs = det.class_set
    counts = EventCounts(cs.classes)
    for c, tr, pl in zip(clips, tracks, players or [None] * len(clips)):
        r = det.predict(tr, c.fps, c.width, c.height, camera=c.camera, n_frames=c.n_frames, keep_all=True,
                        players=pl, bridge_gaps=bridge_gaps)
        counts.add(c.events.frame, [cs.encode_label(str(e)) or 0 for e in c.events.event], r.events.frame,
                   [cs.index(x) for x in r.coarse], tolerance_frames(c.fps))
    return counts


def main(argv=None) -> None:
    from inference.events import EventDetector
    from inference.events.metrics import tolerance_frames
    from training.events.synthetic.degrade import DegradeConfig, degrade_all
    from training.events.synthetic.simulate import simulate_clips

    args = arg_parser().parse_args(argv)
    conditions = conditions_of(args)
    torch.set_num_threads(1)
    t0 = time.process_time()
    clips = simulate_clips(args.sport, args.clips, 6161, args.cache, progress=False, fps=args.fps)
    models = [(w, EventDetector.from_checkpoint(None if w == "shipped" else w, sport=args.sport)) for w in args.weights]
    cs = models[0][1].class_set
    print(f"\n{args.sport}, {len(clips)} held-out simulated rallies at {args.fps:g} fps, every event kept, "
          f"±{tolerance_frames(args.fps)} frames\n")
    variants = [(name, det, True) for name, det in models] + (
        [(f"{name}, no gap bridging", det, False) for name, det in models] if args.no_bridge_too else [])
    for cond, kw in conditions.items():
        tracks = [c.ball for c in clips] if kw is None else degrade_all(clips, 11, DegradeConfig.from_dict(kw))
        print(f"**{cond}**\n\n| model | all | " + " | ".join(cs.classes[1:]) + " |\n|---|" + "---|" * cs.n)
        for name, det, bridge in variants:
            counts = event_counts(det, clips, tracks, bridge_gaps=bridge)
            f1 = [counts.scores()["f1"]] + [counts.scores(i)["f1"] for i in range(1, cs.n)]
            print(f"| {name} | " + " | ".join(f"{v:.3f}" for v in f1) + " |", flush=True)
        print()
    print(f"CPU time {time.process_time() - t0:.1f} s")


if __name__ == "__main__":
    main()
