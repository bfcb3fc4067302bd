"""Validation that means what ``eval.py`` means: the heatmaps of the validation windows turned into ball
candidates the way inference does, joined into whole clips, run through the tracker (and WASB-SBDT's
max-score baseline) and scored at ``τ`` in original-frame pixels.

The validation loader already covers each clip's labelled frames with consecutive non-overlapping windows
(step = frames out), so this costs no extra forward pass: per window, :func:`window_rows` keeps the
candidates of each output frame and the frame's truth as flat numeric rows (gathered across DDP ranks
as they are); at the epoch's end :func:`clip_reports` rebuilds every clip and scores it.

Differences from ``eval.py``, stated: frames of windows with no labelled output frame are not run (the
tracker sees no candidates there; such frames are not scored either) and clip masks are not applied; the
frames come from the frame store (:mod:`.frame_store`), lossless for the scored splits.

Example:
    >>> cands, frames = window_rows(probs, meta, frames_in=3)         # probs (B, F_out, H, W)
    >>> reports = clip_reports(cands, frames, tau_px=4.0)             # {"tracker": DetectionReport, ...}
"""
from __future__ import annotations

import numpy as np

from inference.detection.metrics import DetectionReport, evaluate_detections
from inference.detection.postprocess import FrameCandidates, PostprocessConfig, heatmap_to_candidates, pool_candidates
from inference.detection.tracker import TrackerConfig, max_score_track, track_candidates

CANDIDATE_COLUMNS = ("clip", "frame", "x", "y", "score", "area")
FRAME_COLUMNS = ("clip", "frame", "visibility", "gt_x", "gt_y", "fps", "width", "height")
POSTS = ("tracker", "max-score")


def window_rows(probs: np.ndarray, meta: dict, frames_in: int, config: PostprocessConfig = PostprocessConfig(),
                candidates: list[list[FrameCandidates]] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Candidates and truth of a batch of windows as rows.

    Args:
        probs: ``(B, F_out, h, w)`` heatmap probabilities of full letterboxed frames (no crop offset needed:
            ``meta["offset"]`` is applied).
        meta: the batch's meta (:class:`~training.detection.data.BallWindows`): ``clip``, ``start``,
            ``offset``, ``lb_scale``, ``lb_pad``, ``visibility``, ``xy_px``, ``fps``, ``size`` (and ``skip``:
            leading output frames to leave out, those an earlier window covered).
        frames_in: frames per window (the output frames are the last ``F_out``).
        candidates: the maps' blobs in heatmap pixels (``B`` lists of ``F_out``) when the caller already found
            them with ``config``; else found here.

    Returns:
        ``(K, 6)`` candidate rows (:data:`CANDIDATE_COLUMNS`, original-frame pixels, those in the letterbox
        padding dropped) and ``(≤ B·F_out, 8)`` frame rows (:data:`FRAME_COLUMNS`).
    """
    B, Fo = probs.shape[:2]
    scale, pad, offset = (np.asarray(meta[k], np.float64) for k in ("lb_scale", "lb_pad", "offset"))
    vis = np.asarray(meta["visibility"], np.float64)
    gt = np.asarray(meta["xy_px"], np.float64)
    fps = np.asarray(meta["fps"], np.float64)
    size = np.asarray(meta["size"], np.float64)
    cands, frames = [], []
    for b in range(B):
        first = int(meta["start"][b]) + frames_in - Fo
        clip = float(meta["clip"][b])
        skip = int(meta["skip"][b]) if "skip" in meta else 0  # frames an earlier window already covered
        for f in range(skip, Fo):
            frame = first + f
            frames.append([clip, frame, vis[b, f], gt[b, f, 0], gt[b, f, 1], fps[b], size[b, 0], size[b, 1]])
            c = candidates[b][f] if candidates is not None else blobs(probs[b, f], config)
            if not c.count:
                continue
            xy = (c.xy + offset[b] - pad[b]) / scale[b]
            inside = (xy[:, 0] >= 0) & (xy[:, 0] <= size[b, 0]) & (xy[:, 1] >= 0) & (xy[:, 1] <= size[b, 1])
            for (x, y), s, a in zip(xy[inside], c.score[inside], c.area[inside]):
                cands.append([clip, frame, x, y, s, a])
    return (np.asarray(cands, np.float64).reshape(-1, len(CANDIDATE_COLUMNS)),
            np.asarray(frames, np.float64).reshape(-1, len(FRAME_COLUMNS)))


def blobs(heatmap: np.ndarray, config: PostprocessConfig = PostprocessConfig()) -> FrameCandidates:
    """The blobs of one probability map ``(h, w)`` (heatmap pixels, best first) as inference finds them."""
    return heatmap_to_candidates(heatmap, config.threshold, config.use_weights, config.min_area,
                                 config.max_candidates, config.connectivity)


def _clip_sequence(cands: np.ndarray, frames: np.ndarray):
    """One clip's rows → (candidates per frame over its frame range, visibility (n,), truth (n, 2), fps,
    (width, height))."""
    lo, hi = int(frames[:, 1].min()), int(frames[:, 1].max())
    n = hi - lo + 1
    vis = np.full(n, -1, np.int64)
    gxy = np.full((n, 2), np.nan)
    k = frames[:, 1].astype(np.int64) - lo
    vis[k] = frames[:, 2].astype(np.int64)
    gxy[k] = frames[:, 3:5]
    parts: list[list[FrameCandidates]] = [[] for _ in range(n)]
    for row in cands:
        parts[int(row[1]) - lo].append(FrameCandidates.from_arrays(row[None, 2:4], row[4:5], row[5:6]))
    seq = [pool_candidates(p) if p else FrameCandidates.empty() for p in parts]
    return seq, vis, gxy, float(frames[0, 5]), (int(frames[0, 6]), int(frames[0, 7]))


def clip_reports(cands: np.ndarray, frames: np.ndarray, tau_px: float = 4.0, ignore_flags=(3,),
                 tracker: TrackerConfig = TrackerConfig()) -> dict[str, DetectionReport]:
    """Per post-processing (:data:`POSTS`), the :class:`DetectionReport` over every clip of the rows
    (:func:`window_rows`, possibly gathered from several processes; repeated frames count once): detections
    only (coasted tracker estimates are not claimed as seen), as ``eval.py`` scores them."""
    joined = {p: ([], [], [], [], []) for p in POSTS}
    frames = np.unique(frames, axis=0) if len(frames) else frames
    for clip in np.unique(frames[:, 0]) if len(frames) else []:
        seq, vis, gxy, fps, size = _clip_sequence(cands[cands[:, 0] == clip], frames[frames[:, 0] == clip])
        for post, tr in (("tracker", track_candidates(seq, fps, tracker, size)), ("max-score", max_score_track(seq))):
            for part, value in zip(joined[post], (tr.state == 1, tr.xy, tr.score, vis, gxy)):
                part.append(value)
    out = {}
    for post, parts in joined.items():
        if not parts[0]:
            parts = ([np.zeros(0, bool)], [np.zeros((0, 2))], [np.zeros(0)], [np.zeros(0, np.int64)], [np.zeros((0, 2))])
        shown, xy, score, vis, gxy = (np.concatenate(p) for p in parts)
        out[post] = evaluate_detections(shown, xy, score, vis, gxy, tau_px=tau_px, ignore_flags=tuple(ignore_flags))
    return out


__all__ = ["CANDIDATE_COLUMNS", "FRAME_COLUMNS", "POSTS", "blobs", "clip_reports", "window_rows"]
