"""The Hydra tasks behind train.py and eval.py: instantiate data, model, callbacks, loggers and trainer
from the composed config, then fit / test. Plain functions, testable without a command line.

Order of a detector run, so that a trained model is never lost: data checked (before anything is built)
→ fit (``last.ckpt`` kept current by :class:`training.callbacks.SafeCheckpoint`, also on Ctrl-C and
exceptions) → the model file exported (``<run>/<model>.pth.tar``, and ``export_path``) → only then the
test table, whose failure is reported and does not fail the run.
"""
from __future__ import annotations

import logging
import sys
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import hydra
import lightning as L
import numpy as np
from omegaconf import DictConfig, OmegaConf, open_dict

from training.preflight import check_data

log = logging.getLogger(__name__)

VISIBILITY_CLASSES = {0: "absent (0)", 1: "visible (1)", 2: "hard to see (2)", 3: "occluded (3)"}


def instantiate_group(cfg: DictConfig | None) -> list[Any]:
    """Instantiate every ``_target_`` entry of a config group (callbacks, loggers)."""
    if not cfg:
        return []
    return [hydra.utils.instantiate(c) for c in cfg.values() if isinstance(c, DictConfig) and "_target_" in c]


def progress_bar(cfg: DictConfig) -> bool:
    """``progress_bar: auto`` shows Lightning's bar only in a terminal (a log file gets ProgressLog's lines)."""
    setting = cfg.get("progress_bar", "auto")
    return sys.stderr.isatty() if setting in ("auto", None) else bool(setting)


def init_source(cfg: DictConfig) -> str | None:
    """The weights a run starts from: ``init_weights``, or its older spelling ``model.pretrained``."""
    return cfg.get("init_weights") or (cfg.model.get("pretrained") if "model" in cfg else None) or None


def apply_debug(cfg: DictConfig) -> DictConfig:
    """``debug=NAME`` (conf/debug/): its ``debug.trainer`` settings merged over ``cfg.trainer`` last, so they
    win over the experiment's (``+experiment`` is composed after the debug group). In place; returns cfg."""
    extra = cfg.get("debug")
    if isinstance(extra, DictConfig) and extra.get("trainer"):
        with open_dict(cfg):
            cfg.trainer = OmegaConf.merge(cfg.trainer, extra.trainer)
    return cfg


def log_hyperparameters(cfg: DictConfig, model, trainer) -> dict[str, Any]:
    """Send the composed config (data, model, trainer, callbacks, seed, tags, the experiment) and the
    parameter counts to every logger (CSV: ``hparams.yaml``, TensorBoard: the HPARAMS tab), as
    lightning-hydra-template does; returns what was logged."""
    if not trainer.loggers:
        return {}

    from training.results import resolved

    hp: dict[str, Any] = {k: resolved(cfg.get(k)) for k in ("task_name", "tags", "seed", "data", "model", "trainer",
                                                            "callbacks", "ckpt_path", "init_weights", "task",
                                                            "optimized_metric") if k in cfg}
    hp["experiment"] = current_experiment()
    params = list(model.parameters())
    hp["model/params/total"] = sum(p.numel() for p in params)
    hp["model/params/trainable"] = sum(p.numel() for p in params if p.requires_grad)
    hp["model/params/non_trainable"] = hp["model/params/total"] - hp["model/params/trainable"]
    for logger in trainer.loggers:
        logger.log_hyperparams(hp)
    return hp


def optimized_metric(cfg: DictConfig, metrics: dict[str, float]) -> float | None:
    """The value a sweeper optimises: ``metrics[cfg.optimized_metric]`` (e.g. ``val/f1_best``, the best
    epoch's validation F1). Missing: an error in a sweep (naming what was logged), None otherwise."""
    name = cfg.get("optimized_metric")
    if not name:
        return None
    if name in metrics:
        return float(metrics[name])
    msg = (f"optimized_metric={name} was not logged by this run; logged: {', '.join(sorted(metrics)) or 'nothing'} "
           "(set optimized_metric= to one of them)")
    try:
        from hydra.core.hydra_config import HydraConfig
        from hydra.types import RunMode

        sweeping = HydraConfig.get().mode == RunMode.MULTIRUN
    except (ValueError, AttributeError):
        sweeping = False
    if sweeping:
        raise KeyError(msg)
    log.warning(msg)
    return None


