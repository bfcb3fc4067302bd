"""Export of a review: the replay for viser's static client (no Python needed) and the per-shot CSV.

- ``replay.viser``: viser's scene serializer recording (court, contacts, the ball moving along its path with
  its trail and the players, one step per frame at real time). Play it with viser's static client:
  ``index.html?playbackPath=replay.viser`` served over HTTP (see the README's "3D review").
- ``replay.html``: the same recording embedded in viser's self-contained client page, with a side panel: at
  its top the clip's 3D status (``#rally3d-banner``: red ``3D NOT plausible`` / ``NOT judged`` when it
  applies, and the rally's coverage), the clip's video (copied next to it as ``video.<ext>``) and its frame
  number, the 3D view's frame number, and the shot table (click a shot: the video jumps to its hit). The 3D
  recording labels each step with its frame.
- ``shots.csv``: one row per shot (:data:`labeler.review.shots.CSV_COLUMNS`).

Example:
    >>> export_review(ReviewData.load("runs/demo/padel_sample"), "runs/demo/review")
"""
from __future__ import annotations

import base64
import contextlib
import html as html_lib
import io
import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
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
from .panels import SHOT_COLUMNS, shot_cells
from .shots import RallyAnalysis, write_shots_csv


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
    add_contacts(scene, data.analysis, data.court.ball.radius, project=data.camera.project)


FRAME_LABEL = "/replay/frame"
"""The 3D recording's label that names the frame of each step."""


def frame_label_position(data: ReviewData) -> tuple[float, float, float]:
    """Where the frame label floats: above the court's far end, out of the ball's way (m)."""
    corners = np.concatenate([p.corners_3d() for p in data.court.planes])
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    return (float(lo[0]), float(hi[1]), float(hi[2]) + 0.5)


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
        label = server.scene.add_label(FRAME_LABEL, "", position=frame_label_position(data), font_screen_scale=1.2)
        frames = range(data.first_frame, data.last_frame + 1, max(1, int(stride)))
        for f in tqdm(frames, desc="record replay", unit="frame", disable=not progress, leave=False):
            update_ball(nodes, data.ball_at(f), data.trail(f, TRAIL_FRAMES))
            players.update(data.players_at(f))
            label.text = f"frame {f}"
            ser.insert_sleep(stride / data.fps)
        blob = ser.serialize()
    finally:
        with contextlib.redirect_stdout(io.StringIO()):
            server.stop()
    return blob, embed_html(blob), len(frames)


def embed_html(blob: bytes, side: str = "") -> str:
    """viser's client page with the recording embedded (the client reads ``window.__VISER_EMBED_DATA__``),
    and ``side`` (HTML: :func:`side_panel_html`) at the start of its body."""
    import viser

    page = (Path(viser.__file__).parent / "client" / "build" / "index.html").read_text()
    inject = (f'<script>window.__VISER_EMBED_DATA__="{base64.b64encode(blob).decode("ascii")}";'
              "window.__VISER_EMBED_CONFIG__={darkMode:false};</script>")
    head_end = page.index("</head>")
    page = page[:head_end] + inject + page[head_end:]
    if side:
        body = page.index(">", page.index("<body")) + 1
        page = page[:body] + side + page[body:]
    return page


SIDE_CSS = """
#rally3d-side{position:fixed;left:0;top:0;bottom:0;width:38vw;overflow:auto;box-sizing:border-box;
 padding:10px;background:#fff;border-right:1px solid #ccc;font:13px system-ui,sans-serif;z-index:10}
#root{position:fixed!important;left:38vw!important;top:0;right:0;bottom:0;width:auto!important}
#rally3d-side video{width:100%;background:#000}
#rally3d-side table{border-collapse:collapse;width:100%;margin-top:8px}
#rally3d-side td,#rally3d-side th{border:1px solid #ddd;padding:2px 4px;text-align:left}
#rally3d-side tr.now td{background:#fff3b0}
#rally3d-side tbody tr{cursor:pointer}
.rally3d-frame{font:600 15px monospace;margin:4px 0}
/* sticky: top -10px (the panel's padding) puts it at the very top */
#rally3d-banner{position:sticky;top:-10px;margin:-10px -10px 8px;padding:8px 10px;font-size:14px;z-index:1}
#rally3d-banner.bad{background:#ffd7d2;border-bottom:3px solid #c62828;color:#5a0000}
#rally3d-banner.ok{background:#e8f5e9;border-bottom:1px solid #8bc48f;color:#1b4d20}
"""

