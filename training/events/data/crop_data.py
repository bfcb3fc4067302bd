"""Training data of the crop hit-event model (:mod:`inference.events.crop`): **rendered** clips of a dataset
folder (``rally3d synth`` output such as ``data/synth_padel``) with ground-truth events.

Per clip: the ball-only features and per-frame classes of :mod:`.data` (at the reference rate) plus the
ball crops of every reference frame, extracted once by streaming the video and cached as ``.npy`` under
``cache_dir`` (``runs/`` is git-ignored; the key covers the clip, its ball.csv and video, and the crop
settings). When the dataset folder is missing, the embedded ``datasets/sample`` clip of the sport is used
for every split (enough for a smoke run, not for a model; a warning says so).

Batches (:class:`CropChunkSet`): ``x (B, L + W - 1, F) float32`` features of runs of frames, ``crops
(B, L + W - 1, S, S, 3) uint8``, ``y (B, L) int64`` labels of the L windows of each run (-1 = padding).
"""
from __future__ import annotations

import hashlib
import logging
import warnings
from dataclasses import dataclass
from pathlib import Path

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from inference.clipio import Clip, private_temp_path
from inference.events.classes import ClassSet
from inference.events.crop import CropConfig, extract_crops
from inference.events.features import FeatureConfig, dense_xy, resample_xy, window_labels, window_starts

from training.events.data.datamodule import LabelledClip, clips_from_folder, label_clips

log = logging.getLogger(__name__)
SAMPLE_ROOT = Path(__file__).resolve().parents[3] / "datasets" / "sample"


@dataclass
class CropClip:
    """A labelled clip with its crops: ``crops (T', S, S, 3) uint8`` aligned with ``lc.feats (T', F)``."""

    lc: LabelledClip
    crops: np.ndarray


def _cache_key(clip: Clip, config: CropConfig, ref_fps: float | None) -> str:
    video = clip.video_path
    stamp = "|".join([str(clip.root.resolve()), str(clip.ball_path.stat().st_mtime_ns),
                      str(video.stat().st_mtime_ns if video.exists() else 0), repr(config.to_dict()), str(ref_fps)])
    return hashlib.sha1(stamp.encode()).hexdigest()[:16]


def clip_crops(clip: Clip, n_frames: int, features: FeatureConfig, config: CropConfig,
               cache_dir: str | Path | None) -> np.ndarray:
    """``(T', S, S, 3)`` crops around the clip's ``ball.csv`` positions (cached when ``cache_dir``)."""
    cache = None
    if cache_dir is not None:
        cache = Path(cache_dir) / f"{clip.root.name}_{_cache_key(clip, config, features.ref_fps)}.npy"
        if cache.is_file():
            return np.load(cache)
    xy = resample_xy(dense_xy(clip.read_ball(), n_frames), clip.info.fps, features.ref_fps)
    with clip.frames(cache_size=0) as frames:
        crops = extract_crops(frames, xy, clip.info.fps, features.ref_fps, config, n_frames, progress=True)
    if cache is not None:
        cache.parent.mkdir(parents=True, exist_ok=True)
        tmp = private_temp_path(cache)  # DDP ranks may extract the same crops at once
        try:
            np.save(tmp, crops)
            tmp.replace(cache)
        finally:
            tmp.unlink(missing_ok=True)
    return crops


def sample_clips(sport: str) -> list[Path]:
    """The embedded sample clip(s) of ``sport`` (the fallback when the dataset folder is missing)."""
    return [p.parent for p in sorted(SAMPLE_ROOT.glob("*/clip.yaml")) if Clip(p.parent).info.sport == sport]


def load_crop_clips(root: str | Path | None, split: str, class_set: ClassSet, features: FeatureConfig,
                    config: CropConfig, cache_dir: str | Path | None, max_clips: int | None = None,
                    on_unmapped: str = "error") -> list[CropClip]:
    """The clips of one split of ``root`` with features, classes and crops."""
    root = Path(root) if root else None
    if root is None or not (root / "manifest.yaml").is_file():
        paths = sample_clips(class_set.sport)
        if not paths:
            raise FileNotFoundError(f"no dataset folder at {root} and no embedded {class_set.sport} sample; "
                                    "render one with rally3d synth --sport padel --clips 24 --out data/synth_padel")
        warnings.warn(f"no manifest.yaml in {root}: using the embedded sample clip(s) {[p.name for p in paths]} "
                      f"for the {split} split (a smoke run, not a model)", stacklevel=2)
        sims = []
        for p in paths:
            sims += [s for s in clips_from_folder(p.parent, "test") if Path(s.name).name == p.name]
    else:
        sims = clips_from_folder(root, split)
    sims = sims[: max_clips or None]
    out = []
    for lc in label_clips(sims, class_set, features, on_unmapped):
        crops = clip_crops(Clip(lc.sim.name), lc.sim.n_frames, features, config, cache_dir)
        if len(crops) != len(lc.feats):
            raise ValueError(f"{lc.sim.name}: {len(crops)} crops for {len(lc.feats)} feature rows")
        out.append(CropClip(lc, crops))
    return out


