"""From ball heatmaps to per-frame candidate blobs, as in WASB-SBDT's postprocessor.

1. Threshold the probability map (``p > threshold``, 0.5 by default, strict like ``cv2.THRESH_BINARY``).
2. Label 8-connected components (``cv2.connectedComponentsWithStats``).
3. Each blob's centre is the **heatmap-weighted centroid** and its score the **sum of the heatmap** over
   the blob (WASB, ``use_weights=True``); the baselines use the plain pixel mean and the pixel count.
4. Centres are mapped back to original-frame pixels with the :class:`~.geometry.Letterbox` inverse.

Everything after the labelling is vectorised with ``np.bincount`` over the foreground pixels.

Example:
    >>> hm = np.zeros((288, 512), np.float32); hm[100:103, 200:203] = 0.9
    >>> xy, score, area = heatmap_to_candidates(hm)
    >>> xy.tolist(), round(float(score[0]), 2), area.tolist()
    ([[201.0, 101.0]], 8.1, [9])
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import cv2
import numpy as np

from .geometry import Letterbox


class FrameCandidates(NamedTuple):
    """Ball candidates of one frame, best score first.

    Attributes:
        xy: ``(K, 2) float64`` blob centres (heatmap or original-frame pixels, see the producer).
        score: ``(K,) float64`` Σ heatmap over the blob (or its pixel count without weights).
        area: ``(K,) int64`` blob sizes in heatmap pixels.
    """

    xy: np.ndarray
    score: np.ndarray
    area: np.ndarray

    @classmethod
    def empty(cls) -> FrameCandidates:
        """No candidates."""
        return cls(np.empty((0, 2)), np.empty(0), np.empty(0, np.int64))

    @classmethod
    def from_arrays(cls, xy, score, area=None) -> FrameCandidates:
        """Validated candidates from ``xy (K, 2)``, ``score (K,)`` and optional ``area (K,)`` (default 1)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        score = np.asarray(score, dtype=np.float64).reshape(-1)
        area = np.ones(len(xy), np.int64) if area is None else np.asarray(area, np.int64).reshape(-1)
        if not len(xy) == len(score) == len(area):
            raise ValueError(f"xy (K, 2), score (K,) and area (K,) disagree: {xy.shape}, {score.shape}, "
                             f"{area.shape}")
        return cls(xy, score, area)

    @property
    def count(self) -> int:
        """Number of candidates ``K``."""
        return len(self.score)

    def take(self, index) -> FrameCandidates:
        """The candidates selected by an index array or boolean mask."""
        return FrameCandidates(self.xy[index], self.score[index], self.area[index])


@dataclass(frozen=True)
class PostprocessConfig:
    """Knobs of the heatmap → candidates step (defaults: WASB-SBDT's ``tracknetv2`` detector config)."""

    threshold: float = 0.5          # probability above which a pixel belongs to a blob
    use_weights: bool = True        # heatmap-weighted centroid and Σ heatmap score (WASB); else mean / count
    min_area: int = 1               # smaller blobs (in heatmap pixels) are dropped
    max_candidates: int | None = 16  # keep the best-scoring blobs only (None: all)
    connectivity: int = 8           # 8- or 4-connected components


def sigmoid(logits: np.ndarray) -> np.ndarray:
    """Numerically safe logistic function, elementwise, float32."""
    x = np.asarray(logits, dtype=np.float32)
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def heatmap_to_candidates(heatmap: np.ndarray, threshold: float = 0.5, use_weights: bool = True,
                          min_area: int = 1, max_candidates: int | None = 16, connectivity: int = 8
                          ) -> FrameCandidates:
    """Blobs of one probability map ``(H, W)`` as :class:`FrameCandidates` in heatmap pixels.

    Args:
        heatmap: ``(H, W)`` probabilities (after the sigmoid).
        threshold: pixels with ``p > threshold`` form the blobs; must be in ``[0, 1)``.
        use_weights: centroid weighted by ``p`` and score ``Σ p`` (WASB); otherwise the plain mean of
            the pixel positions and the pixel count (the TrackNetV2 / MonoTrack baselines).
        min_area: blobs with fewer pixels are dropped.
        max_candidates: keep at most this many, best score first (``None``: all).
        connectivity: 8 (default, as ``cv2.connectedComponents``) or 4.

    Returns:
        ``(xy (K, 2), score (K,), area (K,))`` sorted by decreasing score (ties: scan order).
    """
    hm = np.asarray(heatmap, dtype=np.float32)
    if hm.ndim != 2:
        raise ValueError(f"heatmap must have shape (H, W), got {hm.shape}")
    if not 0.0 <= threshold < 1.0:
        raise ValueError(f"threshold must be in [0, 1), got {threshold}")
    if connectivity not in (4, 8):
        raise ValueError(f"connectivity must be 4 or 8, got {connectivity}")
    mask = (hm > threshold).astype(np.uint8)
    if not mask.any():
        return FrameCandidates.empty()
    n_labels, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=connectivity,
                                                                  ltype=cv2.CV_32S)
    xy, score = _blob_centroids(hm, labels, n_labels, use_weights)
    area = stats[1:, cv2.CC_STAT_AREA].astype(np.int64)
    if not use_weights:
        score = area.astype(np.float64)
    keep = np.flatnonzero(area >= min_area)
    order = keep[np.argsort(-score[keep], kind="stable")][:max_candidates]
    return FrameCandidates(xy[order], score[order], area[order])


