"""Windows, class balancing, augmentation and the Lightning data module of the hit-event models.

Sources of clips (``EventDataModule``):
- ``source: synthetic`` — simulated rallies through random cameras (:mod:`.simulate`), train / val / test
  with different seeds;
- ``source: folder`` — a dataset folder with ``manifest.yaml`` (``rally3d synth`` output, a converted
  TrackNet ``Label.csv``), a folder of clip folders as the labeler writes them (a manifest is inferred,
  :mod:`training.datasets`), or a list of these mixed with ``root_weights``: ``ball.csv`` and ``events.csv``
  (``gt/events.csv`` if present) of each clip of each split. Clips without ``ball.csv`` or events are
  skipped with a warning; missing ``ball.csv`` rows (a real tracker's) are frames without a ball.
"""
from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset, Sampler

from inference.clipio import BallTrack, Clip, FormatError, PlayerTracks
from inference.court import load_court
from inference.events.classes import ClassSet
from inference.events.features import (FeatureConfig, check_label_block, clip_features, make_windows, to_ref_frames,
                                       window_labels, window_starts)

from training.events.synthetic.degrade import DegradeConfig, degrade_all
from training.events.data.parallel import clip_rngs, map_clips
from training.events.synthetic.pose_noise import PoseNoiseConfig, noisy_all, noisy_players
from training.events.synthetic.simulate import SimClip, simulate_clips

log = logging.getLogger(__name__)


# ------------------------------------------------------------------------------------------ clip sets
@dataclass
class LabelledClip:
    """A clip ready for the event models: features at the reference rate and per-frame classes."""

    sim: SimClip
    feats: np.ndarray   # (T', F) float32
    y: np.ndarray       # (T',) int64 classes at the reference rate


def ref_labels(sim: SimClip, class_set: ClassSet, features: FeatureConfig, n_ref: int,
               on_unmapped: str = "error") -> np.ndarray:
    """``(n_ref,)`` classes of the clip's events at the reference frame rate."""
    y_native = class_set.encode(sim.events, sim.n_frames, on_unmapped=on_unmapped, where=sim.name)
    frames = np.flatnonzero(y_native)
    y = np.zeros(n_ref, np.int64)
    ref = np.clip(to_ref_frames(frames, sim.fps, features.ref_fps), 0, max(n_ref - 1, 0))
    for f, c in zip(ref, y_native[frames]):
        if y[f] and f + 1 < n_ref:
            f = f + 1  # two events on one reference frame: keep both
        y[f] = c
    return y


def label_clips(clips: list[SimClip], class_set: ClassSet, features: FeatureConfig,
                on_unmapped: str = "error", workers: int = 0) -> list[LabelledClip]:
    """Features (with each clip's ``players`` when ``features.poses``) and reference-rate labels
    (``workers``: forked processes, :func:`~training.events.data.parallel.map_clips`)."""
    court = load_court(class_set.sport) if class_set.sport else None

    def job(k: int) -> tuple[np.ndarray, np.ndarray]:
        c = clips[k]
        feats = clip_features(c.ball, c.n_frames, c.fps, features, camera=c.camera, court=court, players=c.players)
        return feats, ref_labels(c, class_set, features, len(feats), on_unmapped)

    return [LabelledClip(c, feats, y) for c, (feats, y) in zip(clips, map_clips(job, len(clips), workers))]


def with_tracks(clips: list[LabelledClip], tracks: list[BallTrack], features: FeatureConfig, court=None,
                players: Callable[[int], PlayerTracks | None] | None = None, workers: int = 0) -> list[LabelledClip]:
    """The same clips and labels with other ball tracks (e.g. degraded ones): features recomputed, with the
    players ``players(k)`` draws for clip k when given (drawn in the workers; the returned clips keep their own
    ``sim.players``)."""
    def job(k: int) -> np.ndarray:
        s = clips[k].sim
        pl = s.players if players is None else players(k)
        return clip_features(tracks[k], s.n_frames, s.fps, features, camera=s.camera, court=court, players=pl)

    return [LabelledClip(lc.sim, f, lc.y) for lc, f in zip(clips, map_clips(job, len(clips), workers))]


def clips_from_folder(root, split: str, seed: int = 0, sources=None) -> list[SimClip]:
    """The labelled clips of one split of a dataset folder, a folder of clip folders, or several of them
    (``root`` a list), as :class:`SimClip` (camera None when absent). ``sources``: already resolved roots."""
    return [c for c, _ in clips_with_source(root, split, seed, sources)]


