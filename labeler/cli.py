"""``rally3d label``: the browser labeler for a clip or a dataset."""
from __future__ import annotations

import argparse
import time
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "label",
        help="label a clip (ball, visibility, stationary balls, hit events, court points) in the browser",
        description="Starts a viser server and prints its URL. Every change is saved at once, atomically, to the "
        "clip's ball.csv, inactive_balls.csv, events.csv, court_points.csv and camera.yaml. Open the URL in a "
        "browser; Ctrl/Cmd+K lists the hotkeys. With a dataset folder the GUI lists its clips.",
    )
    p.add_argument("path", type=Path, help="clip folder (with clip.yaml) or dataset (manifest.yaml or clip folders)")
    p.add_argument("--host", default="127.0.0.1", help="interface to listen on (0.0.0.0 for other machines)")
    p.add_argument("--port", type=int, default=8080)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .app import LabelerApp

    app = LabelerApp(args.path, host=args.host, port=args.port)
    print(f"rally3d label: {len(app.clips)} clip(s); open {app.url} in a browser (Ctrl+C to stop)", flush=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        pass
    finally:
        app.stop()
    return 0
