"""Hit events (play segmentation): features, the HitNet network, the decoder, a physics-aware
detector and the runtime :class:`EventDetector` used by ``rally3d events`` and ``rally3d infer``."""

from .classes import ClassSet, DecodeRules, UnmappedLabelError
from .decode import DecodeParams, decode
from .detector import EventDetector, EventResult, default_weights, load_model_file
from .features import FeatureConfig
from .metrics import EventCounts, format_event_table, tolerance_frames
from .network import HitNet
from .physics import PhysicsParams

__all__ = [
    "ClassSet",
    "DecodeParams",
    "DecodeRules",
    "EventCounts",
    "EventDetector",
    "EventResult",
    "FeatureConfig",
    "HitNet",
    "PhysicsParams",
    "UnmappedLabelError",
    "decode",
    "default_weights",
    "format_event_table",
    "load_model_file",
    "tolerance_frames",
]
