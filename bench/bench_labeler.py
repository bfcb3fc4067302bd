"""Labeler speed: server-side time to serve the next frame, and end-to-end step latency in headless Chromium.

For a 720p and a 1080p synthetic H.264 clip (``rally3d synth``, generated into a temporary folder):

* **serve next frame (cold)**: decode + JPEG-encode of frame i+1 by :class:`labeler.frames.FrameCache` with
  prefetching off, i.e. what a step costs when the frame is not cached yet;
* **serve next frame (prefetched)**: the same request once the prefetch thread has had the frame in hand;
* **key L → status line / new image on screen**: hotkey ``L`` in headless Debian Chromium (software WebGL),
  timed in the page from the ``keydown`` event to the status line naming the new frame, and to the first
  animation frame whose pixels (the frame-number box burned into each picture, read back from the WebGL canvas)
  differ from the old picture's: the image on screen, not the text. Once with one image plane (the JPEG is
  sent and decoded after the key) and once with the frame stack (:mod:`labeler.framestack`, the next frames
  already in the browser), in the same run.

Prints median and p95 per row. Usage:
``.venv/bin/python bench/bench_labeler.py [--steps 40] [--frames 90] [--dwell 0.3] [--sizes 1280x720]``.
"""
from __future__ import annotations

import argparse
import os
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
    cmd = [sys.executable, "-m", "inference.cli", "synth", "--sport", "padel", "--clips", "1", "--out", str(out),
           "--seed", "3", "--size", size, "--max-frames", str(frames), "--codec", "h264", "--fps", "30"]
    subprocess.run(cmd, check=True, capture_output=True, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)})
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


ON_SCREEN_JS = """
(region) => {
  const src = document.querySelector('canvas[data-engine^="three.js"]');
  const probe = document.createElement("canvas");
  probe.width = Math.max(1, Math.round(region.w)); probe.height = Math.max(1, Math.round(region.h));
  const ctx = probe.getContext("2d", {willReadFrequently: true});
  const read = () => {
    ctx.drawImage(src, region.x, region.y, region.w, region.h, 0, 0, probe.width, probe.height);
    return ctx.getImageData(0, 0, probe.width, probe.height).data;
  };
  // a new picture: at least 12 pixels of the number box changed by more than 60 levels (the renderer's
  // fade-in after each redraw moves every pixel by a level or two, and is not a new picture)
  const changed = (a, b) => {
    let n = 0;
    for (let i = 0; i < a.length; i += 4) {
      if (Math.abs(a[i] - b[i]) + Math.abs(a[i + 1] - b[i + 1]) + Math.abs(a[i + 2] - b[i + 2]) > 60) n += 1;
    }
    return n >= 12;
  };
  const r = window.__r3d = {armed: false, key: null, image: null, status: null, before: null, expect: ""};
  r.arm = (expect) => { r.key = r.image = r.status = r.before = null; r.expect = expect; r.armed = true; };
  document.addEventListener("keydown", (ev) => { if (r.armed && r.key === null) r.key = ev.timeStamp; }, true);
  const tick = () => {
    if (r.armed && r.key === null && r.before === null) r.before = read().slice();  // the old picture
    if (r.armed && r.key !== null && r.before !== null) {
      const now = performance.now();
      if (r.status === null && document.body.textContent.includes(r.expect)) r.status = now;
      if (r.image === null && changed(read(), r.before)) r.image = now;
      if (r.status !== null && r.image !== null) r.armed = false;
    }
    requestAnimationFrame(tick);
  };
  requestAnimationFrame(tick);
}
"""
"""Measures in the page: from the key's ``keydown`` to (a) the status line naming the new frame and (b) the first
animation frame whose pixels in the frame-number box of the picture differ from the old picture's, i.e. the new
image on screen (the three.js canvas read back every animation frame)."""