def clips_with_source(root, split: str, seed: int = 0, sources=None, players: bool = False) -> list[tuple[SimClip, int]]:
    """:func:`clips_from_folder` with the index of the root each clip comes from (``players``: read each
    clip's players.csv, else gt/players.csv, when there is one)."""
    from training.datasets import resolve_sources, skip_unlabelled

    out = []
    for k, src in enumerate(sources or resolve_sources(root, None, seed)):
        clips = [Clip(p) for p in src.paths(split)]
        clips = skip_unlabelled(clips, "ball.csv", f"{src.root} ({split})")
        labelled = [c for c in clips if c.events_path.is_file() or (c.gt_dir / "events.csv").is_file()]
        if len(labelled) < len(clips):
            log.warning("%s (%s): %d clip(s) without events.csv skipped (events not labelled yet): %s", src.root,
                        split, len(clips) - len(labelled), ", ".join(c.root.name for c in clips if c not in labelled))
        sims = [_sim_clip(c, players) for c in labelled]
        if not all(s.n_frames for s in sims):
            log.warning("%s (%s): clip(s) without frames skipped (no n_frames in clip.yaml, no video, no ball.csv "
                        "or events.csv row): %s", src.root, split, ", ".join(s.name for s in sims if not s.n_frames))
        out += [(s, k) for s in sims if s.n_frames]
    return out


def _frame_count(clip: Clip, ball: BallTrack, events) -> int:
    """clip.yaml's ``n_frames``, else the video's frame count, else one past the last frame ball.csv or
    events.csv names (0 when none does)."""
    info = clip.info
    if info.n_frames or (clip.root / info.video).exists():
        return info.n_frames or clip.n_frames
    return max([int(t.frame.max()) + 1 for t in (ball, events) if len(t)], default=0)


def _sim_clip(clip: Clip, with_players: bool = False) -> SimClip:
    info = clip.info
    ball = clip.read_ball()
    gt_events = clip.gt_dir / "events.csv"
    events = clip.read_events(gt=gt_events.is_file())
    n = _frame_count(clip, ball, events)
    camera = None
    for gt in (True, False):
        try:
            camera = clip.read_camera(gt=gt)
            break
        except (FileNotFoundError, OSError, FormatError):
            continue
    players = None
    for gt in (False, True) if with_players else ():  # the clip's players.csv (a pose backend's), else gt/
        try:
            players = clip.read_players(gt=gt)
            break
        except (FileNotFoundError, OSError, FormatError):
            continue
    return SimClip(str(clip.root), float(info.fps), int(info.width), int(info.height), n, ball, events, camera,
                   players=players)


