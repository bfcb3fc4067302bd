"""What multi-process (DDP) training needs beyond Lightning's own strategy: global metrics and shards.

- :func:`all_reduce_sum` adds count arrays (TP/FP/FN per rank, per class) over every process, so F1 and
  the other ratios are computed from the *global* counts: each rank validates only its shard.
- :func:`all_gather_concat` joins small per-rank arrays (AP needs every score) in rank order.
- :func:`eval_sampler` gives each rank its share of a validation/test set **without** the padding of
  ``DistributedSampler`` (which repeats samples so that every rank has as many): the union of the shards
  is exactly the single-process set, so the global figures equal the single-process ones.

Outside a process group every function is the identity (one process: nothing to reduce).

The metrics logged from these global counts are equal on every rank, so Lightning's advice to log them with
``sync_dist=True`` does not apply: :func:`quiet_sync_dist_advice` silences it for them (:data:`GLOBAL_METRICS`)
and for no other metric.

Example:
    >>> counts = all_reduce_sum(np.array([tp, fp, fn]))   # global counts on every rank
"""
from __future__ import annotations

import warnings
from collections.abc import Sized

import numpy as np
import torch
from torch.utils.data import DistributedSampler, Sampler


GLOBAL_METRICS = r"(val|test)/(precision|recall|f1|f1_best|f1_tracker|f1_max_score|f1_blob|accuracy|acc|ap|rmse_px|tp|fp1|fp2|fn|tn)"
"""The epoch metrics the modules compute from :func:`all_reduce_sum` counts (detectors'
``training.detection.module``, hit events' ``log_event_metrics``) and log without ``sync_dist``."""


def quiet_sync_dist_advice() -> None:
    """Silence Lightning's "It is recommended to use ``self.log(NAME, ..., sync_dist=True)``" warning for
    :data:`GLOBAL_METRICS` (already global: a second reduction adds nothing); any other metric still warns."""
    from lightning.fabric.utilities.warnings import PossibleUserWarning

    warnings.filterwarnings("ignore", message=rf"It is recommended to use `self\.log\('{GLOBAL_METRICS}',",
                            category=PossibleUserWarning)


def world() -> tuple[int, int]:
    """``(rank, world_size)`` of the current process group, ``(0, 1)`` outside one."""
    if torch.distributed.is_available() and torch.distributed.is_initialized():
        return torch.distributed.get_rank(), torch.distributed.get_world_size()
    return 0, 1


def _device() -> torch.device:
    """The device collectives of this process group run on (NCCL needs CUDA tensors)."""
    if torch.distributed.get_backend() == "nccl":
        return torch.device("cuda", torch.cuda.current_device())
    return torch.device("cpu")


def all_reduce_sum(values) -> np.ndarray:
    """``values`` (any shape, counts or sums) added over every process; float64 (exact for counts < 2⁵³)."""
    arr = np.asarray(values, dtype=np.float64)
    if world()[1] == 1:
        return arr
    t = torch.as_tensor(arr, device=_device())
    torch.distributed.all_reduce(t, op=torch.distributed.ReduceOp.SUM)
    return t.cpu().numpy()


def all_gather_concat(values: np.ndarray) -> np.ndarray:
    """Per-rank arrays ``(N_r, ...)`` joined along the first axis in rank order (any N_r)."""
    values = np.asarray(values)
    size = world()[1]
    if size == 1:
        return values
    parts: list = [None] * size
    torch.distributed.all_gather_object(parts, values)
    return np.concatenate(parts)


class EvalShard(DistributedSampler):
    """Rank ``rank``'s share of ``base`` (a sampler or a sized dataset): items ``rank, rank + world, …`` of
    its deterministic order, **without padding**: the shards of all ranks hold the whole set exactly once
    (ranks may differ by one item). A ``DistributedSampler`` subclass, so Lightning does not wrap it again.
    """

    def __init__(self, base, rank: int, world_size: int):  # no super().__init__: no padding, no shuffling
        self.base, self.rank, self.num_replicas = base, int(rank), int(world_size)
        self.epoch, self.shuffle, self.drop_last = 0, False, False

    def _order(self) -> list[int]:
        return list(self.base) if isinstance(self.base, Sampler) else list(range(len(self.base)))

    def __iter__(self):
        return iter(self._order()[self.rank::self.num_replicas])

    def __len__(self) -> int:
        n = len(self.base) if isinstance(self.base, Sized) else len(self._order())
        return len(range(self.rank, n, self.num_replicas))


def eval_sampler(trainer, base) -> Sampler | None:
    """The sampler of a validation/test loader under ``trainer``: None with one process (keep the
    loader's own), else this rank's :class:`EvalShard` of ``base`` (a sampler or a dataset). Lightning's
    own ``DistributedSampler`` would repeat samples to even out the ranks, counting some frames twice."""
    if trainer is None or int(getattr(trainer, "world_size", 1)) <= 1:
        return None
    return EvalShard(base, trainer.global_rank, trainer.world_size)


__all__ = ["GLOBAL_METRICS", "EvalShard", "all_gather_concat", "all_reduce_sum", "eval_sampler", "quiet_sync_dist_advice",
           "world"]