def one_line_per_record() -> None:
    """Lightning's loggers print through their own console handler *and* propagate to the root logger; when
    the root has handlers (Hydra's console and ``train.log``), theirs are removed so that every record is
    written once (with Hydra's format, to the console and the log file)."""
    if not logging.getLogger().handlers:
        return  # no root handler (an API caller): Lightning's own handler is the only one printing
    for name in ("lightning", "lightning.pytorch", "lightning.fabric"):
        lightning_log = logging.getLogger(name)
        for handler in [h for h in lightning_log.handlers if type(h) is logging.StreamHandler]:
            lightning_log.removeHandler(handler)
        lightning_log.propagate = True


def with_progress(callbacks: list, cfg: DictConfig) -> list:
    """Progress in every mode: without Lightning's bar (a log file), ProgressLog's lines, also when the config
    has no callbacks (``debug=…``, ``callbacks=none``)."""
    from training.callbacks import ProgressLog

    bar = cfg.trainer.get("enable_progress_bar", progress_bar(cfg))
    if not bar and not any(isinstance(c, ProgressLog) for c in callbacks):
        callbacks.append(ProgressLog())
    return callbacks


def build(cfg: DictConfig) -> tuple[L.LightningDataModule, L.LightningModule, L.Trainer]:
    from training.distributed import quiet_sync_dist_advice

    apply_debug(cfg)
    one_line_per_record()
    quiet_sync_dist_advice()
    if cfg.get("seed") is not None:
        L.seed_everything(cfg.seed, workers=True)
    datamodule = hydra.utils.instantiate(cfg.data, _convert_="all")  # plain lists: checkpoints load weights_only
    model_cfg = cfg.model
    if "pretrained" in model_cfg and model_cfg.pretrained:  # loaded below with the data's normalisation checked
        model_cfg = model_cfg.copy()
        with open_dict(model_cfg):
            model_cfg.pretrained = None
    model = hydra.utils.instantiate(model_cfg, _convert_="all")
    if cfg.get("task") != "events" and init_source(cfg):
        init_detector(model, init_source(cfg), cfg)
    kw = {"enable_progress_bar": progress_bar(cfg)} if "enable_progress_bar" not in cfg.trainer else {}
    trainer = hydra.utils.instantiate(cfg.trainer, callbacks=with_progress(instantiate_group(cfg.get("callbacks")), cfg),
                                      logger=instantiate_group(cfg.get("logger")) or False, **kw)
    log_hyperparameters(cfg, model, trainer)
    return datamodule, model, trainer


def init_detector(module, path: str, cfg: DictConfig) -> None:
    """Load ``path`` into a detector module before fine-tuning; its stated input normalisation must be the
    data's (a clear error naming ``data.normalize`` otherwise)."""
    from inference.models.checkpoint import load_weights

    info = load_weights(module.net, path, trust=bool(cfg.get("trust_checkpoint", False)))
    spec, wanted = info["input"], cfg.data.get("normalize")
    if wanted and spec.normalize != wanted:
        how = "states" if spec.origin != "assumed" else "does not state its normalisation; WASB-SBDT files use"
        raise ValueError(f"{path} {how} {spec.normalize} input normalisation but data.normalize={wanted}: fine-tune "
                         f"with data.normalize={spec.normalize} (the network's first layers expect it)")
    if tuple(spec.input_size) != tuple(cfg.data.get("net_size", spec.input_size)):
        log.info("%s was trained at %s input, this run uses data.net_size=%s", path, list(spec.input_size),
                 list(cfg.data.net_size))
    log.info("initialised %s from %s (%s, %s normalisation)", type(module.net).__name__, path, info["format"],
             spec.normalize)


def current_experiment() -> str | None:
    """The ``+experiment=NAME`` of this Hydra run (None outside Hydra or without one)."""
    try:
        from hydra.core.hydra_config import HydraConfig

        overrides = list(HydraConfig.get().overrides.task)
    except (ValueError, AttributeError):
        return None
    return _experiment_of(overrides)


def _experiment_of(overrides) -> str | None:
    for o in overrides:
        key, _, value = str(o).lstrip("+~").partition("=")
        if key == "experiment":
            return value
    return None


