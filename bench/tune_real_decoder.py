"""Tune an event model's decoder thresholds on real tracks with hand labels, check them on held-out points,
and write a copy of the model file with them (the network is not touched: it stays trained on simulated
data only).

    .venv/bin/python bench/tune_real_decoder.py --weights MODEL.pth.tar [--out TUNED.pth.tar] [--held-out 50]

Real material (measurement and threshold tuning only, read in place; skips with one line without it):
``$RALLY3D_REAL`` or the development setup's ``shared/real`` beside the checkout — the tennis points
(``tennis_events_rg2025_dev``: a real broadcast tracker's ``ball.csv``, hand-made hit/bounce labels, 50 fps).
The points are taken in name order; the last ``--held-out`` are never tuned on and are reported apart. The
events are those ``rally3d events`` writes (every event kept, the far hits' gap bridging on), scored as
``bench/bench_real.py`` scores them (same class within ±2 frames at 50 fps, one to one, inside
``tracked_window``). Coordinate ascent over the per-class thresholds on the grid the training's decoder
tuning uses (``training.events.evaluate.tune_decoder``), two passes. Prints Markdown; asserts nothing.

Why on real tracks: the decoder tuned on simulated validation rallies takes thresholds the simulated
probabilities like (on the shipped tennis tagger's recipe the far hits' threshold fell to 0.05) while on
a real tracker's tracks the same network's far-hit peaks are placed by the bridge and the outside-the-point
bounces are many; a threshold is three numbers, checked on points it never saw.
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

GRID = (0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
TOL = 2


def load_points(real: Path, det):
    """Per point: the model's reference-rate probabilities, the dense track, the labels and the window."""
    from inference.clipio import Clip
    from inference.events.features import dense_xy

    folder = real / "tennis_events_rg2025_dev"
    out = []
    for d in sorted((p for p in folder.iterdir() if (p / "clip.yaml").is_file()), key=lambda p: p.name):
        clip = Clip(d)
        info = clip.info
        ball, truth = clip.read_ball(), clip.read_events()
        a, b = (int(v) for v in info.extra["tracked_window"])
        probs = det.ref_probs(ball, info.n_frames, info.fps)
        keep = (truth.frame >= a) & (truth.frame <= b)
        out.append({"name": d.name, "fps": float(info.fps), "aspect": info.width / info.height, "probs": probs,
                    "xy": dense_xy(ball, info.n_frames), "gt_f": truth.frame[keep],
                    "gt_c": np.array([det.class_set.encode_label(str(e)) for e in truth.event[keep]], np.int64),
                    "window": (a, b), "n": info.n_frames})
    return out


def events_of(det, point: dict, params) -> tuple[np.ndarray, np.ndarray]:
    """What :meth:`EventDetector.predict` decodes with ``params`` (the far hits bridged), in clip frames."""
    from inference.events.decode import decode
    from inference.events.features import from_ref_frames
    from inference.events.gaps import BridgeParams, bridge_events

    f_ref, cls = decode(point["probs"], det.ref_fps or point["fps"], det.class_set, params)
    frames = np.clip(from_ref_frames(f_ref, point["fps"], det.ref_fps), 0, point["n"] - 1)
    cs = det.class_set
    bp = BridgeParams()
    hit = np.isin(cls, [cs.index(h) for h in cs.rules.hits if h in bp.classes])
    frames, _ = bridge_events(point["xy"], point["fps"], frames, aspect=point["aspect"], params=bp, which=hit)
    return frames, cls


def counts(det, points, params):
    from inference.events.metrics import EventCounts

    c = EventCounts(det.class_set.classes)
    for p in points:
        f, k = events_of(det, p, params)
        a, b = p["window"]
        m = (f >= a) & (f <= b)
        c.add(p["gt_f"], p["gt_c"], f[m], k[m], TOL)
    return c


def tune(det, points, start, passes: int = 2):
    """Coordinate ascent of the per-class thresholds on ``points`` (all-events F1)."""
    params, best = start, counts(det, points, start).scores()["f1"]
    for _ in range(passes):
        for c in range(1, det.class_set.n):
            for v in GRID:
                th = list(params.thresholds)
                th[c] = v
                cand = replace(params, thresholds=tuple(th))
                s = counts(det, points, cand).scores()["f1"]
                if s > best:
                    best, params = s, cand
    return params, best


def row(name: str, det, c) -> str:
    s = c.scores()
    per = " | ".join(f"{c.scores(i)['f1']:.3f}" for i in range(1, det.class_set.n))
    return f"| {name} | {s['prec']:.3f} | {s['recall']:.3f} | **{s['f1']:.3f}** | {per} |"


def main(argv=None) -> int:
    import torch

    from bench_real import real_root
    from inference.events import EventDetector

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--weights", type=Path, required=True, help="the event model file to tune")
    ap.add_argument("--out", type=Path, help="write the model file with the tuned thresholds here")
    ap.add_argument("--held-out", type=int, default=50, help="the last N points: never tuned on")
    args = ap.parse_args(argv)
    real = real_root()
    if not (real / "tennis_events_rg2025_dev").is_dir():
        print(f"tune_real_decoder: no real tennis points under {real} (set RALLY3D_REAL): skipped")
        return 0
    torch.set_num_threads(1)
    t0 = time.process_time()
    det = EventDetector.from_checkpoint(args.weights, sport="tennis")
    points = load_points(real, det)
    tune_on, held = points[:-args.held_out], points[-args.held_out:]
    start = det.decode_params
    tuned, f1 = tune(det, tune_on, start)
    names = " | ".join(det.class_set.classes[1:])
    print(f"\n{args.weights.name}: decoder thresholds tuned on {len(tune_on)} real points "
          f"({tune_on[0]['name']}–{tune_on[-1]['name']}), checked on the last {len(held)}\n")
    print(f"| thresholds (none, {', '.join(det.class_set.classes[1:])}) | P | R | F1 all | {names} |")
    print("|---|---|---|---|" + "---|" * (det.class_set.n - 1))
    for label, params in (("as exported " + str(tuple(start.thresholds)), start), ("tuned " + str(tuple(tuned.thresholds)), tuned)):
        print(row(f"{label}, tuning points", det, counts(det, tune_on, params)))
        print(row(f"{label}, **held-out points**", det, counts(det, held, params)))
        print(row(f"{label}, all {len(points)}", det, counts(det, points, params)))
    if args.out:
        det.decode_params = tuned
        det.meta = {**det.meta, "decode_tuned_on_real": {
            "points": len(tune_on), "held_out": len(held), "f1_tuning": round(float(f1), 4),
            "f1_held_out": round(float(counts(det, held, tuned).scores()["f1"]), 4),
            "thresholds_before": [float(v) for v in start.thresholds],
            "note": "decoder thresholds tuned on a real broadcast tracker's tennis tracks with hand labels "
                    "(bench/tune_real_decoder.py); the network is trained on simulated data only"}}
        det.save(args.out)
        print(f"\nwrote {args.out}")
    print(f"\nCPU {time.process_time() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
