"""Ball detection after the network: letterbox geometry, heatmap → candidates, online tracking, metrics.

Pipeline: frames ─(:class:`Letterbox` ``warp``)→ detector ─→ heatmaps ─(:func:`heatmaps_to_candidates`)→
per-frame :class:`FrameCandidates` in original pixels ─(:func:`track_candidates`)→ :class:`TrackResult`
─→ :class:`~inference.clipio.tables.BallTrack` (``ball.csv``); scored with :func:`evaluate_ball_tracks`.
"""
from .geometry import Letterbox
from .metrics import (
    DetectionCounts,
    DetectionReport,
    Outcome,
    TableRow,
    average_precision,
    classify_frames,
    evaluate_ball_tracks,
    evaluate_detections,
    format_table,
)
from .postprocess import (
    FrameCandidates,
    PostprocessConfig,
    heatmap_to_candidates,
    heatmaps_to_candidates,
    pool_candidates,
)
from .tracker import (
    BallTracker,
    TrackerConfig,
    TrackResult,
    TrackState,
    inactive_positions,
    max_score_track,
    track_candidates,
)

__all__ = [
    "BallTracker",
    "DetectionCounts",
    "DetectionReport",
    "FrameCandidates",
    "Letterbox",
    "Outcome",
    "PostprocessConfig",
    "TableRow",
    "TrackResult",
    "TrackState",
    "TrackerConfig",
    "average_precision",
    "classify_frames",
    "evaluate_ball_tracks",
    "evaluate_detections",
    "format_table",
    "heatmap_to_candidates",
    "heatmaps_to_candidates",
    "inactive_positions",
    "max_score_track",
    "pool_candidates",
    "track_candidates",
]
