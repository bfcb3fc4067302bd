"""The comparison table of the hit-event detectors (README "Hit events"): on the same held-out simulated
clips, with annotated and with detector-like ball positions, the random forest of the thesis, the
HitNet model files given, and the physics-aware detector — each with its decoder tuned on the same
validation clips.

    python -m training.events.studies.compare --sport padel --models inference/weights/hitnet_padel.pth.tar \
        --out docs/events_padel_table.md

The clips are those of ``python train.py +experiment=hitnet_<sport>`` (same seeds and counts, read from
the simulation cache ``data/events_cache``).
"""
from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from inference.events.decode import DecodeParams
from inference.events.detector import EventDetector
from inference.events.metrics import format_event_table
from inference.events.physics import PhysicsParams

from training.events.data.datamodule import EventDataModule, WindowSet
from training.events.evaluate import TOLERANCE_NOTE, counts_for, detector_scorer, publish_tables, score_all, tune_decoder
from training.events.models.rf import ForestScorer
from training.events.synthetic.simulate import perturb


def tuned_physics(dm: EventDataModule, val) -> EventDetector:
    """The physics detector with its speed-ratio and decoder parameters tuned on validation clips."""
    best, best_det = -1.0, None
    for hit_ratio in (1.1, 1.25, 1.5):
        det = EventDetector("physics", dm.class_set, replace(dm.features, velocity=False),
                            DecodeParams(thresholds=0.3), physics=PhysicsParams(hit_ratio=hit_ratio))
        probs = score_all(detector_scorer(det), val, desc="physics val")
        det.decode_params, f1 = tune_decoder(probs, val, dm.class_set, det.ref_fps, det.decode_params, passes=1)
        if f1 > best:
            best, best_det = f1, det
    return best_det


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sport", default="padel", choices=["padel", "tennis"])
    ap.add_argument("--models", nargs="*", default=[], type=Path, help="exported HitNet model files")
    ap.add_argument("--n-train", type=int, default=1000)
    ap.add_argument("--n-val", type=int, default=100)
    ap.add_argument("--n-test", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1234, help="the experiment's seed (data seeds 10·seed + 0/1/2)")
    ap.add_argument("--cache-dir", default="data/events_cache")
    ap.add_argument("--max-test", type=int, help="use only the first N test clips (speed)")
    ap.add_argument("--no-rf", action="store_true")
    ap.add_argument("--out", type=Path, help="also write the tables (markdown) here")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    class_set = {"padel": "padel6", "tennis": "tennis4"}[args.sport]
    dm = EventDataModule(sport=args.sport, class_set=class_set, n_train=args.n_train, n_val=args.n_val,
                         n_test=args.n_test, seed=args.seed, cache_dir=args.cache_dir,
                         on_unmapped="error" if args.sport == "padel" else "warn")
    val = [c.sim for c in dm.labelled("val")]
    test = [c.sim for c in dm.labelled("test")][: args.max_test or None]
    rng = np.random.default_rng(7)
    e2e_tracks = [perturb(c, rng) for c in test]
    entries = []  # (name, scorer, decode params, ref fps)
    if not args.no_rf:
        forest = ForestScorer(dm.features, dm.class_set.n, dm.window, dm.last_k, args.sport)
        forest.fit(WindowSet(dm.labelled("train"), dm.window, dm.last_k))
        params, _ = tune_decoder(score_all(forest, val, desc="rf val"), val, dm.class_set, dm.features.ref_fps,
                                 DecodeParams(thresholds=0.5), passes=1)
        entries.append(("random forest (thesis baseline)", forest, params, dm.features.ref_fps))
    for path in args.models:
        det = EventDetector.from_checkpoint(path)
        h = det.net.hparams
        name = f"HitNet {h['layers']}×{h['hidden']}{' bi' if h['bidirectional'] else ' uni'} ({path.name})"
        entries.append((name, detector_scorer(det), det.decode_params, det.ref_fps))
    phys = tuned_physics(dm, val)
    entries.append(("physics-aware (kinks + line of sight)", detector_scorer(phys), phys.decode_params, phys.ref_fps))
    sections = []
    for mode, tracks in (("annotated ball positions", None), ("detector-like ball positions", e2e_tracks)):
        rows = []
        for name, scorer, params, ref_fps in entries:
            probs = score_all(scorer, test, tracks, desc=name[:20])
            rows.append((name, counts_for(probs, test, dm.class_set, ref_fps, params)))
        sections.append(format_event_table(rows, title=f"**{args.sport}, {len(test)} held-out simulated clips, "
                                           f"{mode}**, {TOLERANCE_NOTE}"))
    publish_tables(sections, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
