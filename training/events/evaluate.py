"""Decoder tuning, temperature calibration and the event-set evaluation of any per-frame scorer.

A *scorer* maps a :class:`SimClip` (ball track, fps, camera) to ``(T', C)`` probabilities at the
reference rate; the HitNet, the random forest and the physics detector are all scorers, so they share
the decoder, its tuning on validation data and the evaluation tables.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
import torch
from tqdm import tqdm

from inference.clipio import BallTrack, atomic_write_text
from inference.events.classes import ClassSet
from inference.events.decode import DecodeParams, decode
from inference.events.detector import EventDetector
from inference.events.features import FeatureConfig, from_ref_frames, to_ref_frames
from inference.events.metrics import EventCounts, tolerance_frames

from training.events.synthetic.simulate import SimClip

Scorer = Callable[[SimClip, BallTrack], np.ndarray]


def gt_classes(sim: SimClip, class_set: ClassSet, on_unmapped: str = "warn") -> tuple[np.ndarray, np.ndarray]:
    """Ground-truth events as (frames, class indices) in clip frames (unmapped labels dropped)."""
    y = class_set.encode(sim.events, sim.n_frames, on_unmapped=on_unmapped, where=sim.name)
    f = np.flatnonzero(y)
    return f, y[f]


def score_all(scorer: Scorer, clips: Sequence[SimClip], tracks: Sequence[BallTrack] | None = None,
              desc: str = "scoring") -> list[np.ndarray]:
    tracks = tracks or [c.ball for c in clips]
    return [scorer(c, t) for c, t in tqdm(list(zip(clips, tracks)), desc=desc, leave=False)]


def counts_for(probs: Sequence[np.ndarray], clips: Sequence[SimClip], class_set: ClassSet, ref_fps: float | None,
               params: DecodeParams, tol_at_50: float = 2.0) -> EventCounts:
    """Decode every clip and count matches in clip frames (tolerance scaled with each clip's fps)."""
    counts = EventCounts(class_set.classes)
    for p, sim in zip(probs, clips):
        f_ref, cls = decode(p, ref_fps or sim.fps, class_set, params)
        f = np.clip(from_ref_frames(f_ref, sim.fps, ref_fps), 0, sim.n_frames - 1)
        gf, gc = gt_classes(sim, class_set)
        counts.add(gf, gc, f, cls, tolerance_frames(sim.fps, tol_at_50))
    return counts


def tune_decoder(probs: Sequence[np.ndarray], clips: Sequence[SimClip], class_set: ClassSet, ref_fps: float | None,
                 base: DecodeParams | None = None, tol_at_50: float = 2.0, grid=None,
                 passes: int = 2) -> tuple[DecodeParams, float]:
    """Coordinate ascent on validation F1 over per-class thresholds, the peak radius and the shift."""
    C = class_set.n
    params = base or DecodeParams(thresholds=tuple([0.5] * C))
    if np.ndim(params.thresholds) == 0:
        params = replace(params, thresholds=tuple([float(params.thresholds)] * C))
    grid = grid or [0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9]

    def f1(p: DecodeParams) -> float:
        s = counts_for(probs, clips, class_set, ref_fps, p, tol_at_50).scores()["f1"]
        return -1.0 if np.isnan(s) else s

    best = f1(params)
    for _ in range(passes):
        for c in range(1, C):
            for v in grid:
                th = list(params.thresholds)
                th[c] = v
                cand = replace(params, thresholds=tuple(th))
                s = f1(cand)
                if s > best:
                    best, params = s, cand
        for field, values in (("shift", [-2, -1, 0, 1, 2]), ("peak_radius", [2, 3, 4, 6, 8]), ("min_gap", [1, 2, 3])):
            for v in values:
                cand = replace(params, **{field: v})
                s = f1(cand)
                if s > best:
                    best, params = s, cand
    return params, best


def fit_temperature(logits: torch.Tensor, labels: torch.Tensor, iters: int = 200) -> float:
    """Temperature T in [0.05, 20] minimising the NLL of ``softmax(logits / T)`` on validation windows; 1.0
    (with a warning) when the fit does not converge to a finite value (e.g. a few windows of one class)."""
    import warnings

    lo, hi = float(np.log(0.05)), float(np.log(20.0))
    log_t = torch.zeros(1, requires_grad=True)
    opt = torch.optim.LBFGS([log_t], lr=0.1, max_iter=iters)
    loss_fn = torch.nn.CrossEntropyLoss()

    def closure():
        opt.zero_grad()
        loss = loss_fn(logits / log_t.clamp(lo, hi).exp(), labels)
        loss.backward()
        return loss

    opt.step(closure)
    t = float(np.clip(np.exp(float(log_t.detach())), 0.05, 20.0))  # in float64: the bounds hold exactly
    if not np.isfinite(t):
        warnings.warn("the temperature fit did not converge on the validation windows: temperature 1.0", stacklevel=2)
        return 1.0
    return t


def detector_scorer(det: EventDetector) -> Scorer:
    """A scorer from a runtime detector (HitNet or physics); player-aware models read ``sim.players``."""
    return lambda sim, track: det.ref_probs(track, sim.n_frames, sim.fps, camera=sim.camera,
                                            players=getattr(sim, "players", None))


def labels_at_ref(sim: SimClip, class_set: ClassSet, features: FeatureConfig, n_ref: int) -> np.ndarray:
    f, c = gt_classes(sim, class_set)
    y = np.zeros(n_ref, np.int64)
    y[np.clip(to_ref_frames(f, sim.fps, features.ref_fps), 0, n_ref - 1)] = c
    return y


TOLERANCE_NOTE = "tolerance ±2 frames at 50 fps (±1 at 25/30 fps, ±2 at 60)"


def publish_tables(sections: Sequence[str], out=None) -> str:
    """Join comparison tables, print them, and write them atomically to ``out`` if given; returns the text."""
    text = "\n\n".join(sections)
    print(text)
    if out:
        atomic_write_text(out, text + "\n")
    return text
