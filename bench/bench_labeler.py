"""Labeler speed: key → the new frame on screen, read from the canvas, in headless Chromium.

For synthetic H.264 clips (``rally3d synth``, generated into a temporary folder) at 720p, 1080p and 4K:

* **serve next frame (cold / prefetched)**: decode + JPEG-encode of frame i+1 by :class:`labeler.frames.FrameCache`
  with prefetching off, and the same once the prefetch thread has had the frame in hand (server side);
* **key → new frame on screen**, in headless Debian Chromium (software WebGL). Every picture carries its frame
  number as a binary code under the burned-in ``#number`` (:func:`labeler.frames.stamp_frame_number`); the page
  reads the code's cells back from the picture on screen at every animation frame (the page player's frame
  canvas, or viser's WebGL canvas where the server draws the frame), and the latency is the time from
  the key's ``keydown`` to the first animation frame whose code reads the new frame's number. The same
  reading for every variant:

  - ``L`` (one frame) and ``Shift+L`` (ten frames), each after a pause on the frame;
  - **holding L** for 3 s: frames per second shown while playing (distinct codes read per second from the
    first played frame: the key's own step and the 0.35 s before playing starts are left out) and the largest
    lag behind the clip's clock; then **holding J** from the last frame (End), through frames the server has
    not decoded yet (a backward seek in H.264 decodes from the previous key frame);
  - **intermediate renders**: steps with an animation frame, between the key and the new frame, whose
    picture is not the old one (another code read, or the old code over changed pixels: the old picture
    drawn again moved, or a blank);

  for each variant: ``page`` (the page's frame player, :mod:`labeler.player_js`) and ``server`` (a JPEG sent
  per step, the fallback), each idle and with a CPU-bound job beside it (one busy process per core).

Prints median and p95 per row, and the CPU time of this process. Usage:
``.venv/bin/python bench/bench_labeler.py [--steps 30] [--sizes 1280x720,1920x1080,3840x2160]
[--variants page,server] [--loads idle,busy] [--no-browser]``.
"""
from __future__ import annotations

import argparse
import inspect
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
HOLD_S = 3.0


def make_clip(root: Path, size: str, frames: int) -> Path:
    out = root / size
    cmd = [sys.executable, "-m", "inference.cli", "synth", "--sport", "padel", "--clips", "1", "--out", str(out),
           "--seed", "3", "--size", size, "--max-frames", str(frames), "--codec", "h264", "--fps", "30"]
    subprocess.run(cmd, check=True, capture_output=True, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)})
    return next(p.parent for p in sorted(out.glob("*/clip.yaml")))


def stats(values: list[float], scale: float = 1000.0) -> str:
    if not values:
        return f"{'–':>8} {'–':>8}"
    v = np.asarray(values) * scale
    return f"{np.median(v):8.1f} {np.percentile(v, 95):8.1f}"


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


KEY_JS = """
window.__r3dKeys = [];
window.addEventListener("keydown", (ev) => window.__r3dKeys.push(ev.timeStamp), true);
"""
"""Registered before any page script (Playwright init script): the first keydown listener of the window, so
it sees the key even where the page's player stops the event."""

READ_JS = """
(cfg) => {
  const probe = eval(cfg.probe);
  const pts = cfg.code.concat(cfg.grid), n = cfg.code.length;
  const R = window.__r3dRead = {log: [], running: true};
  const tick = () => {
    if (!R.running) return;
    const levels = probe(pts);
    let code = 0;
    for (let k = 0; k < n; k++) code = code * 2 + (levels[k] > 127 ? 1 : 0);
    R.log.push([performance.now(), code, levels.slice(n)]);
    if (R.log.length > 20000) R.log.splice(0, 10000);
    requestAnimationFrame(tick);
  };
  requestAnimationFrame(tick);
}
"""
"""Reads, at every animation frame, the frame code (``cfg.code``: cell centres in CSS px) and a few picture
pixels (``cfg.grid``) of the picture on screen with :data:`labeler.player_js.PROBE_JS` (the page player's
frame canvas where it shows the frame, else viser's WebGL drawing buffer: small reads, so that reading does
not slow the page); ``window.__r3dRead.log`` holds ``[time, code, grid]``."""


class Busy:
    """One busy process per core (a CPU-bound job beside the browser and the server), while in ``with``."""

    def __init__(self, on: bool):
        self.on, self.procs = on, []

    def __enter__(self):
        if self.on:
            self.procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(os.cpu_count() or 2)]
        return self

    def __exit__(self, *exc):
        for p in self.procs:
            p.kill()
            p.wait()


