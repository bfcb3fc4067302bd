"""The Hydra tasks behind train.py and eval.py: instantiate data, model, callbacks, loggers and trainer
from the composed config, then fit / test. Plain functions, testable without a command line."""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import hydra
import numpy as np
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
    if cfg.get("task") == "events" and str(cfg.model.get("_target_", "")).endswith("CropHitNetModule"):
        from training.events.crop_run import train_crop_events  # hitnet_crop_* experiments

        return train_crop_events(cfg)
    if cfg.get("task") == "events":  # hit-event models (conf/experiment/hitnet_*.yaml)
        from training.events.run import train_events

        return train_events(cfg)
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
    """Evaluate a detector on whole clips of ``split`` at full resolution, the way inference runs it:
    windows → heatmaps → candidates → tracker. Prints the thesis-style tables at τ = 4 px in original
    frame pixels (WASB-SBDT) and τ = 10 px at 1280×720 (the thesis), for our tracker and WASB's
    max-score tracker, with frames/s; returns the F1s. Hit-event models (``task: events``) print their
    event-set tables instead (training/events/run.py)."""
    if cfg.get("task") == "events" and str(cfg.model.get("_target_", "")).endswith("CropHitNetModule"):
        from training.events.crop_run import evaluate_crop_events

        return evaluate_crop_events(cfg)
    if cfg.get("task") == "events":
        from training.events.run import evaluate_events

        return evaluate_events(cfg)
    from inference.detection.metrics import format_table

    result = evaluate_detector(cfg)
    print(f"\n{result.n_clips} clips of {cfg.data.root} ({cfg.split}), {result.n_frames} frames, "
          f"{result.fps:.1f} frames/s end to end\n")
    print("\n\n".join(format_table(rows, counts=True) for rows in result.tables.values()))
    return result.f1s


@dataclass
class DetectorEval:
    """What :func:`evaluate_detector` measured: per τ setting, one table row per post-processing."""

    tables: dict[str, list]        # "tau4" / "tau10" → [TableRow(name, DetectionReport, fps), ...]
    f1s: dict[str, float]          # "f1_tau4_tracker", "f1_tau10_max-score", ...
    fps: float
    n_frames: int
    n_clips: int


def evaluate_detector(cfg: DictConfig) -> DetectorEval:
    """Run a ball detector over whole clips of ``cfg.split`` as inference does and score it at τ = 4 px
    in original-frame pixels and τ = 10 px at 1280×720, for our tracker and the max-score baseline."""
    from inference.clipio import Clip, Manifest
    from inference.detection.detect import BallDetectorRunner
    from inference.detection.metrics import TableRow, evaluate_detections
    from inference.detection.tracker import max_score_track
    from inference.models.checkpoint import load_weights

    if not cfg.get("ckpt_path") and not cfg.model.get("pretrained"):
        raise ValueError("eval needs ckpt_path=PATH (a checkpoint of ours) or model.pretrained=PATH (WASB-SBDT)")
    if cfg.get("ckpt_path") and not Path(cfg.ckpt_path).is_file():
        raise FileNotFoundError(f"checkpoint {cfg.ckpt_path} not found")
    module = hydra.utils.instantiate(cfg.model, _convert_="all")
    if cfg.get("ckpt_path"):
        load_weights(module.net, cfg.ckpt_path)
    runner = BallDetectorRunner(module.net.eval(), frames_in=cfg.model.net.frames_in,
                                net_size=tuple(cfg.data.net_size), normalize=cfg.data.normalize,
                                step=int(cfg.get("step") or cfg.model.net.frames_in),
                                batch_size=int(cfg.get("batch_size") or 4))
    root = Path(cfg.data.root)
    if not (root / "manifest.yaml").is_file():
        raise FileNotFoundError(f"no manifest.yaml in {root}: point data.root to a dataset folder")
    clips = [Clip(p) for p in Manifest.load(root).paths(cfg.split)]
    if cfg.get("max_clips"):
        clips = clips[: int(cfg.max_clips)]
    if not clips:
        raise ValueError(f"the {cfg.split} split of {root} has no clips")
    rows = {"tracker": [], "max-score": []}
    seconds = frames = 0
    for clip in clips:
        result = runner.run(clip, progress=True)
        seconds += result.seconds_total
        frames += result.n_frames
        gt = clip.read_ball().dense(clip.n_frames)
        size = np.array([clip.info.width, clip.info.height], float)
        for name, tr in (("tracker", result.tracked), ("max-score", max_score_track(result.candidates))):
            shown = np.isin(tr.state, (1,))  # detections only (coasted estimates are not claimed as seen)
            rows[name].append((shown, tr.xy, tr.score, gt.visibility, gt.xy * size, size))
    fps = frames / seconds
    out, tables = {}, {}
    for tau, space, rescale in ((4.0, "original-frame px", False), (10.0, "px at 1280×720", True)):
        table = []
        for name, parts in rows.items():
            vis, xy, score, gvis, gxy = (np.concatenate([p[k] for p in parts]) for k in range(5))
            if rescale:  # both into a 1280-wide frame
                scale = np.concatenate([np.full(len(p[0]), 1280.0 / p[5][0]) for p in parts])[:, None]
                xy, gxy = xy * scale, gxy * scale
            report = evaluate_detections(vis, xy, score, gvis, gxy, tau_px=tau, ignore_flags=(3,), space=space)
            table.append(TableRow(f"{cfg.model.net.name} + {name}", report, fps))
            out[f"f1_tau{tau:g}_{name}"] = report.f1
        tables[f"tau{tau:g}"] = table
    return DetectorEval(tables, out, fps, frames, len(clips))