# ------------------------------------------------------------------------------------------- windows
def clip_windows(lc: LabelledClip, window: int, last_k: int, lookahead: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """All windows of a clip: ``(N, W, F)`` features and ``(N,)`` labels."""
    return make_windows(lc.feats, window), window_labels(lc.y, window, last_k, lookahead)


class WindowSet(Dataset):
    """Windows of many clips held in memory: ``x (N, W, F) float32``, ``y (N,) int64``."""

    def __init__(self, clips: list[LabelledClip], window: int, last_k: int, lookahead: int = 0):
        xs, ys = zip(*(clip_windows(c, window, last_k, lookahead) for c in clips)) if clips else ((), ())
        self.x = torch.from_numpy(np.concatenate(xs).astype(np.float32)) if xs else torch.zeros(0, window, 1)
        self.y = torch.from_numpy(np.concatenate(ys)) if ys else torch.zeros(0, dtype=torch.long)

    def __len__(self) -> int:
        return len(self.y)

    def __getitem__(self, i):
        return self.x[i], self.y[i]


class BalancedSampler(Sampler):
    """Every positive window each epoch and a fresh random draw of ``neg_ratio`` × as many negatives
    (MonoTrack keeps each negative with probability #pos/#neg).

    With ``weights`` (N,) — per window, e.g. its root's share divided by the root's window count — the
    positives and the negatives are each drawn (with replacement, same counts) in proportion to them:
    how a few real clips are mixed with many synthetic ones."""

    def __init__(self, labels: torch.Tensor, neg_ratio: float = 1.0, seed: int = 0, on_epoch=None,
                 weights: torch.Tensor | None = None, fixed: bool = False):
        self.seed, self.fixed = seed, fixed  # fixed: the same draw every epoch (validation)
        self.on_epoch = on_epoch  # called at the start of each epoch (e.g. new degraded tracks)
        self.pos = torch.nonzero(labels > 0).flatten()
        self.neg = torch.nonzero(labels == 0).flatten()
        self.n_neg = min(len(self.neg), int(round(neg_ratio * max(len(self.pos), 1))))
        self.weights = None if weights is None else torch.as_tensor(weights, dtype=torch.double)
        self.gen = torch.Generator().manual_seed(seed)

    def __len__(self) -> int:
        return len(self.pos) + self.n_neg

    def _draw(self, idx: torch.Tensor, n: int) -> torch.Tensor:
        if self.weights is None:
            return idx[torch.randperm(len(idx), generator=self.gen)[:n]]
        if n == 0 or len(idx) == 0:
            return idx[:0]
        return idx[torch.multinomial(self.weights[idx], n, replacement=True, generator=self.gen)]

    def __iter__(self):
        if self.on_epoch is not None:
            self.on_epoch()
        if self.fixed:
            self.gen.manual_seed(self.seed)
        pos = self.pos if self.weights is None else self._draw(self.pos, len(self.pos))
        idx = torch.cat([pos, self._draw(self.neg, self.n_neg)])
        return iter(idx[torch.randperm(len(idx), generator=self.gen)].tolist())


# ------------------------------------------------------------------------------------- augmentation
@dataclass(frozen=True)
class AugmentConfig:
    """MonoTrack's augmentations on batches of windows (docs/models.md, "HitNet").

    Each window gets one of {identity, drop a 4-frame block, corrupt a 4-frame block, drop 5 % of
    frames, corrupt 5 %, rotate ±15° + shear ≤ 0.1, and combinations} with ``weights``; separately a
    horizontal mirror with probability ``p_mirror`` (class labels permuted by the class set's mirror
    pairs, e.g. ``wall_left`` ↔ ``wall_right``).
    """

    enabled: bool = True
    weights: tuple[float, ...] = (2, 1, 1, 1, 1, 5, 1, 1, 9, 9)
    block: int = 4
    frac: float = 0.05
    rotate_deg: float = 15.0
    shear: float = 0.1
    p_mirror: float = 0.5


OPS = (  # the ten choices of `weights`: (drop/corrupt, block/frac, geometric)
    (), ("drop_block",), ("corrupt_block",), ("drop_frac",), ("corrupt_frac",), ("affine",),
    ("drop_block", "affine"), ("corrupt_block", "affine"), ("drop_frac", "affine"), ("corrupt_frac", "affine"),
)


def position_columns(features: FeatureConfig) -> list[tuple[int, int]]:
    """(x, y) column pairs that hold image positions in ``[1, 2]`` (0 = missing)."""
    pairs = [(0, 1)]
    base = 5 if features.velocity else 2
    if features.corners:
        pairs += [(base + 2 * k, base + 2 * k + 1) for k in range(4)]
        base += 8
    return pairs


def player_offset_columns(features: FeatureConfig) -> tuple[list[tuple[int, int]], list[int], list[int]]:
    """Columns of the ``poses`` block: (x, y) pairs of image offsets (rotate and mirror with the image),
    the court-x columns (mirror) and the ball-relative columns (zeroed where the ball is dropped)."""
    if not features.poses:
        return [], [], []
    from inference.events.features import PLAYER_COLUMNS, SIDES

    col = {n: i for i, n in enumerate(PLAYER_COLUMNS)}
    pairs, court_x, ball_rel = [], [], []
    for s in range(len(SIDES)):
        o = features.player_offset + s * len(PLAYER_COLUMNS)
        pairs += [(o + col[a], o + col[b]) for a, b in (("body_dx", "body_dy"), ("wrist_dx", "wrist_dy"),
                                                         ("racket_wrist_x", "racket_wrist_y"),
                                                         ("other_wrist_x", "other_wrist_y"))]
        court_x.append(o + col["court_x"])
        ball_rel += [o + col[n] for n in ("body_dx", "body_dy", "wrist_dx", "wrist_dy")]
    return pairs, court_x, ball_rel


def augment_batch(x: torch.Tensor, y: torch.Tensor, features: FeatureConfig, cfg: AugmentConfig,
                  mirror_perm: torch.Tensor, gen: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Augment ``(B, W, F)`` windows and their labels ``(B,)``, or crops and their per-frame labels ``(B, W)``
    (see :class:`AugmentConfig`). Batches on an accelerator are augmented on the CPU (the random draws
    and ``gen`` live there) and moved back."""
    if not cfg.enabled or len(x) == 0:
        return x, y
    if x.device.type != "cpu":
        xa, ya = augment_batch(x.cpu(), y.cpu(), features, cfg, mirror_perm.cpu(), gen)
        return xa.to(x.device, non_blocking=True), ya.to(y.device, non_blocking=True)
    x = x.clone()
    B, W, _ = x.shape
    w = torch.tensor(cfg.weights, dtype=torch.float)
    op = torch.multinomial(w / w.sum(), B, replacement=True, generator=gen)
    pairs = position_columns(features)
    ball_cols = list(range(5 if features.velocity else 2))
    # geometric: rotation + shear about the image centre (1.5, 1.5), and the mirror
    ang = (torch.rand(B, generator=gen) * 2 - 1) * np.radians(cfg.rotate_deg)
    sh = (torch.rand(B, generator=gen) * 2 - 1) * cfg.shear
    geo = torch.tensor([("affine" in OPS[int(o)]) for o in op])
    ang, sh = torch.where(geo, ang, 0.0), torch.where(geo, sh, 0.0)
    mirror = torch.rand(B, generator=gen) < cfg.p_mirror
    c, s = torch.cos(ang), torch.sin(ang)
    A = torch.stack([torch.stack([c, -s + sh * c], 1), torch.stack([s, c + sh * s], 1)], 1)  # (B, 2, 2)
    A[:, 0, :] *= torch.where(mirror, -1.0, 1.0)[:, None]
    for cx, cy in pairs:
        p = x[:, :, [cx, cy]]
        known = (p != 0).any(dim=2, keepdim=True)
        q = torch.einsum("bij,bwj->bwi", A, p - 1.5) + 1.5
        x[:, :, [cx, cy]] = torch.where(known, q, p)
    if features.velocity:
        x[:, :, 2:4] = torch.einsum("bij,bwj->bwi", A, x[:, :, 2:4])
    offsets, court_x, ball_rel = player_offset_columns(features)
    for cx, cy in offsets:  # image offsets: rotated and mirrored, never translated
        x[:, :, [cx, cy]] = torch.einsum("bij,bwj->bwi", A, x[:, :, [cx, cy]])
    if court_x:  # a mirrored image is the court seen mirrored
        x[:, :, court_x] = torch.where(mirror[:, None, None], -x[:, :, court_x], x[:, :, court_x])
    m = mirror.view(-1, *([1] * (y.dim() - 1)))  # y: (B,) window labels or (B, T) per-frame (negative: ignored)
    y = torch.where(m & (y >= 0), mirror_perm[y.clamp(min=0)], y)
    # drops and corruptions of the ball columns (vectorised: a (B, W) mask of affected frames)
    names = [OPS[int(o)] for o in op]
    is_block = torch.tensor([any(n.endswith("block") for n in ns) for ns in names])
    is_frac = torch.tensor([any(n.endswith("frac") for n in ns) for ns in names])
    is_drop = torch.tensor([any(n.startswith("drop") for n in ns) for ns in names])
    start = torch.randint(0, max(W - cfg.block, 1), (B, 1), generator=gen)
    steps = torch.arange(W)[None]
    rows = (is_block[:, None] & (steps >= start) & (steps < start + cfg.block)) | (
        is_frac[:, None] & (torch.rand(B, W, generator=gen) < cfg.frac))
    drop = rows & is_drop[:, None]
    corrupt = rows & ~is_drop[:, None]
    x[:, :, ball_cols + ball_rel] = torch.where(drop[..., None], 0.0, x[:, :, ball_cols + ball_rel])
    x[:, :, 0:2] = torch.where(corrupt[..., None], 1.0 + torch.rand(B, W, 2, generator=gen), x[:, :, 0:2])
    if features.velocity:
        x[:, :, 2:4] = torch.where(corrupt[..., None], torch.randn(B, W, 2, generator=gen) * 0.1, x[:, :, 2:4])
        x[:, :, 4] = torch.where(corrupt, 1.0, x[:, :, 4])
    return x, y


# -------------------------------------------------------------------------------------- data module
def camera_shares(cameras: dict | None) -> dict[str, float] | None:
    """``data.cameras`` checked: ``{preset: share}`` with known presets and positive shares summing to 1 (None
    stays None).

    Raises:
        ValueError: naming the preset or the share to fix.
    """
    if cameras is None:
        return None
    from synth.cameras import CameraSpec

    if not isinstance(cameras, dict) or not cameras:
        raise ValueError(f"data.cameras must map camera presets to shares, e.g. {{padel_installed: 0.5, padel_tv: 0.5}}; "
                         f"got {cameras!r}")
    out = {}
    for name, share in cameras.items():
        try:
            CameraSpec.preset(str(name))
        except KeyError as e:
            raise ValueError(f"data.cameras: {e.args[0]}") from None
        if not isinstance(share, (int, float)) or not share > 0:
            raise ValueError(f"data.cameras.{name}: a share must be a positive number, got {share!r}")
        out[str(name)] = float(share)
    total = sum(out.values())
    if abs(total - 1.0) > 1e-6:
        raise ValueError(f"data.cameras: the shares add up to {total:g}, not 1")
    return out


def split_counts(n: int, shares: dict[str, float]) -> dict[str, int]:
    """``n`` clips split in proportion to ``shares`` (largest remainders; the counts add up to ``n``)."""
    names = list(shares)
    raw = np.array([shares[k] * n for k in names])
    counts = np.floor(raw).astype(int)
    for i in np.argsort(-(raw - counts), kind="stable")[:n - int(counts.sum())]:
        counts[i] += 1
    return {k: int(c) for k, c in zip(names, counts)}


class EventDataModule(L.LightningDataModule):
    """Windows for HitNet training, or crops of whole clips for the event tagger (``sequence``; see the
    module docstring for the sources).

    Args:
        sport, class_set: the class set (name or dict); features: :class:`FeatureConfig` fields.
        window, last_k, lookahead: W, K and L — a window's label is the event in its K frames that end
            L frames before its end (L > 0 lets the network see the ball and players after the event).
        source: ``synthetic`` or ``folder``; root: a dataset folder, a folder of clip folders, or a list of these; root_weights: per root, its share of the training windows
            (None: by size); split_seed: seed of an inferred split (default ``seed``).
        n_train, n_val, n_test, seed: synthetic clip counts; seeds ``seed``, ``seed + 1``, ``seed + 2``.
        on_unmapped: ``error`` or ``warn`` for labels the class set does not cover.
        neg_ratio: negatives per positive per epoch. cache_dir: simulated clips are cached here.
        around: share of the synthetic clips simulated with the server's bounces before the serve and the
            ball after the point (not events: the model learns they are none).
        tour: share of the synthetic clips played at a tour final's pace (tennis: faster, flatter
            groundstrokes from deeper, :data:`synth.rally.TENNIS_TOUR`); the rest at the club pace.
        tour_camera: the camera preset that films the tour-pace clips (:mod:`synth.cameras`; ``tennis_tv``: a
            tour broadcast's long lens far behind the baseline); None: the sport's default camera.
        cameras: the camera presets that film the club-pace clips and their shares, e.g. ``{padel_installed: 0.5,
            padel_tv: 0.5}`` (a club's fixed camera beside a tour broadcast's); None: the sport's default camera
            (each preset's clips have their own seeds: the default set is unchanged).
        degrade: :class:`~training.events.synthetic.degrade.DegradeConfig` fields: train on detector-like tracks
            (new draws each epoch) and validate on the clean clips plus ``val_copies`` degraded copies;
            None or ``enabled: false`` keeps the annotated tracks.
        pose_noise: :class:`~training.events.synthetic.pose_noise.PoseNoiseConfig` fields: with ``features.poses``,
            the players as a pose backend gives them (misses, jitter, swaps; a new draw each epoch for
            training, a fixed one for val and test); None or ``enabled: false`` keeps them exact.
        sequence: 0 (HitNet's windows) or the crop length in reference frames of the event tagger's
            examples (:class:`~training.events.data.sequences.SequenceSet`: ``sequence_repeats`` random crops per
            training clip and epoch, events spread over ± ``sequence_radius`` frames); ``batch_size`` then
            counts crops.
        prep_workers: forked processes for the per-clip data work (simulation, labelling, each epoch's new
            degraded tracks and players; :mod:`.parallel`): the same data as 0, faster on many cores. 0 or 1:
            in this process. (``num_workers`` is the DataLoader's.)
    """

    def __init__(self, sport: str = "padel", class_set: str | dict = "padel6", features: dict | None = None,
                 window: int = 12, last_k: int = 6, lookahead: int = 0, source: str = "synthetic",
                 root: str | None = None,
                 n_train: int = 600, n_val: int = 100, n_test: int = 200, seed: int = 0,
                 on_unmapped: str = "error", neg_ratio: float = 1.0, batch_size: int = 256,
                 num_workers: int = 0, cache_dir: str | None = None, augment: dict | None = None,
                 degrade: dict | None = None, root_weights: list[float] | None = None,
                 split_seed: int | None = None, around: float = 0.0, pose_noise: dict | None = None,
                 sequence: int = 0, sequence_radius: int = 1, sequence_repeats: int = 2, prep_workers: int = 0,
                 tour: float = 0.0, tour_camera: str | None = None, cameras: dict | None = None):
        super().__init__()
        if source not in ("synthetic", "folder"):
            raise ValueError(f"data.source must be 'synthetic' or 'folder', got {source!r}")
        if source == "folder" and not root:
            raise ValueError("data.source=folder needs data.root=DATASET_FOLDER")
        try:
            check_label_block(window, last_k, lookahead)
        except ValueError as e:
            raise ValueError(f"data.window/last_k/lookahead: {e}") from None
        self.sport, self.class_set = sport, ClassSet.load(class_set)
        self.features = FeatureConfig.from_dict(features or {})
        self.window, self.last_k, self.source, self.root = window, last_k, source, root
        self.lookahead = int(lookahead)
        if sequence and int(sequence) < 8:
            raise ValueError(f"data.sequence must be 0 (windows) or a crop length of at least 8 frames, got {sequence}")
        self.sequence, self.sequence_radius = int(sequence or 0), int(sequence_radius)
        self.sequence_repeats = max(int(sequence_repeats), 1)
        self.root_weights, self.split_seed = root_weights, seed if split_seed is None else split_seed
        if not 0.0 <= float(around) <= 1.0:
            raise ValueError(f"data.around must be a fraction in [0, 1], got {around!r}")
        self.around = float(around)
        if not 0.0 <= float(tour) <= 1.0:
            raise ValueError(f"data.tour must be a fraction in [0, 1], got {tour!r}")
        if tour and source == "synthetic":
            from synth.rally import default_config

            try:
                default_config(sport, "tour")
            except KeyError as e:
                raise ValueError(f"data.tour: {e.args[0]}; set data.tour=0") from None
        self.tour = float(tour)
        if tour_camera is not None:
            from synth.cameras import CameraSpec

            try:
                CameraSpec.preset(str(tour_camera))
            except KeyError as e:
                raise ValueError(f"data.tour_camera: {e.args[0]}") from None
        self.tour_camera = None if tour_camera is None else str(tour_camera)
        self.cameras = camera_shares(cameras)
        self._sources = None
        self.clip_source: dict[str, list[int]] = {}  # per split: the root index of each clip
        self.counts = {"train": n_train, "val": n_val, "test": n_test}
        self.seed, self.on_unmapped, self.neg_ratio = seed, on_unmapped, neg_ratio
        self.batch_size, self.num_workers, self.cache_dir = batch_size, num_workers, cache_dir
        if int(prep_workers or 0) < 0:
            raise ValueError(f"data.prep_workers must be 0 (in this process) or a number of processes, got {prep_workers}")
        self.prep_workers = int(prep_workers or 0)
        self.augment = AugmentConfig(**(augment or {}))
        self.degrade = DegradeConfig.from_dict(degrade)
        self.pose_noise = PoseNoiseConfig.from_dict(pose_noise)
        self._draw = 0  # degradation draws of the training split so far
        self._exact: dict[str, list[SimClip]] = {}  # per split: the clips with their exact players
        self.clips: dict[str, list[LabelledClip]] = {}
        self.sets: dict[str, WindowSet] = {}

    @property
    def sources(self):
        """The resolved roots of ``source: folder`` (inferred manifests included)."""
        if self._sources is None:
            from training.datasets import resolve_sources

            self._sources = resolve_sources(self.root, self.root_weights, self.split_seed)
        return self._sources

    def raw_clips(self, split: str) -> list[SimClip]:
        if self.source == "folder":
            pl = self.features.poses
            pairs = clips_with_source(self.root, split, self.split_seed, self.sources, pl)
            if not pairs and split == "val":
                log.warning("no labelled validation clips: tuning and checkpointing on the training clips "
                            "(optimistic); give the dataset a val split for an honest one")
                pairs = clips_with_source(self.root, "train", self.split_seed, self.sources, pl)
            clips = [c for c, _ in pairs]
            self.clip_source[split] = [k for _, k in pairs]
        else:
            offset = {"train": 0, "val": 1, "test": 2}[split]
            n = self.counts[split]
            n_tour = int(round(self.tour * n))
            pl = self.features.poses  # players articulated and projected only when the model reads them
            w = self.prep_workers
            clips = []
            groups = [("tour", n_tour, self.seed * 10 + offset + 1000, self.tour_camera)]
            if self.cameras is None:
                groups.insert(0, ("club", n - n_tour, self.seed * 10 + offset, None))
            else:
                for i, (cam, n_cam) in enumerate(split_counts(n - n_tour, self.cameras).items()):
                    groups.insert(i, ("club", n_cam, self.seed * 10 + offset + 3000 + 100 * i, cam))
            for pace, n_pace, base, cam in groups:
                n_around = int(round(self.around * n_pace))
                if n_pace > n_around:
                    clips += simulate_clips(self.sport, n_pace - n_around, base, self.cache_dir, players=pl,
                                            workers=w, pace=pace, camera=cam)
                if n_around:  # rallies with the server's bounces before the serve and the ball after the point
                    clips += simulate_clips(self.sport, n_around, base + 5, self.cache_dir, around=True,
                                            players=pl, workers=w, pace=pace, camera=cam)
        return clips

    def labelled(self, split: str) -> list[LabelledClip]:
        if split not in self.clips:
            raw = self.raw_clips(split)
            if not raw:
                raise ValueError(f"the {split} split of {self.root or 'the synthetic data'} has no clips")
            self._exact[split] = raw
            if self.features.poses:  # the players as a pose backend would give them (a fixed draw per split)
                raw = [replace(c, players=p) for c, p in zip(raw, self.players_draw(split, raw, 0))]
            self.clips[split] = label_clips(raw, self.class_set, self.features, self.on_unmapped, self.prep_workers)
            n_ev = sum(int((c.y > 0).sum()) for c in self.clips[split])
            if n_ev == 0:
                log.warning("the %s split has no events of the class set %s: the model cannot learn events "
                            "from it", split, self.class_set.name)
        return self.clips[split]

    def players_seed(self, split: str, draw: int) -> int:
        """The pose-noise seed of a split's draw."""
        offset = {"train": 0, "val": 1, "test": 2}[split]
        return (self.seed * 10 + offset) * 1000 + 500 + draw

    def players_draw(self, split: str, sims: list[SimClip], draw: int) -> list:
        """Noisy players of ``sims`` (:mod:`.pose_noise`; a fixed seed per split and draw)."""
        return noisy_all(sims, self.players_seed(split, draw), self.pose_noise, self.prep_workers)

    def degraded(self, split: str, draw: int = 0) -> list[LabelledClip]:
        """The clips of ``split`` with degraded tracks (draw ``draw``: a fixed seed per split and draw); with
        ``features.poses`` and a draw > 0, features from new noisy players too (drawn per clip, in the
        ``prep_workers``; the clips' ``sim.players`` stay the split's fixed draw)."""
        clips = self.labelled(split)
        offset = {"train": 0, "val": 1, "test": 2}[split]
        seed = (self.seed * 10 + offset) * 1000 + draw
        court = load_court(self.class_set.sport) if self.class_set.sport else None
        tracks = degrade_all([c.sim for c in clips], seed, self.degrade, self.prep_workers)
        players = None
        if self.features.poses and draw > 0:
            exact = self._exact[split]
            rngs = clip_rngs(self.players_seed(split, draw), len(exact))
            players = lambda k: noisy_players(exact[k], rngs[k], self.pose_noise)  # noqa: E731
        return with_tracks(clips, tracks, self.features, court, players, self.prep_workers)

    def tuning_clips(self) -> tuple[list[SimClip], list]:
        """Validation clips and their tracks for temperature and decoder tuning: the annotated tracks, plus
        ``val_copies`` degraded copies when degradation is on."""
        val = self.labelled("val")
        sims, tracks = [c.sim for c in val], [c.sim.ball for c in val]
        if self.degrade.enabled:
            for k in range(int(self.degrade.val_copies)):
                sims += [c.sim for c in val]
                tracks += degrade_all([c.sim for c in val], (self.seed * 10 + 1) * 1000 + k, self.degrade)
        return sims, tracks

    def setup(self, stage: str | None = None) -> None:
        splits = ("train", "val") if stage in (None, "fit", "validate") else ("test",)
        for split in splits:
            if split in self.sets:
                continue
            clips = self.labelled(split)
            if self.degrade.enabled and split == "train":
                clips = self.degraded("train", 0)
            elif self.degrade.enabled and split == "val":
                clips = clips + [c for k in range(int(self.degrade.val_copies)) for c in self.degraded("val", k)]
            self.sets[split] = self.example_set(clips, split)

    def example_set(self, clips: list[LabelledClip], split: str):
        """HitNet's windows, or the tagger's crops (:attr:`sequence`) of these clips."""
        if not self.sequence:
            return WindowSet(clips, self.window, self.last_k, self.lookahead)
        from training.events.data.sequences import SequenceSet

        return SequenceSet(clips, self.sequence, self.sequence_radius, random=split == "train",
                           repeats=self.sequence_repeats)

    def redraw(self) -> None:
        """New degraded tracks for the training windows or crops (in place: same windows, same labels); the
        first call keeps the draw made by :meth:`setup`."""
        if self._draw > 0:
            ds = self.sets["train"]
            if self.sequence:
                ds.clips = self.degraded("train", self._draw)
            else:
                ds.x = WindowSet(self.degraded("train", self._draw), self.window, self.last_k, self.lookahead).x
        self._draw += 1

    def train_dataloader(self):
        ds = self.sets["train"]
        if self.sequence:
            return self._sequence_loader(ds)
        if int((ds.y > 0).sum()) == 0:
            raise ValueError("the training split has no events: nothing to learn (check events.csv and the "
                             f"class set {self.class_set.name})")
        noisy_poses = self.features.poses and self.pose_noise.enabled
        redraw = self.redraw if (self.degrade.enabled and self.degrade.every_epoch) or noisy_poses else None
        return DataLoader(ds, batch_size=self.batch_size,
                          sampler=BalancedSampler(ds.y, self.neg_ratio, self.seed, on_epoch=redraw,
                                                  weights=self.window_weights()),
                          num_workers=self.num_workers)

    def _sequence_loader(self, ds) -> DataLoader:
        """The tagger's training crops: every clip ``sequence_repeats`` times per epoch in a new order (drawn
        by root share with ``root_weights``), new degraded tracks each epoch."""
        if not any((t > 0).any() for t in ds.targets):
            raise ValueError("the training split has no events: nothing to learn (check events.csv and the "
                             f"class set {self.class_set.name})")
        noisy_poses = self.features.poses and self.pose_noise.enabled
        redraw = self.redraw if (self.degrade.enabled and self.degrade.every_epoch) or noisy_poses else None
        w = self.clip_weights()
        weights = None if w is None else w.repeat(self.sequence_repeats)  # item i is clip i % n_clips
        sampler = BalancedSampler(torch.ones(len(ds), dtype=torch.long), 0.0, self.seed, on_epoch=redraw,
                                  weights=weights)
        return DataLoader(ds, batch_size=self.batch_size, sampler=sampler, num_workers=self.num_workers)

    def clip_weights(self) -> torch.Tensor | None:
        """Per training clip, its sampling weight when ``root_weights`` mixes several roots (else None)."""
        if not self._mixes_roots():
            return None
        return self._root_shares(np.asarray(self.clip_source.get("train", []), np.int64))

    def _mixes_roots(self) -> bool:
        return self.source == "folder" and bool(self.root_weights) and len(self.root_weights) >= 2

    def _root_shares(self, src: np.ndarray) -> torch.Tensor:
        """Per item (its root index in ``src``), its root's share divided by the root's item count, normalised."""
        counts = np.bincount(src, minlength=len(self.root_weights)).astype(float)
        w = np.asarray(self.root_weights, float)[src] / np.maximum(counts[src], 1)
        return torch.as_tensor(w / w.sum())

    def window_weights(self) -> torch.Tensor | None:
        """Per training window, its sampling weight when ``root_weights`` mixes several roots (else None)."""
        if not self._mixes_roots():
            return None
        clips, roots = self.labelled("train"), self.clip_source.get("train", [])
        per_clip = [len(window_starts(len(c.feats), self.window)) for c in clips]  # as clip_windows cuts them
        return self._root_shares(np.repeat(np.asarray(roots, np.int64), per_clip))

    def val_dataloader(self):
        """The same windows every epoch (all positives, 3 × as many negatives drawn once); under DDP each
        rank validates its unpadded shard of them."""
        from training.distributed import eval_sampler

        ds = self.sets["val"]
        if self.sequence:  # every crop of every validation clip, in order
            return DataLoader(ds, batch_size=self.batch_size, num_workers=self.num_workers,
                              sampler=eval_sampler(getattr(self, "trainer", None), ds))
        sampler = BalancedSampler(ds.y, 3.0, self.seed + 1, fixed=True)
        return DataLoader(ds, batch_size=self.batch_size * 4, num_workers=self.num_workers,
                          sampler=eval_sampler(getattr(self, "trainer", None), sampler) or sampler)

    def test_dataloader(self):
        from training.distributed import eval_sampler

        self.setup("test")
        ds = self.sets["test"]
        return DataLoader(ds, batch_size=self.batch_size * 4, num_workers=self.num_workers,
                          sampler=eval_sampler(getattr(self, "trainer", None), ds))

    def prepare_data(self) -> None:
        """Simulate (and cache) the rallies once: Lightning calls this on one process per node before
        every rank's :meth:`setup`."""
        if self.source == "synthetic" and self.cache_dir:
            for split in ("train", "val"):
                self.raw_clips(split)
