"""What every training task shares (detectors here in :mod:`training.run`, hit events in
:mod:`training.events.run` and :mod:`training.events.crop_run`): the data, model and trainer built from the
composed config, debug modes and progress, resuming from a checkpoint, the guarded evaluation table and the
results files. It imports no task, so the tasks can import it (no import circle)."""
from __future__ import annotations

import logging
import sys
import traceback
from pathlib import Path
from typing import Any

import hydra
import lightning as L
from omegaconf import DictConfig, OmegaConf, open_dict

log = logging.getLogger("training.run")


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


def write_eval_results(rows: list[dict], cfg: DictConfig) -> tuple[Path, Path]:
    from training.results import write_results

    stem = Path(cfg.get("results_path") or Path(cfg.paths.output_dir) / "results")
    return write_results(rows, stem, config=cfg)
