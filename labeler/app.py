"""The browser labeler: a viser server, one :class:`ClientView` (session, GUI, render thread) per browser tab.

Callbacks only change the tab's :class:`~labeler.state.LabelSession` or its requested frame and then ask the
tab's render thread for an update; the thread renders the newest request only (auto-repeat of a step key
coalesces), inside ``client.atomic()``, and prefetches the frames around it.

Stepping happens in the page (:mod:`labeler.player_js`): the page holds the frames around the cursor, draws
the new one into its own canvas on J/L (no 3D render) and reports the frame shown; the render thread then draws that frame's
overlays and status, and sends the frames the page asks for. Until the page's player attaches (or if it
cannot), the thread shows each frame itself by sending its JPEG.
"""
from __future__ import annotations

import threading
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from inference.clipio import Clip, FormatError

from .client_js import SHORTCUTS_BUTTON, install_keyboard, show_tab
from .frames import BACKWARD_RUN, FrameCache
from .frameplane import NODE, FramePlane
from .panels.assist import populate_assist
from .panels.ball import populate_ball
from .panels.court import populate_court
from .panels.events import populate_events
from .panels.navigation import MODES, populate_navigation
from .panels.stationary import populate_stationary
from .player import BrowserPlayer, PlayerReport
from .render import Overlay
from .state import VISIBILITY_NAMES, LabelSession, clip_overview, find_clips
from .viewer_common import ImagePlane, fit_camera, md_escape, set_slider_marks, setup_server

MAX_KEYFRAME_MARKS = 40
PAGE_AHEAD, PAGE_BEHIND = 16, 6
"""Frames the page keeps ready ahead of the cursor (in the stepping direction) and behind it."""
PAGE_BUDGET_PX = 64e6
"""Decoded pixels the page keeps (≈ 256 MB of bitmaps, at the size the view needs: ≥ 30 frames at 1080p)."""
PLAYING_DRAW_S = 0.5
"""While the page plays, overlays and status follow it at most this often (each update re-renders the page's
panel, which would take the time the page needs for its frames)."""
PAGE_MAX_BLOBS = 400
"""Compressed frames the page keeps at 1080p (≈ 100 MB of JPEGs; fewer for larger frames, more for smaller)."""

# (label, hotkey, modifier, action name, argument): the keys avoid W/A/S/D/Q/E and the arrows (camera keys)
HOTKEYS: list[tuple[str, str, str | None, str, object]] = [
    ("next frame", "L", None, "step", 1),
    ("previous frame", "J", None, "step", -1),
    ("10 frames forward", "L", "shift", "step", 10),
    ("10 frames back", "J", "shift", "step", -10),
    ("first frame", "home", None, "goto", 0),
    ("last frame", "end", None, "goto", -1),
    ("next unlabelled frame", "N", None, "next_unlabelled", None),
    ("play / pause", "space", None, "toggle_play", None),
    ("next event", "K", None, "jump_event", 1),
    ("previous event", "K", "shift", "jump_event", -1),
    ("ball hard to see", "H", None, "set_visibility", 2),
    ("ball occluded", "O", None, "set_visibility", 3),
    ("ball out of frame", "X", None, "set_visibility", 0),
    ("clear ball", "backspace", None, "clear_ball", None),
    ("interpolate keyframes", "I", None, "interpolate", None),
    ("accept proposal here", "Y", None, "accept_here", None),
    ("accept the proposals of this flight (stops at events)", "Y", "shift", "accept_flight", None),
    ("next uncertain frame (detector)", "U", None, "next_uncertain", None),
    ("accept the proposed event here", "V", None, "accept_event_here", None),
    ("next proposed event", "P", None, "jump_proposed_event", None),
    ("follow the ball (zoom)", "G", None, "toggle_follow", None),
    ("cycle mode (ball / stationary / court)", "M", None, "cycle_mode", None),
    ("fit view", "F", None, "fit", None),
    ("undo", "Z", "cmd/ctrl", "undo", None),
    ("redo", "Z", "cmd/ctrl+shift", "redo", None),
    ("remove event", "0", None, "event_key", 0),
] + [(f"event {k}", str(k), None, "event_key", k) for k in range(1, 10)]


#: the panel tab of each mode (a mode change shows it)
MODE_TABS = {"ball": "Ball", "stationary": "Still", "court": "Court"}


