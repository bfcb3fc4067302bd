"""Callbacks that keep a run's work and say how it goes, in a terminal and in a log file.

- :class:`SafeCheckpoint` writes ``last.ckpt`` at the end of every training epoch (validation or not),
  every ``every_n_minutes`` of training, and when the run stops on an exception, Ctrl-C or SIGTERM; the
  file is replaced atomically, so a crash while writing never leaves half a checkpoint.
  ``python train.py … ckpt_path=last`` resumes from it.
- :class:`ProgressLog` logs one line every ``every_n_steps`` training steps (and at each epoch's end):
  epoch, step, loss (last and running mean), seconds per step, samples/s and the remaining time of the
  epoch and of the run. Unlike a progress bar it reads well in ``train.log`` or ``… > log.txt``.
"""
from __future__ import annotations

import logging
import math
import os
import signal
import threading
import time
from pathlib import Path

import lightning as L
import torch
from lightning.pytorch.callbacks import Callback, ModelCheckpoint

log = logging.getLogger(__name__)


class SafeCheckpoint(Callback):
    """``dirpath/filename`` (default ``last.ckpt``), kept current (see the module docstring).

    Args:
        dirpath: the run's checkpoint folder.
        every_n_minutes: also save after this much training time since the last save (None: never).
        every_n_train_steps: also save every this many optimiser steps (None: never).
        on_sigterm: turn SIGTERM (``kill PID``, a cluster's pre-emption) into a graceful stop with a save.
    """

    def __init__(self, dirpath: str, filename: str = "last.ckpt", every_n_minutes: float | None = 10.0,
                 every_n_train_steps: int | None = None, on_sigterm: bool = True):
        super().__init__()
        self.path = Path(dirpath) / filename
        self.every_s = None if every_n_minutes is None else float(every_n_minutes) * 60.0
        self.every_steps = every_n_train_steps
        self.on_sigterm = on_sigterm
        self._last = time.monotonic()
        self._old_handler = None
        self.saves = 0

    @property
    def state_key(self) -> str:
        return f"SafeCheckpoint{{{self.path.name}}}"

    # ------------------------------------------------------------------------------------ saving
    def save(self, trainer: L.Trainer, why: str) -> Path | None:
        """Write the checkpoint atomically (temporary file, then rename); returns its path."""
        if trainer.sanity_checking or getattr(trainer, "fast_dev_run", False):
            return None
        tmp = self.path.with_name(f".{self.path.name}.tmp")
        try:
            trainer.save_checkpoint(tmp)
            if trainer.is_global_zero:
                os.replace(tmp, self.path)
        except Exception as e:  # noqa: BLE001 - a failed save is reported, the older file stays
            log.error("could not save %s (%s): %s: %s", self.path, why, type(e).__name__, e)
            return None
        self._last = time.monotonic()
        self.saves += 1
        log.debug("saved %s (%s)", self.path, why)
        return self.path

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx) -> None:
        step = trainer.global_step
        due_steps = self.every_steps and step > 0 and step % self.every_steps == 0
        due_time = self.every_s is not None and time.monotonic() - self._last >= self.every_s
        if due_steps or due_time:
            self.save(trainer, f"step {step}")

    def on_train_epoch_end(self, trainer, pl_module) -> None:
        # Lightning calls checkpoint callbacks last: a ModelCheckpoint that saves now updates its best-model state
        # first (its own call then finds the step done), so last.ckpt holds it and a resumed run keeps its best
        for cb in trainer.checkpoint_callbacks:
            if isinstance(cb, ModelCheckpoint):
                cb.on_train_epoch_end(trainer, pl_module)
        self.save(trainer, f"end of {epoch_of(trainer)}")

    def on_exception(self, trainer, pl_module, exception: BaseException) -> None:
        why = "interrupted" if isinstance(exception, KeyboardInterrupt) else f"{type(exception).__name__}"
        path = self.save(trainer, why)
        if path is not None:
            log.warning("%s at %s, step %d: saved %s — resume with ckpt_path=%s (or ckpt_path=last)",
                        why, epoch_of(trainer), trainer.global_step, path, path)

    # ------------------------------------------------------------------------------------ SIGTERM
    def setup(self, trainer, pl_module, stage: str) -> None:
        self._last = time.monotonic()
        if stage == "fit" and self.on_sigterm and threading.current_thread() is threading.main_thread():
            self._old_handler = signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)

    def teardown(self, trainer, pl_module, stage: str) -> None:
        if self._old_handler is not None:
            signal.signal(signal.SIGTERM, self._old_handler)
            self._old_handler = None