class CropChunkSet(Dataset):
    """Chunks of ``chunk`` consecutive windows of a clip, with the frames they cover (the CNN then runs
    once per frame, not once per window).

    Item → ``(x (L + W - 1, F) float32, crops (L + W - 1, S, S, 3) uint8, y (L,) int64)``: frames of the
    clip zero-padded by W at both ends, from padded index ``s`` on, and the labels of the L windows that
    start at ``s .. s + L - 1`` (:func:`~inference.events.features.window_labels`). Chunks start every
    ``stride`` windows; the last ones are padded with label -1 (ignored).
    """

    def __init__(self, clips: list[CropClip], window: int, last_k: int, chunk: int = 96, stride: int | None = None):
        self.window, self.chunk = int(window), int(chunk)
        stride = int(stride or chunk)
        self.feats, self.crops, self.labels, index = [], [], [], []
        span = self.chunk + self.window - 1
        for k, c in enumerate(clips):
            n_win = len(window_starts(len(c.lc.feats), window))
            extra = span - window + ((-n_win) % stride) + stride  # room for the last, partly empty chunk
            F = c.lc.feats.shape[1]
            self.feats.append(torch.from_numpy(np.concatenate(
                [np.zeros((window, F), np.float32), c.lc.feats, np.zeros((window + extra, F), np.float32)])))
            z = np.zeros((window, *c.crops.shape[1:]), np.uint8)
            self.crops.append(torch.from_numpy(np.concatenate([z, c.crops, np.zeros((window + extra,
                                                                                        *c.crops.shape[1:]), np.uint8)])))
            y = np.full(n_win + extra + stride, -1, np.int64)
            y[:n_win] = window_labels(c.lc.y, window, last_k)
            self.labels.append(torch.from_numpy(y))
            index += [(k, s) for s in range(0, n_win, stride)]
        self.index = index

    def __len__(self) -> int:
        return len(self.index)

    def __getitem__(self, i):
        k, s = self.index[i]
        span = self.chunk + self.window - 1
        return self.feats[k][s:s + span], self.crops[k][s:s + span], self.labels[k][s:s + self.chunk]


class CropEventDataModule(L.LightningDataModule):
    """Rendered clips of a dataset folder → balanced windows with crops.

    Args:
        sport, class_set, features, window, last_k, on_unmapped: as
        :class:`~training.events.data.datamodule.EventDataModule`. root: dataset folder (``manifest.yaml``).
        crop: :class:`CropConfig` fields. chunk: windows per chunk (train chunks start every ``chunk // 3``
        windows, shuffled; validation chunks tile the clips); batch_size: chunks per batch.
        n_train, n_val, n_test: at most this many clips of each split
        (None = all). cache_dir: crop cache. seed: the sampler's.
    """

    def __init__(self, sport: str = "padel", class_set: str | dict = "padel6", features: dict | None = None,
                 crop: dict | None = None, window: int = 24, last_k: int = 6, root: str | None = None,
                 n_train: int | None = None, n_val: int | None = None, n_test: int | None = None,
                 on_unmapped: str = "error", chunk: int = 96, batch_size: int = 8, num_workers: int = 0,
                 cache_dir: str | None = None, seed: int = 0):
        super().__init__()
        self.sport, self.root, self.cache_dir = sport, root, cache_dir
        self.class_set = ClassSet.load(class_set)
        self.features = FeatureConfig.from_dict(features or {})
        self.crop = CropConfig.from_dict(crop or {})
        self.window, self.last_k = int(window), int(last_k)
        self.limits = {"train": n_train, "val": n_val, "test": n_test}
        self.on_unmapped, self.chunk = on_unmapped, int(chunk)
        self.batch_size, self.num_workers, self.seed = int(batch_size), int(num_workers), int(seed or 0)
        self._clips: dict[str, list[CropClip]] = {}
        self.sets: dict[str, CropChunkSet] = {}

    def clips(self, split: str) -> list[CropClip]:
        if split not in self._clips:
            self._clips[split] = load_crop_clips(self.root, split, self.class_set, self.features, self.crop,
                                                 self.cache_dir, self.limits.get(split), self.on_unmapped)
        return self._clips[split]

    @property
    def counts(self) -> dict[str, int]:
        return {s: len(c) for s, c in self._clips.items()}

    def setup(self, stage: str | None = None) -> None:
        for split in ("train", "val"):
            if split not in self.sets:
                stride = max(self.chunk // 3, 1) if split == "train" else self.chunk
                self.sets[split] = CropChunkSet(self.clips(split), self.window, self.last_k, self.chunk, stride)

    def train_dataloader(self) -> DataLoader:
        return DataLoader(self.sets["train"], batch_size=self.batch_size, num_workers=self.num_workers,
                          shuffle=True, generator=torch.Generator().manual_seed(self.seed))

    def prepare_data(self) -> None:
        """Extract the crops once (one process per node, before every rank's :meth:`setup`)."""
        for split in ("train", "val"):
            self.clips(split)

    def val_dataloader(self) -> DataLoader:
        from training.distributed import eval_sampler

        ds = self.sets["val"]
        return DataLoader(ds, batch_size=self.batch_size, num_workers=self.num_workers,
                          sampler=eval_sampler(getattr(self, "trainer", None), ds))
