"""Model assistance for the labeler: the ball detector over a whole clip (with progress), proposed hit events."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from inference.clipio import BallTrack, Clip, HitEvents

from .state import LabelSession, _ball_track

ProgressFn = Callable[[int, int], None]


class _CountingFrames:
    """Wraps a frame source so that iterating it reports ``progress(done, total)``."""

    def __init__(self, source, progress: ProgressFn):
        self.source, self.progress = source, progress

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.source.close()

    def __len__(self) -> int:
        return len(self.source)

    def iter(self, start: int = 0, stop: int | None = None):
        total = len(self.source)
        for k, frame in enumerate(self.source.iter(start, stop), start=start + 1):
            yield frame
            self.progress(k, total)


class ProgressClip(Clip):
    """A :class:`Clip` whose frame iteration reports progress (for a GUI progress bar)."""

    def __init__(self, root, progress: ProgressFn):
        super().__init__(root)
        self._progress = progress

    def frames(self, *, cache_size: int = 8):
        return _CountingFrames(super().frames(cache_size=cache_size), self._progress)


def run_ball_detector(clip: Clip, weights: str | None, progress: ProgressFn,
                      model: str = "wasb") -> tuple[BallTrack, np.ndarray, str]:
    """Detect and track the ball over ``clip`` with a checkpoint (None: the shipped weights).

    Returns the track, ``(n_frames,)`` confidences in ``[0, 1]`` (:func:`confidence`) and a one-line summary.
    Missing or wrong checkpoints raise the runner's clear errors.
    """
    from inference.detection.detect import BallDetectorRunner

    runner = BallDetectorRunner.from_weights(model, weights)
    result = runner.run(ProgressClip(clip.root, progress))
    seen = int((result.track.visibility > 0).sum())
    return result.track, confidence(result.tracked.score), (
        f"detector proposals: ball in {seen} of {result.n_frames} frames ({result.fps:.1f} frames/s); "
        "colour = confidence (red unsure, cyan sure); U jumps to the next unsure frame")


def confidence(score: np.ndarray) -> np.ndarray:
    """The tracker's per-frame scores (heatmap mass, any scale; 0 = nothing found) mapped to ``[0, 1]``: divided
    by the 90th percentile of the frames with a detection, so a typical clear detection scores 1."""
    score = np.nan_to_num(np.asarray(score, float), nan=0.0)
    found = score[score > 0]
    if not found.size:
        return np.zeros_like(score)
    return np.clip(score / max(float(np.percentile(found, 90)), 1e-9), 0.0, 1.0)


def propose_events(session: LabelSession) -> HitEvents:
    """Hit events proposed by the event model from the labelled ball track.

    Raises:
        RuntimeError: "no hit-event model available" when :mod:`inference.events` is missing or has no model.
    """
    try:
        from inference.events import EventDetector
    except ImportError as e:
        raise RuntimeError(f"no hit-event model available ({e})") from None
    ball = _ball_track(session.ball)
    if not len(ball):
        raise RuntimeError("label (or accept) some ball positions first: events are proposed from the ball track")
    camera = session.calibration.camera if session.calibration is not None else None
    try:
        detector = EventDetector.from_checkpoint(None, sport=session.court.sport)
        return detector.predict(ball, session.fps, session.width, session.height, camera=camera).events
    except (FileNotFoundError, ValueError, KeyError) as e:
        raise RuntimeError(f"no hit-event model available ({e})") from None
