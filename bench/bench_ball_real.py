"""Ball detectors on real broadcast video, judged by eye: frames with a ball, and crops of random detections.

    .venv/bin/python bench/bench_ball_real.py [--weights NAME=FILE ...] [--videos V.mp4 ...] [--n 24]

For every video (default: the real tennis broadcast clips of ``$RALLY3D_REAL`` or ``../shared/real``; skips with
one line without them) and every detector (default: the shipped ``wasb_padel`` and ``wasb_tennis``), runs the
detector as ``rally3d detect`` does (the tracker, the crop tracking) and prints the frames with a ball. It then
draws ``--n`` random frames with a detection (seeded, per video and model) and writes their 96×96 crops around
the detection, 2× enlarged with a ring at the detected centre, as one contact sheet per video and model under
``runs/ball_real/`` (not committed): look at the sheet and count the crops whose ring sits on the ball — the
precision of random detections, by eye. The real footage is read in place and never copied into the repository.
Prints Markdown; asserts nothing (a measurement, not a test).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
RUNS = ROOT / "runs" / "ball_real"
CROP = 96
ZOOM = 2


def real_root() -> Path:
    env = os.environ.get("RALLY3D_REAL")
    return Path(env) if env else ROOT.parent / "shared" / "real"


def default_weights() -> dict[str, Path]:
    w = ROOT / "inference" / "weights"
    return {p.stem.replace(".pth", ""): p for p in (w / "wasb_padel.pth.tar", w / "wasb_tennis.pth.tar") if p.is_file()}


def crop_at(frame: np.ndarray, x: float, y: float) -> np.ndarray:
    """A ``CROP``² crop of ``frame (H, W, 3)`` centred on ``(x, y)`` px (padded black), enlarged, ringed."""
    import cv2

    h, w = frame.shape[:2]
    half = CROP // 2
    out = np.zeros((CROP, CROP, 3), np.uint8)
    cx, cy = int(round(x)), int(round(y))
    x0, y0, x1, y1 = max(cx - half, 0), max(cy - half, 0), min(cx + half, w), min(cy + half, h)
    if x1 > x0 and y1 > y0:
        out[y0 - (cy - half):y1 - (cy - half), x0 - (cx - half):x1 - (cx - half)] = frame[y0:y1, x0:x1]
    big = cv2.resize(out, (CROP * ZOOM, CROP * ZOOM), interpolation=cv2.INTER_NEAREST)
    c = (CROP * ZOOM // 2, CROP * ZOOM // 2)
    cv2.circle(big, c, 9 * ZOOM, (0, 255, 255), 1, cv2.LINE_AA)
    return big


def sheet(crops: list[np.ndarray], labels: list[str], cols: int = 6) -> np.ndarray:
    """Crops in a grid, each captioned (its frame number)."""
    import cv2

    s = CROP * ZOOM
    rows = (len(crops) + cols - 1) // cols
    out = np.full((rows * (s + 18), cols * s, 3), 40, np.uint8)
    for k, (c, t) in enumerate(zip(crops, labels)):
        r, q = divmod(k, cols)
        out[r * (s + 18) + 18:r * (s + 18) + 18 + s, q * s:(q + 1) * s] = c
        cv2.putText(out, t, (q * s + 4, r * (s + 18) + 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--weights", nargs="*", default=None, help="NAME=FILE detectors (default: the shipped ones)")
    ap.add_argument("--videos", nargs="*", type=Path, default=None)
    ap.add_argument("--n", type=int, default=24, help="random detections per video and model")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sport", default="tennis")
    args = ap.parse_args(argv)

    import cv2

    from inference.clipio import Clip
    from inference.detection.detect import BallDetectorRunner
    from inference.pipeline import prepare

    videos = args.videos or sorted((real_root() / "tennis_broadcast_clips").glob("*.mp4"))
    if not videos:
        print(f"bench_ball_real: no videos (none given, none under {real_root()}): skipped")
        return 0
    weights = dict(w.split("=", 1) for w in args.weights) if args.weights else default_weights()
    rows = []
    for v in videos:
        dest = RUNS / "clips" / v.stem
        clip = Clip(dest) if (dest / "clip.yaml").is_file() else prepare(v, dest, args.sport).clip
        frames = None
        for name, path in weights.items():
            t0 = time.process_time()
            runner = BallDetectorRunner.from_weights("wasb", path)
            res = runner.run(clip)
            cpu = time.process_time() - t0
            tr = res.track
            seen = tr.visibility > 0
            rng = np.random.default_rng([args.seed, sum(map(ord, v.stem))])
            pick = np.sort(rng.choice(np.flatnonzero(seen), size=min(args.n, int(seen.sum())), replace=False))
            if frames is None:
                with clip.frames() as src:
                    frames = [f for f in src.iter(0, clip.n_frames)]
            w, h = clip.info.width, clip.info.height
            crops = [crop_at(frames[int(tr.frame[k])], tr.xy[k, 0] * w, tr.xy[k, 1] * h) for k in pick]
            out = RUNS / name / f"{v.stem}.png"
            out.parent.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(out), cv2.cvtColor(sheet(crops, [f"#{i + 1} f{int(tr.frame[k])}" for i, k in
                                                             enumerate(pick)]), cv2.COLOR_RGB2BGR))
            rows.append((v.stem, name, int(seen.sum()), clip.n_frames, len(pick), out, cpu))
            print(f"[bench_ball_real] {v.stem} {name}: ball in {int(seen.sum())}/{clip.n_frames} frames, "
                  f"{cpu:.1f} CPU-s, sheet {out.relative_to(ROOT)}", file=sys.stderr)
    print("\n| video | detector | frames with a ball | crops (judge by eye) | CPU s |\n|---|---|---|---|---|")
    for stem, name, n_seen, n, k, out, cpu in rows:
        print(f"| {stem} | {name} | {n_seen} / {n} ({n_seen / max(n, 1):.0%}) | {k}: {out.relative_to(ROOT)} "
              f"| {cpu:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
