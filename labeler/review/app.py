"""The 3D review app: a viser server showing one reconstructed clip.

Shared by every viewer (``server.scene``): the court, the whole path, the contact markers. Per viewer
(``client.scene`` / ``client.gui``, a :class:`Session`): the moving ball and its trail, the players, the
timeline with its own play/pause and speed, the camera presets, the video frame with the reprojection drawn
over it, and the shot panel, under a banner with the clip's 3D status (red when it is not plausible). One
background thread advances every playing session.

Example (non-blocking, e.g. in tests or ``make demo``)::

    app = ReviewApp("runs/demo/padel_sample", port=8080)
    print(app.start())      # the URL
    ...
    app.stop()
"""
from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

import numpy as np

from .data import ReviewData
from .export import build_static_scene, record_replay
from .overlay import draw_overlay, placeholder_frame
from .panels import (
    current_shot_markdown,
    populate_cameras,
    populate_export,
    populate_banner,
    populate_info,
    populate_playback,
    speed_of,
)
from .playback import Playback
from .scene import TRAIL_FRAMES, PlayerNodes, add_ball, apply_pose, camera_presets, update_ball
from .shots import shots_csv_text

VIDEO_WIDTH = 960
"""Width (px) of the video frame sent to the page (the panel beside the 3D view scales it to its width)."""


class FrameImages:
    """Video frames with the overlay, decoded on demand (``inference.clipio`` frames, small cache); thread-safe."""

    def __init__(self, data: ReviewData, width: int = VIDEO_WIDTH, cache_size: int = 16):
        self.data = data
        self.width = width
        self._lock = threading.Lock()
        self._src = None
        self._cache: dict[int, np.ndarray] = {}
        self._order: list[int] = []
        self._cache_size = cache_size
        if data.video_ok:
            self._src = data.clip.frames(cache_size=4)

    def get(self, frame: int) -> np.ndarray:
        with self._lock:
            img = self._cache.get(frame)
            if img is not None:
                return img
            d = self.data
            base = None
            if self._src is not None and 0 <= frame < len(self._src):
                try:
                    base = self._src[frame]
                except Exception:  # a damaged frame: show the placeholder, keep reviewing
                    base = None
            if base is None:
                base = placeholder_frame(d.camera, self.width)
            obs = d.uv[frame] if frame < len(d.uv) else None
            img = draw_overlay(base, d.camera, d.court, ball_xyz=d.ball_at(frame),
                               trail_xyz=d.trail(frame, TRAIL_FRAMES), observed_px=obs, out_width=self.width,
                               text=f"frame {frame}")
            self._cache[frame] = img
            self._order.append(frame)
            if len(self._order) > self._cache_size:
                self._cache.pop(self._order.pop(0), None)
            return img

    def close(self) -> None:
        if self._src is not None:
            self._src.close()


