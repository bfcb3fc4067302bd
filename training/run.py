"""The Hydra tasks behind train.py and eval.py: instantiate data, model, callbacks, loggers and trainer
from the composed config, then fit / test. Plain functions, testable without a command line.

Order of a detector run, so that a trained model is never lost: data checked (before anything is built)
→ fit (``last.ckpt`` kept current by :class:`training.callbacks.SafeCheckpoint`, also on Ctrl-C and
exceptions) → the model file exported (``<run>/<model>.pth.tar``, and ``export_path``) → only then the
test table, whose failure is reported and does not fail the run.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from omegaconf import DictConfig, OmegaConf

from training.common import (  # noqa: F401 (shared with the hit-event tasks; named here as before)
    instantiate_group, progress_bar, init_source, apply_debug, log_hyperparameters, optimized_metric,
    one_line_per_record, with_progress, build, init_detector, current_experiment, _experiment_of,
    find_last_checkpoint, resume_path, save_manifests, guarded_table, write_eval_results,
)
from training.preflight import check_data, require_eval_weights

log = logging.getLogger(__name__)

VISIBILITY_CLASSES = {0: "absent (0)", 1: "visible (1)", 2: "hard to see (2)", 3: "occluded (3)"}


def train(cfg: DictConfig) -> dict[str, float]:
    """Fit (optionally resuming from ``ckpt_path``), export the model file, then test; returns the metrics.
    Under DDP every rank fits and tests (Lightning's collectives); only rank 0 exports."""
    apply_debug(cfg)
    check_data(cfg)
    if cfg.get("task") == "events" and str(cfg.model.get("_target_", "")).endswith("CropHitNetModule"):
        from training.events.models.crop_run import train_crop_events  # hitnet_crop_* experiments

        return train_crop_events(cfg)
    if cfg.get("task") == "events":  # hit-event models (conf/experiment/hitnet_*.yaml)
        from training.events.run import train_events

        return train_events(cfg)
    log.info("config:\n%s", OmegaConf.to_yaml(cfg, resolve=False))
    datamodule, model, trainer = build(cfg)
    metrics: dict[str, float] = {}
    best = ""
    if cfg.get("train", True):
        trainer.fit(model, datamodule=datamodule, ckpt_path=resume_path(cfg),
                    weights_only=not cfg.get("trust_checkpoint", False))
        save_manifests(datamodule, cfg)
        metrics.update({k: float(v) for k, v in trainer.callback_metrics.items()})
        best = getattr(trainer.checkpoint_callback, "best_model_path", "") if trainer.checkpoint_callback else ""
        best = trainer.strategy.broadcast(best)  # rank 0 knows the best checkpoint
        if not trainer.fast_dev_run and trainer.is_global_zero:
            export_detector(model, best, cfg, metrics)
    if cfg.get("test", False):
        tested = guarded_table("test", lambda: _test(trainer, model, datamodule, best), cfg)
        metrics.update(tested)
        if cfg.get("train", True) and not trainer.fast_dev_run and trainer.is_global_zero and "test/failed" not in tested:
            export_detector(model, best, cfg, metrics)  # again, with the test scores (WASB-SBDT's test_* keys)
    return metrics


def _test(trainer, model, datamodule, best: str) -> dict[str, float]:
    trainer.test(model, datamodule=datamodule, ckpt_path=best or None, weights_only=True)
    return {k: float(v) for k, v in trainer.callback_metrics.items()}


def wasb_sbdt_entries(metrics: dict[str, float]) -> dict[str, float]:
    """The scalar entries WASB-SBDT's ``*_best.pth.tar`` files carry beside ``model_state_dict`` and
    ``epoch``: ``train_loss`` and ``test_*`` (here also ``val_*``), from a run's metrics."""
    out = {}
    for key, value in metrics.items():
        split, _, name = key.partition("/")
        if key in ("train/loss_epoch", "train/loss") and "train_loss" not in out:
            out["train_loss"] = float(value)
        elif split in ("val", "test") and name and "/" not in name:
            out[f"{split}_{name}"] = float(value)
    return out


def export_detector(module, best: str, cfg: DictConfig, metrics: dict[str, float] | None = None) -> list[Path]:
    """Write the trained network (the best checkpoint's weights when there is one) as a model file in
    WASB-SBDT's layout (``model_state_dict`` without prefixes, ``epoch`` of those weights, ``train_loss``,
    ``val_*``/``test_*`` scores) plus its input description: ``<output_dir>/<model>.pth.tar`` and
    ``export_path``."""
    from inference.models.checkpoint import load_weights, save_wasb_checkpoint

    spec = module.input_spec()
    epoch = int(getattr(module, "current_epoch", 0))
    if best and Path(best).is_file():
        epoch = int(load_weights(module.net, best)["meta"].get("epoch", epoch))
    outs = [Path(cfg.paths.output_dir) / f"{spec.arch or 'detector'}.pth.tar"]
    if cfg.get("export_path"):
        outs.append(Path(cfg.export_path))
    for out in outs:
        save_wasb_checkpoint(module.net, out, epoch=epoch, input=spec, **wasb_sbdt_entries(metrics or {}))
        log.info("exported %s (%s, %s normalisation, input %s)", out, spec.arch, spec.normalize, list(spec.input_size))
    return outs


# ---------------------------------------------------------------------------------------------- eval
def evaluate(cfg: DictConfig) -> dict[str, float]:
    """Evaluate a detector on whole clips of ``split`` at full resolution, the way inference runs it:
    windows → heatmaps → candidates → tracker. Prints the thesis-style tables at τ = 4 px in original
    frame pixels (WASB-SBDT) and τ = 10 px at 1280×720 (the thesis), for our tracker and WASB's
    max-score tracker, with frames/s, and a per-visibility table; writes every row to
    ``<output_dir>/results.{json,csv}``; returns the F1s. Hit-event models (``task: events``) print
    their event-set tables instead (training/events/run.py)."""
    require_eval_weights(cfg)  # before the data: the default dataset takes minutes to make
    check_data(cfg)
    if cfg.get("task") == "events" and str(cfg.model.get("_target_", "")).endswith("CropHitNetModule"):
        from training.events.models.crop_run import evaluate_crop_events

        return evaluate_crop_events(cfg)
    if cfg.get("task") == "events":
        from training.events.run import evaluate_events

        return evaluate_events(cfg)
    from inference.detection.metrics import format_table

    result = evaluate_detector(cfg)
    print(f"\n{result.n_clips} clips of {result.data} ({result.split}), {result.n_frames} frames, "
          f"{result.fps:.1f} frames/s end to end; ball.csv = {result.ball_input}\n")
    print("\n\n".join(format_table(rows, counts=True) for rows in result.tables.values()))
    print("\n" + result.per_class_table)
    paths = write_eval_results(result.rows, cfg)
    print(f"\nresults: {paths[0]}, {paths[1]}")
    return result.f1s


@dataclass
class DetectorEval:
    """What :func:`evaluate_detector` measured: per τ setting, one table row per post-processing."""

    tables: dict[str, list]        # "tau4" / "tau10" → [TableRow(name, DetectionReport, fps), ...]
    f1s: dict[str, float]          # "f1_tau4_tracker", "f1_tau10_max-score", ...
    fps: float
    n_frames: int
    n_clips: int
    rows: list[dict] = field(default_factory=list)   # every table row, flat (results.json / .csv)
    per_class_table: str = ""
    data: str = ""
    split: str = ""
    ball_input: str = ""


def eval_device(cfg: DictConfig) -> str:
    """The device eval.py runs a detector on, from ``trainer.accelerator`` (cpu, gpu/cuda, auto)."""
    import torch

    acc = str((cfg.get("trainer") or {}).get("accelerator", "cpu"))
    if acc in ("gpu", "cuda") or (acc == "auto" and torch.cuda.is_available()):
        if not torch.cuda.is_available():
            raise ValueError(f"trainer.accelerator={acc} but no CUDA device is visible: use trainer.accelerator=cpu")
        return "cuda"
    return "cpu"


def eval_split(cfg: DictConfig, source) -> str:
    """``split: auto``: the test split of a dataset (manifest.yaml, or clips whose clip.yaml state a split),
    every clip of a plain folder of clips that state none."""
    split = str(cfg.get("split") or "auto")
    return source.eval_split() if split == "auto" else split


def eval_clips(cfg: DictConfig) -> tuple[list, str, str]:
    """The clips to evaluate (labelled ones), a description of the data and of the splits used."""
    from inference.clipio import Clip
    from training.datasets import resolve_sources, skip_unlabelled

    seed = cfg.data.get("split_seed") if cfg.data.get("split_seed") is not None else cfg.get("seed", 0)
    clips, splits = [], []
    for src in resolve_sources(cfg.data.root, None, seed):
        split = eval_split(cfg, src)
        splits.append(split)
        clips += skip_unlabelled([Clip(p) for p in src.paths(split)], "ball.csv", f"{src.root} ({split})")
    if cfg.get("max_clips"):
        clips = clips[: int(cfg.max_clips)]
    if not clips:
        raise ValueError(f"no labelled clips (with ball.csv) in the {'/'.join(sorted(set(splits)))} split of "
                         f"{cfg.data.root}: pass split=all to use every clip, or another data.root")
    return clips, str(cfg.data.root), "/".join(sorted(set(splits)))


def evaluate_detector(cfg: DictConfig) -> DetectorEval:
    """Run a ball detector over whole clips as inference does and score it at τ = 4 px in original-frame
    pixels and τ = 10 px at 1280×720, for our tracker and the max-score baseline; the input normalisation,
    frames and size come from the checkpoint (WASB-SBDT's ImageNet convention for files that do not say)."""
    from inference.detection.detect import BallDetectorRunner
    from inference.detection.metrics import TableRow, evaluate_detections
    from inference.detection.tracker import max_score_track
    from training.datasets import ball_input

    require_eval_weights(cfg)
    path = cfg.get("ckpt_path") or init_source(cfg)
    runner = BallDetectorRunner.from_weights(cfg.model.net.name, path, trust=bool(cfg.get("trust_checkpoint", False)),
                                             step=int(cfg.get("step") or cfg.model.net.frames_in),
                                             batch_size=int(cfg.get("batch_size") or 4), device=eval_device(cfg))
    if cfg.data.get("normalize") and cfg.data.normalize != runner.normalize:
        log.info("%s states %s normalisation: used instead of data.normalize=%s", path, runner.normalize,
                 cfg.data.normalize)
    clips, data, split = eval_clips(cfg)
    name = f"{cfg.model.net.name}"
    rows = {"tracker": [], "max-score": []}
    inputs: dict[str, int] = {}
    seconds = frames = 0
    for clip in clips:
        result = runner.run(clip, progress=True)
        seconds += result.seconds_total
        frames += result.n_frames
        kind = ball_input(clip, str(cfg.get("ball_input", "auto")))
        inputs[kind] = inputs.get(kind, 0) + 1
        gt = clip.read_ball(n_frames=clip.n_frames).dense(clip.n_frames)
        size = np.array([clip.info.width, clip.info.height], float)
        for post, tr in (("tracker", result.tracked), ("max-score", max_score_track(result.candidates))):
            shown = np.isin(tr.state, (1,))  # detections only (coasted estimates are not claimed as seen)
            rows[post].append((shown, tr.xy, tr.score, gt.visibility, gt.xy * size, size))
    fps = frames / max(seconds, 1e-9)
    what = ", ".join(f"{k} ({v} clips)" for k, v in sorted(inputs.items()))
    common = {"model": name, "checkpoint": str(path), "data": data, "split": split, "ball_input": what,
              "normalize": runner.normalize}
    out, tables, flat = {}, {}, []
    for tau, space, rescale in ((4.0, "original-frame px", False), (10.0, "px at 1280×720", True)):
        table = []
        for post, parts in rows.items():
            vis, xy, score, gvis, gxy = _joined(parts, rescale)
            report = evaluate_detections(vis, xy, score, gvis, gxy, tau_px=tau, ignore_flags=(3,), space=space)
            table.append(TableRow(f"{name} + {post}", report, fps))
            out[f"f1_tau{tau:g}_{post}"] = report.f1
            flat.append({**common, "table": f"tau{tau:g}", "post": post, "class": "all (1, 2; 3 left out)",
                         **report.as_dict(), "fps": fps})
        tables[f"tau{tau:g}"] = table
    per_class, class_rows = per_visibility_table(rows["tracker"], f"{name} + tracker")
    flat += [{**common, **r} for r in class_rows]
    return DetectorEval(tables, out, fps, frames, len(clips), flat, per_class, data, split, what)


def _joined(parts, rescale: bool):
    vis, xy, score, gvis, gxy = (np.concatenate([p[k] for p in parts]) for k in range(5))
    if rescale:  # both into a 1280-wide frame
        scale = np.concatenate([np.full(len(p[0]), 1280.0 / p[5][0]) for p in parts])[:, None]
        xy, gxy = xy * scale, gxy * scale
    return vis, xy, score, gvis, gxy


def per_visibility_table(parts, name: str, tau: float = 10.0) -> tuple[str, list[dict]]:
    """Per ground-truth visibility class (τ = 10 px at 1280×720): how many frames, how many detected within
    τ, wrongly placed, missed, and (class 0) false alarms."""
    from inference.detection.metrics import classify_frames, Outcome

    vis, xy, _, gvis, gxy = _joined(parts, True)
    lines = [f"{name}, per ground-truth visibility, τ = {tau:g} px at 1280×720",
             "", "| class | frames | within τ | wrong place | missed | false alarm | rate |", "|---|---|---|---|---|---|---|"]
    rows = []
    for code, label in VISIBILITY_CLASSES.items():
        keep = gvis == code
        if not keep.any():
            continue
        flags = (code,) if code else (1,)
        outcome, _ = classify_frames(vis[keep], xy[keep], gvis[keep], gxy[keep], tau, visible_flags=flags)
        n = int(keep.sum())
        c = {k: int(np.sum(outcome == getattr(Outcome, k.upper()))) for k in ("tp", "fp1", "fn", "fp2", "tn")}
        rate = c["fp2"] / n if code == 0 else c["tp"] / n
        what = "false-alarm rate" if code == 0 else "detected within τ"
        lines.append(f"| {label} | {n} | {c['tp']} | {c['fp1']} | {c['fn']} | {c['fp2']} | {100 * rate:.1f} % {what} |")
        rows.append({"table": "per_visibility_tau10", "post": "tracker", "class": label, "frames": n, **c,
                     "rate": rate, "rate_is": what, "tau_px": tau, "space": "px at 1280×720"})
    return "\n".join(lines), rows
