"""The Hydra tasks behind train.py and eval.py: instantiate data, model, callbacks, loggers and trainer
from the composed config, then fit / test. Plain functions, testable without a command line."""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import hydra
import lightning as L
from omegaconf import DictConfig, OmegaConf

log = logging.getLogger(__name__)


def instantiate_group(cfg: DictConfig | None) -> list[Any]:
    """Instantiate every ``_target_`` entry of a config group (callbacks, loggers)."""
    if not cfg:
        return []
    return [hydra.utils.instantiate(c) for c in cfg.values() if isinstance(c, DictConfig) and "_target_" in c]


def build(cfg: DictConfig) -> tuple[L.LightningDataModule, L.LightningModule, L.Trainer]:
    if cfg.get("seed") is not None:
        L.seed_everything(cfg.seed, workers=True)
    datamodule = hydra.utils.instantiate(cfg.data, _convert_="all")  # plain lists: checkpoints load weights_only
    model = hydra.utils.instantiate(cfg.model, _convert_="all")
    trainer = hydra.utils.instantiate(cfg.trainer, callbacks=instantiate_group(cfg.get("callbacks")),
                                      logger=instantiate_group(cfg.get("logger")) or False)
    return datamodule, model, trainer


def train(cfg: DictConfig) -> dict[str, float]:
    """Fit (optionally resuming from ``ckpt_path``), then test the best checkpoint; returns the metrics."""
    log.info("config:\n%s", OmegaConf.to_yaml(cfg, resolve=False))
    datamodule, model, trainer = build(cfg)
    metrics: dict[str, float] = {}
    if cfg.get("train", True):
        trainer.fit(model, datamodule=datamodule, ckpt_path=cfg.get("ckpt_path"))
        metrics.update({k: float(v) for k, v in trainer.callback_metrics.items()})
    if cfg.get("test", False):
        best = getattr(trainer.checkpoint_callback, "best_model_path", "") if trainer.checkpoint_callback else ""
        trainer.test(model, datamodule=datamodule, ckpt_path=best or None)
        metrics.update({k: float(v) for k, v in trainer.callback_metrics.items()})
    return metrics


def evaluate(cfg: DictConfig) -> dict[str, float]:
    """Test a checkpoint (``ckpt_path``, ours) or the model's ``pretrained`` weights on ``split``."""
    if not cfg.get("ckpt_path") and not cfg.model.get("pretrained"):
        raise ValueError("eval needs ckpt_path=PATH (a Lightning checkpoint) or model.pretrained=PATH")
    if cfg.get("ckpt_path") and not Path(cfg.ckpt_path).is_file():
        raise FileNotFoundError(f"checkpoint {cfg.ckpt_path} not found")
    datamodule, model, trainer = build(cfg)
    trainer.test(model, datamodule=datamodule, ckpt_path=cfg.get("ckpt_path"))
    return {k: float(v) for k, v in trainer.callback_metrics.items()}