def wait_for(fn, what: str, timeout_s: float = 180.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = fn()
        if value:
            return value
        time.sleep(0.02)
    raise TimeoutError(f"timed out after {timeout_s:.0f} s waiting for {what}")


def make_app(clip_dir: Path, port: int, variant: str):
    from labeler.app import LabelerApp

    params = inspect.signature(LabelerApp).parameters
    if "page_player" in params:
        return LabelerApp(clip_dir, port=port, page_player=(variant == "page"))
    return LabelerApp(clip_dir, port=port, frame_slots=10 if variant == "stack" else 1)  # before the page player


def browser_run(clip_dir: Path, steps: int, chromium: str, variant: str, dwell_s: float) -> dict:
    """One browser session: ``steps`` × L, ``steps // 3`` × Shift+L, L held for :data:`HOLD_S` seconds, then End and
    J held as long."""
    from playwright.sync_api import sync_playwright

    from labeler.frames import code_cell_centres
    from labeler.viewer_common import screen_of_pixel

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    app = make_app(clip_dir, port, variant)
    out = {"one": [], "ten": [], "intermediate": 0, "missed": 0}
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, headless=True, args=FLAGS)
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.add_init_script(KEY_JS)
            page.goto(f"http://127.0.0.1:{port}/?fixedDpr=1", wait_until="load")
            page.wait_for_selector(CANVAS, timeout=60_000)
            view = wait_for(lambda: next(iter(app.views.values()), None), "the labeler view")
            wait_for(lambda: view.shown >= 0 and view.camera_fitted, "the first frame and the fitted camera")
            if variant == "page":
                wait_for(lambda: getattr(view, "paged", False), "the page's player")
            time.sleep(2.0)
            box = page.locator(CANVAS).bounding_box()
            plane, w, h = view.plane, view.plane.width, view.plane.height
            code = screen_of_pixel(code_cell_centres(w), plane, box["width"], box["height"], view.fit_distance)
            grid_px = np.array([[x, y] for x in (0.3, 0.5, 0.7) for y in (0.3, 0.5, 0.7)]) * [w, h]
            grid = screen_of_pixel(grid_px, plane, box["width"], box["height"], view.fit_distance)
            from labeler.player_js import PROBE_JS

            page.evaluate(READ_JS, {"code": code.tolist(), "grid": grid.tolist(), "probe": PROBE_JS})
            fps = float(view.session.fps)
            frame = 0

            def shown_code() -> int:
                return page.evaluate("(window.__r3dRead.log.at(-1) || [0, -1])[1]")

            wait_for(lambda: shown_code() == frame, "frame 0's code on the canvas", 60)

            def step(key: str, expect: int) -> float | None:
                time.sleep(dwell_s)
                t_mark = page.evaluate("performance.now()")
                n_keys = page.evaluate("window.__r3dKeys.length")
                page.keyboard.press(key)
                try:
                    wait_for(lambda: shown_code() == expect, f"frame {expect} on screen", 30)
                except TimeoutError:
                    out["missed"] += 1
                    return None
                key_t = page.evaluate(f"window.__r3dKeys[{n_keys}]")
                # from a second before the mark: the picture on screen when the key went down is known even
                # when no animation frame ran between the mark and the key
                log = page.evaluate(f"window.__r3dRead.log.filter((r) => r[0] >= {t_mark} - 1000)")
                first = next(r for r in log if r[0] >= key_t and r[1] == expect)
                before = [r for r in log if r[0] < key_t]
                if not before:
                    print(f"  no picture read before the key {key} (to {expect}): not judged", file=sys.stderr)
                    before = [(key_t, None, [])]
                ref, old = np.asarray(before[-1][2]), before[-1][1]
                for r in log:  # before the new frame: another picture than the old one (an intermediate render)
                    if old is not None and key_t <= r[0] < first[0] and \
                            (r[1] != old or np.abs(np.asarray(r[2]) - ref).max() > 40):
                        out["intermediate"] += 1
                        print(f"  intermediate picture: key {key} from {old} to {expect}: code {r[1]} read "
                              f"{r[0] - key_t:.0f} ms after the key", file=sys.stderr)
                        break
                return (first[0] - key_t) / 1000

            for _ in range(steps):
                frame += 1
                dt = step("l", frame)
                if dt is not None:
                    out["one"].append(dt)
            for _ in range(max(steps // 3, 3)):
                frame += 10
                dt = step("Shift+L", frame)
                if dt is not None:
                    out["ten"].append(dt)
            def hold(key: str) -> dict:
                """Hold ``key`` for HOLD_S: distinct frames shown per second from the first played frame to the
                key's release (the first change is the key's own step; playing starts 0.35 s later), the
                frames it moved, and its largest lag behind the clip's clock at any animation frame."""
                time.sleep(1.0)
                t0 = page.evaluate("performance.now()")
                page.keyboard.down(key)
                time.sleep(HOLD_S)
                t_up = page.evaluate("performance.now()")
                page.keyboard.up(key)
                time.sleep(0.5)
                log = [(t, n) for t, n, _ in page.evaluate(f"window.__r3dRead.log.filter((r) => r[0] >= {t0})")]
                changes = [(t, n) for (t, n), (_, m) in zip(log[1:], log[:-1]) if n != m][1:]
                changes = [(t, n) for t, n in changes if t <= t_up]
                if len(changes) < 2:
                    return {}
                (ta, na), sign = changes[0], (1 if changes[-1][1] >= changes[0][1] else -1)
                playing = [(t, n) for t, n in log if ta <= t <= t_up]
                return {"fps": (len(changes) - 1) / max((t_up - ta) / 1000, 1e-3),
                        "frames": abs(changes[-1][1] - na),
                        # lag: how far the frame shown is behind a clock started at the first played frame
                        "lag": max(0.0, max((t - ta) / 1000 * fps - sign * (n - na) for t, n in playing) / fps)}

            out["hold"] = hold("l")
            last = view.session.n_frames - 1
            page.keyboard.press("End")  # backwards from frames not decoded yet: the video is sought back
            wait_for(lambda: shown_code() == last, f"the last frame ({last}) on screen", 60)
            out["back"] = hold("j")
            browser.close()
    finally:
        app.stop()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--chromium", default="/usr/bin/chromium")
    ap.add_argument("--no-browser", action="store_true", help="only the server-side rows")
    ap.add_argument("--dwell", type=float, default=0.4, help="seconds on each frame before the next key")
    ap.add_argument("--sizes", default="1280x720,1920x1080,3840x2160")
    ap.add_argument("--variants", default="page,server", help="page, server (and stack: before the page player)")
    ap.add_argument("--loads", default="idle,busy")
    args = ap.parse_args()
    steps = args.steps
    frames = steps + 10 * max(steps // 3, 3) + 2 * int(HOLD_S * 30 * 1.2) + 20  # the J hold starts beyond the L one
    tmp = Path(tempfile.mkdtemp(prefix="bench_labeler_"))
    rows = []

    def row(size: str, what: str, figs: str) -> None:
        rows.append((size, what, figs))
        print(f"  {size:<10} {what:<62} {figs}", file=sys.stderr, flush=True)  # as they come (a crash keeps them)

    t_cpu = time.process_time()
    try:
        for size in args.sizes.split(","):
            clip = make_clip(tmp, size, frames)
            cold, warm = serve_times(clip, min(steps, 30))
            row(size, "serve next frame, cold (decode + JPEG encode)", stats(cold))
            row(size, "serve next frame, prefetched", stats(warm))
            if args.no_browser or not Path(args.chromium).exists():
                continue
            for variant in args.variants.split(","):
                for load in args.loads.split(","):
                    with Busy(load == "busy"):
                        r = browser_run(clip, steps, args.chromium, variant, args.dwell)
                    tag = f"{variant}, {load}"
                    row(size, f"L → new frame on screen ({tag})", stats(r["one"]))
                    row(size, f"Shift+L → frame +10 on screen ({tag})", stats(r["ten"]))
                    for key, what in (("hold", "hold L"), ("back", "hold J from the end")):
                        h = r.get(key) or {}
                        figs = (f"{h['fps']:8.1f} {h['frames']:8d} {h['lag'] * 1000:8.0f}" if h
                                else f"{'–':>8} {'–':>8} {'–':>8}")
                        row(size, f"{what}: frames/s | frames moved | max lag ms ({tag})", figs)
                    row(size, f"intermediate renders | steps missed ({tag})",
                        f"{r['intermediate']:8d} {r['missed']:8d}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"labeler step latency ({steps} steps, {args.dwell:g} s on each frame; ms unless named; "
          f"CPU time of this process {time.process_time() - t_cpu:.1f} s)")
    print(f"{'clip':<10} {'what':<62} {'median':>8} {'p95':>8}")
    for size, what, figs in rows:
        print(f"{size:<10} {what:<62} {figs}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
