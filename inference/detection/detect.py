"""Ball detection on a whole clip: stream frames → letterbox → batched N-frame windows through the
network at full resolution → heatmap candidates in original pixels → online tracker → ball.csv rows.

The video is streamed (never held in memory); windows are non-overlapping (``step = frames_out``) as in
WASB-SBDT, or overlapping with candidates pooled per frame (``step = 1``).

Example:
    >>> det = BallDetectorRunner.from_weights("wasb", SHIPPED)           # the shipped padel weights
    >>> result = det.run(Clip("clip"))                                   # DetectionResult
    >>> clip.write_ball(result.track)
"""
from __future__ import annotations

import logging
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from inference.clipio import BallTrack, Clip, FormatError
from inference.masks import apply_mask, clip_mask
from inference.models.checkpoint import load_detector
from inference.models.fuse import fold_batchnorm

from .geometry import Letterbox
from .preprocess import normalize
from .postprocess import FrameCandidates, PostprocessConfig, heatmaps_to_candidates, pool_candidates
from .tracker import TrackerConfig, TrackResult, track_candidates

log = logging.getLogger(__name__)
WEIGHTS_DIR = Path(__file__).resolve().parent.parent / "weights"
SHIPPED = {"wasb": WEIGHTS_DIR / "wasb_padel.pth.tar"}
#: the sport each shipped checkpoint was trained on
SHIPPED_SPORT = {"wasb": "padel"}


def shipped_weights(model: str, sport: str | None) -> tuple[Path | None, str]:
    """The shipped checkpoint of ``model`` for ``sport`` and a sentence that says which model it is.

    There is no tennis ball detector yet: a tennis clip gets the padel weights, and the sentence says so
    (and how to train one), so nobody mistakes it for a tennis model.
    """
    path = SHIPPED.get(model)
    if path is None:
        return None, f"no shipped weights for {model!r}"
    trained = SHIPPED_SPORT[model]
    if sport and sport != trained:
        return path, (f"no {sport} ball detector is shipped: using the {trained} {model.upper()} weights "
                      f"({path.name}, trained on {trained} clips only; expect lower recall). Train one with "
                      f"`python train.py +experiment={model}_{sport}` and pass it with --weights/--detector")
    return path, f"{model.upper()} weights trained on {trained} ({path.name})"


@dataclass
class DetectionResult:
    """Per-frame candidates, the tracked ball and timing of one clip."""

    candidates: list[FrameCandidates]
    tracked: TrackResult
    track: BallTrack
    seconds_network: float
    seconds_total: float
    n_frames: int
    truncated: str | None = None  # why decoding stopped before the video's reported end, if it did

    @property
    def fps(self) -> float:
        return self.n_frames / self.seconds_total if self.seconds_total else float("nan")


