"""Training data for the ball detectors: N-frame windows of clip folders with heatmap targets.

* Clips come from a dataset folder with ``manifest.yaml`` (splits by clip or match) or a list of clips.
* Frames are resized once, aspect-preserving (letterbox), to the network size and cached as ``uint8``
  arrays on disk, so epochs after the first never decode video again (``cache_dir``).
* Targets: a binary disk of ``radius`` px (net resolution) around the ball of each output frame whose
  visibility is in ``visible_flags``; real-valued maps for the hard frames of ``soft_flags`` (e.g. [2]);
  all-zero maps otherwise.
* CPU-friendly training: random ``crop`` windows (a multiple of 8), centred near the ball with
  probability ``ball_crop_prob`` and anywhere otherwise (background crops teach what is *not* a ball).
* Augmentation: horizontal flip, brightness/contrast jitter, scale-crop; the published normalisation
  (ImageNet mean/std for WASB, /255 for TrackNetV2 and MonoTrack).

Example:
    >>> dm = BallDataModule(root="data/synth_padel", net_size=(288, 512), crop=(128, 128))
    >>> dm.setup("fit"); x, y, meta = next(iter(dm.train_dataloader()))   # (B, 9, 128, 128), (B, 3, 128, 128)
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from inference.clipio import Clip, FormatError, Manifest
from inference.detection.geometry import Letterbox
from inference.detection.preprocess import normalize



@dataclass
class ClipData:
    """One clip ready for sampling: cached letterboxed frames and the ball in net pixels."""

    name: str
    frames: np.ndarray          # (T, H, W, 3) uint8 memmap at network size
    visibility: np.ndarray      # (T,) int8, -1 where not labelled
    xy_net: np.ndarray          # (T, 2) ball in network pixels (NaN where none)
    xy_px: np.ndarray           # (T, 2) ball in original pixels
    letterbox: Letterbox


def _cache_key(clip: Clip, net_size: tuple[int, int]) -> str:
    video = clip.video_path
    stamp = f"{clip.root.resolve()}|{video.stat().st_mtime_ns if video.exists() else 0}|{net_size}"
    return hashlib.sha1(stamp.encode()).hexdigest()[:16]


def load_clip(clip: Clip, net_size: tuple[int, int], cache_dir: Path, progress: bool = False) -> ClipData:
    """Read ball.csv and the letterboxed frames of a clip (building the frame cache on first use)."""
    if not clip.ball_path.is_file():
        raise FormatError(clip.ball_path, "file not found",
                          fix="label the ball (rally3d label) or remove the clip from the manifest")
    info = clip.info
    lb = Letterbox(info.width, info.height, net_size[1], net_size[0])
    n = clip.n_frames
    track = clip.read_ball(n_frames=n)
    dense = track.dense(n)
    xy_px = dense.xy * np.array([info.width, info.height], float)
    xy_net = np.full_like(xy_px, np.nan)
    ok = np.isfinite(xy_px).all(axis=1)
    xy_net[ok] = lb.forward(xy_px[ok])
    cache = Path(cache_dir) / f"{clip.root.name}_{_cache_key(clip, net_size)}.npy"
    if not cache.is_file():
        _build_cache(clip, lb, net_size, n, cache, progress)
    frames = np.load(cache, mmap_mode="r")
    if len(frames) < n:
        raise FormatError(clip.video_path, f"the video has {len(frames)} frames but ball.csv/clip.yaml need {n}",
                          fix="check clip.yaml's n_frames and the labels against the video")
    return ClipData(clip.root.name, frames, dense.visibility, xy_net, xy_px, lb)


def _build_cache(clip: Clip, lb: Letterbox, net_size, n: int, path: Path, progress: bool) -> None:
    from tqdm import tqdm

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npy")
    out = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.uint8, shape=(n, net_size[0], net_size[1], 3))
    count = 0
    with clip.frames(cache_size=0) as src:
        for i, frame in enumerate(tqdm(src.iter(0, n), total=n, desc=f"cache {clip.root.name}", disable=not progress)):
            out[i] = lb.warp(frame)
            count = i + 1
    out.flush()
    del out
    if count < n:
        tmp.unlink(missing_ok=True)
        raise FormatError(clip.video_path, f"the video has {count} frames but the clip needs {n}",
                          fix="check clip.yaml's n_frames and the labels against the video")
    tmp.replace(path)


@dataclass(frozen=True)
class WindowSpec:
    """How windows are cut and turned into tensors."""

    frames_in: int = 3
    frames_out: int = 3
    step: int = 1
    radius: float = 2.5
    visible_flags: tuple[int, ...] = (1, 2)
    soft_flags: tuple[int, ...] = ()  # visibilities that get a real-valued (Gaussian) map instead of a disk
    crop: tuple[int, int] | None = None
    ball_crop_prob: float = 0.7
    normalize: str = "imagenet"
    augment: bool = False
    flip_prob: float = 0.5
    jitter_prob: float = 0.5
    scale_prob: float = 0.3


class BallWindows(Dataset):
    """All windows of ``frames_in`` consecutive frames of some clips.

    Item: ``x`` (3·frames_in, H, W) float32, ``y`` (frames_out, H, W) float32 heatmaps of the last
    ``frames_out`` frames, and ``meta`` with the output frames' visibility (frames_out,), ball in original
    pixels (frames_out, 2), the crop offset (2,) in net pixels, the clip index and the first frame.
    """

    def __init__(self, clips: list[ClipData], spec: WindowSpec, seed: int = 0):
        if spec.frames_out > spec.frames_in:
            raise ValueError("frames_out cannot exceed frames_in")
        if spec.crop is not None and any(c % 8 for c in spec.crop):
            raise ValueError(f"crop {spec.crop} must be multiples of 8")
        self.clips, self.spec, self.seed = clips, spec, seed
        self.index = [(c, s) for c, cd in enumerate(clips)
                      for s in range(0, len(cd.visibility) - spec.frames_in + 1, spec.step)
                      if (cd.visibility[s + spec.frames_in - spec.frames_out: s + spec.frames_in] >= 0).any()]
        if not self.index:
            raise ValueError("no labelled windows: every clip is shorter than frames_in or has no ball.csv rows")
        self.epoch = 0

    def __len__(self) -> int:
        return len(self.index)

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def __getitem__(self, i: int):
        spec = self.spec
        c, s = self.index[i]
        cd = self.clips[c]
        rng = np.random.default_rng([self.seed, self.epoch, i])
        imgs = np.asarray(cd.frames[s:s + spec.frames_in], dtype=np.float32)         # (F, H, W, 3)
        out = slice(s + spec.frames_in - spec.frames_out, s + spec.frames_in)
        vis = cd.visibility[out].astype(np.int64)
        shown = np.isin(vis, spec.visible_flags)
        centres = np.where(shown[:, None], cd.xy_net[out], np.nan)                     # (Fo, 2) net px
        H, W = imgs.shape[1:3]
        if spec.augment and rng.random() < spec.scale_prob:
            imgs, centres = _scale_crop(imgs, centres, rng)
        x0, y0 = 0, 0
        if spec.crop is not None:
            x0, y0 = _crop_origin(centres, (H, W), spec.crop, spec.ball_crop_prob, rng)
            ch, cw = spec.crop
            imgs = imgs[:, y0:y0 + ch, x0:x0 + cw]
            centres = centres - [x0, y0]
        if spec.augment and rng.random() < spec.flip_prob:
            imgs = imgs[:, :, ::-1]
            centres = np.stack([imgs.shape[2] - 1 - centres[:, 0], centres[:, 1]], axis=1)
        if spec.augment and rng.random() < spec.jitter_prob:
            gain, bias = rng.uniform(0.75, 1.25), rng.uniform(-20, 20)
            imgs = np.clip(imgs * gain + bias, 0, 255)
        heat = disk_heatmaps(centres, imgs.shape[1:3], spec.radius)
        soft = np.isin(vis, spec.soft_flags) & shown
        if soft.any():
            heat[soft] = soft_heatmaps(centres[soft], imgs.shape[1:3], spec.radius)
        x = normalize(imgs, spec.normalize)
        meta = {"visibility": torch.as_tensor(vis), "xy_px": torch.as_tensor(cd.xy_px[out], dtype=torch.float32),
                "offset": torch.tensor([x0, y0], dtype=torch.float32),
                "lb_scale": torch.tensor(cd.letterbox.scale, dtype=torch.float32),
                "lb_pad": torch.tensor(cd.letterbox.offset, dtype=torch.float32), "clip": c, "start": s}
        return torch.from_numpy(x), torch.from_numpy(heat), meta


def _crop_origin(centres, hw, crop, p_ball, rng) -> tuple[int, int]:
    H, W = hw
    ch, cw = crop
    ok = np.isfinite(centres).all(axis=1)
    if ok.any() and rng.random() < p_ball:
        cx, cy = centres[rng.choice(np.flatnonzero(ok))] + rng.uniform(-0.35, 0.35, 2) * [cw, ch]
        x0, y0 = int(round(cx - cw / 2)), int(round(cy - ch / 2))
    else:
        x0, y0 = int(rng.integers(0, W - cw + 1)), int(rng.integers(0, H - ch + 1))
    return int(np.clip(x0, 0, W - cw)), int(np.clip(y0, 0, H - ch))


def _scale_crop(imgs: np.ndarray, centres: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
    """Zoom in by up to ×1.125 about a random point (the published scale augmentation)."""
    import cv2

    F_, H, W, _ = imgs.shape
    s = rng.uniform(1.0, 1.125)
    ox, oy = rng.uniform(0, W * (s - 1)), rng.uniform(0, H * (s - 1))
    M = np.array([[s, 0, -ox], [0, s, -oy]], np.float32)
    out = np.stack([cv2.warpAffine(im, M, (W, H), flags=cv2.INTER_LINEAR) for im in imgs])
    return out, centres * s - [ox, oy]


def disk_heatmaps(centres: np.ndarray, hw: tuple[int, int], radius: float) -> np.ndarray:
    """(F, 2) centres in pixels (NaN = no ball) → (F, H, W) float32 binary disks of ``radius``."""
    H, W = hw
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    out = np.zeros((len(centres), H, W), np.float32)
    for k, (cx, cy) in enumerate(centres):
        if np.isfinite(cx) and np.isfinite(cy):
            out[k] = ((xx - cx) ** 2 + (yy - cy) ** 2 <= radius**2).astype(np.float32)
    return out


def soft_heatmaps(centres: np.ndarray, hw: tuple[int, int], radius: float) -> np.ndarray:
    """Real-valued maps for hard frames (WASB-SBDT's position-aware targets): 0.6·exp(-d²/r²)/e⁻¹,
    zero below 0.5, clipped at 1."""
    H, W = hw
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    out = np.zeros((len(centres), H, W), np.float32)
    for k, (cx, cy) in enumerate(centres):
        if np.isfinite(cx) and np.isfinite(cy):
            m = 0.6 * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / radius**2) / np.exp(-1.0)
            out[k] = np.where(m < 0.5, 0.0, np.minimum(m, 1.0))
    return out


class BallDataModule(L.LightningDataModule):
    """Lightning data module over a dataset folder (manifest.yaml) or explicit clip lists per split.

    Args:
        root: dataset folder with manifest.yaml (or None when ``train_clips``/``val_clips`` are given).
        net_size: (H, W) network input size; crop: (h, w) training crops or None for full frames.
        cache_dir: where resized frames are cached (default ``<root>/.cache``).
    """

    def __init__(self, root: str | None = None, train_clips: list[str] | None = None,
                 val_clips: list[str] | None = None, test_clips: list[str] | None = None,
                 net_size: tuple[int, int] = (288, 512), frames_in: int = 3, frames_out: int = 3,
                 crop: tuple[int, int] | None = None, ball_crop_prob: float = 0.7, radius: float = 2.5,
                 visible_flags: tuple[int, ...] = (1, 2), soft_flags: tuple[int, ...] = (),
                 normalize: str = "imagenet", augment: bool = True,
                 train_step: int = 1, batch_size: int = 8, num_workers: int = 0, cache_dir: str | None = None,
                 seed: int = 1234):
        super().__init__()
        self.save_hyperparameters(logger=False)
        self.net_size = tuple(net_size)
        self.data: dict[str, BallWindows] = {}

    def _clips(self, split: str) -> list[Clip]:
        hp = self.hparams
        explicit = {"train": hp.train_clips, "val": hp.val_clips, "test": hp.test_clips}[split]
        if explicit is not None:
            return [Clip(p) for p in explicit]
        if hp.root is None:
            raise ValueError("BallDataModule needs data.root (a dataset folder with manifest.yaml) or clip lists")
        root = Path(hp.root)
        if not (root / "manifest.yaml").is_file():
            raise FileNotFoundError(f"no manifest.yaml in {root}: generate data with `rally3d synth --out {root}` "
                                    "or point data.root to a dataset folder")
        return [Clip(p) for p in Manifest.load(root).paths(split)]

    def _windows(self, split: str) -> BallWindows:
        hp = self.hparams
        cache = Path(hp.cache_dir) if hp.cache_dir else Path(hp.root or ".") / ".cache"
        clips = [load_clip(c, self.net_size, cache, progress=True) for c in self._clips(split)]
        if not clips:
            raise ValueError(f"the {split} split has no clips")
        train = split == "train"
        spec = WindowSpec(hp.frames_in, hp.frames_out, hp.train_step if train else hp.frames_out, hp.radius,
                          tuple(hp.visible_flags), tuple(hp.soft_flags) if train else (),
                          tuple(hp.crop) if (train and hp.crop) else None,
                          hp.ball_crop_prob, hp.normalize, bool(hp.augment and train))
        return BallWindows(clips, spec, hp.seed)

    def setup(self, stage: str | None = None) -> None:
        wanted = {"fit": ("train", "val"), "validate": ("val",), "test": ("test",), None: ("train", "val")}
        for split in wanted.get(stage, ("test",)):
            if split not in self.data:
                self.data[split] = self._windows(split)

    def _loader(self, split: str, shuffle: bool) -> DataLoader:
        return DataLoader(self.data[split], batch_size=self.hparams.batch_size, shuffle=shuffle,
                          num_workers=self.hparams.num_workers, persistent_workers=self.hparams.num_workers > 0,
                          collate_fn=collate)

    def train_dataloader(self) -> DataLoader:
        return self._loader("train", True)

    def val_dataloader(self) -> DataLoader:
        return self._loader("val", False)

    def test_dataloader(self) -> DataLoader:
        return self._loader("test", False)


def collate(batch):
    xs, ys, metas = zip(*batch)
    meta = {k: (torch.stack([m[k] for m in metas]) if torch.is_tensor(metas[0][k]) else [m[k] for m in metas])
            for k in metas[0]}
    return torch.stack(xs), torch.stack(ys), meta
