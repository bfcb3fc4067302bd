"""Score a pipeline result against a reference clip (hand annotations or synthetic ground truth).

Three figures, each only where the reference has the data:
* 2D ball: F1 / precision / recall at τ = 10 px at 1280 px width (scaled), against ``ball.csv``;
* events: event-set F1 of the fine-grained labels at ±2 frames at 50 fps (scaled), against ``gt/events.csv`` or
  ``events.csv``;
* 3D: mean and median distance to ``gt/ball_3d.csv`` over the frames both have.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from inference.clipio import EVENT_LABELS, Clip


@dataclass
class Scores:
    """Scores of one clip; NaN where the reference lacks the data or the result is missing."""

    ball_f1: float = float("nan")
    ball_precision: float = float("nan")
    ball_recall: float = float("nan")
    tau_px: float = float("nan")
    events_f1: float = float("nan")
    events_recall: float = float("nan")
    events_precision: float = float("nan")
    events_tol: int = 0
    mae_m: float = float("nan")
    medae_m: float = float("nan")
    frames_3d: int = 0

    def lines(self) -> list[str]:
        out = []
        if self.ball_f1 == self.ball_f1:
            out.append(f"2D ball   F1 {self.ball_f1:.3f}  precision {self.ball_precision:.3f}  "
                       f"recall {self.ball_recall:.3f}  (τ = {self.tau_px:.1f} px)")
        if self.events_f1 == self.events_f1:
            out.append(f"events    F1 {self.events_f1:.3f}  precision {self.events_precision:.3f}  "
                       f"recall {self.events_recall:.3f}  (±{self.events_tol} frames, fine-grained labels)")
        if self.frames_3d:
            out.append(f"3D ball   MAE {self.mae_m:.3f} m  MedAE {self.medae_m:.3f} m  over {self.frames_3d} frames")
        return out


def _ref(clip: Clip, name: str) -> bool:
    return (clip.root / name).is_file()


def score(result: Clip, reference: Clip) -> Scores:
    """Compare ``result``'s ball.csv, events.csv and ball_3d.csv with ``reference`` (see module docstring)."""
    from inference.detection.metrics import evaluate_ball_tracks
    from inference.events.metrics import EventCounts, tolerance_frames

    s = Scores()
    info = result.info
    if _ref(reference, "ball.csv") and result.ball_path.is_file():
        s.tau_px = 10.0 * info.width / 1280.0
        rep = evaluate_ball_tracks(result.read_ball(), reference.read_ball(), info.width, info.height,
                                   tau_px=s.tau_px)
        s.ball_f1, s.ball_precision, s.ball_recall = rep.f1, rep.precision, rep.recall
    gt_events = "gt/events.csv" if _ref(reference, "gt/events.csv") else "events.csv"
    if _ref(reference, gt_events) and result.events_path.is_file():
        gt = reference.read_events(gt=gt_events.startswith("gt/"))
        pred = result.read_events()
        classes = ("none", *EVENT_LABELS)
        index = {c: i for i, c in enumerate(classes)}
        counts = EventCounts(classes)
        s.events_tol = tolerance_frames(info.fps)
        counts.add(gt.frame, [index[e] for e in gt.event], pred.frame, [index[e] for e in pred.event], s.events_tol)
        sc = counts.scores()
        s.events_f1, s.events_recall, s.events_precision = sc["f1"], sc["recall"], sc["prec"]
    if _ref(reference, "gt/ball_3d.csv") and result.ball_3d_path.is_file():
        gt3 = reference.read_ball_3d(gt=True)
        b = result.read_ball_3d()
        i = np.searchsorted(gt3.frame, b.frame)
        ok = (i < len(gt3.frame)) & (gt3.frame[np.minimum(i, len(gt3.frame) - 1)] == b.frame)
        err = np.linalg.norm(b.xyz[ok] - gt3.xyz[i[ok]], axis=1)
        err = err[np.isfinite(err)]
        if len(err):
            s.mae_m, s.medae_m, s.frames_3d = float(err.mean()), float(np.median(err)), int(len(err))
    return s