@dataclass
class BallDetectorRunner:
    """A detector network with its pre/post-processing.

    Args:
        model: maps (B, 3·F, H, W) to (B, F, H, W) logits.
        frames_in: F; net_size: (H, W); normalize: ``imagenet`` or ``unit``.
        step: window step in frames (``frames_in``: non-overlapping; 1: pooled overlapping windows).
        batch_size: windows per forward pass.
    """

    model: torch.nn.Module
    frames_in: int = 3
    net_size: tuple[int, int] = (288, 512)
    normalize: str = "imagenet"
    step: int = 3
    batch_size: int = 1
    postprocess: PostprocessConfig = field(default_factory=PostprocessConfig)
    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    device: str = "cpu"

    def __post_init__(self) -> None:
        # batch-norm folded into the convolutions and channels-last memory: ~1.3x and ~1.2-2x faster for these
        # convnets on a CPU (bench/bench_detectors.py); the runner's model is a folded copy, never trained
        self.model, _ = fold_batchnorm(self.model)
        self.model = self.model.to(self.device, memory_format=torch.channels_last)

    @classmethod
    def from_weights(cls, name: str | None = "wasb", weights: str | Path | None = None, *, trust: bool = False,
                     **kw) -> BallDetectorRunner:
        """Build the detector of ``weights`` (default: the shipped weights of ``name``) with the input the
        file states: architecture, frames in/out, normalisation and input size
        (:func:`~inference.models.checkpoint.detector_input`; WASB-SBDT's ImageNet normalisation for files
        that do not say). ``name`` is used when the file does not name its architecture; a file naming
        another one wins. ``trust`` allows pickled objects (see ``read_checkpoint``)."""
        weights = weights or SHIPPED.get(name or "wasb")
        if weights is None:
            raise FileNotFoundError(f"no shipped weights for {name!r}; pass the path of a checkpoint "
                                    "(weights are never downloaded)")
        model, spec, _ = load_detector(weights, name, trust=trust)
        if name and spec.arch != name:
            log.info("%s holds a %s detector (stored in the file), not %s: using %s", weights, spec.arch, name, spec.arch)
        return cls(model, frames_in=spec.frames_in, net_size=spec.input_size, normalize=spec.normalize, **kw)

    def _tensor(self, frames: list[np.ndarray]) -> torch.Tensor:
        return torch.from_numpy(normalize(np.stack(frames), self.normalize))

    def heatmaps(self, frames) -> tuple[dict[int, list[np.ndarray]], float]:
        """Run the network over letterboxed frames; frame index → its probability maps (one per window)."""
        maps: dict[int, list[np.ndarray]] = {}
        window: deque = deque(maxlen=self.frames_in)
        batch, starts = [], []
        seconds = 0.0

        def flush():
            nonlocal seconds
            t0 = time.perf_counter()
            with torch.inference_mode():
                x = torch.stack(batch).to(self.device).contiguous(memory_format=torch.channels_last)
                probs = torch.sigmoid(self.model(x)).float().cpu().numpy()
            seconds += time.perf_counter() - t0
            for s, p in zip(starts, probs):
                for k in range(p.shape[0]):
                    maps.setdefault(s + self.frames_in - p.shape[0] + k, []).append(p[k])
            batch.clear()
            starts.clear()

        last_start = -self.step
        for i, frame in enumerate(frames):
            window.append(frame)
            start = i - self.frames_in + 1
            if len(window) == self.frames_in and start - last_start >= self.step:
                batch.append(self._tensor(list(window)))
                starts.append(start)
                last_start = start
                if len(batch) == self.batch_size:
                    flush()
        if batch:
            flush()
        return maps, seconds

    def run(self, clip: Clip, progress: bool = False, tolerate_truncation: bool = False,
            active: np.ndarray | None = None) -> DetectionResult:
        """Detect and track the ball over the whole clip (original-frame pixels).

        With ``tolerate_truncation`` a video that stops decoding early yields the frames before the damage
        (``result.truncated`` says why) instead of raising :class:`FormatError`. ``active`` (N,) bool: only
        these frames are searched (court-view shots, :mod:`inference.shots`); each run of active frames is
        windowed and tracked on its own, the other frames have no candidates and no ball.
        """
        from tqdm import tqdm

        from inference.shots import segments

        t0 = time.perf_counter()
        info = clip.info
        lb = Letterbox(info.width, info.height, self.net_size[1], self.net_size[0])
        truncated: list[str] = []
        rects = clip_mask(clip)
        maps: dict[int, list[np.ndarray]] = {}
        seconds_net = 0.0
        with clip.frames(cache_size=0) as src:
            n = len(src)
            runs = [(0, n)] if active is None else segments(np.asarray(active, bool)[:n])
            bar = tqdm(total=sum(b - a for a, b in runs), desc=f"detect {clip.root.name}", unit="frame",
                       disable=not progress)

            def decoded(start: int, stop: int):
                nonlocal n
                at = start
                try:
                    for frame in src.iter(start, stop):
                        at += 1
                        bar.update()
                        yield lb.warp(apply_mask(frame, rects))
                except FormatError as e:  # a truncated or damaged video: keep what was decoded
                    if not tolerate_truncation:
                        raise
                    truncated.append(str(e))
                    n = at

            for start, stop in runs:
                if truncated or start >= n:
                    break
                run_maps, seconds = self.heatmaps(decoded(start, stop))
                maps.update({start + k: v for k, v in run_maps.items()})
                seconds_net += seconds
            bar.close()
        candidates = []
        for i in range(n):
            per_window = [heatmaps_to_candidates(m[None], lb, self.postprocess)[0] for m in maps.get(i, [])]
            candidates.append(pool_candidates(per_window) if per_window else FrameCandidates.empty())
        tracked = TrackResult.empty(n)
        for start, stop in runs:  # a track never crosses a cut
            stop = min(stop, n)
            if start >= stop:
                continue
            part = track_candidates(candidates[start:stop], info.fps, self.tracker, (info.width, info.height))
            ids = np.where(part.track_id >= 0, part.track_id + int(tracked.track_id.max()) + 1, -1)
            tracked.state[start:stop], tracked.xy[start:stop] = part.state, part.xy
            tracked.score[start:stop], tracked.track_id[start:stop] = part.score, ids
        track = tracked.to_ball_track(info.width, info.height)
        return DetectionResult(candidates, tracked, track, seconds_net, time.perf_counter() - t0, n,
                               truncated[0] if truncated else None)
