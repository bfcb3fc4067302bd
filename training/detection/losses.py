"""Heatmap losses of the ball detectors (on logits; probabilities are clamped to [1e-4, 1 - 1e-4]).

=============  ====================================================================
``wbce``       -mean[(1-p)² y log p + p² (1-y) log(1-p)]      (TrackNetV2 paper, WASB)
``focal``      the same form with exponent γ (default 2)        (MonoTrack, thesis TrackNetV2)
``qfl``        -mean[|p - y|^β BCE(p, y)], β = 2                (quality focal, real-valued targets)
``bce_dice``   0.9 BCE - 0.1 · 2(I + ε)/(ΣP + ΣT + ε)          (WASB ``hm_combo``)
``bce``        plain BCE
=============  ====================================================================

Example:
    >>> loss = HeatmapLoss("wbce")
    >>> value = loss(logits, targets)            # (B, F, H, W) each → scalar
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

KINDS = ("wbce", "focal", "qfl", "bce_dice", "bce")
EPS_P = 1e-4


class HeatmapLoss(nn.Module):
    """One of :data:`KINDS` on (B, F, H, W) logits and targets in [0, 1]."""

    def __init__(self, kind: str = "wbce", gamma: float = 2.0, beta: float = 2.0, dice_weight: float = 0.1):
        super().__init__()
        if kind not in KINDS:
            raise ValueError(f"unknown heatmap loss {kind!r}; choose one of {', '.join(KINDS)}")
        self.kind, self.gamma, self.beta, self.dice_weight = kind, gamma, beta, dice_weight

    def forward(self, logits: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """Loss of (B, F, H, W) logits against targets; ``mask`` (B, F) bool/float selects the frames that
        count (unlabelled frames: 0). Each counted frame weighs the same; no counted frame gives 0."""
        if logits.shape != target.shape:
            raise ValueError(f"logits {tuple(logits.shape)} and targets {tuple(target.shape)} differ")
        p = torch.sigmoid(logits).clamp(EPS_P, 1 - EPS_P)
        y = target.to(p.dtype)
        w = None if mask is None else mask.to(p.dtype)[..., None, None].expand_as(p)
        if self.kind in ("wbce", "focal"):
            g = 2.0 if self.kind == "wbce" else self.gamma
            loss = -((1 - p) ** g * y * torch.log(p) + p**g * (1 - y) * torch.log(1 - p))
            return _mean(loss, w)
        bce = -(y * torch.log(p) + (1 - y) * torch.log(1 - p))
        if self.kind == "qfl":
            return _mean((p - y).abs() ** self.beta * bce, w)
        if self.kind == "bce":
            return _mean(bce, w)
        pm, ym = (p, y) if w is None else (p * w, y * w)
        inter = (pm * ym).sum()
        dice = 2 * (inter + EPS_P) / (pm.sum() + ym.sum() + EPS_P)
        return (1 - self.dice_weight) * _mean(bce, w) - self.dice_weight * dice


def _mean(loss: torch.Tensor, w: torch.Tensor | None) -> torch.Tensor:
    """Mean over every element, or over the elements of the frames ``w`` keeps (0 when it keeps none)."""
    if w is None:
        return loss.mean()
    return (loss * w).sum() / w.sum().clamp_min(1.0)


def bce_with_logits(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Numerically safe BCE on logits (for metrics and sanity checks)."""
    return F.binary_cross_entropy_with_logits(logits, target)