class ClientView:
    """One browser tab on one clip: its session, GUI, frame plane, overlays and render thread."""

    def __init__(self, app: LabelerApp, client, clip: Clip, session: LabelSession | None = None):
        self.app, self.client, self.clip = app, client, clip
        self.lock = threading.RLock()
        self.session = session if session is not None else LabelSession(clip)
        s = self.session
        self.plane = ImagePlane(s.width, s.height)
        self.frames = app.frame_cache(clip)
        self.mode = "ball"
        self.pending_visibility = 1
        self.target, self.shown, self.direction = 0, -1, 1
        self.page_goal = 0       # the page's cursor (its last report)
        self._go: int | None = None   # a jump asked by the server (slider, events, ...) not yet sent to the page
        self._drawn = -1         # the frame whose overlays and status were drawn last
        self._drawn_at = 0.0
        self.playing, self.speed = False, 1.0
        self.follow = False
        self.fit_distance: float | None = None
        self.reported_camera: np.ndarray | None = None  # the browser's last reported camera position (3,)
        self._aspect = 0.0
        self._fit_lock = threading.RLock()
        self._fit_pending = True
        self._overlay_dirty = self._gui_dirty = True
        self._attach_sent = False
        self._play_box_stale = False
        self._closed = False
        self._cond = threading.Condition()
        self._detector_thread: threading.Thread | None = None
        self._shortcuts = None

        self.frame_node = FramePlane(client.scene, self.plane, self._on_click)
        self.player = BrowserPlayer(client, self._page_jpeg, self._on_report, pick=self.frames.next_to_serve,
                                    kind="plane", node=NODE, lo=0, hi=s.n_frames - 1, fps=float(s.fps), first=0,
                                    ahead=PAGE_AHEAD, behind=PAGE_BEHIND, budget_px=PAGE_BUDGET_PX,
                                    max_blobs=max(32, int(PAGE_MAX_BLOBS * 1920 * 1080 / (s.width * s.height))),
                                    width=s.width, height=s.height, render_height=self.plane.render_height,
                                    speed=1.0, loop=False)
        self.use_page = bool(app.page_player)
        self.overlay = Overlay(client.scene, self.plane)

        gui = client.gui
        self.folder = gui.add_folder(f"{clip.root.name}", order=1)
        with self.folder:
            self.nav = populate_navigation(gui, self)
            tabs = gui.add_tab_group()
            with tabs.add_tab(MODE_TABS["ball"]):
                self.ball_panel = populate_ball(gui, self)
            with tabs.add_tab(MODE_TABS["stationary"]):
                self.still_panel = populate_stationary(gui, self)
            with tabs.add_tab("Events"):
                self.events_panel = populate_events(gui, self)
            with tabs.add_tab(MODE_TABS["court"]):
                self.court_panel = populate_court(gui, self)
            with tabs.add_tab("Assist"):
                self.assist_panel = populate_assist(gui, self)
        s.on_change(lambda _s: self.request(overlay=True, gui=True))
        client.camera.on_update(self._on_camera)
        self.fit()
        self._thread = threading.Thread(target=self._render_loop, name=f"render-{client.client_id}", daemon=True)
        self._thread.start()
        self._player = threading.Thread(target=self._play_loop, name=f"play-{client.client_id}", daemon=True)
        self._player.start()

    # --------------------------------------------------------------------------------- lifecycle
    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        with warnings.catch_warnings():  # a disconnected client's handles are already gone
            warnings.simplefilter("ignore")
            for remove in (self.player.remove, self.folder.remove, *(h.remove for h in self.frame_node.handles()),
                           *(h.remove for h in self.overlay.handles())):
                try:
                    remove()
                except Exception:
                    pass

    def request(self, *, overlay: bool = False, gui: bool = False) -> None:
        with self._cond:
            self._overlay_dirty |= overlay
            self._gui_dirty |= gui
            self._cond.notify_all()

    # ------------------------------------------------------------------------------- navigation
    @property
    def paged(self) -> bool:
        """Whether the page's player shows the frames (attached); else the render thread does."""
        return self.use_page and self.player.attached

    @property
    def cursor(self) -> int:
        """The frame being gone to: the page's cursor, or the server's target before the page attaches."""
        return self.page_goal if self.paged else self.target

    def goto(self, frame: int) -> None:
        n = self.session.n_frames
        frame = n - 1 if frame < 0 else min(int(frame), n - 1)
        with self._cond:
            if frame == self.cursor and (self.paged or frame == self.target):
                return
            self.direction = 1 if frame >= self.cursor else -1
            self.target = frame
            if self.paged:
                self._go = self.page_goal = frame  # the page goes there (a second step counts from it)
            self._cond.notify_all()
        self.app.note_place(self)

    def step(self, delta: int) -> None:
        with self._cond:
            cursor = self.cursor
        self.goto(max(0, cursor + int(delta)))

    def next_unlabelled(self) -> None:
        f = self.session.next_unlabelled(self.cursor)
        if f is not None:
            self.goto(f)

    def jump_event(self, direction: int) -> None:
        f = self.session.next_event(self.cursor, direction)
        if f is not None:
            self.goto(f)

    def next_uncertain(self) -> None:
        f = self.session.next_uncertain(self.cursor)
        if f is None:
            self._notice("no uncertain frame: run the ball detector (Assist tab) first" if not self.session.ball_scores
                         else "no unlabelled frame where the detector is unsure")
        else:
            self.goto(f)

    def jump_proposed_event(self) -> None:
        later = sorted(f for f in self.session.event_proposals if f > self.cursor)
        frames = later or sorted(self.session.event_proposals)
        if frames:
            self.goto(frames[0])
        else:
            self._notice("no proposed events: use 'propose events' in the Assist tab")

    def toggle_follow(self) -> None:
        self.follow = not self.follow
        if self.ball_panel.follow.value != self.follow:
            self.ball_panel.follow.value = self.follow
        if not self.follow:
            self.fit()
        self.request(overlay=True)

    def set_playing(self, playing: bool) -> None:
        """Play or pause (the page plays once attached; the server's play thread before)."""
        self.playing = playing
        if self.nav.play.value != playing:
            self.nav.play.value = playing
        if self.paged:
            self.player.set_playing(playing)

    def set_speed(self, speed: float) -> None:
        self.speed = float(speed)
        if self.paged:
            self.player.set_speed(self.speed)

    def toggle_play(self) -> None:
        self.set_playing(not self.playing)

    def _play_loop(self) -> None:
        while not self._closed:
            if not self.playing or self.paged:
                time.sleep(0.05)
                continue
            time.sleep(1.0 / max(self.session.fps * self.speed, 1e-3))
            if self.target >= self.session.n_frames - 1:
                self.set_playing(False)
            else:
                self.step(1)

    def _page_jpeg(self, frame: int, scale: float) -> bytes:
        """A frame for the page, at ``scale``. When the page goes backwards, a frame that needs a seek comes
        with a run below it: :data:`~labeler.frames.BACKWARD_RUN` frames below the page's cursor in all (the
        page asks for the frames from a little below its cursor first)."""
        rep = self.player.last
        run = 0
        if rep is not None and rep.direction < 0:
            run = max(BACKWARD_RUN // 4, BACKWARD_RUN - max(0, rep.goal - frame))
        return self.frames.get(frame, scale, backward=run)

    def _on_report(self, rep: PlayerReport, first: bool) -> None:
        """The page showed ``rep.shown`` (viser's event loop: only records it and wakes the render thread).

        The first report attaches the page: it still shows the server's last picture, and goes to the server's
        frame (a jump asked while it was attaching, e.g. a reload's return to its frame)."""
        with self._cond:
            if first:
                self.page_goal = self.shown = rep.shown
                if self.target != rep.goal:
                    self._go = self.target
                self._cond.notify_all()
                return
            self.shown, self.page_goal, self.direction = rep.shown, rep.goal, rep.direction
            if self._go is None:
                self.target = rep.goal
            if rep.playing != self.playing and self.player.follows_commands(rep):
                self.playing = rep.playing   # the page's own doing (a held key, Space): the checkbox follows
                self._play_box_stale = True
                self._gui_dirty = True
            self._cond.notify_all()
        self.app.note_place(self)

    def set_mode(self, mode: str) -> None:
        if mode not in MODES:
            raise ValueError(f"unknown mode {mode!r}; modes: {MODES}")
        changed = mode != self.mode
        self.mode = mode
        if self.nav.mode.value != mode:
            self.nav.mode.value = mode
        if changed:
            show_tab(self.client, MODE_TABS[mode])   # the panel follows the mode (M, the dropdown)
        self.app.note_place(self)
        self.request(overlay=True, gui=True)

    def cycle_mode(self) -> None:
        self.set_mode(MODES[(MODES.index(self.mode) + 1) % len(MODES)])

    # ---------------------------------------------------------------------------------- camera
    def fit(self, aspect: float | None = None) -> None:
        """Fit the browser's camera to the frame (for the canvas aspect, default: the last one reported).

        Serialised: the first fit (at connection) and a refit after a canvas resize may run in two
        threads, and the browser must end at the pose whose distance ``fit_distance`` says.
        """
        with self._fit_lock:
            if aspect is None:
                aspect = float(self.client.camera.aspect or 0.0)
            self.fit_distance = fit_camera(self.client, self.plane, aspect=aspect)
            self._aspect = float(aspect)
            self._fit_pending = True

    def view_px(self) -> tuple[float, float, float, float] | None:
        """The part of the image the browser shows now, ``(x0, y0, x1, y1)`` pixels (None before a report)."""
        cam = self.reported_camera
        if cam is None or cam[2] >= 0 or not self._aspect:
            return None
        half_h = -cam[2] * np.tan(np.radians(50.0) / 2)
        half_w = half_h * self._aspect
        lo = self.plane.scene_to_pixel([[cam[0] - half_w, cam[1] - half_h]])[0]
        hi = self.plane.scene_to_pixel([[cam[0] + half_w, cam[1] + half_h]])[0]
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    def _follow_ball(self, frame: int) -> None:
        """Centre the view on the ball of ``frame`` (labelled, else proposed, else the last labelled before)."""
        s = self.session
        row = s.ball.get(frame) or s.ball_proposals.get(frame)
        if row is None or row[0] == 0:
            before = [f for f in s.keyframes() if f <= frame]
            row = s.ball[before[-1]] if before else None
        if row is None or not self.fit_distance:
            return
        c = self.plane.pixel_to_scene([[row[1] * s.width, row[2] * s.height]])[0]
        d = self.fit_distance / max(float(self.ball_panel.zoom.value), 1.0)
        with self._fit_lock, self.client.atomic():
            self.client.camera.position = (c[0], c[1], -d)
            self.client.camera.look_at = (c[0], c[1], 0.0)

    @property
    def camera_fitted(self) -> bool:
        """True once the browser has reported its camera at the last fitted pose (also when a second fit to the
        same pose, from another thread, left nothing for the browser to move and so nothing to report)."""
        return not self._fit_pending or self._at_fit(self.reported_camera)

    def _at_fit(self, position) -> bool:
        """Whether a reported camera position (3,) is the fitted pose."""
        d = self.fit_distance or 0.0
        return position is not None and d > 0 and bool(np.allclose(position, (0.0, 0.0, -d), atol=1e-3 * d))

    def _on_camera(self, camera) -> None:
        """The browser reported its camera (viser calls this for client messages only).

        Refits when the canvas changed shape. Until the browser reports the fitted pose, a report of another
        pose is answered by the fit again: on a fresh connection the browser may apply the fits it was sent
        out of order (it resets to its initial camera as it starts), and the annotator has not moved the view yet.
        """
        self.reported_camera = np.array(camera.position, float)
        with self._fit_lock:
            aspect = float(camera.aspect or 0.0)
            at_fit = self._at_fit(self.reported_camera)
            if aspect > 0 and abs(aspect - self._aspect) > 1e-3:  # canvas resized (or first real size): refit
                self.fit(aspect)
            elif self._fit_pending and not at_fit:
                self.fit(self._aspect)
            elif at_fit:
                self._fit_pending = False

    # ---------------------------------------------------------------------------------- edits
    def _notice(self, text: str) -> None:
        self.session.notices.append(text)
        self.request(gui=True)

    def _edit(self, fn, *args, **kw):
        with self.lock:
            try:
                return fn(*args, **kw)
            except (ValueError, KeyError) as e:
                self._notice(f"⚠ {e.args[0] if e.args else e}")
                return None

    @property
    def frame(self) -> int:
        """The frame the annotator sees (the last one rendered)."""
        return max(self.shown, 0)

    def _on_click(self, ev) -> None:
        px = self.plane.ray_to_pixel(ev.ray_origin, ev.ray_direction)
        if px is None:
            return
        self.on_pixel_click(*px)

    def on_pixel_click(self, x_px: float, y_px: float) -> None:
        """A click on the frame at pixel ``(x_px, y_px)``: ball, stationary ball or court point by mode."""
        s, f = self.session, self.frame
        xy = s.to_norm(x_px, y_px)
        if self.mode == "ball":
            self._edit(s.set_ball, f, xy, self.pending_visibility)
            self.pending_visibility = 1
        elif self.mode == "stationary":
            action = self.still_panel.action.value
            if action == "add":
                b = self._edit(s.add_inactive, f, xy)
                if b is not None:
                    self.still_panel.selected.value = b
            elif action == "move selected":
                self._edit(s.move_inactive, f, int(self.still_panel.selected.value), xy)
            else:
                b = s.nearest_inactive(f, xy)
                if b is None:
                    self._notice("no stationary ball within 20 px of the click")
                else:
                    self._edit(s.remove_inactive, f, b)
        else:
            name = str(self.court_panel.point.value)
            self._edit(s.set_point, name, xy)
            nxt = self.next_court_point(after=name)
            if nxt is not None:
                self.court_panel.point.value = nxt
                self._notice(f"placed {name}; next: {nxt} (in view)")

    def set_visibility(self, visibility: int) -> None:
        if not self._edit(self.session.set_visibility, self.frame, visibility) and visibility in (2, 3):
            self.pending_visibility = visibility
            self._notice(f"click the ball: it will be saved as {VISIBILITY_NAMES[visibility]}")

    def clear_ball(self) -> None:
        self._edit(self.session.clear_ball, self.frame)

    def interpolate(self) -> None:
        s = self.session
        n = self._edit(s.interpolate, str(self.ball_panel.method.value), max_gap=int(self.ball_panel.max_gap.value))
        text = f"{n or 0} proposed position(s) between keyframes: Y accepts one, shift+Y this flight"
        if s.interpolation_skipped:
            gaps = ", ".join(f"{a}–{b} ({why})" for a, b, why in s.interpolation_skipped[:3])
            text += f"; not filled: {gaps}" + (" …" if len(s.interpolation_skipped) > 3 else "")
        self._notice(text)

    def accept_here(self) -> None:
        n = self._edit(self.session.accept_ball_proposals, [self.frame], overwrite=True)
        if not n:
            self._notice("no proposal on this frame")

    def accept_flight(self) -> None:
        res = self._edit(self.session.accept_flight_proposals, self.frame)
        if res is not None:
            n, (lo, hi) = res
            self._notice(f"accepted {n} proposal(s) of the flight {lo}–{hi} (stops at its events)")

    def accept_range(self, start: int | None = None, stop: int | None = None, *, overwrite: bool = False) -> None:
        frames = None if start is None else range(start, (stop if stop is not None else start) + 1)
        n = self._edit(self.session.accept_ball_proposals, frames, overwrite=overwrite)
        self._notice(f"accepted {n or 0} proposal(s)")

    def reject_proposals(self, frames=None) -> None:
        self._edit(self.session.reject_ball_proposals, frames)

    def event_key(self, key: int) -> None:
        labels = self.session.event_labels
        if key == 0:
            self._edit(self.session.set_event, self.frame, None)
        elif key <= len(labels):
            self._edit(self.session.toggle_event, self.frame, labels[key - 1])

    def remove_inactive(self, ball_no: int) -> None:
        self._edit(self.session.remove_inactive, self.frame, ball_no)

    def remove_point(self, name: str) -> None:
        self._edit(self.session.remove_point, name)

    def next_court_point(self, after: str | None = None) -> str | None:
        """The next unplaced court point, preferring one expected inside the part of the image in view."""
        return self.session.next_point(after, self.view_px())

    def show_shortcuts(self) -> None:
        """Open the cheat-sheet (hotkey ``?``): every key, with this court's event names."""
        if self._shortcuts is not None:
            try:
                self._shortcuts.close()
            except Exception:
                pass
        with self.client.gui.add_modal("Shortcuts") as modal:
            self.client.gui.add_markdown(shortcuts_markdown(self.session.event_labels))
            self.client.gui.add_button("close").on_click(lambda ev: modal.close())
        self._shortcuts = modal

    def undo(self) -> None:
        edit = self._edit(self.session.undo)
        if edit is None:
            self._notice("nothing to undo")
        elif edit.changes:
            self._notice(f"undid: {edit.label}")
        else:
            self.request(gui=True)  # the session's notice says whose rows were left

    def redo(self) -> None:
        edit = self._edit(self.session.redo)
        if edit is None:
            self._notice("nothing to redo")
        elif edit.changes:
            self._notice(f"redid: {edit.label}")
        else:
            self.request(gui=True)

    # ------------------------------------------------------------------------ model assistance
    def run_detector(self, weights: str | None) -> None:
        if self._detector_thread is not None and self._detector_thread.is_alive():
            self._notice("the detector is already running")
            return
        self._detector_thread = threading.Thread(target=self._detect, args=(weights,), daemon=True)
        self._detector_thread.start()

    def _detect(self, weights: str | None) -> None:
        from .assist import run_ball_detector

        bar, info = self.assist_panel.progress, self.assist_panel.info
        bar.visible, bar.value = True, 0.0
        info.content = "loading the detector …"

        def progress(done: int, total: int) -> None:
            bar.value = 100.0 * done / max(total, 1)
            info.content = f"detector: frame {done} / {total}"

        try:
            track, scores, text = run_ball_detector(self.clip, weights, progress)
        except Exception as e:  # shown in the GUI: a bad checkpoint must not kill the labeler
            info.content = f"⚠ detector failed: {md_escape(e)}"
            bar.visible = False
            return
        with self.lock:
            self.session.set_ball_proposals(track, "ball detector", scores)
        info.content = md_escape(text)
        bar.value, bar.visible = 100.0, False

    def propose_events(self) -> None:
        from .assist import propose_events

        info = self.assist_panel.info
        with self.lock:
            try:
                events = propose_events(self.session)
            except RuntimeError as e:
                info.content = md_escape(e)
                return
            n = self.session.set_event_proposals(events)
        info.content = f"{n} proposed event(s): P jumps to the next, V accepts the one on this frame"
        self.request(overlay=True, gui=True)

    def accept_events(self) -> None:
        n = self._edit(self.session.accept_event_proposals)
        self._notice(f"accepted {n or 0} event proposal(s)")

    def accept_event_here(self) -> None:
        label = self.session.event_proposals.get(self.frame)
        if label is None:
            self._notice("no proposed event on this frame (P jumps to the next)")
            return
        n = self._edit(self.session.accept_event_proposals, [self.frame], overwrite=True)
        self._notice(f"accepted the proposed event {label} @{self.frame}" if n else "event not accepted")

    # ------------------------------------------------------------------------------- rendering
    def _work(self) -> bool:
        """Whether the render thread has something to do (call holding ``_cond``)."""
        if self._overlay_dirty or self._gui_dirty or self._go is not None:
            return True
        if self.paged:
            return self._page_frame_due() or self.player.has_wanted()
        return self.target != self.shown

    def _page_frame_due(self) -> bool:
        """Whether the page's frame needs its overlays drawn (call holding ``_cond``): a frame not drawn yet,
        at most every :data:`PLAYING_DRAW_S` while the page plays (each draw re-renders the 3D scene)."""
        return self.shown != self._drawn and \
            (not self.playing or time.monotonic() - self._drawn_at >= PLAYING_DRAW_S)

    def _render_loop(self) -> None:
        while True:
            with self._cond:
                if not self._closed and not self._work():
                    self._cond.wait(timeout=PLAYING_DRAW_S / 2 if self.playing else 1.0)
                if self._closed:
                    return
                if not self._work():
                    idle, go = True, None
                else:
                    idle, go = False, self._go
                    self._go = None
                    paged = self.paged
                    frame = self.shown if paged else self.target
                    direction = self.direction
                    draw = self._overlay_dirty or self._gui_dirty or \
                        (self._page_frame_due() if paged else frame != self._drawn or frame != self.shown)
                    self._overlay_dirty = self._gui_dirty = False
            if idle:  # outside the condition: syncing takes the session lock (lock order: session, then cond)
                self._sync_from_disk()
                continue
            if go is not None:
                self.player.goto(go)
            if draw and frame >= 0:
                try:
                    self._render(frame, direction, paged)
                except Exception as e:  # a failing frame is reported, the labeler goes on
                    self._notice(f"⚠ could not show frame {frame}: {e}")
                    self.shown = self._drawn = frame
            elif paged:
                try:
                    self.player.send_next()
                except Exception as e:
                    self._notice(f"⚠ could not send a frame to the page: {e}")
                    self.player.clear_wanted()

    def _sync_from_disk(self) -> None:
        with self.lock:
            try:
                self.session.sync()
            except Exception as e:
                self.session.notices.append(f"⚠ could not re-read the clip files: {e}")

    def _render(self, frame: int, direction: int, paged: bool) -> None:
        """Draw ``frame``'s overlays and status; show its picture too unless the page shows it.

        While the page plays, only the status follows it (:data:`PLAYING_DRAW_S`), and the overlays of one
        frame (ball, proposal, trail, stationary balls) are hidden until it stops: drawn twice a second they
        would sit on frames they do not belong to, and each draw re-renders the 3D scene, which costs the
        page the frames it plays (in software WebGL). The court stays."""
        playing = paged and self.playing
        with self.lock, self.client.atomic():
            if not paged:
                self.frame_node.show(frame, self.frames.get)
            if playing:
                self.overlay.hide_frame_layers()
            else:
                self.overlay.draw(self.session, frame, mode=self.mode, trail_length=int(self.ball_panel.trail.value),
                                  show_court=bool(self.court_panel.show.value) or self.mode == "court",
                                  selected_point=str(self.court_panel.point.value) if self.mode == "court" else None)
            self._refresh_gui(frame)
        if not paged:
            self.shown = frame
        # while playing no frame's overlays are drawn: the frame where it stops gets them at once
        self._drawn, self._drawn_at = (-1 if playing else frame), time.monotonic()
        self.client.flush()
        if self.use_page and not self.player.attached and not self._attach_sent:
            self._attach_sent = True   # the node has its first picture: the page's player can take it over
            self.player.config["first"] = frame
            self.player.attach()
        if self.follow:
            self._follow_ball(frame)
        if not (paged and self.playing):  # a playing page asks for its own frames (the one drawn here is
            # already behind it: prefetching around it would seek the video back)
            self.frames.prefetch(frame, direction, self.player.scale if paged else 1.0)

    def _refresh_gui(self, frame: int) -> None:
        s = self.session
        sm = s.summary()
        nav = self.nav
        if int(nav.slider.value) != frame:
            nav.slider.value = frame
        if self._play_box_stale:  # only then: a click on the box may still be on its way
            self._play_box_stale = False
            nav.play.value = self.playing
        row = s.ball.get(frame)
        ball = "not labelled" if row is None else VISIBILITY_NAMES[row[0]]
        if row is not None and row[0] > 0:
            ball += f" ({row[1] * s.width:.1f}, {row[2] * s.height:.1f}) px"
        event = s.events.get(frame, "–")
        proposed = s.event_proposals.get(frame)
        if proposed is not None and proposed != s.events.get(frame):
            event += f" · proposed: {proposed} (V accepts)"
        nav.status.content = (
            f"**frame {frame} / {s.n_frames - 1}** · mode **{self.mode}**  \n"
            f"ball: {ball} · event: {event}  \n"
            f"labelled {sm['labelled']} ({sm['labelled_pct']:.1f} %) · events {sm['events']} · "
            f"still balls {sm['inactive_balls']} · court points {sm['court_points']}"
        )
        nav.notice.content = f"_{md_escape(relative_to(s.notices[-1], self.app.shown_base))}_" if s.notices else ""
        few = len(s.events) <= 6  # labels of dense marks overlap: then only ticks (the events tab lists them)
        marks = [(f, e.split("_")[-1][:5] if few else "") for f, e in sorted(s.events.items())]
        keys = s.keyframes()
        if len(keys) <= MAX_KEYFRAME_MARKS:
            marks += [(f, "") for f in keys if f not in s.events]
        set_slider_marks(nav.slider, marks)
        prop = s.ball_proposals.get(frame)
        score = s.ball_scores.get(frame)
        self.ball_panel.info.content = (
            f"proposals: {sm['ball_proposals']} ({md_escape(s.ball_proposal_source or 'none')})"
            + (f" · here: ({prop[1] * s.width:.1f}, {prop[2] * s.height:.1f}) px" if prop and prop[0] else "")
            + (f", confidence {score:.2f}" if prop and score is not None else "")
            + f"  \nkeyframes: {len(keys)}"
        )
        still = s.inactive_at(frame)
        self.still_panel.info.content = "stationary balls here: " + (
            ", ".join(f"#{b} ({x * s.width:.0f}, {y * s.height:.0f})" for b, (x, y) in sorted(still.items())) or "none")
        ev_list = ", ".join(f"{f}: {e}" for f, e in sorted(s.events.items())[:30])
        pending = ", ".join(f"{f}: {e}" for f, e in sorted(s.event_proposals.items())[:20])
        self.events_panel.info.content = (f"{len(s.events)} event(s): {ev_list or 'none'}"
                                          + (f"  \nproposed (V accepts on its frame): {pending}" if pending else ""))
        self.court_panel.info.content = self._court_text()
        self._offer_court_points()

    def _offer_court_points(self) -> None:
        """The point dropdown offers the points inside the picture (:meth:`LabelSession.offered_points`);
        the point chosen stays chosen while it is offered."""
        offered = tuple(self.session.offered_points()) or tuple(self.session.court.point_names)
        dropdown = self.court_panel.point
        if tuple(dropdown.options) == offered:
            return
        chosen = str(dropdown.value)
        dropdown.options = offered
        if chosen in offered:
            dropdown.value = chosen
        else:
            dropdown.value = self.next_court_point() or offered[0]

    def _court_text(self) -> str:
        s = self.session
        if s.calibration is None:
            return f"{len(s.points)} point(s). {md_escape(s.calibration_error)}"
        cal = s.calibration
        rows = "\n".join(f"| {md_escape(n)} | {cal.residuals_px[n]:.2f}{' ⚠' if n in cal.suspect else ''} |"
                         for n in cal.names)
        return (f"calibrated from {len(cal.names)} points, RMS **{cal.rms_px:.2f} px** (camera.yaml saved)\n\n"
                f"| point | residual px |\n|---|---|\n{rows}")


def shortcuts_markdown(event_labels: list[str]) -> str:
    """The cheat-sheet: every hotkey of :data:`HOTKEYS` (event keys with this court's names)."""
    def key(hotkey: str, modifier: str | None) -> str:
        k = {"space": "Space", "backspace": "Backspace", "home": "Home", "end": "End"}.get(hotkey, hotkey)
        return f"{modifier.replace('cmd/ctrl', 'Ctrl/Cmd').replace('shift', 'Shift')}+{k}" if modifier else k

    rows = []
    for label, hotkey, modifier, action, arg in HOTKEYS:
        if action == "event_key" and arg:
            if arg > len(event_labels):
                continue
            label = f"event {md_escape(event_labels[arg - 1])}"
        rows.append(f"| {key(hotkey, modifier)} | {label} |")
    rows.append("| ? | this cheat-sheet |")
    return ("Keys work when no field has focus; Enter or Escape leaves a field.\n\n"
            "| key | action |\n|---|---|\n" + "\n".join(rows))


def shorten(text: str, n: int) -> str:
    """``text`` in at most ``n`` characters: its start and end around an ellipsis when longer."""
    text = str(text)
    if len(text) <= n:
        return text
    head = (n - 1) // 2 + (n - 1) % 2
    return text[:head] + "…" + text[len(text) - (n - 1 - head):]


def dataset_markdown(rows: list[dict], name_chars: int = 20, error_chars: int = 28) -> str:
    """The Dataset panel's table (one row per :func:`labeler.state.clip_overview`), narrow enough for the
    panel: short headers, clip names and errors shortened around an ellipsis (the clip dropdown below
    holds the full names), every file-derived string escaped."""
    out = ["| clip | frames | done | events | pts |", "|---|---|---|---|---|"]
    for r in rows:
        name = md_escape(shorten(r["clip"], name_chars))
        if "error" in r:
            out.append(f"| {name} | ⚠ {md_escape(shorten(r['error'], error_chars))} | | | |")
        else:
            out.append(f"| {name} | {r.get('frames', '?')} | {r.get('labelled_pct', 0):.0f} % | "
                       f"{r.get('events', '?')} | {r.get('court_points', '?')} |")
    return "\n".join(out)


#: hosts that serve this machine only: the page may show absolute paths
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


def relative_to(text: str, base: Path | None) -> str:
    """``text`` with the absolute paths under ``base`` written relative to it (``base`` None: unchanged) — what
    a page served beyond this machine shows of the server's files."""
    if base is None:
        return text
    for root in dict.fromkeys((str(base.resolve()), str(base.absolute()), str(base))):
        text = text.replace(root + "/", "").replace(root, ".")
    return text


def error_markdown(clip: Clip, err: Exception, base: Path | None = None) -> str:
    """What the page shows for a clip that cannot be opened: file, line, problem and fix (all escaped); with
    ``base`` (the dataset, when serving beyond localhost) paths relative to it."""
    if isinstance(err, FormatError):
        where = md_escape(relative_to(str(err.path), base)) + (f", line {err.line}" if err.line is not None else "")
        text = f"**{where}**  \n{md_escape(relative_to(err.problem, base))}"
        if err.fix:
            text += f"  \nfix: {md_escape(relative_to(err.fix, base))}"
    else:
        text = md_escape(relative_to(f"{type(err).__name__}: {err}", base))
    return f"⚠ **cannot open {md_escape(clip.root.name)}**  \n{text}"


@dataclass(frozen=True)
class Place:
    """Where a tab was: its clip folder (resolved), frame and mode."""

    clip: Path
    frame: int
    mode: str


class LabelerApp:
    """The labeler server for a clip or a dataset (``rally3d label``).

    Args:
        target: a clip folder, or a dataset (``manifest.yaml`` or clip sub-folders).
        host, port: where viser listens.
        page_player: let the page hold the frames and step (:mod:`labeler.player_js`); False: the server
            sends each frame's JPEG when it is shown (the fallback when the page's player cannot attach).
    """

    def __init__(self, target: str | Path, host: str = "127.0.0.1", port: int = 8080, page_player: bool = True):
        import viser

        self.clips = find_clips(target)
        target = Path(target)
        dataset = target if target.is_dir() else target.parent   # a manifest.yaml's folder
        # beyond this machine the pages show paths relative to the dataset (a clip: its folder's parent)
        self.shown_base: Path | None = None if host in LOCAL_HOSTS else \
            (dataset.parent if len(self.clips) == 1 and self.clips[0].root.resolve() == dataset.resolve() else dataset)
        self.page_player = bool(page_player)
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        setup_server(self.server)
        # the frame and overlays are unlit: no lights, no shadow passes (software WebGL pays per pixel drawn)
        self.server.scene.configure_default_lights(enabled=False, cast_shadow=False)
        self._caches: dict[Path, FrameCache] = {}
        self._cache_lock = threading.Lock()
        self.views: dict[int, ClientView] = {}
        self.errors: dict[int, object] = {}  # client id → the error folder shown in its page
        self.last_place: Place | None = None  # where a tab last was (a reload returns there)
        self._tabs = 0
        self.server.on_client_connect(self._connect)
        self.server.on_client_disconnect(self._disconnect)

    @property
    def url(self) -> str:
        return f"http://{self.server.get_host()}:{self.server.get_port()}/"

    def frame_cache(self, clip: Clip) -> FrameCache:
        with self._cache_lock:
            key = clip.root.resolve()
            if key not in self._caches:
                self._caches[key] = FrameCache(clip)
            return self._caches[key]

    def stop(self) -> None:
        for view in list(self.views.values()):
            view.close()
        self.server.stop()
        for cache in self._caches.values():
            cache.close()

    def _connect(self, client) -> None:
        install_keyboard(client)
        self._register_hotkeys(client)
        self._tabs += 1
        client.gui.add_button(SHORTCUTS_BUTTON, order=0.5).on_click(lambda ev: self._shortcuts(client))
        if len(self.clips) > 1:
            self._dataset_panel(client)
        place = self.last_place
        roots = [c.root.resolve() for c in self.clips]
        if place is not None and place.clip in roots:   # a reload: back to the clip, frame and mode
            view = self.open(client, self.clips[roots.index(place.clip)])
            if view is not None:
                view.goto(place.frame)
                view.set_mode(place.mode)
                view._notice(f"back at frame {place.frame} ({place.mode} mode), where this page was left")
                return
        self.open(client, self.clips[0])

    def _shortcuts(self, client) -> None:
        view = self.views.get(client.client_id)
        if view is not None:
            view.show_shortcuts()

    def note_place(self, view: ClientView) -> None:
        """Remember where ``view`` is (its clip, frame and mode): a page opened or reloaded next returns
        there (noted on every step and mode change: a reload's new tab may connect before the old one has
        gone)."""
        self.last_place = Place(view.clip.root.resolve(), int(view.cursor), view.mode)

    def _disconnect(self, client) -> None:
        view = self.views.pop(client.client_id, None)
        if view is not None:
            view.close()
        self.errors.pop(client.client_id, None)

    def open(self, client, clip: Clip, *, skip_bad_rows: bool = False) -> ClientView | None:
        """Show ``clip`` in ``client``'s tab. A clip that cannot be opened leaves the tab's current clip open
        and shows the file, line and fix in the page, with "open anyway, skip bad rows" (the file is not
        touched). Returns the new view, or None."""
        self._clear_error(client)
        try:
            session = LabelSession(clip, skip_bad_rows=skip_bad_rows, name=f"tab {self._tabs}")
            self.frame_cache(clip).get(0)  # the video opens and decodes
        except (FormatError, ValueError, KeyError, OSError) as e:
            self._show_error(client, clip, e)
            return None
        old = self.views.pop(client.client_id, None)
        if old is not None:
            old.close()
        view = ClientView(self, client, clip, session)
        self.views[client.client_id] = view
        skipped = [e for errs in session.skipped.values() for e in errs]
        if skipped:
            first = skipped[0]
            view._notice(f"opened with {len(skipped)} bad row(s) left out (the file is unchanged until you edit "
                         f"it, then backed up): {first}")
        return view

    def _clear_error(self, client) -> None:
        folder = self.errors.pop(client.client_id, None)
        if folder is not None:
            try:
                folder.remove()
            except Exception:
                pass

    def _show_error(self, client, clip: Clip, err: Exception) -> None:
        gui = client.gui
        with gui.add_folder("⚠ clip not opened", order=0.8) as folder:
            gui.add_markdown(error_markdown(clip, err, self.shown_base))
            if self.views.get(client.client_id) is not None:
                gui.add_markdown(f"Still showing {md_escape(self.views[client.client_id].clip.root.name)}.")
            if isinstance(err, FormatError) and err.line is not None and err.line > 1:
                gui.add_button("open anyway, skip bad rows").on_click(
                    lambda ev: self.open(client, clip, skip_bad_rows=True))
            gui.add_button("try again").on_click(lambda ev: self.open(client, clip))
        self.errors[client.client_id] = folder

    def _register_hotkeys(self, client) -> None:
        for label, key, modifier, action, arg in HOTKEYS:
            cmd = client.gui.add_command(label, hotkey=key, modifier=modifier)

            def trigger(ev, action=action, arg=arg) -> None:
                view = self.views.get(ev.client.client_id) if ev.client is not None else None
                if view is None:
                    return
                fn = getattr(view, action)
                fn() if arg is None else fn(arg)

            cmd.on_trigger(trigger)

    def _dataset_panel(self, client) -> None:
        gui = client.gui
        with gui.add_folder("Dataset", order=0, expand_by_default=True):
            gui.add_markdown(dataset_markdown([clip_overview(c) for c in self.clips]))
            names = [c.root.name for c in self.clips]
            pick = gui.add_dropdown("clip", names, initial_value=names[0])
            button = gui.add_button("open clip")
            button.on_click(lambda ev: self.open(client, self.clips[names.index(str(pick.value))]))
