"""README screenshots of each labeler mode, taken in headless Debian Chromium (Playwright, no browser download).

Usage::

    python -m labeler.screenshots docs/img            # writes docs/img/labeler_{ball,stationary,events,court,assist,dataset}.png
    python -m labeler.screenshots docs/img --detector # the assist shot runs the shipped detector (≈1 min on CPU)

Works on a copy of ``datasets/sample/padel_sample`` in a temporary folder (never writes into ``datasets/``).
"""
from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "datasets" / "sample" / "padel_sample"
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--enable-unsafe-swiftshader"]
CANVAS = 'canvas[data-engine^="three.js"]'


def _wait(pred, timeout: float = 30.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return
        time.sleep(0.05)
    raise TimeoutError("timed out waiting for the labeler")


def _dismiss(page, wait_s: float = 1.0) -> None:
    for _ in range(max(1, int(wait_s / 0.1))):
        buttons = page.locator(".mantine-Notification-root button")
        if buttons.count():
            for i in range(buttons.count()):
                try:
                    buttons.nth(i).click(timeout=500)
                except Exception:
                    pass
            return
        time.sleep(0.1)


def _settle(view, frame: int) -> None:
    view.goto(frame)
    view.request(overlay=True, gui=True)
    _wait(lambda: view.shown == frame)
    time.sleep(1.5)


def take(out_dir: Path, *, detector: bool = False, chromium: str = "/usr/bin/chromium") -> list[Path]:
    from playwright.sync_api import sync_playwright

    from inference.clipio import Clip

    from .app import LabelerApp

    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
        ds = Path(tmp) / "dataset"
        shutil.copytree(SAMPLE, ds / "padel_sample")
        shutil.copytree(SAMPLE, ds / "padel_unlabelled")
        for name in ("ball.csv", "events.csv", "inactive_balls.csv", "court_points.csv"):
            (ds / "padel_unlabelled" / name).unlink(missing_ok=True)
        clip = Clip(ds / "padel_sample")
        ball = clip.read_ball()
        keep = (ball.frame % 6 == 0) | (ball.frame < 40) | (ball.frame > 70)  # gaps to interpolate
        clip.write_ball(type(ball)(ball.frame[keep], ball.visibility[keep], ball.xy[keep]))
        app = LabelerApp(ds, port=_free_port())
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=FLAGS)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 860})
            page.goto(f"http://127.0.0.1:{app.server.get_port()}/?fixedDpr=1", wait_until="load")
            page.wait_for_selector(CANVAS, timeout=30_000)
            _dismiss(page)
            _wait(lambda: app.views)
            view = next(iter(app.views.values()))
            names = [c.root.name for c in app.clips]
            _wait(lambda: view.shown >= 0)

            def shot(name: str, tab: str | None = None) -> None:
                if tab:
                    page.get_by_role("tab", name=tab).click()
                time.sleep(0.8)
                _dismiss(page, wait_s=0.3)  # the software-WebGL toast can come back after a long run
                path = out_dir / f"labeler_{name}.png"
                page.screenshot(path=str(path))
                written.append(path)

            shot("dataset")
            app.open(view.client, app.clips[names.index("padel_sample")])
            _wait(lambda: app.views[view.client.client_id] is not view)
            view = app.views[view.client.client_id]
            _wait(lambda: view.shown >= 0)
            page.get_by_text("Dataset").first.click()  # fold the overview away
            view.session.interpolate("physics")
            _settle(view, 52)
            shot("ball", "Ball")
            s = view.session
            if not s.inactive:
                s.add_inactive(0, (0.83, 0.93))
            view.set_mode("stationary")
            _settle(view, 60)
            shot("stationary", "Still")
            view.set_mode("ball")
            _settle(view, int(sorted(s.events)[2]) if len(s.events) > 2 else 30)
            shot("events", "Events")
            view.set_mode("court")
            _settle(view, 0)
            shot("court", "Court")
            view.set_mode("ball")
            if detector:
                view.run_detector(None)
                _wait(lambda: view.session.ball_proposal_source == "ball detector", timeout=600)
            _settle(view, 52)
            shot("assist", "Assist")
        finally:
            browser.close()
            app.stop()
    return written


def _free_port() -> int:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path, nargs="?", default=REPO / "docs" / "img")
    ap.add_argument("--detector", action="store_true", help="run the shipped detector for the assist shot")
    ap.add_argument("--chromium", default="/usr/bin/chromium")
    args = ap.parse_args(argv)
    for path in take(args.out, detector=args.detector, chromium=args.chromium):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["take"]
