"""The hit-event networks over per-frame features.

- :class:`HitNet`: a GRU stack over a window of frames, global max pool over time, a linear layer and a
  softmax with a calibrated temperature (MonoTrack's hit detector; docs/models.md, "HitNet").
- :class:`EventTagger`: a bidirectional GRU over the whole clip that scores every frame (docs/models.md,
  "Event tagger").
"""
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


class EventTagger(nn.Module):
    """Per-frame event tagger over a whole clip (``kind: tagger``; docs/models.md, "Event tagger").

    A linear embedding of each frame's features, one residual temporal convolution (``kernel`` frames), a
    bidirectional GRU stack over the whole sequence and a linear layer per frame: every frame sees the
    flights on both sides of a contact however long the tracker's gap there, and the class of each frame
    is scored directly (no windows to average).

    Args:
        n_features: F per frame; n_classes: C; hidden: embedding and GRU width per direction;
        layers: GRU depth; kernel: convolution length (odd); dropout: between GRU layers and before the head.

    Shapes:
        ``forward``: ``(B, T, F)`` → logits ``(B, T, C)``; ``probs``: ``(T, F)`` → ``(T, C)`` calibrated
        (``softmax(logits / temperature)``).
    """

    def __init__(self, n_features: int, n_classes: int, hidden: int = 96, layers: int = 3, kernel: int = 5,
                 dropout: float = 0.1):
        super().__init__()
        if min(n_features, n_classes, hidden, layers, kernel) < 1 or kernel % 2 == 0:
            raise ValueError("n_features, n_classes, hidden and layers must be >= 1 and kernel odd")
        self.hparams = {"n_features": n_features, "n_classes": n_classes, "hidden": hidden, "layers": layers,
                        "kernel": kernel, "dropout": dropout}
        self.embed = nn.Sequential(nn.Linear(n_features, hidden), nn.GELU())
        self.conv = nn.Conv1d(hidden, hidden, kernel, padding=kernel // 2)
        self.gru = nn.GRU(hidden, hidden, layers, batch_first=True, bidirectional=True,
                          dropout=dropout if layers > 1 else 0.0)
        self.drop = nn.Dropout(dropout)
        self.head = nn.Linear(2 * hidden, n_classes)
        self.register_buffer("temperature", torch.ones(()))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        z = self.embed(x)
        z = z + torch.relu(self.conv(z.transpose(1, 2))).transpose(1, 2)
        h, _ = self.gru(z)
        return self.head(self.drop(h))

    @torch.no_grad()
    def probs(self, x: torch.Tensor) -> torch.Tensor:
        """Calibrated per-frame probabilities ``(T, C)`` of one clip's features ``(T, F)``."""
        if len(x) == 0:
            return torch.zeros(0, self.head.out_features)
        return torch.softmax(self(x[None].float())[0] / self.temperature, dim=1)
