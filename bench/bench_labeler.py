"""Labeler speed: server-side time to serve the next frame, and end-to-end step latency in headless Chromium.

For a 720p and a 1080p synthetic H.264 clip (``rally3d synth``, generated into a temporary folder):

* **serve next frame (cold)**: decode + JPEG-encode of frame i+1 by :class:`labeler.frames.FrameCache` with
  prefetching off, i.e. what a step costs when the frame is not cached yet;
* **serve next frame (prefetched)**: the same request once the prefetch thread has had the frame in hand;
* **browser step**: hotkey ``L`` pressed in headless Debian Chromium (software WebGL) → the GUI line
  "frame i" updated in the page. The frame image travels in the same ``atomic()`` message batch, so this is the
  step latency the annotator sees, up to the texture upload.

Prints median and p95 per row. Usage: ``.venv/bin/python bench/bench_labeler.py [--steps 40] [--frames 90]``.
"""
from __future__ import annotations

import argparse
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--enable-unsafe-swiftshader"]
CANVAS = 'canvas[data-engine^="three.js"]'


def make_clip(root: Path, size: str, frames: int) -> Path:
    out = root / size
    cmd = [str(REPO / ".venv" / "bin" / "rally3d"), "synth", "--sport", "padel", "--clips", "1", "--out", str(out),
           "--seed", "3", "--size", size, "--max-frames", str(frames), "--codec", "h264", "--fps", "30"]
    subprocess.run(cmd, check=True, capture_output=True)
    return next(p.parent for p in sorted(out.glob("*/clip.yaml")))


def stats(seconds: list[float]) -> str:
    ms = np.asarray(seconds) * 1000
    return f"{np.median(ms):8.1f} {np.percentile(ms, 95):8.1f}"


def serve_times(clip_dir: Path, steps: int) -> tuple[list[float], list[float]]:
    from inference.clipio import Clip
    from labeler.frames import FrameCache

    cold, warm = [], []
    cache = FrameCache(Clip(clip_dir), prefetch=False)
    cache.get(0)
    for i in range(1, steps + 1):
        t0 = time.perf_counter()
        cache.get(i)
        cold.append(time.perf_counter() - t0)
    cache.close()
    cache = FrameCache(Clip(clip_dir), prefetch=True)
    cache.get(0)
    for i in range(1, steps + 1):
        cache.prefetch(i - 1, 1)
        time.sleep(0.05)  # the annotator looks at frame i-1 for a moment
        t0 = time.perf_counter()
        cache.get(i)
        warm.append(time.perf_counter() - t0)
    cache.close()
    return cold, warm


def browser_steps(clip_dir: Path, steps: int, chromium: str) -> list[float]:
    from playwright.sync_api import sync_playwright

    from labeler.app import LabelerApp

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    app = LabelerApp(clip_dir, port=port)
    out = []
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, headless=True, args=FLAGS)
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto(f"http://127.0.0.1:{port}/?fixedDpr=1", wait_until="load")
            page.wait_for_selector(CANVAS, timeout=60_000)
            deadline = time.monotonic() + 60
            while not app.views and time.monotonic() < deadline:
                time.sleep(0.05)
            view = next(iter(app.views.values()))
            while view.shown < 0:
                time.sleep(0.05)
            time.sleep(1.5)
            for i in range(1, steps + 1):
                time.sleep(0.15)  # a deliberate step, not auto-repeat
                t0 = time.perf_counter()
                page.keyboard.press("l")
                page.wait_for_function(f"document.body.innerText.includes('frame {i} / ')", timeout=30_000)
                out.append(time.perf_counter() - t0)
            browser.close()
    finally:
        app.stop()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--frames", type=int, default=90, help="frames of each generated clip")
    ap.add_argument("--chromium", default="/usr/bin/chromium")
    ap.add_argument("--no-browser", action="store_true", help="only the server-side rows")
    args = ap.parse_args()
    steps = min(args.steps, args.frames - 2)
    tmp = Path(tempfile.mkdtemp(prefix="bench_labeler_"))
    rows = []
    try:
        for size in ("1280x720", "1920x1080"):
            clip = make_clip(tmp, size, args.frames)
            cold, warm = serve_times(clip, steps)
            rows.append((size, "serve next frame, cold (decode + JPEG encode)", stats(cold)))
            rows.append((size, "serve next frame, prefetched", stats(warm)))
            if not args.no_browser and Path(args.chromium).exists():
                rows.append((size, "browser step: hotkey L → frame shown (headless, SwiftShader)",
                             stats(browser_steps(clip, steps, args.chromium))))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"labeler frame serving and step latency ({steps} steps; ms)")
    print(f"{'clip':<10} {'what':<62} {'median':>8} {'p95':>8}")
    for size, what, figs in rows:
        print(f"{size:<10} {what:<62} {figs}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
