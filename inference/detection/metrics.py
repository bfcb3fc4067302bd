"""Frame-level ball-detection metrics as in WASB-SBDT's evaluator, with τ and its space explicit.

Each frame with a ground-truth row gets one outcome:

========================  ==========================  =======
ground truth              prediction                  outcome
========================  ==========================  =======
visible                   visible, distance ``< τ``   TP
visible                   visible, distance ``≥ τ``   FP1
visible                   none                        FN
not visible               visible                     FP2
not visible               none                        TN
========================  ==========================  =======

"Visible" in the ground truth means a visibility code in ``visible_flags`` (default ``{1, 2}``, WASB's
tennis setting, so 0 and 3 count as absent); codes in ``ignore_flags`` (e.g. ``{3}``, occluded) drop
the frame, and frames without a ground-truth row are ignored. τ is in **original-frame pixels**
(WASB: 4 px; the thesis: 10 px at 1280×720; TrackNetV2/V3 measure at 512×288 instead).

Summary: precision = TP / (TP + FP1 + FP2), recall = TP / (TP + FN), accuracy = (TP + TN) / all,
RMSE over the TP + FP1 frames, and AP: predicted-visible frames ranked by score, label 1 only for TP,
recall over TP + FN, the best precision per recall value, AP = Σ Δr · p.

Example:
    >>> r = evaluate_detections([True, True, False], [[0, 0], [9, 0], [0, 0]], [0.9, 0.8, 0.0],
    ...                         [1, 1, 0], [[1, 0], [0, 0], [0, 0]], tau_px=4)
    >>> r.counts
    DetectionCounts(tp=1, fp1=1, fp2=0, fn=0, tn=1)
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import numpy as np

from inference.clipio.tables import BallTrack

DEFAULT_VISIBLE_FLAGS: frozenset[int] = frozenset({1, 2})
"""Ground-truth visibility codes that count as "ball visible" (WASB tennis ``visible_flags``)."""


class Outcome(IntEnum):
    """Per-frame outcome codes; ``IGNORED`` marks frames without (usable) ground truth."""

    IGNORED = -1
    TP = 0
    FP1 = 1
    FP2 = 2
    FN = 3
    TN = 4


# ------------------------------------------------------------------------------------------- counts
@dataclass(frozen=True)
class DetectionCounts:
    """Frame counts of the five outcomes, and the ratios built from them (0 when undefined)."""

    tp: int = 0
    fp1: int = 0
    fp2: int = 0
    fn: int = 0
    tn: int = 0

    @classmethod
    def from_outcomes(cls, outcome: np.ndarray) -> DetectionCounts:
        """Count an ``(N,)`` array of :class:`Outcome` codes (``IGNORED`` is skipped)."""
        codes = np.asarray(outcome, dtype=np.int64)
        n = np.bincount(codes[codes >= 0], minlength=len(Outcome) - 1)
        return cls(*(int(v) for v in n[:5]))

    def __add__(self, other: DetectionCounts) -> DetectionCounts:
        return DetectionCounts(self.tp + other.tp, self.fp1 + other.fp1, self.fp2 + other.fp2,
                               self.fn + other.fn, self.tn + other.tn)

    @property
    def fp(self) -> int:
        return self.fp1 + self.fp2

    @property
    def total(self) -> int:
        return self.tp + self.fp1 + self.fp2 + self.fn + self.tn

    @property
    def precision(self) -> float:
        return _ratio(self.tp, self.tp + self.fp)

    @property
    def recall(self) -> float:
        return _ratio(self.tp, self.tp + self.fn)

    @property
    def f1(self) -> float:
        p, r = self.precision, self.recall
        return _ratio(2 * p * r, p + r)

    @property
    def accuracy(self) -> float:
        return _ratio(self.tp + self.tn, self.total)


def _ratio(num: float, den: float) -> float:
    return float(num) / den if den > 0 else 0.0


# ----------------------------------------------------------------------------------- per-frame work
def gt_visible_mask(visibility, visible_flags: Iterable[int] = DEFAULT_VISIBLE_FLAGS) -> np.ndarray:
    """``(N,) bool``: ground-truth codes that count as visible."""
    return np.isin(np.asarray(visibility), list(visible_flags))


def classify_frames(pred_visible, pred_xy, gt_visibility, gt_xy, tau_px: float,
                    visible_flags: Iterable[int] = DEFAULT_VISIBLE_FLAGS,
                    ignore_flags: Iterable[int] = ()) -> tuple[np.ndarray, np.ndarray]:
    """Outcome of every frame.

    Args:
        pred_visible: ``(N,) bool`` the prediction says "ball here".
        pred_xy: ``(N, 2)`` predicted pixels (used where ``pred_visible``).
        gt_visibility: ``(N,) int`` ground-truth codes 0..3; a negative code means "no ground-truth
            row" and the frame is ignored.
        gt_xy: ``(N, 2)`` true pixels (used where visible).
        tau_px: distance threshold (strict ``<`` for a TP), same pixel space as the coordinates.
        visible_flags: codes that count as visible; others count as absent.
        ignore_flags: codes whose frames are left out entirely.

    Returns:
        ``outcome (N,) int8`` (:class:`Outcome`) and ``distance (N,)`` (NaN unless TP or FP1).
    """
    pred_vis = np.asarray(pred_visible, dtype=bool)
    n = len(pred_vis)
    code = np.asarray(gt_visibility, dtype=np.int64).reshape(-1)
    pxy = np.asarray(pred_xy, dtype=np.float64).reshape(-1, 2)
    gxy = np.asarray(gt_xy, dtype=np.float64).reshape(-1, 2)
    if not len(code) == len(pxy) == len(gxy) == n:
        raise ValueError(f"pred_visible (N,), pred_xy (N, 2), gt_visibility (N,), gt_xy (N, 2) disagree: "
                         f"{pred_vis.shape}, {pxy.shape}, {code.shape}, {gxy.shape}")
    gt_vis = gt_visible_mask(code, visible_flags)
    both = gt_vis & pred_vis
    dist = np.full(n, np.nan)
    dist[both] = np.linalg.norm(pxy[both] - gxy[both], axis=1)
    if np.any(np.isnan(dist[both])):
        raise ValueError("coordinates must be finite where both the prediction and the truth are visible")
    outcome = np.select(
        [both & (dist < tau_px), both, gt_vis, pred_vis],
        [Outcome.TP, Outcome.FP1, Outcome.FN, Outcome.FP2], default=Outcome.TN).astype(np.int8)
    ignored = (code < 0) | np.isin(code, list(ignore_flags))
    outcome[ignored] = Outcome.IGNORED
    dist[ignored] = np.nan
    return outcome, dist


def average_precision(score, is_tp, n_positive: int) -> float:
    """WASB's AP over the predicted-visible frames.

    Args:
        score: ``(M,)`` scores of the predicted-visible frames (NaN ranks last).
        is_tp: ``(M,) bool`` the frame is a TP.
        n_positive: TP + FN, the recall denominator.

    Returns:
        Σ over distinct recall values of (Δ recall × the best precision reached at that recall).
    """
    s = np.nan_to_num(np.asarray(score, dtype=np.float64), nan=-np.inf)
    hit = np.asarray(is_tp, dtype=bool)
    if n_positive <= 0 or not hit.any():
        return 0.0
    order = np.argsort(-s, kind="stable")
    tp = np.cumsum(hit[order])
    precision = tp / np.arange(1, len(tp) + 1)
    recall = tp / n_positive
    levels, first = np.unique(recall, return_index=True)
    best = np.maximum.reduceat(precision, first)   # recall is non-decreasing: groups are contiguous
    return float(np.sum(np.diff(levels, prepend=0.0) * best))


# ------------------------------------------------------------------------------------------ reports
@dataclass(frozen=True)
class DetectionReport:
    """Counts and summary metrics of one evaluation, with the τ and pixel space they were taken at."""

    counts: DetectionCounts
    rmse_px: float
    ap: float
    tau_px: float
    space: str = "original-frame px"
    visible_flags: tuple[int, ...] = tuple(sorted(DEFAULT_VISIBLE_FLAGS))

    @property
    def precision(self) -> float:
        return self.counts.precision

    @property
    def recall(self) -> float:
        return self.counts.recall

    @property
    def f1(self) -> float:
        return self.counts.f1

    @property
    def accuracy(self) -> float:
        return self.counts.accuracy

    def as_dict(self) -> dict[str, float | int | str]:
        """Flat dict for logging: counts, ratios, RMSE, AP, τ and space."""
        c = self.counts
        return {"tp": c.tp, "fp1": c.fp1, "fp2": c.fp2, "fn": c.fn, "tn": c.tn,
                "precision": c.precision, "recall": c.recall, "f1": c.f1, "accuracy": c.accuracy,
                "rmse_px": self.rmse_px, "ap": self.ap, "tau_px": self.tau_px, "space": self.space}


def evaluate_detections(pred_visible, pred_xy, pred_score, gt_visibility, gt_xy, tau_px: float = 4.0,
                        visible_flags: Iterable[int] = DEFAULT_VISIBLE_FLAGS,
                        ignore_flags: Iterable[int] = (), space: str = "original-frame px"
                        ) -> DetectionReport:
    """:class:`DetectionReport` of frame-aligned predictions and ground truth.

    Args:
        pred_visible, pred_xy, gt_visibility, gt_xy, tau_px, visible_flags, ignore_flags: see
            :func:`classify_frames`.
        pred_score: ``(N,)`` confidence used for AP (``None``: all equal).
        space: the pixel space of the coordinates and τ, carried into the report and tables.
    """
    outcome, dist = classify_frames(pred_visible, pred_xy, gt_visibility, gt_xy, tau_px, visible_flags,
                                    ignore_flags)
    counts = DetectionCounts.from_outcomes(outcome)
    scores = np.ones(len(outcome)) if pred_score is None else np.asarray(pred_score, np.float64)
    ranked = np.isin(outcome, [Outcome.TP, Outcome.FP1, Outcome.FP2])
    ap = average_precision(scores[ranked], outcome[ranked] == Outcome.TP, counts.tp + counts.fn)
    located = np.isfinite(dist)
    rmse = float(np.sqrt(np.mean(dist[located] ** 2))) if located.any() else float("nan")
    return DetectionReport(counts, rmse, ap, float(tau_px), space, tuple(sorted(set(visible_flags))))


def evaluate_ball_tracks(pred: BallTrack, gt: BallTrack, width: int, height: int, pred_score=None,
                         tau_px: float = 4.0, visible_flags: Iterable[int] = DEFAULT_VISIBLE_FLAGS,
                         ignore_flags: Iterable[int] = ()) -> DetectionReport:
    """Compare two :class:`BallTrack` s (``ball.csv``) in original-frame pixels of a ``width × height`` clip.

    Only frames with a ground-truth row count; a frame the prediction has no row for is "no ball".
    A prediction is visible when its visibility code is > 0.

    Args:
        pred_score: ``(len(pred),)`` scores aligned with ``pred``'s rows (``None``: all equal).
    """
    frames = gt.frame
    pos = np.searchsorted(pred.frame, frames)
    pos_c = np.minimum(pos, max(len(pred) - 1, 0))
    has = (pos < len(pred)) & (pred.frame[pos_c] == frames) if len(pred) else np.zeros(len(frames), bool)
    pred_vis = np.zeros(len(frames), bool)
    pred_vis[has] = pred.visibility[pos_c[has]] > 0
    pred_px = np.full((len(frames), 2), np.nan)
    pred_px[has] = pred.to_pixels(width, height)[pos_c[has]]
    score = np.zeros(len(frames))
    if pred_score is not None:
        score[has] = np.asarray(pred_score, np.float64)[pos_c[has]]
    return evaluate_detections(pred_vis, pred_px, None if pred_score is None else score, gt.visibility,
                               gt.to_pixels(width, height), tau_px, visible_flags, ignore_flags,
                               space=f"original-frame px ({width}×{height})")


# -------------------------------------------------------------------------------------------- table
class TableRow(NamedTuple):
    """One line of :func:`format_table`: a method's name, its report and (optionally) its speed."""

    name: str
    report: DetectionReport
    fps: float | None = None


