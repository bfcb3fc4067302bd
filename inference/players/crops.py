"""Pose on tiles around the people already seen: the geometry of a tile look.

A whole-frame look runs the pose model on the frame scaled to its input size (1080p: 960 × 544 px). Players move
little between two looks (~1/15 s), so most looks only need the pose model on a tile around each person seen
lately (:class:`TileMemory`), small tiles zoomed up: a fraction of the input's pixels. A whole-frame look still
comes every ``full_every``-th look (somebody new walks in) and whenever a tile loses a confident person.

Pure geometry here (boxes in, tiles and kept persons out); :class:`~inference.players.backends.MoveNetBackend`
runs the model on the tiles.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .types import Persons


@dataclass(frozen=True)
class CropLooks:
    """When and where a look poses tiles instead of the whole frame.

    Attributes:
        full_every: a whole-frame look at least every this many looks (1: every look; crops off).
        margin: a tile is the person's box grown by this share of its larger side on every side (a sprinting
            player moves ~0.5 m, a quarter of their height, between looks 1/15 s apart).
        min_score: persons with at least this score get a tile (the tracker's own threshold: a far player
            may score 0.14 in a whole frame and 0.6 in its tile).
        keep_score: a person of the previous look this confident whom its tile no longer shows (nobody of
            ``min_score`` within half a box height of where it was) makes the look a whole-frame one.
        memory: a weaker person whom its tile no longer shows keeps a tile this many looks more.
        still_after, still_every: a person whose box moved less than ``still_frac`` of its height at each of
            its last ``still_after`` looks (a line judge, a ball kid, the umpire: a tennis broadcast shows 5–8
            of them) gets a tile only every ``still_every``-th look; the tracker keeps their tracks across.
        max_tiles: more people than this to follow → a whole-frame look.
        quantum: tile sides are rounded up to a multiple of this many input pixels (a few model shapes only).
        min_side: a tile smaller than this in the model's input is scaled up to it (at most ``max_zoom`` × its
            frame pixels): a far player of ~35 input px, which a whole-frame look still finds among the
            court's lines, goes unseen alone in a 64-px tile.
    """

    full_every: int = 8
    margin: float = 0.35
    min_score: float = 0.1
    keep_score: float = 0.4
    memory: int = 3
    still_after: int = 4
    still_every: int = 3
    still_frac: float = 0.15
    max_tiles: int = 12
    quantum: int = 64
    min_side: int = 192
    max_zoom: float = 2.0

    def __post_init__(self) -> None:
        if self.full_every < 1:
            raise ValueError(f"full_every must be ≥ 1, got {self.full_every}")
        if not 0 <= self.margin <= 5:
            raise ValueError(f"margin must lie in [0, 5], got {self.margin}")
        if self.max_tiles < 1 or self.quantum < 32 or self.quantum % 32:
            raise ValueError("max_tiles must be ≥ 1 and quantum a positive multiple of 32")


def tiles_around(boxes: np.ndarray, frame_hw: tuple[int, int], margin: float) -> np.ndarray:
    """Square tiles around ``boxes`` (N, 4) ``x1, y1, x2, y2`` px, grown by ``margin`` × the larger side on every
    side, overlapping ones merged into one (until none overlap), clipped to the frame: (M, 4) int ``x1, y1, x2, y2``."""
    h, w = frame_hw
    rects = []
    for x1, y1, x2, y2 in np.asarray(boxes, float).reshape(-1, 4):
        side = max(x2 - x1, y2 - y1) * (1 + 2 * margin)
        cx, cy = (x1 + x2) / 2, (y1 + y2) / 2
        rects.append([cx - side / 2, cy - side / 2, cx + side / 2, cy + side / 2])
    merged = True
    while merged and len(rects) > 1:
        merged = False
        for i in range(len(rects)):
            for j in range(i + 1, len(rects)):
                a, b = rects[i], rects[j]
                if a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]:
                    rects[i] = [min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])]
                    del rects[j]
                    merged = True
                    break
            if merged:
                break
    out = np.array(rects, float).reshape(-1, 4)
    out[:, [0, 2]] = np.clip(np.round(out[:, [0, 2]]), 0, w)
    out[:, [1, 3]] = np.clip(np.round(out[:, [1, 3]]), 0, h)
    keep = (out[:, 2] - out[:, 0] >= 8) & (out[:, 3] - out[:, 1] >= 8)
    return out[keep].astype(int)


def inside_tile(persons: Persons, tile: np.ndarray, frame_hw: tuple[int, int], edge_px: float = 2.0) -> np.ndarray:
    """(N,) bool: the persons (frame pixels) whose box does not touch a side of ``tile`` that lies inside the frame
    — a person cut by the tile's edge is a partial copy of somebody another tile or the next look sees whole."""
    h, w = frame_hw
    x1, y1, x2, y2 = (float(v) for v in tile)
    b = persons.boxes
    ok = np.ones(len(persons), bool)
    if x1 > 0:
        ok &= b[:, 0] > x1 + edge_px
    if y1 > 0:
        ok &= b[:, 1] > y1 + edge_px
    if x2 < w:
        ok &= b[:, 2] < x2 - edge_px
    if y2 < h:
        ok &= b[:, 3] < y2 - edge_px
    return ok


