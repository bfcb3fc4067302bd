"""Training the per-frame event tagger (:class:`~inference.events.network.EventTagger`, ``kind: tagger``).

Where HitNet learns from balanced windows, the tagger learns from crops of ``data.sequence`` reference
frames of whole clips: every frame gets a class — an event's class on its frame and ``radius`` frames
either side, ``none`` elsewhere (weighted ``none_weight`` in the loss; padding ignored). The same clips,
degradation, pose noise, augmentation, temperature calibration and decoder tuning as HitNet
(:mod:`.data`, :mod:`.run`).

Example:
    >>> ds = SequenceSet(dm.labelled("train"), length=200, radius=1)
    >>> x, y = ds[0]          # (200, F) float32, (200,) int64 (-100: padding)
"""
from __future__ import annotations

import lightning as L
import numpy as np
import torch
from torch import nn
from torch.utils.data import Dataset

from inference.events.classes import ClassSet
from inference.events.features import FeatureConfig
from inference.events.network import EventTagger
from training.finetune import freeze as freeze_layers
from training.finetune import trainable

from .data import AugmentConfig, LabelledClip
from .module import EventSteps

IGNORE = -100  # padding frames: no loss, no score


def frame_targets(y: np.ndarray, radius: int) -> np.ndarray:
    """``(T,)`` per-frame classes (events on one frame) → the same with each event spread over ± ``radius``
    frames (a later event wins where two overlap)."""
    out = np.zeros(len(y), np.int64)
    for f in np.flatnonzero(y):
        out[max(f - radius, 0):f + radius + 1] = y[f]
    return out


class SequenceSet(Dataset):
    """Crops of ``length`` frames of labelled clips.

    ``random=True`` (training): item ``i`` is a random crop of clip ``i % n_clips`` (``repeats`` items per
    clip and epoch; the offset drawn from torch's RNG, which ``seed_everything(workers=True)`` seeds in each
    loader worker); else (validation, test) the clips cut into consecutive crops, the last one padded.
    ``clips`` may be replaced (new degraded tracks each epoch: same clips, same labels)."""

    def __init__(self, clips: list[LabelledClip], length: int, radius: int = 1, random: bool = True,
                 repeats: int = 1):
        if length < 8:
            raise ValueError(f"data.sequence must be at least 8 frames, got {length}")
        self.clips, self.length, self.radius, self.random, self.repeats = clips, int(length), int(radius), random, repeats
        self.targets = [frame_targets(c.y, self.radius) for c in clips]
        self.index = [(k, s) for k, c in enumerate(clips) for s in range(0, max(len(c.feats), 1), self.length)]

    def __len__(self) -> int:
        return len(self.clips) * self.repeats if self.random else len(self.index)

    def __getitem__(self, i):
        if self.random:
            k = i % len(self.clips)
            s = int(torch.randint(0, max(len(self.clips[k].feats) - self.length, 0) + 1, ()))
        else:
            k, s = self.index[i]
        c, L_ = self.clips[k], self.length
        x = np.zeros((L_, c.feats.shape[1]), np.float32)
        y = np.full(L_, IGNORE, np.int64)
        seg = c.feats[s:s + L_]
        x[:len(seg)] = seg
        y[:len(seg)] = self.targets[k][s:s + L_]
        return torch.from_numpy(x), torch.from_numpy(y)

    def all_frames(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Every crop stacked: ``(N, L, F)``, ``(N, L)`` (validation)."""
        xs, ys = zip(*(self[i] for i in range(len(self)))) if len(self) else ((), ())
        return torch.stack(xs), torch.stack(ys)


class TaggerModule(EventSteps, L.LightningModule):
    """Args:
        class_set: name or dict; features: :class:`FeatureConfig` fields (must match the data's).
        hidden, layers, kernel, dropout: the network. lr, weight_decay: AdamW with a one-cycle schedule over
        the run. none_weight: loss weight of the ``none`` frames. augment: :class:`AugmentConfig` fields.
    """

    def __init__(self, class_set: str | dict = "tennis4", features: dict | None = None, hidden: int = 96,
                 layers: int = 3, kernel: int = 5, dropout: float = 0.1, lr: float = 2e-3,
                 weight_decay: float = 1e-4, none_weight: float = 0.3, augment: dict | None = None,
                 freeze: list[str] | None = None):
        super().__init__()
        self.save_hyperparameters()
        self.class_set = ClassSet.load(class_set)
        self.features = FeatureConfig.from_dict(features or {})
        self.net = EventTagger(self.features.n_features, self.class_set.n, hidden, layers, kernel, dropout)
        self.frozen = freeze_layers(self.net, freeze or [])
        self.aug = AugmentConfig(**(augment or {}))
        self.register_buffer("mirror_perm", torch.as_tensor(self.class_set.mirror_permutation()), persistent=False)
        weight = torch.ones(self.class_set.n)
        weight[0] = none_weight
        self.loss = nn.CrossEntropyLoss(weight=weight, ignore_index=IGNORE)
        self._val = []

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)

    def _loss(self, logits: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return self.loss(logits.reshape(-1, logits.shape[-1]), y.reshape(-1))

    def _pairs(self, logits: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        keep = y.reshape(-1) != IGNORE
        return logits.argmax(-1).reshape(-1)[keep], y.reshape(-1)[keep]

    def configure_optimizers(self):
        opt = torch.optim.AdamW(trainable(self), lr=self.hparams.lr, weight_decay=self.hparams.weight_decay)
        total = max(int(self.trainer.estimated_stepping_batches), 1)
        sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=self.hparams.lr, total_steps=total)
        return {"optimizer": opt, "lr_scheduler": {"scheduler": sched, "interval": "step"}}
