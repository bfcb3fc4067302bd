"""The Hydra tasks of the hit-event models (``task: events`` in the experiment config):

``train_events``: fit HitNet on balanced windows (or the event tagger on crops of whole clips) → calibrate the temperature on validation windows →
tune the decoder on validation clips → export the model file (``<output_dir>/hitnet_<sport>.pth.tar``,
and ``export_path`` when set) → only then evaluate the test clips (event-set metrics, thesis-style
table per class; a failing table is reported and the run still succeeds). The tables say what the ball
input is (the clips' ``ball.csv``: annotated, tracker or detector); rows with synthetically degraded
tracks are added only when asked (``degraded_rows``; ``auto``: for simulated data only).

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
from inference.events.features import FeatureConfig
from inference.events.network import EventTagger
from inference.events.metrics import format_event_table
from inference.models.checkpoint import read_checkpoint
from training.common import guarded_table, resume_path, save_manifests, write_eval_results

from training.events.data.datamodule import EventDataModule
from training.events.synthetic.degrade import DegradeConfig, degrade_all
from training.events.evaluate import counts_for, detector_scorer, fit_temperature, score_all, tune_decoder
from training.events.synthetic.simulate import perturb

log = logging.getLogger(__name__)


def model_kind(module) -> str:
    """``tagger`` for the per-frame event tagger, else ``hitnet``."""
    return "tagger" if isinstance(module.net, EventTagger) else "hitnet"


def model_label(module) -> str:
    """The network's name in the tables, e.g. ``HitNet 2×64 bi`` or ``tagger 3×96``."""
    h = module.hparams
    if model_kind(module) == "tagger":
        return f"tagger {h.layers}×{h.hidden}"
    return f"HitNet {h.layers}×{h.hidden}{' bi' if h.bidirectional else ''}"


def detector_from_module(module, dm: EventDataModule, decode: DecodeParams | None = None,
                         meta: dict | None = None) -> EventDetector:
    return EventDetector(model_kind(module), dm.class_set, dm.features, decode or DecodeParams(), net=module.net,
                         window=dm.window, last_k=dm.last_k, lookahead=dm.lookahead, meta=meta or {})


def _first(n: int, max_n: int) -> torch.Tensor:
    """A fixed random draw of at most ``max_n`` of ``n`` indices."""
    return torch.randperm(n, generator=torch.Generator().manual_seed(0))[:max_n]


