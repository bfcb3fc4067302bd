"""A stretch of a clip in seconds (``--start``/``--end`` of ``rally3d infer``, ``detect``, ``events``, ``players``)
and the merge of a stretch's new rows into a table that covers the whole clip.

Example:
    >>> span = Span(2.0, 4.0)
    >>> span.frames(fps=25, n=300)
    (50, 100)
"""
from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

T = TypeVar("T")


@dataclass(frozen=True)
class Span:
    """``[start_s, end_s)`` in seconds of a video (None: from the start / to the end)."""

    start_s: float | None = None
    end_s: float | None = None

    def __post_init__(self) -> None:
        for name, v in (("--start", self.start_s), ("--end", self.end_s)):
            if v is not None and not np.isfinite(v):
                raise ValueError(f"{name} must be a number of seconds, got {v}")
        if self.start_s is not None and self.start_s < 0:
            raise ValueError(f"--start must be ≥ 0 seconds, got {self.start_s}")
        if self.start_s is not None and self.end_s is not None and self.end_s <= self.start_s:
            raise ValueError(f"--end ({self.end_s} s) must come after --start ({self.start_s} s)")

    @property
    def active(self) -> bool:
        """Whether a stretch was asked for (either bound given)."""
        return self.start_s is not None or self.end_s is not None

    def frames(self, fps: float, n: int) -> tuple[int, int]:
        """First frame and the frame after the last, clamped to the video's ``n`` frames.

        Raises:
            ValueError: the stretch starts at or past the end of the video.
        """
        first = int(round((self.start_s or 0.0) * fps))
        stop = n if self.end_s is None else min(n, int(round(self.end_s * fps)))
        if first >= stop:
            raise ValueError(f"--start {self.start_s} s is at or past the end of the video ({n / fps:.1f} s)")
        return first, stop

    def mask(self, fps: float, n: int) -> np.ndarray:
        """``(n,) bool``: True on the frames of the stretch."""
        first, stop = self.frames(fps, n)
        out = np.zeros(n, dtype=bool)
        out[first:stop] = True
        return out

    def describe(self, fps: float, n: int) -> str:
        """``frames 50-99 (2.00-4.00 s)``."""
        first, stop = self.frames(fps, n)
        return f"frames {first}-{stop - 1} ({first / fps:.2f}-{stop / fps:.2f} s)"


def add_span_arguments(parser: argparse.ArgumentParser, what: str) -> None:
    """``--start``/``--end`` (seconds) for a command that works on a clip's frames."""
    parser.add_argument("--start", type=float, help=f"seconds: {what} from here on (the rows of the existing "
                        "file outside the stretch are kept; the old file is backed up)")
    parser.add_argument("--end", type=float, help=f"seconds: {what} up to here")


def span_of(args: argparse.Namespace) -> Span:
    """The :class:`Span` of parsed ``--start``/``--end`` arguments."""
    return Span(getattr(args, "start", None), getattr(args, "end", None))


# ------------------------------------------------------------------------------------ merging tables
def _rows(table: T, keep: np.ndarray) -> T:
    """The rows of a frame-indexed table (a dataclass of ``(N, ...)`` arrays and an ``extra`` dict) where
    ``keep`` is True."""
    values = {}
    for f in dataclasses.fields(table):  # type: ignore[arg-type]
        v = getattr(table, f.name)
        if isinstance(v, dict):
            values[f.name] = {k: np.asarray(c)[keep] for k, c in v.items()}
        elif isinstance(v, np.ndarray) and v.ndim and len(v) == len(keep):
            values[f.name] = v[keep]
        else:
            values[f.name] = v
    return type(table)(**values)


def _concat(a: T, b: T) -> T:
    """Rows of ``a`` then ``b``, sorted by frame (stable); ``extra`` columns missing on one side are ""."""
    order = np.argsort(np.concatenate([a.frame, b.frame]), kind="stable")  # type: ignore[attr-defined]
    values = {}
    for f in dataclasses.fields(a):  # type: ignore[arg-type]
        va, vb = getattr(a, f.name), getattr(b, f.name)
        if isinstance(va, dict):
            names = list(dict.fromkeys([*va, *vb]))
            values[f.name] = {k: np.concatenate([np.asarray(va.get(k, [""] * len(a)), dtype=str),  # type: ignore
                                                 np.asarray(vb.get(k, [""] * len(b)), dtype=str)])[order]
                              for k in names}
        elif isinstance(va, np.ndarray) and va.ndim:
            values[f.name] = np.concatenate([va, vb.astype(va.dtype) if va.dtype.kind != "U" else vb])[order]
        else:
            values[f.name] = va
    return type(a)(**values)


def merge_span(old: T, new: T, first: int, stop: int) -> T:
    """``old``'s rows outside frames ``[first, stop)`` plus ``new``'s rows inside it, sorted by frame.

    Works for every frame-indexed table of the clip folder (ball, events, players); a players table's new
    identities are renumbered after the old ones so that they never merge with a kept track.
    """
    inside_old = (old.frame >= first) & (old.frame < stop)  # type: ignore[attr-defined]
    inside_new = (new.frame >= first) & (new.frame < stop)  # type: ignore[attr-defined]
    kept, added = _rows(old, ~inside_old), _rows(new, inside_new)
    if hasattr(added, "player_id") and len(kept) and len(added):  # type: ignore[arg-type]
        added.player_id = added.player_id + int(kept.player_id.max()) + 1  # type: ignore[attr-defined]
    return _concat(kept, added)