def non_max(persons: Persons, iou: float = 0.5) -> Persons:
    """The persons left after dropping any whose box overlaps a higher-scoring one's by IoU > ``iou``
    (supervision's greedy non-maximum suppression)."""
    import supervision as sv

    if len(persons) < 2:
        return persons
    return persons.select(sv.box_non_max_suppression(np.c_[persons.boxes, persons.scores], iou))


def concat(parts: list[Persons]) -> Persons:
    """One :class:`Persons` of several (frame pixels)."""
    if not parts:
        return Persons.empty()
    return Persons(np.concatenate([p.boxes for p in parts]), np.concatenate([p.keypoints for p in parts]),
                   np.concatenate([p.kp_scores for p in parts]), np.concatenate([p.scores for p in parts]))


def shifted(persons: Persons, dx: float, dy: float) -> Persons:
    """``persons`` moved by (dx, dy) px (tile → frame pixels)."""
    d = np.array([dx, dy], float)
    return Persons(persons.boxes + np.tile(d, 2), persons.keypoints + d, persons.kp_scores, persons.scores)


@dataclass
class TileMemory:
    """The people tiles are posed around: each moved to where the last look found it, kept ``CropLooks.memory``
    looks after a look last showed it (a player whom one look misses, behind the net post or another player, or
    whom a whole-frame look scores too low, is looked for again), joined by new people the looks show.

    Attributes:
        boxes: (K, 4) ``x1, y1, x2, y2`` px.
        scores: (K,) the person scores when last seen.
        age: (K,) looks since last seen (0: the last look).
        still: (K,) looks in a row at which the person barely moved.
    """

    boxes: np.ndarray
    scores: np.ndarray
    age: np.ndarray
    still: np.ndarray

    @classmethod
    def of(cls, persons: Persons, min_score: float) -> TileMemory:
        keep = persons.scores >= min_score
        zero = np.zeros(int(keep.sum()), int)
        return cls(persons.boxes[keep].copy(), persons.scores[keep].copy(), zero, zero.copy())

    def __len__(self) -> int:
        return len(self.scores)

    def due(self, look: int, cfg: CropLooks) -> np.ndarray:
        """(K,) bool: the people to pose tiles around at tile look number ``look`` (people standing still:
        every ``still_every``-th look only)."""
        return (self.still < cfg.still_after) | (look % cfg.still_every == 0)

    def update(self, found: Persons, cfg: CropLooks, whole: bool = False, only: np.ndarray | None = None) -> bool:
        """Move each remembered person (of ``only`` (K,) bool, the people looked for; None: all) to the found
        one within half its box height (score ≥ ``min_score``), age the others, forget those older than
        ``cfg.memory``, add the new ones. True when a remembered person with score ≥ ``keep_score`` was not
        found (the look should be a whole-frame one). After a ``whole``-frame look a person it missed keeps
        its tiles but no longer calls for another whole look."""
        ok = np.flatnonzero(found.scores >= cfg.min_score)
        c1 = (found.boxes[ok, :2] + found.boxes[ok, 2:]) / 2
        used = np.zeros(len(ok), bool)
        lost_strong = False
        looked = np.ones(len(self), bool) if only is None else np.asarray(only, bool)
        for k in np.argsort(-self.scores, kind="stable"):
            c0 = (self.boxes[k, :2] + self.boxes[k, 2:]) / 2
            height = max(self.boxes[k, 3] - self.boxes[k, 1], 1.0)
            d = np.linalg.norm(c1 - c0, axis=1) if len(ok) else np.zeros(0)
            d[used] = np.inf
            if len(d) and d.min() <= height / 2:
                j = int(np.argmin(d))
                used[j] = True
                self.still[k] = self.still[k] + 1 if d[j] < cfg.still_frac * height else 0
                self.boxes[k], self.scores[k], self.age[k] = found.boxes[ok[j]], found.scores[ok[j]], 0
            elif not looked[k]:
                continue
            else:
                lost_strong |= bool(self.scores[k] >= cfg.keep_score)
                if whole:
                    self.scores[k] = min(self.scores[k], 0.5 * cfg.keep_score)
                self.age[k] += 1
        keep = self.age <= cfg.memory
        new = ok[~used]
        self.boxes = np.concatenate([self.boxes[keep], found.boxes[new]])
        self.scores = np.concatenate([self.scores[keep], found.scores[new]])
        self.age = np.concatenate([self.age[keep], np.zeros(len(new), int)])
        self.still = np.concatenate([self.still[keep], np.zeros(len(new), int)])
        return lost_strong