def _blob_centroids(hm: np.ndarray, labels: np.ndarray, n_labels: int, use_weights: bool
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Per-blob centroids ``(n_labels-1, 2)`` and weight sums ``(n_labels-1,)`` via ``np.bincount``."""
    flat = np.flatnonzero(labels)
    lab = labels.ravel()[flat]
    rows, cols = np.divmod(flat, hm.shape[1])
    weight = hm.ravel()[flat].astype(np.float64) if use_weights else np.ones(len(flat))
    total = np.bincount(lab, weights=weight, minlength=n_labels)[1:]
    cx = np.bincount(lab, weights=weight * cols, minlength=n_labels)[1:] / total
    cy = np.bincount(lab, weights=weight * rows, minlength=n_labels)[1:] / total
    return np.stack([cx, cy], axis=1), total


def heatmaps_to_candidates(heatmaps: np.ndarray, letterbox: Letterbox | None = None,
                           config: PostprocessConfig = PostprocessConfig(), from_logits: bool = False,
                           drop_outside: bool = True) -> list[FrameCandidates]:
    """Candidates of every map of ``heatmaps (T, H, W)``, in original-frame pixels.

    Args:
        heatmaps: ``(T, H, W)`` probabilities (or logits with ``from_logits=True``).
        letterbox: the frames' letterbox; it is re-targeted to the heatmap grid ``W × H`` (as WASB
            builds its inverse transform at the output size). ``None`` keeps heatmap pixels.
        config: :class:`PostprocessConfig`.
        from_logits: apply the sigmoid first.
        drop_outside: drop blobs whose centre falls in the letterbox padding (outside the frame).

    Returns:
        ``T`` :class:`FrameCandidates`, best score first.
    """
    maps = np.asarray(heatmaps)
    if maps.ndim != 3:
        raise ValueError(f"heatmaps must have shape (T, H, W), got {maps.shape}")
    if from_logits:
        maps = sigmoid(maps)
    box = None if letterbox is None else letterbox.resized(maps.shape[2], maps.shape[1])
    out = []
    for hm in maps:
        cand = heatmap_to_candidates(hm, config.threshold, config.use_weights, config.min_area,
                                     config.max_candidates, config.connectivity)
        if box is not None and cand.count:
            cand = cand._replace(xy=box.inverse(cand.xy))
            if drop_outside:
                cand = cand.take(_inside(cand.xy, box.src_w, box.src_h))
        out.append(cand)
    return out


def _inside(xy: np.ndarray, width: int, height: int) -> np.ndarray:
    """``(K,) bool``: centres within the frame ``[0, W] × [0, H]``."""
    return (xy[:, 0] >= 0) & (xy[:, 0] <= width) & (xy[:, 1] >= 0) & (xy[:, 1] <= height)


def pool_candidates(parts: Sequence[FrameCandidates], merge_radius: float = 0.0,
                    max_candidates: int | None = None) -> FrameCandidates:
    """One frame's candidates from several sources (e.g. WASB ``step=1``: 3 overlapping windows).

    With ``merge_radius > 0`` a candidate within that distance of a better-scoring kept one is dropped
    (greedy non-maximum suppression); with 0 the lists are only concatenated, as in WASB.

    Returns:
        :class:`FrameCandidates` sorted by decreasing score.
    """
    if not parts:
        return FrameCandidates.empty()
    pooled = FrameCandidates(*(np.concatenate(a) for a in zip(*parts)))
    pooled = pooled.take(np.argsort(-pooled.score, kind="stable"))
    if merge_radius > 0 and pooled.count > 1:
        pooled = pooled.take(_suppress_near(pooled.xy, merge_radius))
    return pooled.take(slice(0, max_candidates))


def _suppress_near(xy: np.ndarray, radius: float) -> np.ndarray:
    """Indices kept by greedy NMS on points sorted best first: ``(M,) int``."""
    near = np.linalg.norm(xy[:, None] - xy[None], axis=-1) < radius
    kept = np.zeros(len(xy), dtype=bool)
    for i in range(len(xy)):                      # K is small (tens): one pass over candidates
        kept[i] = not np.any(near[i, :i] & kept[:i])
    return np.flatnonzero(kept)
