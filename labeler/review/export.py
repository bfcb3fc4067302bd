"""Export of a review: the replay for viser's static client (no Python needed) and the per-shot CSV.

- ``replay.viser``: viser's scene serializer recording (court, contacts, the ball moving along its path with
  its trail and the players, one step per frame at real time). Play it with viser's static client:
  ``index.html?playbackPath=replay.viser`` served over HTTP (see the README's "3D review").
- ``replay.html``: the same recording embedded in viser's self-contained client page; open it in a browser.
- ``shots.csv``: one row per shot (:data:`labeler.review.shots.CSV_COLUMNS`).

Example:
    >>> export_review(ReviewData.load("runs/demo/padel_sample"), "runs/demo/review")
"""
from __future__ import annotations

import base64
import contextlib
import io
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from inference.clipio.atomic import atomic_write_bytes, atomic_write_text

from .data import ReviewData
from .scene import (
    TRAIL_FRAMES,
    PlayerNodes,
    add_ball,
    add_contacts,
    add_court,
    add_full_path,
    camera_presets,
    update_ball,
)
from .shots import write_shots_csv


@dataclass(frozen=True)
class ExportResult:
    replay: Path
    html: Path
    shots_csv: Path
    n_steps: int


def build_static_scene(scene, data: ReviewData) -> None:
    """What every viewer shares: court, whole path, contact markers."""
    scene.set_up_direction("+z")
    add_court(scene, data.court)
    add_full_path(scene, data.traj.xyz)
    add_contacts(scene, data.analysis, data.court.ball.radius)


def record_replay(data: ReviewData, *, stride: int = 1, progress: bool = True) -> tuple[bytes, str, int]:
    """Build the scene on a private viser server and record the rally frame by frame.

    Returns:
        (the ``.viser`` bytes, the self-contained HTML page, the number of recorded steps).
    """
    import viser

    with contextlib.redirect_stdout(io.StringIO()):  # viser prints its URL box even when not verbose
        server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        ser = server.get_scene_serializer()
        build_static_scene(server.scene, data)
        pose = camera_presets(data.camera, data.court)["broadcast"]
        cam = server.initial_camera
        cam.position, cam.look_at, cam.up = pose.position, pose.look_at, pose.up
        cam.fov = pose.fov
        nodes = add_ball(server.scene, data.court.ball.radius)
        players = PlayerNodes(server.scene)
        frames = range(data.first_frame, data.last_frame + 1, max(1, int(stride)))
        for f in tqdm(frames, desc="record replay", unit="frame", disable=not progress, leave=False):
            update_ball(nodes, data.ball_at(f), data.trail(f, TRAIL_FRAMES))
            players.update(data.players_at(f))
            ser.insert_sleep(stride / data.fps)
        blob = ser.serialize()
    finally:
        with contextlib.redirect_stdout(io.StringIO()):
            server.stop()
    return blob, embed_html(blob), len(frames)


def embed_html(blob: bytes) -> str:
    """viser's client page with the recording embedded (the client reads ``window.__VISER_EMBED_DATA__``)."""
    import viser

    page = (Path(viser.__file__).parent / "client" / "build" / "index.html").read_text()
    inject = (f'<script>window.__VISER_EMBED_DATA__="{base64.b64encode(blob).decode("ascii")}";'
              "window.__VISER_EMBED_CONFIG__={darkMode:false};</script>")
    head_end = page.index("</head>")
    return page[:head_end] + inject + page[head_end:]


def export_review(data: ReviewData, out_dir: str | Path, *, stride: int = 1, progress: bool = True) -> ExportResult:
    """Write ``replay.viser``, ``replay.html`` and ``shots.csv`` into ``out_dir`` (atomically)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    blob, html, n = record_replay(data, stride=stride, progress=progress)
    replay = atomic_write_bytes(out / "replay.viser", blob)
    page = atomic_write_text(out / "replay.html", html)
    csv_path = write_shots_csv(out / "shots.csv", data.analysis)
    return ExportResult(replay, page, csv_path, n)
