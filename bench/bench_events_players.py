"""Ball-only vs player-aware hit-event models, per class, with and without gaps at the contacts.

    .venv/bin/python bench/bench_events_players.py [--sport tennis] [--clips 60] [--fps 50]
        [--weights shipped runs/hitnet_tennis_players.pth.tar ...] [--no-bridge-too] [--out FILE.md]
        [--degrade conf/data/degrade/detector_measured.yaml] [--only annotated real measured]

Held-out simulated rallies (seed 6161, never used for training or tuning) with their articulated players
(they swing at their hits) seen through pose-backend noise (``training.events.synthetic.pose_noise``: misses, the far
player more often, jitter, lost wrists, left/right flips, near/far swaps, clips without players or
poses); every event kept, ±2 frames at 50 fps (scaled with fps). Ball conditions: the annotated track,
a real-tracker-like track without gaps at the contacts (whole pixels, the far end lost more often, the top
5 % cropped, misses, outliers, smoothing) and the same with 90 % of the hits hidden; ``--degrade FILE`` adds
the degradation measured on the project's own detector (``conf/data/degrade/detector_measured.yaml``). A player-aware model is
scored twice: with the players and without any (``players.csv`` missing: it must still work). Prints one
Markdown table per condition and the CPU time (``time.process_time``).

``--pose-noise FILE`` draws the held-out players with other pose-noise settings (e.g.
``conf/data/pose_noise/movenet_measured.yaml``). ``--rendered CLIP ...`` scores rendered clips (``rally3d synth``)
instead, with the players a real pose backend finds in their video (MoveNet through the players stage, the
poses cached by ``bench/bench_pose_stats.py``) and their true ball track under the same ball conditions.
"""
from __future__ import annotations

import time
from pathlib import Path

import torch

from bench_event_conditions import CONDITIONS as BALL_CONDITIONS  # bench/ is the script's folder
from bench_event_conditions import arg_parser, conditions_of, event_counts

GAPS = BALL_CONDITIONS["real-tracker-like, gaps at contacts"]
CONDITIONS = {
    "annotated ball": None,
    "real-tracker-like, no gaps at contacts": dict(GAPS, p_occlude_near=0.0, p_occlude_far=0.0, p_gap_event=0.0),
    "real-tracker-like, gaps at contacts": GAPS,
}


def rendered(dirs: list[Path], backend: str = "movenet"):
    """Rendered clips as simulated ones (true ball, events, camera) and the players MoveNet finds in them."""
    from bench_pose_stats import players_of

    from training.events.synthetic.simulate import SimClip

    clips, players = [], []
    for d in dirs:
        c, _, pred = players_of(d, backend)
        clips.append(SimClip(f"{d.parent.name}/{d.name}", float(c.info.fps), int(c.info.width), int(c.info.height),
                             c.n_frames, c.read_ball(), c.read_events(gt=True), c.read_camera(gt=True)))
        players.append(pred)
    return clips, players


def main(argv=None) -> None:
    import logging

    from inference.events import EventDetector
    from training.events.synthetic.degrade import DegradeConfig, degrade_all
    from training.events.synthetic.pose_noise import PoseNoiseConfig, noisy_all
    from training.events.synthetic.simulate import simulate_clips

    ap = arg_parser()
    ap.add_argument("--out", type=Path, help="also write the tables here")
    ap.add_argument("--pose-noise", type=Path, help="pose-noise settings (YAML) for the held-out players")
    ap.add_argument("--rendered", nargs="+", type=Path, help="rendered clip folders instead (MoveNet's players)")
    ap.add_argument("--backend", default="movenet", help="with --rendered: the pose backend (movenet@960: larger input)")
    args = ap.parse_args(argv)
    logging.getLogger("inference.events.detector").setLevel(logging.ERROR)  # "model without players" rows
    torch.set_num_threads(1)
    t0 = time.process_time()
    if args.rendered:
        clips, players = rendered(args.rendered, args.backend)
        source = f"{len(clips)} rendered clips, players from {args.backend} and the players stage"
    else:
        clips = simulate_clips(args.sport, args.clips, 6161, args.cache, progress=False, fps=args.fps, players=True)
        cfg = PoseNoiseConfig.from_file(args.pose_noise) if args.pose_noise else PoseNoiseConfig()
        players = noisy_all(clips, 17, cfg)
        source = (f"{len(clips)} held-out simulated rallies (seed 6161) at {args.fps:g} fps, players from pose-backend "
                  f"noise ({args.pose_noise or 'the default settings'})")
    no_players = [None] * len(clips)
    rows = []
    for w in args.weights:
        det = EventDetector.from_checkpoint(None if w == "shipped" else w, sport=args.sport)
        name = "shipped" if w == "shipped" else Path(w).name
        if det.wants_players:
            rows += [(f"{name} (player-aware, with players)", det, players, True),
                     (f"{name} (player-aware, no players)", det, no_players, True)]
        else:
            rows.append((f"{name} (ball only)", det, no_players, True))
    if args.no_bridge_too:
        rows += [(f"{name}, no gap bridging", det, pl, False) for name, det, pl, _ in rows]
    cs = rows[0][1].class_set
    n_found = sum(p is not None and len(p) > 0 for p in players)
    lines = [f"{args.sport}, {source}; every event kept, ±2 frames at 50 fps (scaled); {n_found} clips with players",
             ""]
    for cond, kw in conditions_of(args, CONDITIONS).items():
        tracks = [c.ball for c in clips] if kw is None else degrade_all(clips, 11, DegradeConfig.from_dict(kw))
        lines += [f"**{cond}**", "", "| model | all | " + " | ".join(cs.classes[1:]) + " |", "|---|" + "---|" * cs.n]
        for name, det, pl, bridge in rows:
            s = event_counts(det, clips, tracks, pl, bridge_gaps=bridge).scores
            f1 = [s()["f1"]] + [s(i)["f1"] for i in range(1, cs.n)]
            lines.append(f"| {name} | " + " | ".join(f"{v:.3f}" for v in f1) + " |")
            print(lines[-1], flush=True)
        lines.append("")
    lines.append(f"CPU time {time.process_time() - t0:.1f} s")
    text = "\n".join(lines)
    print("\n" + text)
    if args.out:
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
