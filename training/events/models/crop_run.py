"""Hydra tasks of the crop hit-event model (``conf/experiment/hitnet_crop_padel.yaml``; dispatched from
``training/run.py`` when the model is a :class:`~training.events.models.crop.CropHitNetModule`).

``train_crop_events``: fit on balanced windows of rendered clips → calibrate the temperature on the
validation windows → tune the decoder on the validation clips → export ``<output_dir>/hitnet_<sport>.pth.tar``
(and ``export_path``) → event-set tables of the test clips with annotated and detector-like ball positions.
Scoring runs the runtime path: ``EventDetector.ref_probs(..., frames=clip.frames())`` (crops re-cut
around the given track).

``evaluate_crop_events``: the same tables for an exported crop model file.
"""
from __future__ import annotations

import logging
from pathlib import Path

import hydra
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from inference.clipio import BallTrack, Clip
from inference.events.decode import DecodeParams
from inference.events.detector import EventDetector, load_model_file
from inference.events.metrics import format_event_table
from inference.models.checkpoint import read_checkpoint
from training.common import resume_path, write_eval_results

from training.events.data.crop_data import CropEventDataModule
from training.events.run import table_rows, test_and_export
from training.events.evaluate import counts_for, fit_temperature, score_all, tune_decoder
from training.events.synthetic.simulate import SimClip, perturb

log = logging.getLogger(__name__)


def frames_scorer(det: EventDetector):
    """A scorer (``(SimClip, BallTrack) → (T', C)``) that streams each clip's frames (crop models)."""
    def score(sim: SimClip, track: BallTrack) -> np.ndarray:
        with Clip(sim.name).frames(cache_size=0) as frames:
            return det.ref_probs(track, sim.n_frames, sim.fps, camera=sim.camera, frames=frames)
    return score


def calibrate_crop(module, dm: CropEventDataModule) -> float:
    """Fit the temperature on the validation windows (stored in the network)."""
    module.eval()
    logits, labels = [], []
    with torch.no_grad():
        module.net.temperature.fill_(1.0)
        for x, c, y in torch.utils.data.DataLoader(dm.sets["val"], batch_size=8):
            out = module(x, c)
            logits.append(out[y >= 0])
            labels.append(y[y >= 0])
    if not logits:
        return 1.0
    t = fit_temperature(torch.cat(logits), torch.cat(labels))
    module.net.temperature.fill_(t)
    return t


def crop_tables(det: EventDetector, dm: CropEventDataModule, name: str, split: str = "test",
                noise_seed: int = 7) -> tuple[dict[str, float], str, list[dict]]:
    """Event-set metrics of ``split`` with annotated (``gt``) and detector-like (``e2e``) ball positions:
    the scores, the Markdown tables and one row per table line (results files)."""
    clips = [c.lc.sim for c in dm.clips(split)]
    rng = np.random.default_rng(noise_seed)
    out, tables, rows = {}, [], []
    for mode, tracks in (("gt", [c.ball for c in clips]), ("e2e", [perturb(c, rng) for c in clips])):
        probs = score_all(frames_scorer(det), clips, tracks, desc=f"{split} {mode}")
        counts = counts_for(probs, clips, dm.class_set, det.ref_fps, det.decode_params)
        out.update({f"events/{mode}_{k}": v for k, v in counts.scores().items() if k in ("recall", "acc", "prec", "f1")})
        what = "annotated ball" if mode == "gt" else "detector-like ball (misses, jitter, false positives)"
        tables.append(format_event_table([(name, counts)], title=f"{split}, {len(clips)} rendered clips, {what}, "
                                         "tolerance ±2 frames at 50 fps (±1 at 25/30, ±2 at 60)"))
        rows += table_rows(counts, model=name, split=split, ball_input=what, table=mode)
    return out, "\n\n".join(tables), rows


def tune_crop(det: EventDetector, dm: CropEventDataModule, passes: int = 2) -> float:
    val = [c.lc.sim for c in dm.clips("val")]
    probs = score_all(frames_scorer(det), val, desc="val scores")
    det.decode_params, f1 = tune_decoder(probs, val, dm.class_set, det.ref_fps, det.decode_params, passes=passes)
    return f1


def train_crop_events(cfg: DictConfig) -> dict[str, float]:
    from training.common import build

    log.info("config:\n%s", OmegaConf.to_yaml(cfg, resolve=False))
    if cfg.get("threads"):
        torch.set_num_threads(int(cfg.threads))
    dm, module, trainer = build(cfg)
    dev = bool(cfg.trainer.get("fast_dev_run"))
    trainer.fit(module, datamodule=dm, ckpt_path=resume_path(cfg), weights_only=not cfg.get("trust_checkpoint", False))
    metrics = {k: float(v) for k, v in trainer.callback_metrics.items()}
    if not trainer.is_global_zero:  # DDP: calibration, decoder tuning, export and tables run once, on rank 0
        return metrics
    best = getattr(trainer.checkpoint_callback, "best_model_path", "") if trainer.checkpoint_callback else ""
    if best and not dev:
        module.load_state_dict(read_checkpoint(best)["state_dict"])
    metrics["events/temperature"] = calibrate_crop(module, dm)
    det = EventDetector("crop", dm.class_set, dm.features, DecodeParams(), net=module.net, window=dm.window,
                        last_k=dm.last_k, crop=dm.crop,
                        meta={"experiment": OmegaConf.to_container(cfg.get("tags") or []),
                              "data": {"root": str(dm.root), "counts": dm.counts},
                              "init_from": module.hparams.init_from})
    metrics["events/val_f1"] = det.meta["val_f1"] = tune_crop(det, dm, passes=1 if dev else 2)
    name = f"HitNet+crops {module.hparams.layers}×{module.hparams.hidden}"
    return test_and_export(cfg, det, dm, metrics, lambda: crop_tables(det, dm, name))


def evaluate_crop_events(cfg: DictConfig) -> dict[str, float]:
    if not cfg.get("ckpt_path") or not Path(cfg.ckpt_path).is_file():
        raise FileNotFoundError(f"eval needs ckpt_path=PATH of an exported crop model file, got {cfg.get('ckpt_path')}")
    if cfg.get("threads"):
        torch.set_num_threads(int(cfg.threads))
    dm = hydra.utils.instantiate(cfg.data, _convert_="all")
    det = EventDetector.from_blob(load_model_file(cfg.ckpt_path))
    if det.kind != "crop":
        raise ValueError(f"{cfg.ckpt_path} is a {det.kind} model; evaluate it with +experiment=hitnet_<sport>")
    split = str(cfg.get("split") or "test")
    split = "test" if split == "auto" else split
    scores, table, rows = crop_tables(det, dm, f"crop ({Path(cfg.ckpt_path).name})", split=split)
    print("\n" + table)
    paths = write_eval_results([{**r, "checkpoint": str(cfg.ckpt_path)} for r in rows], cfg)
    print(f"\nresults: {paths[0]}, {paths[1]}")
    return scores