@torch.no_grad()
def _val_logits(module, dm: EventDataModule, max_n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Uncalibrated logits ``(N, C)`` and labels ``(N,)`` of at most ``max_n`` validation windows, or frames of
    the tagger's crops (padding left out)."""
    ds = dm.sets.get("val") or dm.example_set(dm.labelled("val"), "val")
    if model_kind(module) == "tagger":
        x, y = ds.all_frames()
        logits = torch.cat([module.net(x[i:i + 64]) for i in range(0, len(x), 64)])
        logits, y = logits.reshape(-1, logits.shape[-1]), y.reshape(-1)
        idx = torch.nonzero(y >= 0).flatten()
        idx = idx[_first(len(idx), max_n)]
        return logits[idx], y[idx]
    idx = _first(len(ds), max_n)
    return torch.cat([module.net(ds.x[idx[i:i + 8192]]) for i in range(0, len(idx), 8192)]), ds.y[idx]


def calibrate(module, dm: EventDataModule, max_windows: int = 200_000) -> float:
    """Fit the temperature on (up to ``max_windows``) validation windows, or validation frames of the
    tagger's crops; stored in the network."""
    module.net.eval()
    module.net.temperature.fill_(1.0)
    t = fit_temperature(*_val_logits(module, dm, max_windows))
    module.net.temperature.fill_(t)
    return t


def tune(det: EventDetector, dm: EventDataModule, passes: int = 2) -> float:
    """Tune the detector's decoder on the validation clips (annotated, plus degraded copies when the data
    module degrades tracks); returns the validation event F1."""
    val, tracks = dm.tuning_clips()
    probs = score_all(detector_scorer(det), val, tracks, desc="val scores")
    det.decode_params, f1 = tune_decoder(probs, val, dm.class_set, det.ref_fps, det.decode_params, passes=passes)
    return f1


def degraded_rows(cfg: DictConfig | None, dm) -> bool:
    """Whether the tables add synthetic-degradation rows: ``degraded_rows`` true/false; ``auto`` → only for
    simulated data (on real clips they would mix our noise model into a real track)."""
    setting = "auto" if cfg is None else cfg.get("degraded_rows", "auto")
    if setting in ("auto", None):
        return getattr(dm, "source", "synthetic") == "synthetic"
    return bool(setting)


def ball_inputs(clips, dm, override: str = "auto") -> str:
    """What the ball of these clips is, for table titles: ``annotated ball`` for simulated data, else the
    kinds of the clips' ``ball.csv`` (:func:`training.datasets.ball_input`) with their counts."""
    if getattr(dm, "source", "synthetic") == "synthetic":
        return "annotated ball (simulated rallies)"
    from inference.clipio import Clip
    from training.datasets import ball_input

    kinds: dict[str, int] = {}
    for c in clips:
        kind = ball_input(Clip(c.name), override) if Path(c.name).is_dir() else override.replace("auto", "annotated")
        kinds[kind] = kinds.get(kind, 0) + 1
    return "ball.csv: " + ", ".join(f"{k} ({v} clips)" for k, v in sorted(kinds.items()))


def event_tables(det: EventDetector, dm: EventDataModule, name: str, split: str = "test",
                 noise_seed: int = 7, max_clips: int | None = None, cfg: DictConfig | None = None
                 ) -> tuple[dict[str, float], str, list[dict]]:
    """Event-set metrics on ``split`` (its first ``max_clips``) with the clips' own ball track (``gt``);
    with :func:`degraded_rows`, also detector-like (:func:`perturb`, ``e2e``) and pipeline-like
    (:func:`~training.events.synthetic.degrade.degrade`, every clip degraded, ``deg``) tracks made from it.
    Returns the scores, the Markdown tables and one flat row per table line (results files)."""
    clips = [c.sim for c in dm.labelled(split)][: max_clips or None]
    scorer = detector_scorer(det)
    rng = np.random.default_rng(noise_seed)
    modes = [("gt", ball_inputs(clips, dm, str(cfg.get("ball_input", "auto")) if cfg is not None else "auto"),
              lambda: [c.ball for c in clips])]
    if degraded_rows(cfg, dm):
        modes += [("e2e", "detector-like ball made from it (misses, jitter, false positives)",
                   lambda: [perturb(c, rng) for c in clips]),
                  ("deg", "pipeline-like ball made from it (training.events.synthetic.degrade, every clip degraded)",
                   lambda: degrade_all(clips, noise_seed, DegradeConfig(p_clean=0.0)))]
    out, tables, rows = {}, [], []
    for mode, what, tracks in modes:
        probs = score_all(scorer, clips, tracks(), desc=f"{split} {mode}")
        counts = counts_for(probs, clips, dm.class_set, det.ref_fps, det.decode_params)
        s = counts.scores()
        out.update({f"events/{mode}_{k}": v for k, v in s.items() if k in ("recall", "acc", "prec", "f1")})
        tables.append(format_event_table([(name, counts)], title=f"{split}, {len(clips)} clips, {what}, "
                                         "tolerance ±2 frames at 50 fps (±1 at 25/30, ±2 at 60)"))
        rows += table_rows(counts, model=name, split=split, ball_input=what, table=mode)
    return out, "\n\n".join(tables), rows


def table_rows(counts, **common) -> list[dict]:
    """One results row per class of an event table (``all`` first), with the ``common`` columns."""
    return [{**common, "class": cname, **counts.scores(c)}
            for c, cname in [(None, "all"), *[(i + 1, n) for i, n in enumerate(counts.classes[1:])]]]


def train_events(cfg: DictConfig) -> dict[str, float]:
    from training.common import build

    log.info("config:\n%s", OmegaConf.to_yaml(cfg, resolve=False))
    if cfg.get("threads"):
        torch.set_num_threads(int(cfg.threads))  # small GRUs: one thread is fastest on a shared CPU
    dm, module, trainer = build(cfg)
    if cfg.get("init_weights"):  # fine-tune from an exported model file of the same architecture
        init_events(module, cfg.init_weights, dm)
    metrics: dict[str, float] = {}
    dev = bool(cfg.trainer.get("fast_dev_run"))
    trainer.fit(module, datamodule=dm, ckpt_path=resume_path(cfg), weights_only=not cfg.get("trust_checkpoint", False))
    metrics.update({k: float(v) for k, v in trainer.callback_metrics.items()})
    if not trainer.is_global_zero:  # DDP: calibration, decoder tuning, export and tables run once, on rank 0
        return metrics
    best = getattr(trainer.checkpoint_callback, "best_model_path", "") if trainer.checkpoint_callback else ""
    if best and not dev:
        module.load_state_dict(read_checkpoint(best)["state_dict"])
    metrics["events/temperature"] = calibrate(module, dm)
    det = detector_from_module(module, dm, meta={"experiment": OmegaConf.to_container(cfg.get("tags") or []),
                                                 "data": {"source": dm.source, "root": dm.root,
                                                          "counts": dm.counts, "seed": dm.seed}})
    metrics["events/val_f1"] = det.meta["val_f1"] = tune(det, dm, passes=1 if dev else 2)
    name = model_label(module)
    save_manifests(dm, cfg)
    return test_and_export(cfg, det, dm, metrics, lambda: event_tables(det, dm, name, cfg=cfg))


def init_events(module, path: str | Path, dm: EventDataModule | None = None) -> None:
    """Start from an exported hit-event model file of the same network (class set, features, window):
    a mismatch with the data's settings is an error naming the config keys to set.

    One mismatch is allowed on purpose: a ball-only file (``features.poses: false``) warm-starts a
    player-aware network (``data.features.poses=true``) — the ball columns keep their weights and the
    players block starts at zero (:func:`widen_to_players`), so training begins from the ball-only model's
    predictions and learns what the players add."""
    blob = load_model_file(path)
    file_feats = FeatureConfig.from_model_file(blob["features"])
    widen = dm is not None and dm.features.poses and not file_feats.poses
    if dm is not None:
        wanted = {"data.window": blob.get("window"), "data.last_k": blob.get("last_k"),
                  "data.lookahead": blob.get("lookahead", 0),
                  "data.class_set": blob["class_set"].get("name")}
        have = {"data.window": dm.window, "data.last_k": dm.last_k, "data.lookahead": dm.lookahead,
                "data.class_set": dm.class_set.name}
        # rel_scale only scales the players block; filling short holes is preprocessing the weights do not depend on
        skip = ({"poses", "rel_scale"} if widen else set()) | {"fill_holes_s"}
        feats = file_feats.to_dict()
        wanted.update({f"data.features.{k}": v for k, v in feats.items() if k not in skip})
        have.update({f"data.features.{k}": v for k, v in dm.features.to_dict().items() if k not in skip})
        diff = [f"{k}={wanted[k]}" for k in wanted if k in have and wanted[k] is not None and wanted[k] != have[k]]
        if diff:
            raise ValueError(f"init_weights={path} was trained with other data settings: set {' '.join(diff)}")
    state = blob["state_dict"]
    if widen:
        state = widen_to_players(state, file_feats.n_features, dm.features.n_features)
    try:
        module.net.load_state_dict(state)
    except RuntimeError as e:
        raise ValueError(f"init_weights={path} does not fit this HitNet (model.hidden, model.layers, "
                         f"data.features and data.class_set must match the file's): {str(e)[:300]}") from None
    log.info("initialised from %s%s", path, " (ball-only weights; the players block starts at zero)" if widen else "")


def widen_to_players(state: dict[str, torch.Tensor], n_ball: int, n_features: int) -> dict[str, torch.Tensor]:
    """A ball-only HitNet state dict made to read ``n_features`` columns: the first GRU layer's input
    weights ``(3H, n_ball)`` (each direction) get ``n_features − n_ball`` zero columns appended, the
    players block's place (:attr:`FeatureConfig.player_offset` = ``n_ball``). Every other tensor is kept."""
    out = dict(state)
    for k, w in state.items():
        if k.startswith("gru.weight_ih_l0"):
            if w.shape[1] != n_ball:
                raise ValueError(f"{k} reads {w.shape[1]} features, expected {n_ball} (ball-only model file)")
            out[k] = torch.cat([w, w.new_zeros(w.shape[0], n_features - n_ball)], dim=1)
    return out


def test_and_export(cfg: DictConfig, det: EventDetector, dm, metrics: dict[str, float], tables) -> dict[str, float]:
    """After training: save the model file to the run folder (and ``export_path``) first; then, unless
    ``test=false``, score the test split (``tables() → (scores, markdown[, rows])``), print the table,
    write the rows to ``<output_dir>/results.{json,csv}`` and save the model file again with the scores in
    its meta. A failing table is reported (:func:`training.run.guarded_table`): the model stays saved.
    Returns ``metrics`` with the test scores added."""
    outs = [Path(cfg.paths.output_dir) / f"{'tagger' if det.kind == 'tagger' else 'hitnet'}_{dm.class_set.sport or 'model'}.pth.tar"]
    outs += [Path(cfg.export_path)] if cfg.get("export_path") else []
    for out in outs:
        det.save(out)
        log.info("exported %s", out)
    if not cfg.get("test", True):
        return metrics

    def run_tables() -> dict[str, float]:
        scores, table, *rows = tables()
        print("\n" + table)
        if rows:
            write_eval_results(rows[0], cfg)
        det.meta["test"] = {k: float(v) for k, v in scores.items()}
        for out in outs:
            det.save(out)
        return scores

    metrics.update(guarded_table("test", run_tables, cfg))
    return metrics


def load_detector(path: str | Path, cfg: DictConfig, dm: EventDataModule) -> EventDetector:
    """An exported model file, or a Lightning checkpoint of ours (then calibrated and tuned on val)."""
    try:
        return EventDetector.from_blob(load_model_file(path))
    except ValueError:
        pass
    module = hydra.utils.instantiate(cfg.model, _convert_="all")
    state = read_checkpoint(path, trust=bool(cfg.get("trust_checkpoint", False)))
    if not isinstance(state, dict) or "state_dict" not in state:
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
    split = str(cfg.get("split") or "test")
    if split == "auto":
        every = dm.source == "folder" and all(s.eval_split() == "all" for s in dm.sources)
        split = "all" if every else "test"  # clips stating their split: the test split, as for a manifest
    scores, table, rows = event_tables(det, dm, f"{det.kind} ({path.name})", split=split,
                                       max_clips=cfg.get("max_clips"), cfg=cfg)
    if "val_f1" in det.meta:
        print(f"\nvalidation event F1 after decoder tuning: {det.meta['val_f1']:.3f}")
    print("\n" + table)
    paths = write_eval_results([{**r, "checkpoint": str(path)} for r in rows], cfg)
    print(f"\nresults: {paths[0]}, {paths[1]}")
    if cfg.get("export_path"):  # e.g. a Lightning checkpoint, calibrated and tuned here, shipped as a model file
        det.meta["test"] = {k: float(v) for k, v in scores.items()}
        det.save(cfg.export_path)
        log.info("exported %s", cfg.export_path)
    return scores
