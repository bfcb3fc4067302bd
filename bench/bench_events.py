"""Frames/s of each hit-event detector on this CPU (features + model + decoding, whole clips).

    .venv/bin/python bench/bench_events.py [--clips 20] [--threads 1]

HitNet and tagger rows use the shipped padel models when present (the player-aware ones without players:
the same cost) plus untrained networks of the sweep's sizes
(speed does not depend on the weights); the random forest is fitted on a small simulated set first.
Frames are the clips' own frames (25–60 fps), so frames/s compares with a video's frame rate.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from inference.events import ClassSet, DecodeParams, EventDetector, FeatureConfig, HitNet, PhysicsParams
from inference.events.detector import PLAYER_WEIGHTS, WEIGHTS_DIR, ball_only_weights


def timed(fn, clips) -> float:
    t0 = time.perf_counter()
    for c in clips:
        fn(c)
    return sum(c.n_frames for c in clips) / (time.perf_counter() - t0)


def main() -> None:
    from training.events.data.datamodule import WindowSet, label_clips
    from training.events.models.rf import ForestScorer
    from training.events.synthetic.simulate import simulate_clips

    ap = argparse.ArgumentParser()
    ap.add_argument("--clips", type=int, default=20)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    cs, fc = ClassSet.load("padel6"), FeatureConfig()
    clips = simulate_clips("padel", args.clips, seed=99, progress=False)
    dets: list[tuple[str, EventDetector]] = []
    for path in (ball_only_weights("padel"), WEIGHTS_DIR / "hitnet_padel_players.pth.tar", WEIGHTS_DIR / PLAYER_WEIGHTS["padel"]):
        if path.is_file():  # the player-aware ones run here without players (same cost)
            det = EventDetector.from_checkpoint(path)
            dets.append((f"{'tagger' if det.kind == 'tagger' else 'HitNet'} shipped ({path.name})", det))
    for layers, hidden in ((1, 16), (2, 64), (4, 128)):
        net = HitNet(fc.n_features, cs.n, hidden, layers, True)
        dets.append((f"HitNet {layers}×{hidden} bi (untrained)", EventDetector("hitnet", cs, fc, DecodeParams(), net=net)))
    dets.append(("physics-aware", EventDetector("physics", cs, FeatureConfig(velocity=False), DecodeParams(0.3),
                                                physics=PhysicsParams())))
    rows = []
    for name, det in dets:
        fps = timed(lambda c, d=det: d.predict(c.ball, c.fps, c.width, c.height, camera=c.camera, n_frames=c.n_frames),
                    clips)
        rows.append((name, fps))
    train = simulate_clips("padel", 40, seed=98, progress=False)
    forest = ForestScorer(fc, cs.n, 12, 6, "padel", n_estimators=200).fit(WindowSet(label_clips(train, cs, fc), 12, 6))
    from inference.events.decode import decode

    rows.append(("random forest (200 trees)", timed(lambda c: decode(forest(c, c.ball), 50.0, cs, DecodeParams()), clips)))
    n = sum(c.n_frames for c in clips)
    print(f"\n{len(clips)} simulated padel clips, {n} frames, torch threads {args.threads}\n")
    print("| detector | frames/s |\n|---|---|")
    for name, fps in rows:
        print(f"| {name} | {fps:,.0f} |")


if __name__ == "__main__":
    main()
