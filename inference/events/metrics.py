"""Event-set metrics (docs/anchors.md): an event matches when its class agrees and its frame
is within a tolerance; ``acc = |G∩Ĝ| / |G∪Ĝ|``, ``recall = |G∩Ĝ| / |G|``, ``prec = |G∩Ĝ| / |Ĝ|``, F1.

The tolerance is ``tol_frames_at_50`` frames at 50 fps scaled with the frame rate and rounded to the
nearest integer (halves up), at least 1: ±2 at 50 fps, ±1 at 25 and 30 fps (2·30/50 = 1.2 → 1),
±2 at 60 fps (2.4 → 2).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def tolerance_frames(fps: float, tol_frames_at_50: float = 2.0) -> int:
    """The matching tolerance in frames at ``fps`` (see the module docstring)."""
    return max(1, int(np.floor(tol_frames_at_50 * fps / 50.0 + 0.5)))


def match_events(gt_frames: np.ndarray, pred_frames: np.ndarray, tol: int) -> int:
    """Number of one-to-one matches within ``± tol`` frames (closest pairs first)."""
    if len(gt_frames) == 0 or len(pred_frames) == 0:
        return 0
    d = np.abs(np.asarray(gt_frames)[:, None] - np.asarray(pred_frames)[None, :])
    gi, pi = np.nonzero(d <= tol)
    order = np.argsort(d[gi, pi], kind="stable")
    used_g, used_p, n = set(), set(), 0
    for k in order:
        g, p = int(gi[k]), int(pi[k])
        if g not in used_g and p not in used_p:
            used_g.add(g)
            used_p.add(p)
            n += 1
    return n


@dataclass
class EventCounts:
    """Per-class true positives, ground-truth and predicted counts, accumulated over clips."""

    classes: tuple[str, ...]
    tp: np.ndarray = field(default=None)  # type: ignore[assignment]
    n_gt: np.ndarray = field(default=None)  # type: ignore[assignment]
    n_pred: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        n = len(self.classes)
        self.tp = np.zeros(n, np.int64) if self.tp is None else self.tp
        self.n_gt = np.zeros(n, np.int64) if self.n_gt is None else self.n_gt
        self.n_pred = np.zeros(n, np.int64) if self.n_pred is None else self.n_pred

    def add(self, gt_frames, gt_cls, pred_frames, pred_cls, tol: int) -> None:
        """Add one clip (class indices; index 0 = none is ignored)."""
        gt_frames, gt_cls = np.asarray(gt_frames), np.asarray(gt_cls)
        pred_frames, pred_cls = np.asarray(pred_frames), np.asarray(pred_cls)
        for c in range(1, len(self.classes)):
            g, p = gt_frames[gt_cls == c], pred_frames[pred_cls == c]
            self.tp[c] += match_events(g, p, tol)
            self.n_gt[c] += len(g)
            self.n_pred[c] += len(p)

    def scores(self, c: int | None = None) -> dict[str, float]:
        """recall, acc, prec, f1 of class ``c`` (None: all event classes pooled)."""
        sl = slice(1, None) if c is None else slice(c, c + 1)
        tp, g, p = self.tp[sl].sum(), self.n_gt[sl].sum(), self.n_pred[sl].sum()
        rec = tp / g if g else float("nan")
        prec = tp / p if p else float("nan")
        acc = tp / (g + p - tp) if (g + p - tp) else float("nan")
        f1 = 2 * tp / (g + p) if (g + p) else float("nan")
        return {"recall": float(rec), "acc": float(acc), "prec": float(prec), "f1": float(f1),
                "n_gt": int(g), "n_pred": int(p)}


def format_event_table(rows: list[tuple[str, EventCounts]], title: str = "") -> str:
    """A thesis-style table (Tables 5.3–5.5): per model, per class and overall recall / acc / prec / F1."""
    if not rows:
        return title
    classes = rows[0][1].classes[1:]
    head = f"| model | class | recall | acc | prec | F1 | #gt | #pred |\n|---|---|---|---|---|---|---|---|"
    lines = [title, "", head] if title else [head]
    for name, counts in rows:
        for c, cname in [(None, "**all**"), *[(i + 1, n) for i, n in enumerate(classes)]]:
            s = counts.scores(c)
            f = lambda v: "–" if np.isnan(v) else f"{100 * v:.1f}"  # noqa: E731
            f1 = "–" if np.isnan(s["f1"]) else f"{s['f1']:.3f}"
            lines.append(f"| {name if c is None else ''} | {cname} | {f(s['recall'])} | {f(s['acc'])} | "
                         f"{f(s['prec'])} | {f1} | {s['n_gt']} | {s['n_pred']} |")
    return "\n".join(lines)
