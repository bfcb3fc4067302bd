"""Ball detection after the network: letterbox geometry, heatmap → candidates, online tracking, metrics.

Pipeline: frames ─(:class:`Letterbox` ``warp``)→ detector ─→ heatmaps ─(:func:`heatmaps_to_candidates`)→
per-frame :class:`FrameCandidates` in original pixels ─(:func:`track_candidates`)→ :class:`TrackResult`
─→ :class:`~inference.clipio.tables.BallTrack` (``ball.csv``); scored with :func:`evaluate_ball_tracks`.
"""
from inference.lazy import lazy_exports

# name → submodule, imported on first use (keeps `rally3d --help` free of torch/scipy)
_EXPORTS = {
    "Letterbox": ".geometry",
    "DetectionCounts": ".metrics",
    "DetectionReport": ".metrics",
    "Outcome": ".metrics",
    "TableRow": ".metrics",
    "average_precision": ".metrics",
    "classify_frames": ".metrics",
    "evaluate_ball_tracks": ".metrics",
    "evaluate_detections": ".metrics",
    "format_table": ".metrics",
    "FrameCandidates": ".postprocess",
    "PostprocessConfig": ".postprocess",
    "heatmap_to_candidates": ".postprocess",
    "heatmaps_to_candidates": ".postprocess",
    "pool_candidates": ".postprocess",
    "BallTracker": ".tracker",
    "TrackerConfig": ".tracker",
    "TrackResult": ".tracker",
    "TrackState": ".tracker",
    "inactive_positions": ".tracker",
    "max_score_track": ".tracker",
    "track_candidates": ".tracker",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

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
