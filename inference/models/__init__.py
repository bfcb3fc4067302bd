"""Ball-detector networks, weight-compatible with the public WASB-SBDT checkpoints.

All three take ``(B, 3·frames_in, H, W)`` float frames (H, W multiples of 8; 288×512 by default) and
return ``(B, frames_out, H, W)`` heatmap **logits** (apply a sigmoid for probabilities).

=================  ==============  ============================================
name               parameters      architecture
=================  ==============  ============================================
``wasb``           1,481,427       HRNet, full-resolution stem (:class:`WASB`)
``tracknetv2``     11,334,147      VGG U-Net (:class:`TrackNetV2`)
``monotrack``      2,903,171       residual U-Net (:class:`MonoTrack`)
=================  ==============  ============================================

Example:
    >>> model = build_model("wasb")
    >>> load_weights(model, "wasb_tennis_best.pth.tar")      # never downloaded: a file you provide
    >>> logits = model.eval()(frames)                          # (1, 9, 288, 512) -> (1, 3, 288, 512)
"""
from .checkpoint import (
    DetectorInput,
    UntrustedCheckpointError,
    load_detector,
    load_weights,
    save_wasb_checkpoint,
)
from .monotrack import MonoTrack
from .registry import MODEL_NAMES, build_model
from .tracknetv2 import TrackNetV2
from .wasb import WASB

__all__ = [
    "DetectorInput",
    "MODEL_NAMES",
    "MonoTrack",
    "TrackNetV2",
    "UntrustedCheckpointError",
    "WASB",
    "build_model",
    "load_detector",
    "load_weights",
    "save_wasb_checkpoint",
]
