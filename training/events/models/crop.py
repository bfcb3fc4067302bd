"""The Lightning module of the crop hit-event model (:class:`inference.events.crop.CropHitNet`).

Cross-entropy on balanced windows with augmentations that keep features and crops consistent: a
horizontal mirror (x → 3 − x of known positions, vx → −vx, crops flipped, labels permuted by the class
set's mirror pairs), ball drops (features and crops of a few frames zeroed, as a detector's misses),
position jitter, crop shifts of a few pixels (detector localisation error) and contrast changes.

``init_from`` warm-starts the GRU head from a ball-only HitNet model file of the same features and
window (the crop columns of its first layer start at 0, so training starts from that model's outputs);
``head_lr_scale`` then slows the head's learning rate relative to the new CNN.
"""
from __future__ import annotations

from dataclasses import dataclass

import lightning as L
import torch
from torch import nn

from inference.events.classes import ClassSet
from inference.events.crop import CropConfig, CropHitNet
from inference.events.detector import load_model_file
from inference.events.features import FeatureConfig

from training.events.models.hitnet import log_event_metrics


@dataclass(frozen=True)
class CropAugment:
    """Probabilities and sizes of the augmentations (per window)."""

    enabled: bool = True
    p_mirror: float = 0.5
    p_drop: float = 0.3         # drop a fraction ``drop_frac`` of the frames of a window
    drop_frac: float = 0.1
    jitter_px: float = 1.5      # position noise (pixels at 1280 wide)
    max_shift_px: int = 2       # crop translation (crop pixels)
    contrast: float = 0.25      # crops scaled by 1 ± this about their mean


def augment_crop_batch(x: torch.Tensor, crops: torch.Tensor, y: torch.Tensor, cfg: CropAugment,
                       features: FeatureConfig, mirror_perm: torch.Tensor, gen: torch.Generator | None = None):
    """Augment runs of frames ``x (B, T, F)``, ``crops (B, T, S, S, 3) uint8`` and their labels ``y (B,)``
    or ``(B, L)`` (-1 = ignored, kept)."""
    if not cfg.enabled or len(x) == 0:
        return x, crops, y
    x, crops = x.clone(), crops.clone()
    B, W, _ = x.shape
    known = (x[:, :, :2] != 0).any(dim=2)                                   # (B, W)
    mirror = torch.rand(B, generator=gen) < cfg.p_mirror
    mx = mirror[:, None] & known
    x[:, :, 0] = torch.where(mx, 3.0 - x[:, :, 0], x[:, :, 0])
    if features.velocity:
        x[:, :, 2] = torch.where(mirror[:, None], -x[:, :, 2], x[:, :, 2])
    crops[mirror] = crops[mirror].flip(3)
    m = mirror.view(-1, *[1] * (y.dim() - 1))
    y = torch.where(m & (y >= 0), mirror_perm[y.clamp(min=0)], y)
    jit = torch.randn(B, W, 2, generator=gen) * (cfg.jitter_px / 1280.0)
    x[:, :, :2] = torch.where(known[..., None], x[:, :, :2] + jit, x[:, :, :2])
    if cfg.max_shift_px > 0:
        for b in range(B):
            dx, dy = (int(v) for v in torch.randint(-cfg.max_shift_px, cfg.max_shift_px + 1, (2,), generator=gen))
            if dx or dy:
                crops[b] = torch.roll(crops[b], shifts=(dy, dx), dims=(1, 2))
    if cfg.contrast > 0:
        scale = 1.0 + (torch.rand(B, 1, 1, 1, 1, generator=gen) * 2 - 1) * cfg.contrast
        c = crops.float()
        mean = c.mean(dim=(2, 3), keepdim=True)
        crops = ((c - mean) * scale + mean).clamp(0, 255).to(torch.uint8)
    drop = (torch.rand(B, generator=gen) < cfg.p_drop)[:, None] & (torch.rand(B, W, generator=gen) < cfg.drop_frac)
    x = torch.where(drop[..., None], 0.0, x)
    crops = torch.where(drop[..., None, None, None], torch.zeros((), dtype=torch.uint8), crops)
    return x, crops, y


def warm_start_head(net: CropHitNet, path: str) -> None:
    """Copy a ball-only HitNet's GRU and linear layer into ``net.head`` (crop inputs start at weight 0)."""
    blob = load_model_file(path)
    if blob["kind"] != "hitnet":
        raise ValueError(f"{path}: init_from needs a ball-only HitNet model file, got kind {blob['kind']!r}")
    src = blob["state_dict"]
    h = blob["net"]
    mine = net.head.hparams
    for k in ("hidden", "layers", "bidirectional", "n_classes"):
        if h[k] != mine[k]:
            raise ValueError(f"{path}: its {k} is {h[k]} but the crop model's head has {mine[k]}; set "
                             f"model.{k}={h[k]} or init_from=null")
    if h["n_features"] != net.n_features:
        raise ValueError(f"{path}: {h['n_features']} ball features per frame, the crop model has {net.n_features}")
    state = net.head.state_dict()
    for k, v in src.items():
        if k.startswith("gru.weight_ih_l0"):  # (3H, F) → (3H, F + E)
            w = torch.zeros_like(state[k])
            w[:, : v.shape[1]] = v
            state[k] = w
        else:
            state[k] = v
    net.head.load_state_dict(state)


