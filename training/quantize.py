"""Make the int8 companion of a ball detector's weights: ``NAME.int8.onnx`` beside ``NAME.pth.tar``.

    python -m training.quantize [--weights inference/weights/wasb_padel.pth.tar] --data CLIPS [--clips 3]
        [--every 4] [--windows 80] [--out FILE]

The float network runs over the clips of ``--data`` (a clip folder, a dataset or a folder of clips) exactly as
``rally3d detect`` runs it (ONNX Runtime, crop-tracking: full frames and crops); every ``--every``-th window it
is given is kept, up to ``--windows``, as calibration input for static quantisation
(:func:`inference.detection.quantize.quantize_detector`). ``rally3d infer --detector-backend onnx-int8`` and
``rally3d detect --backend onnx-int8`` then run it, as long as the checkpoint's bytes do not change.
Calibrate on clips that look like what the detector will see (rendered clips are fine; a few hundred frames
are enough); never on the clips you evaluate on. Recipe and figures: docs/detectors.md#int8.
"""
from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import numpy as np

from inference.clipio import Clip
from inference.clipio.manifest import dataset_clips
from inference.detection.crop import CropConfig
from inference.detection.detect import SHIPPED, BallDetectorRunner
from inference.detection.quantize import companion_path, file_sha256, quantize_detector

log = logging.getLogger("rally3d.quantize")


class WindowRecorder:
    """An engine wrapper that keeps every ``every``-th input it runs (at most ``limit``), then runs it."""

    def __init__(self, engine, every: int, limit: int) -> None:
        if every < 1 or limit < 1:
            raise ValueError(f"every and limit must be >= 1, got {every}, {limit}")
        self.engine, self.every, self.limit = engine, every, limit
        self.name = getattr(engine, "name", "recorder")
        self.calls = 0
        self.kept: list[np.ndarray] = []

    def __call__(self, x: np.ndarray) -> np.ndarray:
        if self.calls % self.every == 0 and len(self.kept) < self.limit:
            self.kept.extend(np.ascontiguousarray(w[None], np.float32) for w in x)
        self.calls += 1
        return self.engine(x)


def calibration_windows(runner: BallDetectorRunner, clips: list[Path], every: int, limit: int) -> list[np.ndarray]:
    """Detector inputs ``(1, 3·F, H, W)`` float32 kept while ``runner`` detects the ball in ``clips``."""
    recorder = WindowRecorder(runner.engine, every, limit)
    runner.engine = recorder
    try:
        for k, path in enumerate(clips, 1):
            t0 = time.process_time()
            result = runner.run(Clip(path))
            log.info("calibration clip %d/%d %s: %d frames, %d windows kept so far (%.1f CPU-s)", k, len(clips),
                     path, result.n_frames, len(recorder.kept), time.process_time() - t0)
            if len(recorder.kept) >= limit:
                break
    finally:
        runner.engine = recorder.engine
    return recorder.kept[:limit]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m training.quantize", description=__doc__.split("\n\n")[0])
    ap.add_argument("--weights", type=Path, default=SHIPPED["wasb"], help="detector checkpoint (default: the "
                    "shipped padel WASB)")
    ap.add_argument("--model", default=None, help="architecture when the file does not name it (wasb, ...)")
    ap.add_argument("--data", type=Path, required=True, help="calibration clips: a clip folder, a dataset or a folder "
                    "of clips (not the clips you evaluate on)")
    ap.add_argument("--clips", type=int, default=3, help="at most this many clips of --data (default 3)")
    ap.add_argument("--every", type=int, default=4, help="keep every N-th detector window (default 4)")
    ap.add_argument("--windows", type=int, default=80, help="calibration windows at most (default 80)")
    ap.add_argument("--out", type=Path, default=None, help="output file (default: NAME.int8.onnx beside the weights)")
    ap.add_argument("--trust-checkpoint", action="store_true", help="allow a checkpoint holding pickled objects")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    if not args.weights.is_file():
        print(f"error: {args.weights}: no such checkpoint; pass --weights FILE", file=sys.stderr)
        return 2
    clips = dataset_clips(args.data)[: args.clips]
    if not clips:
        print(f"error: {args.data}: no clip folders there (a folder with clip.yaml, a dataset with manifest.yaml, "
              "or a folder of clips); render some with `rally3d synth`", file=sys.stderr)
        return 2
    runner = BallDetectorRunner.from_weights(args.model, args.weights, trust=args.trust_checkpoint, backend="onnx",
                                             crop=CropConfig(), int8=None)
    windows = calibration_windows(runner, clips, args.every, args.windows)
    out = args.out or companion_path(args.weights)
    t0 = time.process_time()
    quantize_detector(runner.engine.path, windows, out, source_sha256=file_sha256(args.weights))
    shapes = sorted({tuple(w.shape[2:]) for w in windows})
    print(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB) from {len(windows)} windows of {len(clips)} clips "
          f"(sizes {', '.join(f'{h}x{w}' for h, w in shapes)}), {time.process_time() - t0:.1f} CPU-s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