def epoch_of(trainer) -> str:
    """``epoch 2/30``: the epoch under way, counted from 1 (Lightning's ``current_epoch`` counts from 0), out of
    ``max_epochs`` when there is a limit; the one numbering of every line the callbacks write."""
    limit = trainer.max_epochs
    return f"epoch {trainer.current_epoch + 1}" + (f"/{limit}" if limit is not None and limit > 0 else "")


def _raise_keyboard_interrupt(signum, frame):  # noqa: ARG001 - a signal handler's signature
    raise KeyboardInterrupt(f"signal {signum}")


def _duration(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "?"
    seconds = int(round(seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m" if h else f"{m}m{s:02d}s"


class ProgressLog(Callback):
    """One log line per ``every_n_steps`` training steps (see the module docstring).

    Speeds are measured over training steps only (validation time is left out of s/step); the ETAs add
    nothing for validation.
    """

    def __init__(self, every_n_steps: int = 50, mean_over: int = 50):
        super().__init__()
        if every_n_steps < 1:
            raise ValueError("every_n_steps must be >= 1")
        self.every = int(every_n_steps)
        self.mean_over = int(mean_over)
        self.losses: list[float] = []
        self.lines: list[str] = []  # what was logged (tests, callers)
        self._t_step = None
        self._busy = 0.0
        self._steps = 0
        self._t0 = time.monotonic()

    def on_train_start(self, trainer, pl_module) -> None:
        self._t0 = time.monotonic()
        total = trainer.estimated_stepping_batches
        self._emit(f"training: {trainer.max_epochs} epochs, {trainer.num_training_batches} steps per epoch, "
                   f"{total if math.isfinite(total) else '?'} steps in all; a line every {self.every} steps")

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx) -> None:
        self._t_step = time.monotonic()

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx) -> None:
        if self._t_step is not None:
            self._busy += time.monotonic() - self._t_step
            self._steps += 1
        loss = outputs.get("loss") if isinstance(outputs, dict) else outputs
        if isinstance(loss, torch.Tensor):
            self.losses = (self.losses + [float(loss.detach())])[-self.mean_over:]
        if (batch_idx + 1) % self.every == 0:
            self._emit(self._line(trainer, batch, batch_idx))

    def on_train_epoch_end(self, trainer, pl_module) -> None:
        metrics = {k: float(v) for k, v in trainer.callback_metrics.items() if k.startswith("val/")}
        shown = ", ".join(f"{k} {v:.4f}" for k, v in sorted(metrics.items()))
        self._emit(f"{epoch_of(trainer)} done after "
                   f"{_duration(time.monotonic() - self._t0)}" + (f": {shown}" if shown else ""))

    def _line(self, trainer, batch, batch_idx: int) -> str:
        per_step = self._busy / max(self._steps, 1)
        n_batch = len(batch[0]) if isinstance(batch, (list, tuple)) and hasattr(batch[0], "__len__") else 0
        per_epoch = trainer.num_training_batches
        total = trainer.estimated_stepping_batches
        done = trainer.global_step
        left_epoch = (per_epoch - batch_idx - 1) * per_step if math.isfinite(per_epoch) else float("nan")
        left_run = (total - done) * per_step if math.isfinite(total) else float("nan")
        loss = f"loss {self.losses[-1]:.4g} (mean {sum(self.losses) / len(self.losses):.4g})" if self.losses else "loss ?"
        speed = f"{per_step:.2f} s/step" + (f", {n_batch / per_step:.1f} samples/s" if n_batch and per_step else "")
        return (f"{epoch_of(trainer)} · step {batch_idx + 1}/{per_epoch} "
                f"(total {done}/{total if math.isfinite(total) else '?'}) · {loss} · {speed} · "
                f"ETA epoch {_duration(left_epoch)}, run {_duration(left_run)}")

    def _emit(self, line: str) -> None:
        self.lines.append(line)
        log.info(line)