SIDE_JS = """
(function () {
  const cfg = JSON.parse(document.getElementById("rally3d-config").textContent);
  const video = document.getElementById("rally3d-video");
  const out = document.getElementById("rally3d-video-frame");
  const rows = Array.from(document.querySelectorAll("#rally3d-shots tbody tr"));
  const frameOf = (t) => Math.floor(t * cfg.fps + 1e-6);
  const show = () => {
    const f = video ? frameOf(video.currentTime) : null;
    if (out) out.textContent = f === null ? "" : "video: frame " + f;
    rows.forEach((r, i) => r.classList.toggle("now", f !== null && f >= cfg.hits[i] &&
      (i + 1 >= cfg.hits.length || f < cfg.hits[i + 1])));
  };
  rows.forEach((r, i) => r.addEventListener("click", () => {
    if (video) { video.currentTime = (cfg.hits[i] + 0.5) / cfg.fps; show(); }
  }));
  if (video) {
    const tick = () => { show(); video.requestVideoFrameCallback ? video.requestVideoFrameCallback(tick)
                                                                : requestAnimationFrame(tick); };
    video.addEventListener("seeked", show);
    tick();
  }
  show();
})();
"""


def banner_div(analysis: RallyAnalysis) -> str:
    """The replay page's 3D status banner (:meth:`RallyAnalysis.status_lines`, escaped; "" without one)."""
    lines = analysis.status_lines()
    if not lines:
        return ""
    p = analysis.plausibility
    kind = "ok" if p is not None and p.judged and p.plausible else "bad"
    rest = "".join(f"<br>{html_lib.escape(t)}" for t in lines[1:])
    return (f'<div id="rally3d-banner" class="{kind}" role="{"alert" if kind == "bad" else "status"}">'
            f"<b>{html_lib.escape(lines[0])}</b>{rest}</div>")


def side_panel_html(title: str, analysis: RallyAnalysis, fps: float, video_name: str | None) -> str:
    """The replay page's side panel: the 3D status banner (:func:`banner_div`), the video with its frame
    number, and the shot table (every file-derived string HTML-escaped; the script is ours and reads its
    figures from a JSON block)."""
    esc = html_lib.escape
    head = "".join(f"<th>{esc(c)}</th>" for c in SHOT_COLUMNS)
    body = "".join("<tr>" + "".join(f"<td>{esc(c)}</td>" for c in shot_cells(s)) + "</tr>" for s in analysis.shots)
    cfg = json.dumps({"fps": float(fps), "hits": [int(s.hit.frame) for s in analysis.shots]})
    video = (f'<video id="rally3d-video" src="{esc(video_name)}" controls muted preload="auto"></video>'
             '<div id="rally3d-video-frame" class="rally3d-frame"></div>' if video_name
             else "<p>(no video: the clip's video could not be read)</p>")
    return (f"<style>{SIDE_CSS}</style><aside id=\"rally3d-side\">{banner_div(analysis)}"
            f"<h3>{esc(title)}</h3>{video}"
            "<p>The 3D view (right) names its frame above the court; click a shot to put the video on its hit."
            f"</p><table id=\"rally3d-shots\"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
            f'<script type="application/json" id="rally3d-config">{esc(cfg, quote=False)}</script>'
            f"<script>{SIDE_JS}</script></aside>")


def copy_video(data: ReviewData, out: Path) -> str | None:
    """Copy the clip's video next to the replay (``video.<ext>``); its name, or None without a readable video."""
    src = data.clip.video_path
    if not data.video_ok or not src.is_file():
        return None
    name = f"video{src.suffix.lower()}"
    tmp = out / f".{name}.tmp"
    shutil.copyfile(src, tmp)
    tmp.replace(out / name)
    return name


def export_review(data: ReviewData, out_dir: str | Path, *, stride: int = 1, progress: bool = True) -> ExportResult:
    """Write ``replay.viser``, ``replay.html`` (with the video copied beside it) and ``shots.csv`` into
    ``out_dir`` (atomically)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    blob, _, n = record_replay(data, stride=stride, progress=progress)
    replay = atomic_write_bytes(out / "replay.viser", blob)
    side = side_panel_html(data.clip.root.name, data.analysis, data.fps, copy_video(data, out))
    page = atomic_write_text(out / "replay.html", embed_html(blob, side))
    csv_path = write_shots_csv(out / "shots.csv", data.analysis)
    return ExportResult(replay, page, csv_path, n)