class Session:
    """One viewer: its playback state, scene nodes and panels."""

    def __init__(self, app: ReviewApp, client):
        self.app = app
        self.client = client
        d = app.data
        self.lock = threading.Lock()
        self.playback = Playback(d.first_frame, d.last_frame, d.fps)
        self.nodes = add_ball(client.scene, d.court.ball.radius)
        self.players = PlayerNodes(client.scene)
        gui = client.gui
        self.presets = camera_presets(d.camera, d.court)
        self.banner = populate_banner(gui, d.analysis.plausibility)  # first: the 3D status before any figure
        self.panel = populate_playback(gui, d.first_frame, d.last_frame, d.event_marks())
        self.views = populate_cameras(gui, list(self.presets))
        self.info = populate_info(gui, app.frames.get(self.playback.frame), d.analysis, d.summary())
        self.dl_replay, self.dl_csv = populate_export(gui)
        self._syncing = False
        self.shown = -1  # the frame whose ball and video were last sent together
        self._wire()
        apply_pose(client, self.presets["broadcast"])
        self.render()

    def _wire(self) -> None:
        p = self.panel

        @p.frame.on_update
        def _(_ev) -> None:
            if self._syncing:
                return
            with self.lock:
                self.playback.seek(int(p.frame.value))
            self.render(from_slider=True)

        @p.play.on_update
        def _(_ev) -> None:
            with self.lock:
                self.playback.playing = bool(p.play.value)

        @p.speed.on_update
        def _(_ev) -> None:
            with self.lock:
                self.playback.set_speed(speed_of(p.speed.value))

        @p.prev.on_click
        def _(ev) -> None:
            with self.lock:
                self.playback.step(-1 if "−1" in str(ev.target.value) else 1)
            self._set_play(False)
            self.render()

        @self.views.on_click
        def _(ev) -> None:
            apply_pose(self.client, self.presets[str(ev.target.value)])

        @self.dl_replay.on_click
        def _(_ev) -> None:
            blob, _html, _ = record_replay(self.app.data, progress=False)
            self.client.send_file_download(f"{self.app.data.clip.root.name}.viser", blob)

        @self.dl_csv.on_click
        def _(_ev) -> None:
            self.client.send_file_download(f"{self.app.data.clip.root.name}_shots.csv",
                                           shots_csv_text(self.app.data.analysis).encode())

        cmd = self.client.gui.add_command("play / pause", hotkey="P")

        @cmd.on_trigger
        def _(_ev) -> None:
            self._set_play(not self.playback.playing)

    def _set_play(self, playing: bool) -> None:
        self.playback.playing = playing
        self._syncing = True
        try:
            self.panel.play.value = playing
        finally:
            self._syncing = False

    def tick(self, dt: float) -> None:
        """Advance when playing and redraw if the frame changed."""
        with self.lock:
            was_playing = self.playback.playing
            before = self.playback.frame
            frame = self.playback.advance(dt)
            ended = was_playing and not self.playback.playing
        if frame != before:
            self.render()
        if ended:  # stopped at the end (no loop): only then uncheck the box, never a click still on its way
            self._set_play(False)

    def render(self, from_slider: bool = False) -> None:
        """Show the current frame: ball, trail, players, video overlay, shot text, slider position."""
        d = self.app.data
        f = self.playback.frame
        image = self.app.frames.get(f)  # decoded before the batch: 3D and video leave together
        with self.client.atomic():
            update_ball(self.nodes, d.ball_at(f), d.trail(f, TRAIL_FRAMES))
            self.players.update(d.players_at(f))
            self.info.video.image = image
            self.info.frame.content = f"**frame {f}** (3D view and video)"
            self.shown = f
        self.info.current.content = current_shot_markdown(d.analysis, f)
        if not from_slider:
            self._syncing = True
            try:
                self.panel.frame.value = f
            finally:
                self._syncing = False


class ReviewApp:
    """The review server. ``start()`` returns at once (the server runs in threads); ``serve_forever()``
    blocks until Ctrl-C; ``stop()`` shuts it down.

    Args:
        clip: the clip folder (or an already loaded :class:`ReviewData`).
        host, port: where to listen (port 0: any free port).
        tick_hz: how often playing sessions advance.
    """

    def __init__(self, clip: str | Path | ReviewData, *, host: str = "127.0.0.1", port: int = 8080,
                 tick_hz: float = 20.0):
        self.data = clip if isinstance(clip, ReviewData) else ReviewData.load(clip)
        self.host, self.port = host, port
        self.tick_hz = tick_hz
        self.server = None
        self.sessions: dict[int, Session] = {}
        self.frames = FrameImages(self.data)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        if self.server is None:
            raise RuntimeError("the review is not started")
        host = "localhost" if self.host in ("0.0.0.0", "") else self.host
        return f"http://{host}:{self.server.get_port()}"

    def start(self) -> str:
        """Start serving; returns the URL."""
        import viser

        from labeler import viewer_common

        self.server = viser.ViserServer(host=self.host, port=self.port, label=f"rally3d review {self.data.clip.root.name}")
        viewer_common.setup_server(self.server)
        build_static_scene(self.server.scene, self.data)
        self.server.on_client_connect(self._connect)
        self.server.on_client_disconnect(lambda c: self.sessions.pop(c.client_id, None))
        self._stop.clear()
        self._thread = threading.Thread(target=self._loop, name="review-playback", daemon=True)
        self._thread.start()
        return self.url

    def _connect(self, client) -> None:
        self.sessions[client.client_id] = Session(self, client)

    def _loop(self) -> None:
        last = time.monotonic()
        while not self._stop.wait(1.0 / self.tick_hz):
            now = time.monotonic()
            dt, last = now - last, now
            for s in list(self.sessions.values()):
                try:
                    s.tick(dt)
                except Exception as e:  # a viewer that went away mid-update
                    print(f"rally3d review: dropping viewer {s.client.client_id}: {e!r}", file=sys.stderr)
                    self.sessions.pop(s.client.client_id, None)

    def serve_forever(self) -> None:
        """Block until Ctrl-C."""
        if self.server is None:
            self.start()
        try:
            while not self._stop.wait(0.5):
                pass
        except KeyboardInterrupt:
            pass
        finally:
            self.stop()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2)
        if self.server is not None:
            self.server.stop()
            self.server = None
        self.frames.close()

    def __enter__(self) -> ReviewApp:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
