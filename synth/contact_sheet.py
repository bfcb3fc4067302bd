"""A contact sheet: a PNG/JPEG grid of frames from clip folders, each with a zoomed inset of the ball.

    .venv/bin/python -m synth.contact_sheet OUT.jpg CLIP [CLIP ...] [--per-clip 4]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from inference.clipio import Clip

VIS_NAMES = {0: "out", 1: "visible", 2: "hard", 3: "occluded"}


def tile(frame: np.ndarray, xy_px: np.ndarray | None, label: str, width: int = 480, crop: int = 40,
         zoom: int = 4) -> np.ndarray:
    """(h, width, 3) RGB: the frame scaled to ``width`` with a ``zoom``× inset around the ball."""
    h, w = frame.shape[:2]
    out = cv2.resize(frame, (width, int(round(h * width / w))), interpolation=cv2.INTER_AREA)
    if xy_px is not None and np.isfinite(xy_px).all():
        x, y = np.round(xy_px).astype(int)
        pad = np.pad(frame, ((crop, crop), (crop, crop), (0, 0)), mode="edge")
        patch = pad[y:y + 2 * crop, x:x + 2 * crop]
        inset = cv2.resize(patch, None, fx=zoom * width / w, fy=zoom * width / w, interpolation=cv2.INTER_NEAREST)
        ih, iw = inset.shape[:2]
        out[4:4 + ih, width - iw - 4:width - 4] = inset
        cv2.rectangle(out, (width - iw - 5, 3), (width - 4, 4 + ih), (255, 255, 255), 1)
        s = width / w
        cv2.circle(out, (int(x * s), int(y * s)), 7, (255, 60, 60), 1, cv2.LINE_AA)
    cv2.putText(out, label, (6, out.shape[0] - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def contact_sheet(clips: list[Path], per_clip: int = 4, width: int = 480) -> np.ndarray:
    """(H, W, 3) RGB grid: one row per clip, ``per_clip`` frames spread over the frames with a ball."""
    rows = []
    for root in clips:
        clip = Clip(root)
        ball = clip.read_ball()
        shown = ball.frame[ball.visibility > 0]
        picks = shown[np.linspace(0, len(shown) - 1, per_clip).round().astype(int)] if len(shown) else np.arange(per_clip)
        with clip.frames() as frames:
            tiles = []
            for f in picks:
                f = int(f)
                vis = int(ball.visibility[ball.frame == f][0]) if f in ball.frame else 0
                xy = ball.to_pixels(clip.info.width, clip.info.height)[ball.frame == f]
                tiles.append(tile(frames[f], xy[0] if len(xy) and vis else None,
                                  f"{Path(root).name} #{f} {VIS_NAMES[vis]}", width))
        h = min(t.shape[0] for t in tiles)
        rows.append(np.hstack([t[:h] for t in tiles]))
    wmax = max(r.shape[1] for r in rows)
    return np.vstack([np.pad(r, ((0, 0), (0, wmax - r.shape[1]), (0, 0))) for r in rows])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("clips", type=Path, nargs="+")
    ap.add_argument("--per-clip", type=int, default=4)
    ap.add_argument("--width", type=int, default=480)
    a = ap.parse_args(argv)
    sheet = contact_sheet(a.clips, a.per_clip, a.width)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(a.out), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 88])
    print(f"wrote {a.out} ({sheet.shape[1]}x{sheet.shape[0]})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
