"""Ball detection on a whole clip: stream frames → letterbox → batched N-frame windows through the
network at full resolution (or, with crop-tracking, a small window around the expected ball:
:mod:`.crop`) → heatmap candidates in original pixels → tracker → ball.csv rows. The network runs in
eager PyTorch or ONNX Runtime (:mod:`.engine`).

The video is streamed (never held in memory); windows are non-overlapping (``step = frames_out``) as in
WASB-SBDT, or overlapping with candidates pooled per frame (``step = 1``).

Example:
    >>> det = BallDetectorRunner.from_weights("wasb", SHIPPED)           # the shipped padel weights
    >>> result = det.run(Clip("clip"))                                   # DetectionResult
    >>> clip.write_ball(result.track)
"""
from __future__ import annotations

import copy
import logging
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from inference.clipio import BallTrack, Clip, FormatError
from inference.video.masks import apply_mask, clip_mask
from inference.models.checkpoint import load_detector
from inference.models.fuse import fold_batchnorm

from .crop import CropConfig, crop_candidates, place_crop
from .engine import make_engine
from .geometry import Letterbox
from .postprocess import FrameCandidates, PostprocessConfig, heatmaps_to_candidates, pool_candidates
from .preprocess import normalize
from .tracker import BallTracker, TrackerConfig, TrackResult, track_candidates

log = logging.getLogger(__name__)
WEIGHTS_DIR = Path(__file__).resolve().parent.parent / "weights"
STILL_PX = 6.0  # px: a candidate this close to one of the window searched before has not moved (lost-ball backoff)
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
    """Per-frame candidates, the tracked ball and timing of one clip.

    ``windows``: how many detector windows ran on the full frame (``full``), on a crop (``crop``), and
    crops whose answer was not trusted and were re-run on the full frame (``crop_rerun``), and windows not
    searched while the ball was lost (``lost_skipped``, see :mod:`.crop`).
    """

    candidates: list[FrameCandidates]
    tracked: TrackResult
    track: BallTrack
    seconds_network: float
    seconds_total: float
    n_frames: int
    truncated: str | None = None  # why decoding stopped before the video's reported end, if it did
    windows: dict[str, int] = field(default_factory=dict)

    @property
    def fps(self) -> float:
        return self.n_frames / self.seconds_total if self.seconds_total else float("nan")


def window_starts(n: int, frames_in: int, step: int) -> list[tuple[int, int]]:
    """``(start, first_new)`` of the detector windows over ``n`` frames, as the runner places them: every
    ``step`` frames (``first_new`` 0), plus one window ending at the last frame when those leave the last
    frames out, whose frames before ``first_new`` were searched by an earlier window."""
    starts = [(s, 0) for s in range(0, n - frames_in + 1, step)]
    if starts and starts[-1][0] < n - frames_in:
        starts.append((n - frames_in, starts[-1][0] + frames_in))
    return starts


