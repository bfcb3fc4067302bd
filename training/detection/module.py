"""The LightningModule that trains a ball detector (TrackNetV2, MonoTrack or WASB) on heatmaps.

Validation scores what ``eval.py`` scores (:mod:`.clip_scores`): each output heatmap becomes ball
candidates as inference makes them, the validation clips are rebuilt from their windows and run through
the tracker and the max-score baseline, and TP/FP1/FP2/FN/TN are counted at ``tau_px`` in original-frame
pixels, leaving out unlabelled frames and the visibilities of ``ignore_flags``. ``val/f1`` (the best
checkpoint, ``val_post``: ``tracker`` by default) is that F1; ``val/f1_tracker``, ``val/f1_max_score`` and
``val/f1_blob`` (each frame's best blob alone, the earlier measure) are logged beside it. The loss counts
only the labelled frames of a window.
Every checkpoint stores the input description (``inference.models.checkpoint.META_KEY``).

Example (what Hydra instantiates from conf/model/*.yaml):
    >>> module = BallDetector(net=build_model("wasb"), loss=HeatmapLoss("wbce"),
    ...                       optimizer=partial(torch.optim.Adam, lr=1e-3))
"""
from __future__ import annotations

from collections.abc import Callable

import lightning as L
import numpy as np
import torch
from torch import nn

from inference.detection.metrics import DetectionCounts, DetectionReport, Outcome, average_precision, classify_frames
from inference.detection.postprocess import PostprocessConfig
from inference.models.checkpoint import META_KEY, DetectorInput, architecture_of, load_weights
from training.detection.clip_scores import CANDIDATE_COLUMNS, FRAME_COLUMNS, POSTS, blobs, clip_reports, window_rows
from training.distributed import all_gather_concat, all_reduce_sum, world
from training.finetune import freeze as freeze_layers
from training.finetune import freeze_unused, hold_frozen_norms, trainable


