"""What every training task shares (detectors here in :mod:`training.run`, hit events in
:mod:`training.events.run` and :mod:`training.events.models.crop_run`): the data, model and trainer built from the
composed config, debug modes and progress, resuming from a checkpoint, the guarded evaluation table and the
results files. It imports no task, so the tasks can import it (no import circle)."""
from __future__ import annotations

import csv
import filecmp
import logging
import os
import re
import shutil
import sys
import traceback
import warnings
from datetime import datetime
from pathlib import Path
from typing import Any

import hydra
import lightning as L
from omegaconf import DictConfig, OmegaConf, open_dict

from training.preflight import init_source  # noqa: F401 (re-exported: training.run and its callers name it here)

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
    continued = continue_run(cfg)  # before callbacks and loggers read paths.output_dir
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
                                      logger=instantiate_loggers(cfg, continued) or False, **kw)
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
    """``ckpt_path`` resolved (``last`` → :func:`find_last_checkpoint`); checked against the allow-list.
    After :func:`build` it is the file :func:`continue_run` resolved and checked (read once)."""
    ckpt = cfg.get("ckpt_path")
    if not ckpt:
        return None
    if str(ckpt) == "last":
        ckpt = str(find_last_checkpoint(cfg, current_experiment()))
        log.info("resuming from %s", ckpt)
    checkpoint_info(ckpt, trust=bool(cfg.get("trust_checkpoint", False)))  # refuses pickled objects first
    return str(ckpt)


# ------------------------------------------------------------------------------------------------ resuming
HYDRA_OUTPUT_DIR = "hydra:runtime.output_dir"
"""What ``paths.output_dir`` is unless the user sets it (conf/paths/default.yaml): Hydra's run folder."""
CONTINUED_NOTE = "continued_in.txt"
"""Written in Hydra's new folder of a run that continues in the folder of the checkpoint it resumes."""
RESUMES_LOG = "resumes.log"
"""One line per resume, in the continued run folder: when, from which checkpoint, the resume's config folder."""
_checked: dict[tuple, dict[str, int]] = {}
_continued_log: logging.Handler | None = None


def checkpoint_info(path: str | Path, trust: bool = False) -> dict[str, int]:
    """Read ``path`` through the allow-list (an error on pickled objects unless ``trust``) and return its
    ``epoch`` and ``global_step``; the same unchanged file is read once (build, then fit, ask twice)."""
    from inference.models.checkpoint import read_checkpoint

    st = Path(path).stat() if Path(path).is_file() else None
    key = (str(Path(path).resolve()), st and st.st_mtime_ns, st and st.st_size, bool(trust))
    if key not in _checked:
        state = read_checkpoint(path, trust=trust)
        _checked.clear()
        _checked[key] = {k: int(state.get(k, 0) or 0) for k in ("epoch", "global_step")} \
            if isinstance(state, dict) else {"epoch": 0, "global_step": 0}
    return _checked[key]


def run_folder_of(ckpt: str | Path) -> Path | None:
    """The run folder of a checkpoint (``<run>/checkpoints/NAME.ckpt`` → ``<run>``), None elsewhere."""
    p = Path(ckpt).resolve()
    return p.parent.parent if p.parent.name == "checkpoints" else None


def new_folder_reason(cfg: DictConfig) -> str | None:
    """Why a resumed run writes to a folder of its own instead of continuing in its checkpoint's run folder
    (None: it continues): ``resume_new_folder=true``, ``paths.output_dir=`` or ``hydra.run.dir=`` given,
    a sweep's trial, a debug run."""
    if cfg.get("resume_new_folder"):
        return "resume_new_folder=true"
    if cfg.get("debug") is not None or ("trainer" in cfg and cfg.trainer.get("fast_dev_run")):
        return "a debug run"
    if HYDRA_OUTPUT_DIR not in str(OmegaConf.to_container(cfg.paths, resolve=False).get("output_dir")):
        return "paths.output_dir is set"
    try:
        from hydra.core.hydra_config import HydraConfig
        from hydra.types import RunMode

        hc = HydraConfig.get()
    except (ValueError, ImportError):
        return None
    if hc.mode == RunMode.MULTIRUN:
        return "a sweep: each trial keeps its own folder"
    overrides = [str(o) for o in hc.overrides.hydra]
    run_dirs = [o for o in overrides if o.startswith("hydra.run.dir=")]
    if any(o.startswith("hydra.job.name=train_ddp_process_") for o in overrides):
        run_dirs = run_dirs[:-1]  # a DDP process Lightning started: its last hydra.run.dir is the first process's
    return "hydra.run.dir is set" if run_dirs else None


