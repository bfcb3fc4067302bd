"""The server side of the page's frame player (:mod:`labeler.player_js`): attach, reports, frames on request.

One :class:`BrowserPlayer` per browser tab. It adds a hidden text field to the tab's GUI, through which the
page sends its reports (:class:`PlayerReport`: the frame shown, the cursor, the frames it lacks); it answers
by sending those frames, compressed, one call at a time (:meth:`BrowserPlayer.send_next`), so that a newer
report can reorder the queue between two frames. Until the page's first report the player is not
``attached`` and its owner shows frames the old way (a JPEG per step through viser's image node).
"""
from __future__ import annotations

import json
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass

from .player_js import call_player, install_player, put_frame_js, queue_js

MAX_WANT = 32
"""Frames one report may ask for (the page asks for at most 8 at a time)."""


@dataclass(frozen=True)
class PlayerReport:
    """One report of the page (see :mod:`labeler.player_js`).

    Attributes:
        seq: the page's report counter; token: the player's token (reports of an older clip are ignored);
        shown: the frame on screen; goal: the frame the page is going to (= shown unless still decoding);
        direction: +1 / -1, the last stepping direction; playing: the page is playing;
        want: frames the page lacks around its cursor, most wanted first;
        cmd: the number of the server's last play / pause command the page had received;
        scale: the share of the frame's size the page's view needs (0, 1] (the frames are sent at that size).
    """

    seq: int
    token: str
    shown: int
    goal: int
    direction: int
    playing: bool
    want: tuple[int, ...]
    cmd: int = 0
    scale: float = 1.0

    @classmethod
    def parse(cls, text: str, lo: int, hi: int) -> PlayerReport | None:
        """A report from the page's JSON, frames checked against ``lo..hi``; None for anything malformed."""
        try:
            d = json.loads(text)
            rep = cls(int(d["seq"]), str(d["token"]), int(d["shown"]), int(d["goal"]),
                      1 if int(d["dir"]) >= 0 else -1, bool(d["playing"]),
                      tuple(int(f) for f in d["want"][:MAX_WANT] if lo <= int(f) <= hi), int(d.get("cmd", 0)),
                      min(1.0, max(0.125, float(d.get("scale", 1.0)))))
        except (ValueError, TypeError, KeyError, AttributeError):
            return None
        if not (lo <= rep.shown <= hi and lo <= rep.goal <= hi):
            return None
        return rep


def in_time(frames: list[int], goal: float, direction: int, ahead_s: float, rate: float,
            loop: tuple[int, int] | None = None) -> list[int]:
    """The ``frames`` that a page playing at ``rate`` frames/s in ``direction`` from frame ``goal`` (its clock
    at its last report) has not passed ``ahead_s`` seconds from now (the time since that report plus the time
    to serve one frame): the others would arrive too late to be shown, and serving them would keep the
    server behind the clock for good. ``loop``: ``(lo, hi)`` of a page that wraps around at the end."""
    due = goal + direction * ahead_s * rate
    out = []
    for f in frames:
        ahead = (f - due) * direction
        if loop is not None and ahead < -(loop[1] - loop[0] + 1) / 2:
            ahead += loop[1] - loop[0] + 1  # past the wrap: ahead of the clock
        if ahead >= 0:
            out.append(f)
    return out


