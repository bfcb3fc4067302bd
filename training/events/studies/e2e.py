"""End-to-end figures of the hit-event models: events from the ball that the real detector found (thesis
Table 5.5's "detected ball" row), beside the simulated conditions.

Real detector tracks come from two places, both turned into ``ball.csv`` exactly like ``rally3d infer``
does (the tracker's coasts dropped, then the RTS smoother of :mod:`inference.detection.smooth`):

- ``--infer DIR[=CLIP]``: the output folder of ``rally3d infer CLIP --out DIR --pose none`` (its raw track
  ``DIR/.rally3d/ball_detected.csv``), scored against ``CLIP``'s ground-truth events (``CLIP`` defaults to
  the ``video:`` folder of ``DIR/clip.yaml``);
- ``--heatmaps FOLDER --root DATASET``: the cached WASB probability maps of ``bench/tune_tracker.py``
  (``runs/tune_tracker/<dataset>_<sha>/clip_*.npz``) → candidates → tracker, for the val/test clips of
  ``DATASET`` (no network run).

    python -m training.events.studies.e2e --models inference/weights/hitnet_padel.pth.tar runs/robust.pth.tar \\
        --infer runs/x=datasets/sample/padel_sample \\
        --heatmaps runs/tune_tracker/synth_padel_b11a56f3b97f3932 --root data/synth_padel

Also scores the simulated held-out clips (annotated, :func:`~.simulate.perturb`, :func:`~.degrade.degrade`)
unless ``--no-sim``. Prints Markdown tables (``--out`` writes them).
"""
from __future__ import annotations

import argparse
import pickle
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import yaml

from inference.clipio import BallTrack, Clip, FormatError, Manifest, read_ball_csv
from inference.events.classes import ClassSet
from inference.events.decode import DecodeParams
from inference.events.detector import EventDetector
from inference.events.metrics import EventCounts, format_event_table

from training.events.data.datamodule import EventDataModule, WindowSet
from training.events.synthetic.degrade import DegradeConfig, degrade_all
from training.events.evaluate import (TOLERANCE_NOTE, counts_for, detector_scorer, publish_tables, score_all,
                       tune_decoder)
from training.events.models.rf import ForestScorer
from training.events.synthetic.simulate import SimClip, perturb

CLASS_SET = ClassSet.load("padel6")


@dataclass
class RealClip:
    """A rendered clip with its ground truth (``sim``: annotated ball, gt events, gt camera) and the
    ``detected`` track the pipeline would write to ``ball.csv``."""

    sim: SimClip
    detected: BallTrack
    source: str


def pipeline_ball(raw: BallTrack, width: int, height: int, fps: float) -> BallTrack:
    """The pipeline's smooth stage: coasts (visibility 3) withdrawn, then the RTS smoother."""
    from inference.detection.smooth import smooth_track

    coasted = raw.visibility == 3
    xy = raw.xy.copy()
    xy[coasted] = np.nan
    measured = BallTrack(raw.frame, np.where(coasted, 0, raw.visibility).astype(np.int8), xy)
    return smooth_track(measured, width, height, fps).track


def clips_from_folder_single(path: Path) -> list[SimClip]:
    clip = Clip(path)
    info = clip.info
    ball = clip.read_ball(n_frames=info.n_frames) if info.n_frames else clip.read_ball()
    n = info.n_frames or int(ball.frame[-1]) + 1
    gt = clip.gt_dir / "events.csv"
    if not gt.is_file() and not clip.events_path.is_file():
        raise FileNotFoundError(f"{path}: no gt/events.csv or events.csv to score against")
    events = clip.read_events(gt=gt.is_file())
    camera = None
    for g in (True, False):
        try:
            camera = clip.read_camera(gt=g)
            break
        except (FileNotFoundError, OSError, FormatError):
            continue
    return [SimClip(str(clip.root), float(info.fps), int(info.width), int(info.height), n, ball, events, camera)]


def dense(track: BallTrack, n: int) -> BallTrack:
    """One row per frame 0..n-1 (missing rows: visibility 0, NaN)."""
    vis = np.zeros(n, np.int8)
    xy = np.full((n, 2), np.nan)
    keep = (track.frame >= 0) & (track.frame < n)
    vis[track.frame[keep]] = track.visibility[keep]
    xy[track.frame[keep]] = track.xy[keep]
    return BallTrack(np.arange(n), vis, xy)


