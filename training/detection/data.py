"""Training data for the ball detectors: N-frame windows of clip folders with heatmap targets.

* Clips come from a dataset folder with ``manifest.yaml``, a folder of clip folders (a manifest is inferred,
  :mod:`training.datasets`), several of these mixed with weights (``root_weights``), or lists of clips.
  Clips without ``ball.csv`` (not labelled yet) are skipped with a warning.
* Frames are resized once, aspect-preserving (letterbox), to the network size and stored, one indexed file
  per clip (:mod:`training.detection.frame_store`, in ``cache_dir``, default ``<root>/.cache``): JPEG for
  the training split (1/10 of raw ``uint8``), PNG (lossless) for the scored splits, so validation and test
  see exactly the frames eval.py and inference see. Epochs after the first never decode video again; each
  window decodes its frames in ``__getitem__`` (in the DataLoader workers), with a small per-process LRU.
* Targets: a binary disk of ``radius`` px (net resolution) around the ball of each output frame whose
  visibility is in ``visible_flags``; real-valued maps for the hard frames of ``soft_flags`` (e.g. [2]);
  all-zero maps otherwise. Frames without a ``ball.csv`` row (never labelled) and frames whose visibility
  is in ``ignore_flags`` (default [3], occluded) are left out of the loss (``meta["labelled"]``): a
  partially labelled clip trains on its labelled frames only.
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
import logging
from dataclasses import dataclass
from pathlib import Path

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset, WeightedRandomSampler

from inference.clipio import Clip, FormatError, private_temp_path
from inference.detection.detect import window_starts
from inference.detection.geometry import Letterbox
from inference.detection.preprocess import normalize
from training.detection.frame_store import FrameStore, StoreError, StoreWriter, store_tag

log = logging.getLogger(__name__)


@dataclass
class ClipData:
    """One clip ready for sampling: its letterboxed frames (a frame store, decoded on demand) and the ball in
    net pixels."""

    name: str
    frames: FrameStore          # (T, H, W, 3) uint8 array-like at net size: frames[s:e] is (k, H, W, 3)
    visibility: np.ndarray      # (T,) int8, -1 where not labelled
    xy_net: np.ndarray          # (T, 2) ball in network pixels (NaN where none)
    xy_px: np.ndarray           # (T, 2) ball in original pixels
    letterbox: Letterbox


def _cache_key(clip: Clip, net_size: tuple[int, int], store: str | None = None) -> str:
    """The clip's folder, its video's mtime, the net size and the store format (``store_tag()``; the
    empty string gives the key of the raw ``uint8`` caches written before the frame store)."""
    video = clip.video_path
    stamp = f"{clip.root.resolve()}|{video.stat().st_mtime_ns if video.exists() else 0}|{net_size}"
    if store != "":
        stamp += f"|{store or store_tag()}"
    return hashlib.sha1(stamp.encode()).hexdigest()[:16]


def load_clip(clip: Clip, net_size: tuple[int, int], cache_dir: Path, progress: bool = False,
              exact: bool = False) -> ClipData:
    """Read ball.csv and the letterboxed frames of a clip (building its frame store on first use).

    The store is ``<cache_dir>/<clip>_<key>.npy`` (:mod:`training.detection.frame_store`): JPEG, or with
    ``exact`` PNG (lossless: the frames are the letterboxed video's, bit for bit). One that is incomplete,
    damaged in its layout or shorter than the clip is rebuilt (logged). The raw ``uint8`` cache of the same
    clip written by earlier versions is deleted (logged).
    """
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
    cache_dir = Path(cache_dir)
    old = cache_dir / f"{clip.root.name}_{_cache_key(clip, net_size, store='')}.npy"
    if old.is_file():
        log.info("deleting the old raw frame cache %s (%.0f MB): frames are now kept as JPEG (frame store)",
                 old, old.stat().st_size / 1e6)
        old.unlink(missing_ok=True)
    codec = "png" if exact else "jpeg"
    cache = cache_dir / f"{clip.root.name}_{_cache_key(clip, net_size, store_tag(codec))}.npy"
    frames = None
    if cache.is_file():
        try:
            frames = FrameStore(cache)
        except StoreError as e:
            log.warning("%s: %s; rebuilding it from the video", cache, e)
        else:
            if len(frames) < n or frames.shape[1:3] != tuple(net_size):
                log.warning("%s holds %d frames of %s, the clip needs %d of %s: rebuilding it from the video",
                            cache, len(frames), frames.shape[1:3], n, tuple(net_size))
                frames = None
    if frames is None:
        _build_cache(clip, lb, net_size, n, cache, progress, codec)
        frames = FrameStore(cache)
    return ClipData(clip.root.name, frames, dense.visibility, xy_net, xy_px, lb)


def _build_cache(clip: Clip, lb: Letterbox, net_size, n: int, path: Path, progress: bool,
                 codec: str = "jpeg") -> None:
    """Decode the video once, letterbox every frame and write the frame store (a temporary name, renamed
    when complete: DDP ranks or two runs may build the same store at once)."""
    from tqdm import tqdm

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = private_temp_path(path)
    count = 0
    try:
        with StoreWriter(tmp, net_size, codec) as out, clip.frames(cache_size=0) as src:
            for i, frame in enumerate(tqdm(src.iter(0, n), total=n, desc=f"cache {clip.root.name}",
                                           disable=not progress)):
                out.add(lb.warp(frame))
                count = i + 1
        if count < n:
            raise FormatError(clip.video_path, f"the video has {count} frames but the clip needs {n}",
                              fix="check clip.yaml's n_frames and the labels against the video")
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


@dataclass(frozen=True)
class WindowSpec:
    """How windows are cut and turned into tensors."""

    frames_in: int = 3
    frames_out: int = 3
    step: int = 1
    radius: float = 2.5
    visible_flags: tuple[int, ...] = (1, 2)
    soft_flags: tuple[int, ...] = ()  # visibilities that get a real-valued (Gaussian) map instead of a disk
    ignore_flags: tuple[int, ...] = (3,)  # visibilities left out of the loss (like unlabelled frames)
    crop: tuple[int, int] | None = None
    ball_crop_prob: float = 0.7
    normalize: str = "imagenet"
    augment: bool = False
    flip_prob: float = 0.5
    jitter_prob: float = 0.5
    scale_prob: float = 0.3


class BallWindows(Dataset):
    """All windows of ``frames_in`` consecutive frames of some clips with at least one labelled output frame.

    Item: ``x`` (3·frames_in, H, W) float32, ``y`` (frames_out, H, W) float32 heatmaps of the last
    ``frames_out`` frames, and ``meta`` with the output frames' visibility (frames_out,; -1 = not labelled),
    ``labelled`` (frames_out,) bool (the frames the loss counts), ball in original pixels (frames_out, 2),
    the crop offset (2,) in net pixels, the clip index and the first frame.
    """

    def __init__(self, clips: list[ClipData], spec: WindowSpec, seed: int = 0, fps: list[float] | None = None,
                 max_frames: int | None = None):
        if spec.frames_out > spec.frames_in:
            raise ValueError("frames_out cannot exceed frames_in")
        if spec.crop is not None and any(c % 8 for c in spec.crop):
            raise ValueError(f"crop {spec.crop} must be multiples of 8")
        self.clips, self.spec, self.seed = clips, spec, seed
        self.fps = list(fps) if fps is not None else [30.0] * len(clips)
        windows = {(c, s): first_new for c, cd in enumerate(clips)
                   for s, first_new in window_starts(len(cd.visibility), spec.frames_in, spec.step)}
        self.index = [(c, s) for c, s in windows
                      if _counts(self.clips[c].visibility[s + spec.frames_in - spec.frames_out: s + spec.frames_in], spec)]
        self.first_new = {key: f for key, f in windows.items() if f}  # the windows ending at a clip's last frame
        if max_frames:
            self.index = _stretches(self.index, int(max_frames), seed)
        if not self.index:
            raise ValueError("no labelled windows: every clip is shorter than frames_in or has no ball.csv rows "
                             f"(other than visibility {list(spec.ignore_flags)}, which is left out)")
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
        imgs = np.asarray(cd.frames[s:s + spec.frames_in])                          # (F, H, W, 3) uint8
        out = slice(s + spec.frames_in - spec.frames_out, s + spec.frames_in)
        vis = cd.visibility[out].astype(np.int64)
        labelled = (vis >= 0) & ~np.isin(vis, spec.ignore_flags)
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
        imgs = imgs.astype(np.float32)  # after the crop: only the pixels used are converted
        if spec.augment and rng.random() < spec.jitter_prob:
            gain, bias = rng.uniform(0.75, 1.25), rng.uniform(-20, 20)
            imgs = np.clip(imgs * gain + bias, 0, 255)
        heat = disk_heatmaps(centres, imgs.shape[1:3], spec.radius)
        soft = np.isin(vis, spec.soft_flags) & shown
        if soft.any():
            heat[soft] = soft_heatmaps(centres[soft], imgs.shape[1:3], spec.radius)
        x = normalize(imgs, spec.normalize)
        meta = {"visibility": torch.as_tensor(vis), "labelled": torch.as_tensor(labelled), "xy_px": torch.as_tensor(cd.xy_px[out], dtype=torch.float32),
                "offset": torch.tensor([x0, y0], dtype=torch.float32),
                "lb_scale": torch.tensor(cd.letterbox.scale, dtype=torch.float32),
                "lb_pad": torch.tensor(cd.letterbox.offset, dtype=torch.float32), "clip": c, "start": s,
                "skip": max(self.first_new.get((c, s), 0) - (s + spec.frames_in - spec.frames_out), 0),
                "fps": torch.tensor(self.fps[c], dtype=torch.float64),
                "size": torch.tensor([cd.letterbox.src_w, cd.letterbox.src_h], dtype=torch.float64)}
        return torch.from_numpy(x), torch.from_numpy(heat), meta


def _stretches(index: list[tuple[int, int]], max_frames: int, seed: int) -> list[tuple[int, int]]:
    """Per clip, only the windows starting inside one fixed stretch of ``max_frames`` frames (its place
    seeded per clip, the same every epoch): a cheaper validation that still tracks whole stretches."""
    by_clip: dict[int, list[int]] = {}
    for c, s in index:
        by_clip.setdefault(c, []).append(s)
    out = []
    for c, starts in by_clip.items():
        lo, hi = min(starts), max(starts)
        first = lo + int(np.random.default_rng([seed, c]).integers(0, max(hi - lo - max_frames, 0) + 1))
        out += [(c, s) for s in starts if first <= s < first + max_frames]
    return out


def _counts(vis: np.ndarray, spec: WindowSpec) -> bool:
    """Whether any of these output frames is labelled and not ignored."""
    return bool(((vis >= 0) & ~np.isin(vis, spec.ignore_flags)).any())


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
    """Zoom in by up to ×1.125 about a random point (the published scale augmentation); ``imgs`` ``(F, H, W, 3)``
    of any dtype OpenCV warps (uint8 here)."""
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
    """Lightning data module over dataset folders (see the module docstring) or explicit clip lists per split.

    Args:
        root: a dataset folder (manifest.yaml), a folder of clip folders, or a list of these (mixed).
        root_weights: per root, its share of the training samples (None: in proportion to its windows).
        split_seed: seed of an inferred manifest's split.
        net_size: (H, W) network input size; crop: (h, w) training crops or None for full frames.
        ignore_flags: visibilities left out of the loss and of validation (default [3]: occluded).
        cache_dir: where resized frames are cached (default ``<root>/.cache`` of each clip's root).
        val_max_frames: validate on one fixed stretch of this many frames per clip (None: whole clips).
    """

    def __init__(self, root: str | list[str] | None = None, train_clips: list[str] | None = None,
                 val_clips: list[str] | None = None, test_clips: list[str] | None = None,
                 net_size: tuple[int, int] = (288, 512), frames_in: int = 3, frames_out: int = 3,
                 crop: tuple[int, int] | None = None, ball_crop_prob: float = 0.7, radius: float = 2.5,
                 visible_flags: tuple[int, ...] = (1, 2), soft_flags: tuple[int, ...] = (),
                 ignore_flags: tuple[int, ...] = (3,), normalize: str = "imagenet", augment: bool = True,
                 train_step: int = 1, batch_size: int = 8, num_workers: int = 0, cache_dir: str | None = None,
                 seed: int = 1234, root_weights: list[float] | None = None, split_seed: int | None = None,
                 val_max_frames: int | None = None):
        super().__init__()
        self.save_hyperparameters()  # logged with the module's (hparams.yaml)
        self.net_size = tuple(net_size)
        self.data: dict[str, BallWindows] = {}
        self._sources = None
        self.window_source: dict[str, np.ndarray] = {}  # per split: the source index of each window

    @property
    def sources(self):
        """The resolved roots (:class:`training.datasets.DataSource`), inferred manifests included."""
        if self._sources is None:
            from training.datasets import resolve_sources

            hp = self.hparams
            if hp.root is None:
                raise ValueError("BallDataModule needs data.root (a dataset folder, a folder of clip folders, or a "
                                 "list of them) or clip lists")
            seed = hp.seed if hp.split_seed is None else hp.split_seed
            self._sources = resolve_sources(hp.root, hp.root_weights, seed)
        return self._sources

    def _clips(self, split: str) -> list[tuple[Clip, int]]:
        """(clip, source index; -1 for explicit lists) of ``split`` (``all``: every clip), labelled clips only."""
        from training.datasets import skip_unlabelled

        hp = self.hparams
        explicit = {"train": hp.train_clips, "val": hp.val_clips, "test": hp.test_clips}.get(split)
        if explicit is not None:
            return [(Clip(p), -1) for p in explicit]
        out = []
        for k, src in enumerate(self.sources):
            clips = skip_unlabelled([Clip(p) for p in src.paths(split)], "ball.csv", f"{src.root} ({split})")
            out += [(c, k) for c in clips]
        return out

    def _cache_dir(self, clip: Clip, k: int) -> Path:
        """``cache_dir``, else ``.cache`` in the clip's root (k = -1: an explicit clip, its parent folder)."""
        if self.hparams.cache_dir:
            return Path(self.hparams.cache_dir)
        return (clip.root.parent if k < 0 else self.sources[k].root) / ".cache"

    def _windows(self, split: str) -> BallWindows:
        hp = self.hparams
        pairs = self._clips(split)
        if not pairs and split == "val" and hp.val_clips is None:
            log.warning("no labelled validation clips: validating on the training clips (the F1 is optimistic); "
                        "give the dataset a val split (manifest.yaml, or more clips) for an honest one")
            pairs = self._clips("train")
        if not pairs:
            raise ValueError(f"the {split} split has no labelled clips (with ball.csv) in {hp.root}")
        clips = [load_clip(c, self.net_size, self._cache_dir(c, k), progress=True, exact=split != "train")
                 for c, k in pairs]  # scored splits: lossless frames, as eval.py sees them
        train = split == "train"
        spec = WindowSpec(hp.frames_in, hp.frames_out, hp.train_step if train else hp.frames_out, hp.radius,
                          tuple(hp.visible_flags), tuple(hp.soft_flags) if train else (),
                          tuple(hp.ignore_flags), tuple(hp.crop) if (train and hp.crop) else None,
                          hp.ball_crop_prob, hp.normalize, bool(hp.augment and train))
        windows = BallWindows(clips, spec, hp.seed, fps=[c.info.fps for c, _ in pairs],
                              max_frames=hp.val_max_frames if split == "val" else None)
        self.window_source[split] = np.array([max(pairs[c][1], 0) for c, _ in windows.index], dtype=np.int64)
        return windows

    def prepare_data(self) -> None:
        """Build the frame caches of the fit splits once (Lightning calls this on one process per node
        before :meth:`setup` on all of them, so DDP ranks do not decode the same videos together; the test
        split's are built when tested, each rank under its own temporary name)."""
        for split in ("train", "val"):
            for c, k in self._clips(split):
                if c.ball_path.is_file():
                    load_clip(c, self.net_size, self._cache_dir(c, k), progress=True, exact=split != "train")

    def setup(self, stage: str | None = None) -> None:
        wanted = {"fit": ("train", "val"), "validate": ("val",), "test": ("test",), None: ("train", "val")}
        for split in wanted.get(stage, ("test",)):
            if split not in self.data:
                self.data[split] = self._windows(split)

    def sample_weights(self) -> np.ndarray | None:
        """Per training window, its sampling weight when ``root_weights`` mixes several roots (else None):
        each root's windows share its weight equally."""
        weights = self.hparams.root_weights
        if not weights or len(weights) < 2:
            return None
        src = self.window_source["train"]
        counts = np.bincount(src, minlength=len(weights)).astype(float)
        w = np.asarray(weights, float)[src] / np.maximum(counts[src], 1)
        return w / w.sum()

    def _loader(self, split: str, shuffle: bool) -> DataLoader:
        from training.distributed import eval_sampler

        sampler = None
        if split != "train":  # DDP: each rank its shard of the windows, none repeated (global F1 exact)
            sampler = eval_sampler(getattr(self, "trainer", None), self.data[split])
        if split == "train" and (w := self.sample_weights()) is not None:
            sampler = WeightedRandomSampler(torch.as_tensor(w, dtype=torch.double), len(w), replacement=True,
                                            generator=torch.Generator().manual_seed(int(self.hparams.seed)))
            shuffle = False
        return DataLoader(self.data[split], batch_size=self.hparams.batch_size, shuffle=shuffle, sampler=sampler,
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