def _rank_zero() -> bool:
    from lightning.fabric.utilities.rank_zero import rank_zero_only

    return getattr(rank_zero_only, "rank", 0) == 0


def _backup(path: Path) -> Path | None:
    """Copy ``path`` to ``path.bak`` (``.bak2``, … when an older, different copy is there); returns the copy."""
    if not path.is_file():
        return None
    n = 1
    while True:
        bak = path.with_name(f"{path.name}.bak" + (str(n) if n > 1 else ""))
        if bak.is_file() and filecmp.cmp(path, bak, shallow=False):
            return bak
        if not bak.exists():
            shutil.copy2(path, bak)
            return bak
        n += 1


def continue_run(cfg: DictConfig) -> Path | None:
    """Resuming (``ckpt_path=PATH|last``, ``train=true``): the run continues in the run folder of the checkpoint
    (``<run>/checkpoints/*.ckpt``), unless :func:`new_folder_reason`. Called by :func:`build` before any
    callback or logger is made; returns the continued folder (None: no resume, or a new folder).

    Continuing: ``cfg.ckpt_path`` becomes the resolved file and ``cfg.paths.output_dir`` the run folder, so
    ``checkpoints/`` (ModelCheckpoint's dirpath is the checkpoint's, so its best score and path are restored:
    a worse epoch never becomes the best), the CSV/TensorBoard logs (appended, :func:`instantiate_loggers`),
    the exported model file and the results are the original run's. Before anything is replaced, the run's
    model files (``*.pth.tar``), ``results.{json,csv}``, ``export_path`` and — when another checkpoint than
    ``last.ckpt`` is resumed — ``last.ckpt`` are copied to ``*.bak``. Hydra's new folder keeps this resume's
    config (``.hydra/``) and log, and a note (:data:`CONTINUED_NOTE`) naming the continued folder; the run
    folder gets a line in :data:`RESUMES_LOG` and this run's log records in its log file."""
    global _continued_log

    if not cfg.get("ckpt_path") or not cfg.get("train", True):
        return None
    trust = bool(cfg.get("trust_checkpoint", False))
    ckpt = Path(str(cfg.ckpt_path))
    if str(cfg.ckpt_path) == "last":
        ckpt = find_last_checkpoint(cfg, current_experiment())
    ckpt = ckpt.resolve()
    info = checkpoint_info(ckpt, trust=trust)
    with open_dict(cfg):
        cfg.ckpt_path = str(ckpt)  # resolved once: resume_path() returns this file
    here = Path(cfg.paths.output_dir).resolve()
    run = run_folder_of(ckpt)
    reason = None if run == here else new_folder_reason(cfg)
    if reason is None and run is None:
        reason = "the checkpoint is not in a run's checkpoints/ folder"
    if reason is None and not os.access(run, os.W_OK):
        reason = f"{run} is not writable"
    if reason:
        log.info("resuming from %s: writing to the new run folder %s (%s)", ckpt, here, reason)
        return None
    if _rank_zero():
        if run != here:
            _continued_log = _log_to(run, here, _continued_log)
            here.mkdir(parents=True, exist_ok=True)
            (here / CONTINUED_NOTE).write_text(
                f"This run resumed {ckpt} and continues in {run}: its checkpoints, logs, model file and results "
                f"are there (set resume_new_folder=true to write to a new folder instead). This folder keeps the "
                f"resume's config (.hydra/) and log.\n")
        log.info("resuming from %s: continuing in %s (saved in epoch %d at step %d; this resume's config and log: %s)",
                 ckpt, run, info["epoch"] + 1, info["global_step"], here)
        last = run / "checkpoints" / str(OmegaConf.select(cfg, "callbacks.last_checkpoint.filename",
                                                          default="last.ckpt") or "last.ckpt")
        keep = [*sorted(run.glob("*.pth.tar")), run / "results.json", run / "results.csv",
                *([Path(cfg.export_path)] if cfg.get("export_path") else []), *([last] if last != ckpt else [])]
        for path in keep:
            bak = _backup(path)
            if bak is not None:
                log.info("kept a copy of %s as %s before the resumed run replaces it", path, bak.name)
        with (run / RESUMES_LOG).open("a") as f:
            f.write(f"{datetime.now().isoformat(timespec='seconds')} resumed from {ckpt} (saved in epoch "
                    f"{info['epoch'] + 1} at step {info['global_step']}); this resume's config and log: {here}\n")
    with open_dict(cfg):
        cfg.paths.output_dir = str(run)
    warnings.filterwarnings("ignore", message=re.escape(f"Checkpoint directory {os.path.realpath(run / 'checkpoints')}"
                                                        ) + " exists and is not empty")
    return run