class CropHitNetModule(L.LightningModule):
    """Args:
        class_set, features, window, last_k: as :class:`~training.events.models.hitnet.HitNetModule`.
        crop: :class:`CropConfig` fields; embed, channels: the CNN. hidden, layers, bidirectional, dropout:
        the GRU head. lr, weight_decay, head_lr_scale: Adam. init_from: a HitNet model file to warm-start
        the head. augment: :class:`CropAugment` fields. neg_weight: loss weight of windows without an
        event (class balancing; events are ~10 % of windows).

    Batches are chunks of consecutive windows (:class:`~training.events.data.crop_data.CropChunkSet`).
    """

    def __init__(self, class_set: str | dict = "padel6", features: dict | None = None, crop: dict | None = None,
                 window: int = 24, last_k: int = 6, hidden: int = 64, layers: int = 2, bidirectional: bool = True,
                 dropout: float = 0.1, embed: int = 16, channels: list[int] | tuple[int, ...] = (16, 32, 32),
                 lr: float = 2e-3, weight_decay: float = 1e-4, head_lr_scale: float = 1.0,
                 init_from: str | None = None, augment: dict | None = None, lr_patience: int = 4,
                 neg_weight: float = 0.25):
        super().__init__()
        self.save_hyperparameters()
        self.class_set = ClassSet.load(class_set)
        self.features = FeatureConfig.from_dict(features or {})
        self.crop = CropConfig.from_dict(crop or {})
        self.net = CropHitNet(self.features.n_features, self.class_set.n, hidden, layers, bidirectional, dropout,
                              self.crop.size, embed, tuple(channels))
        if init_from:
            warm_start_head(self.net, init_from)
        self.aug = CropAugment(**(augment or {}))
        self.register_buffer("mirror_perm", torch.as_tensor(self.class_set.mirror_permutation()), persistent=False)
        self._val = []

    def forward(self, x: torch.Tensor, crops: torch.Tensor) -> torch.Tensor:
        """Chunks ``x (B, T, F)``, ``crops (B, T, S, S, 3)`` → logits ``(B, L, C)`` of their
        ``L = T - W + 1`` windows (the CNN runs once per frame)."""
        B, T, F = x.shape
        W = int(self.hparams.window)
        z = self.net.frame_inputs(x.reshape(B * T, F), crops.reshape(B * T, *crops.shape[2:])).reshape(B, T, -1)
        wins = z.unfold(1, W, 1).permute(0, 1, 3, 2)  # (B, L, W, D)
        L = wins.shape[1]
        return self.net.head(wins.reshape(B * L, W, -1)).reshape(B, L, -1)

    def chunk_loss(self, logits: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """Cross-entropy over the valid windows, negatives weighted by ``neg_weight``."""
        valid = y >= 0
        ce = nn.functional.cross_entropy(logits[valid], y[valid], reduction="none")
        w = torch.where(y[valid] == 0, float(self.hparams.neg_weight), 1.0)
        return (ce * w).sum() / w.sum().clamp(min=1e-6)

    def training_step(self, batch, _):
        x, crops, y = batch
        x, crops, y = augment_crop_batch(x, crops, y, self.aug, self.features, self.mirror_perm)
        loss = self.chunk_loss(self(x, crops), y)
        self.log("train/loss", loss, prog_bar=True, on_step=True, on_epoch=True, batch_size=len(y), sync_dist=True)
        return loss

    def validation_step(self, batch, _):
        x, crops, y = batch
        logits = self(x, crops)
        self.log("val/loss", self.chunk_loss(logits, y), on_epoch=True, batch_size=len(y), sync_dist=True)
        valid = y >= 0
        self._val.append((logits.argmax(-1)[valid].cpu(), y[valid].cpu()))

    def on_validation_epoch_end(self) -> None:
        log_event_metrics(self, "val", self._val, self.class_set.n)

    def configure_optimizers(self):
        head = list(self.net.head.parameters())
        enc = list(self.net.encoder.parameters())
        opt = torch.optim.Adam([{"params": enc, "lr": self.hparams.lr},
                                {"params": head, "lr": self.hparams.lr * self.hparams.head_lr_scale}],
                               weight_decay=self.hparams.weight_decay)
        sched = torch.optim.lr_scheduler.ReduceLROnPlateau(opt, mode="max", factor=0.5,
                                                           patience=self.hparams.lr_patience)
        return {"optimizer": opt, "lr_scheduler": {"scheduler": sched, "monitor": "val/f1"}}