@dataclass
class BallDetectorRunner:
    """A detector network with its pre/post-processing.

    Args:
        model: maps (B, 3·F, H, W) to (B, F, H, W) logits.
        frames_in: F; net_size: (H, W); normalize: ``imagenet`` or ``unit``.
        step: window step in frames (``frames_in``: non-overlapping; 1: pooled overlapping windows).
        batch_size: windows per forward pass (full-frame windows; crop-tracking runs one at a time).
        backend: ``torch`` (eager PyTorch: the library's default, what training's evaluation compares against),
            ``onnx`` (ONNX Runtime, CPU; exported and cached on first use, :mod:`.engine`), ``onnx-int8`` (the
            weights' int8 companion, :mod:`.quantize`: faster, loses weak detections) or ``auto`` (ONNX Runtime's
            float network on the CPU where installed, else eager PyTorch: the default of ``rally3d infer`` and
            ``rally3d detect``).
        crop: :class:`~.crop.CropConfig` for crop-tracking, ``None`` for the full frame everywhere.
        fold_bn: fold batch norms into the convolutions (an inference copy of ``model``).
        int8: the weights' int8 companion (:func:`~.quantize.int8_companion`; :meth:`from_weights` finds it for
            ``onnx-int8``), run by ``onnx-int8`` on the CPU.
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
    backend: str = "torch"
    crop: CropConfig | None = None
    fold_bn: bool = True
    onnx_dir: Path | None = None
    int8: Path | None = None

    def __post_init__(self) -> None:
        # batch-norm folded into the convolutions and channels-last memory: ~1.3x and ~1.2-2x faster for these
        # convnets on a CPU (bench/bench_detectors.py); the runner's model is a folded copy, never trained
        if self.fold_bn:
            self.model, _ = fold_batchnorm(self.model)
        else:
            self.model = copy.deepcopy(self.model).eval()
        self.engine = make_engine(self.model, self.backend, self.frames_in, self.device, self.onnx_dir, self.int8)

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
        if "int8" not in kw and kw.get("backend", "torch") == "onnx-int8":
            from .quantize import int8_companion

            kw["int8"] = int8_companion(weights)
        if name and spec.arch != name:
            log.info("%s holds a %s detector (stored in the file), not %s: using %s", weights, spec.arch, name, spec.arch)
        return cls(model, frames_in=spec.frames_in, net_size=spec.input_size, normalize=spec.normalize, **kw)

    def _forward(self, windows: list[list[np.ndarray]]) -> tuple[np.ndarray, float]:
        """Probabilities ``(B, F_out, h, w)`` of ``B`` windows of ``F`` frames ``(h, w, 3)``, and the seconds."""
        t0 = time.perf_counter()
        x = np.stack([normalize(np.stack(w), self.normalize) for w in windows])
        probs = self.engine(x)
        return probs, time.perf_counter() - t0

    def _windows(self, frames):
        """``(start, frames, first_new)`` of each detector window over the frame stream: windows every ``step``
        frames (``first_new`` 0), and when the stream's last frames fall after the last of them, one more window
        ending at the last frame whose outputs before ``first_new`` repeat frames already searched (so every
        frame is searched once): :func:`window_starts` on a stream of unknown length."""
        window: deque = deque(maxlen=self.frames_in)
        last_start = -self.step
        i = -1
        for i, frame in enumerate(frames):
            window.append(frame)
            start = i - self.frames_in + 1
            if len(window) == self.frames_in and start - last_start >= self.step:
                last_start = start
                yield start, list(window), 0
        start = i - self.frames_in + 1
        if len(window) == self.frames_in and start > last_start:
            yield start, list(window), last_start + self.frames_in

    def heatmaps(self, frames) -> tuple[dict[int, list[np.ndarray]], float]:
        """Run the network over letterboxed frames (full grid); frame index → its probability maps (one per
        window), and the network seconds."""
        maps: dict[int, list[np.ndarray]] = {}
        seconds = 0.0
        batch: list[tuple[int, list[np.ndarray]]] = []

        def flush():
            nonlocal seconds
            probs, dt = self._forward([w for _, w, _ in batch])
            seconds += dt
            for (s, _, first_new), p in zip(batch, probs):
                for k in range(p.shape[0]):
                    f = s + self.frames_in - p.shape[0] + k
                    if f >= first_new:
                        maps.setdefault(f, []).append(p[k])
            batch.clear()

        for item in self._windows(frames):
            batch.append(item)
            if len(batch) == self.batch_size:
                flush()
        if batch:
            flush()
        return maps, seconds

    def candidates(self, frames, lb: Letterbox, fps: float) -> tuple[list[FrameCandidates], float, dict[str, int]]:
        """Per-frame candidates (original pixels) of letterboxed ``frames``, the network seconds and the window
        counts (see :class:`DetectionResult`). Frames' candidates are made as soon as their last window has
        run, so no heatmap outlives its window; with ``crop`` an online tracker places the crops."""
        done: list[FrameCandidates] = []
        pending: dict[int, list[FrameCandidates]] = {}
        counts = {"full": 0, "crop": 0, "crop_rerun": 0}
        seconds = 0.0
        online = None if self.crop is None else BallTracker(fps, self.tracker, (lb.src_w, lb.src_h))
        full_every = None if self.crop is None else self.tracker.frames(self.crop.full_every_s, fps)
        last_full = -(10 ** 9)

        def finish(upto: int) -> None:   # frames < upto have all their windows: pool, feed the online tracker
            while len(done) < upto:
                parts = pending.pop(len(done), [])
                fc = pool_candidates(parts) if parts else FrameCandidates.empty()
                done.append(fc)
                if online is not None:
                    online.update(fc.xy, fc.score)

        def add(starts: list[tuple[int, int]], probs: np.ndarray, origin=None) -> bool:
            found = True
            for (s, first_new), p in zip(starts, probs):
                first = s + self.frames_in - p.shape[0]
                skip = max(first_new - first, 0)  # outputs of frames an earlier window searched
                if origin is None:
                    cands = heatmaps_to_candidates(p, lb, self.postprocess)
                else:
                    raw = heatmaps_to_candidates(p, None, self.postprocess)
                    cands, found = crop_candidates(raw, origin, p.shape[2] / self.crop.size[1], lb, self.crop)
                    if not found:
                        return False
                for k, c in enumerate(cands):
                    if k >= skip:
                        pending.setdefault(first + k, []).append(c)
            return found

        batch: list[tuple[int, list[np.ndarray], int]] = []
        skipped: list[tuple[int, list[np.ndarray], int]] = []  # windows not searched while the ball is lost
        misses = 0  # full-frame windows in a row that found no ball while the tracker had none

        still = np.empty((0, 2))  # the candidates of the last window searched: a blob that stays is no ball

        def full(start: int, window: list[np.ndarray], first_new: int) -> bool:
            """Run one window on the full frame; whether it holds a new candidate (one scoring ``min_score`` or
            more away from every candidate of the window searched before: a ball lying still is not one)."""
            nonlocal seconds, last_full, still
            probs, dt = self._forward([window])
            seconds += dt
            counts["full"] += 1
            last_full = start
            add([(start, first_new)], probs)
            cs = [c for f in range(start, start + self.frames_in) for c in pending.get(f, [])]
            xy = np.concatenate([np.asarray(c.xy, float).reshape(-1, 2)[np.asarray(c.score) >= self.crop.min_score]
                                 for c in cs]) if cs else np.empty((0, 2))
            new = xy if not len(still) else xy[np.min(np.linalg.norm(xy[:, None] - still[None], axis=2), axis=1)
                                               > STILL_PX] if len(xy) else xy
            still = xy
            return bool(len(new))

        for start, window, first_new in self._windows(frames):
            if online is None:   # full frames, batched
                batch.append((start, window, first_new))
                if len(batch) == self.batch_size:
                    probs, dt = self._forward([w for _, w, _ in batch])
                    seconds += dt
                    add([(s, n) for s, _, n in batch], probs)
                    counts["full"] += len(batch)
                    finish(batch[-1][0] + self.step)
                    batch.clear()
                continue
            finish(skipped[0][0] if skipped else start)
            origin = None
            if start - last_full < full_every:
                origin = self._place_crop(online, lb, start)
            if origin is not None:
                (y0, x0), (h, w) = origin, self.crop.size
                probs, dt = self._forward([[f[y0:y0 + h, x0:x0 + w] for f in window]])
                seconds += dt
                counts["crop"] += 1
                if add([(start, first_new)], probs, origin):
                    finish(start + self.step)
                    continue
                counts["crop_rerun"] += 1
            lost = online.expected(np.arange(1, 2)) is None
            if lost and misses >= self.crop.lost_after and len(skipped) < self.crop.lost_skip:
                skipped.append((start, window, first_new))   # decided by the next searched window
                counts["lost_skipped"] = counts.get("lost_skipped", 0) + 1
                continue
            found = full(start, window, first_new)
            if found and skipped:   # the ball is back: search the windows skipped before it (same result)
                for args in skipped:
                    full(*args)
                    counts["lost_skipped"] -= 1
            skipped.clear()
            misses = 0 if found or not lost else misses + 1
            finish(start + self.step)
        if batch:
            probs, dt = self._forward([w for _, w, _ in batch])
            seconds += dt
            add([(s, n) for s, _, n in batch], probs)
            counts["full"] += len(batch)
        if not counts.get("lost_skipped", 1):
            del counts["lost_skipped"]   # every skipped window was searched after all
        ends = [max(pending, default=-1) + 1] + [s + self.frames_in for s, _, _ in skipped]
        finish(max(ends))   # windows still skipped at the end: the ball never came back, their frames are empty
        return done, seconds, counts

    def _place_crop(self, online: BallTracker, lb: Letterbox, start: int) -> tuple[int, int] | None:
        """The crop origin for the window of frames ``start..start+F-1``, or None (full frame)."""
        last = online.frame - 1
        expected = online.expected(np.arange(start, start + self.frames_in) - last)
        if expected is None or expected[1] < self.crop.min_score:
            return None
        return place_crop(lb.forward(expected[0]), self.net_size, self.crop)

    def run(self, clip: Clip, progress: bool = False, tolerate_truncation: bool = False,
            active: np.ndarray | None = None) -> DetectionResult:
        """Detect and track the ball over the whole clip (original-frame pixels).

        With ``tolerate_truncation`` a video that stops decoding early yields the frames before the damage
        (``result.truncated`` says why) instead of raising :class:`FormatError`. ``active`` (N,) bool: only
        these frames are searched (court-view scenes, :mod:`inference.video.scenes`); each run of active frames is
        windowed and tracked on its own, the other frames have no candidates and no ball.
        """
        from tqdm import tqdm

        from inference.video.scenes import segments

        t0 = time.perf_counter()
        info = clip.info
        lb = Letterbox(info.width, info.height, self.net_size[1], self.net_size[0])
        truncated: list[str] = []
        rects = clip_mask(clip)
        seconds_net = 0.0
        windows = {"full": 0, "crop": 0, "crop_rerun": 0}
        with clip.frames(cache_size=0) as src:
            n = len(src)
            candidates = [FrameCandidates.empty() for _ in range(n)]
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
                run_cands, seconds, run_windows = self.candidates(decoded(start, stop), lb, info.fps)
                k = min(len(run_cands), stop - start)
                candidates[start:start + k] = run_cands[:k]
                seconds_net += seconds
                windows = {k: windows.get(k, 0) + v for k, v in run_windows.items()}
            bar.close()
        candidates = candidates[:n]
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
                               truncated[0] if truncated else None, windows)
