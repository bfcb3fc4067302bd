"""Shared fixtures: headless Debian Chromium driven by Playwright for the browser (E2E) tests.

The browser is Debian's ``chromium`` (installed by ``make test``), never a Playwright download. Pitfalls
handled here: a fixed device pixel ratio (``?fixedDpr=1``, else viser lowers the canvas resolution when
frames are slow), software WebGL (SwiftShader), and the WebGL canvas is the three.js one
(``canvas[data-engine^="three.js"]``, not the first ``canvas`` of the page).
"""
from __future__ import annotations

import os
import shutil
import socket
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--enable-unsafe-swiftshader",
]
WEBGL_CANVAS = 'canvas[data-engine^="three.js"]'
WAIT_CEILING_S = float(os.environ.get("RALLY3D_TEST_WAIT_S", "180"))
"""Ceiling of every wait on a condition in the browser tests: generous, because a loaded 1-core machine is
slow; a passing run never waits this long (the waits end when their condition holds)."""
HIDE_TOASTS_CSS = ".mantine-Notification-root { display: none !important; }"


def chromium_executable() -> str:
    """Path of the system Chromium; a clear failure naming the fix when it is missing."""
    path = os.environ.get("CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
    if not Path(path).exists():
        pytest.fail(f"Chromium not found at {path}: run `make test` (installs Debian chromium) "
                    "or `apt-get install chromium`, or set CHROMIUM=/path/to/chromium")
    return path


def free_port() -> int:
    """A TCP port that is free on 127.0.0.1 right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="session")
def browser() -> Iterator[object]:
    """One headless Chromium for the whole session (Playwright sync API)."""
    from playwright.sync_api import sync_playwright

    exe = chromium_executable()
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=exe, headless=True, args=CHROMIUM_FLAGS)
        yield b
        b.close()


@pytest.fixture
def viser_page(browser) -> Iterator[Callable[..., object]]:
    """Factory ``open(port, width=1400, height=900) -> page`` that loads a viser server and waits for its canvas.

    The page is closed after the test. viser's toasts (e.g. "Software WebGL rendering detected") are hidden
    so they never cover the canvas.
    """
    pages = []

    def open_page(port: int, width: int = 1400, height: int = 900):
        page = browser.new_page(viewport={"width": width, "height": height})
        page.set_default_timeout(WAIT_CEILING_S * 1000)
        pages.append(page)
        page.goto(f"http://127.0.0.1:{port}/?fixedDpr=1", wait_until="load")
        wait_for_canvas(page)
        return page

    yield open_page
    for page in pages:
        page.close()


def wait_for_canvas(page) -> None:
    """Wait (up to the ceiling) for viser's WebGL canvas, then hide toasts; call again after a reload."""
    page.wait_for_selector(WEBGL_CANVAS, timeout=WAIT_CEILING_S * 1000)
    page.add_style_tag(content=HIDE_TOASTS_CSS)


def wait_until(predicate: Callable[[], bool], timeout_s: float = WAIT_CEILING_S, what: str = "condition") -> None:
    """Poll ``predicate`` until it is true; fail the test naming ``what`` after ``timeout_s`` (a ceiling)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.05)
    pytest.fail(f"timed out after {timeout_s:.0f} s waiting for {what}")


@pytest.fixture
def port() -> int:
    """A free local port for a viser server."""
    return free_port()


def compose_cfg(overrides: list[str], out: Path, name: str = "train"):
    """The config ``python {name}.py OVERRIDES`` composes (Hydra, as the script would), writing under ``out``."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.hydra_config import HydraConfig
    from omegaconf import open_dict

    root = Path(__file__).resolve().parents[1]
    GlobalHydra.instance().clear()
    os.environ.setdefault("PROJECT_ROOT", str(root))
    with initialize_config_dir(config_dir=str(root / "conf"), version_base="1.3"):
        cfg = compose(config_name=name, return_hydra_config=True, overrides=overrides)
    with open_dict(cfg):
        cfg.paths.output_dir = str(out)
        cfg.hydra.runtime.output_dir = str(out)
        if not any(o.startswith("paths.log_dir=") for o in overrides):
            cfg.paths.log_dir = str(out)
    HydraConfig().set_config(cfg)
    return cfg
