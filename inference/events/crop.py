"""The crop hit-event model: HitNet that also sees a small image patch around the ball in every frame.

The thesis found that padel events need visual context (a racket next to the ball, the wall behind it);
this model adds it cheaply. Per reference frame (the track resampled to ``ref_fps``, as for HitNet):

1. a square crop of side ``context × image width`` pixels centred on the ball, zero-padded outside the
   image and resized to ``size × size`` (all zeros when the ball is missing) — :func:`extract_crops`
   streams the clip's frames once and never holds the whole video;
2. a tiny CNN (:class:`CropEncoder`, three strided convolutions, global average pool, linear; ~15k
   parameters) turns it into ``embed`` numbers, set to 0 where the ball is missing;
3. these are concatenated with the ball-only features of :mod:`.features` and the windows go through the
   same GRU head as HitNet (:class:`~inference.events.network.HitNet`).

Shapes: crops ``(T', S, S, 3) uint8`` (RGB, S = ``size``); features ``(T', F)``; per-frame inputs of the
head ``(T', F + E)``; windows ``(B, W, F + E)`` → logits ``(B, C)``.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from .network import HitNet


@dataclass(frozen=True)
class CropConfig:
    """How crops are cut.

    Attributes:
        size: side of the resized crop in pixels (S).
        context: side of the cut square as a fraction of the image width (0.05 = 64 px at 1280 wide).
    """

    size: int = 32
    context: float = 0.05

    def __post_init__(self) -> None:
        if not 8 <= int(self.size) <= 128:
            raise ValueError(f"crop size must be in 8..128 px, got {self.size}")
        if not 0.005 <= float(self.context) <= 0.5:
            raise ValueError(f"crop context must be a fraction of the image width in 0.005..0.5, got {self.context}")

    @classmethod
    def from_dict(cls, d) -> CropConfig:
        if isinstance(d, CropConfig):
            return d
        d = dict(d or {})
        return cls(**{k: d[k] for k in ("size", "context") if k in d})

    def to_dict(self) -> dict:
        return {"size": int(self.size), "context": float(self.context)}

    def side_px(self, width: int) -> int:
        """Side of the cut square in pixels of an image ``width`` wide (at least 4)."""
        return max(int(round(self.context * width)), 4)


# ------------------------------------------------------------------------------------------ extraction
def crop_at(frame: np.ndarray, center_px: np.ndarray, side: int, size: int) -> np.ndarray:
    """``(size, size, 3) uint8``: the ``side × side`` square of ``frame (H, W, 3)`` centred on
    ``center_px = (x, y)`` (pixels), zeros outside the image, resized to ``size``; all zeros when the
    centre is not finite."""
    out = np.zeros((side, side, 3), np.uint8)
    if not np.all(np.isfinite(center_px)):
        return np.zeros((size, size, 3), np.uint8)
    h, w = frame.shape[:2]
    x0 = int(np.floor(center_px[0] - side / 2 + 0.5))
    y0 = int(np.floor(center_px[1] - side / 2 + 0.5))
    sx0, sy0 = max(x0, 0), max(y0, 0)
    sx1, sy1 = min(x0 + side, w), min(y0 + side, h)
    if sx1 > sx0 and sy1 > sy0:
        out[sy0 - y0:sy1 - y0, sx0 - x0:sx1 - x0] = frame[sy0:sy1, sx0:sx1]
    if side == size:
        return out
    interp = cv2.INTER_AREA if side > size else cv2.INTER_LINEAR
    return cv2.resize(out, (size, size), interpolation=interp)


def ref_to_source(n_ref: int, fps: float, ref_fps: float | None, n_frames: int) -> np.ndarray:
    """``(n_ref,)`` the clip frame shown at each reference frame (nearest, clipped to the clip)."""
    if ref_fps is None:
        return np.clip(np.arange(n_ref), 0, max(n_frames - 1, 0))
    return np.clip(np.round(np.arange(n_ref) * fps / ref_fps).astype(np.int64), 0, max(n_frames - 1, 0))


def extract_crops(frames, xy_ref: np.ndarray, fps: float, ref_fps: float | None, config: CropConfig,
                  n_frames: int | None = None, progress: bool = False) -> np.ndarray:
    """Crops around the ball at every reference frame, streaming the clip's frames once, in order.

    Args:
        frames: a ``FrameSource`` (or any sequence of ``(H, W, 3)`` RGB frames with ``iter(start, stop)``
            or plain iteration).
        xy_ref: ``(T', 2)`` ball positions at the reference rate, normalised image coordinates, NaN where
            missing (``resample_xy(dense_xy(ball, n), fps, ref_fps)``).
        fps, ref_fps: the clip's and the reference frame rates; n_frames: frames in the clip.

    Returns:
        ``(T', S, S, 3) uint8``; all-zero crops where the ball is missing.
    """
    n_ref = len(xy_ref)
    S = int(config.size)
    out = np.zeros((n_ref, S, S, 3), np.uint8)
    if n_frames is None:
        n_frames = len(frames)
    src = ref_to_source(n_ref, fps, ref_fps, n_frames)
    seen = np.isfinite(xy_ref).all(axis=1)
    if not seen.any():
        return out
    need: dict[int, list[int]] = {}
    for t in np.flatnonzero(seen):
        need.setdefault(int(src[t]), []).append(int(t))
    last = max(need) + 1
    it = frames.iter(0, last) if hasattr(frames, "iter") else iter(frames)
    side, count = None, 0
    for i, frame in enumerate(tqdm(it, total=last, desc="ball crops", disable=not progress, leave=False)):
        if i >= last:
            break
        count = i + 1
        ts = need.get(i)
        if not ts:
            continue
        h, w = frame.shape[:2]
        side = side or config.side_px(w)
        for t in ts:
            out[t] = crop_at(frame, xy_ref[t] * np.array([w, h], float), side, S)
    if count < last:
        raise ValueError(f"the frame source ended after {count} frames but the ball track needs frame {last - 1}; "
                         "check clip.yaml's n_frames against the video")
    return out


# ---------------------------------------------------------------------------------------------- network
class CropEncoder(nn.Module):
    """Tiny CNN: ``(N, S, S, 3) uint8`` crops → ``(N, E)`` embeddings.

    Each crop is scaled to [0, 1] and its per-channel mean is removed (brightness invariance), then
    three 3×3 stride-2 convolutions with ReLU, a global average pool and a linear layer.
    """

    def __init__(self, embed: int = 16, channels: tuple[int, ...] = (16, 32, 32)):
        super().__init__()
        layers, c_in = [], 3
        for c in channels:
            layers += [nn.Conv2d(c_in, c, 3, stride=2, padding=1), nn.ReLU(inplace=True)]
            c_in = c
        self.convs = nn.Sequential(*layers)
        self.proj = nn.Linear(c_in, embed)

    def forward(self, crops: torch.Tensor) -> torch.Tensor:
        x = crops.permute(0, 3, 1, 2).float() / 255.0
        x = x - x.mean(dim=(2, 3), keepdim=True)
        return self.proj(self.convs(x).mean(dim=(2, 3)))


class CropHitNet(nn.Module):
    """HitNet over per-frame ``[ball features, crop embedding]``.

    Args:
        n_features: F ball features per frame; n_classes: C.
        hidden, layers, bidirectional, dropout: the GRU head (as :class:`HitNet`).
        crop_size: S; embed: E; channels: the encoder's conv widths.

    Shapes:
        ``frame_inputs(feats (T, F), crops (T, S, S, 3) uint8)`` → ``(T, F + E)``;
        ``forward(x (B, W, F), crops (B, W, S, S, 3) uint8)`` → logits ``(B, C)``;
        ``probs(z (B, W, F + E))`` → calibrated probabilities ``(B, C)`` of windows of frame inputs.
    """

    def __init__(self, n_features: int, n_classes: int, hidden: int = 64, layers: int = 2,
                 bidirectional: bool = True, dropout: float = 0.0, crop_size: int = 32, embed: int = 16,
                 channels: tuple[int, ...] | list[int] = (16, 32, 32)):
        super().__init__()
        channels = tuple(int(c) for c in channels)
        self.hparams = {"n_features": n_features, "n_classes": n_classes, "hidden": hidden, "layers": layers,
                        "bidirectional": bidirectional, "dropout": dropout, "crop_size": crop_size,
                        "embed": embed, "channels": list(channels)}
        self.n_features, self.crop_size = int(n_features), int(crop_size)
        self.encoder = CropEncoder(embed, channels)
        self.head = HitNet(n_features + embed, n_classes, hidden, layers, bidirectional, dropout)

    @property
    def temperature(self) -> torch.Tensor:
        return self.head.temperature

    def embed_crops(self, crops: torch.Tensor, seen: torch.Tensor, batch_size: int = 4096) -> torch.Tensor:
        """``(N, S, S, 3)`` crops and ``(N,)`` bool ball-seen → ``(N, E)``, 0 where not seen."""
        if crops.shape[1:] != (self.crop_size, self.crop_size, 3):
            raise ValueError(f"crops must be (N, {self.crop_size}, {self.crop_size}, 3), got {tuple(crops.shape)}")
        z = torch.cat([self.encoder(crops[i:i + batch_size]) for i in range(0, len(crops), batch_size)]) \
            if len(crops) else torch.zeros(0, self.encoder.proj.out_features)
        return z * seen[:, None].to(z.dtype)

    def frame_inputs(self, feats: torch.Tensor, crops: torch.Tensor) -> torch.Tensor:
        """Per-frame head inputs ``(T, F + E)`` (the ball is seen where its position features are non-zero)."""
        if feats.shape[-1] != self.n_features or len(feats) != len(crops):
            raise ValueError(f"need feats (T, {self.n_features}) and crops (T, S, S, 3) of the same T, got "
                             f"{tuple(feats.shape)} and {tuple(crops.shape)}")
        seen = (feats[:, :2] != 0).any(dim=1)
        return torch.cat([feats, self.embed_crops(crops, seen)], dim=1)

    def forward(self, x: torch.Tensor, crops: torch.Tensor) -> torch.Tensor:
        B, W, F = x.shape
        z = self.frame_inputs(x.reshape(B * W, F), crops.reshape(B * W, *crops.shape[2:]))
        return self.head(z.reshape(B, W, -1))

    @torch.no_grad()
    def probs(self, z: torch.Tensor, batch_size: int = 4096) -> torch.Tensor:
        """Calibrated class probabilities ``(B, C)`` of windows of frame inputs ``(B, W, F + E)``."""
        return self.head.probs(z, batch_size)

    @torch.no_grad()
    def clip_probs(self, feats: np.ndarray, crops: np.ndarray, window: int) -> np.ndarray:
        """``(T + W + 1, C)`` window probabilities of a whole clip (features and crops at the reference
        rate); the crops go through the CNN once per frame, not once per window."""
        from .features import make_windows

        z = self.frame_inputs(torch.from_numpy(np.ascontiguousarray(feats, np.float32)),
                              torch.from_numpy(np.ascontiguousarray(crops)))
        wins = torch.from_numpy(make_windows(z.numpy(), window))
        return self.probs(wins).numpy().astype(np.float64)


def n_parameters(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())
