"""The event tagger's examples: crops of whole labelled clips, every frame with a class
(:class:`SequenceSet`), beside HitNet's windows (:class:`~training.events.data.datamodule.WindowSet`).

Example:
    >>> ds = SequenceSet(dm.labelled("train"), length=200, radius=1)
    >>> x, y = ds[0]          # (200, F) float32, (200,) int64 (-100: padding)
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch
from torch.utils.data import Dataset

if TYPE_CHECKING:
    from training.events.data.datamodule import LabelledClip

IGNORE = -100  # padding frames: no loss, no score


def frame_targets(y: np.ndarray, radius: int) -> np.ndarray:
    """``(T,)`` per-frame classes (events on one frame) → the same with each event spread over ± ``radius``
    frames (a later event wins where two overlap)."""
    out = np.zeros(len(y), np.int64)
    for f in np.flatnonzero(y):
        out[max(f - radius, 0):f + radius + 1] = y[f]
    return out


class SequenceSet(Dataset):
    """Crops of ``length`` frames of labelled clips.

    ``random=True`` (training): item ``i`` is a random crop of clip ``i % n_clips`` (``repeats`` items per
    clip and epoch; the offset drawn from torch's RNG, which ``seed_everything(workers=True)`` seeds in each
    loader worker); else (validation, test) the clips cut into consecutive crops, the last one padded.
    ``clips`` may be replaced (new degraded tracks each epoch: same clips, same labels)."""

    def __init__(self, clips: list[LabelledClip], length: int, radius: int = 1, random: bool = True,
                 repeats: int = 1):
        if length < 8:
            raise ValueError(f"data.sequence must be at least 8 frames, got {length}")
        self.clips, self.length, self.radius, self.random, self.repeats = clips, int(length), int(radius), random, repeats
        self.targets = [frame_targets(c.y, self.radius) for c in clips]
        self.index = [(k, s) for k, c in enumerate(clips) for s in range(0, max(len(c.feats), 1), self.length)]

    def __len__(self) -> int:
        return len(self.clips) * self.repeats if self.random else len(self.index)

    def __getitem__(self, i):
        if self.random:
            k = i % len(self.clips)
            s = int(torch.randint(0, max(len(self.clips[k].feats) - self.length, 0) + 1, ()))
        else:
            k, s = self.index[i]
        c, L_ = self.clips[k], self.length
        x = np.zeros((L_, c.feats.shape[1]), np.float32)
        y = np.full(L_, IGNORE, np.int64)
        seg = c.feats[s:s + L_]
        x[:len(seg)] = seg
        y[:len(seg)] = self.targets[k][s:s + L_]
        return torch.from_numpy(x), torch.from_numpy(y)

    def all_frames(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Every crop stacked: ``(N, L, F)``, ``(N, L)`` (validation)."""
        xs, ys = zip(*(self[i] for i in range(len(self)))) if len(self) else ((), ())
        return torch.stack(xs), torch.stack(ys)