def from_infer_dir(spec: str) -> RealClip:
    """``DIR[=CLIP]``: the raw detector track of a ``rally3d infer`` output folder and its source clip."""
    out, _, src = spec.partition("=")
    out = Path(out)
    raw_path = out / ".rally3d" / "ball_detected.csv"
    if not raw_path.is_file():
        raise FileNotFoundError(f"{raw_path} not found: run `rally3d infer CLIP --out {out} --pose none` first")
    if not src:
        meta = yaml.safe_load((out / "clip.yaml").read_text())
        src = str((out / meta["video"]).resolve().parent)
    sim = clips_from_folder_single(Path(src))[0]
    raw = read_ball_csv(raw_path)
    return RealClip(sim, dense(pipeline_ball(raw, sim.width, sim.height, sim.fps), sim.n_frames), str(out))


def from_heatmaps(folder: Path, root: Path, splits=("val", "test")) -> list[RealClip]:
    """The val/test clips of ``root`` through their cached WASB maps, the shipped runner's post-processing
    and tracker, and the pipeline's smoother."""
    from inference.detection.detect import BallDetectorRunner
    from inference.detection.geometry import Letterbox
    from inference.detection.postprocess import heatmaps_to_candidates
    from inference.detection.tracker import track_candidates

    defaults = BallDetectorRunner(torch.nn.Identity())
    out = []
    for split in splits:
        for path in Manifest.load(root).paths(split):
            file = Path(folder) / f"{path.name}.npz"
            if not file.is_file():
                raise FileNotFoundError(f"{file} not found: cache the maps with `python bench/tune_tracker.py "
                                        f"--root {root}`")
            sim = clips_from_folder_single(path)[0]
            with np.load(file) as z:
                maps = z["maps"].astype(np.float32)
            lb = Letterbox(sim.width, sim.height, maps.shape[2], maps.shape[1])
            cands = heatmaps_to_candidates(maps, lb, defaults.postprocess)
            tracked = track_candidates(cands, sim.fps, defaults.tracker, (sim.width, sim.height))
            raw = tracked.to_ball_track(sim.width, sim.height)
            out.append(RealClip(sim, dense(pipeline_ball(raw, sim.width, sim.height, sim.fps), sim.n_frames),
                                f"{root.name}/{path.name} ({split})"))
    return out


def track_quality(rc: RealClip, tau_px: float = 10.0) -> tuple[float, float]:
    """Recall and precision of the detected track against the annotated ball (within ``tau_px`` pixels)."""
    gt, det = rc.sim.ball, dense(rc.detected, rc.sim.n_frames)
    g = dense(gt, rc.sim.n_frames)
    size = np.array([rc.sim.width, rc.sim.height], float)
    seen_g = g.visibility > 0
    seen_d = det.visibility > 0
    err = np.linalg.norm((det.xy - g.xy) * size, axis=1)
    good = seen_g & seen_d & (err <= tau_px)
    return good.sum() / max(seen_g.sum(), 1), good.sum() / max(seen_d.sum(), 1)


@dataclass
class Entry:
    """One model of the table: a scorer with its tuned decoder."""

    name: str
    scorer: object
    params: DecodeParams
    ref_fps: float | None


def entry_of(path: Path) -> Entry:
    det = EventDetector.from_checkpoint(path)
    return Entry(model_name(path, det), detector_scorer(det), det.decode_params, det.ref_fps)


def forest_entries(dm: EventDataModule, cache: Path | None = None) -> list[Entry]:
    """The thesis's random forest trained on clean windows and on degraded windows, each with its decoder
    tuned on the clean + degraded validation clips (pickled to ``cache`` when given, reused if there)."""
    if cache is not None and Path(cache).is_file():
        with open(cache, "rb") as fh:
            return pickle.load(fh)
    val, val_tracks = dm.tuning_clips()
    out = []
    for name, split in (("random forest, clean training tracks", "clean"),
                        ("random forest, degraded training tracks", "degraded")):
        clips = dm.labelled("train") if split == "clean" else dm.degraded("train", 0)
        forest = ForestScorer(dm.features, dm.class_set.n, dm.window, dm.last_k, "padel")
        forest.fit(WindowSet(clips, dm.window, dm.last_k))
        params, _ = tune_decoder(score_all(forest, val, val_tracks, desc="rf val"), val, dm.class_set,
                                 dm.features.ref_fps, DecodeParams(thresholds=0.5), passes=1)
        out.append(Entry(name, forest, params, dm.features.ref_fps))
    if cache is not None:
        Path(cache).parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(cache).with_suffix(".tmp")
        with open(tmp, "wb") as fh:
            pickle.dump(out, fh)
        tmp.replace(cache)
    return out