class BallDetector(L.LightningModule):
    """Heatmap training of a detector network.

    Args:
        net: maps (B, 3·F_in, H, W) to (B, F_out, H, W) logits.
        loss: heatmap loss on logits (training/detection/losses.py).
        optimizer: a partial taking the parameters; scheduler: a partial taking the optimizer (or None).
        pretrained: a checkpoint to start from (WASB-SBDT public format or ours); never downloaded.
        trust_checkpoint: allow ``pretrained`` to hold pickled objects (runs their code).
        freeze: prefixes of parameter names that do not learn (e.g. WASB's stem ``[conv1, bn1, conv2, bn2,
            layer1]``); their batch-norm statistics stay as loaded.
        tau_px: validation distance threshold in original-frame pixels (4: eval.py's first table).
        val_post: what ``val/f1`` and ``test/f1`` score: ``tracker`` or ``max-score`` over whole clips (as
            eval.py), or ``blob`` (each frame's best blob, no tracker).
        ignore_flags: ground-truth visibilities left out of validation (default [3]: occluded, as eval.py).
        threshold: heatmap probability threshold of the blob detection.
        channels_last: keep weights and inputs in NHWC memory format (about ×1.4 faster training steps
            for WASB on a CPU; also what GPU tensor cores prefer). The state_dict is unchanged.
        compile: run the forward pass through ``torch.compile`` (weights and checkpoints unchanged).
    """

    def __init__(self, net: nn.Module, loss: nn.Module, optimizer: Callable, scheduler: Callable | None = None,
                 pretrained: str | None = None, tau_px: float = 4.0, threshold: float = 0.5,
                 channels_last: bool = False, compile: bool = False, trust_checkpoint: bool = False,
                 freeze: list[str] | None = None, ignore_flags: list[int] | None = (3,), val_post: str = "tracker"):
        if val_post not in (*POSTS, "blob"):
            raise ValueError(f"val_post must be one of {(*POSTS, 'blob')}, got {val_post!r}")
        super().__init__()
        # factories are kept as attributes, not hyperparameters: checkpoints stay loadable with weights_only
        # (the loggers get the whole composed config from training.run.log_hyperparameters)
        self.save_hyperparameters(ignore=["net", "loss", "optimizer", "scheduler"])
        self.optimizer_factory, self.scheduler_factory = optimizer, scheduler
        self.net = net
        self.loss_fn = loss
        if pretrained:
            load_weights(self.net, pretrained, trust=trust_checkpoint)
        self.frozen = freeze_layers(self.net, freeze or [])
        # parameters the forward pass never uses (WASB's stage4 fuse paths into branches 1-3) learn
        # nothing: frozen, so DDP needs no find_unused_parameters; they stay in the state_dict
        self.unused = freeze_unused(self.net, torch.zeros(1, 3 * int(getattr(net, "frames_in", 3)), 32, 32))
        self.best: dict[str, float] = {}  # best val/f1 of the run, sanity check left out (val/f1_best)
        if channels_last:
            self.net = self.net.to(memory_format=torch.channels_last)
        # kept out of the module tree so state_dict names stay those of the plain network
        self._forward_fn = {"net": torch.compile(self.net) if compile else self.net}
        self.outputs: dict[str, list[tuple]] = {"val": [], "test": []}
        self.clip_rows: dict[str, list[tuple]] = {"val": [], "test": []}  # (candidate rows, frame rows) per batch

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, 3·F_in, H, W) → (B, F_out, H, W) logits."""
        if self.hparams.channels_last:
            x = x.contiguous(memory_format=torch.channels_last)
        return self._forward_fn["net"](x)

    def train(self, mode: bool = True):
        super().train(mode)
        if mode and self.frozen:
            hold_frozen_norms(self.net, self.frozen)
        return self

    def on_train_batch_start(self, batch, batch_idx: int) -> None:
        # Lightning restores submodule modes one by one after validation (bypassing train() above): the
        # frozen layers' batch-norm statistics must stay those loaded, so hold them before every step
        if self.frozen:
            hold_frozen_norms(self.net, self.frozen)

    def input_spec(self) -> DetectorInput:
        """The input this network is trained on: the data module's normalisation and size when attached."""
        dm = getattr(self._trainer, "datamodule", None) if self._trainer is not None else None
        hp = dm.hparams if dm is not None and hasattr(dm, "hparams") else {}
        net = self.net
        return DetectorInput(architecture_of(net), int(getattr(net, "frames_in", 3)), int(getattr(net, "frames_out", 3)),
                             str(hp.get("normalize", "imagenet")), tuple(hp.get("net_size", (288, 512))), "stored")

    def on_save_checkpoint(self, checkpoint: dict) -> None:
        checkpoint[META_KEY] = self.input_spec().to_dict()
        if "val/f1" in self.best:
            checkpoint["val_f1_best"] = self.best["val/f1"]  # a resumed run keeps its best so far

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        if "val_f1_best" in checkpoint:
            self.best["val/f1"] = float(checkpoint["val_f1_best"])

    def training_step(self, batch, batch_idx):
        x, y, meta = batch
        loss = self.loss_fn(self(x), y, meta.get("labelled"))
        self.log("train/loss", loss, prog_bar=True, on_step=True, on_epoch=True, batch_size=len(x), sync_dist=True)
        return loss

    def _eval_step(self, batch, split: str):
        x, y, meta = batch
        logits = self(x)
        loss = self.loss_fn(logits, y, meta.get("labelled"))
        self.log(f"{split}/loss", loss, prog_bar=True, on_epoch=True, batch_size=len(x), sync_dist=True)
        probs = torch.sigmoid(logits).float().cpu().numpy()
        self._count(probs, meta, split)

    def validation_step(self, batch, batch_idx):
        self._eval_step(batch, "val")

    def test_step(self, batch, batch_idx):
        self._eval_step(batch, "test")

    def _count(self, probs: np.ndarray, meta: dict, split: str) -> None:
        """Decode each heatmap to at most one ball and compare with the truth in original pixels."""
        B, Fo = probs.shape[:2]
        scale = meta["lb_scale"].numpy()
        pad = meta["lb_pad"].numpy()
        offset = meta["offset"].numpy()
        vis = meta["visibility"].numpy()
        gt = meta["xy_px"].numpy()
        config = PostprocessConfig(threshold=float(self.hparams.threshold))
        cands = [[blobs(probs[b, f], config) for f in range(Fo)] for b in range(B)]   # found once, used twice
        if "fps" in meta and "size" in meta:  # the clip-level score (eval.py's post-processing)
            frames_in = int(getattr(self.net, "frames_in", Fo))
            self.clip_rows[split].append(window_rows(probs, meta, frames_in, config, candidates=cands))
        pred_vis = np.zeros((B, Fo), bool)
        pred_xy = np.full((B, Fo, 2), np.nan)
        score = np.zeros((B, Fo))
        for b in range(B):
            for f in range(Fo):
                cand = cands[b][f]
                if len(cand.score):
                    k = int(np.argmax(cand.score))
                    pred_vis[b, f] = True
                    pred_xy[b, f] = (cand.xy[k] + offset[b] - pad[b]) / scale[b]
                    score[b, f] = cand.score[k]
        self.outputs[split].append((pred_vis.ravel(), pred_xy.reshape(-1, 2), score.ravel(), vis.ravel(),
                                    gt.reshape(-1, 2)))

    def report(self, split: str) -> DetectionReport:
        """The :class:`DetectionReport` of the frames of ``split`` seen since the last call, over **every**
        process: TP/FP1/FP2/FN/TN and the squared distances are summed across ranks before the ratios, the
        AP ranks the scores of all ranks (each rank validates only its shard)."""
        parts = [np.concatenate(a) for a in zip(*self.outputs[split])] if self.outputs[split] else [
            np.zeros(0, bool), np.zeros((0, 2)), np.zeros(0), np.zeros(0, np.int64), np.zeros((0, 2))]
        self.outputs[split] = []
        pred_vis, pred_xy, score, vis, gt = parts
        tau = float(self.hparams.tau_px)
        outcome, dist = classify_frames(pred_vis, pred_xy, vis, gt, tau,
                                        ignore_flags=tuple(self.hparams.ignore_flags or ()))
        c = DetectionCounts.from_outcomes(outcome)
        located = np.isfinite(dist)
        total = all_reduce_sum([c.tp, c.fp1, c.fp2, c.fn, c.tn, np.sum(dist[located] ** 2), located.sum()])
        counts = DetectionCounts(*(int(round(v)) for v in total[:5]))
        rmse = float(np.sqrt(total[5] / total[6])) if total[6] > 0 else float("nan")
        ranked = np.isin(outcome, [Outcome.TP, Outcome.FP1, Outcome.FP2])
        pairs = all_gather_concat(np.stack([score[ranked], outcome[ranked] == Outcome.TP], axis=1).reshape(-1, 2))
        ap = average_precision(pairs[:, 0], pairs[:, 1] > 0, counts.tp + counts.fn)
        return DetectionReport(counts, rmse, ap, tau)

    def clip_reports(self, split: str) -> dict[str, DetectionReport]:
        """Per post-processing, the report over the whole clips of ``split`` seen since the last call, over
        every process (each rank's rows gathered, every rank scores them all: the same figures)."""
        parts = self.clip_rows[split]
        self.clip_rows[split] = []
        cands = np.concatenate([p[0] for p in parts]) if parts else np.zeros((0, len(CANDIDATE_COLUMNS)))
        frames = np.concatenate([p[1] for p in parts]) if parts else np.zeros((0, len(FRAME_COLUMNS)))
        cands, frames = all_gather_concat(cands), all_gather_concat(frames)
        if not len(frames):  # a data module whose windows carry no fps/size: the blob measure only
            return {}
        return clip_reports(cands, frames, float(self.hparams.tau_px), tuple(self.hparams.ignore_flags or ()))

    def _log_counts(self, split: str) -> None:
        if not self.outputs[split] and world()[1] == 1:
            return
        blob = self.report(split)
        reports = {"blob": blob}
        if self.clip_rows[split] or world()[1] > 1:
            reports.update(self.clip_reports(split))
        post = self.hparams.get("val_post", "tracker")
        values = reports.get(post, blob).as_dict()
        # already global (equal on every rank): logged as they are, no second reduction
        for name in ("precision", "recall", "f1", "accuracy", "ap", "rmse_px", "tp", "fp1", "fp2", "fn", "tn"):
            value = float(values[name])
            self.log(f"{split}/{name}", value if value == value else 0.0, prog_bar=name == "f1")
        for name, report in reports.items():
            self.log(f"{split}/f1_{name.replace('-', '_')}", float(report.f1))
        if split == "val" and not self.trainer.sanity_checking:
            self.best["val/f1"] = max(self.best.get("val/f1", -1.0), float(values["f1"]))
            self.log("val/f1_best", self.best["val/f1"])

    def on_validation_epoch_end(self) -> None:
        self._log_counts("val")

    def on_test_epoch_end(self) -> None:
        self._log_counts("test")

    def configure_optimizers(self):
        opt = self.optimizer_factory(params=trainable(self))
        if self.scheduler_factory is None:
            return opt
        return {"optimizer": opt, "lr_scheduler": {"scheduler": self.scheduler_factory(optimizer=opt),
                                                   "interval": "epoch"}}
