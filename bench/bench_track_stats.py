"""What our ball detector does to a track, measured on rendered clips with ground truth (``rally3d synth``):
miss rate by the ball's image size and distance and near contacts, gap lengths, false detections and
how far they lie, jitter, whole pixels (:mod:`training.events.stats.track_stats`), and the ``data.degrade``
settings that reproduce them. Writes both to a YAML (default ``conf/data/degrade/detector_measured.yaml``).

    .venv/bin/python bench/bench_track_stats.py CLIP[=DETECTED_CSV] ... [--out FILE] [--tau 10]

A CLIP without ``=DETECTED_CSV`` is run through the shipped detector first (``rally3d detect``'s
library path; the detected track is kept under ``runs/track_stats/``). Prints the figures and the CPU time.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

HEADER = """# Statistics of the project's own ball detector (shipped WASB + tracker, `rally3d detect`) on rendered
# clips with ground truth, and the `data.degrade` settings that reproduce them. Written by
# bench/bench_track_stats.py ({clips}); regenerate with its command line below.
#   {command}
# The clips: rally3d synth --around-point --max-frames 240 (docs/events.md#our-detectors-tracks-measured).
# Use as: python train.py +experiment=hitnet_padel data=events_padel_robust +data/degrade=detector_measured
"""


def detect(clip_dir: Path, out_dir: Path):
    """The shipped detector's track of one clip (cached as ``out_dir/<clip>.csv``)."""
    from inference.clipio import Clip, read_ball_csv, write_ball_csv
    from inference.detection.detect import BallDetectorRunner, shipped_weights

    path = out_dir / f"{clip_dir.parent.name}_{clip_dir.name}.csv"
    if path.is_file():
        return read_ball_csv(path)
    clip = Clip(clip_dir)
    weights, _ = shipped_weights("wasb", clip.info.sport)
    result = BallDetectorRunner.from_weights("wasb", weights).run(clip, progress=True)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_ball_csv(path, result.track)
    return result.track


def main(argv=None) -> dict:
    import sys

    import yaml

    from inference.clipio import Clip, read_ball_csv
    from training.events.stats.track_stats import ClipTruth, degrade_settings, measure_clips

    ap = argparse.ArgumentParser()
    ap.add_argument("clips", nargs="+", help="CLIP_DIR or CLIP_DIR=DETECTED_BALL_CSV")
    ap.add_argument("--out", default="conf/data/degrade/detector_measured.yaml")
    ap.add_argument("--tau", type=float, default=10.0, help="a detection within this many px (at 1280 wide) is a hit")
    ap.add_argument("--cache", default="runs/track_stats")
    args = ap.parse_args(argv)
    t0 = time.process_time()
    pairs, names = [], []
    for spec in args.clips:
        clip_dir, _, csv = spec.partition("=")
        clip = Clip(clip_dir)
        track = read_ball_csv(csv) if csv else detect(Path(clip_dir), Path(args.cache))
        pairs.append((ClipTruth.from_clip(clip), track))
        names.append(f"{Path(clip_dir).parent.name}/{Path(clip_dir).name} ({clip.info.camera_id or 'camera'}, "
                     f"{clip.info.fps:g} fps, {clip.info.width}x{clip.info.height})")
    stats = measure_clips(pairs, tau_px=args.tau)
    stats["clips_measured"] = names
    settings = degrade_settings(stats)
    cpu = time.process_time() - t0
    print(yaml.safe_dump({"measured": stats}, sort_keys=False, allow_unicode=True))
    print(yaml.safe_dump({"degrade": settings}, sort_keys=False))
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        cmd = "python bench/bench_track_stats.py " + " ".join(sys.argv[1:] if argv is None else argv)
        body = yaml.safe_dump({**settings, "measured": stats}, sort_keys=False, allow_unicode=True)
        out.write_text(HEADER.format(clips=f"{len(pairs)} clips", command=cmd) + body)
        print(f"wrote {out}")
    print(f"CPU time {cpu:.1f} s (detection included where it ran)")
    return {"stats": stats, "degrade": settings, "cpu_s": cpu}


if __name__ == "__main__":
    main()
