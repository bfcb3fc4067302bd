"""Batch inference over many clips with Lightning's predict loop.

Each item of the dataset is one clip; ``predict_step`` runs the whole pipeline on it with the rank's device,
so ``Trainer(strategy="ddp", devices=N)`` spreads the clips of a dataset over N GPUs (Lightning's
``DistributedSampler`` gives each rank its share) and ``devices=1`` runs them one after another.
"""
from __future__ import annotations

from dataclasses import asdict, replace
from pathlib import Path

import torch
from lightning import LightningModule, Trainer
from torch.utils.data import DataLoader, Dataset

from .prepare import prepare
from .run import run_pipeline
from .stages import PipelineConfig


class ClipItems(Dataset):
    """(input path, output folder or None) pairs."""

    def __init__(self, items: list[tuple[Path, Path | None]]):
        self.items = list(items)

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, i: int) -> tuple[Path, Path | None]:
        return self.items[i]


def _keep(batch):
    return batch


class PipelineModule(LightningModule):
    """Runs :func:`run_pipeline` per clip; returns one summary dict per clip."""

    def __init__(self, cfg: PipelineConfig, court: str | None = None, camera: Path | None = None,
                 court_points: Path | None = None):
        super().__init__()
        self.cfg, self.court, self.camera, self.court_points = cfg, court, camera, court_points
        self.register_buffer("_device_probe", torch.zeros(1), persistent=False)

    def predict_step(self, batch, batch_idx: int):
        out = []
        for source, dest in batch:
            cfg = replace(self.cfg, device=str(self.device), progress=False)
            try:
                prepared = prepare(Path(source), dest, self.court, self.camera, self.court_points)
            except (FileNotFoundError, ValueError, FileExistsError) as e:
                out.append({"input": str(source), "ok": False, "error": str(e), "stages": []})
                continue
            report = run_pipeline(prepared.clip, cfg, log=lambda *_: None)
            out.append({"input": str(source), "clip": str(prepared.clip.root), "ok": report.ok,
                        "table": report.table(), "stages": [asdict(s) for s in report.stages]})
        return out


def predict_clips(items: list[tuple[Path, Path | None]], cfg: PipelineConfig, *, court: str | None = None,
                  camera: Path | None = None, court_points: Path | None = None, accelerator: str = "auto", devices: int | str = 1, strategy: str = "auto") -> list[dict]:
    """Run the pipeline on many clips through ``Trainer.predict``; one summary per clip (this rank's)."""
    trainer = Trainer(accelerator=accelerator, devices=devices, strategy=strategy, logger=False,
                      enable_checkpointing=False, enable_model_summary=False, enable_progress_bar=cfg.progress)
    loader = DataLoader(ClipItems(items), batch_size=1, shuffle=False, collate_fn=_keep, num_workers=0)
    results = trainer.predict(PipelineModule(cfg, court, camera, court_points), loader)
    return [r for batch in results or [] for r in batch]
