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
import torch
from torch import nn

from inference.events.classes import ClassSet
from inference.events.features import FeatureConfig
from inference.events.network import EventTagger
from training.finetune import freeze as freeze_layers
from training.finetune import trainable

from training.events.data.datamodule import AugmentConfig
from training.events.models.hitnet import EventSteps
from training.events.data.sequences import IGNORE, SequenceSet, frame_targets

__all__ = ["IGNORE", "SequenceSet", "TaggerModule", "frame_targets"]

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
