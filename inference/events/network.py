"""HitNet: a GRU stack over a window of per-frame features, global max pool over time, a linear layer
and a softmax with a calibrated temperature (MonoTrack's hit detector; docs/models.md, "HitNet")."""
from __future__ import annotations

import torch
from torch import nn


class HitNet(nn.Module):
    """Window classifier.

    Args:
        n_features: F per frame; n_classes: C.
        hidden: GRU width per direction; layers: GRU depth; bidirectional: two directions.
        dropout: between GRU layers (and before the linear layer).

    Shapes:
        ``forward``: ``(B, W, F)`` → logits ``(B, C)``; ``probs`` applies ``softmax(logits / T)``.
    """

    def __init__(self, n_features: int, n_classes: int, hidden: int = 64, layers: int = 2,
                 bidirectional: bool = True, dropout: float = 0.0):
        super().__init__()
        if min(n_features, n_classes, hidden, layers) < 1:
            raise ValueError("n_features, n_classes, hidden and layers must be >= 1")
        self.hparams = {"n_features": n_features, "n_classes": n_classes, "hidden": hidden, "layers": layers,
                        "bidirectional": bidirectional, "dropout": dropout}
        self.gru = nn.GRU(n_features, hidden, layers, batch_first=True, bidirectional=bidirectional,
                          dropout=dropout if layers > 1 else 0.0)
        self.drop = nn.Dropout(dropout)
        self.head = nn.Linear(hidden * (2 if bidirectional else 1), n_classes)
        self.register_buffer("temperature", torch.ones(()))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h, _ = self.gru(x)
        return self.head(self.drop(h.amax(dim=1)))

    @torch.no_grad()
    def probs(self, x: torch.Tensor, batch_size: int = 4096) -> torch.Tensor:
        """Calibrated class probabilities ``(B, C)`` (batched, no grad)."""
        out = [torch.softmax(self(x[i:i + batch_size]) / self.temperature, dim=1) for i in range(0, len(x), batch_size)]
        return torch.cat(out) if out else torch.zeros(0, self.head.out_features)