def _log_to(run: Path, hydra_dir: Path, previous: logging.Handler | None) -> logging.Handler | None:
    """Append this process's log records to the continued run's log file (Hydra's own, ``train.log``, stays
    in ``hydra_dir``); replaces the handler an earlier call added."""
    root = logging.getLogger()
    if previous is not None:
        root.removeHandler(previous)
        previous.close()
    hydra_files = [h for h in root.handlers if isinstance(h, logging.FileHandler)
                   and Path(h.baseFilename).resolve().parent == hydra_dir]
    if not hydra_files:
        return None  # no Hydra log file (an API caller, a test)
    handler = logging.FileHandler(run / Path(hydra_files[0].baseFilename).name, mode="a")
    handler.setFormatter(hydra_files[0].formatter)
    handler.setLevel(hydra_files[0].level)
    root.addHandler(handler)
    return handler


def instantiate_loggers(cfg: DictConfig, continued: Path | None = None) -> list[Any]:
    """The ``logger`` group; in a continued run (:func:`continue_run`) every logger without a ``version``
    writes to the newest ``version_N`` folder the run already has (CSV: ``metrics.csv`` appended, its rows
    kept; TensorBoard: a new events file beside the old ones) instead of starting ``version_N+1``."""
    loggers = instantiate_group(cfg.get("logger"))
    if continued is None:
        return loggers
    nodes = [c for c in cfg.get("logger").values() if isinstance(c, DictConfig) and "_target_" in c]
    out = []
    for node, logger in zip(nodes, loggers):
        root = getattr(logger, "root_dir", None)
        versions = [int(p.name[8:]) for p in Path(root).glob("version_*") if p.is_dir() and p.name[8:].isdigit()] \
            if root and node.get("version") is None else []
        if versions:
            logger = hydra.utils.instantiate(node, version=max(versions))
            _keep_metrics_csv(logger)
        out.append(logger)
    return out


def _keep_metrics_csv(logger) -> None:
    """Lightning's CSV writer deletes an existing ``metrics.csv`` when it starts; keep its rows (the writer
    then appends, rewriting the header only when new columns come)."""
    from lightning.fabric.loggers import CSVLogger

    if not isinstance(logger, CSVLogger) or not _rank_zero():
        return
    path = Path(logger.log_dir) / "metrics.csv"
    aside = path.with_name(".metrics.csv.resuming")
    if aside.is_file() and not path.exists():
        os.replace(aside, path)  # an earlier resume stopped between the two renames
    if not path.is_file():
        return
    os.replace(path, aside)
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Experiment logs directory")
            writer = logger.experiment
    finally:
        os.replace(aside, path)
    with path.open(newline="") as f:
        header = next(csv.reader(f), [])
    writer.metrics_keys = list(header)


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