class BrowserPlayer:
    """The frame feed of one tab.

    Args:
        client: the viser client (its page runs :data:`labeler.player_js.PLAYER_JS`).
        jpeg: ``jpeg(frame, scale) -> bytes``, the compressed frame to send at ``scale`` of its size.
        on_report: ``on_report(report, first)`` with each new :class:`PlayerReport` on viser's event loop (must
            not block); ``first`` for the report that attaches the page.
        config: the page's configuration (see ``P.attach`` in the script), without token and channel.
    """

    def __init__(self, client, jpeg: Callable[[int, float], bytes], on_report: Callable[[PlayerReport, bool], None],
                 *, pick: Callable[..., int] | None = None, **config):
        self.client = client
        self.jpeg = jpeg
        self.pick = pick
        self.on_report = on_report
        self.config = dict(config)
        self.lo, self.hi = int(config["lo"]), int(config["hi"])
        self.token = uuid.uuid4().hex[:12]
        self.attached = False
        self.last: PlayerReport | None = None
        self.sent = 0
        self.cmd = 0  # the number of the last play / pause command sent
        self._want: list[int] = []
        self._lock = threading.Lock()
        self.speed = float(config.get("speed", 1.0))
        self._report_at = 0.0  # time.monotonic() of the last report
        self._serve_s = 0.0    # running mean of the time to encode and send one frame
        self.channel = client.gui.add_text("frame player", "", visible=False, order=1000)
        self.channel.on_update(self._on_channel)

    def attach(self) -> None:
        """Install the script in the page and attach it to this tab's frames."""
        install_player(self.client)
        call_player(self.client, "attach", {**self.config, "token": self.token, "channel": self.channel._impl.uuid})
        self.client.flush()

    async def _on_channel(self, _ev) -> None:  # awaited in order on viser's event loop: before a later click
        rep = PlayerReport.parse(str(self.channel.value), self.lo, self.hi)
        if rep is None or rep.token != self.token or (self.last is not None and rep.seq <= self.last.seq):
            return
        first = self.last is None
        stopped = self.last is not None and self.last.playing and not rep.playing
        self.attached = True
        self.last, self._report_at = rep, time.monotonic()
        with self._lock:  # the new wants first, then those of earlier reports not sent yet (asked for once;
            # none once it stops: it asks again for those it still wants; while playing, those the clock has
            # passed are dropped by send_next)
            older = [] if stopped else self._want
            self._want = list(dict.fromkeys([*rep.want, *older]))[:4 * MAX_WANT]
        self.on_report(rep, first)

    @property
    def scale(self) -> float:
        """The share of the frame's size the page needs (its last report; 1 before the first)."""
        return self.last.scale if self.last is not None else 1.0

    def has_wanted(self) -> bool:
        with self._lock:
            return bool(self._want)

    def clear_wanted(self) -> None:
        """Forget the frames asked for (the page asks again for those it still lacks)."""
        with self._lock:
            self._want.clear()

    def send_next(self) -> int | None:
        """Send a frame the page lacks; returns it (None when nothing is wanted). The most wanted one, or the
        one ``pick(wanted, scale, first=...)`` chooses (a cheaper one to decode first: see
        :meth:`labeler.frames.FrameCache.next_to_serve`); ``first`` when the most wanted frame is the one the
        page is going to (an annotator waits for it)."""
        with self._lock:
            if not self._want:
                return None
            wanted = list(self._want)
        scale, rep = self.scale, self.last
        if rep is not None and rep.playing:  # frames the page's clock will have passed are dropped, not sent
            rate = min(float(self.config.get("fps", 30.0)) * self.speed, 60.0)
            loop = (self.lo, self.hi) if self.config.get("loop") else None
            timely = in_time(wanted, rep.goal, rep.direction,
                             time.monotonic() - self._report_at + self._serve_s, rate, loop)
            if len(timely) < len(wanted):
                late = set(wanted) - set(timely)
                with self._lock:
                    self._want = [f for f in self._want if f not in late]
                if not timely:
                    return None
                wanted = timely
        t0 = time.monotonic()
        frame = wanted[0]
        if self.pick is not None:
            frame = self.pick(wanted, scale, first=rep is None or frame == rep.goal)
        with self._lock:
            if frame in self._want:
                self._want.remove(frame)
        queue_js(self.client, put_frame_js(self.token, frame, self.jpeg(frame, scale), scale))
        self.client.flush()
        self.sent += 1
        # a run decoded backwards serves many frames at once: the mean follows, it is not a single frame's time
        self._serve_s = 0.8 * self._serve_s + 0.2 * (time.monotonic() - t0)
        return frame

    def _call(self, method: str, *args) -> None:
        call_player(self.client, method, *args)
        self.client.flush()

    def goto(self, frame: int) -> None:
        self._call("goto", int(frame))

    def set_playing(self, playing: bool) -> None:
        self.cmd += 1
        self._call("setPlaying", bool(playing), self.cmd)

    def follows_commands(self, rep: PlayerReport) -> bool:
        """Whether ``rep`` was sent after the page received the last play / pause command (its ``playing``
        is then the page's own doing, e.g. a held key, and not a command still on its way)."""
        return rep.cmd >= self.cmd

    def set_speed(self, speed: float) -> None:
        self.speed = float(speed)
        self._call("setSpeed", float(speed))

    def remove(self) -> None:
        call_player(self.client, "reset")
        self.channel.remove()
