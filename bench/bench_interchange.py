"""Benchmark CVAT / Label Studio interchange on a long labelled clip. Prints figures; asserts nothing.

    .venv/bin/python bench/bench_interchange.py [--frames 54000] [--gap 0.05]

A clip of ``--frames`` frames (30 min at 30 fps by default) with visibility 0-3 and a share ``--gap`` of
frames not labelled, plus an event every 2 s, goes to each format and back; the table gives CPU seconds of
export and import (``time.process_time``), the file size and whether the round trip gave the same rows.
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from inference.clipio import BallTrack, HitEvents
from inference.interchange import export_cvat, export_labelstudio, import_cvat, import_labelstudio


def labelled_clip(n: int, gap: float, seed: int = 0) -> tuple[BallTrack, HitEvents]:
    rng = np.random.default_rng(seed)
    keep = rng.random(n) >= gap
    frames = np.arange(n)[keep]
    vis = rng.choice([0, 1, 1, 1, 1, 2, 3], size=len(frames))
    xy = np.where((vis > 0)[:, None], rng.random((len(frames), 2)), np.nan)
    event_frames = np.arange(10, n, 60)
    return BallTrack(frames, vis, xy), HitEvents(event_frames, ["ground"] * len(event_frames))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=54000)
    ap.add_argument("--gap", type=float, default=0.05, help="share of frames not labelled")
    args = ap.parse_args()
    track, events = labelled_clip(args.frames, args.gap)
    print(f"{args.frames} frames, {len(track)} ball rows, {len(events)} events\n")
    print("| format | export (s CPU) | import (s CPU) | file (MB) | same rows and events |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as d:
        for name, suffix, export, read, extra in (
            ("CVAT for video 1.1", ".xml", export_cvat, import_cvat, {}),
            ("Label Studio JSON", ".json", export_labelstudio, import_labelstudio, {"fps": 30.0}),
        ):
            path = Path(d) / f"labels{suffix}"
            t0 = time.process_time()
            export(path, track, events, width=1920, height=1080, n_frames=args.frames, **extra)
            t1 = time.process_time()
            back = read(path)
            t2 = time.process_time()
            same = (np.array_equal(back.ball.frame, track.frame)
                    and np.array_equal(back.ball.visibility, track.visibility)
                    and np.allclose(back.ball.xy, track.xy, atol=1e-6, equal_nan=True)
                    and back.events == events)
            print(f"| {name} | {t1 - t0:.2f} | {t2 - t1:.2f} | {path.stat().st_size / 1e6:.1f} | {same} |")


if __name__ == "__main__":
    main()