def counts_of(e: Entry, sims: list[SimClip], tracks) -> EventCounts:
    probs = score_all(e.scorer, sims, tracks, desc=e.name[:20])
    return counts_for(probs, sims, CLASS_SET, e.ref_fps, e.params)


def real_counts(e: Entry, clips: list[RealClip], detected: bool) -> EventCounts:
    tracks = [c.detected if detected else dense(c.sim.ball, c.sim.n_frames) for c in clips]
    return counts_of(e, [c.sim for c in clips], tracks)


def model_name(path: Path, det: EventDetector) -> str:
    h = det.net.hparams if det.net is not None else {}
    arch = f"HitNet {h.get('layers')}×{h.get('hidden')}{' bi' if h.get('bidirectional') else ''}" if h else det.kind
    return f"{arch} ({path})"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", nargs="+", type=Path, required=True, help="exported hit-event model files")
    ap.add_argument("--infer", nargs="*", default=[], help="rally3d infer output folders, DIR or DIR=CLIP")
    ap.add_argument("--heatmaps", type=Path, help="cached WASB maps folder (bench/tune_tracker.py)")
    ap.add_argument("--root", type=Path, help="the dataset of --heatmaps (manifest.yaml)")
    ap.add_argument("--no-sim", action="store_true", help="skip the simulated held-out clips")
    ap.add_argument("--n-test", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1234)
    ap.add_argument("--cache-dir", default="data/events_cache")
    ap.add_argument("--rf", action="store_true", help="also the random forest, trained on clean and on degraded "
                    "tracks (the simulated train split; a few minutes)")
    ap.add_argument("--rf-cache", type=Path, help="pickle of the fitted forests (reused when present)")
    ap.add_argument("--out", type=Path, help="also write the tables (markdown) here")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    if args.heatmaps and not args.root:
        ap.error("--heatmaps needs --root DATASET")
    real = [from_infer_dir(s) for s in args.infer]
    if args.heatmaps:
        real += from_heatmaps(args.heatmaps, args.root)
    dm = EventDataModule(sport="padel", class_set="padel6", n_train=1000, n_val=100, n_test=args.n_test,
                         seed=args.seed, cache_dir=args.cache_dir, window=24, degrade={"p_clean": 0.2},
                         features={"ref_fps": 50, "velocity": True, "velocity_scale": 100})
    entries = [entry_of(p) for p in args.models] + (forest_entries(dm, args.rf_cache) if args.rf else [])
    sections = []
    if real:
        lines = ["| real clip | fps | detected-ball recall | precision (≤ 10 px) | #gt events |", "|---|---|---|---|---|"]
        for rc in real:
            r, p = track_quality(rc)
            lines.append(f"| {rc.source} | {rc.sim.fps:g} | {r:.2f} | {p:.2f} | {len(rc.sim.events)} |")
        sections.append("\n".join(lines))
        for detected, what in ((False, "annotated ball"), (True, "**detected ball** (real detector → tracker → "
                                                             "coasts dropped → RTS smoother, as `rally3d infer`)")):
            rows = [(e.name, real_counts(e, real, detected)) for e in entries]
            sections.append(format_event_table(rows, title=f"**padel, {len(real)} rendered clips, {what}**, "
                                               + TOLERANCE_NOTE))
    if not args.no_sim:
        test = [c.sim for c in dm.labelled("test")]
        rng = np.random.default_rng(7)
        conditions = (("annotated ball", None), ("detector-like ball (`perturb`)", [perturb(c, rng) for c in test]),
                      ("pipeline-like ball (`degrade`, every clip)", degrade_all(test, 7, DegradeConfig(p_clean=0.0))))
        for what, tracks in conditions:
            rows = [(e.name, counts_of(e, test, tracks)) for e in entries]
            sections.append(format_event_table(rows, title=f"**padel, {len(test)} held-out simulated clips, {what}**, "
                                               + TOLERANCE_NOTE))
    publish_tables(sections, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
