"""The Hydra tasks of the hit-event models (``task: events`` in the experiment config):

``train_events``: fit HitNet on balanced windows → calibrate the temperature on validation windows →
tune the decoder on validation clips → export the model file (``<output_dir>/hitnet_<sport>.pth.tar``,
and ``export_path`` when set) → evaluate the test clips with annotated and with detector-like ball
positions (event-set metrics, thesis-style table).

``evaluate_events``: the same evaluation for an exported model file or a Lightning checkpoint.
"""
from __future__ import annotations

import logging
from pathlib import Path

import hydra
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from inference.events.decode import DecodeParams
from inference.events.detector import EventDetector, load_model_file
from inference.events.metrics import format_event_table

from .data import EventDataModule, WindowSet
from .degrade import DegradeConfig, degrade_all
from .evaluate import counts_for, detector_scorer, fit_temperature, score_all, tune_decoder
from .simulate import perturb

log = logging.getLogger(__name__)


def detector_from_module(module, dm: EventDataModule, decode: DecodeParams | None = None,
                         meta: dict | None = None) -> EventDetector:
    return EventDetector("hitnet", dm.class_set, dm.features, decode or DecodeParams(), net=module.net,
                         window=dm.window, last_k=dm.last_k, meta=meta or {})


def calibrate(module, dm: EventDataModule, max_windows: int = 200_000) -> float:
    """Fit the temperature on (up to ``max_windows``) validation windows; stored in the network."""
    ds = dm.sets.get("val") or WindowSet(dm.labelled("val"), dm.window, dm.last_k)
    idx = torch.randperm(len(ds), generator=torch.Generator().manual_seed(0))[:max_windows]
    module.net.eval()
    with torch.no_grad():
        module.net.temperature.fill_(1.0)
        logits = torch.cat([module.net(ds.x[idx[i:i + 8192]]) for i in range(0, len(idx), 8192)])
    t = fit_temperature(logits, ds.y[idx])
    module.net.temperature.fill_(t)
    return t


def tune(det: EventDetector, dm: EventDataModule, passes: int = 2) -> float:
    """Tune the detector's decoder on the validation clips (annotated, plus degraded copies when the data
    module degrades tracks); returns the validation event F1."""
    val, tracks = dm.tuning_clips()
    probs = score_all(detector_scorer(det), val, tracks, desc="val scores")
    det.decode_params, f1 = tune_decoder(probs, val, dm.class_set, det.ref_fps, det.decode_params, passes=passes)
    return f1


def event_tables(det: EventDetector, dm: EventDataModule, name: str, split: str = "test",
                 noise_seed: int = 7, max_clips: int | None = None) -> tuple[dict[str, float], str]:
    """Event-set metrics on ``split`` (its first ``max_clips``) with annotated, detector-like
    (:func:`perturb`) and pipeline-like (:func:`~training.events.degrade.degrade`, every clip degraded)
    ball positions."""
    clips = [c.sim for c in dm.labelled(split)][: max_clips or None]
    scorer = detector_scorer(det)
    rng = np.random.default_rng(noise_seed)
    degraded = degrade_all(clips, noise_seed, DegradeConfig(p_clean=0.0))
    out, tables = {}, []
    what = {"gt": "annotated ball", "e2e": "detector-like ball (misses, jitter, false positives)",
            "deg": "pipeline-like ball (training.events.degrade, every clip degraded)"}
    for mode, tracks in (("gt", [c.ball for c in clips]), ("e2e", [perturb(c, rng) for c in clips]),
                         ("deg", degraded)):
        probs = score_all(scorer, clips, tracks, desc=f"{split} {mode}")
        counts = counts_for(probs, clips, dm.class_set, det.ref_fps, det.decode_params)
        s = counts.scores()
        out.update({f"events/{mode}_{k}": v for k, v in s.items() if k in ("recall", "acc", "prec", "f1")})
        tables.append(format_event_table([(name, counts)], title=f"{split}, {len(clips)} clips, {what[mode]}, "
                                         "tolerance ±2 frames at 50 fps (±1 at 25/30, ±2 at 60)"))
    return out, "\n\n".join(tables)


