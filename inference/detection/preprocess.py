"""The detectors' input: N RGB frames stacked on channels with the published normalisation."""
from __future__ import annotations

import numpy as np

IMAGENET_MEAN = np.array([0.485, 0.456, 0.406], np.float32)
IMAGENET_STD = np.array([0.229, 0.224, 0.225], np.float32)


def normalize(frames: np.ndarray, mode: str) -> np.ndarray:
    """(F, H, W, 3) RGB 0–255 → (3F, H, W) float32: ``imagenet`` mean/std or ``unit`` (/255)."""
    x = np.asarray(frames, np.float32) / 255.0
    if mode == "imagenet":
        x = (x - IMAGENET_MEAN) / IMAGENET_STD
    elif mode != "unit":
        raise ValueError(f"normalize must be 'imagenet' or 'unit', got {mode!r}")
    return np.ascontiguousarray(x.transpose(0, 3, 1, 2).reshape(-1, *x.shape[1:3]), dtype=np.float32)
