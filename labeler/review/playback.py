"""Per-client playback state of the review: current frame, play/pause, speed. UI-free.

Example:
    >>> pb = Playback(first=18, last=233, fps=30.0)
    >>> pb.playing = True
    >>> pb.advance(0.5)     # half a second at 1×: 15 frames later
    33
"""
from __future__ import annotations

from dataclasses import dataclass, field

SPEEDS = (0.1, 0.25, 0.5, 1.0, 2.0)
"""Playback speeds offered (× real time)."""


@dataclass
class Playback:
    """Where one viewer is in the rally.

    Attributes:
        first, last: the frame range played (inclusive); fps: the clip's frame rate.
        frame: the frame shown; playing: whether time advances; speed: × real time; loop: wrap at the end.
    """

    first: int
    last: int
    fps: float
    frame: int = -1
    playing: bool = False
    speed: float = 1.0
    loop: bool = True
    _pos: float = field(default=0.0, repr=False)

    def __post_init__(self) -> None:
        if self.last < self.first:
            raise ValueError(f"empty playback range {self.first}..{self.last}")
        if not self.fps > 0:
            raise ValueError(f"fps must be > 0, got {self.fps}")
        self.seek(self.first if self.frame < 0 else self.frame)

    def seek(self, frame: int) -> int:
        """Jump to ``frame`` (clamped to the range); returns the frame shown."""
        self.frame = int(min(max(int(frame), self.first), self.last))
        self._pos = float(self.frame)
        return self.frame

    def set_speed(self, speed: float) -> None:
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed}")
        self.speed = float(speed)

    def advance(self, dt_s: float) -> int:
        """Move ``dt_s`` seconds of wall time forward when playing; returns the frame to show.

        At the end it wraps to ``first`` (``loop``) or stops playing on ``last``.
        """
        if not self.playing:
            return self.frame
        self._pos += dt_s * self.fps * self.speed
        if self._pos > self.last:
            if self.loop:
                span = self.last - self.first + 1
                self._pos = self.first + (self._pos - self.first) % span
            else:
                self._pos, self.playing = float(self.last), False
        self.frame = int(self._pos)
        return self.frame

    def step(self, n: int) -> int:
        """``n`` frames forward (negative: back), clamped; pauses."""
        self.playing = False
        return self.seek(self.frame + n)
