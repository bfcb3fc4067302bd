"""The 3D review app: a viser server showing one reconstructed clip.

Shared by every viewer (``server.scene``): the court, the whole path, the contact markers. Per viewer
(``client.scene`` / ``client.gui``, a :class:`Session`): the moving ball and its trail, the players, the
timeline with its own play/pause and speed, the camera presets, the video frame with the reprojection drawn
over it, and the shot panel, under a banner with the clip's 3D status (red when it is not plausible).

Playback runs in the page (:mod:`labeler.player_js`): one clock there picks the video frame to draw (the
newest one decoded, frames not ready are dropped) and moves the 3D ball to that same frame in the same
animation frame, so under load video and 3D skip together. The page reports the frame shown; one background
thread then updates the server-drawn parts of every session (trail, players, shot text, timeline). Until the
page's player attaches, that thread advances playing sessions and sends the video frame itself.

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
from collections.abc import Sequence
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

from ..frames import SERVE_WINDOW, serve_next, stamp_frame_number
from ..player import BrowserPlayer, PlayerReport
from ..viewer_common import encode_jpeg
from .shots import shots_csv_text

VIDEO_WIDTH = 960
"""Width (px) of the video frame sent to the page (the panel beside the 3D view scales it to its width)."""
PAGE_AHEAD = 24
"""Video frames the page keeps decoded ahead of its clock."""
PAGE_BUDGET_PX = 32e6
"""Decoded video pixels the page keeps (≈ 60 frames of 960×540)."""


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
                               trail_xyz=d.trail(frame, TRAIL_FRAMES), observed_px=obs, out_width=self.width)
            img = stamp_frame_number(img, frame)  # the number, and its code that tests read from the page
            self._cache[frame] = img
            self._order.append(frame)
            if len(self._order) > self._cache_size:
                self._cache.pop(self._order.pop(0), None)
            return img

    def next_to_serve(self, frames: Sequence[int], _scale: float = 1.0, *, first: bool = False) -> int:
        """Which of ``frames`` (most wanted first) to draw and send next (:func:`labeler.frames.serve_next`)."""
        cands = list(frames[:SERVE_WINDOW])
        with self._lock:
            ready = {f for f in cands if f in self._cache}
            free = {f for f in cands if self._src is None or self._src.seek_free(f)}
        return serve_next(cands, ready, free, first=first)

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
        first = app.frames.get(self.playback.frame)
        self.info = populate_info(gui, first, d.analysis, d.summary())
        self.dl_replay, self.dl_csv = populate_export(gui)
        self.shown = -1  # the frame whose ball and video were last shown together
        self._drawn = -1  # the frame whose trail, players and shot text were drawn last (page playback)
        self._attached_now = False
        ball = [d.ball_at(f) for f in range(d.first_frame, d.last_frame + 1)]
        self.player = BrowserPlayer(
            client, self._jpeg, self._on_report, pick=app.frames.next_to_serve, kind="review", lo=d.first_frame,
            hi=d.last_frame, fps=float(d.fps),
            first=d.first_frame, ahead=PAGE_AHEAD, behind=4, budget_px=PAGE_BUDGET_PX, max_blobs=10_000,
            width=int(first.shape[1]), height=int(first.shape[0]), speed=1.0, loop=True, ball="/live/ball",
            offset=d.first_frame, ball_xyz=[[round(float(v), 4) for v in p] if np.isfinite(p).all() else None
                                            for p in ball],
            caption=" (3D view and video)")
        self._wire()
        apply_pose(client, self.presets["broadcast"])
        self.render()
        self.player.attach()

    @property
    def paged(self) -> bool:
        """Whether the page's player plays (attached); else the server's thread does."""
        return self.player.attached

    def _jpeg(self, frame: int, _scale: float = 1.0) -> bytes:  # the video panel: always the whole frame
        return encode_jpeg(self.app.frames.get(frame), 80)

    def _on_report(self, rep: PlayerReport, first: bool) -> None:
        """The page showed ``rep.shown`` (viser's event loop: only records it; :meth:`tick` draws the rest)."""
        with self.lock:
            if first:
                self._attached_now = True  # the rest in tick(): this runs on viser's event loop
                return
            self.playback.seek(rep.shown)
            if self.player.follows_commands(rep):
                self.playback.playing = rep.playing
            self.shown = rep.shown

    def _wire(self) -> None:
        p = self.panel

        # viser also runs these when the server sets the value (the timeline follows playback): only the
        # viewer's own changes act
        @p.frame.on_update
        def _(ev) -> None:
            if ev.client is None:
                return
            with self.lock:
                self.playback.seek(int(p.frame.value))
            self.render(from_slider=True)

        @p.play.on_update
        def _(ev) -> None:
            if ev.client is None:
                return
            self._play(bool(p.play.value))

        @p.speed.on_update
        def _(_ev) -> None:
            with self.lock:
                self.playback.set_speed(speed_of(p.speed.value))
            if self.paged:
                self.player.set_speed(self.playback.speed)

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

    def _play(self, playing: bool) -> None:
        with self.lock:
            self.playback.playing = playing
        if self.paged:
            self.player.set_playing(playing)

    def _set_play(self, playing: bool) -> None:
        """Play or pause, and show it in the checkbox (without its callback)."""
        self._play(playing)
        self.panel.play.value = playing

    def tick(self, dt: float) -> None:
        """Page playback: draw the server's parts for the frame the page reported. Before the page attaches:
        advance when playing and redraw if the frame changed."""
        if self.paged:
            if self._attached_now:
                self._attached_now = False
                self.nodes.ball.visible = True  # the page shows and hides the ball's mesh from now on
                self.info.frame.content = ""    # the page writes the caption under its clock
                self.player.goto(self.playback.frame)
                if self.playback.playing:
                    self.player.set_playing(True)
            for _ in range(8):  # the video frames the page asked for
                if self.player.send_next() is None:
                    break
            with self.lock:
                frame = self.playback.frame
            if frame != self._drawn:
                self._draw(frame)
            return
        with self.lock:
            was_playing = self.playback.playing
            before = self.playback.frame
            frame = self.playback.advance(dt)
            ended = was_playing and not self.playback.playing
        if frame != before:
            self.render()
        if ended:  # stopped at the end (no loop): only then uncheck the box, never a click still on its way
            self._set_play(False)

    def _draw(self, f: int, from_slider: bool = False, video: np.ndarray | None = None) -> None:
        """Trail, players, shot text and slider for frame ``f``; with ``video`` also the ball and the video
        picture, in one message batch (the server's clock, before the page's player attaches)."""
        d = self.app.data
        with self.client.atomic():
            update_ball(self.nodes, d.ball_at(f), d.trail(f, TRAIL_FRAMES), move_ball=video is not None)
            self.players.update(d.players_at(f))
            if video is not None:
                self.info.video.image = video
                self.info.frame.content = f"**frame {f}** (3D view and video)"
                self.shown = f
        self.info.current.content = current_shot_markdown(d.analysis, f)
        self._drawn = f
        if not from_slider:
            self.panel.frame.value = f

    def render(self, from_slider: bool = False) -> None:
        """Show the current frame: ball, trail, players, video overlay, shot text, slider position (once the
        page's player is attached: ask the page to go there; it draws video and ball, then reports)."""
        f = self.playback.frame
        if self.paged:
            self.player.goto(f)
            self._draw(f, from_slider)
        else:
            self._draw(f, from_slider, video=self.app.frames.get(f))  # decoded before the batch


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
