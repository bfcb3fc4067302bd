"""What pose estimation produces: the people of one frame, and a clip's worth of them."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from inference.players.skeleton import COCO17

J = len(COCO17)


@dataclass
class Persons:
    """The people detected in one frame (COCO-17 keypoints, pixels of the original frame).

    Attributes:
        boxes: (N, 4) ``x1, y1, x2, y2`` pixels (NaN when the source had no box: derived from keypoints).
        keypoints: (N, 17, 2) pixels (NaN where missing).
        kp_scores: (N, 17) confidences in [0, 1] (0 where missing).
        scores: (N,) person confidences.
        track_ids: (N,) identities (-1 = not assigned yet).
    """

    boxes: np.ndarray
    keypoints: np.ndarray
    kp_scores: np.ndarray
    scores: np.ndarray
    track_ids: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        self.keypoints = np.asarray(self.keypoints, dtype=float).reshape(-1, J, 2)
        n = len(self.keypoints)
        self.kp_scores = np.asarray(self.kp_scores, dtype=float).reshape(n, J)
        self.boxes = np.asarray(self.boxes, dtype=float).reshape(n, 4)
        self.scores = np.asarray(self.scores, dtype=float).reshape(n)
        self.track_ids = (np.full(n, -1, np.int64) if self.track_ids is None
                          else np.asarray(self.track_ids, dtype=np.int64).reshape(n))
        if np.isinf(self.keypoints).any() or np.isinf(self.boxes).any():
            raise ValueError("keypoints and boxes must not be infinite")
        missing = np.isnan(self.boxes).any(axis=1)
        if missing.any():  # a box from the keypoints
            kp = self.keypoints[missing]
            with np.errstate(all="ignore"), _quiet():
                self.boxes[missing] = np.concatenate([np.nanmin(kp, axis=1), np.nanmax(kp, axis=1)], axis=1)

    def __len__(self) -> int:
        return len(self.scores)

    @classmethod
    def empty(cls) -> Persons:
        return cls(np.zeros((0, 4)), np.zeros((0, J, 2)), np.zeros((0, J)), np.zeros(0))

    def select(self, mask: np.ndarray) -> Persons:
        return Persons(self.boxes[mask], self.keypoints[mask], self.kp_scores[mask], self.scores[mask],
                       self.track_ids[mask])


class _quiet:
    """Silence numpy's all-NaN warnings inside a block."""

    def __enter__(self):
        import warnings

        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("ignore", RuntimeWarning)

    def __exit__(self, *exc):
        self._w.__exit__(*exc)


@dataclass
class PoseSequence:
    """Persons per frame of a clip: ``frames[i]`` holds frame ``i`` (empty when nobody was detected, or when the
    model did not look at it).

    Attributes:
        looked: (N,) bool, the frames the model looked at on its grid (posing every N-th frame,
            :func:`~inference.players.sampling.sampled_frames`; outside the court views, empty frames on the same
            grid), None: every frame. The tracker runs on these frames and fills the others.
        tiled: (N,) bool, the looks that posed only tiles around people already seen
            (:mod:`~inference.players.crops`): their person scores run higher than a whole frame's, so the tracker
            scales the two kinds apart; None: no such look.
    """

    frames: list[Persons]
    source: str = ""
    looked: np.ndarray | None = None
    tiled: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.frames)


