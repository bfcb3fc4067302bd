"""End-to-end frames/s and CPU per stage of ``rally3d infer`` on a clip (by default the embedded 1280×720 padel sample).

Runs the whole pipeline (camera, detect, smooth, events, players with MoveNet, reconstruct) into a fresh
output folder, prints the per-stage table with the slowest stage named, and the scores against the sample's
ground truth. With ``--device cuda`` it measures the GPU (where one is lent).

    .venv/bin/python bench/bench_pipeline.py [--device cpu] [--pose movenet|none] [--batch-size 1] [--detector-backend auto|torch|onnx|onnx-int8] [--pose-every N]
    .venv/bin/python bench/bench_pipeline.py --input VIDEO.mp4 --court tennis --court-points auto   # any video
"""
from __future__ import annotations

import argparse
import os
import platform
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "datasets" / "sample" / "padel_sample"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--pose", default="movenet")
    ap.add_argument("--batch-size", type=int, default=1)
    ap.add_argument("--pose-every", type=int, default=0, help="pose every N-th frame (0: auto, as rally3d infer)")
    ap.add_argument("--detector-backend", default="auto", choices=["auto", "torch", "onnx", "onnx-int8"])
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "bench_pipeline")
    ap.add_argument("--input", type=Path, default=SAMPLE, help="a video or clip folder (default: the padel sample)")
    ap.add_argument("--court", default=None, help="with a video: its court (padel, tennis)")
    ap.add_argument("--court-points", default=None, help="with a video: court_points.csv, or auto (the court fit)")
    args = ap.parse_args()

    from inference.clipio import Clip
    from inference.pipeline import PipelineConfig, prepare, run_pipeline, score

    if args.out.exists():
        shutil.rmtree(args.out)
    points = None if args.court_points in (None, "auto") else Path(args.court_points)
    prepared = prepare(args.input, args.out, args.court, court_points=points)
    cfg = PipelineConfig(pose=args.pose, device=args.device, batch_size=args.batch_size, progress=False,
                         detector_backend=args.detector_backend, pose_every=args.pose_every,
                         auto_court=args.court_points == "auto")
    report = run_pipeline(prepared.clip, cfg, log=lambda *_: None)
    import torch

    print(f"rally3d infer on {args.input.name}: {prepared.clip.info.width}×{prepared.clip.info.height}, "
          f"{prepared.clip.n_frames} frames; device {args.device}, {os.cpu_count()} CPU cores, "
          f"torch {torch.__version__}, {platform.processor() or platform.machine()}")
    print(report.table())
    total = sum(s.seconds for s in report.stages)
    cpu = sum(s.cpu_seconds for s in report.stages)
    video_s = prepared.clip.n_frames / prepared.clip.info.fps
    print(f"end to end: {prepared.clip.n_frames / total:.2f} frames/s; {cpu / video_s:.2f} CPU-s per second of video, "
          f"{total / video_s:.2f} wall s per second of video")
    if prepared.reference is not None or args.input == SAMPLE:
        for line in score(prepared.clip, prepared.reference or Clip(SAMPLE)).lines():
            print("  " + line)
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