def format_table(rows: Sequence[TableRow | tuple], counts: bool = False) -> str:
    """Markdown table of reports (ratios in %), headed by the τ and pixel space they share.

    Args:
        rows: :class:`TableRow` s or ``(name, report[, fps])`` tuples, all at the same τ and space.
        counts: add TP / FP1 / FP2 / FN / TN columns.

    Raises:
        ValueError: the rows were measured at different τ or in different pixel spaces.
    """
    rows = [TableRow(*r) for r in rows]
    if not rows:
        raise ValueError("format_table needs at least one row")
    settings = {(r.report.tau_px, r.report.space, r.report.visible_flags) for r in rows}
    if len(settings) != 1:
        raise ValueError(f"rows were measured at different τ / space / visible flags: {sorted(settings)}")
    tau, space, flags = settings.pop()
    head = ["Method", "F1 (%)", "Acc (%)", "AP (%)", "Precision (%)", "Recall (%)", "RMSE (px)", "FPS"]
    head += ["TP", "FP1", "FP2", "FN", "TN"] if counts else []
    lines = [f"τ = {tau:g} px in {space}; ground truth visible = visibility ∈ {set(flags)}", "",
             "| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for name, rep, fps in rows:
        cells = [name, *(f"{100 * v:.2f}" for v in (rep.f1, rep.accuracy, rep.ap, rep.precision,
                                                    rep.recall)),
                 "–" if np.isnan(rep.rmse_px) else f"{rep.rmse_px:.2f}", "–" if fps is None else f"{fps:.1f}"]
        if counts:
            c = rep.counts
            cells += [str(v) for v in (c.tp, c.fp1, c.fp2, c.fn, c.tn)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