def wait_for(fn, what: str, timeout_s: float = 180.0):
    """``fn()``'s first truthy value, polled; a clear error naming ``what`` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = fn()
        if value:
            return value
        time.sleep(0.05)
    raise TimeoutError(f"timed out after {timeout_s:.0f} s waiting for {what}")


def browser_steps(clip_dir: Path, steps: int, chromium: str, slots: int, dwell_s: float) -> tuple[list, list]:
    """Step ``steps`` times with the hotkey L in headless Chromium; (status-line, image-on-screen) seconds.

    ``slots``: image planes per tab (1 = the JPEG is sent and decoded after the key, as before the frame stack).
    """
    from playwright.sync_api import sync_playwright

    from labeler.app import LabelerApp
    from labeler.viewer_common import screen_of_pixel

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    app = LabelerApp(clip_dir, port=port, frame_slots=slots)
    status, image = [], []
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, headless=True, args=FLAGS)
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto(f"http://127.0.0.1:{port}/?fixedDpr=1", wait_until="load")
            page.wait_for_selector(CANVAS, timeout=60_000)
            view = wait_for(lambda: next(iter(app.views.values()), None), "the labeler view")
            wait_for(lambda: view.shown >= 0 and view.camera_fitted, "the first frame and the fitted camera")
            time.sleep(1.5)
            box = page.locator(CANVAS).bounding_box()
            w = view.plane.width
            corner = np.array([[0.0, 0.0], [0.1 * w, 0.05 * w]])  # the frame-number box at the top-left
            (x0, y0), (x1, y1) = screen_of_pixel(corner, view.plane, box["width"], box["height"], view.fit_distance)
            page.evaluate(ON_SCREEN_JS, {"x": x0, "y": y0, "w": x1 - x0, "h": y1 - y0})
            for i in range(1, steps + 1):
                time.sleep(dwell_s)  # the annotator looks at the frame, then steps (not auto-repeat)
                page.evaluate(f"window.__r3d.arm('frame {i} / ')")
                page.wait_for_function("window.__r3d.before !== null", timeout=30_000)
                page.keyboard.press("l")
                page.wait_for_function("!window.__r3d.armed", timeout=30_000)
                key, st, im = page.evaluate("[window.__r3d.key, window.__r3d.status, window.__r3d.image]")
                status.append((st - key) / 1000)
                image.append((im - key) / 1000)
                print(f"\r  {slots} plane(s): step {i}/{steps}", end="", file=sys.stderr, flush=True)
            print(file=sys.stderr)
            browser.close()
    finally:
        app.stop()
    return status, image


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--frames", type=int, default=90, help="frames of each generated clip")
    ap.add_argument("--chromium", default="/usr/bin/chromium")
    ap.add_argument("--no-browser", action="store_true", help="only the server-side rows")
    ap.add_argument("--dwell", type=float, default=0.3, help="seconds on each frame before the next key")
    ap.add_argument("--sizes", default="1280x720,1920x1080")
    args = ap.parse_args()
    steps = min(args.steps, args.frames - 2)
    tmp = Path(tempfile.mkdtemp(prefix="bench_labeler_"))
    rows = []
    try:
        for size in args.sizes.split(","):
            clip = make_clip(tmp, size, args.frames)
            cold, warm = serve_times(clip, steps)
            rows.append((size, "serve next frame, cold (decode + JPEG encode)", stats(cold)))
            rows.append((size, "serve next frame, prefetched", stats(warm)))
            if not args.no_browser and Path(args.chromium).exists():
                from labeler.app import FRAME_SLOTS

                for slots, name in ((1, "one plane, JPEG sent on the key"), (FRAME_SLOTS, "frame stack")):
                    st, im = browser_steps(clip, steps, args.chromium, slots, args.dwell)
                    rows.append((size, f"key L → status line, {name}", stats(st)))
                    rows.append((size, f"key L → new image on screen, {name}", stats(im)))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"labeler frame serving and step latency ({steps} steps, {args.dwell:g} s on each frame; ms; "
          f"CPU time of this process {time.process_time():.1f} s)")
    print(f"{'clip':<10} {'what':<62} {'median':>8} {'p95':>8}")
    for size, what, figs in rows:
        print(f"{size:<10} {what:<62} {figs}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
