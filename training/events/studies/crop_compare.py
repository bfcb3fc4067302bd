"""Compare the crop hit-event model with the ball-only ones on the held-out **rendered** clips of a dataset
folder (default ``data/synth_padel``, split ``test``), with three ball tracks: annotated (``ball.csv``),
detector-like (the annotated track perturbed as in :func:`.simulate.perturb`, seed 7) and, where cached,
the real detector (WASB probability maps cached by ``bench/tune_tracker.py`` under ``runs/tune_tracker``
→ candidates → our tracker, detections only).

    .venv/bin/python -m training.events.studies.crop_compare --crop inference/weights/hitnet_crop_padel.pth.tar \
        --out runs/crop_compare.md

Every model runs its runtime path (``EventDetector.ref_probs``; crop models stream the clip's frames and
cut crops around the given track). Decoders: as stored in each model file, and for the ball-only HitNet
also re-tuned on the same rendered validation clips the crop model was tuned on. The random forest is
trained on simulated rallies (``--rf-train`` clips, as ``training.events.studies.compare``).
"""
from __future__ import annotations

import argparse
import hashlib
import sys
from copy import deepcopy
from pathlib import Path

import numpy as np
import torch

from inference.clipio import BallTrack
from inference.events.classes import ClassSet
from inference.events.decode import DecodeParams
from inference.events.detector import EventDetector
from inference.events.metrics import format_event_table

from training.events.models.crop_run import frames_scorer
from training.events.data.datamodule import clips_from_folder
from training.events.evaluate import TOLERANCE_NOTE, counts_for, publish_tables, score_all, tune_decoder
from training.events.synthetic.simulate import SimClip, perturb

ROOT = Path(__file__).resolve().parents[3]


def detector_track(sim: SimClip, cache: Path) -> BallTrack | None:
    """The shipped WASB detector + our tracker on ``sim`` from cached probability maps (None if not cached)."""
    from inference.detection.detect import SHIPPED
    from inference.detection.geometry import Letterbox
    from inference.detection.postprocess import PostprocessConfig, heatmaps_to_candidates
    from inference.detection.tracker import TrackerConfig, track_candidates

    weights = Path(SHIPPED["wasb"])
    if not weights.is_file():
        return None
    key = hashlib.sha256(weights.read_bytes()).hexdigest()[:16]
    root = Path(sim.name)
    file = cache / f"{root.parent.name}_{key}" / f"{root.name}.npz"
    if not file.is_file():
        return None
    with np.load(file) as z:
        maps = z["maps"].astype(np.float32)
    lb = Letterbox(sim.width, sim.height, maps.shape[2], maps.shape[1])
    cands = heatmaps_to_candidates(maps, lb, PostprocessConfig())
    result = track_candidates(cands, sim.fps, TrackerConfig(), (sim.width, sim.height))
    return result.to_ball_track(sim.width, sim.height, coast_visibility=0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", type=Path, default=ROOT / "data" / "synth_padel")
    ap.add_argument("--split", default="test", help="split of --root to evaluate, or 'all'")
    ap.add_argument("--val-root", type=Path, help="dataset whose val split re-tunes HitNet's decoder (default --root)")
    ap.add_argument("--crop", nargs="*", type=Path, default=[], help="crop model files")
    ap.add_argument("--hitnet", nargs="+", type=Path, default=[ROOT / "inference" / "weights" / "hitnet_padel.pth.tar"],
                    help="ball-only HitNet model files")
    ap.add_argument("--retune", action="store_true", help="also HitNet with its decoder re-tuned on the val clips")
    ap.add_argument("--rf-train", type=int, default=1000, help="simulated clips for the random forest (0: none)")
    ap.add_argument("--detector-cache", type=Path, default=ROOT / "runs" / "tune_tracker")
    ap.add_argument("--out", type=Path, help="also write the tables (markdown) here")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    if not (args.root / "manifest.yaml").is_file():
        raise SystemExit(f"no manifest.yaml in {args.root}: render it with "
                         "rally3d synth --sport padel --clips 24 --out data/synth_padel --seed 10")
    splits = ("train", "val", "test") if args.split == "all" else (args.split,)
    test = [c for s in splits for c in clips_from_folder(args.root, s)]
    val = clips_from_folder(args.val_root or args.root, "val")
    entries = []  # (name, scorer, decode params, ref fps)
    for path in args.hitnet:
        hit = EventDetector.from_checkpoint(path)
        entries.append((f"HitNet ball-only ({path.name})", frames_scorer(hit), hit.decode_params, hit.ref_fps))
        if args.retune:
            tuned = deepcopy(hit)
            tuned.decode_params, _ = tune_decoder(score_all(frames_scorer(hit), val, desc="hitnet val"), val,
                                                  hit.class_set, hit.ref_fps, hit.decode_params)
            entries.append((f"HitNet ball-only ({path.name}, decoder tuned on rendered val)", frames_scorer(tuned),
                            tuned.decode_params, hit.ref_fps))
    class_set: ClassSet = hit.class_set
    if args.rf_train:
        from training.events.data.datamodule import EventDataModule, WindowSet
        from training.events.models.rf import ForestScorer

        dm = EventDataModule(sport=class_set.sport, class_set=class_set.name, n_train=args.rf_train, n_val=100,
                             n_test=200, seed=1234, cache_dir=str(ROOT / "data" / "events_cache"),
                             features=hit.features.to_dict(), window=hit.window, last_k=hit.last_k)
        forest = ForestScorer(dm.features, class_set.n, dm.window, dm.last_k, class_set.sport)
        forest.fit(WindowSet(dm.labelled("train"), dm.window, dm.last_k))
        sim_val = [c.sim for c in dm.labelled("val")]
        params, _ = tune_decoder(score_all(forest, sim_val, desc="rf val"), sim_val, class_set, dm.features.ref_fps,
                                 DecodeParams(thresholds=0.5), passes=1)
        entries.append(("random forest (thesis baseline, simulated training)", forest, params, dm.features.ref_fps))
    for path in args.crop:
        det = EventDetector.from_checkpoint(path)
        if det.kind != "crop":
            raise SystemExit(f"{path} is a {det.kind} model, not a crop model")
        init = "warm-started from HitNet" if det.meta.get("init_from") else "from scratch"
        entries.append((f"HitNet + ball crops ({path.name}, {init})", frames_scorer(det), det.decode_params,
                        det.ref_fps))
    tracks = {"annotated ball positions": [c.ball for c in test]}
    rng = np.random.default_rng(7)
    tracks["detector-like ball positions"] = [perturb(c, rng) for c in test]
    det_tracks = [detector_track(c, args.detector_cache) for c in test]
    if all(t is not None for t in det_tracks):
        tracks["WASB detector + tracker ball positions"] = det_tracks
    else:
        print(f"no cached detector maps under {args.detector_cache} for every {args.split} clip "
              "(run bench/tune_tracker.py): skipping the detector rows", file=sys.stderr)
    n_events = sum(len(c.events) for c in test)
    sections = []
    for mode, trs in tracks.items():
        rows = []
        for name, scorer, params, ref_fps in entries:
            probs = score_all(scorer, test, trs, desc=name[:20])
            rows.append((name, counts_for(probs, test, class_set, ref_fps, params)))
        sections.append(format_event_table(rows, title=f"**{class_set.sport}, {len(test)} held-out rendered clips "
                                           f"of {args.root.name} ({args.split}, {n_events} events), {mode}**, "
                                           + TOLERANCE_NOTE))
    publish_tables(sections, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
