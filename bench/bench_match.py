"""A whole match through ``rally3d infer``: rallies found, the index, peak memory, time (issue 47, item 2).

Builds a simulated match from the embedded padel sample (1280×720, 30 fps): broadcast-style points (the
court view with a pause before the serve, then a slowed replay and a close-up cut in) for the first part, and
club-camera points (one view, never cut: a pause of players walking back between points) for the last part.
Then, in a fresh interpreter each (peak memory of the child process):

1. ``rally3d infer MATCH --match --only scenes``: the scan, the split, one clip folder per rally, the index;
2. ``rally3d infer MATCH --match --rallies 1-K`` with the sample's court points: the whole pipeline on the
   first K rallies (the rest is projected from their CPU time per second of video).

It prints the rallies found against the points the match was built from (a found rally matches a point when
it covers the point's rally frames, within 0.5 s at each end), the index's first rows and the figures.

    .venv/bin/python bench/bench_match.py [--minutes 30] [--full 2] [--out runs/bench_match]
"""
from __future__ import annotations

import argparse
import csv
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "datasets" / "sample" / "padel_sample"


def sample_frames() -> list[np.ndarray]:
    from inference.clipio import Clip

    with Clip(SAMPLE).frames(cache_size=0) as src:
        return [f.copy() for f in src.iter()]


def held(frame: np.ndarray, n: int, rng) -> list[np.ndarray]:
    """A court view with nobody playing: the frame held, with sensor noise (σ 2 grey levels per pixel)."""
    out = []
    for _ in range(n):
        noise = rng.normal(0, 2, frame.shape[:2])[:, :, None]
        out.append(np.clip(frame.astype(np.float32) + noise, 0, 255).astype(np.uint8))
    return out


