"""Hit events (play segmentation): features, the HitNet network, the decoder, a physics-aware
detector and the runtime :class:`EventDetector` used by ``rally3d events`` and ``rally3d infer``."""

from inference.lazy import lazy_exports

# light, and named like their submodule (an import of the submodule would rebind a lazy name to it)
from .decode import DecodeParams, decode

# name → submodule, imported on first use (keeps `rally3d --help` free of torch/scipy)
_EXPORTS = {
    "ClassSet": ".classes",
    "DecodeRules": ".classes",
    "UnmappedLabelError": ".classes",
    "EventDetector": ".detector",
    "EventResult": ".detector",
    "ball_only_weights": ".detector",
    "load_model_file": ".detector",
    "FeatureConfig": ".features",
    "EventCounts": ".metrics",
    "format_event_table": ".metrics",
    "tolerance_frames": ".metrics",
    "HitNet": ".network",
    "EventTagger": ".network",
    "PhysicsParams": ".physics",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

__all__ = [
    "ClassSet",
    "DecodeParams",
    "DecodeRules",
    "EventCounts",
    "EventDetector",
    "EventResult",
    "EventTagger",
    "FeatureConfig",
    "HitNet",
    "PhysicsParams",
    "UnmappedLabelError",
    "decode",
    "ball_only_weights",
    "format_event_table",
    "load_model_file",
    "tolerance_frames",
]
