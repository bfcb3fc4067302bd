"""The Lightning module of HitNet: cross-entropy on balanced, augmented windows; validation reports
window accuracy and the macro F1 over event classes (``val/f1``, the checkpoint monitor)."""
from __future__ import annotations

import lightning as L
import numpy as np
import torch
from torch import nn

from inference.events.classes import ClassSet
from inference.events.features import FeatureConfig
from inference.events.network import HitNet

from training.distributed import all_reduce_sum, world
from training.finetune import freeze as freeze_layers
from training.finetune import trainable

from training.events.data.datamodule import AugmentConfig, augment_batch



def event_counts(pred: torch.Tensor, y: torch.Tensor, n_classes: int) -> np.ndarray:
    """``(n_classes, 3)`` per class: true positives, predicted, true (pred, y: ``(N,)`` class indices).
    Counts add up over shards (DDP ranks), ratios do not."""
    pred, y = torch.as_tensor(pred).reshape(-1), torch.as_tensor(y).reshape(-1)
    return np.array([[((pred == c) & (y == c)).sum().item(), (pred == c).sum().item(), (y == c).sum().item()]
                     for c in range(n_classes)], dtype=np.float64)


def f1_from_counts(counts: np.ndarray) -> float:
    """Mean per-class F1 over the event classes 1..n-1 present (true > 0) in :func:`event_counts`."""
    f1s = [2 * tp / max(p + t, 1) for tp, p, t in np.asarray(counts)[1:] if t > 0]
    return float(sum(f1s) / max(len(f1s), 1))


def macro_event_f1(pred: torch.Tensor, y: torch.Tensor, n_classes: int) -> float:
    """Mean per-class F1 over the event classes 1..n-1 present in ``y`` (class 0, none, left out).

    pred, y: ``(N,)`` class indices.
    """
    return f1_from_counts(event_counts(pred, y, n_classes))


def log_event_metrics(module: L.LightningModule, stage: str, outputs: list[tuple], n_classes: int) -> float | None:
    """Log ``{stage}/acc`` and ``{stage}/f1`` from ``outputs`` [(pred, y), ...] of **every** process (the
    per-class counts are summed over DDP ranks before the F1); empties ``outputs``; returns the F1."""
    if not outputs and world()[1] == 1:
        return None
    pred, y = ((torch.cat(t) for t in zip(*outputs)) if outputs else (torch.zeros(0, dtype=torch.long),) * 2)
    outputs.clear()
    local = np.concatenate([event_counts(pred, y, n_classes).ravel(), [(pred == y).sum().item(), len(y)]])
    total = all_reduce_sum(local)
    counts, correct, n = total[:-2].reshape(n_classes, 3), total[-2], total[-1]
    f1 = f1_from_counts(counts)
    module.log(f"{stage}/acc", float(correct / n) if n else 0.0)  # global already: no second reduction
    module.log(f"{stage}/f1", f1, prog_bar=True)
    if stage == "val" and not module.trainer.sanity_checking:
        module.best_f1 = max(getattr(module, "best_f1", -1.0), f1)
        module.log("val/f1_best", module.best_f1)
    return f1

class EventSteps:
    """The training, validation and test steps shared by the hit-event Lightning modules: augment, the loss
    (``self._loss(logits, y)``), and the per-class F1 of ``self._pairs(logits, y) → (pred, y)`` (class indices,
    padding left out) at each epoch's end. Needs ``features``, ``aug``, ``mirror_perm``, ``class_set`` and ``_val``."""

    def _loss(self, logits: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return self.loss(logits, y)

    def _pairs(self, logits: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return logits.argmax(1), y

    def training_step(self, batch, _):
        x, y = batch
        x, y = augment_batch(x, y, self.features, self.aug, self.mirror_perm)
        loss = self._loss(self(x), y)
        self.log("train/loss", loss, prog_bar=True, on_step=True, on_epoch=True, batch_size=len(y), sync_dist=True)
        return loss

    def _eval_step(self, batch, stage: str):
        x, y = batch
        logits = self(x)
        self.log(f"{stage}/loss", self._loss(logits, y), on_epoch=True, batch_size=len(y), sync_dist=True)
        pred, true = self._pairs(logits, y)
        self._val.append((pred.cpu(), true.cpu()))

    def validation_step(self, batch, _):
        self._eval_step(batch, "val")

    def test_step(self, batch, _):
        self._eval_step(batch, "test")

    def on_validation_epoch_end(self) -> None:
        log_event_metrics(self, "val", self._val, self.class_set.n)

    def on_test_epoch_end(self) -> None:
        log_event_metrics(self, "test", self._val, self.class_set.n)


class HitNetModule(EventSteps, L.LightningModule):
    """Args:
        class_set: name or dict; features: :class:`FeatureConfig` fields (must match the data's).
        hidden, layers, bidirectional, dropout: the network. lr, weight_decay, clip_norm: Adam (MonoTrack:
        lr 1e-2, clipnorm 2). window, last_k, lookahead: stored for export. augment: :class:`AugmentConfig` fields.
    """

    def __init__(self, class_set: str | dict = "padel6", features: dict | None = None, hidden: int = 64,
                 layers: int = 2, bidirectional: bool = True, dropout: float = 0.0, lr: float = 3e-3,
                 weight_decay: float = 0.0, window: int = 12, last_k: int = 6, lookahead: int = 0, augment: dict | None = None,
                 lr_patience: int = 3, freeze: list[str] | None = None):
        super().__init__()
        self.save_hyperparameters()
        self.class_set = ClassSet.load(class_set)
        self.features = FeatureConfig.from_dict(features or {})
        self.net = HitNet(self.features.n_features, self.class_set.n, hidden, layers, bidirectional, dropout)
        self.frozen = freeze_layers(self.net, freeze or [])
        self.aug = AugmentConfig(**(augment or {}))
        self.register_buffer("mirror_perm", torch.as_tensor(self.class_set.mirror_permutation()), persistent=False)
        self.loss = nn.CrossEntropyLoss()
        self._val = []

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)

    def configure_optimizers(self):
        opt = torch.optim.Adam(trainable(self), lr=self.hparams.lr, weight_decay=self.hparams.weight_decay)
        sched = torch.optim.lr_scheduler.ReduceLROnPlateau(opt, mode="max", factor=0.5,
                                                           patience=self.hparams.lr_patience)
        return {"optimizer": opt, "lr_scheduler": {"scheduler": sched, "monitor": "val/f1"}}