def replay(frames: list[np.ndarray], n: int) -> list[np.ndarray]:
    """A slowed, zoomed replay of the rally (another camera: nothing like the main view)."""
    import cv2

    h, w = frames[0].shape[:2]
    out = []
    for i in range(n):
        f = frames[min(len(frames) - 1, i // 2)]
        crop = f[h // 4:h // 4 + h // 2, w // 3:w // 3 + w // 2]
        out.append(cv2.resize(crop, (w, h), interpolation=cv2.INTER_LINEAR)[:, :, ::-1].copy())
    return out


def closeup(n: int, shape, rng) -> list[np.ndarray]:
    base = np.empty(shape, np.uint8)
    base[:] = rng.integers(30, 220, 3)
    return [np.clip(base.astype(np.int16) + rng.integers(-6, 7), 0, 255).astype(np.uint8) for _ in range(n)]


def build_match(path: Path, minutes: float, fps: float, frames: list[np.ndarray], club_share: float = 0.25):
    """Write the match video; returns the points ``[(style, rally_first, rally_stop), ...]`` (frames)."""
    from inference.clipio import write_video

    rng = np.random.default_rng(0)
    total = int(minutes * 60 * fps)
    points: list[tuple[str, int, int]] = []
    state = {"n": 0}

    def gen():
        while state["n"] < total:
            style = "club" if state["n"] >= (1 - club_share) * total else "broadcast"
            pause = held(frames[0], int(rng.uniform(3, 6) * fps), rng)
            for f in pause:
                yield f
            state["n"] += len(pause)
            points.append((style, state["n"], state["n"] + len(frames)))
            for f in frames:
                yield f
            state["n"] += len(frames)
            if style == "broadcast":
                cut = replay(frames, int(4 * fps)) + closeup(int(rng.uniform(1.5, 3) * fps), frames[0].shape, rng)
            else:
                cut = held(frames[-1], int(rng.uniform(4, 8) * fps), rng)  # players walk back: one view
            for f in cut:
                yield f
            state["n"] += len(cut)

    n = write_video(path, gen(), fps, fourcc="h264", crf=23)
    return points, n


#: runs ``rally3d ARGS`` and writes the process's own peak memory (VmHWM: its address space after exec, not the
#: parent's pages a fork's ru_maxrss counts) to the file named by $RALLY3D_BENCH_HWM
_CHILD = """
import os, sys
from inference.cli import main
try:
    code = main(sys.argv[1:])
finally:
    hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM")]
    open(os.environ["RALLY3D_BENCH_HWM"], "w").write(hwm[0].split()[1] if hwm else "nan")
sys.exit(code)
"""


def run_child(args: list[str], log: Path) -> tuple[int, float, float, float]:
    """Run ``rally3d *args`` in a fresh interpreter; (exit code, wall s, CPU s, peak RSS MiB) of it."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    hwm = log.with_suffix(".hwm")
    t0 = time.perf_counter()
    with open(log, "w") as f:
        code = subprocess.call([sys.executable, "-c", _CHILD, *args], stdout=f, stderr=subprocess.STDOUT, cwd=ROOT,
                               env={**os.environ, "PYTHONPATH": str(ROOT), "RALLY3D_BENCH_HWM": str(hwm)})
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return code, wall, cpu, float(hwm.read_text()) / 1024 if hwm.is_file() else float("nan")


def matches(points, rows, fps: float, tol_s: float = 0.5) -> int:
    """Points whose rally frames a found rally covers (within ``tol_s`` at each end)."""
    tol = tol_s * fps
    found = [(int(r["first_frame"]), int(r["stop_frame"])) for r in rows]
    return sum(any(a - tol <= s and e <= b + tol for a, b in found) for _, s, e in points)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--full", type=int, default=2, help="rallies run through the whole pipeline (0: none)")
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "bench_match")
    ap.add_argument("--reuse", action="store_true", help="keep the match video of an earlier run (the result is "
                    "always made afresh)")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    video, result = args.out / "match.mp4", args.out / "result"
    frames = sample_frames()
    fps = 30.0
    points_file = args.out / "points.csv"
    t0 = time.perf_counter()
    import shutil

    shutil.rmtree(result, ignore_errors=True)
    if not (args.reuse and video.is_file() and points_file.is_file()):
        points, n = build_match(video, args.minutes, fps, frames)
        with open(points_file, "w", newline="") as f:
            csv.writer(f).writerows(points)
        print(f"built {video}: {n} frames ({n / fps / 60:.1f} min), {len(points)} points, "
              f"{time.perf_counter() - t0:.0f} s", flush=True)
    with open(points_file, newline="") as f:
        points = [(s, int(a), int(b)) for s, a, b in csv.reader(f)]
    exe = ["infer", str(video), "--match", "--court", "padel", "--out", str(result)]
    code, wall, cpu, rss = run_child([*exe, "--only", "scenes"], args.out / "split.log")
    with open(result / "index.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    n_frames = sum(int(r["stop_frame"]) - int(r["first_frame"]) for r in rows)
    video_s = max(b for _, _, b in points) / fps
    print(f"\n1. split (--only scenes): exit {code}, wall {wall:.0f} s, CPU {cpu:.0f} s, peak RSS {rss:.0f} MiB")
    for style in ("broadcast", "club"):
        pts = [p for p in points if p[0] == style]
        print(f"   {style}: {matches(pts, rows, fps)} of {len(pts)} points covered by a rally")
    statuses = ", ".join(f"{s} {sum(r['status'] == s for r in rows)}" for s in sorted({r["status"] for r in rows}))
    print(f"   {len(rows)} rallies found for {len(points)} points; {n_frames / fps / 60:.1f} min of rallies in "
          f"{video_s / 60:.1f} min of video (statuses: {statuses})")
    print("   index.csv, first rows:")
    with open(result / "index.csv") as f:
        for line in f.read().splitlines()[:5]:
            print("     " + line)
    if args.full > 0:
        k = min(args.full, len(rows))
        code, wall, cpu, rss = run_child([*exe, "--rallies", f"1-{k}", "--court-points",
                                          str(SAMPLE / "court_points.csv"), "--pose", "none"],
                                         args.out / "full.log")
        with open(result / "index.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        done = rows[:k]
        secs = sum(float(r["end_s"]) - float(r["start_s"]) for r in done)
        print(f"\n2. whole pipeline (--pose none) on rallies 1–{k} ({secs:.1f} s of video): exit {code}, wall "
              f"{wall:.0f} s, CPU {cpu:.0f} s ({cpu / secs:.1f} CPU-s per second of video), peak RSS {rss:.0f} MiB")
        for r in done:
            print(f"   rally {r['rally']}: {r['status']}, {r['events']} events, serve {r['serve'] or '-'}, point "
                  f"{r['point_start_s']}–{r['point_end_s']} s {r['note']}")
        print(f"   projected for all {len(rows)} rallies ({n_frames / fps / 60:.1f} min): "
              f"{cpu / secs * n_frames / fps / 3600:.1f} CPU-hours at this rate")
    print(f"\nlogs: {args.out / 'split.log'}, {args.out / 'full.log'}, {result / 'match.log'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