def train_events(cfg: DictConfig) -> dict[str, float]:
    from training.run import build

    log.info("config:\n%s", OmegaConf.to_yaml(cfg, resolve=False))
    if cfg.get("threads"):
        torch.set_num_threads(int(cfg.threads))  # small GRUs: one thread is fastest on a shared CPU
    dm, module, trainer = build(cfg)
    if cfg.get("init_weights"):  # fine-tune from an exported model file of the same architecture
        module.net.load_state_dict(load_model_file(cfg.init_weights)["state_dict"])
        log.info("initialised from %s", cfg.init_weights)
    metrics: dict[str, float] = {}
    dev = bool(cfg.trainer.get("fast_dev_run"))
    trainer.fit(module, datamodule=dm, ckpt_path=cfg.get("ckpt_path"))
    metrics.update({k: float(v) for k, v in trainer.callback_metrics.items()})
    best = getattr(trainer.checkpoint_callback, "best_model_path", "") if trainer.checkpoint_callback else ""
    if best and not dev:
        state = torch.load(best, map_location="cpu", weights_only=False)["state_dict"]
        module.load_state_dict(state)
    metrics["events/temperature"] = calibrate(module, dm)
    det = detector_from_module(module, dm, meta={"experiment": OmegaConf.to_container(cfg.get("tags") or []),
                                                 "data": {"source": dm.source, "root": dm.root,
                                                          "counts": dm.counts, "seed": dm.seed}})
    metrics["events/val_f1"] = det.meta["val_f1"] = tune(det, dm, passes=1 if dev else 2)
    name = f"HitNet {module.hparams.layers}×{module.hparams.hidden}{' bi' if module.hparams.bidirectional else ''}"
    return test_and_export(cfg, det, dm, metrics, lambda: event_tables(det, dm, name))


def test_and_export(cfg: DictConfig, det: EventDetector, dm, metrics: dict[str, float], tables) -> dict[str, float]:
    """After training: unless ``test=false``, score the test split (``tables() → (scores, markdown)``),
    print the table and keep the scores in the model file's meta; then save the model file to the run
    folder (and ``export_path``). Returns ``metrics`` with the test scores added."""
    if cfg.get("test", True):
        scores, table = tables()
        metrics.update(scores)
        det.meta["test"] = {k: float(v) for k, v in scores.items()}
        print("\n" + table)
    for out in (Path(cfg.paths.output_dir) / f"hitnet_{dm.class_set.sport or 'model'}.pth.tar", cfg.get("export_path")):
        if out:
            det.save(out)
            log.info("exported %s", out)
    return metrics


def load_detector(path: str | Path, cfg: DictConfig, dm: EventDataModule) -> EventDetector:
    """An exported model file, or a Lightning checkpoint of ours (then calibrated and tuned on val)."""
    try:
        return EventDetector.from_blob(load_model_file(path))
    except ValueError:
        pass
    module = hydra.utils.instantiate(cfg.model, _convert_="all")
    state = torch.load(path, map_location="cpu", weights_only=False)
    if "state_dict" not in state:
        raise ValueError(f"{path} is neither a rally3d hit-event model nor a Lightning checkpoint")
    module.load_state_dict(state["state_dict"])
    calibrate(module, dm)
    det = detector_from_module(module, dm)
    det.meta["val_f1"] = tune(det, dm)
    return det


def evaluate_events(cfg: DictConfig) -> dict[str, float]:
    if not cfg.get("ckpt_path"):
        raise ValueError("eval needs ckpt_path=PATH: an exported hit-event model (*.pth.tar) or a Lightning "
                         "checkpoint; the shipped default is inference/weights/hitnet_<sport>.pth.tar")
    path = Path(cfg.ckpt_path)
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint {path} not found")
    if cfg.get("threads"):
        torch.set_num_threads(int(cfg.threads))
    dm = hydra.utils.instantiate(cfg.data, _convert_="all")
    det = load_detector(path, cfg, dm)
    scores, table = event_tables(det, dm, f"{det.kind} ({path.name})", split=cfg.get("split", "test"),
                                 max_clips=cfg.get("max_clips"))
    if "val_f1" in det.meta:
        print(f"\nvalidation event F1 after decoder tuning: {det.meta['val_f1']:.3f}")
    print("\n" + table)
    if cfg.get("export_path"):  # e.g. a Lightning checkpoint, calibrated and tuned here, shipped as a model file
        det.meta["test"] = {k: float(v) for k, v in scores.items()}
        det.save(cfg.export_path)
        log.info("exported %s", cfg.export_path)
    return scores