def find_last_checkpoint(cfg: DictConfig, experiment: str | None = None) -> Path:
    """``ckpt_path=last``: the newest ``last.ckpt`` of an earlier run of the same experiment under
    ``<paths.log_dir>/<task_name>/runs/``."""
    import yaml

    base = Path(cfg.paths.log_dir) / str(cfg.get("task_name", "train")) / "runs"
    here = Path(cfg.paths.output_dir).resolve()
    found = []
    for ckpt in base.glob("*/checkpoints/last.ckpt"):
        run = ckpt.parent.parent
        if run.resolve() == here:
            continue
        overrides = run / ".hydra" / "overrides.yaml"
        try:
            exp = _experiment_of(yaml.safe_load(overrides.read_text()) or []) if overrides.is_file() else None
        except (OSError, yaml.YAMLError):
            exp = None
        if experiment is None or exp == experiment:
            found.append(ckpt)
    if not found:
        what = f" of +experiment={experiment}" if experiment else ""
        raise FileNotFoundError(f"ckpt_path=last: no last.ckpt{what} under {base}/*/checkpoints: pass the path of the "
                                "checkpoint to resume (ckpt_path=PATH)")
    return max(found, key=lambda p: p.stat().st_mtime)


def resume_path(cfg: DictConfig) -> str | None:
    """``ckpt_path`` resolved (``last`` → :func:`find_last_checkpoint`); checked against the allow-list."""
    ckpt = cfg.get("ckpt_path")
    if not ckpt:
        return None
    if str(ckpt) == "last":
        ckpt = str(find_last_checkpoint(cfg, current_experiment()))
        log.info("resuming from %s", ckpt)
    from inference.models.checkpoint import read_checkpoint

    read_checkpoint(ckpt, trust=bool(cfg.get("trust_checkpoint", False)))  # refuses pickled objects first
    return str(ckpt)


def save_manifests(datamodule, cfg: DictConfig) -> None:
    """Keep a copy of inferred manifests in the run folder (to reuse or fix the split)."""
    sources = getattr(datamodule, "_sources", None)
    if sources:
        from training.datasets import save_inferred

        for path in save_inferred(sources, Path(cfg.paths.output_dir)):
            log.info("inferred split saved to %s (copy it to the dataset folder as manifest.yaml to fix it)", path)


def train(cfg: DictConfig) -> dict[str, float]:
    """Fit (optionally resuming from ``ckpt_path``), export the model file, then test; returns the metrics.
    Under DDP every rank fits and tests (Lightning's collectives); only rank 0 exports."""
    apply_debug(cfg)
    check_data(cfg)
    if cfg.get("task") == "events" and str(cfg.model.get("_target_", "")).endswith("CropHitNetModule"):
        from training.events.crop_run import train_crop_events  # hitnet_crop_* experiments

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


def guarded_table(name: str, run, cfg: DictConfig) -> dict[str, float]:
    """Run an evaluation table after the model is saved: a failure is reported (with the traceback in the
    log) and returns ``{f'{name}/failed': 1.0}`` instead of failing the run."""
    try:
        return run()
    except Exception as e:  # noqa: BLE001 - whatever breaks a table must not lose the trained model
        log.debug("%s", traceback.format_exc())
        log.error("the %s table failed (%s: %s); the trained model is saved in %s — evaluate it again with eval.py",
                  name, type(e).__name__, e, cfg.paths.output_dir)
        print(f"\n{name} table failed: {type(e).__name__}: {e} (the model files in {cfg.paths.output_dir} are kept)")
        return {f"{name}/failed": 1.0}


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
    check_data(cfg)
    if cfg.get("task") == "events" and str(cfg.model.get("_target_", "")).endswith("CropHitNetModule"):
        from training.events.crop_run import evaluate_crop_events

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


def write_eval_results(rows: list[dict], cfg: DictConfig) -> tuple[Path, Path]:
    from training.results import write_results

    stem = Path(cfg.get("results_path") or Path(cfg.paths.output_dir) / "results")
    return write_results(rows, stem, config=cfg)


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
    """``split: auto``: the test split of a dataset with manifest.yaml, every clip of a plain folder."""
    split = str(cfg.get("split") or "auto")
    if split == "auto":
        return "all" if source.inferred else "test"
    return split


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

    path = cfg.get("ckpt_path") or init_source(cfg)
    if not path:
        raise ValueError("eval needs ckpt_path=PATH: a model file or checkpoint (ours, Lightning or WASB-SBDT's)")
    if not Path(path).is_file():
        raise FileNotFoundError(f"checkpoint {path} not found")
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
